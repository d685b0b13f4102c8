//! The gradient of the MSGP loss ([`super::msgp_loss`]) by the adjoint sweep
//! (`crate::rollout::adjoint`): every episode's rollout scored by the likelihood of its
//! measured outputs, then the pull-back through the GP's preparation (`β = K̃⁻¹ȳ`, `K̃⁻¹`,
//! `log|K̃|`, `K̃ = K + σ_x² I`) to the parameters. Tested against forward-mode duals through
//! [`super::msgp_loss`] (`tests/adjoint_vs_dual.rs`). The episodes, their parallel sum and the
//! pull-back through the preparation are `gradient_over_episodes`, shared with the filter
//! likelihood's gradient ([`super::filter_loss_and_gradient`]).

use nalgebra::{DMatrix, DVector};

use super::{Complexity, LossValue, complexity_term, gaussian_nll};
use crate::data::Trajectory;
use crate::error::{MsgpError, Result};
use crate::gp::kernel::kernel_matrix;
use crate::gp::{GpConfig, GpParams, GpShape, PreparedGp};
use crate::moments::vjp::GpAdjoint;
use crate::narx::NarxSpec;
use crate::numeric::dual::Dual;
use crate::numeric::linalg::{JitterLog, cholesky};
use crate::numeric::parallel::{Threads, map_indexed};
use crate::policy::{FeedbackPolicy, PolicySpec};
use crate::rollout::adjoint::{AdjointPolicy, PolicyVjp, Predicted, StepScore, rollout_adjoint};
use crate::rollout::window::initial_window;
use crate::rollout::{Episode, Excitation};

/// The MSGP loss's step score: `−log N(y_t; mean, cov)` of the measured output.
struct MeasuredNll<'a>(&'a Trajectory);

impl StepScore for MeasuredNll<'_> {
    fn value(&self, y: &Predicted<'_>, log: &mut JitterLog) -> Result<f64> {
        let row: Vec<f64> = (0..y.mean.len()).map(|j| self.0.y[(y.t, j)]).collect();
        gaussian_nll(&row, y.mean, y.cov, y.jitter, log)
    }

    fn vjp(&self, y: &Predicted<'_>) -> Result<(DVector<f64>, DMatrix<f64>)> {
        // NLL = ½[rᵀV⁻¹r + log|V|]
        let resid = DVector::from_fn(y.mean.len(), |j, _| self.0.y[(y.t, j)] - y.mean[j]);
        let vch = cholesky(y.cov, y.jitter, "predictive covariance")?;
        let vinv = vch.inverse();
        let alpha = &vinv * &resid;
        let cov_bar = (&vinv - &alpha * alpha.transpose()) * 0.5;
        Ok((-alpha, cov_bar))
    }
}

/// The MSGP loss of one episode: its free-running prediction from the measured window (open
/// loop on its inputs, or closed loop under its policy), scored by the likelihood of the
/// measured outputs. Adds the GP adjoints to `adj`; returns the NLL and the number of steps.
fn episode_adjoint(
    gp: &PreparedGp<f64>,
    spec: &NarxSpec,
    traj: &Trajectory,
    policy: Option<&PolicySpec>,
    adj: &mut GpAdjoint,
    log: &mut JitterLog,
) -> Result<(f64, usize)> {
    let pol: Option<Box<dyn FeedbackPolicy<f64>>> = policy.map(|p| p.lift::<f64>());
    // the episode's policy is fixed (no parameters): lifted to duals once
    let pol_dual: Option<Box<dyn FeedbackPolicy<Dual>>> = policy.map(|p| p.lift::<Dual>());
    let moments;
    // the policy's vector–Jacobian product in closed form where it has one (the duals through
    // `moments` are its reference)
    let vjp = policy.filter(|p| p.has_closed_form_vjp()).map(|p| {
        move |qm: &DVector<f64>,
              qc: &DMatrix<f64>,
              mean_bar: &DVector<f64>,
              cov_bar: &DMatrix<f64>,
              c_bar: &DMatrix<f64>| {
            let (qm_bar, qc_bar, _) = p.moments_vjp(qm, qc, mean_bar, cov_bar, c_bar)?;
            Ok((qm_bar, qc_bar, Vec::new()))
        }
    });
    let adjoint_policy = match (pol.as_deref(), pol_dual.as_deref()) {
        (Some(p), Some(pd)) => {
            moments = move |_: &[Dual], qm: &DVector<Dual>, qc: &DMatrix<Dual>| pd.moments(qm, qc);
            Some(AdjointPolicy {
                policy: p,
                moments: &moments,
                vjp: vjp.as_ref().map(|f| f as &PolicyVjp<'_>),
                theta: &[],
            })
        }
        _ => None,
    };
    let first = initial_window(gp, spec, traj, gp.start)?;
    let t0 = first.t0;
    let start = first.state(pol.as_deref(), traj)?;
    let out = rollout_adjoint(
        gp,
        spec,
        &start,
        &MeasuredNll(traj),
        Some(&traj.u),
        adjoint_policy.as_ref(),
        t0,
        traj.len(),
        adj,
        log,
    )?;
    // the start window's output covariance is the observation noise times its pattern
    for j in 0..spec.dy {
        for k in 0..spec.ly {
            for k2 in 0..spec.ly {
                adj.sy2[j] += first.pattern[(k, k2)]
                    * out.start_cov[(spec.y_index(k, j), spec.y_index(k2, j))];
            }
        }
    }
    Ok((out.total, out.steps))
}

/// What one episode contributes to the loss and its adjoints.
struct EpisodeOut {
    adj: GpAdjoint,
    nll: f64,
    steps: usize,
    log: JitterLog,
}

/// Value and gradient (in [`GpParams::to_flat`] layout) of the MSGP loss, by the adjoint sweep,
/// with the episodes on up to `threads` threads. Every episode accumulates its own adjoints and
/// the episodes are summed in order, so the result does not depend on `threads`.
pub fn loss_and_gradient(
    params: &GpParams<f64>,
    config: &GpConfig,
    spec: &NarxSpec,
    episodes: &[Episode],
    complexity: Complexity,
    threads: Threads,
    log: &mut JitterLog,
) -> Result<(LossValue<f64>, Vec<f64>)> {
    weighted_loss_and_gradient(
        params,
        config,
        spec,
        episodes,
        (complexity, 1.0),
        threads,
        log,
    )
}

/// [`loss_and_gradient`] with the complexity term weighted: `complexity.1` times the term, in
/// the value and the gradient (a batch's estimate of a loss per step weights the complexity
/// of all the steps against the NLL of its own).
pub(crate) fn weighted_loss_and_gradient(
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
        |gp, ep, adj, elog| {
            let policy = match &ep.excitation {
                Excitation::FeedForward => None,
                Excitation::Feedback(p) => Some(p.as_ref()),
            };
            episode_adjoint(gp, spec, &ep.traj, policy, adj, elog)
        },
    )
}

