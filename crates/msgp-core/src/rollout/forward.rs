//! Free-running moment-matching rollouts over the NARX window (paper section 3.3).
//!
//! The state is the joint Gaussian over the whole window `x̃_t` (see [`crate::narx`]). One step:
//! 1. moment-match the GP at `x̃_t ~ N(μ, Σ)`: `f ~ N(M, S)`, `Cov(x̃_t, f) = C` (with the
//!    linear prior mean, if any: [`crate::moments::mean`]);
//! 2. `x_{t+1} = f + ε_x`: mean `M`, covariance `S + Σ_x`, `Cov(x̃_t, x_{t+1}) = C`;
//! 3. the observation `y_{t+1} = x_{t+1} + ε_y ~ N(M, S + Σ_x + Σ_y)` is reported;
//! 4. the window shifts: `x_{t+1}` enters at lag 0, the oldest output and input lags drop out,
//!    and `u_{t+1}` enters: the measured input (open loop, zero variance) or the policy's output
//!    on `y_{t+1}` (closed loop, correlated with the window through the policy's `C`).
//!
//! The rollout starts at `t0 = max(l_y, l_u)` from the first `t0` measured samples: latent
//! outputs `x ~ N(y, Σ_y)` (independent), inputs as measured. The training loss can start it
//! from a smoothed window instead ([`crate::narx::start_window`]).

use nalgebra::{DMatrix, DVector};

use super::window::{Layout, StartState, StepMoments, gather, initial_window, predict_step};
use crate::data::Trajectory;
use crate::error::{MsgpError, Result};
use crate::gp::PreparedGp;
use crate::moments::MomentMatch;
use crate::narx::NarxSpec;
use crate::narx::start_window::StartWindow;
use crate::numeric::linalg::JitterLog;
use crate::numeric::scalar::Scalar;
use crate::optim::Flow;
use crate::policy::FeedbackPolicy;

/// Where the inputs of a rollout come from.
pub enum Control<'a, T: Scalar> {
    /// The measured inputs of the trajectory (open loop).
    FeedForward,
    /// A feedback policy acting on the predicted observations (closed loop).
    Feedback(&'a dyn FeedbackPolicy<T>),
}

impl<T: Scalar> std::fmt::Debug for Control<'_, T> {
    fn fmt(&self, f: &mut std::fmt::Formatter<'_>) -> std::fmt::Result {
        match self {
            Control::FeedForward => write!(f, "FeedForward"),
            Control::Feedback(_) => write!(f, "Feedback(..)"),
        }
    }
}

/// Predicted observation distribution at one time step.
#[derive(Clone, Debug)]
pub struct StepPrediction<T: Scalar> {
    /// Time index.
    pub t: usize,
    /// `E[y_t]` (d_y).
    pub mean: DVector<T>,
    /// `Cov[y_t]` (d_y × d_y), process and observation noise included.
    pub cov: DMatrix<T>,
}

/// Runs a rollout over `t0..horizon`, calling `visit` with each step's observation prediction.
///
/// `traj` supplies the first `t0` samples and, open loop, the inputs up to `horizon − 2`.
pub fn rollout<T: MomentMatch>(
    gp: &PreparedGp<T>,
    spec: &NarxSpec,
    traj: &Trajectory,
    control: &Control<'_, T>,
    horizon: usize,
    log: &mut JitterLog,
    visit: impl FnMut(StepPrediction<T>) -> Result<()>,
) -> Result<()> {
    rollout_started(
        gp,
        spec,
        traj,
        control,
        horizon,
        StartWindow::Measured,
        log,
        None,
        visit,
    )
}

/// A widening of each step's reported output covariance that is not fed back (the correlated
/// function uncertainty, [`super::function_uncertainty`]): it sees the window and the step's
/// moments, and adds to the observation covariance `ycov` only.
pub(crate) trait Widen<T: Scalar> {
    /// Adds to `ycov` at the window whose mean is `mu` and moments `mm`.
    fn widen(
        &mut self,
        mu: &DVector<T>,
        mm: &crate::moments::Moments<T>,
        ycov: &mut DMatrix<T>,
    ) -> Result<()>;
}

/// [`rollout`] from the start `how` (the training loss's [`PreparedGp::start`]): predictions
/// begin at [`TrajectoryStart::t0`]. `widen`, if any, adds to each step's reported covariance
/// ([`Widen`]).
#[allow(clippy::too_many_arguments)]
pub(crate) fn rollout_started<T: MomentMatch>(
    gp: &PreparedGp<T>,
    spec: &NarxSpec,
    traj: &Trajectory,
    control: &Control<'_, T>,
    horizon: usize,
    how: StartWindow,
    log: &mut JitterLog,
    widen: Option<&mut dyn Widen<T>>,
    mut visit: impl FnMut(StepPrediction<T>) -> Result<()>,
) -> Result<()> {
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
    let first = initial_window(gp, spec, traj, how)?;
    let t0 = first.t0;
    let needed_u = match control {
        Control::FeedForward => horizon.saturating_sub(1),
        Control::Feedback(p) => {
            if p.input_dim() != du {
                return Err(MsgpError::Shape(format!(
                    "policy produces {} inputs, the model has {}",
                    p.input_dim(),
                    du
                )));
            }
            t0
        }
    };
    if traj.len() < t0 || traj.u.nrows() < needed_u {
        return Err(MsgpError::Data(format!(
            "rollout to {horizon} needs {} initial samples and {needed_u} inputs; trajectory has {}",
            t0,
            traj.len()
        )));
    }

    let policy = match control {
        Control::FeedForward => None,
        Control::Feedback(p) => Some(*p),
    };
    let start = first.state(policy, traj)?;
    rollout_from_widened(
        gp,
        spec,
        &start,
        control,
        Some(&traj.u),
        t0,
        horizon,
        log,
        widen,
        |p| visit(p).map(|()| Flow::Continue),
    )
}

