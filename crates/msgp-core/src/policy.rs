//! Feedback policies `u = π(y; θ_π)` inside a moment-matching rollout (paper eq. 10).
//!
//! A policy receives the Gaussian of the current *observation* `y_t ~ N(m, S)` and returns the
//! moments of `u_t`: its mean, covariance and the matrix `C` with `Cov(y_t, u_t) = S C`.
//! The rollout then sets `Cov(z, u_t) = Cov(z, y_t) C` for every other state entry `z`, which is
//! exact for linear policies and PILCO's moment-matching approximation for nonlinear ones
//! (saturated policies implement this same trait).

use nalgebra::{DMatrix, DVector};

use crate::error::{MsgpError, Result};
use crate::scalar::Scalar;

/// Moments of a policy output.
#[derive(Clone, Debug)]
pub struct PolicyMoments<T: Scalar> {
    /// `E[u]` (d_u).
    pub mean: DVector<T>,
    /// `Cov[u]` (d_u × d_u).
    pub cov: DMatrix<T>,
    /// `C` (d_y × d_u) with `Cov(y, u) = Cov(y) C`.
    pub c: DMatrix<T>,
}

/// A feedback policy usable in closed-loop rollouts.
pub trait FeedbackPolicy<T: Scalar>: Send + Sync {
    /// Number of inputs it produces.
    fn input_dim(&self) -> usize;
    /// Moments of `u = π(y)` for `y ~ N(mean, cov)`.
    fn moments(&self, mean: &DVector<T>, cov: &DMatrix<T>) -> Result<PolicyMoments<T>>;
}

/// `u = K y + b`; moments are exact.
#[derive(Clone, Debug, PartialEq)]
pub struct LinearPolicy<T: Scalar> {
    /// `K` (d_u × d_y).
    pub gain: DMatrix<T>,
    /// `b` (d_u).
    pub offset: DVector<T>,
}

impl<T: Scalar> LinearPolicy<T> {
    /// Checks shapes.
    pub fn new(gain: DMatrix<T>, offset: DVector<T>) -> Result<Self> {
        if gain.nrows() != offset.len() {
            return Err(MsgpError::Shape(format!(
                "linear policy gain has {} rows but offset has {} entries",
                gain.nrows(),
                offset.len()
            )));
        }
        Ok(Self { gain, offset })
    }

    /// Converts the scalar type.
    pub fn map<U: Scalar>(&self, f: impl Fn(T) -> U + Copy) -> LinearPolicy<U> {
        LinearPolicy {
            gain: self.gain.map(f),
            offset: self.offset.map(f),
        }
    }
}

impl<T: Scalar> FeedbackPolicy<T> for LinearPolicy<T> {
    fn input_dim(&self) -> usize {
        self.gain.nrows()
    }

    fn moments(&self, mean: &DVector<T>, cov: &DMatrix<T>) -> Result<PolicyMoments<T>> {
        if mean.len() != self.gain.ncols() {
            return Err(MsgpError::Shape(format!(
                "linear policy expects {} observations, got {}",
                self.gain.ncols(),
                mean.len()
            )));
        }
        Ok(PolicyMoments {
            mean: &self.gain * mean + &self.offset,
            cov: &self.gain * cov * self.gain.transpose(),
            c: self.gain.transpose(),
        })
    }
}
