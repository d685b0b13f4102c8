//! The rollout's state: the Gaussian window a measured trajectory starts from, the augmented
//! vector of one step (window, policy state, new output, new input) and the shift to the next
//! window. Shared by the forward rollout ([`super::forward`]) and its adjoint.

use nalgebra::{DMatrix, DVector};

use crate::data::Trajectory;
use crate::error::{MsgpError, Result};
use crate::gp::PreparedGp;
use crate::moments::mean::add_linear_mean;
use crate::moments::{MomentMatch, Moments, moment_match};
use crate::narx::NarxSpec;
use crate::narx::start_window::StartWindow;
use crate::numeric::linalg::{JitterLog, symmetrize};
use crate::numeric::scalar::{Scalar, c};
use crate::policy::{FeedbackPolicy, PolicyMoments};

/// The Gaussian state a rollout starts from: the window `x̃_{t0−1}` followed by the policy's
/// state (closed loop), in normalised units.
#[derive(Clone, Debug)]
pub struct StartState<T: Scalar> {
    /// Mean (D + d_p).
    pub mean: DVector<T>,
    /// Covariance.
    pub cov: DMatrix<T>,
}

/// The Gaussian window a measured trajectory's rollout starts from.
pub(crate) struct TrajectoryStart<T: Scalar> {
    /// First predicted step: `max(l_y, l_u)` from the measured window, the smoother's sample
    /// count from a smoothed one.
    pub t0: usize,
    /// Window mean (D).
    pub mean: DVector<T>,
    /// Window covariance (D × D).
    pub cov: DMatrix<T>,
    /// The output lags' covariance per unit `σ_{y,j}²`, the same for every output `j`
    /// (l_y × l_y): the identity for the measured window, `H Hᵀ` for a smoothed one.
    pub pattern: DMatrix<f64>,
}

impl<T: Scalar> TrajectoryStart<T> {
    /// The rollout's start state: this window, then (closed loop) the policy's state from the
    /// measured samples before `t0`.
    pub(crate) fn state(
        &self,
        policy: Option<&dyn FeedbackPolicy<T>>,
        traj: &Trajectory,
    ) -> Result<StartState<T>> {
        let d = self.mean.len();
        let ds = policy.map_or(0, |p| p.state_dim());
        let mut mean = DVector::<T>::zeros(d + ds);
        let mut cov = DMatrix::<T>::zeros(d + ds, d + ds);
        mean.rows_mut(0, d).copy_from(&self.mean);
        cov.view_mut((0, 0), (d, d)).copy_from(&self.cov);
        if let Some(p) = policy {
            let p0 = p.initial_state(&traj.y, &traj.u, self.t0);
            if p0.len() != ds {
                return Err(MsgpError::Shape(format!(
                    "policy initial state has {} entries, its state dimension is {ds}",
                    p0.len()
                )));
            }
            for k in 0..ds {
                mean[d + k] = c(p0[k]);
            }
        }
        Ok(StartState { mean, cov })
    }
}

/// The window at time `t0 − 1`: latent outputs from the measured samples `N(y, σ_y²)`
/// (independent) or, under [`StartWindow::Smoothed`], from the smoother `N(H y, σ_y² H Hᵀ)`;
/// inputs as measured (zero variance). Fails on a trajectory shorter than the window.
pub(crate) fn initial_window<T: Scalar>(
    gp: &PreparedGp<T>,
    spec: &NarxSpec,
    traj: &Trajectory,
    how: StartWindow,
) -> Result<TrajectoryStart<T>> {
    if traj.len() < spec.warmup() || traj.u.nrows() < spec.warmup() {
        return Err(MsgpError::Data(format!(
            "a rollout needs {} initial samples with their inputs; the trajectory has {} outputs \
             and {} inputs",
            spec.warmup(),
            traj.len(),
            traj.u.nrows()
        )));
    }
    let d = spec.input_dim();
    let smoother = how.smoother(spec.warmup(), spec.ly, traj.len().min(traj.u.nrows()));
    let t0 = smoother.as_ref().map_or(spec.warmup(), |s| s.samples);
    let pattern = smoother.as_ref().map_or_else(
        || DMatrix::identity(spec.ly, spec.ly),
        |s| s.pattern.clone(),
    );
    let mut mu = DVector::<T>::zeros(d);
    let mut sigma = DMatrix::<T>::zeros(d, d);
    for j in 0..spec.dy {
        let smoothed = smoother.as_ref().map(|s| s.window(&traj.y, j));
        for k in 0..spec.ly {
            let i = spec.y_index(k, j);
            mu[i] = c(smoothed.as_ref().map_or(traj.y[(t0 - 1 - k, j)], |w| w[k]));
            for k2 in 0..spec.ly {
                sigma[(i, spec.y_index(k2, j))] = gp.outputs[j].sy2 * c::<T>(pattern[(k, k2)]);
            }
        }
    }
    for k in 0..spec.lu {
        for j in 0..spec.du {
            mu[spec.u_index(k, j)] = c(traj.u[(t0 - 1 - k, j)]);
        }
    }
    Ok(TrajectoryStart {
        t0,
        mean: mu,
        cov: sigma,
        pattern,
    })
}

