//! The filter likelihood: the joint density of a whole observed trajectory under the GP-NARX
//! window model, by assumed-density (moment-matched) Gaussian filtering (Deisenroth, Huber &
//! Hanebeck 2009, "Analytic moment-based Gaussian process filtering").
//!
//! ## Why
//! Eq. (4) of the paper asks for `−log p(y_{t0:T} | u, x̃_{t0−1})`, the *joint* density of the
//! observations. The free-run loss of [`super::msgp_loss`] sums `−log N(y_t; M_t, V_t)` over the
//! marginals of a free simulation: a product of per-step marginals, which drops the correlation
//! between the observations (`y_t` and `y_{t+1}` share the window they are predicted from). The
//! joint density of any sequence factorises exactly into one-step conditionals, the
//! prediction-error decomposition
//! `−log p(y_{t0:T} | …) = Σ_t −log p(y_t | y_{t0:t−1}, u, x̃_{t0−1})`,
//! and for a Gaussian state model each factor is Gaussian in the innovation. This module computes
//! it with the window model's own Gaussian state, conditioned on every observation as it comes.
//!
//! ## The filter
//! The state is the joint Gaussian over the window `x̃_t` (latent outputs at lags `0..l_y`,
//! inputs at lags `0..l_u`; [`crate::narx`]). It starts, as a rollout from measured data, from
//! the window at `t0 − 1`, `t0 = max(l_y, l_u)`: latent outputs `N(y, σ_y²)` independent, inputs
//! as measured with zero variance ([`StartWindow::Measured`]). This is the diffuse-prior start of
//! the linear Kalman filter of [`crate::fit::linear_kf`]: a flat prior on the first window's latent
//! outputs, conditioned on their measurements `y = x + ε_y`, is exactly `N(y, σ_y²)`; and both
//! score the same samples `y_{t0}, …, y_{T−1}`. Each step `t = t0, …, T−1`:
//! 1. *predict* (the forward rollout's steps 1–2, [`crate::rollout::forward`]): moment-match the
//!    GP (and the linear prior mean) at `x̃_{t−1} | y_{<t}`, so `x_t = f + ε_x` has mean `M`,
//!    covariance `S + Σ_x` and `Cov(x̃_{t−1}, x_t) = C`; shift the window, with the input `u_t`
//!    entering as measured;
//! 2. *score*: the innovation `e = y_t − M`, `S_inn = S + Σ_x + Σ_y`, adds `−log N(e; 0, S_inn)`;
//! 3. *update*: the observation `y_t = H x̃_t + ε_y` is linear (`H` picks the lag-0 latent
//!    outputs), so conditioning the window's Gaussian on it is an exact Kalman update with gain
//!    `K = P Hᵀ S_inn⁻¹`: `μ ← μ + K e`, `P ← (I − KH) P (I − KH)ᵀ + K Σ_y Kᵀ` (Joseph form,
//!    symmetrised).
//!
//! The only approximation is the moment matching of step 1 (as in the free run); for the linear
//! model without GP it is exact, and the filter is the Kalman filter (`tests/filter.rs`). Its
//! first prediction is the free run's first prediction; from the second on, the free run keeps
//! predicting from its unconditioned window and its variances grow, the filter's stay at the
//! one-step level.
//!
//! Inputs always enter as measured, also for feedback episodes: the recorded commands are what
//! the policy (a function of the measured outputs and its own state) produced, so `u_{<t}` is a
//! function of `y_{<t}` and conditioning on it changes no factor of the decomposition.
//!
//! The code is generic over [`MomentMatch`] (f64, or forward-mode duals for gradients). Its
//! exact reverse-mode gradient, what a fit trains on, is [`super::filter_loss_and_gradient`] (the
//! adjoint sweep of `filter_gradient`, which runs this filter's steps and `kalman_update`).

use nalgebra::{DMatrix, DVector};

use super::{LossValue, factored_nll, over_episodes};
use crate::data::Trajectory;
use crate::error::{MsgpError, Result};
use crate::gp::{GpConfig, GpParams, PreparedGp};
use crate::loss::Complexity;
use crate::moments::MomentMatch;
use crate::narx::NarxSpec;
use crate::narx::start_window::StartWindow;
use crate::numeric::linalg::{Cholesky, JitterLog, cholesky, symmetrize};
use crate::numeric::scalar::{Scalar, c};
use crate::rollout::Episode;
use crate::rollout::window::{Layout, StepMoments, gather, initial_window, predict_step};

