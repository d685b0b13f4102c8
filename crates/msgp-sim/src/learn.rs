//! PILCO with MSGP (or one-step GP-NARX) models on the simulated pendulum: learning to balance
//! from scratch (paper section 4.2).
//!
//! The loop: `random_rollouts` episodes of smooth random excitation → fit the model on every
//! episode so far (random ones feed-forward, policy ones in closed loop under the gains that ran
//! them, the paper's `L_fb`) → optimise the PID + PD gains on the model (expected saturating
//! cost of a closed-loop moment-matching rollout from rest, exact dual gradients) → run them on
//! the simulator for one episode → repeat. After every iteration the simulator's stability test
//! judges the gains; it is neither interaction time nor training data. Optionally, from the
//! second iteration on, an MSGP fit continues the previous model ([`LearnSettings::warm_start`]).
//!
//! Outputs are `[θ, x]` (measured), the input is the commanded acceleration; the modelled policy
//! is [`msgp_core::policy::PidPolicy`] with the sine saturation that the simulator's policy
//! applies when its gains say `saturation: sine`.

use std::ops::ControlFlow;

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use msgp_core::cost::SaturatingCost;
use msgp_core::fit::{
    FitProgress, FitSettings, TrainingEpisode, fit_episodes, fit_episodes_observed,
};
use msgp_core::gp::MeanFunction;
use msgp_core::integrator::Integrator;
use msgp_core::model::Method;
use msgp_core::policy::{PidPolicy, PolicySpec};
use msgp_core::policy_search::{PidMask, PolicyProblem, PolicySearchSettings, optimise_pid_scaled};
use msgp_core::trajectory::Trajectory;

use crate::controller::{
    Controller, ExcitationConfig, PidPdGains, PidPdPolicy, RandomExcitation, Saturation,
};
use crate::episode::{Episode, EpisodeConfig, run_episode};
use crate::error::SimError;
use crate::params::PendulumParams;
use crate::stability::{StabilityCriteria, stability_test};

