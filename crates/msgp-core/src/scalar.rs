//! One scalar abstraction for every numerical routine.
//!
//! Kernel, GP prediction, moment matching, rollouts and losses are written once, generic over
//! [`Scalar`]. They run on `f64` and on forward-mode vector dual numbers
//! ([`num_dual::DualSVec64`]), which carry `N` directional derivatives at once; the real part of
//! a dual run is the f64 run (the same operations in the same order).

use nalgebra::{DMatrix, DVector, RealField};
use num_dual::DualSVec64;

use crate::error::Result;
use crate::gp::PreparedGp;
use crate::linalg::{Cholesky, JitterLog};
use crate::moments::Moments;

/// A real scalar the numerics can run on: `f64` or a forward-mode dual number.
pub trait Scalar: RealField + Copy + Send + Sync {
    /// Lift a constant.
    fn lift(v: f64) -> Self;
    /// The real (value) part.
    fn re(&self) -> f64;

    /// Moment matching of `N(mu, sigma)` through `gp` ([`crate::moments::moment_match`]).
    /// The default is the generic reference implementation
    /// ([`crate::moments::moment_match_generic`]); `f64` overrides it with a vectorised kernel
    /// that computes the same quantities (equal to rounding).
    fn moment_match(
        gp: &PreparedGp<Self>,
        mu: &DVector<Self>,
        sigma: &DMatrix<Self>,
        log: &mut JitterLog,
    ) -> Result<Moments<Self>> {
        crate::moments::moment_match_generic(gp, mu, sigma, log)
    }

    /// `A⁻¹` from `A`'s Cholesky factor ([`Cholesky::inverse`]); f64 overrides it with the
    /// vectorised row solves of the fast kernels.
    fn spd_inverse(chol: &Cholesky<Self>) -> DMatrix<Self> {
        chol.inverse()
    }

    /// What the f64 moment-matching kernel needs of a diagonal output pair, prepared once per
    /// loss ([`crate::gp::OutputGp::q_weights`]); nothing for other scalars.
    fn q_weights(_beta: &DVector<Self>, _kinv: &DMatrix<Self>) -> Vec<Self> {
        Vec::new()
    }

    /// The SE-ARD kernel matrix ([`crate::kernel::kernel_matrix`]).
    fn kernel_matrix(
        a: &DMatrix<Self>,
        b: &DMatrix<Self>,
        inv_l2: &[Self],
        sf2: Self,
    ) -> DMatrix<Self> {
        crate::kernel::kernel_matrix_generic(a, b, inv_l2, sf2)
    }
}

impl Scalar for f64 {
    #[inline]
    fn lift(v: f64) -> Self {
        v
    }
    #[inline]
    fn re(&self) -> f64 {
        *self
    }
    fn moment_match(
        gp: &PreparedGp<f64>,
        mu: &DVector<f64>,
        sigma: &DMatrix<f64>,
        log: &mut JitterLog,
    ) -> Result<Moments<f64>> {
        crate::mm_f64::moment_match_f64(gp, mu, sigma, log)
    }
    fn spd_inverse(chol: &Cholesky<f64>) -> DMatrix<f64> {
        crate::simd::spd_inverse(&chol.l)
    }

    fn q_weights(beta: &DVector<f64>, kinv: &DMatrix<f64>) -> Vec<f64> {
        crate::mm_f64::sym_weights(beta, kinv)
    }

    fn kernel_matrix(a: &DMatrix<f64>, b: &DMatrix<f64>, inv_l2: &[f64], sf2: f64) -> DMatrix<f64> {
        crate::simd::kernel_matrix(a, b, inv_l2, sf2)
    }
}

impl<const N: usize> Scalar for DualSVec64<N> {
    #[inline]
    fn lift(v: f64) -> Self {
        DualSVec64::from_re(v)
    }
    #[inline]
    fn re(&self) -> f64 {
        self.re
    }
}

/// Shorthand for a constant in generic code.
#[inline]
pub fn c<T: Scalar>(v: f64) -> T {
    T::lift(v)
}