/// The frame of every loss gradient by adjoints (the free run's [`loss_and_gradient`], the
/// filter's [`super::filter_loss_and_gradient`]): prepares the GP, runs `episode` on every
/// episode (up to `threads` at a time; each adds its GP adjoints to its own accumulator and
/// returns its NLL and step count), sums the episodes in order (the result does not depend on
/// `threads`), adds the complexity term `complexity.0` weighted by `complexity.1` and pulls the summed adjoints through the GP's
/// preparation to the parameters ([`GpParams::to_flat`] layout).
pub(crate) fn gradient_over_episodes(
    (params, config): (&GpParams<f64>, &GpConfig),
    spec: &NarxSpec,
    episodes: &[Episode],
    (complexity, weight): (Complexity, f64),
    threads: Threads,
    log: &mut JitterLog,
    episode: impl Fn(&PreparedGp<f64>, &Episode, &mut GpAdjoint, &mut JitterLog) -> Result<(f64, usize)>
    + Sync,
) -> Result<(LossValue<f64>, Vec<f64>)> {
    let gp = PreparedGp::new(params, config, log)?;
    let (mut adj, nll, steps) =
        summed_adjoints(&gp, params.shape()?, spec, episodes, threads, log, episode)?;
    let comp = weight * complexity_term(params, &gp, complexity);
    let (ybar, logdet_bar) = complexity_adjoints(params, &gp, (complexity, weight), &mut adj);
    let gradient = pulled_through(params, config, &gp, adj, (ybar, logdet_bar));
    Ok((
        LossValue {
            nll,
            complexity: comp,
            steps,
        },
        gradient.to_flat(),
    ))
}

/// Every episode's GP adjoints (`episode` on each, up to `threads` at a time, one accumulator
/// per episode), summed in episode order so the result does not depend on `threads`; with the
/// summed NLL and step count.
fn summed_adjoints(
    gp: &PreparedGp<f64>,
    GpShape { m, d, e }: GpShape,
    spec: &NarxSpec,
    episodes: &[Episode],
    threads: Threads,
    log: &mut JitterLog,
    episode: impl Fn(&PreparedGp<f64>, &Episode, &mut GpAdjoint, &mut JitterLog) -> Result<(f64, usize)>
    + Sync,
) -> Result<(GpAdjoint, f64, usize)> {
    let run = |k: usize, ep: &Episode| -> Result<EpisodeOut> {
        ep.traj
            .check(spec)
            .map_err(|err| MsgpError::Data(format!("episode {k}: {err}")))?;
        let mut adj = GpAdjoint::zeros(m, d, e);
        let mut elog = JitterLog::default();
        let (nll, steps) = episode(gp, ep, &mut adj, &mut elog)?;
        Ok(EpisodeOut {
            adj,
            nll,
            steps,
            log: elog,
        })
    };
    let outs = map_indexed(episodes, threads.get(), run);
    let mut adj = GpAdjoint::zeros(m, d, e);
    let mut nll = 0.0;
    let mut steps = 0;
    for out in outs {
        let out = out?;
        adj.add(&out.adj);
        log.merge(&out.log);
        nll += out.nll;
        steps += out.steps;
    }
    Ok((adj, nll, steps))
}

