//! Free-running moment-matching rollouts over the NARX window (paper section 3.3).
//!
//! The state is the joint Gaussian over the whole window `x̃_t` (see [`crate::narx`]). One step:
//! 1. moment-match the GP at `x̃_t ~ N(μ, Σ)`: `f ~ N(M, S)`, `Cov(x̃_t, f) = C`;
//! 2. `x_{t+1} = f + ε_x`: mean `M`, covariance `S + Σ_x`, `Cov(x̃_t, x_{t+1}) = C`;
//! 3. the observation `y_{t+1} = x_{t+1} + ε_y ~ N(M, S + Σ_x + Σ_y)` is reported;
//! 4. the window shifts: `x_{t+1}` enters at lag 0, the oldest output and input lags drop out,
//!    and `u_{t+1}` enters: the measured input (open loop, zero variance) or the policy's output
//!    on `y_{t+1}` (closed loop, correlated with the window through the policy's `C`).
//!
//! The rollout starts at `t0 = max(l_y, l_u)` from the first `t0` measured samples: latent
//! outputs `x ~ N(y, Σ_y)` (independent), inputs as measured.

use nalgebra::{DMatrix, DVector};

use crate::error::{MsgpError, Result};
use crate::gp::PreparedGp;
use crate::linalg::{JitterLog, symmetrize};
use crate::moments::moment_match;
use crate::narx::NarxSpec;
use crate::policy::{FeedbackPolicy, PolicyMoments};
use crate::scalar::{Scalar, c};
use crate::trajectory::Trajectory;

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
pub fn rollout<T: Scalar>(
    gp: &PreparedGp<T>,
    spec: &NarxSpec,
    traj: &Trajectory,
    control: &Control<'_, T>,
    horizon: usize,
    log: &mut JitterLog,
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
    let t0 = spec.warmup();
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

    let (mut mu, mut sigma) = initial_window(gp, spec, traj);
    let sel = spec.shift_map();

    for t in t0..horizon {
        let mm = moment_match(gp, &mu, &sigma, log)?;
        let mut xcov = mm.cov.clone();
        for j in 0..dy {
            xcov[(j, j)] += gp.outputs[j].sx2;
        }
        let mut ycov = xcov.clone();
        for j in 0..dy {
            ycov[(j, j)] += gp.outputs[j].sy2;
        }
        if mm.mean.iter().any(|v| !v.re().is_finite()) || ycov.iter().any(|v| !v.re().is_finite()) {
            return Err(MsgpError::NonFinite(format!(
                "rollout prediction at step {t}"
            )));
        }
        let next_needed = t + 1 < horizon;
        let mean = mm.mean.clone();
        visit(StepPrediction {
            t,
            mean: mean.clone(),
            cov: ycov.clone(),
        })?;
        if !next_needed {
            break;
        }

        let (mut amu, mut acov) = augmented(&mu, &sigma, &mm.mean, &mm.io_cov, &xcov, du);
        match control {
            Control::FeedForward => {
                for j in 0..du {
                    amu[d + dy + j] = c(traj.u[(t, j)]);
                }
            }
            Control::Feedback(policy) => {
                let pm = policy.moments(&mean, &ycov)?;
                set_policy_input(&mut amu, &mut acov, d, dy, &pm);
            }
        }
        (mu, sigma) = gather(&amu, &acov, &sel);
    }
    Ok(())
}

/// Moments of the window at time `t0 − 1` from the first `t0` measured samples: latent outputs
/// `N(y, σ_y²)` (independent), inputs as measured (zero variance).
pub(crate) fn initial_window<T: Scalar>(
    gp: &PreparedGp<T>,
    spec: &NarxSpec,
    traj: &Trajectory,
) -> (DVector<T>, DMatrix<T>) {
    let d = spec.input_dim();
    let t0 = spec.warmup();
    let mut mu = DVector::<T>::zeros(d);
    let mut sigma = DMatrix::<T>::zeros(d, d);
    for k in 0..spec.ly {
        for j in 0..spec.dy {
            let i = spec.y_index(k, j);
            mu[i] = c(traj.y[(t0 - 1 - k, j)]);
            sigma[(i, i)] = gp.outputs[j].sy2;
        }
    }
    for k in 0..spec.lu {
        for j in 0..spec.du {
            mu[spec.u_index(k, j)] = c(traj.u[(t0 - 1 - k, j)]);
        }
    }
    (mu, sigma)
}

/// Joint moments of `[x̃_t, x_{t+1}, u_{t+1}]`, with the input slot left at zero.
pub(crate) fn augmented<T: Scalar>(
    mu: &DVector<T>,
    sigma: &DMatrix<T>,
    mean: &DVector<T>,
    io_cov: &DMatrix<T>,
    xcov: &DMatrix<T>,
    du: usize,
) -> (DVector<T>, DMatrix<T>) {
    let (d, dy) = (mu.len(), mean.len());
    let n = d + dy + du;
    let mut amu = DVector::<T>::zeros(n);
    let mut acov = DMatrix::<T>::zeros(n, n);
    amu.rows_mut(0, d).copy_from(mu);
    amu.rows_mut(d, dy).copy_from(mean);
    acov.view_mut((0, 0), (d, d)).copy_from(sigma);
    acov.view_mut((0, d), (d, dy)).copy_from(io_cov);
    acov.view_mut((d, 0), (dy, d))
        .copy_from(&io_cov.transpose());
    acov.view_mut((d, d), (dy, dy)).copy_from(xcov);
    (amu, acov)
}

/// Fills the input slot of the augmented moments from a policy acting on `y_{t+1}`:
/// `Cov(z, u) = Cov(z, x_{t+1}) C` for `z` in `[x̃_t, x_{t+1}]`.
pub(crate) fn set_policy_input<T: Scalar>(
    amu: &mut DVector<T>,
    acov: &mut DMatrix<T>,
    d: usize,
    dy: usize,
    pm: &PolicyMoments<T>,
) {
    let du = pm.mean.len();
    let cross = acov.view((0, d), (d + dy, dy)) * &pm.c;
    amu.rows_mut(d + dy, du).copy_from(&pm.mean);
    acov.view_mut((0, d + dy), (d + dy, du)).copy_from(&cross);
    acov.view_mut((d + dy, 0), (du, d + dy))
        .copy_from(&cross.transpose());
    acov.view_mut((d + dy, d + dy), (du, du)).copy_from(&pm.cov);
}

/// The next window's moments, gathered from the augmented ones by [`NarxSpec::shift_map`].
pub(crate) fn gather<T: Scalar>(
    amu: &DVector<T>,
    acov: &DMatrix<T>,
    sel: &[usize],
) -> (DVector<T>, DMatrix<T>) {
    let d = sel.len();
    let mu = DVector::from_fn(d, |i, _| amu[sel[i]]);
    let mut sigma = DMatrix::from_fn(d, d, |i, j| acov[(sel[i], sel[j])]);
    symmetrize(&mut sigma);
    (mu, sigma)
}

/// Collects every step of a rollout.
pub fn simulate<T: Scalar>(
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
