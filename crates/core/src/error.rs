//! Errors of the core. One enum; the bindings map it to the package's exception tree.

use thiserror::Error;

/// An error of the core.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum CoreError {
    /// A scenario value is invalid; `key` is the dotted path (`servicer.mass`).
    #[error("{key}: {message}")]
    InvalidScenario {
        /// Dotted path of the offending key, e.g. `facility.robot_delay`.
        key: String,
        /// What is wrong and what is allowed.
        message: String,
    },
}

impl CoreError {
    /// Shorthand for [`CoreError::InvalidScenario`].
    pub fn invalid(key: impl Into<String>, message: impl Into<String>) -> Self {
        CoreError::InvalidScenario {
            key: key.into(),
            message: message.into(),
        }
    }
}

/// Result type of the core.
pub type Result<T> = std::result::Result<T, CoreError>;
