//! Dense f64 factorisations through faer, for the large one-step GP matrices (N ≈ 500–1000)
//! where faer's blocked Cholesky pays. Same jitter policy as [`crate::numeric::linalg`].

use faer::Side;
use faer::linalg::solvers::{DenseSolveCore, Solve};
use nalgebra::DMatrix;

use crate::error::{MsgpError, Result};
use crate::numeric::linalg::{JitterLog, JitterPolicy};

/// A faer Cholesky factorisation of an SPD matrix, with the jitter that was needed.
#[derive(Debug)]
pub struct DenseChol {
    llt: faer::linalg::solvers::Llt<f64>,
    n: usize,
    /// Absolute jitter added to the diagonal.
    pub jitter: f64,
}

fn to_faer(a: &DMatrix<f64>, jitter: f64) -> faer::Mat<f64> {
    faer::Mat::from_fn(a.nrows(), a.ncols(), |i, j| {
        a[(i, j)] + if i == j { jitter } else { 0.0 }
    })
}

fn to_na(m: faer::MatRef<'_, f64>) -> DMatrix<f64> {
    DMatrix::from_fn(m.nrows(), m.ncols(), |i, j| m[(i, j)])
}

impl DenseChol {
    /// Factorises `a` (symmetric), adding recorded jitter if needed.
    pub fn new(
        a: &DMatrix<f64>,
        policy: &JitterPolicy,
        what: &str,
        log: &mut JitterLog,
    ) -> Result<Self> {
        let n = a.nrows();
        if let Ok(llt) = to_faer(a, 0.0).llt(Side::Lower) {
            return Ok(Self {
                llt,
                n,
                jitter: 0.0,
            });
        }
        let mean_diag = (0..n).map(|i| a[(i, i)].abs()).sum::<f64>() / n.max(1) as f64;
        let scale = if mean_diag > 0.0 && mean_diag.is_finite() {
            mean_diag
        } else {
            1.0
        };
        let mut rel = policy.initial_relative;
        while rel <= policy.max_relative * (1.0 + 1e-12) {
            if let Ok(llt) = to_faer(a, rel * scale).llt(Side::Lower) {
                log.record(rel * scale);
                return Ok(Self {
                    llt,
                    n,
                    jitter: rel * scale,
                });
            }
            rel *= policy.growth.max(1.001);
        }
        Err(MsgpError::NotPositiveDefinite {
            what: what.to_string(),
            pivot: 0,
            value: f64::NAN,
            jitter: policy.max_relative * scale,
        })
    }

    /// `A⁻¹`.
    pub fn inverse(&self) -> DMatrix<f64> {
        to_na(self.llt.inverse().as_ref())
    }

    /// `A⁻¹ B`.
    pub fn solve(&self, b: &DMatrix<f64>) -> DMatrix<f64> {
        let rhs = to_faer(b, 0.0);
        to_na(self.llt.solve(&rhs).as_ref())
    }

    /// `log |A|`.
    pub fn log_det(&self) -> f64 {
        let l = self.llt.L();
        (0..self.n).map(|i| l[(i, i)].ln()).sum::<f64>() * 2.0
    }
}
