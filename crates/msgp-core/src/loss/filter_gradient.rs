//! The gradient of the filter likelihood ([`super::filter_loss`]) by an adjoint sweep, in f64:
//! what the fit trains on when it scores trajectories by the filter instead of the free run.
//!
//! Per episode a forward pass runs the filter of [`super::filter`] and records every step (the
//! moment-matching intermediates of its prediction, the predicted window's covariance `P`, the
//! innovation `e`, `S_inn⁻¹` and the gain `K`); the value is the forward filter's, bit for bit
//! (the same prediction, gather and [`super::filter::kalman_update`] code). The backward pass
//! then runs `t = T−1, …, t0` with the adjoints `(μ̄_f, P̄_f)` of the filtered window (zero at the
//! last step; `P̄_f` symmetric) and the step's own score:
//! - NLL `½ eᵀS⁻¹e + ½ log|S|`: `ē = α`, `S̄ = ½(S⁻¹ − α αᵀ)`, `α = S⁻¹e`;
//! - `μ_f = μ_p + K e`: `μ̄_p = μ̄_f`, `K̄ = μ̄_f eᵀ`, `ē += Kᵀ μ̄_f`;
//! - Joseph form `P_f = A P Aᵀ + K Σ_y Kᵀ`, `A = I − KH`: with `G = P̄_f K`,
//!   `P̄ = Aᵀ P̄_f A = P̄_f − G H − Hᵀ Gᵀ + Hᵀ Kᵀ G H`, `Σ̄_y = diag(Kᵀ G)`,
//!   `K̄ += 2 G Σ_y − 2 P̄_f A P Hᵀ` (`A P Hᵀ = P Hᵀ − K H P Hᵀ`): all `O(D² d_y)`, no `D × D`
//!   product;
//! - `K = P Hᵀ S⁻¹`: `(P̄ Hᵀ) += K̄ S⁻¹`, `S̄ −= Kᵀ K̄ S⁻¹`; `P̄` and `S̄` symmetrised (the
//!   forward symmetrises `P`, and `S` is symmetric along every path);
//! - `e = y_t − M`: `M̄ = −ē`; `S = S_mm + Σ_x + Σ_y` is the prediction's `Cov[y]`.
//!
//! From `(μ̄_p, P̄)` on, the step is the free run's backward step: the window shift
//! ([`crate::rollout::adjoint::gather_backward`]; the measured input has no adjoint), the
//! augmented moments, the noises (`Σ̄_x`, `Σ̄_y`), the linear mean and the moment matching's VJP
//! (`crate::rollout::adjoint::predict_backward`). What it returns is `(μ̄_f, P̄_f)` of the step
//! before; after `t0` it is the start window's, whose latent outputs `N(y, σ_y²)` give `σ_y²` the
//! trace of their block. The episodes and the pull-back through the GP's preparation (complexity
//! term included) are the free-run gradient's ([`super::loss_and_gradient`]).
//!
//! Tested against forward-mode duals through [`super::filter_loss`] and against finite
//! differences (`tests/filter_gradient.rs`).

use nalgebra::{DMatrix, DVector};

use super::filter::kalman_update;
use super::gradient::gradient_over_episodes;
use super::{Complexity, LossValue};
use crate::data::Trajectory;
use crate::error::{MsgpError, Result};
use crate::gp::{GpConfig, GpParams, PreparedGp};
use crate::moments::vjp::{BackWork, GpAdjoint};
use crate::narx::NarxSpec;
use crate::narx::start_window::StartWindow;
use crate::numeric::linalg::{JitterLog, symmetrize};
use crate::numeric::parallel::Threads;
use crate::rollout::Episode;
use crate::rollout::adjoint::{
    PredictRecord, StepBar, augmented_backward, gather_backward, predict_backward,
};
use crate::rollout::window::{Layout, gather, initial_window};

