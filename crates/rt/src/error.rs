//! Errors of the real-time crate: setup and protocol problems found before or after the loop.
//! (Inside the loop nothing is an error: bad packets are counted and dropped, and every stop
//! has a [`crate::safety::StopKind`].)

use std::io::ErrorKind;

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
    /// A socket, address, file or thread could not be set up; keeps the OS error's kind and
    /// number (the bindings raise it as `RealtimeError` with `errno` set).
    #[error("{context}: {message}")]
    Io {
        /// What was being done, e.g. `sensor (RDT): cannot bind UDP 127.0.0.1:49152`.
        context: String,
        /// The error's kind (`AddrInUse`, `ConnectionRefused`, ...; `Other` when the error did
        /// not come from the OS).
        kind: ErrorKind,
        /// The raw OS error number (`errno`, e.g. 98 = `EADDRINUSE` on Linux), when the error
        /// came from the OS.
        errno: Option<i32>,
        /// The error's own text, e.g. `Address already in use (os error 98)`.
        message: String,
    },
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

    /// An [`RtError::Io`] from an OS error, keeping its kind and errno; `context` says what
    /// was being done.
    pub fn io(context: impl Into<String>, error: &std::io::Error) -> Self {
        RtError::Io {
            context: context.into(),
            kind: error.kind(),
            errno: error.raw_os_error(),
            message: error.to_string(),
        }
    }

    /// An [`RtError::Io`] that did not come from the OS (kind `Other`, no errno), e.g. a thread
    /// that panicked.
    pub fn io_other(context: impl Into<String>, message: impl Into<String>) -> Self {
        RtError::Io {
            context: context.into(),
            kind: ErrorKind::Other,
            errno: None,
            message: message.into(),
        }
    }

    /// An [`RtError::Io`] from any error: an [`std::io::Error`] inside it keeps its kind and
    /// errno (e.g. the HTTP server's bind error), anything else is `Other`.
    pub fn io_dyn(context: impl Into<String>, error: &(dyn std::error::Error + 'static)) -> Self {
        match error.downcast_ref::<std::io::Error>() {
            Some(e) => RtError::io(context, e),
            None => RtError::io_other(context, error.to_string()),
        }
    }

    /// The OS error number of an [`RtError::Io`] that came from the OS.
    pub fn errno(&self) -> Option<i32> {
        match self {
            RtError::Io { errno, .. } => *errno,
            _ => None,
        }
    }
}

/// Result type of the real-time crate.
pub type Result<T> = std::result::Result<T, RtError>;