/// Positions in the augmented vector `[x̃_t (D), p_t (d_p), x_{t+1} (d_y), u_{t+1} (d_u),
/// p_{t+1} (d_p)]` of one step: the current state (window and policy state), the new latent
/// output, and the policy's output.
#[derive(Clone, Copy, Debug)]
pub(crate) struct Layout {
    pub d: usize,
    pub ds: usize,
    pub dy: usize,
    pub du: usize,
}

impl Layout {
    /// Size of the current state `[x̃_t, p_t]`.
    pub fn n(&self) -> usize {
        self.d + self.ds
    }
    /// Start of `x_{t+1}`.
    pub fn x_slot(&self) -> usize {
        self.n()
    }
    /// Start of `u_{t+1}` (followed by `p_{t+1}`).
    pub fn u_slot(&self) -> usize {
        self.n() + self.dy
    }
    /// Size of the augmented vector.
    pub fn len(&self) -> usize {
        self.u_slot() + self.du + self.ds
    }

    /// Where each entry of the next state `[x̃_{t+1}, p_{t+1}]` comes from.
    pub fn gather_map(&self, spec: &NarxSpec) -> Vec<usize> {
        let mut sel: Vec<usize> = spec
            .shift_map()
            .into_iter()
            .map(|i| if i < self.d { i } else { i + self.ds })
            .collect();
        sel.extend((0..self.ds).map(|k| self.u_slot() + self.du + k));
        sel
    }

    /// Augmented moments with the policy slots left at zero; `v` is the moment-matching
    /// `Σ_w⁻¹ Cov(x̃, f)`, so `Cov([x̃; p], x_{t+1}) = Cov([x̃; p], x̃) V`.
    pub fn augmented<T: Scalar>(
        &self,
        mu: &DVector<T>,
        sigma: &DMatrix<T>,
        mean: &DVector<T>,
        v: &DMatrix<T>,
        xcov: &DMatrix<T>,
    ) -> (DVector<T>, DMatrix<T>) {
        let (n, dy, x) = (self.n(), self.dy, self.x_slot());
        let len = self.len();
        let mut amu = DVector::<T>::zeros(len);
        let mut acov = DMatrix::<T>::zeros(len, len);
        amu.rows_mut(0, n).copy_from(mu);
        amu.rows_mut(x, dy).copy_from(mean);
        acov.view_mut((0, 0), (n, n)).copy_from(sigma);
        let zx = sigma.columns(0, self.d) * v;
        acov.view_mut((0, x), (n, dy)).copy_from(&zx);
        acov.view_mut((x, 0), (dy, n)).copy_from(&zx.transpose());
        acov.view_mut((x, x), (dy, dy)).copy_from(xcov);
        (amu, acov)
    }

    /// Sets the slots of `u_{t+1}` to the measured input (row `t` of `inputs`, absolute time
    /// steps) with zero variance: the augmented covariance already has those rows at zero.
    pub fn set_measured_input<T: Scalar>(
        &self,
        amu: &mut DVector<T>,
        inputs: &DMatrix<f64>,
        t: usize,
    ) {
        for j in 0..self.du {
            amu[self.u_slot() + j] = c(inputs[(t, j)]);
        }
    }

    /// Moments of the policy input `q = [y_{t+1}; p_t]` (`ycov` includes observation noise).
    pub fn policy_input<T: Scalar>(
        &self,
        amu: &DVector<T>,
        acov: &DMatrix<T>,
        ycov: &DMatrix<T>,
    ) -> (DVector<T>, DMatrix<T>) {
        let (dy, ds, x, d) = (self.dy, self.ds, self.x_slot(), self.d);
        let mut qm = DVector::<T>::zeros(dy + ds);
        let mut qc = DMatrix::<T>::zeros(dy + ds, dy + ds);
        qm.rows_mut(0, dy).copy_from(&amu.rows(x, dy));
        qm.rows_mut(dy, ds).copy_from(&amu.rows(d, ds));
        qc.view_mut((0, 0), (dy, dy)).copy_from(ycov);
        qc.view_mut((0, dy), (dy, ds))
            .copy_from(&acov.view((x, d), (dy, ds)));
        qc.view_mut((dy, 0), (ds, dy))
            .copy_from(&acov.view((d, x), (ds, dy)));
        qc.view_mut((dy, dy), (ds, ds))
            .copy_from(&acov.view((d, d), (ds, ds)));
        (qm, qc)
    }

