//! Z-scoring with training statistics; predictions are mapped back to original units.

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use crate::data::Trajectory;
use crate::error::{MsgpError, Result};

/// Per-column mean and standard deviation of inputs and outputs, from training data.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Normalizer {
    /// Input means.
    pub u_mean: Vec<f64>,
    /// Input standard deviations.
    pub u_std: Vec<f64>,
    /// Output means.
    pub y_mean: Vec<f64>,
    /// Output standard deviations.
    pub y_std: Vec<f64>,
}

fn column_stats(ms: &[&DMatrix<f64>], what: &str) -> Result<(Vec<f64>, Vec<f64>)> {
    let cols = ms.first().map_or(0, |m| m.ncols());
    let n: usize = ms.iter().map(|m| m.nrows()).sum();
    if n < 2 {
        return Err(MsgpError::Data(format!(
            "need at least 2 samples to normalise {what}"
        )));
    }
    let mut mean = vec![0.0; cols];
    let mut std = vec![0.0; cols];
    for j in 0..cols {
        let s: f64 = ms.iter().map(|m| m.column(j).sum()).sum();
        mean[j] = s / n as f64;
        let ss: f64 = ms
            .iter()
            .map(|m| {
                m.column(j)
                    .iter()
                    .map(|v| (v - mean[j]).powi(2))
                    .sum::<f64>()
            })
            .sum();
        let sd = (ss / (n - 1) as f64).sqrt();
        // a constant column is left unscaled (e.g. a constant input)
        std[j] = if sd > 0.0 && sd.is_finite() { sd } else { 1.0 };
    }
    Ok((mean, std))
}

impl Normalizer {
    /// Statistics over all training trajectories.
    pub fn fit(trajs: &[&Trajectory]) -> Result<Self> {
        let us: Vec<&DMatrix<f64>> = trajs.iter().map(|t| &t.u).collect();
        let ys: Vec<&DMatrix<f64>> = trajs.iter().map(|t| &t.y).collect();
        let (u_mean, u_std) = column_stats(&us, "inputs")?;
        let (y_mean, y_std) = column_stats(&ys, "outputs")?;
        Ok(Self {
            u_mean,
            u_std,
            y_mean,
            y_std,
        })
    }

    /// The identity map of `dy` outputs and `du` inputs (data already in model units).
    pub fn identity(dy: usize, du: usize) -> Self {
        Self {
            u_mean: vec![0.0; du],
            u_std: vec![1.0; du],
            y_mean: vec![0.0; dy],
            y_std: vec![1.0; dy],
        }
    }

    /// The same scales without the shifts (means 0): for models with a linear prior mean and
    /// no intercept, where centring would turn the data's mean command into a constant drive
    /// of the plant.
    pub fn uncentred(self) -> Self {
        Self {
            u_mean: vec![0.0; self.u_mean.len()],
            y_mean: vec![0.0; self.y_mean.len()],
            ..self
        }
    }

    /// Original → normalised units.
    pub fn apply(&self, t: &Trajectory) -> Trajectory {
        let mut u = t.u.clone();
        for j in 0..u.ncols() {
            for v in u.column_mut(j).iter_mut() {
                *v = (*v - self.u_mean[j]) / self.u_std[j];
            }
        }
        let mut y = t.y.clone();
        for j in 0..y.ncols() {
            for v in y.column_mut(j).iter_mut() {
                *v = (*v - self.y_mean[j]) / self.y_std[j];
            }
        }
        Trajectory { u, y }
    }

    /// A normalised output mean of component `j` in original units.
    pub fn y_to_original(&self, j: usize, v: f64) -> f64 {
        v * self.y_std[j] + self.y_mean[j]
    }

    /// A normalised output variance of component `j` in original units.
    pub fn y_var_to_original(&self, j: usize, v: f64) -> f64 {
        v * self.y_std[j] * self.y_std[j]
    }
}
