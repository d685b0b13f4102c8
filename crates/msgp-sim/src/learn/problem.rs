//! The pendulum's task for the learning loop: the saturating cost on `[θ, x]`, the start at
//! rest upright, the PID + PD gains as the searched policy, and the cost of a measured episode.

use nalgebra::{DMatrix, DVector};

use msgp_core::learner::{ExcitationConfig, LearnerSettings, StartDistribution, Task};
use msgp_core::policy::{PidPolicy, Policy};
use msgp_core::policy_search::cost::SaturatingCost;
use msgp_core::policy_search::{PidMask, PolicyProblem, SearchSpace};

use super::settings::LearnSettings;
use crate::controller::{PidPdGains, Saturation};
use crate::episode::Episode;
use crate::error::SimError;
use crate::params::PendulumParams;

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
    let (mean, var) = start(params);
    PolicyProblem {
        model,
        y0_mean: mean,
        y0_var: var,
        u0: vec![0.0],
        cost,
        horizon,
    }
}

/// The start of the predicted rollouts: upright with the plant's spread of initial angles, the
/// end effector at 0.
fn start(params: &PendulumParams) -> (Vec<f64>, Vec<f64>) {
    (vec![0.0, 0.0], vec![params.initial_theta_std.powi(2), 1e-8])
}

/// The loop's task on the pendulum of `params` under `settings`: the saturating cost of
/// [`LearnSettings::cost_widths`] around upright and centred, episodes of
/// [`LearnSettings::episode_seconds`], rollouts of [`LearnSettings::policy_horizon_seconds`]
/// from rest, the PID + PD gains from [`LearnSettings::gain_scale`] with `kp` and `kd` on both
/// outputs and `ki` on the end effector free, each at its typical magnitude.
pub fn pendulum_task(params: &PendulumParams, settings: &LearnSettings) -> Result<Task, SimError> {
    let cost = SaturatingCost::with_widths(DVector::from_element(2, 0.0), &settings.cost_widths)?;
    let steps = |seconds: f64, name: &'static str| -> Result<usize, SimError> {
        let n = (seconds * params.control_rate_hz).round();
        if !(n >= 1.0 && n.is_finite()) {
            return Err(SimError::invalid(
                name,
                seconds,
                "needs at least one control step",
            ));
        }
        Ok(n as usize)
    };
    let episode_steps = steps(settings.episode_seconds, "episode_seconds")?;
    let policy_horizon = steps(settings.policy_horizon_seconds, "policy_horizon_seconds")?;
    if let Some(bad) = settings.gain_scale.iter().find(|g| !g.is_finite()) {
        return Err(SimError::invalid(
            "gain_scale",
            *bad,
            "typical gain magnitudes must be finite",
        ));
    }
    let mask = gain_mask();
    let initial = modelled_policy(&initial_gains(&settings.gain_scale), params)?;
    let typical = mask.pack(&initial).into_iter().map(f64::abs).collect();
    let (mean, var) = start(params);
    Ok(Task {
        cost,
        episode_steps,
        policy_horizon,
        start: StartDistribution::Fixed { mean, var },
        rest_command: vec![0.0],
        space: SearchSpace::pid(&initial, &mask),
        typical,
    })
}

/// The loop's settings on the pendulum of `params`: the random episodes' excitation as a
/// fraction of the action limit.
pub fn learner_settings(
    params: &PendulumParams,
    s: &LearnSettings,
) -> Result<LearnerSettings, SimError> {
    s.excitation.validate()?;
    Ok(LearnerSettings {
        iterations: s.iterations,
        random_rollouts: s.random_rollouts,
        excitation: ExcitationConfig {
            components: s.excitation.components,
            min_hz: s.excitation.min_hz,
            max_hz: s.excitation.max_hz,
            rms_fraction: s.excitation.rms / params.action_limit,
        },
        seed: s.seed,
        fit: s.fit.clone(),
        search: s.search,
        evaluation_episodes: s.evaluation_episodes,
        prequential_choice: s.prequential_choice,
        ff_segment: s.ff_segment,
        warm_start: s.warm_start,
        search_from_first: false,
        one_step_guard: false,
    })
}

/// The gains the search moves: `kp` and `kd` on both outputs, `ki` on the end effector.
fn gain_mask() -> PidMask {
    PidMask {
        kp: DMatrix::from_element(1, 2, true),
        ki: DMatrix::from_row_slice(1, 2, &[false, true]),
        kd: DMatrix::from_element(1, 2, true),
    }
}

/// The gains of the loop's first search: [`LearnSettings::gain_scale`] with the sine saturation.
pub(super) fn initial_gains(s: &[f64; 5]) -> PidPdGains {
    PidPdGains {
        kp_x: s[0],
        ki_x: s[1],
        kd_x: s[2],
        kp_theta: s[3],
        kd_theta: s[4],
        saturation: Saturation::Sine,
    }
}

/// The pendulum's gains of a searched policy (the loop searches PID policies only).
pub fn gains_from(c: &Policy) -> Result<PidPdGains, SimError> {
    let Policy::Pid(p) = c else {
        return Err(SimError::invalid(
            "policy",
            0.0,
            "the pendulum loop searches PID + PD gains only",
        ));
    };
    Ok(PidPdGains {
        kp_theta: p.kp[(0, 0)],
        kp_x: p.kp[(0, 1)],
        ki_x: p.ki[(0, 1)],
        kd_theta: p.kd[(0, 0)],
        kd_x: p.kd[(0, 1)],
        saturation: Saturation::Sine,
    })
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