/// Settings of the learning loop.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LearnSettings {
    /// Model training method (`Msgp` or the one-step `GpNarx` of standard PILCO).
    pub method: Method,
    /// Policy-learning iterations after the random rollouts.
    pub iterations: usize,
    /// Random episodes before the first policy.
    pub random_rollouts: usize,
    /// How many of the `random_rollouts` run a *random policy* instead of open-loop
    /// excitation: PID + PD gains drawn uniformly in `[0, 2 × gain_scale]` each (the box the
    /// first policy search's trust region spans), so that the first model sees the loop closed
    /// with gains of the kind the search will ask about. They enter the model loss under their
    /// gains (the paper's `L_fb`), like the loop's own episodes. 0 (the default): the paper's
    /// smooth random signals only. Whether a drawn gain set would pass the stability test is
    /// recorded ([`LearnOutcome::random_policies`]), so that luck is not read as learning.
    #[serde(default)]
    pub random_policies: usize,
    /// The smooth random signal of those episodes. Its band reaches 10 Hz: a NARX model at
    /// 50 Hz only learns how the pole answers quick changes of the command (the inputs' lags
    /// differ) if the first data have them, and every feedback policy makes them (its
    /// derivative term passes on measurement noise). With 0.1–2 Hz the input lags are nearly
    /// collinear and a fitted model may weight their differences arbitrarily (docs/design.md).
    #[serde(default = "learn_excitation")]
    pub excitation: ExcitationConfig,
    /// Length of every interaction episode \[s\].
    pub episode_seconds: f64,
    /// Horizon of the predicted rollouts the gains are optimised on \[s\]. Longer than an
    /// episode, so that the policy search sees the slow drift of the end effector that a
    /// 3 s episode hides but the 10 s stability test does not.
    pub policy_horizon_seconds: f64,
    /// Seed of everything random (episodes, excitation, fits, restarts).
    pub seed: u64,
    /// Model fit settings (history, inducing points, iterations). The default prior mean is
    /// linear (an ARX map under the GP, started by instrumental variables): with a zero mean the
    /// fitted models lose the pole's angular velocity (docs/design.md). The end effector is
    /// declared a double integrator ([`END_EFFECTOR_INTEGRATOR`]).
    pub fit: FitSettings,
    /// Policy optimisation settings. The default trust region (1 typical magnitude per
    /// iteration) keeps the new gains near the data the model was fitted to.
    pub search: PolicySearchSettings,
    /// Cost widths for `[θ, x]` (rad, m): `c = 1 − exp(−½ Σ (y_j / w_j)²)`.
    pub cost_widths: [f64; 2],
    /// Feed-forward (random-excitation) episodes enter the model loss as overlapping segments
    /// of this many samples (stride half of it); `None` keeps them whole. MSGP only. The pendulum is
    /// open-loop unstable: a free-running prediction from an episode's first samples carries no
    /// information after a second or so (initial uncertainty grows like `e^{3.5 t}`), and fitting
    /// the trajectory likelihood of whole falls distorts the dynamics (docs/design.md).
    pub ff_segment: Option<usize>,
    /// Feedback (policy) episodes enter the model loss as overlapping segments of this many
    /// samples (stride half of it), each under the gains that ran it; `None` (the default)
    /// keeps them whole, as the paper does. MSGP only. A feedback episode of weakly damped
    /// gains oscillates and falls; fitted whole, its trajectory likelihood can turn the
    /// model's pole into a damped oscillator (docs/design.md). A segment's modelled PID
    /// integral sums its own samples only; the controller's had run since the episode began
    /// (with the loop's integral gains, a small offset of the command).
    #[serde(default)]
    pub fb_segment: Option<usize>,
    /// Typical gain magnitudes `[kp_x, ki_x, kd_x, kp_θ, kd_θ]`: the first policy's gains and
    /// the optimiser's coordinate scales (units of the problem, not a solution).
    pub gain_scale: [f64; 5],
    /// Warm starts (MSGP and linear-kf): from the second iteration on, each fit continues the
    /// previous iteration's model for this many solver iterations ([`msgp_core::fit::refit_episodes`]: its
    /// normaliser, pseudo-inputs and parameters) instead of starting over from a one-step fit
    /// (linear-kf: from its two cold starts); `None` starts over every time (the default).
    /// MSGP warm starts make iterations 2–8 4.5–6× faster, but on the five Figure 4 seeds the
    /// later iterations measured worse (mean episode cost 36–97 against 28–65), so MSGP starts
    /// over by default. linear-kf warm starts kept every iteration at 2.0–2.8 s (5 s policy
    /// horizon) with the same seeds stable: [`LearnSettings::for_method`] turns them on for linear-kf
    /// ([`LINEAR_KF_WARM_START`]; BENCHMARKS.md).
    #[serde(default)]
    pub warm_start: Option<usize>,
}

impl Default for LearnSettings {
    fn default() -> Self {
        Self {
            method: Method::Msgp,
            iterations: 8,
            random_rollouts: 4,
            random_policies: 0,
            excitation: learn_excitation(),
            episode_seconds: 3.0,
            policy_horizon_seconds: 5.0,
            seed: 0,
            fit: FitSettings {
                ly: 2,
                lu: 3,
                inducing: 50,
                iterations: 300,
                learning_rate: 0.01,
                validation_fraction: 0.0,
                mean: MeanFunction::Linear,
                integrators: vec![END_EFFECTOR_INTEGRATOR],
                ..FitSettings::default()
            },
            search: PolicySearchSettings {
                iterations: 20,
                learning_rate: 0.1,
                restarts: 1,
                restart_spread: 0.5,
                seed: 0,
                candidates: 150,
                candidate_spread: 2.0,
                candidate_starts: 2,
                trust_region: 1.0,
            },
            cost_widths: [0.1, 0.3],
            ff_segment: Some(30),
            fb_segment: None,
            gain_scale: [1.0, 0.3, 1.0, 10.0, 2.0],
            warm_start: None,
        }
    }
}

