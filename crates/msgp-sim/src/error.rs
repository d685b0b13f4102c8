//! The crate's single error type.

use std::path::PathBuf;

/// Everything that can go wrong in `msgp-sim`: invalid user input, file I/O and log formats.
///
/// The library never panics on user input; every check ends in one of these variants.
/// Wrapped errors are exposed through [`std::error::Error::source`] (not repeated in the
/// message), so print the whole chain, e.g. with anyhow's `{:#}`.
#[derive(Debug, thiserror::Error)]
pub enum SimError {
    /// Model learning or policy search failed.
    #[error("model")]
    Model(#[from] msgp_core::MsgpError),
    /// A plant parameter, controller gain or episode setting is out of range.
    #[error("invalid {name} = {value}: {reason}")]
    InvalidParameter {
        /// Name of the offending field (as in the params struct / JSON file).
        name: &'static str,
        /// The rejected value.
        value: f64,
        /// What a valid value looks like.
        reason: &'static str,
    },
    /// A controller returned a NaN or infinite command.
    #[error("controller `{controller}` produced a non-finite command {value} at t = {t} s")]
    NonFiniteCommand {
        /// Description of the controller.
        controller: String,
        /// The produced value.
        value: f64,
        /// Simulation time of the control step.
        t: f64,
    },
    /// The physics state became non-finite (should not happen for validated parameters).
    #[error("physics state became non-finite at t = {t} s")]
    NonFiniteState {
        /// Simulation time at which it was detected.
        t: f64,
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
    /// A JSON document (policy file, MCAP message or metadata) could not be parsed or written.
    #[error("bad JSON in {context}")]
    Json {
        /// Where the JSON came from.
        context: String,
        /// The underlying error.
        #[source]
        source: serde_json::Error,
    },
    /// The MCAP library reported an error.
    #[error("MCAP error in {path}")]
    Mcap {
        /// The file concerned.
        path: PathBuf,
        /// The underlying error.
        #[source]
        source: mcap::McapError,
    },
    /// A Foxglove scene message could not be encoded (a schema missing from the `foxglove`
    /// crate or a protobuf encoding failure: a bug, reported rather than written half).
    #[error("cannot encode the Foxglove {what} for {path}: {message}")]
    Scene {
        /// The file concerned.
        path: PathBuf,
        /// Which message.
        what: &'static str,
        /// What went wrong.
        message: String,
    },
    /// An option of a learning run's budget or of a reproduction plan is out of range.
    #[error("invalid {option}: {reason}")]
    Budget {
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
    /// The observer of [`crate::learn::learn_policy_observed`] asked the loop to stop.
    #[error("policy learning stopped by its observer at iteration {iteration}")]
    Stopped {
        /// The policy iteration it stopped in.
        iteration: usize,
    },
    /// A run log's file name ends in neither `.csv` nor `.mcap`.
    #[error("unsupported run-log extension for {path} (expected .csv or .mcap)")]
    UnsupportedExtension {
        /// The offending path.
        path: PathBuf,
    },
    /// A run log was readable but its content is not what this crate writes.
    #[error("malformed run log {path}: {reason}")]
    MalformedLog {
        /// The file concerned.
        path: PathBuf,
        /// What is wrong with it.
        reason: String,
    },
}

impl SimError {
    /// Shorthand for [`SimError::InvalidParameter`].
    pub(crate) fn invalid(name: &'static str, value: f64, reason: &'static str) -> Self {
        Self::InvalidParameter {
            name,
            value,
            reason,
        }
    }
}

/// Checks that `value` is finite and strictly positive.
pub(crate) fn require_positive(name: &'static str, value: f64) -> Result<(), SimError> {
    if value.is_finite() && value > 0.0 {
        Ok(())
    } else {
        Err(SimError::invalid(name, value, "must be finite and > 0"))
    }
}

/// Checks that `value` is finite and non-negative.
pub(crate) fn require_non_negative(name: &'static str, value: f64) -> Result<(), SimError> {
    if value.is_finite() && value >= 0.0 {
        Ok(())
    } else {
        Err(SimError::invalid(name, value, "must be finite and >= 0"))
    }
}

/// Checks that `value` is finite.
pub(crate) fn require_finite(name: &'static str, value: f64) -> Result<(), SimError> {
    if value.is_finite() {
        Ok(())
    } else {
        Err(SimError::invalid(name, value, "must be finite"))
    }
}
