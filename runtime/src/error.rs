//! The runtime's error type (failures that prevent or abort a run; faults
//! detected during a run are reported in the `RunReport` instead).

use crate::backend::BackendError;
use crate::log::LogError;
use std::fmt;

/// Why a run could not start or did not end normally.
#[derive(Debug, Clone, PartialEq)]
pub enum RuntimeError {
    /// The run configuration is inconsistent.
    InvalidConfig(String),
    /// The backend failed to start (the output was left at 0 V).
    Backend(BackendError),
    /// The log could not be started.
    Log(LogError),
    /// The loop itself panicked (a bug); the backend was closed at 0 V.
    Panic(String),
    /// Closing the backend failed (every failed call and what holds the
    /// output are in `close`), after `cause` ended the run.
    CloseFailed {
        /// Why the run ended before the close, if it did not end normally.
        cause: Option<Box<RuntimeError>>,
        /// The close's error ([`BackendError::SafeStop`] for a board).
        close: BackendError,
    },
}

impl fmt::Display for RuntimeError {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        match self {
            RuntimeError::InvalidConfig(s) => write!(f, "invalid run configuration: {s}"),
            RuntimeError::Backend(e) => write!(f, "backend: {e}"),
            RuntimeError::Log(e) => write!(f, "{e}"),
            RuntimeError::Panic(s) => write!(f, "control loop panicked: {s}"),
            RuntimeError::CloseFailed { cause, close } => {
                if let Some(c) = cause {
                    write!(f, "{c}; then ")?;
                }
                write!(f, "{close}")
            }
        }
    }
}

impl std::error::Error for RuntimeError {}

impl From<BackendError> for RuntimeError {
    fn from(e: BackendError) -> Self {
        RuntimeError::Backend(e)
    }
}

impl From<LogError> for RuntimeError {
    fn from(e: LogError) -> Self {
        RuntimeError::Log(e)
    }
}
