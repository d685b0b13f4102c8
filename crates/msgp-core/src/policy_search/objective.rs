//! The policy-search objective: the expected saturating cost of a closed-loop moment-matching
//! rollout, summed over the horizon (closed form per step), with per-step variances for
//! reporting ([`closed_loop_cost`]); the problem a learned model, a start and a cost pose
//! ([`PolicyProblem`], original units, normalised exactly inside), and its gradient over the
//! free parameters of a [`SearchSpace`]. Generic over [`Scalar`], so forward-mode duals over
//! the parameters are the reference of the adjoint gradient ([`super::gradient`]).

use nalgebra::{DMatrix, DVector};

use super::cost::{CostMoments, SaturatingCost};
use super::gradient::closed_loop_cost_gradient;
use super::space::SearchSpace;
use crate::error::Result;
use crate::gp::PreparedGp;
use crate::model::Model;
use crate::moments::MomentMatch;
use crate::narx::NarxSpec;
use crate::numeric::dual::{Dual, LANES, gradient_lanes};
use crate::numeric::linalg::JitterLog;
use crate::numeric::scalar::{Scalar, c};
use crate::optim::Flow;
use crate::policy::{FeedbackPolicy, Normalized, RestEntry};
use crate::rollout::adjoint::PolicyVjp;
use crate::rollout::{Control, StartState, rollout_from};

/// Expected cost of a closed-loop rollout.
#[derive(Clone, Debug)]
pub struct RolloutCost<T: Scalar> {
    /// `Σ_t E[c(y_t)]`.
    pub total: T,
    /// Per-step mean and variance of the cost.
    pub steps: Vec<CostMoments<T>>,
}

/// Runs `policy` in closed loop on the model from `start` over `t0..horizon` and accumulates the
/// expected cost of the predicted observations.
pub fn closed_loop_cost<T: MomentMatch>(
    gp: &PreparedGp<T>,
    spec: &NarxSpec,
    start: &StartState<T>,
    policy: &dyn FeedbackPolicy<T>,
    (t0, horizon): (usize, usize),
    cost: &SaturatingCost,
    log: &mut JitterLog,
) -> Result<RolloutCost<T>> {
    closed_loop_cost_bounded(gp, spec, start, policy, (t0, horizon), cost, None, log)
        .map(|(rc, _)| rc)
}

/// [`closed_loop_cost`] that stops as soon as the running total exceeds `bound` (the flag
/// then says so and the cost covers the steps run): every step's expected saturating cost
/// lies in `[0, 1]`, so the total can only grow from there, and a rollout already dearer than
/// the bound is known to end dearer still.
#[allow(clippy::too_many_arguments)]
fn closed_loop_cost_bounded<T: MomentMatch>(
    gp: &PreparedGp<T>,
    spec: &NarxSpec,
    start: &StartState<T>,
    policy: &dyn FeedbackPolicy<T>,
    (t0, horizon): (usize, usize),
    cost: &SaturatingCost,
    bound: Option<f64>,
    log: &mut JitterLog,
) -> Result<(RolloutCost<T>, bool)> {
    let mut steps = Vec::with_capacity(horizon.saturating_sub(t0));
    let mut total = T::zero();
    let mut cost_log = JitterLog::default();
    let mut exceeded = false;
    rollout_from(
        gp,
        spec,
        start,
        &Control::Feedback(policy),
        None,
        t0,
        horizon,
        log,
        |p| {
            let m = cost.moments(&p.mean, &p.cov, &gp.jitter, &mut cost_log)?;
            total += m.mean;
            steps.push(m);
            // a margin far above rounding: a step's cost can come out a hair below zero
            exceeded = bound.is_some_and(|b| total.re() > b + BOUND_SLACK * (1.0 + b.abs()));
            Ok(if exceeded { Flow::Stop } else { Flow::Continue })
        },
    )?;
    log.merge(&cost_log);
    Ok((RolloutCost { total, steps }, exceeded))
}

/// Relative slack of [`PolicyProblem::evaluate_bounded`]'s bound.
const BOUND_SLACK: f64 = 1e-9;

/// The problem: model, start, cost and horizon, all in original units.
#[derive(Debug)]
pub struct PolicyProblem<'a> {
    /// The learned dynamics model.
    pub model: &'a Model,
    /// Mean of the latent outputs at rest before the rollout (original units, d_y).
    pub y0_mean: Vec<f64>,
    /// Variance of the latent outputs at rest (original units, d_y).
    pub y0_var: Vec<f64>,
    /// Inputs before the rollout (original units, d_u).
    pub u0: Vec<f64>,
    /// Cost on the predicted observations (original units).
    pub cost: SaturatingCost,
    /// Number of predicted steps.
    pub horizon: usize,
}

