//! The GP's uncertainty about its own function, kept correlated over a free simulation.
//!
//! Moment matching (paper section 3.3, [`super::forward`]) draws the latent function afresh at
//! every step: the GP's uncertainty about `f` at the window enters each step's variance as if
//! it were fresh process noise. A real model is *one* function, wrong in the same way every time
//! it visits the same region. Under an input that dwells (a held level, a slow sine) the same
//! error repeats and is summed by the plant's dynamics: with a static gain of 10 the mean's
//! error is 10× the function's, while independent draws grow the standard deviation by only
//! `√(Σ_k g_k²)` (about 2.9× for the same plant). Coverage on such inputs then collapses although
//! the model is as good as its data allow (synthetic system 4's steps in the generalisation
//! table: 2σ coverage 0.44–0.82).
//!
//! The fitted GP is the posterior given its pseudo-data `(X̄, ȳ)` with noise `σ_x²`. Its
//! function's posterior deviation is represented at the pseudo-inputs: `δu ~ N(0, K − K K̃⁻¹ K)`
//! (`K = K(X̄, X̄)`, `K̃ = K + σ_x² I`), that is pseudo-targets moved by `δȳ = K̃ K⁻¹ δu =
//! B ξ`, `ξ ~ N(0, I)`, `B = V diag(√(σ_x² (λ+σ_x²)/λ))` from `K = V diag(λ) Vᵀ` (directions
//! with `λ < 10⁻⁹ λ_max` carry no variance the kernel can express and are left out). With the
//! linear prior mean, its coefficients are uncertain too: under a flat-ish prior (variance
//! 100 per coefficient, normalised units) the pseudo-data give `Cov(A_a) = (X̄ᵀ K̃⁻¹ X̄ +
//! 10⁻² I)⁻¹` (Rasmussen & Williams §2.7), drawn as `δA_a = L_a ζ` with the residual targets
//! moved by `−X̄ δA_aᵀ`.
//!
//! Each drawn function gives a rollout mean `μ_t(ξ, ζ)`; its first-order spread is carried
//! forward exactly, with the window's covariance held at the moment-matching values:
//! `∂M_a/∂μ = V_a` (the moments' `Σ⁻¹ Cov[x̃, f]`, by Stein's lemma `E[∇f]`), `∂M_a/∂ȳ_a =
//! K̃_a⁻¹ q_a` (`q_a` the expected kernel vector of moment matching) and `∂M_a/∂A_a = μᵀ`.
//! The window's tangent `T` (D × directions) shifts with the window; inputs, measured, have
//! none. Moment matching has already counted each step's own function variance once, as
//! independent noise: the same linear recursion with independent injections (the pseudo-target
//! part of each step's direct term, propagated with no correlation) is subtracted, so
//! what is added to `Var[y_t]` is `max(0, ‖T_y‖² − P_y)`: the part the correlation adds, and
//! the linear mean's uncertainty, which moment matching does not have. On a white-noise input
//! the two nearly cancel; on a held input the correlated sum dominates.
//!
//! It widens the reported outputs of open-loop free simulations only, and is never fed back:
//! no mean moves, so no RMSE does; the training loss, filtered predictions and closed-loop
//! rollouts (policy search) keep the paper's moment matching. [`crate::model::Rollout`]
//! `MomentMatchingIndependent` simulates without it.

use nalgebra::{DMatrix, DVector};

use super::forward::{Control, StepPrediction, Widen, rollout_widened};
use crate::data::Trajectory;
use crate::error::{MsgpError, Result};
use crate::gp::PreparedGp;
use crate::gp::kernel::kernel_matrix;
use crate::moments::Moments;
use crate::narx::NarxSpec;
use crate::narx::start_window::StartWindow;
use crate::numeric::linalg::JitterLog;

/// Relative eigenvalue of `K(X̄, X̄)` below which a direction is left out of the draws.
const EIGEN_FLOOR: f64 = 1e-9;

/// Prior precision of each linear-mean coefficient (normalised units): variance 100.
const LINEAR_PRIOR_PRECISION: f64 = 1e-2;

