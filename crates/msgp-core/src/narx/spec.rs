//! The NARX (nonlinear autoregressive with exogenous input) state layout.
//!
//! The GP input at time `t` is the window
//! `x̃_t = [x_t, x_{t-1}, …, x_{t-l_y+1}, u_t, u_{t-1}, …, u_{t-l_u+1}]`
//! of the last `l_y` (latent) outputs and the last `l_u` inputs, each possibly multi-dimensional;
//! the GP predicts `x_{t+1}`. Output lags come first, newest first; then input lags, newest first.

use serde::{Deserialize, Serialize};

use crate::error::{MsgpError, Result};

/// History lengths and signal dimensions of a NARX model.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct NarxSpec {
    /// `l_y`: number of past outputs in the window (≥ 1).
    pub ly: usize,
    /// `l_u`: number of past inputs in the window (0 for an autonomous system).
    pub lu: usize,
    /// Output dimension (one GP per output).
    pub dy: usize,
    /// Input dimension.
    pub du: usize,
}

impl NarxSpec {
    /// Single-input single-output spec.
    pub fn siso(ly: usize, lu: usize) -> Self {
        Self {
            ly,
            lu,
            dy: 1,
            du: 1,
        }
    }

    /// Checks the spec.
    pub fn validate(&self) -> Result<()> {
        if self.ly == 0 {
            return Err(MsgpError::InvalidSetting {
                name: "history l_y",
                reason: "must be at least 1".into(),
            });
        }
        if self.dy == 0 {
            return Err(MsgpError::InvalidSetting {
                name: "output dimension",
                reason: "must be at least 1".into(),
            });
        }
        if self.lu > 0 && self.du == 0 {
            return Err(MsgpError::InvalidSetting {
                name: "history l_u",
                reason: "input lags need an input dimension ≥ 1".into(),
            });
        }
        Ok(())
    }

    /// Dimension `D = l_y·d_y + l_u·d_u` of the GP input.
    pub fn input_dim(&self) -> usize {
        self.ly * self.dy + self.lu * self.du
    }

    /// Number of leading samples that seed a free simulation: `max(l_y, l_u)`.
    pub fn warmup(&self) -> usize {
        self.ly.max(self.lu)
    }

    /// Window index of output component `j` at lag `k` (k = 0 is the newest).
    pub fn y_index(&self, k: usize, j: usize) -> usize {
        k * self.dy + j
    }

    /// Window index of input component `j` at lag `k` (k = 0 is the newest).
    pub fn u_index(&self, k: usize, j: usize) -> usize {
        self.ly * self.dy + k * self.du + j
    }

    /// The window shift as a gather map: entry `i` of `x̃_{t+1}` is entry `shift_map()[i]` of the
    /// augmented vector `[x̃_t (D), x_{t+1} (d_y), u_{t+1} (d_u)]`.
    pub fn shift_map(&self) -> Vec<usize> {
        let d = self.input_dim();
        let mut sel = vec![0usize; d];
        for j in 0..self.dy {
            sel[self.y_index(0, j)] = d + j;
        }
        for k in 1..self.ly {
            for j in 0..self.dy {
                sel[self.y_index(k, j)] = self.y_index(k - 1, j);
            }
        }
        if self.lu > 0 {
            for j in 0..self.du {
                sel[self.u_index(0, j)] = d + self.dy + j;
            }
            for k in 1..self.lu {
                for j in 0..self.du {
                    sel[self.u_index(k, j)] = self.u_index(k - 1, j);
                }
            }
        }
        sel
    }

    /// The window at time `t` built from measured data (rows are time steps).
    /// Needs `t + 1 ≥ warmup()`.
    pub fn window(
        &self,
        y: &nalgebra::DMatrix<f64>,
        u: &nalgebra::DMatrix<f64>,
        t: usize,
    ) -> Vec<f64> {
        let mut w = vec![0.0; self.input_dim()];
        for k in 0..self.ly {
            for j in 0..self.dy {
                w[self.y_index(k, j)] = y[(t - k, j)];
            }
        }
        for k in 0..self.lu {
            for j in 0..self.du {
                w[self.u_index(k, j)] = u[(t - k, j)];
            }
        }
        w
    }
}
