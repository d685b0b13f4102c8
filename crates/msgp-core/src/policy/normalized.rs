//! A policy written in original units, used inside a rollout that works in normalised units.
//!
//! Observations are de-normalised (`y = m_y + s_y ∘ y_n`, an affine map: exact) before the inner
//! policy sees them, and its inputs are normalised (`u_n = (u − m_u) / s_u`); the policy state
//! stays in original units. For `q_o = A q_n + b` and `o_n = B o_o + c` (A, B diagonal),
//! `Cov(q_n, o_n) = Cov(q_n) A C_o B`.

use nalgebra::{DMatrix, DVector};

use super::{FeedbackPolicy, PolicyMoments};
use crate::data::Normalizer;
use crate::error::Result;
use crate::scalar::{Scalar, c};

/// Wraps a policy in original units for a rollout in normalised units.
#[derive(Clone, Debug, PartialEq)]
pub struct Normalized<P> {
    /// The policy in original units.
    pub inner: P,
    /// The model's normalisation.
    pub normalizer: Normalizer,
}

impl<T: Scalar, P: FeedbackPolicy<T>> FeedbackPolicy<T> for Normalized<P> {
    fn input_dim(&self) -> usize {
        self.inner.input_dim()
    }

    fn state_dim(&self) -> usize {
        self.inner.state_dim()
    }

    fn initial_state(&self, y: &DMatrix<f64>, u: &DMatrix<f64>, t: usize) -> DVector<f64> {
        let n = &self.normalizer;
        let yo = DMatrix::from_fn(y.nrows(), y.ncols(), |r, j| n.y_to_original(j, y[(r, j)]));
        let uo = DMatrix::from_fn(u.nrows(), u.ncols(), |r, j| {
            u[(r, j)] * n.u_std[j] + n.u_mean[j]
        });
        self.inner.initial_state(&yo, &uo, t)
    }

    fn moments(&self, mean: &DVector<T>, cov: &DMatrix<T>) -> Result<PolicyMoments<T>> {
        let n = &self.normalizer;
        let dy = n.y_std.len();
        let du = self.input_dim();
        let nq = mean.len();
        let a: Vec<T> = (0..nq)
            .map(|k| c::<T>(if k < dy { n.y_std[k] } else { 1.0 }))
            .collect();
        let qm = DVector::from_fn(nq, |k, _| {
            if k < dy {
                mean[k] * a[k] + c::<T>(n.y_mean[k])
            } else {
                mean[k]
            }
        });
        let qc = DMatrix::from_fn(nq, nq, |i, j| cov[(i, j)] * a[i] * a[j]);
        let inner = self.inner.moments(&qm, &qc)?;
        let no = inner.mean.len();
        let b: Vec<T> = (0..no)
            .map(|k| c::<T>(if k < du { 1.0 / n.u_std[k] } else { 1.0 }))
            .collect();
        let om = DVector::from_fn(no, |k, _| {
            if k < du {
                (inner.mean[k] - c::<T>(n.u_mean[k])) * b[k]
            } else {
                inner.mean[k]
            }
        });
        let oc = DMatrix::from_fn(no, no, |i, j| inner.cov[(i, j)] * b[i] * b[j]);
        let cm = DMatrix::from_fn(nq, no, |i, j| a[i] * inner.c[(i, j)] * b[j]);
        Ok(PolicyMoments {
            mean: om,
            cov: oc,
            c: cm,
        })
    }
}