    /// Fills the policy slots: `Cov(z, o) = Cov(z, q) C` for `z` in `[x̃_t, p_t, x_{t+1}]`
    /// (observation noise is independent of every `z`, so `Cov(z, y_{t+1}) = Cov(z, x_{t+1})`).
    pub fn set_policy_output<T: Scalar>(
        &self,
        amu: &mut DVector<T>,
        acov: &mut DMatrix<T>,
        pm: &PolicyMoments<T>,
    ) {
        let (dy, ds, x, d, u) = (self.dy, self.ds, self.x_slot(), self.d, self.u_slot());
        let no = self.du + ds;
        let zq = {
            let mut m = DMatrix::<T>::zeros(u, dy + ds);
            m.view_mut((0, 0), (u, dy))
                .copy_from(&acov.view((0, x), (u, dy)));
            m.view_mut((0, dy), (u, ds))
                .copy_from(&acov.view((0, d), (u, ds)));
            m
        };
        let cross = zq * &pm.c;
        amu.rows_mut(u, no).copy_from(&pm.mean);
        acov.view_mut((0, u), (u, no)).copy_from(&cross);
        acov.view_mut((u, 0), (no, u)).copy_from(&cross.transpose());
        acov.view_mut((u, u), (no, no)).copy_from(&pm.cov);
    }
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

/// One step's prediction from the window `x̃_t ~ N(μ, Σ)` (steps 1–2 of [`super::forward`]):
/// the moments of `f` (with the linear prior mean, if any), `Cov[x_{t+1}]` and `Cov[y_{t+1}]`.
pub(crate) struct StepMoments<T: Scalar> {
    /// `f`'s moments: `E[x_{t+1}] = mm.mean`, `Cov(x̃_t, x_{t+1}) = mm.io_cov = Σ mm.v`.
    pub mm: Moments<T>,
    /// `Cov[x_{t+1}] = S + Σ_x`.
    pub xcov: DMatrix<T>,
    /// `Cov[y_{t+1}] = S + Σ_x + Σ_y`.
    pub ycov: DMatrix<T>,
}

/// Moment-matches the GP (plus the linear prior mean) at the window `N(wmu, wsigma)` and adds
/// the noises; fails on a non-finite prediction, naming `what` at step `t`. The one prediction
/// step of the forward rollout and of the filter ([`crate::loss::filter`]).
pub(crate) fn predict_step<T: MomentMatch>(
    gp: &PreparedGp<T>,
    wmu: &DVector<T>,
    wsigma: &DMatrix<T>,
    what: &str,
    t: usize,
    log: &mut JitterLog,
) -> Result<StepMoments<T>> {
    let mut mm = moment_match(gp, wmu, wsigma, log)?;
    if let Some(a) = &gp.linear_mean {
        add_linear_mean(a, wmu, wsigma, &mut mm);
    }
    let (xcov, ycov) = noisy_covariances(gp, &mm.cov);
    if mm.mean.iter().any(|v| !v.re().is_finite()) || ycov.iter().any(|v| !v.re().is_finite()) {
        return Err(MsgpError::NonFinite(format!("{what} at step {t}")));
    }
    Ok(StepMoments { mm, xcov, ycov })
}

/// `Cov[x_{t+1}] = S + Σ_x` and `Cov[y_{t+1}] = S + Σ_x + Σ_y` from the latent `S`.
pub(crate) fn noisy_covariances<T: Scalar>(
    gp: &PreparedGp<T>,
    s: &DMatrix<T>,
) -> (DMatrix<T>, DMatrix<T>) {
    let mut xcov = s.clone();
    for (j, o) in gp.outputs.iter().enumerate() {
        xcov[(j, j)] += o.sx2;
    }
    let mut ycov = xcov.clone();
    for (j, o) in gp.outputs.iter().enumerate() {
        ycov[(j, j)] += o.sy2;
    }
    (xcov, ycov)
}
