//! The linear prior mean `m(x̃) = A x̃` (see [`crate::gp::MeanFunction`]) in moment matching.
//!
//! With `f = A x̃ + g(x̃)`, `x̃ ~ N(μ, Σ)` and the GP's moments `M = E[g]`, `S = Cov[g]`,
//! `V = Σ⁻¹ Cov[x̃, g]`, the moments of `f` are exact:
//! `E[f] = M + Aμ`, `Cov[x̃, f] = Σ (V + Aᵀ)` (so `V' = V + Aᵀ`) and
//! `Cov[f] = S + AΣAᵀ + AΣV + (AΣV)ᵀ`.

use nalgebra::{DMatrix, DVector};

use crate::moments::Moments;
use crate::numeric::linalg::symmetrize;
use crate::numeric::scalar::Scalar;

/// Adds the linear mean `a` (E × D) to the GP's moments at `N(mu, sigma)`.
pub fn add_linear_mean<T: Scalar>(
    a: &DMatrix<T>,
    mu: &DVector<T>,
    sigma: &DMatrix<T>,
    mm: &mut Moments<T>,
) {
    mm.mean += a * mu;
    let a_sigma = a * sigma; // E × D
    let cross = &a_sigma * &mm.v; // AΣV, E × E
    let mut cov = &mm.cov + &a_sigma * a.transpose() + &cross + cross.transpose();
    symmetrize(&mut cov);
    mm.cov = cov;
    mm.io_cov += a_sigma.transpose();
    mm.v += a.transpose();
}

/// Adjoints of the linear-mean step, in f64 (for the adjoint sweeps, `crate::rollout::adjoint`).
pub(crate) struct LinearMeanBar {
    /// `μ̄` contribution (D).
    pub mu: DVector<f64>,
    /// `Σ̄` contribution (D × D, symmetric).
    pub sigma: DMatrix<f64>,
    /// `Ā` contribution (E × D).
    pub a: DMatrix<f64>,
    /// `V̄` of the GP's own `V` (D × E).
    pub v: DMatrix<f64>,
}

/// Pulls `M̄'`, `S̄'`, `V̄'` (adjoints of the moments *with* the mean) back to `μ`, `Σ`, `A` and
/// the GP's `V` (`v` is the GP's `V`, before the mean was added). `M̄` and `S̄` of the GP's
/// moments are `M̄'` and `S̄'` unchanged.
pub(crate) fn linear_mean_backward(
    a: &DMatrix<f64>,
    mu: &DVector<f64>,
    sigma: &DMatrix<f64>,
    v: &DMatrix<f64>,
    mbar: &DVector<f64>,
    sbar: &DMatrix<f64>,
    vbar: &DMatrix<f64>,
) -> LinearMeanBar {
    let ssym = sbar + sbar.transpose(); // E × E
    let a_sigma = a * sigma; // E × D
    // E[f]: M + Aμ
    let mu_bar = a.transpose() * mbar;
    let mut a_bar = mbar * mu.transpose();
    // V' = V + Aᵀ
    a_bar += vbar.transpose();
    // AΣAᵀ: Ā += (S̄ + S̄ᵀ) A Σ, Σ̄ += Aᵀ S̄ A
    a_bar += &ssym * &a_sigma;
    let mut sigma_bar = a.transpose() * sbar * a;
    // AΣV + (AΣV)ᵀ: Ā += Ssym Vᵀ Σ, Σ̄ += Aᵀ Ssym Vᵀ, V̄ += Σ Aᵀ Ssym
    a_bar += &ssym * v.transpose() * sigma;
    sigma_bar += a.transpose() * &ssym * v.transpose();
    let v_bar = vbar + a_sigma.transpose() * &ssym;
    let sigma_sym = (&sigma_bar + sigma_bar.transpose()) * 0.5;
    LinearMeanBar {
        mu: mu_bar,
        sigma: sigma_sym,
        a: a_bar,
        v: v_bar,
    }
}
