//! Errors of the core. One enum; the bindings map it to the package's exception tree.

use thiserror::Error;

/// One problem of a scenario: the dotted key and what is wrong and allowed.
#[derive(Debug, Clone, PartialEq, Eq)]
pub struct ScenarioIssue {
    /// Dotted path of the offending key, e.g. `facility.robot_delay` or `walls[1].normal`.
    pub key: String,
    /// What is wrong and what is allowed.
    pub message: String,
}

/// An error of the core.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum CoreError {
    /// A scenario is invalid. `key` and `message` are its first problem; `more` holds the
    /// others (every problem of the scenario is reported, not only the first).
    #[error("{key}: {message}{}", summary_of_more(more))]
    InvalidScenario {
        /// Dotted path of the first offending key, e.g. `facility.robot_delay`.
        key: String,
        /// What is wrong and what is allowed.
        message: String,
        /// The scenario's other problems, in the order they were found.
        more: Vec<ScenarioIssue>,
    },
}

/// ` (and 2 more: target.mass, contact.bogus)`, or nothing.
fn summary_of_more(more: &[ScenarioIssue]) -> String {
    if more.is_empty() {
        return String::new();
    }
    let keys: Vec<&str> = more.iter().map(|i| i.key.as_str()).collect();
    format!(" (and {} more: {})", more.len(), keys.join(", "))
}

impl CoreError {
    /// A scenario error with one problem.
    pub fn invalid(key: impl Into<String>, message: impl Into<String>) -> Self {
        CoreError::InvalidScenario {
            key: key.into(),
            message: message.into(),
            more: Vec::new(),
        }
    }

    /// Every problem of an invalid scenario, first one first (empty for other errors).
    pub fn issues(&self) -> Vec<ScenarioIssue> {
        match self {
            CoreError::InvalidScenario { key, message, more } => {
                let mut all = vec![ScenarioIssue {
                    key: key.clone(),
                    message: message.clone(),
                }];
                all.extend(more.iter().cloned());
                all
            }
        }
    }
}

/// Collects the problems of a scenario while it is resolved, so that all are reported.
#[derive(Debug, Default)]
pub struct Issues(Vec<ScenarioIssue>);

impl Issues {
    /// Records a problem of `key`.
    pub fn push(&mut self, key: impl Into<String>, message: impl Into<String>) {
        self.0.push(ScenarioIssue {
            key: key.into(),
            message: message.into(),
        });
    }

    /// Whether no problem was recorded.
    pub fn is_empty(&self) -> bool {
        self.0.is_empty()
    }

    /// `Ok(())` if no problem was recorded, else the error with every problem.
    pub fn finish(self) -> Result<()> {
        let mut all = self.0.into_iter();
        match all.next() {
            None => Ok(()),
            Some(first) => Err(CoreError::InvalidScenario {
                key: first.key,
                message: first.message,
                more: all.collect(),
            }),
        }
    }
}

/// Result type of the core.
pub type Result<T> = std::result::Result<T, CoreError>;

/// A recording (a logged run or a user's data) that cannot be replayed or identified: what is
/// wrong, naming the column and the sample.
#[derive(Debug, Clone, PartialEq, Error)]
pub enum RecordingError {
    /// A column the computation needs is absent.
    #[error("missing columns: {}", .0.join(", "))]
    MissingColumns(Vec<String>),
    /// A column's length differs from the time column's.
    #[error("column {name} has {len} samples, time has {expected}")]
    Length {
        /// The column.
        name: String,
        /// Its number of samples.
        len: usize,
        /// The time column's number of samples.
        expected: usize,
    },
    /// Fewer samples than the computation needs.
    #[error("too short: {len} samples, at least {min} needed")]
    TooShort {
        /// Number of samples.
        len: usize,
        /// Minimum.
        min: usize,
    },
    /// Time does not strictly increase.
    #[error("time is not strictly increasing at sample {index} ({before} s, then {after} s)")]
    NonMonotonic {
        /// Index of the offending sample.
        index: usize,
        /// The previous time, s.
        before: f64,
        /// The offending time, s.
        after: f64,
    },
    /// A sample is NaN or infinite.
    #[error("column {name}: sample {index} is not finite ({value})")]
    NonFinite {
        /// The column.
        name: String,
        /// Index of the sample.
        index: usize,
        /// Its value.
        value: f64,
    },
}