impl LearnSettings {
    /// The defaults for `method`. A [`Method::LinearKf`] model has no GP to absorb what a row
    /// should not carry, so the end effector is declared kinematic
    /// ([`END_EFFECTOR_KINEMATIC`]): in closed loop the command is a function of the pole's
    /// motion, and a free row explains the end effector's acceleration by the pole's velocity
    /// instead of the command. Its fits are warm-started ([`LINEAR_KF_WARM_START`]), and its gains
    /// are optimised over [`LINEAR_KF_POLICY_HORIZON_SECONDS`].
    pub fn for_method(method: Method) -> Self {
        let mut s = Self {
            method,
            ..Self::default()
        };
        if method == Method::LinearKf {
            for i in s.fit.integrators.iter_mut() {
                if *i == END_EFFECTOR_INTEGRATOR {
                    *i = END_EFFECTOR_KINEMATIC;
                }
            }
            s.warm_start = Some(LINEAR_KF_WARM_START);
            s.policy_horizon_seconds = LINEAR_KF_POLICY_HORIZON_SECONDS;
        }
        s
    }
}

/// The policy horizon of a linear-kf loop \[s\]: the stability test's length. Once the pole is
/// held, a 5 s horizon lets the search trade a slow drift of the end effector (an ever more
/// negative `ki_x`) for a cheaper 5 s; on the five Figure 4 seeds 33–34 of 40 iterations then
/// passed the 10 s test and two runs of five ended on failing gains; with this horizon 36–37
/// of 40 passed (docs/design.md). The search takes about twice as long as at 5 s (1.1–1.2 s
/// per iteration alone on the 2-core machine, BENCHMARKS.md).
pub const LINEAR_KF_POLICY_HORIZON_SECONDS: f64 = 10.0;

/// The default warm start of a linear-kf loop ([`LearnSettings::warm_start`]): from the second
/// iteration on, at most this many L-BFGS iterations from the previous model (the solver stops
/// by itself when converged, after 10–40), instead of two cold starts. The filter likelihood
/// changes little when one episode is added, so the previous optimum is a start next to the new
/// one; from scratch, the fit's time grows with the data (to 5–14 s by iteration 8), warm it
/// stays at 0.6–2.3 s.
pub const LINEAR_KF_WARM_START: usize = 300;

/// [`END_EFFECTOR_INTEGRATOR`] declared kinematic as well: its acceleration is a linear function
/// of the commands alone (the robot's actuator), so its row is zero on the pole's lags.
pub const END_EFFECTOR_KINEMATIC: Integrator = Integrator {
    linear: true,
    ..END_EFFECTOR_INTEGRATOR
};

/// The end-effector position (output 1) is the double integral of the commanded acceleration,
/// and the plant is the same wherever the end effector is and however fast it moves: a pure
/// integrator of order 2 ([`msgp_core::integrator`]). Declared by default: four random rollouts
/// do not identify it, and a model that misses it cannot tell a position loop from none
/// (docs/design.md).
pub const END_EFFECTOR_INTEGRATOR: Integrator = Integrator {
    output: 1,
    order: 2,
    linear: false,
};

/// The excitation of the random rollouts: 20 sines in 0.1–10 Hz, 1 m/s² RMS.
pub fn learn_excitation() -> ExcitationConfig {
    ExcitationConfig {
        components: 20,
        min_hz: 0.1,
        max_hz: 10.0,
        rms: 1.0,
    }
}

/// One iteration of the loop.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct IterationReport {
    /// 1-based iteration.
    pub iteration: usize,
    /// Expected total cost on the model, from rest, over the episode's length (the policy is
    /// optimised over the longer `policy_horizon_seconds`).
    pub predicted_cost: f64,
    /// Its standard deviation (per-step variances summed; correlations over time ignored).
    pub predicted_cost_std: f64,
    /// Cost of the episode actually run, on the measured outputs.
    pub actual_cost: f64,
    /// Interaction time so far, random rollouts included \[s\].
    pub interaction_seconds: f64,
    /// Whether the gains passed the simulator's stability test.
    pub stable: bool,
    /// Wall-clock seconds of the model fit.
    #[serde(default)]
    pub fit_seconds: f64,
    /// Wall-clock seconds of the policy optimisation.
    #[serde(default)]
    pub search_seconds: f64,
    /// Why the model fit stopped early, when a training step failed numerically (the fit then
    /// keeps the parameters of lowest loss among those that evaluated).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fit_numerical_stop: Option<String>,
    /// Set when every policy-search start diverged on the model: the previous gains ran again
    /// and the predicted cost is the episode's maximum (every step 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub search_failure: Option<String>,
    /// The gains run in this iteration.
    pub gains: PidPdGains,
}

