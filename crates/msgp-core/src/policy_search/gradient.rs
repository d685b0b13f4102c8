//! The gradient of a closed-loop rollout's expected cost with respect to the policy's
//! parameters, by the adjoint sweep with the expected saturating cost as each step's score
//! ([`closed_loop_cost_gradient`]; a few rollouts' work whatever the number of parameters).
//! Forward-mode duals through the whole rollout are its reference
//! ([`super::policy_gradient_duals`]).

use nalgebra::{DMatrix, DVector};

use super::cost::SaturatingCost;
use crate::error::{MsgpError, Result};
use crate::gp::PreparedGp;
use crate::moments::vjp::GpAdjoint;
use crate::narx::NarxSpec;
use crate::numeric::dual::moments_gradient;
use crate::numeric::linalg::{JitterLog, JitterPolicy};
use crate::policy::FeedbackPolicy;
use crate::rollout::StartState;
use crate::rollout::adjoint::{AdjointPolicy, Predicted, StepScore, rollout_adjoint};
pub use crate::rollout::adjoint::{DualPolicyMap, PolicyVjp};

/// The policy search's step score: the expected saturating cost `E[c(y_t)]` of the predicted
/// observation.
struct ExpectedCost<'a>(&'a SaturatingCost);

impl StepScore for ExpectedCost<'_> {
    fn value(&self, y: &Predicted<'_>, log: &mut JitterLog) -> Result<f64> {
        Ok(self.0.moments(y.mean, y.cov, y.jitter, log)?.mean)
    }

    fn vjp(&self, y: &Predicted<'_>) -> Result<(DVector<f64>, DMatrix<f64>)> {
        cost_vjp(self.0, y.mean, y.cov, y.jitter)
    }
}

/// Gradient of the expected cost `E[c(y)]`, `y ~ N(mean, cov)`, with respect to `mean` and
/// (symmetrised) `cov`, by forward-mode duals (`d_y + d_y²` directions).
fn cost_vjp(
    cost: &SaturatingCost,
    mean: &DVector<f64>,
    cov: &DMatrix<f64>,
    jitter: &JitterPolicy,
) -> Result<(DVector<f64>, DMatrix<f64>)> {
    let (gm, gc) = moments_gradient(mean, cov, |m, s| {
        let mut log = JitterLog::default();
        Ok(cost.moments(m, s, jitter, &mut log)?.mean)
    })?;
    Ok((gm, (&gc + gc.transpose()) * 0.5))
}

/// Value and gradient, with respect to the policy parameters `θ`, of the expected cost
/// `Σ_t E[c(y_t)]` of a closed-loop rollout of `policy` from `start` over `t0..horizon`
/// ([`super::closed_loop_cost`]), by the adjoint sweep: reverse mode over the
/// rollout, forward-mode duals only inside each step's small policy and cost maps. It costs a
/// few rollouts whatever `|θ|`; duals over `θ` through the whole rollout are the reference it
/// is tested against. `moments` is the same policy's moment map in dual numbers; `vjp`, when
/// given, its vector–Jacobian product in closed form (used instead of duals through `moments`).
#[allow(clippy::too_many_arguments)]
pub fn closed_loop_cost_gradient(
    gp: &PreparedGp<f64>,
    spec: &NarxSpec,
    start: &StartState<f64>,
    policy: &dyn FeedbackPolicy<f64>,
    moments: &DualPolicyMap<'_>,
    vjp: Option<&PolicyVjp<'_>>,
    theta: &[f64],
    t0: usize,
    horizon: usize,
    cost: &SaturatingCost,
    log: &mut JitterLog,
) -> Result<(f64, Vec<f64>)> {
    let (m, d, e) = (gp.pseudo_inputs.nrows(), gp.input_dim(), gp.output_dim());
    if d != spec.input_dim() || e != spec.dy || policy.input_dim() != spec.du {
        return Err(MsgpError::Shape(format!(
            "GP ({d} inputs, {e} outputs), NARX spec ({} inputs, {} outputs) and policy ({} \
             inputs) do not fit together",
            spec.input_dim(),
            spec.dy,
            policy.input_dim()
        )));
    }
    // the GP's own adjoints are not needed here; they accumulate in a scratch record
    let mut scratch = GpAdjoint::zeros(m, d, e);
    let adjoint_policy = AdjointPolicy {
        policy,
        moments,
        vjp,
        theta,
    };
    let out = rollout_adjoint(
        gp,
        spec,
        start,
        &ExpectedCost(cost),
        None,
        Some(&adjoint_policy),
        t0,
        horizon,
        &mut scratch,
        log,
    )?;
    Ok((out.total, out.theta))
}