impl PolicyProblem<'_> {
    /// Start state in normalised units: every output lag at `y0` (latent, variance `y0_var`,
    /// fully correlated across lags: the system is at rest), inputs at `u0`, and the policy's
    /// state as its [`FeedbackPolicy::rest_state`] says (original units): an earlier observation
    /// is the latent start plus observation noise, correlated with every output lag of the
    /// window and with the other earlier observations of its output (a derivative term then
    /// sees measurement noise, not the whole spread of the start state); an earlier command is
    /// `u0`.
    pub(crate) fn start<T: Scalar>(&self, rest: &[RestEntry]) -> StartState<T> {
        let spec = self.model.spec;
        let n = &self.model.normalizer;
        let d = spec.input_dim();
        let ds = rest.len();
        let mut mean = DVector::<T>::zeros(d + ds);
        let mut cov = DMatrix::<T>::zeros(d + ds, d + ds);
        for k in 0..spec.ly {
            for j in 0..spec.dy {
                mean[spec.y_index(k, j)] = c((self.y0_mean[j] - n.y_mean[j]) / n.y_std[j]);
                for k2 in 0..spec.ly {
                    cov[(spec.y_index(k, j), spec.y_index(k2, j))] =
                        c(self.y0_var[j] / (n.y_std[j] * n.y_std[j]));
                }
            }
        }
        for k in 0..spec.lu {
            for j in 0..spec.du {
                mean[spec.u_index(k, j)] = c((self.u0[j] - n.u_mean[j]) / n.u_std[j]);
            }
        }
        for (a, entry) in rest.iter().enumerate() {
            let p = d + a;
            match *entry {
                RestEntry::Observation(j) if j < spec.dy => {
                    let std = n.y_std[j];
                    let sy2 =
                        self.model.params.log_obs_noise[j].exp() + self.model.config.noise_floor;
                    mean[p] = c(self.y0_mean[j]);
                    cov[(p, p)] = c(self.y0_var[j] + sy2 * std * std);
                    for k in 0..spec.ly {
                        let i = spec.y_index(k, j);
                        cov[(p, i)] = c(self.y0_var[j] / std);
                        cov[(i, p)] = c(self.y0_var[j] / std);
                    }
                    for (b, other) in rest[..a].iter().enumerate() {
                        if *other == RestEntry::Observation(j) {
                            cov[(p, d + b)] = c(self.y0_var[j]);
                            cov[(d + b, p)] = c(self.y0_var[j]);
                        }
                    }
                }
                RestEntry::Command(j) if j < spec.du => mean[p] = c(self.u0[j]),
                _ => {}
            }
        }
        StartState { mean, cov }
    }

    /// The cost on the model's normalised outputs.
    fn normalised_cost(&self) -> SaturatingCost {
        let n = &self.model.normalizer;
        self.cost.in_units(
            DVector::from_column_slice(&n.y_mean),
            DVector::from_column_slice(&n.y_std),
        )
    }

    /// Expected total cost of the policy of `space` with free parameters `x` and its gradient
    /// with respect to `x`, by the adjoint sweep of the closed-loop rollout (a few rollouts'
    /// work whatever the number of parameters; [`policy_gradient_duals`] is the reference).
    /// The policy's map is differentiated in closed form where its family has one, else by
    /// duals.
    pub fn gradient(&self, space: &SearchSpace, x: &[f64]) -> Result<(f64, Vec<f64>)> {
        let mut log = JitterLog::default();
        let gp = PreparedGp::new(&self.model.params, &self.model.config, &mut log)?;
        let normalizer = &self.model.normalizer;
        let policy = Normalized {
            inner: space.controller(x)?,
            normalizer: normalizer.clone(),
        };
        let lifted = Normalized {
            inner: policy.inner.lift::<f64>(),
            normalizer: normalizer.clone(),
        };
        let moments = |th: &[Dual], qm: &DVector<Dual>, qc: &DMatrix<Dual>| {
            Normalized {
                inner: space.policy::<Dual>(th)?,
                normalizer: normalizer.clone(),
            }
            .moments(qm, qc)
        };
        // the policy map's VJP in closed form (the duals through `moments` are its reference)
        let vjp = |qm: &DVector<f64>,
                   qc: &DMatrix<f64>,
                   mean_bar: &DVector<f64>,
                   cov_bar: &DMatrix<f64>,
                   c_bar: &DMatrix<f64>| {
            let (qm_bar, qc_bar, theta) = policy.moments_vjp(qm, qc, mean_bar, cov_bar, c_bar)?;
            Ok((qm_bar, qc_bar, space.pack(&theta)))
        };
        let closed_form = policy.inner.has_closed_form_vjp();
        let start = self.start::<f64>(&lifted.rest_state());
        let t0 = self.model.spec.warmup();
        closed_loop_cost_gradient(
            &gp,
            &self.model.spec,
            &start,
            &lifted,
            &moments,
            closed_form.then_some(&vjp as &PolicyVjp<'_>),
            x,
            t0,
            t0 + self.horizon,
            &self.normalised_cost(),
            &mut log,
        )
    }

    /// Expected total cost of `policy` and the per-step (mean, variance) of the cost.
    pub fn evaluate<T: MomentMatch>(
        &self,
        policy: &dyn FeedbackPolicy<T>,
    ) -> Result<(T, Vec<(T, T)>)> {
        let (rc, _) = self.cost_of(policy, None)?;
        Ok((rc.total, rc.steps.iter().map(|s| (s.mean, s.var)).collect()))
    }

    /// Expected total cost of `policy` if it is at most `bound`, `None` once the rollout's
    /// running cost exceeds it (the rest of the rollout is then not computed: screening many
    /// candidates for the few cheapest needs only the ones below the running k-th best).
    pub fn evaluate_bounded(
        &self,
        policy: &dyn FeedbackPolicy<f64>,
        bound: f64,
    ) -> Result<Option<f64>> {
        let (rc, exceeded) = self.cost_of(policy, Some(bound))?;
        Ok((!exceeded).then_some(rc.total))
    }

    fn cost_of<T: MomentMatch>(
        &self,
        policy: &dyn FeedbackPolicy<T>,
        bound: Option<f64>,
    ) -> Result<(RolloutCost<T>, bool)> {
        let params = self.model.params.map(c::<T>);
        let mut log = JitterLog::default();
        let gp = PreparedGp::new(&params, &self.model.config, &mut log)?;
        let wrapped = Normalized {
            inner: policy,
            normalizer: self.model.normalizer.clone(),
        };
        let start = self.start::<T>(&wrapped.rest_state());
        let t0 = self.model.spec.warmup();
        closed_loop_cost_bounded(
            &gp,
            &self.model.spec,
            &start,
            &wrapped,
            (t0, t0 + self.horizon),
            &self.normalised_cost(),
            bound,
            &mut log,
        )
    }
}

