//! The one error type of msgp-core.

use std::path::PathBuf;

/// Everything that can go wrong in msgp-core. User input never panics; it ends here.
#[derive(Debug, thiserror::Error)]
pub enum MsgpError {
    /// A matrix that must be symmetric positive definite was not, even after the largest
    /// jitter the [`JitterPolicy`](crate::numeric::linalg::JitterPolicy) allows.
    #[error(
        "{what} is not positive definite (pivot {pivot} = {value:e}) even with jitter {jitter:e}"
    )]
    NotPositiveDefinite {
        /// Which matrix (e.g. "K + σx² I of output 0").
        what: String,
        /// Row of the failing pivot.
        pivot: usize,
        /// The failing pivot value.
        value: f64,
        /// Largest jitter tried.
        jitter: f64,
    },
    /// Shapes that do not fit together.
    #[error("shape mismatch: {0}")]
    Shape(String),
    /// A setting outside its valid range.
    #[error("invalid setting `{name}`: {reason}")]
    InvalidSetting {
        /// The setting.
        name: &'static str,
        /// Why it is invalid.
        reason: String,
    },
    /// Settings given by name ([`crate::overlay`]) that the settings type does not take: an
    /// unknown key or a value of the wrong type, named by its dotted path.
    #[error("{0}")]
    Overrides(String),
    /// Data that cannot be used (too short, non-finite, ...).
    #[error("bad data: {0}")]
    Data(String),
    /// A non-finite value appeared during a computation.
    #[error("non-finite value in {0}")]
    NonFinite(String),
    /// A data file could not be read or parsed.
    #[error("{path}: {message}")]
    File {
        /// The file.
        path: PathBuf,
        /// What went wrong, with line and column where known.
        message: String,
    },
    /// A data file with a problem at a known place (CSV cell, ...).
    #[error("{}:{line}:{column}: {message}", path.display())]
    FileAt {
        /// The file.
        path: PathBuf,
        /// 1-based line.
        line: u64,
        /// 1-based column (field number for CSV).
        column: usize,
        /// What is wrong there.
        message: String,
    },
    /// A model file of a format version this build cannot read.
    #[error(
        "{}: model file format version {found} is not supported (this build reads {supported})",
        path.display()
    )]
    ModelVersion {
        /// The file.
        path: PathBuf,
        /// Version found in the file.
        found: String,
        /// Versions this build reads (e.g. "1.x").
        supported: String,
    },
    /// A plant ([`crate::plant::Plant`]) failed or returned what it had not declared.
    #[error("plant: {0}")]
    Plant(String),
    /// The observer of a fit ([`crate::fit::fit_episodes_observed`]) or of the learning loop
    /// ([`crate::learner::Learner::run`]) asked it to stop.
    #[error("stopped by its observer at iteration {iteration}")]
    Stopped {
        /// The solver iteration it stopped at.
        iteration: usize,
    },
}

impl MsgpError {
    /// A numerical failure (a non-finite value, a matrix not positive definite: the model
    /// cannot be fitted or rolled out there), as opposed to a setting or data error.
    pub fn is_numerical(&self) -> bool {
        matches!(
            self,
            MsgpError::NonFinite(_) | MsgpError::NotPositiveDefinite { .. }
        )
    }
}

/// Result alias for msgp-core.
pub type Result<T> = std::result::Result<T, MsgpError>;
