//! Run logs: CSV and MCAP writers/readers, chosen by file extension, written atomically.
//!
//! Both formats hold the same per-step data ([`Sample`]); MCAP additionally stores the
//! [`EpisodeInfo`] as metadata. Layouts are documented in [`csv_file`] and [`mcap_file`]
//! and in the crate README.

pub mod csv_file;
pub mod mcap_file;
pub mod scene;

use std::path::Path;

use crate::episode::{Episode, EpisodeInfo, Sample};
use crate::error::SimError;

/// Run-log formats.
#[derive(Debug, Clone, Copy, PartialEq, Eq)]
pub enum LogFormat {
    /// Comma-separated values, one row per control step (`.csv`).
    Csv,
    /// MCAP with JSON messages (`.mcap`).
    Mcap,
}

impl LogFormat {
    /// Format from the path's extension (case-insensitive `.csv` / `.mcap`).
    pub fn from_path(path: &Path) -> Result<Self, SimError> {
        let ext = path
            .extension()
            .and_then(|e| e.to_str())
            .map(str::to_ascii_lowercase);
        match ext.as_deref() {
            Some("csv") => Ok(Self::Csv),
            Some("mcap") => Ok(Self::Mcap),
            _ => Err(SimError::UnsupportedExtension {
                path: path.to_owned(),
            }),
        }
    }
}

/// A run log read back from disk.
#[derive(Debug, Clone, PartialEq)]
pub struct RunLog {
    /// Episode setup and outcome (MCAP only; CSV files carry no metadata).
    pub info: Option<EpisodeInfo>,
    /// The samples, in step order.
    pub samples: Vec<Sample>,
}

/// Writes `episode` to `path` in the format given by its extension, atomically: the data
/// goes to a temporary file in the same directory that is renamed over `path` only once
/// complete.
pub fn write_run(path: &Path, episode: &Episode) -> Result<(), SimError> {
    match LogFormat::from_path(path)? {
        LogFormat::Csv => csv_file::write(path, &episode.samples),
        LogFormat::Mcap => mcap_file::write(path, episode),
    }
}

/// Encodes `episode` in memory in the given format (the exact bytes [`write_run`] writes).
pub fn encode_run(format: LogFormat, episode: &Episode) -> Result<Vec<u8>, SimError> {
    match format {
        LogFormat::Csv => Ok(csv_file::encode(&episode.samples)),
        LogFormat::Mcap => mcap_file::encode(episode, Path::new("<memory>")),
    }
}

/// Reads a run log written by [`write_run`], choosing the format by extension.
pub fn read_run(path: &Path) -> Result<RunLog, SimError> {
    let bytes = std::fs::read(path).map_err(|source| SimError::Io {
        action: "cannot read",
        path: path.to_owned(),
        source,
    })?;
    match LogFormat::from_path(path)? {
        LogFormat::Csv => Ok(RunLog {
            info: None,
            samples: csv_file::decode(&bytes, path)?,
        }),
        LogFormat::Mcap => mcap_file::decode(&bytes, path),
    }
}
