//! Errors of the real-time crate: setup and protocol problems found before or after the loop.
//! (Inside the loop nothing is an error: bad packets are counted and dropped, and every stop
//! has a [`crate::safety::StopKind`].)

use hilcontact_core::CoreError;
use thiserror::Error;

/// An error of the real-time runtime or the emulator.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum RtError {
    /// The scenario is invalid.
    #[error(transparent)]
    Scenario(#[from] CoreError),
    /// An option is invalid; `key` is the option's name (`force_limit`).
    #[error("{key}: {message}")]
    Option {
        /// The option's name as in [`crate::runtime::RuntimeOptions`] / [`crate::emulator::EmulatorOptions`].
        key: String,
        /// What is wrong and what is allowed.
        message: String,
    },
    /// A socket, address or thread could not be set up.
    #[error("{0}")]
    Io(String),
    /// A peer answered with something that is not its protocol (e.g. a bad netftapi2.xml).
    #[error("{0}")]
    Protocol(String),
    /// The sensor or the robot did not answer before the connect timeout.
    #[error("{0}")]
    Connect(String),
}

impl RtError {
    /// Shorthand for [`RtError::Option`].
    pub fn option(key: impl Into<String>, message: impl Into<String>) -> Self {
        RtError::Option {
            key: key.into(),
            message: message.into(),
        }
    }
}

/// Result type of the real-time crate.
pub type Result<T> = std::result::Result<T, RtError>;