/// One output's draws.
#[derive(Clone, Debug)]
struct OutputDraws {
    /// `K̃⁻¹ B` (m × r): the mean's sensitivity to `ξ` is `qᵀ K̃⁻¹ B`.
    targets: DMatrix<f64>,
    /// With the linear mean: `K̃⁻¹ X̄` (m × D) and `L` (D × D, `L Lᵀ = Cov(A_a)`).
    linear: Option<(DMatrix<f64>, DMatrix<f64>)>,
    /// `ℓ_d²`.
    l2: Vec<f64>,
    /// `σ_f²`.
    sf2: f64,
}

/// The draws of a GP's function: per output, how its pseudo-targets (and linear mean) move
/// with standard normal coordinates. Built once per model.
#[derive(Clone, Debug)]
pub struct FunctionDraws {
    outputs: Vec<OutputDraws>,
    /// First direction of each output's block, and the total as the last entry.
    offsets: Vec<usize>,
}

impl FunctionDraws {
    /// The draws of `gp`.
    pub fn new(gp: &PreparedGp<f64>) -> Result<Self> {
        let z = &gp.pseudo_inputs;
        let (m, d) = (z.nrows(), z.ncols());
        let mut outputs = Vec::with_capacity(gp.outputs.len());
        let mut offsets = vec![0];
        for (a, o) in gp.outputs.iter().enumerate() {
            let k = kernel_matrix(z, z, &o.inv_l2, o.sf2);
            let eig = nalgebra::SymmetricEigen::new(k);
            let top = eig.eigenvalues.iter().copied().fold(0.0, f64::max);
            let kept: Vec<usize> = (0..m)
                .filter(|&i| eig.eigenvalues[i] > EIGEN_FLOOR * top)
                .collect();
            // K̃⁻¹ B = V diag(σ / √(λ (λ + σ²))) on the kept directions
            let sigma = o.sx2.sqrt();
            let mut targets = DMatrix::zeros(m, kept.len());
            for (c, &i) in kept.iter().enumerate() {
                let l = eig.eigenvalues[i];
                let s = sigma / (l * (l + o.sx2)).sqrt();
                for r in 0..m {
                    targets[(r, c)] = eig.eigenvectors[(r, i)] * s;
                }
            }
            let linear = match &gp.linear_mean {
                None => None,
                Some(_) => {
                    let w = &o.kinv * z; // m × D
                    let mut prec = z.transpose() * &w;
                    for i in 0..d {
                        prec[(i, i)] += LINEAR_PRIOR_PRECISION;
                    }
                    let prec = (&prec + prec.transpose()) * 0.5;
                    let cov = prec
                        .cholesky()
                        .ok_or_else(|| {
                            MsgpError::NonFinite(format!(
                                "the linear mean's precision from the pseudo-data of output {a}"
                            ))
                        })?
                        .inverse();
                    let cov = (&cov + cov.transpose()) * 0.5;
                    let l = cov
                        .cholesky()
                        .ok_or_else(|| {
                            MsgpError::NonFinite(format!(
                                "the linear mean's covariance of output {a}"
                            ))
                        })?
                        .l();
                    Some((w, l))
                }
            };
            let next = offsets[a] + kept.len() + linear.as_ref().map_or(0, |_| d);
            offsets.push(next);
            outputs.push(OutputDraws {
                targets,
                linear,
                l2: o.inv_l2.iter().map(|v| 1.0 / v).collect(),
                sf2: o.sf2,
            });
        }
        Ok(Self { outputs, offsets })
    }

    /// Number of standard normal coordinates of a draw.
    pub fn directions(&self) -> usize {
        self.offsets.last().copied().unwrap_or(0)
    }

