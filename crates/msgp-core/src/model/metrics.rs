//! How a free simulation is scored against measured outputs: RMSE, mean NLL per step and the
//! fraction of measurements inside the ±2σ band, in original units; pooled over several
//! simulations by step count.

use std::ops::Range;

use serde::{Deserialize, Serialize};

use super::Simulation;
use crate::data::Trajectory;
use crate::error::{MsgpError, Result};

/// Free-simulation metrics in original units.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    /// Root mean squared error of the predicted mean.
    pub rmse: f64,
    /// Mean negative log predictive density per step (per output dimension summed).
    pub nll: f64,
    /// Fraction of measured outputs inside mean ± 2σ.
    pub coverage_2sigma: f64,
    /// Number of evaluated steps.
    pub steps: usize,
}

/// RMSE, mean NLL and 2σ coverage of a simulation against measured outputs (all outputs
/// pooled).
pub fn score(sim: &Simulation, traj: &Trajectory) -> Result<Metrics> {
    score_columns(sim, traj, 0..sim.mean.ncols())
}

/// [`score`] of output `j` alone (what a plot of that output shows).
pub fn score_output(sim: &Simulation, traj: &Trajectory, j: usize) -> Result<Metrics> {
    if j >= sim.mean.ncols() {
        return Err(MsgpError::Shape(format!(
            "output {j} of a simulation of {} outputs",
            sim.mean.ncols()
        )));
    }
    score_columns(sim, traj, j..j + 1)
}

fn score_columns(sim: &Simulation, traj: &Trajectory, cols: Range<usize>) -> Result<Metrics> {
    let n = sim.mean.nrows();
    let dy = cols.len();
    if n == 0 || sim.start + n > traj.len() || cols.end > traj.y.ncols() {
        return Err(MsgpError::Data(
            "simulation does not fit the measured trajectory".into(),
        ));
    }
    let mut se = 0.0;
    let mut nll = 0.0;
    let mut inside = 0usize;
    for i in 0..n {
        for j in cols.clone() {
            let y = traj.y[(sim.start + i, j)];
            let (m, v) = (sim.mean[(i, j)], sim.var[(i, j)].max(f64::MIN_POSITIVE));
            let r = y - m;
            se += r * r;
            nll += 0.5 * (r * r / v + v.ln() + (2.0 * std::f64::consts::PI).ln());
            if r.abs() <= 2.0 * v.sqrt() {
                inside += 1;
            }
        }
    }
    Ok(Metrics {
        rmse: (se / (n * dy) as f64).sqrt(),
        nll: nll / n as f64,
        coverage_2sigma: inside as f64 / (n * dy) as f64,
        steps: n,
    })
}

/// Metrics of several simulations pooled over all steps.
pub fn pool(metrics: &[Metrics], dy: usize) -> Option<Metrics> {
    let steps: usize = metrics.iter().map(|m| m.steps).sum();
    if steps == 0 {
        return None;
    }
    let w = |m: &Metrics| m.steps as f64;
    let n = steps as f64;
    let se: f64 = metrics
        .iter()
        .map(|m| m.rmse * m.rmse * w(m) * dy as f64)
        .sum();
    Some(Metrics {
        rmse: if metrics.len() == 1 {
            metrics[0].rmse
        } else {
            (se / (n * dy as f64)).sqrt()
        },
        nll: if metrics.len() == 1 {
            metrics[0].nll
        } else {
            metrics.iter().map(|m| m.nll * w(m)).sum::<f64>() / n
        },
        coverage_2sigma: if metrics.len() == 1 {
            metrics[0].coverage_2sigma
        } else {
            metrics
                .iter()
                .map(|m| m.coverage_2sigma * w(m))
                .sum::<f64>()
                / n
        },
        steps,
    })
}