/// The filter likelihood of one trajectory.
#[derive(Clone, Copy, Debug)]
pub struct FilterNll<T: Scalar> {
    /// `Σ_t −log p(y_t | y_{t0:t−1}, u)`, summed over the scored steps.
    pub nll: T,
    /// Number of scored steps (`T − t0`).
    pub steps: usize,
}

/// One filter step `t`, as [`filter_steps`] shows it: the Gaussian it predicted from, what it
/// predicted, the innovation and the conditioned window. All moments are in normalised units; the
/// window layout is [`NarxSpec::y_index`] / [`NarxSpec::u_index`].
#[derive(Clone, Copy, Debug)]
pub struct FilterStep<'a, T: Scalar> {
    /// The time step of the scored observation `y_t`.
    pub t: usize,
    /// `E[x̃_{t−1} | y_{<t}]`: the window predicted from (the start window at `t = t0`).
    pub window_mean: &'a DVector<T>,
    /// `Cov[x̃_{t−1} | y_{<t}]`.
    pub window_cov: &'a DMatrix<T>,
    /// `E[x_t | y_{<t}]`: the predicted latent output (d_y).
    pub x_mean: &'a DVector<T>,
    /// `Cov[x_t | y_{<t}] = S + Σ_x` (d_y × d_y).
    pub x_cov: &'a DMatrix<T>,
    /// `Cov[x̃_{t−1}, x_t | y_{<t}]` (D × d_y).
    pub cross_cov: &'a DMatrix<T>,
    /// `E[x̃_t | y_{<t}]`: the shifted window before the update.
    pub prior_mean: &'a DVector<T>,
    /// `Cov[x̃_t | y_{<t}]`.
    pub prior_cov: &'a DMatrix<T>,
    /// The innovation `y_t − E[x_t | y_{<t}]` (d_y).
    pub innovation: &'a DVector<T>,
    /// Its covariance `S + Σ_x + Σ_y` (d_y × d_y).
    pub innovation_cov: &'a DMatrix<T>,
    /// This step's term `−log N(innovation; 0, innovation_cov)`.
    pub nll: T,
    /// `E[x̃_t | y_{≤t}]`: the window after the update.
    pub filtered_mean: &'a DVector<T>,
    /// `Cov[x̃_t | y_{≤t}]`.
    pub filtered_cov: &'a DMatrix<T>,
}

/// The filter likelihood of `traj` (normalised units) under `gp`: see the module docs. Scores
/// `y_{t0}, …, y_{T−1}`, `t0 = spec.warmup()`.
pub fn filter_nll<T: MomentMatch>(
    gp: &PreparedGp<T>,
    spec: &NarxSpec,
    traj: &Trajectory,
    log: &mut JitterLog,
) -> Result<FilterNll<T>> {
    filter_steps(gp, spec, traj, log, |_| Ok(()))
}