/// What the forward filter records per step.
struct FilterRecord {
    /// The prediction from the filtered window `x̃_{t−1} | y_{<t}`.
    pred: PredictRecord,
    /// The predicted window's covariance `P = Cov[x̃_t | y_{<t}]` (D × D).
    psigma: DMatrix<f64>,
    /// The innovation `e` (d_y).
    innovation: DVector<f64>,
    /// `S_inn⁻¹` (d_y × d_y).
    sinv: DMatrix<f64>,
    /// The gain `K` (D × d_y).
    gain: DMatrix<f64>,
}

/// Value and gradient (in [`GpParams::to_flat`] layout) of the filter loss
/// [`super::filter_loss`], by the adjoint sweep of the module docs, with the episodes on up to
/// `threads` threads: the signature and conventions of [`super::loss_and_gradient`] (every
/// episode accumulates its own adjoints, summed in episode order, so the result does not depend
/// on `threads`). Every episode is filtered on its measured inputs, feedback episodes too, from
/// the measured start window, as [`super::filter_loss`] does. The value is
/// [`super::filter_loss`]'s in f64, bit for bit.
pub fn filter_loss_and_gradient(
    params: &GpParams<f64>,
    config: &GpConfig,
    spec: &NarxSpec,
    episodes: &[Episode],
    complexity: Complexity,
    threads: Threads,
    log: &mut JitterLog,
) -> Result<(LossValue<f64>, Vec<f64>)> {
    weighted_filter_loss_and_gradient(
        params,
        config,
        spec,
        episodes,
        (complexity, 1.0),
        threads,
        log,
    )
}

/// [`filter_loss_and_gradient`] with the complexity term weighted by `complexity.1`
/// (as [`super::gradient::weighted_loss_and_gradient`]).
pub(crate) fn weighted_filter_loss_and_gradient(
    params: &GpParams<f64>,
    config: &GpConfig,
    spec: &NarxSpec,
    episodes: &[Episode],
    complexity: (Complexity, f64),
    threads: Threads,
    log: &mut JitterLog,
) -> Result<(LossValue<f64>, Vec<f64>)> {
    gradient_over_episodes(
        (params, config),
        spec,
        episodes,
        complexity,
        threads,
        log,
        |gp, ep, adj, elog| filter_adjoint(gp, spec, &ep.traj, adj, elog),
    )
}