/// The complexity term's adjoints (weighted by `weight`): of the pseudo-targets `ȳ` (returned,
/// with each output's adjoint of `log|K̃|`) and of `β` (added to `adj`).
fn complexity_adjoints(
    params: &GpParams<f64>,
    gp: &PreparedGp<f64>,
    (complexity, weight): (Complexity, f64),
    adj: &mut GpAdjoint,
) -> (DMatrix<f64>, Vec<f64>) {
    let (m, e) = params.pseudo_targets.shape();
    let half = 0.5 * weight;
    let mut ybar = DMatrix::<f64>::zeros(m, e);
    let mut logdet_bar = vec![0.0; e];
    for a in 0..e {
        match complexity {
            Complexity::None => {}
            Complexity::HalfLogDet => logdet_bar[a] = half,
            Complexity::NegHalfLogDet => logdet_bar[a] = -half,
            Complexity::PseudoDataNll => {
                logdet_bar[a] = half;
                // ½ ȳᵀβ with β = K̃⁻¹ȳ: d/dȳ = β (symmetric K̃), routed as ȳ̄ += ½β, β̄ += ½ȳ
                for i in 0..m {
                    ybar[(i, a)] += half * gp.outputs[a].beta[i];
                }
                let ycol = params.pseudo_targets.column(a).into_owned();
                adj.beta[a] += ycol * half;
            }
        }
    }
    (ybar, logdet_bar)
}

/// The adjoints pulled through the GP's preparation (`β = K̃⁻¹ȳ`, `K̃⁻¹`, `log|K̃|`,
/// `K̃ = K + σx² I`) to the parameters, in their own shape: log length-scales and log variances
/// through their exponentials.
fn pulled_through(
    params: &GpParams<f64>,
    config: &GpConfig,
    gp: &PreparedGp<f64>,
    mut adj: GpAdjoint,
    (mut ybar, logdet_bar): (DMatrix<f64>, Vec<f64>),
) -> GpParams<f64> {
    let GpShape { m, d, e } = GpShape {
        m: params.pseudo_inputs.nrows(),
        d: params.pseudo_inputs.ncols(),
        e: params.pseudo_targets.ncols(),
    };
    let mut inv_l2_bar = adj.inv_l2.clone();
    let mut sf2_bar = adj.sf2.clone();
    let mut sx2_bar = adj.sx2.clone();
    for (a, o) in gp.outputs.iter().enumerate() {
        let w = &o.kinv * &adj.beta[a];
        for i in 0..m {
            ybar[(i, a)] += w[i];
        }
        let ktbar =
            -(&o.kinv * &adj.kinv[a] * &o.kinv) - &w * o.beta.transpose() + &o.kinv * logdet_bar[a];
        sx2_bar[a] += ktbar.trace();
        let k = kernel_matrix(
            &params.pseudo_inputs,
            &params.pseudo_inputs,
            &o.inv_l2,
            o.sf2,
        );
        for i in 0..m {
            for j in 0..m {
                let g = ktbar[(i, j)] * k[(i, j)];
                if g == 0.0 {
                    continue;
                }
                sf2_bar[a] += g / o.sf2;
                for dd in 0..d {
                    let diff = params.pseudo_inputs[(i, dd)] - params.pseudo_inputs[(j, dd)];
                    inv_l2_bar[(a, dd)] -= 0.5 * g * diff * diff;
                    adj.xbar[(i, dd)] -= g * o.inv_l2[dd] * diff;
                    adj.xbar[(j, dd)] += g * o.inv_l2[dd] * diff;
                }
            }
        }
    }
    GpParams {
        pseudo_inputs: adj.xbar,
        pseudo_targets: ybar,
        log_lengthscales: DMatrix::from_fn(e, d, |a, dd| {
            -2.0 * gp.outputs[a].inv_l2[dd] * inv_l2_bar[(a, dd)]
        }),
        log_signal_var: DVector::from_fn(e, |a, _| sf2_bar[a] * gp.outputs[a].sf2),
        log_process_noise: DVector::from_fn(e, |a, _| {
            sx2_bar[a] * (gp.outputs[a].sx2 - config.noise_floor)
        }),
        log_obs_noise: DVector::from_fn(e, |a, _| {
            adj.sy2[a] * (gp.outputs[a].sy2 - config.noise_floor)
        }),
        linear_mean: if gp.linear_mean.is_some() {
            adj.lin
        } else {
            DMatrix::zeros(e, d)
        },
    }
}