    /// The pseudo-target and linear-mean moves `(δȳ (m × E), δA (E × D))` of the draw with
    /// coordinates `x` (length [`directions`](Self::directions)), given `gp`'s factors (the
    /// draws' own, for tests and Monte Carlo: `δȳ = K̃ (K̃⁻¹ B) ξ − X̄ δAᵀ`).
    pub fn moves(&self, gp: &PreparedGp<f64>, x: &[f64]) -> (DMatrix<f64>, DMatrix<f64>) {
        let z = &gp.pseudo_inputs;
        let (m, d) = (z.nrows(), z.ncols());
        let e = self.outputs.len();
        let mut dy = DMatrix::zeros(m, e);
        let mut da = DMatrix::zeros(e, d);
        for (a, od) in self.outputs.iter().enumerate() {
            let o = &gp.outputs[a];
            let r = od.targets.ncols();
            let off = self.offsets[a];
            let xi = DVector::from_column_slice(&x[off..off + r]);
            let kt = o.chol.l.clone() * o.chol.l.transpose();
            let mut col = kt * (&od.targets * xi);
            if let Some((_, l)) = &od.linear {
                let zeta = DVector::from_column_slice(&x[off + r..off + r + d]);
                let dai = l * zeta;
                col -= z * &dai;
                for j in 0..d {
                    da[(a, j)] = dai[j];
                }
            }
            dy.set_column(a, &col);
        }
        (dy, da)
    }
}

/// The expected kernel vector `q_i = σ_f² |Σ Λ⁻¹ + I|^{-½} exp(−½ ν_iᵀ (Σ + Λ)⁻¹ ν_i)`,
/// `ν_i = x̄_i − μ`, of one output at `N(mu, sigma)` (the module docs of [`crate::moments`]).
fn expected_kernel(
    od: &OutputDraws,
    z: &DMatrix<f64>,
    mu: &DVector<f64>,
    sigma: &DMatrix<f64>,
) -> Result<DVector<f64>> {
    let d = mu.len();
    let mut r = sigma.clone();
    for i in 0..d {
        r[(i, i)] += od.l2[i];
    }
    let chol = r.cholesky().ok_or_else(|| {
        MsgpError::NonFinite("Σ + Λ of the function draws' expected kernel".into())
    })?;
    let l = chol.l();
    let log_det_r: f64 = (0..d).map(|i| 2.0 * l[(i, i)].ln()).sum();
    let log_det_l: f64 = od.l2.iter().map(|v| v.ln()).sum();
    let scale = od.sf2 * (0.5 * (log_det_l - log_det_r)).exp();
    let mut q = DVector::zeros(z.nrows());
    let mut nu = DVector::zeros(d);
    for i in 0..z.nrows() {
        for k in 0..d {
            nu[k] = z[(i, k)] - mu[k];
        }
        let y = l
            .solve_lower_triangular(&nu)
            .ok_or_else(|| MsgpError::NonFinite("the expected kernel's solve".into()))?;
        q[i] = scale * (-0.5 * y.norm_squared()).exp();
    }
    Ok(q)
}

/// The first-order spread of the drawn functions' rollout means, carried along an open-loop
/// rollout: the window's tangent and the independent-injection covariance it is compared with.
pub(crate) struct Tangents<'a> {
    draws: &'a FunctionDraws,
    spec: &'a NarxSpec,
    pseudo_inputs: &'a DMatrix<f64>,
    /// `∂μ_window / ∂(ξ, ζ)` (D × directions).
    t: DMatrix<f64>,
    /// The same spread were each step's function draw independent (D × D).
    indep: DMatrix<f64>,
    /// The output tangents of the last step (d_y × directions), for tests.
    pub(crate) last: DMatrix<f64>,
}

impl<'a> Tangents<'a> {
    /// Zero tangents: the start window is measured, not predicted.
    pub(crate) fn new(
        draws: &'a FunctionDraws,
        spec: &'a NarxSpec,
        pseudo_inputs: &'a DMatrix<f64>,
    ) -> Self {
        let (d, p) = (spec.input_dim(), draws.directions());
        Self {
            draws,
            spec,
            pseudo_inputs,
            t: DMatrix::zeros(d, p),
            indep: DMatrix::zeros(d, d),
            last: DMatrix::zeros(spec.dy, p),
        }
    }