/// The filter likelihood of one trajectory and its adjoint sweep: adds the GP adjoints to `adj`,
/// returns the NLL and the number of scored steps.
fn filter_adjoint(
    gp: &PreparedGp<f64>,
    spec: &NarxSpec,
    traj: &Trajectory,
    adj: &mut GpAdjoint,
    log: &mut JitterLog,
) -> Result<(f64, usize)> {
    let d = spec.input_dim();
    let (dy, du) = (spec.dy, spec.du);
    if gp.input_dim() != d || gp.output_dim() != dy {
        return Err(MsgpError::Shape(format!(
            "GP has input dimension {} and {} outputs; the NARX spec needs {} and {}",
            gp.input_dim(),
            gp.output_dim(),
            d,
            dy
        )));
    }
    let start = initial_window(gp, spec, traj, StartWindow::Measured)?;
    let layout = Layout { d, ds: 0, dy, du };
    let len = layout.len();
    let sel = layout.gather_map(spec);
    debug_assert!((0..dy).all(|j| spec.y_index(0, j) == j));

    // forward: the filter of `filter_steps`, recording every step
    let t0 = start.t0;
    let mut recs: Vec<FilterRecord> = Vec::with_capacity(traj.len().saturating_sub(t0));
    let (mut mu, mut sigma) = (start.mean, start.cov);
    let mut nll = 0.0;
    for t in t0..traj.len() {
        let pred = PredictRecord::forward(gp, mu, sigma, log)?;
        if pred.mean.iter().any(|v| !v.is_finite()) || pred.ycov.iter().any(|v| !v.is_finite()) {
            return Err(MsgpError::NonFinite(format!(
                "filter prediction at step {t}"
            )));
        }
        let (mut amu, acov) =
            layout.augmented(&pred.wmu, &pred.wsig, &pred.mean, &pred.v, &pred.xcov);
        layout.set_measured_input(&mut amu, &traj.u, t);
        let (pmu, psigma) = gather(&amu, &acov, &sel);
        let up = kalman_update(gp, (&pmu, &psigma), &pred.ycov, &pred.mean, traj, t, log)?;
        nll += up.nll;
        recs.push(FilterRecord {
            pred,
            psigma,
            innovation: up.innovation,
            sinv: up.chol.inverse(),
            gain: up.gain,
        });
        (mu, sigma) = (up.mean, up.cov);
    }
    if !nll.is_finite() {
        return Err(MsgpError::NonFinite(
            "the filter likelihood is not finite".into(),
        ));
    }
    let steps = recs.len();
    if steps == 0 {
        return Ok((nll, 0));
    }

    // backward
    let sy2: Vec<f64> = gp.outputs.iter().map(|o| o.sy2).collect();
    let mut work = BackWork::default();
    let mut mubar_f = DVector::<f64>::zeros(d);
    let mut sigmabar_f = DMatrix::<f64>::zeros(d, d);
    let last = steps - 1;
    for (s, rec) in recs.iter().enumerate().rev() {
        let FilterRecord {
            pred,
            psigma,
            innovation: e,
            sinv,
            gain: k,
        } = rec;
        let mut bar = StepBar::zeros(d, d, dy);
        // the score: ½ eᵀS⁻¹e + ½ log|S|
        let alpha = sinv * e;
        let mut ebar = alpha.clone();
        let mut sbar = (sinv - &alpha * alpha.transpose()) * 0.5;
        if s < last {
            symmetrize(&mut sigmabar_f);
            let fbar = &sigmabar_f;
            // μ_f = μ_p + K e
            let mut kbar = &mubar_f * e.transpose();
            ebar += k.transpose() * &mubar_f;
            // Joseph form, with G = P̄_f K
            let g = fbar * k;
            let ktg = k.transpose() * &g;
            let mut pbar = fbar.clone();
            for j in 0..dy {
                for i in 0..d {
                    pbar[(i, j)] -= g[(i, j)];
                    pbar[(j, i)] -= g[(i, j)];
                }
                for i in 0..dy {
                    pbar[(i, j)] += ktg[(i, j)];
                }
                adj.sy2[j] += ktg[(j, j)];
            }
            // K̄ += 2 G Σ_y − 2 P̄_f (A P Hᵀ), A P Hᵀ = P Hᵀ − K (H P Hᵀ)
            let pht = psigma.columns(0, dy);
            let aph = pht - k * psigma.view((0, 0), (dy, dy));
            let fa = fbar * aph;
            for j in 0..dy {
                for i in 0..d {
                    kbar[(i, j)] += 2.0 * (g[(i, j)] * sy2[j] - fa[(i, j)]);
                }
            }
            // K = P Hᵀ S⁻¹
            let phtbar = &kbar * sinv;
            sbar -= k.transpose() * &phtbar;
            for j in 0..dy {
                for i in 0..d {
                    pbar[(i, j)] += phtbar[(i, j)];
                }
            }
            symmetrize(&mut pbar);
            // the window shift and the augmented moments
            let (amubar, acovbar) = gather_backward(&sel, len, &mubar_f, &pbar);
            augmented_backward(&layout, &pred.wsig, &pred.v, &amubar, &acovbar, &mut bar);
        }
        symmetrize(&mut sbar);
        // e = y − M; S_inn = Cov[y]
        bar.mbar -= &ebar;
        bar.ycovbar += &sbar;
        predict_backward(gp, pred, &mut bar, adj, &mut work);
        mubar_f = bar.mubar;
        sigmabar_f = bar.sigmabar;
    }
    // the start window's latent outputs N(y, σ_y² · pattern)
    for j in 0..dy {
        for k in 0..spec.ly {
            for k2 in 0..spec.ly {
                adj.sy2[j] +=
                    start.pattern[(k, k2)] * sigmabar_f[(spec.y_index(k, j), spec.y_index(k2, j))];
            }
        }
    }
    Ok((nll, steps))
}