/// Everything the loop produced.
#[derive(Clone, Debug)]
pub struct LearnOutcome {
    /// Per-iteration reports.
    pub iterations: Vec<IterationReport>,
    /// Every interaction episode, random ones first.
    pub episodes: Vec<Episode>,
    /// The last gains.
    pub final_gains: PidPdGains,
    /// The random policies' gains and whether each passed the stability test (which, as after
    /// every iteration, is neither interaction nor training data).
    pub random_policies: Vec<(PidPdGains, bool)>,
}

impl LearnOutcome {
    /// First iteration whose gains passed the stability test.
    pub fn first_stable_iteration(&self) -> Option<usize> {
        self.iterations
            .iter()
            .find(|r| r.stable)
            .map(|r| r.iteration)
    }

    /// The iteration whose gains to keep: the first that passed the stability test, else the
    /// one with the lowest measured episode cost (the earliest on ties; NaN costs never win).
    /// The loop itself ends on its last gains, which a later bad model may have spoiled.
    pub fn best_iteration(&self) -> Option<&IterationReport> {
        self.iterations.iter().find(|r| r.stable).or_else(|| {
            self.iterations
                .iter()
                .filter(|r| !r.actual_cost.is_nan())
                .fold(None, |best: Option<&IterationReport>, r| match best {
                    Some(b) if b.actual_cost <= r.actual_cost => Some(b),
                    _ => Some(r),
                })
        })
    }
}

/// `[θ, x]` and the commands of an episode.
pub fn episode_trajectory(ep: &Episode) -> Result<Trajectory, SimError> {
    let n = ep.samples.len();
    let u = DMatrix::from_fn(n, 1, |k, _| ep.samples[k].command);
    let y = DMatrix::from_fn(n, 2, |k, j| {
        let m = ep.samples[k].measurement;
        if j == 0 { m.theta } else { m.x }
    });
    Ok(Trajectory::new(u, y)?)
}

/// `traj` as overlapping segments of `len` samples with stride `len / 2` (the last one ends
/// at the end); segments shorter than `min_len` are dropped.
pub fn segments(
    traj: &Trajectory,
    len: usize,
    min_len: usize,
) -> Result<Vec<Trajectory>, SimError> {
    let n = traj.len();
    let len = len.max(min_len).max(2);
    let stride = (len / 2).max(1);
    let mut out = Vec::new();
    let mut start = 0;
    while start + min_len <= n {
        let end = (start + len).min(n);
        out.push(Trajectory::new(
            traj.u.rows(start, end - start).into_owned(),
            traj.y.rows(start, end - start).into_owned(),
        )?);
        if end == n {
            break;
        }
        start += stride;
    }
    Ok(out)
}

/// The simulator's gains as the modelled policy on `[θ, x]`.
pub fn modelled_policy(
    g: &PidPdGains,
    params: &PendulumParams,
) -> Result<PidPolicy<f64>, SimError> {
    Ok(PidPolicy::new(
        DMatrix::from_row_slice(1, 2, &[g.kp_theta, g.kp_x]),
        DMatrix::from_row_slice(1, 2, &[0.0, g.ki_x]),
        DMatrix::from_row_slice(1, 2, &[g.kd_theta, g.kd_x]),
        params.control_period(),
        vec![params.action_limit],
    )?)
}

