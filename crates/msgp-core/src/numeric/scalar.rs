//! The scalar every numerical routine is generic over.
//!
//! Kernel, GP prediction, moment matching, rollouts and losses are written once, generic over
//! [`Scalar`]. They run on `f64` and on forward-mode vector dual numbers
//! ([`num_dual::DualSVec64`]), which carry `N` directional derivatives at once; the real part of
//! a dual run is the f64 run (the same operations in the same order).
//!
//! This trait is arithmetic only. The f64 fast paths hang off the traits of the layers that own
//! them: [`crate::gp::KernelScalar`] (kernel matrices, SPD inverses) and
//! [`crate::moments::MomentMatch`] (moment matching).

use nalgebra::RealField;
use num_dual::DualSVec64;

/// A real scalar the numerics can run on: `f64` or a forward-mode dual number.
pub trait Scalar: RealField + Copy + Send + Sync {
    /// Lift a constant.
    fn lift(v: f64) -> Self;
    /// The real (value) part.
    fn re(&self) -> f64;
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
