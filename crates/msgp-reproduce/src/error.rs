//! The crate's single error type.

use std::path::PathBuf;

/// Everything that can go wrong in a reproduction: the model's and the simulator's errors as
/// they are, a plan that cannot run, a plot or a record that cannot be written or read.
#[derive(Debug, thiserror::Error)]
pub enum ReproduceError {
    /// Fitting, simulating or scoring a model failed (as `msgp-core` says it).
    #[error(transparent)]
    Core(#[from] msgp_core::MsgpError),
    /// A learning run or its plant failed (as `msgp-sim` says it).
    #[error(transparent)]
    Sim(#[from] msgp_sim::SimError),
    /// An option of a reproduction plan is out of range.
    #[error("invalid {option}: {reason}")]
    Plan {
        /// The option (the command line's name, without dashes).
        option: String,
        /// What is wrong and what it got.
        reason: String,
    },
    /// A plot could not be drawn or written.
    #[error("cannot write the plot {path}: {message}")]
    Plot {
        /// The file concerned.
        path: PathBuf,
        /// What went wrong.
        message: String,
    },
    /// Reading or writing a file failed.
    #[error("{action} {path}")]
    Io {
        /// What was being done ("cannot write", "cannot read", ...).
        action: &'static str,
        /// The file concerned.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: std::io::Error,
    },
    /// A run's record was readable but its content is not what this crate writes.
    #[error("malformed record {path}: {reason}")]
    MalformedRecord {
        /// The file concerned.
        path: PathBuf,
        /// What is wrong with it.
        reason: String,
    },
}

/// `Result` with [`ReproduceError`].
pub type Result<T, E = ReproduceError> = std::result::Result<T, E>;