/// Runs a rollout from a Gaussian start state over `t0..horizon`. Open loop, `inputs` (rows are
/// absolute time steps) supplies `u_t` for `t0 ≤ t < horizon − 1`. `visit` sees every step's
/// prediction; [`Flow::Stop`] ends the rollout there (a bounded cost that is already too
/// high, [`crate::policy_search::PolicyProblem::evaluate_bounded`]).
#[allow(clippy::too_many_arguments)]
pub fn rollout_from<T: MomentMatch>(
    gp: &PreparedGp<T>,
    spec: &NarxSpec,
    start: &StartState<T>,
    control: &Control<'_, T>,
    inputs: Option<&DMatrix<f64>>,
    t0: usize,
    horizon: usize,
    log: &mut JitterLog,
    visit: impl FnMut(StepPrediction<T>) -> Result<Flow>,
) -> Result<()> {
    rollout_from_widened(
        gp, spec, start, control, inputs, t0, horizon, log, None, visit,
    )
}

/// [`rollout_from`] whose reported covariances `widen` adds to.
#[allow(clippy::too_many_arguments)]
fn rollout_from_widened<T: MomentMatch>(
    gp: &PreparedGp<T>,
    spec: &NarxSpec,
    start: &StartState<T>,
    control: &Control<'_, T>,
    inputs: Option<&DMatrix<f64>>,
    t0: usize,
    horizon: usize,
    log: &mut JitterLog,
    mut widen: Option<&mut dyn Widen<T>>,
    mut visit: impl FnMut(StepPrediction<T>) -> Result<Flow>,
) -> Result<()> {
    let d = spec.input_dim();
    let (dy, du) = (spec.dy, spec.du);
    let ds = match control {
        Control::FeedForward => 0,
        Control::Feedback(p) => p.state_dim(),
    };
    if start.mean.len() != d + ds || start.cov.shape() != (d + ds, d + ds) {
        return Err(MsgpError::Shape(format!(
            "start state has {} entries; window and policy state need {}",
            start.mean.len(),
            d + ds
        )));
    }
    if let Control::FeedForward = control {
        let rows = inputs.map_or(0, |u| u.nrows());
        if horizon > t0 + 1 && rows + 1 < horizon {
            return Err(MsgpError::Data(format!(
                "an open-loop rollout to {horizon} needs inputs up to step {}; {rows} given",
                horizon - 2
            )));
        }
    }
    let mut mu = start.mean.clone();
    let mut sigma = start.cov.clone();
    let layout = Layout { d, ds, dy, du };
    let sel = layout.gather_map(spec);

    for t in t0..horizon {
        let wmu = mu.rows(0, d).into_owned();
        let wsigma = sigma.view((0, 0), (d, d)).into_owned();
        let StepMoments { mm, xcov, ycov } =
            predict_step(gp, &wmu, &wsigma, "rollout prediction", t, log)?;
        let mut reported = ycov.clone();
        if let Some(w) = widen.as_deref_mut() {
            w.widen(&wmu, &mm, &mut reported)?;
        }
        let flow = visit(StepPrediction {
            t,
            mean: mm.mean.clone(),
            cov: reported,
        })?;
        if flow == Flow::Stop || t + 1 >= horizon {
            break;
        }
        let (mut amu, mut acov) = layout.augmented(&mu, &sigma, &mm.mean, &mm.v, &xcov);
        match control {
            Control::FeedForward => {
                if let Some(u) = inputs {
                    layout.set_measured_input(&mut amu, u, t);
                }
            }
            Control::Feedback(policy) => {
                let (qm, qc) = layout.policy_input(&amu, &acov, &ycov);
                let pm = policy.moments(&qm, &qc)?;
                layout.set_policy_output(&mut amu, &mut acov, &pm);
            }
        }
        (mu, sigma) = gather(&amu, &acov, &sel);
    }
    Ok(())
}

/// Collects every step of a rollout.
pub fn simulate<T: MomentMatch>(
    gp: &PreparedGp<T>,
    spec: &NarxSpec,
    traj: &Trajectory,
    control: &Control<'_, T>,
    horizon: usize,
    log: &mut JitterLog,
) -> Result<Vec<StepPrediction<T>>> {
    let mut out = Vec::with_capacity(horizon.saturating_sub(spec.warmup()));
    rollout(gp, spec, traj, control, horizon, log, |p| {
        out.push(p);
        Ok(())
    })?;
    Ok(out)
}