    /// One step at the window `N(mu, sigma)` whose moments are `mm`: the variance the
    /// correlation adds to each output, and the tangents shifted to the next window.
    pub(crate) fn step(
        &mut self,
        mu: &DVector<f64>,
        sigma: &DMatrix<f64>,
        mm: &Moments<f64>,
    ) -> Result<DVector<f64>> {
        let (dy, p) = (self.spec.dy, self.draws.directions());
        let z = self.pseudo_inputs;
        let mut direct = DMatrix::zeros(dy, p);
        let mut injected = DVector::zeros(dy);
        for (a, od) in self.draws.outputs.iter().enumerate() {
            let q = expected_kernel(od, z, mu, sigma)?;
            let off = self.draws.offsets[a];
            let r = od.targets.ncols();
            let row = od.targets.tr_mul(&q); // r
            injected[a] = row.norm_squared();
            for c in 0..r {
                direct[(a, off + c)] = row[c];
            }
            if let Some((w, l)) = &od.linear {
                let g = mu - w.tr_mul(&q); // D
                let row = l.tr_mul(&g);
                for c in 0..row.len() {
                    direct[(a, off + r + c)] = row[c];
                }
            }
        }
        let v = &mm.v; // D × E
        let out = v.tr_mul(&self.t) + direct; // E × P
        let iv = &self.indep * v; // D × E
        let mut out_indep = v.tr_mul(&iv);
        for a in 0..dy {
            out_indep[(a, a)] += injected[a];
        }
        let added = DVector::from_fn(dy, |a, _| {
            (out.row(a).norm_squared() - out_indep[(a, a)]).max(0.0)
        });
        self.shift(&out, &iv, &out_indep);
        self.last = out;
        Ok(added)
    }

    /// Moves the window one step on: the new outputs enter at lag 0, the oldest drop out,
    /// inputs (measured) carry no tangent.
    fn shift(&mut self, out: &DMatrix<f64>, iv: &DMatrix<f64>, out_indep: &DMatrix<f64>) {
        let spec = self.spec;
        let d = spec.input_dim();
        // source of each new window entry in [window (D), new outputs (d_y)], None for inputs
        let src: Vec<Option<usize>> = (0..d)
            .map(|i| {
                if i >= spec.ly * spec.dy {
                    return None;
                }
                let (k, j) = (i / spec.dy, i % spec.dy);
                Some(if k == 0 {
                    d + j
                } else {
                    spec.y_index(k - 1, j)
                })
            })
            .collect();
        let p = self.t.ncols();
        let mut t = DMatrix::zeros(d, p);
        let mut indep = DMatrix::zeros(d, d);
        let aug_cov = |s: usize, s2: usize| match (s >= d, s2 >= d) {
            (false, false) => self.indep[(s, s2)],
            (false, true) => iv[(s, s2 - d)],
            (true, false) => iv[(s2, s - d)],
            (true, true) => out_indep[(s - d, s2 - d)],
        };
        for i in 0..d {
            let Some(s) = src[i] else { continue };
            if s >= d {
                t.row_mut(i).copy_from(&out.row(s - d));
            } else {
                t.row_mut(i).copy_from(&self.t.row(s));
            }
            for i2 in 0..d {
                if let Some(s2) = src[i2] {
                    indep[(i, i2)] = aug_cov(s, s2);
                }
            }
        }
        self.t = t;
        self.indep = indep;
    }
}

impl Widen<f64> for Tangents<'_> {
    fn widen(
        &mut self,
        mu: &DVector<f64>,
        sigma: &DMatrix<f64>,
        mm: &Moments<f64>,
        ycov: &mut DMatrix<f64>,
    ) -> Result<()> {
        let added = self.step(mu, sigma, mm)?;
        for (j, v) in added.iter().enumerate() {
            ycov[(j, j)] += v;
        }
        Ok(())
    }
}

/// Open-loop free simulation of `traj` (normalised units) to `horizon` whose reported output
/// variances include the correlated function uncertainty (see the module docs); the means are
/// moment matching's.
pub fn simulate_correlated(
    gp: &PreparedGp<f64>,
    spec: &NarxSpec,
    traj: &Trajectory,
    horizon: usize,
    log: &mut JitterLog,
) -> Result<Vec<StepPrediction<f64>>> {
    let draws = FunctionDraws::new(gp)?;
    let mut tangents = Tangents::new(&draws, spec, &gp.pseudo_inputs);
    let mut out = Vec::with_capacity(horizon.saturating_sub(spec.warmup()));
    rollout_widened(
        gp,
        spec,
        traj,
        &Control::FeedForward,
        horizon,
        StartWindow::Measured,
        log,
        Some(&mut tangents),
        |p| {
            out.push(p);
            Ok(())
        },
    )?;
    Ok(out)
}

#[cfg(test)]
mod tests;