/// Value and gradient of the expected cost at the free parameters `x` (entries outside
/// `active` are 0), by the adjoint sweep of the closed-loop rollout
/// ([`crate::policy_search::closed_loop_cost_gradient`]).
pub(crate) fn policy_gradient(
    problem: &PolicyProblem<'_>,
    space: &SearchSpace,
    x: &[f64],
    active: &[usize],
) -> Result<(f64, Vec<f64>)> {
    let (value, full) = problem.gradient(space, x)?;
    let mut grad = vec![0.0; x.len()];
    for &i in active {
        grad[i] = full[i];
    }
    Ok((value, grad))
}

/// `policy_gradient` (the search's adjoint gradient) by duals with as many lanes as free
/// parameters (up to [`LANES`]; more take several chunks of `LANES`): the reference the
/// adjoint is tested against.
pub fn policy_gradient_duals(
    problem: &PolicyProblem<'_>,
    space: &SearchSpace,
    x: &[f64],
    active: &[usize],
) -> Result<(f64, Vec<f64>)> {
    // one closure per lane count: the dual type is part of its signature
    macro_rules! lanes {
        ($n:expr) => {
            gradient_lanes::<{ $n }, _>(x, active, 1, |xd| {
                Ok(problem.evaluate(space.policy(xd)?.as_ref())?.0)
            })
        };
    }
    match active.len() {
        1 => lanes!(1),
        2 => lanes!(2),
        3 => lanes!(3),
        4 => lanes!(4),
        5 => lanes!(5),
        6 => lanes!(6),
        7 => lanes!(7),
        _ => lanes!(LANES),
    }
}
