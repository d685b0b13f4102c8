//! The policy-search problem on the pendulum: the simulator's gains as the modelled policy, the
//! start at rest, and the cost of a measured episode.

use nalgebra::DMatrix;

use msgp_core::policy::{PidPolicy, Policy};
use msgp_core::policy_search::PolicyProblem;
use msgp_core::policy_search::cost::SaturatingCost;

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
    PolicyProblem {
        model,
        y0_mean: vec![0.0, 0.0],
        y0_var: vec![params.initial_theta_std.powi(2), 1e-8],
        u0: vec![0.0],
        cost,
        horizon,
    }
}

/// The pendulum's gains of a searched policy (the loop searches PID policies only).
pub(super) fn gains_from(c: &Policy) -> Result<PidPdGains, SimError> {
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