/// The policy problem of the loop on `model`: the pole at rest upright with the plant's spread
/// of initial angles, the end effector at 0 and no command, over `horizon` steps.
pub fn pendulum_problem<'a>(
    model: &'a msgp_core::model::Model,
    params: &PendulumParams,
    cost: SaturatingCost,
    horizon: usize,
) -> PolicyProblem<'a> {
    PolicyProblem {
        model,
        y0_mean: vec![0.0, 0.0],
        y0_var: vec![params.initial_theta_std.powi(2), 1e-8],
        u0: vec![0.0],
        cost,
        horizon,
    }
}

fn gains_from(p: &PidPolicy<f64>) -> PidPdGains {
    PidPdGains {
        kp_theta: p.kp[(0, 0)],
        kp_x: p.kp[(0, 1)],
        ki_x: p.ki[(0, 1)],
        kd_theta: p.kd[(0, 0)],
        kd_x: p.kd[(0, 1)],
        saturation: Saturation::Sine,
    }
}

/// Cost of the measured outputs of an episode over the modelled window; steps after an early
/// stop (the pole fell or the arm left its range) count the full cost 1.
pub fn episode_cost(ep: &Episode, cost: &SaturatingCost, from: usize, steps: usize) -> f64 {
    let measured: Vec<f64> = ep
        .samples
        .iter()
        .skip(from)
        .take(steps)
        .map(|s| cost.at(&[s.measurement.theta, s.measurement.x]))
        .collect();
    measured.iter().sum::<f64>() + (steps - measured.len()) as f64
}

/// One interaction episode from a random initial angle; adds its duration to `seconds`.
fn interact(
    params: &PendulumParams,
    controller: &mut dyn Controller,
    length: f64,
    seed: u64,
    seconds: &mut f64,
) -> Result<Episode, SimError> {
    let ep = run_episode(
        params,
        controller,
        &EpisodeConfig {
            seconds: length,
            seed,
            initial_theta: None,
        },
    )?;
    *seconds += ep.samples.len().saturating_sub(1) as f64 * params.control_period();
    Ok(ep)
}

/// `traj` cut into segments of `segment` samples for MSGP fits; whole otherwise, and always
/// for one-step and linear-kf fits (they see every pair once: segments would duplicate the
/// overlaps; the filter handles a whole unstable episode).
fn msgp_segments(
    traj: Trajectory,
    segment: Option<usize>,
    settings: &LearnSettings,
) -> Result<Vec<Trajectory>, SimError> {
    match segment {
        Some(len) if settings.method == Method::Msgp => {
            segments(&traj, len, settings.fit.ly.max(settings.fit.lu) + 5)
        }
        _ => Ok(vec![traj]),
    }
}

/// One episode of `gains` and its training entries: the trajectory under those gains
/// (`L_fb`), whole or in [`LearnSettings::fb_segment`] segments.
fn feedback_episode(
    params: &PendulumParams,
    gains: &PidPdGains,
    settings: &LearnSettings,
    seed: u64,
    seconds: &mut f64,
) -> Result<(Episode, Vec<TrainingEpisode>), SimError> {
    let mut controller = PidPdPolicy::new(*gains, params)?;
    let ep = interact(
        params,
        &mut controller,
        settings.episode_seconds,
        seed,
        seconds,
    )?;
    let parts = msgp_segments(episode_trajectory(&ep)?, settings.fb_segment, settings)?;
    let policy = PolicySpec::Pid(modelled_policy(gains, params)?);
    let entries = parts
        .into_iter()
        .map(|traj| TrainingEpisode {
            traj,
            policy: Some(policy.clone()),
        })
        .collect();
    Ok((ep, entries))
}

/// What the loop reports while it runs ([`learn_policy_observed`]).
#[derive(Clone, Copy, Debug)]
pub enum LearnEvent<'a> {
    /// The model fit of policy iteration `iteration` (from 1) starts.
    FitStarted {
        /// The policy iteration.
        iteration: usize,
    },
    /// The model fit of policy iteration `iteration` finished a solver iteration (MSGP fits
    /// only: one-step and linear-kf fits report nothing until they end).
    Fit {
        /// The policy iteration.
        iteration: usize,
        /// The fit's own progress.
        progress: &'a FitProgress,
    },
    /// The policy search of an iteration starts (its fit has ended).
    SearchStarted {
        /// The policy iteration.
        iteration: usize,
    },
    /// A policy iteration completed.
    Iteration(&'a IterationReport),
}

