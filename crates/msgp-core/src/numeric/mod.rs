//! The numerical floor every model layer stands on: the [`Scalar`] the generic
//! code runs on (f64 or forward-mode duals), robust Cholesky factorisations with a recorded
//! jitter policy ([`linalg`], and [`dense`] for the large one-step matrices), the dual-number
//! gradient machinery ([`dual`]), the f64 SIMD building blocks of the fast kernels (`simd`,
//! crate-private), deterministic fan-out over threads ([`parallel`]) and independent seeded
//! random streams ([`seed`]), and infinity in JSON ([`infinite_as_null`]).
//!
//! Nothing here knows about GPs, windows or trajectories.

pub mod dense;
pub mod dual;
pub mod infinite_as_null;
pub mod linalg;
pub mod parallel;
pub mod scalar;
pub mod seed;
pub(crate) mod simd;

pub use scalar::{Scalar, c};
