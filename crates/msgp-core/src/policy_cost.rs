//! The policy-search objective: the expected saturating cost of a closed-loop moment-matching
//! rollout, summed over the horizon (closed form per step), with per-step variances for
//! reporting. Generic over [`Scalar`], so policy gradients come from forward-mode duals over the
//! handful of policy parameters.

use crate::cost::{CostMoments, SaturatingCost};
use crate::error::Result;
use crate::gp::PreparedGp;
use crate::linalg::JitterLog;
use crate::narx::NarxSpec;
use crate::policy::FeedbackPolicy;
use crate::rollout::{Control, StartState, rollout_from};
use crate::scalar::Scalar;

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
pub fn closed_loop_cost<T: Scalar>(
    gp: &PreparedGp<T>,
    spec: &NarxSpec,
    start: &StartState<T>,
    policy: &dyn FeedbackPolicy<T>,
    t0: usize,
    horizon: usize,
    cost: &SaturatingCost,
    log: &mut JitterLog,
) -> Result<RolloutCost<T>> {
    let mut steps = Vec::with_capacity(horizon.saturating_sub(t0));
    let mut total = T::zero();
    let mut cost_log = JitterLog::default();
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
            Ok(())
        },
    )?;
    log.merge(&cost_log);
    Ok(RolloutCost { total, steps })
}