/// Runs the loop; `progress` sees each iteration as it completes.
pub fn learn_policy(
    params: &PendulumParams,
    settings: &LearnSettings,
    progress: &mut dyn FnMut(&IterationReport),
) -> Result<LearnOutcome, SimError> {
    learn_policy_observed(params, settings, &mut |e| {
        if let LearnEvent::Iteration(r) = e {
            progress(r)
        }
        ControlFlow::Continue(())
    })
}

/// Runs the loop; `observe` sees its fits' and iterations' progress ([`LearnEvent`]) and can
/// stop it: after a [`ControlFlow::Break`] the loop ends there, returning [`SimError::Stopped`]
/// (an MSGP fit stops at its next solver iteration; its one-step start, and one-step and
/// linear-kf fits, which report nothing, run to their end first).
pub fn learn_policy_observed(
    params: &PendulumParams,
    settings: &LearnSettings,
    observe: &mut dyn FnMut(LearnEvent<'_>) -> ControlFlow<()>,
) -> Result<LearnOutcome, SimError> {
    params.validate()?;
    let mut episodes: Vec<Episode> = Vec::new();
    let mut training: Vec<TrainingEpisode> = Vec::new();
    let mut seconds = 0.0;
    if let Some(bad) = settings.gain_scale.iter().find(|g| !g.is_finite()) {
        return Err(SimError::invalid(
            "gain_scale",
            *bad,
            "typical gain magnitudes must be finite",
        ));
    }
    if settings.random_policies > settings.random_rollouts {
        return Err(SimError::invalid(
            "random_policies",
            settings.random_policies as f64,
            "at most random_rollouts of the random episodes can run a random policy",
        ));
    }
    let mut random_policies = Vec::new();
    for k in 0..settings.random_rollouts {
        let seed = settings.seed.wrapping_mul(1000).wrapping_add(k as u64);
        if k < settings.random_policies {
            let gains = random_gains(seed, &settings.gain_scale);
            let (ep, entries) = feedback_episode(params, &gains, settings, seed, &mut seconds)?;
            training.extend(entries);
            episodes.push(ep);
            let stable =
                stability_test(params, &gains, settings.seed, &StabilityCriteria::default())?
                    .passed;
            random_policies.push((gains, stable));
            continue;
        }
        let mut excitation = RandomExcitation::new(seed, &settings.excitation)?;
        let ep = interact(
            params,
            &mut excitation,
            settings.episode_seconds,
            seed,
            &mut seconds,
        )?;
        let parts = msgp_segments(episode_trajectory(&ep)?, settings.ff_segment, settings)?;
        training.extend(
            parts
                .into_iter()
                .map(|traj| TrainingEpisode { traj, policy: None }),
        );
        episodes.push(ep);
    }
    let cost = SaturatingCost::with_widths(DVector::from_element(2, 0.0), &settings.cost_widths)?;
    let horizon = (settings.episode_seconds * params.control_rate_hz).round() as usize;
    let policy_horizon =
        (settings.policy_horizon_seconds * params.control_rate_hz).round() as usize;
    if policy_horizon == 0 || horizon == 0 {
        return Err(SimError::invalid(
            "policy_horizon_seconds",
            settings
                .policy_horizon_seconds
                .min(settings.episode_seconds),
            "the episode and the policy horizon need at least one control step",
        ));
    }
    let s = settings.gain_scale;
    let mut gains = PidPdGains {
        kp_x: s[0],
        ki_x: s[1],
        kd_x: s[2],
        kp_theta: s[3],
        kd_theta: s[4],
        saturation: Saturation::Sine,
    };
    let mask = PidMask {
        kp: DMatrix::from_element(1, 2, true),
        ki: DMatrix::from_row_slice(1, 2, &[false, true]),
        kd: DMatrix::from_element(1, 2, true),
    };
    // the optimiser's coordinate scales: a gain near zero keeps its kind's typical magnitude
    let typical: Vec<f64> = mask
        .pack(&modelled_policy(&gains, params)?)
        .into_iter()
        .map(f64::abs)
        .collect();
    let mut reports = Vec::new();
    let mut previous_model: Option<msgp_core::model::Model> = None;
    for it in 1..=settings.iterations {
        let fit_settings = FitSettings {
            method: settings.method,
            seed: settings.seed.wrapping_add(it as u64),
            ..settings.fit.clone()
        };
        let clock = std::time::Instant::now();
        let stopped = SimError::Stopped { iteration: it };
        if observe(LearnEvent::FitStarted { iteration: it }).is_break() {
            return Err(stopped);
        }
        let warm = match (&previous_model, settings.warm_start) {
            (Some(prev), Some(n)) if matches!(settings.method, Method::Msgp | Method::LinearKf) => {
                Some((prev, n))
            }
            _ => None,
        };
        let fitted = fit_episodes_observed(
            &training,
            &FitSettings {
                iterations: warm.map_or(fit_settings.iterations, |(_, n)| n),
                ..fit_settings.clone()
            },
            warm.map(|(prev, _)| prev),
            &mut |p| {
                observe(LearnEvent::Fit {
                    iteration: it,
                    progress: p,
                })
            },
        );
        let (model, mut fit_report) = match fitted {
            Ok(fitted) => fitted,
            // the MSGP start (the one-step model rolled out over every episode) can already
            // fail numerically; the iteration then runs on that one-step model
            Err(
                e @ (msgp_core::MsgpError::NonFinite(_)
                | msgp_core::MsgpError::NotPositiveDefinite { .. }),
            ) if settings.method == Method::Msgp => {
                let one_step = FitSettings {
                    method: Method::GpNarx,
                    ..fit_settings.clone()
                };
                let (model, mut report) = fit_episodes(&training, &one_step, &mut |_| {})?;
                report.numerical_stop = Some(format!(
                    "the MSGP fit failed at its start ({e}); this iteration used the one-step \
                     GP-NARX model"
                ));
                (model, report)
            }
            Err(msgp_core::MsgpError::Stopped { .. }) => return Err(stopped),
            Err(e) => return Err(e.into()),
        };
        let fit_seconds = clock.elapsed().as_secs_f64();
        // a one-step fallback model is not continued: the next fit starts over
        if settings.warm_start.is_some() {
            previous_model = (model.method == settings.method).then(|| model.clone());
        }
        let problem = pendulum_problem(&model, params, cost.clone(), policy_horizon);
        let search = PolicySearchSettings {
            seed: settings
                .search
                .seed
                .wrapping_add(settings.seed)
                .wrapping_add(it as u64),
            ..settings.search
        };
        if observe(LearnEvent::SearchStarted { iteration: it }).is_break() {
            return Err(stopped);
        }
        let clock = std::time::Instant::now();
        let searched = optimise_pid_scaled(
            &problem,
            &modelled_policy(&gains, params)?,
            &mask,
            &typical,
            &search,
        );
        let search_seconds = clock.elapsed().as_secs_f64();
        let (predicted, var, search_failure) = match searched {
            Ok(result) => {
                gains = gains_from(&result.policy);
                // reported over the episode's length, comparable with the cost measured on the
                // system
                let episode_steps = &result.steps[..horizon.min(result.steps.len())];
                let predicted: f64 = episode_steps.iter().map(|(m, _)| m).sum();
                let var: f64 = episode_steps.iter().map(|(_, v)| v).sum();
                (predicted, var, None)
            }
            // the model's rollouts diverge for every start: it predicts failure whatever the
            // gains (every step costs 1); the gains stay and the episode adds data
            Err(
                e @ (msgp_core::MsgpError::NonFinite(_)
                | msgp_core::MsgpError::NotPositiveDefinite { .. }),
            ) => (horizon as f64, 0.0, Some(e.to_string())),
            Err(msgp_core::MsgpError::Stopped { .. }) => return Err(stopped),
            Err(e) => return Err(e.into()),
        };

        let seed = settings
            .seed
            .wrapping_mul(1000)
            .wrapping_add(500 + it as u64);
        let (ep, entries) = feedback_episode(params, &gains, settings, seed, &mut seconds)?;
        let warm = settings.fit.ly.max(settings.fit.lu);
        let actual = episode_cost(&ep, &cost, warm, horizon);
        training.extend(entries);
        episodes.push(ep);
        let stable =
            stability_test(params, &gains, settings.seed, &StabilityCriteria::default())?.passed;
        let report = IterationReport {
            iteration: it,
            predicted_cost: predicted,
            predicted_cost_std: var.sqrt(),
            actual_cost: actual,
            interaction_seconds: seconds,
            stable,
            fit_seconds,
            search_seconds,
            fit_numerical_stop: fit_report.numerical_stop.take(),
            search_failure,
            gains,
        };
        if observe(LearnEvent::Iteration(&report)).is_break() {
            return Err(stopped);
        }
        reports.push(report);
    }
    Ok(LearnOutcome {
        iterations: reports,
        episodes,
        final_gains: gains,
        random_policies,
    })
}

/// A random policy's gains: each drawn uniformly in `[0, 2 scale]`, sine saturation.
pub fn random_gains(seed: u64, scale: &[f64; 5]) -> PidPdGains {
    use rand::{RngExt, SeedableRng};
    let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(crate::seed::rng_for(
        seed,
        crate::seed::Stream::RandomGains,
    ));
    let mut g = [0.0; 5];
    for (gk, s) in g.iter_mut().zip(scale) {
        *gk = rng.random_range(0.0..=2.0 * s.abs());
    }
    PidPdGains {
        saturation: Saturation::Sine,
        ..PidPdGains::from_array(g)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn report(iteration: usize, actual_cost: f64, stable: bool) -> IterationReport {
        IterationReport {
            iteration,
            predicted_cost: 1.0,
            predicted_cost_std: 0.1,
            actual_cost,
            interaction_seconds: 12.0 + 3.0 * iteration as f64,
            stable,
            fit_seconds: 1.0,
            search_seconds: 1.0,
            fit_numerical_stop: None,
            search_failure: None,
            gains: PidPdGains {
                kp_x: iteration as f64,
                ki_x: 0.0,
                kd_x: 0.0,
                kp_theta: 10.0,
                kd_theta: 2.0,
                saturation: Saturation::Sine,
            },
        }
    }

    fn outcome(iterations: Vec<IterationReport>) -> LearnOutcome {
        LearnOutcome {
            iterations,
            episodes: Vec::new(),
            final_gains: PidPdGains::hand_tuned(),
            random_policies: Vec::new(),
        }
    }

    #[test]
    fn the_best_iteration_is_the_first_stable_else_the_cheapest() {
        let best = |o: &LearnOutcome| o.best_iteration().map(|r| r.iteration);
        // a stable iteration wins over a cheaper unstable one, and the first stable over later
        let o = outcome(vec![
            report(1, 2.0, false),
            report(2, 5.0, true),
            report(3, 1.0, true),
        ]);
        assert_eq!(best(&o), Some(2));
        assert_eq!(o.first_stable_iteration(), Some(2));
        // none stable: the lowest measured cost, the earliest on ties, NaN never
        let o = outcome(vec![
            report(1, f64::NAN, false),
            report(2, 4.0, false),
            report(3, 3.0, false),
            report(4, 3.0, false),
            report(5, 90.0, false),
        ]);
        assert_eq!(best(&o), Some(3));
        assert_eq!(o.best_iteration().map(|r| r.gains.kp_x), Some(3.0));
        assert_eq!(best(&outcome(vec![report(1, f64::NAN, false)])), None);
        assert_eq!(best(&outcome(Vec::new())), None);
    }
}
