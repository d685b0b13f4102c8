//! CSV run logs.
//!
//! One header row, then one row per control step with these columns (SI units):
//!
//! | column | meaning |
//! |---|---|
//! | `step` | control-step index `k` |
//! | `t` | time \[s\] |
//! | `command` | issued acceleration command after clipping \[m/s²\] |
//! | `meas_theta` | measured (noisy) pole angle \[rad\] |
//! | `meas_x` | measured (noisy) end-effector position \[m\] |
//! | `latent_theta` | **latent** true pole angle \[rad\] |
//! | `latent_theta_dot` | **latent** true pole angular velocity \[rad/s\] |
//! | `latent_x` | **latent** true end-effector position \[m\] |
//! | `latent_x_dot` | **latent** true end-effector velocity \[m/s\] |
//! | `latent_lag_acceleration` | **latent** lag state = end-effector acceleration \[m/s²\] |
//! | `latent_delayed_command` | **latent** command applied during the next period \[m/s²\] |
//!
//! Columns prefixed `latent_` are never available to a controller. Floats are written in
//! Rust's shortest round-trip notation, so reading gives back the identical values.

use std::fmt::Write as _;
use std::io::Write as _;
use std::path::Path;

use crate::episode::Sample;
use crate::error::SimError;
use crate::plant::{LatentState, Measurement};

/// The header row.
pub const HEADER: &str = "step,t,command,meas_theta,meas_x,latent_theta,latent_theta_dot,latent_x,latent_x_dot,latent_lag_acceleration,latent_delayed_command";

const COLUMNS: usize = 11;

/// Encodes samples as CSV text.
pub fn encode(samples: &[Sample]) -> Vec<u8> {
    let mut out = String::with_capacity(64 + samples.len() * 200);
    out.push_str(HEADER);
    out.push('\n');
    for s in samples {
        let (m, l) = (&s.measurement, &s.latent);
        // Writing to a String cannot fail.
        let _ = writeln!(
            out,
            "{},{},{},{},{},{},{},{},{},{},{}",
            s.step,
            s.t,
            s.command,
            m.theta,
            m.x,
            l.theta,
            l.theta_dot,
            l.x,
            l.x_dot,
            l.lag_acceleration,
            l.delayed_command
        );
    }
    out.into_bytes()
}

/// Writes samples to `path` atomically.
pub fn write(path: &Path, samples: &[Sample]) -> Result<(), SimError> {
    let bytes = encode(samples);
    crate::atomic::write_atomically(path, |w| {
        w.write_all(&bytes).map_err(|source| SimError::Io {
            action: "cannot write",
            path: path.to_owned(),
            source,
        })
    })
}

/// Parses CSV text written by [`encode`]; `path` is only used in error messages.
pub fn decode(bytes: &[u8], path: &Path) -> Result<Vec<Sample>, SimError> {
    let malformed = |reason: String| SimError::MalformedLog {
        path: path.to_owned(),
        reason,
    };
    let text = std::str::from_utf8(bytes).map_err(|e| malformed(format!("not UTF-8: {e}")))?;
    let mut lines = text.lines();
    match lines.next() {
        Some(h) if h.trim_end() == HEADER => {}
        Some(h) => return Err(malformed(format!("unexpected header `{h}`"))),
        None => return Err(malformed("empty file".to_owned())),
    }
    let mut samples = Vec::new();
    for (i, line) in lines.enumerate() {
        let line_no = i + 2;
        if line.trim().is_empty() {
            continue;
        }
        let fields: Vec<&str> = line.split(',').map(str::trim).collect();
        if fields.len() != COLUMNS {
            return Err(malformed(format!(
                "line {line_no}: expected {COLUMNS} columns, found {}",
                fields.len()
            )));
        }
        let step: u64 = fields[0]
            .parse()
            .map_err(|e| malformed(format!("line {line_no}, column step: {e}")))?;
        let mut v = [0.0; COLUMNS - 1];
        for (j, field) in fields[1..].iter().enumerate() {
            v[j] = field.parse().map_err(|e| {
                malformed(format!(
                    "line {line_no}, column {}: {e}",
                    HEADER.split(',').nth(j + 1).unwrap_or("?")
                ))
            })?;
        }
        samples.push(Sample {
            step,
            t: v[0],
            command: v[1],
            measurement: Measurement {
                theta: v[2],
                x: v[3],
            },
            latent: LatentState {
                theta: v[4],
                theta_dot: v[5],
                x: v[6],
                x_dot: v[7],
                lag_acceleration: v[8],
                delayed_command: v[9],
            },
        });
    }
    Ok(samples)
}