/// [`filter_nll`], calling `visit` with every step's predicted and filtered moments.
pub fn filter_steps<T: MomentMatch>(
    gp: &PreparedGp<T>,
    spec: &NarxSpec,
    traj: &Trajectory,
    log: &mut JitterLog,
    mut visit: impl FnMut(&FilterStep<'_, T>) -> Result<()>,
) -> Result<FilterNll<T>> {
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
    traj.check(spec)?;
    let start = initial_window(gp, spec, traj, StartWindow::Measured)?;
    let layout = Layout { d, ds: 0, dy, du };
    let sel = layout.gather_map(spec);
    // the lag-0 latent outputs, which the observation picks, are the window's first d_y entries
    debug_assert!((0..dy).all(|j| spec.y_index(0, j) == j));
    let (mut mu, mut sigma) = (start.mean, start.cov);
    let mut nll = T::zero();
    let mut steps = 0usize;
    for t in start.t0..traj.len() {
        let StepMoments { mm, xcov, ycov } =
            predict_step(gp, &mu, &sigma, "filter prediction", t, log)?;
        let (mut amu, acov) = layout.augmented(&mu, &sigma, &mm.mean, &mm.v, &xcov);
        layout.set_measured_input(&mut amu, &traj.u, t);
        let cross = acov.view((0, layout.x_slot()), (d, dy)).into_owned();
        let (pmu, psigma) = gather(&amu, &acov, &sel);
        let up = kalman_update(gp, (&pmu, &psigma), &ycov, &mm.mean, traj, t, log)?;
        nll += up.nll;
        steps += 1;

        visit(&FilterStep {
            t,
            window_mean: &mu,
            window_cov: &sigma,
            x_mean: &mm.mean,
            x_cov: &xcov,
            cross_cov: &cross,
            prior_mean: &pmu,
            prior_cov: &psigma,
            innovation: &up.innovation,
            innovation_cov: &ycov,
            nll: up.nll,
            filtered_mean: &up.mean,
            filtered_cov: &up.cov,
        })?;
        (mu, sigma) = (up.mean, up.cov);
    }
    if !nll.re().is_finite() {
        return Err(MsgpError::NonFinite(
            "the filter likelihood is not finite".into(),
        ));
    }
    Ok(FilterNll { nll, steps })
}

/// Steps 2–3 of one filter step (see the module docs): the score of the observation and the
/// window conditioned on it.
pub(crate) struct KalmanUpdate<T: Scalar> {
    /// The factor of the innovation covariance `S_inn`.
    pub chol: Cholesky<T>,
    /// The innovation `e = y_t − M` (d_y).
    pub innovation: DVector<T>,
    /// `−log N(e; 0, S_inn)`.
    pub nll: T,
    /// The gain `K = P Hᵀ S_inn⁻¹` (D × d_y).
    pub gain: DMatrix<T>,
    /// `E[x̃_t | y_{≤t}] = μ_p + K e`.
    pub mean: DVector<T>,
    /// `Cov[x̃_t | y_{≤t}]`, Joseph form, symmetrised.
    pub cov: DMatrix<T>,
}

/// Scores `y_t` (row `t` of `traj.y`) under the prediction `x_t ~ N(x_mean, ·)` with innovation
/// covariance `ycov`, and conditions the predicted window `N(pmu, psigma)` on it (the lag-0
/// latent outputs are its first d_y entries). Shared by [`filter_steps`] and the filter's
/// adjoint sweep ([`super::filter_loss_and_gradient`]), so both compute the same bits.
pub(crate) fn kalman_update<T: Scalar>(
    gp: &PreparedGp<T>,
    (pmu, psigma): (&DVector<T>, &DMatrix<T>),
    ycov: &DMatrix<T>,
    x_mean: &DVector<T>,
    traj: &Trajectory,
    t: usize,
    log: &mut JitterLog,
) -> Result<KalmanUpdate<T>> {
    let (d, dy) = (pmu.len(), x_mean.len());
    let chol = cholesky(ycov, &gp.jitter, "the filter's innovation covariance")?;
    log.record(chol.jitter);
    let row = DVector::<T>::from_fn(dy, |j, _| c::<T>(traj.y[(t, j)]) - x_mean[j]);
    let nll = factored_nll(&chol, &row);
    // K = P Hᵀ S_inn⁻¹ (D × d_y)
    let pht = psigma.columns(0, dy).into_owned();
    let gain = chol.solve(&pht.transpose()).transpose();
    let mean = pmu + &gain * &row;
    // Joseph form: (I − KH) P (I − KH)ᵀ + K Σ_y Kᵀ
    let mut a = DMatrix::<T>::identity(d, d);
    let mut ksy = gain.clone();
    for (j, o) in gp.outputs.iter().enumerate() {
        for i in 0..d {
            a[(i, j)] -= gain[(i, j)];
            ksy[(i, j)] *= o.sy2;
        }
    }
    let mut cov = &a * psigma * a.transpose() + &ksy * gain.transpose();
    symmetrize(&mut cov);
    Ok(KalmanUpdate {
        chol,
        innovation: row,
        nll,
        gain,
        mean,
        cov,
    })
}

/// The filter counterpart of [`super::msgp_loss`]: the summed [`filter_nll`] of every episode
/// plus the complexity term. Every episode is filtered on its measured inputs (also feedback
/// episodes; see the module docs) from the measured start window, whatever `config.start` says.
pub fn filter_loss<T: MomentMatch>(
    params: &GpParams<T>,
    config: &GpConfig,
    spec: &NarxSpec,
    episodes: &[Episode],
    complexity: Complexity,
    log: &mut JitterLog,
) -> Result<LossValue<T>> {
    over_episodes(
        params,
        config,
        spec,
        episodes,
        complexity,
        log,
        |gp, ep, nll, steps, log| {
            let f = filter_nll(gp, spec, &ep.traj, log)?;
            *nll += f.nll;
            *steps += f.steps;
            Ok(())
        },
    )
}
