//! Input/output trajectories (rows are time steps).

use nalgebra::DMatrix;

use crate::error::{MsgpError, Result};
use crate::narx::NarxSpec;

/// One measured trajectory: `u` is T × d_u, `y` is T × d_y.
#[derive(Clone, Debug, PartialEq)]
pub struct Trajectory {
    /// Inputs.
    pub u: DMatrix<f64>,
    /// Outputs.
    pub y: DMatrix<f64>,
}

impl Trajectory {
    /// Builds a trajectory, checking lengths and finiteness.
    pub fn new(u: DMatrix<f64>, y: DMatrix<f64>) -> Result<Self> {
        if u.nrows() != y.nrows() {
            return Err(MsgpError::Data(format!(
                "inputs have {} samples but outputs have {}",
                u.nrows(),
                y.nrows()
            )));
        }
        for (name, m) in [("input", &u), ("output", &y)] {
            if let Some(pos) = m.iter().position(|v| !v.is_finite()) {
                let (r, c) = (pos % m.nrows(), pos / m.nrows());
                return Err(MsgpError::Data(format!(
                    "non-finite {name} at sample {r}, column {c}"
                )));
            }
        }
        Ok(Self { u, y })
    }

    /// Single-input single-output trajectory from slices.
    pub fn siso(u: &[f64], y: &[f64]) -> Result<Self> {
        Self::new(
            DMatrix::from_column_slice(u.len(), 1, u),
            DMatrix::from_column_slice(y.len(), 1, y),
        )
    }

    /// Number of samples.
    pub fn len(&self) -> usize {
        self.y.nrows()
    }

    /// True when empty.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// Checks that the trajectory fits `spec` and is long enough to predict at least one step.
    pub fn check(&self, spec: &NarxSpec) -> Result<()> {
        if self.u.ncols() != spec.du || self.y.ncols() != spec.dy {
            return Err(MsgpError::Shape(format!(
                "trajectory has {} inputs and {} outputs, the model has {} and {}",
                self.u.ncols(),
                self.y.ncols(),
                spec.du,
                spec.dy
            )));
        }
        if self.len() <= spec.warmup() {
            return Err(MsgpError::Data(format!(
                "trajectory has {} samples; history (l_y={}, l_u={}) needs more than {}",
                self.len(),
                spec.ly,
                spec.lu,
                spec.warmup()
            )));
        }
        Ok(())
    }

    /// Rows `start..end`.
    pub fn slice(&self, start: usize, end: usize) -> Self {
        Self {
            u: self.u.rows(start, end - start).into_owned(),
            y: self.y.rows(start, end - start).into_owned(),
        }
    }
}
