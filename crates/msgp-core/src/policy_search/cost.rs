//! The expected saturating cost of PILCO: `c(y) = 1 − exp(−½ (y − y*)ᵀ W (y − y*))` under a
//! Gaussian `y ~ N(m, S)`, in closed form, with its variance for reporting.
//!
//! `W = AᵀA` is given through `A` (k × d_y), so a positive *semi*-definite weight (an output that
//! does not count) needs no special case: with `z = A(y − y*) ~ N(μ_z, Σ_z)`,
//! `E[exp(−½|z|²)] = |I + Σ_z|^{-½} exp(−½ μ_zᵀ (I + Σ_z)⁻¹ μ_z)` and
//! `E[exp(−|z|²)] = |I + 2Σ_z|^{-½} exp(−μ_zᵀ (I + 2Σ_z)⁻¹ μ_z)`.

use nalgebra::{DMatrix, DVector};

use crate::error::{MsgpError, Result};
use crate::numeric::linalg::{JitterLog, JitterPolicy, cholesky};
use crate::numeric::scalar::{Scalar, c};

/// A saturating cost around a target.
#[derive(Clone, Debug, PartialEq)]
pub struct SaturatingCost {
    /// `y*`.
    pub target: DVector<f64>,
    /// `A` with `W = AᵀA` (k × d_y).
    pub a: DMatrix<f64>,
}

/// Mean and variance of the cost under a Gaussian.
#[derive(Clone, Copy, Debug)]
pub struct CostMoments<T: Scalar> {
    /// `E[c(y)]`.
    pub mean: T,
    /// `Var[c(y)]`.
    pub var: T,
}

impl SaturatingCost {
    /// `W = diag(1/width²)`: each output counts on the scale `width` (∞ or 0 width: see below).
    /// A width of `f64::INFINITY` removes that output from the cost.
    pub fn with_widths(target: DVector<f64>, widths: &[f64]) -> Result<Self> {
        if widths.len() != target.len() || widths.iter().any(|w| w.is_nan() || *w <= 0.0) {
            return Err(MsgpError::InvalidSetting {
                name: "cost widths",
                reason: format!("need {} positive widths, got {widths:?}", target.len()),
            });
        }
        let n = widths.len();
        let a = DMatrix::from_fn(n, n, |i, j| if i == j { 1.0 / widths[i] } else { 0.0 });
        Ok(Self { target, a })
    }

    /// The cost at a point.
    pub fn at(&self, y: &[f64]) -> f64 {
        let d = DVector::from_fn(y.len(), |i, _| y[i] - self.target[i]);
        let z = &self.a * d;
        1.0 - (-0.5 * z.norm_squared()).exp()
    }

    /// `E[c]` and `Var[c]` for `y ~ N(mean, cov)`.
    pub fn moments<T: Scalar>(
        &self,
        mean: &DVector<T>,
        cov: &DMatrix<T>,
        jitter: &JitterPolicy,
        log: &mut JitterLog,
    ) -> Result<CostMoments<T>> {
        let a = self.a.map(c::<T>);
        let mu = &a * DVector::from_fn(mean.len(), |i, _| mean[i] - c::<T>(self.target[i]));
        let sz = &a * cov * a.transpose();
        let k = mu.len();
        let mut gauss = |scale: f64| -> Result<T> {
            let m = DMatrix::<T>::identity(k, k) + &sz * c::<T>(scale);
            let ch = cholesky(&m, jitter, "I + A S Aᵀ")?;
            log.record(ch.jitter);
            let sol = ch.solve_vec(&mu);
            Ok((-(ch.log_det() + mu.dot(&sol) * c::<T>(scale)) * c::<T>(0.5)).exp())
        };
        let e1 = gauss(1.0)?;
        let e2 = gauss(2.0)?;
        Ok(CostMoments {
            mean: T::one() - e1,
            var: e2 - e1 * e1,
        })
    }
}
