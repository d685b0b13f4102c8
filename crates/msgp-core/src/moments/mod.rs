//! Exact moment matching of a GP with SE-ARD kernel under a Gaussian input (PILCO;
//! Deisenroth & Rasmussen 2011; paper appendix A.2, eqs. 17–22).
//!
//! For `x̃ ~ N(μ, Σ)` and one GP per output `a`, returns the mean `M_a = β_aᵀ q_a`, the full
//! output covariance `S_ab` (cross terms included) and the input–output covariance
//! `Cov(x̃, f_a)`. With `ν_i = x̄_i − μ`:
//! - `q_ai = σ_fa² |Σ Λ_a⁻¹ + I|^{-1/2} exp(−½ ν_iᵀ (Σ + Λ_a)⁻¹ ν_i)`, `Λ_a = diag(ℓ_a²)`;
//! - `Cov(x̃, f_a) = Σ (Σ + Λ_a)⁻¹ Σ_i β_ai q_ai ν_i`;
//! - `Q^{ab}_ij = E[k_a(x̃, x̄_i) k_b(x̃, x̄_j)]
//!   = k_a(x̄_i, μ) k_b(x̄_j, μ) |R|^{-1/2} exp(½ z_ijᵀ R⁻¹ Σ z_ij)`,
//!   `R = Σ(Λ_a⁻¹ + Λ_b⁻¹) + I`, `z_ij = Λ_a⁻¹ ν_i + Λ_b⁻¹ ν_j`;
//! - `S_ab = β_aᵀ Q^{ab} β_b − M_a M_b + δ_ab (σ_fa² − tr(K̃_a⁻¹ Q^{aa}))`.
//!
//! Every inverse is taken of a symmetric matrix `I + P^{½} Σ P^{½}` (P diagonal, positive), whose
//! eigenvalues are ≥ 1, so a singular `Σ` (deterministic inputs in open loop) is fine.

//!
//! Modules: [`generic`] (the reference, any scalar), `fast` (the vectorised f64 kernel behind
//! [`MomentMatch`]), `vjp` (its hand-derived vector–Jacobian product, for the adjoint sweeps),
//! [`mean`] (the linear prior mean's exact contribution), [`saturation`] (PILCO's sine
//! saturation of a Gaussian).

use nalgebra::{DMatrix, DVector};
use num_dual::DualSVec64;

use crate::error::Result;
use crate::gp::{KernelScalar, PreparedGp};
use crate::numeric::linalg::JitterLog;
use crate::numeric::scalar::Scalar;

pub(crate) mod fast;
pub mod generic;
pub mod mean;
pub mod saturation;
pub(crate) mod vjp;

pub use generic::moment_match_generic;

/// Moments of the GP output under a Gaussian input.
#[derive(Clone, Debug)]
pub struct Moments<T: Scalar> {
    /// `E[f]` (E).
    pub mean: DVector<T>,
    /// `Cov[f]` (E × E), latent: no process or observation noise.
    pub cov: DMatrix<T>,
    /// `Cov[x̃, f]` (D × E).
    pub io_cov: DMatrix<T>,
    /// `V = Σ⁻¹ Cov[x̃, f]` (D × E), computed without inverting `Σ`: for any `z` jointly
    /// Gaussian with `x̃`, `Cov[z, f] = Cov[z, x̃] V`.
    pub v: DMatrix<T>,
}

/// A scalar moment matching runs on: the generic code ([`moment_match_generic`]) by default,
/// the vectorised kernel for `f64` (equal to the generic code to rounding; `tests/fast_path.rs`).
pub trait MomentMatch: KernelScalar {
    /// Moment matching of `N(mu, sigma)` through `gp` ([`moment_match`]).
    fn moment_match(
        gp: &PreparedGp<Self>,
        mu: &DVector<Self>,
        sigma: &DMatrix<Self>,
        log: &mut JitterLog,
    ) -> Result<Moments<Self>> {
        moment_match_generic(gp, mu, sigma, log)
    }
}

impl MomentMatch for f64 {
    fn moment_match(
        gp: &PreparedGp<f64>,
        mu: &DVector<f64>,
        sigma: &DMatrix<f64>,
        log: &mut JitterLog,
    ) -> Result<Moments<f64>> {
        fast::moment_match_f64(gp, mu, sigma, log)
    }
}

impl<const N: usize> MomentMatch for DualSVec64<N> {}

/// Propagates `N(mu, sigma)` through the GP (see the module docs). Dispatches through
/// [`MomentMatch::moment_match`]: the vectorised f64 kernel for `f64`, the generic code
/// ([`moment_match_generic`]) for dual numbers.
pub fn moment_match<T: MomentMatch>(
    gp: &PreparedGp<T>,
    mu: &DVector<T>,
    sigma: &DMatrix<T>,
    log: &mut JitterLog,
) -> Result<Moments<T>> {
    T::moment_match(gp, mu, sigma, log)
}
