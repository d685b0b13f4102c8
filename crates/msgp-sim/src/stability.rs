//! The stability test for PID + PD gains.

use serde::{Deserialize, Serialize};

use crate::controller::{PidPdGains, PidPdPolicy};
use crate::episode::{EpisodeConfig, Termination, run_episode};
use crate::error::{SimError, require_positive};
use crate::params::PendulumParams;
use crate::seed::{Stream, rng_for};

/// Pass criteria and starts of the stability test.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StabilityCriteria {
    /// Initial pole angles \[rad\], one episode each.
    pub initial_thetas: Vec<f64>,
    /// Episode length \[s\].
    pub seconds: f64,
    /// Fail if the true `|theta|` ever reaches this \[rad\].
    pub max_abs_theta: f64,
    /// Fail if the true `|x|` ever reaches this \[m\].
    pub max_abs_x: f64,
    /// Length of the final window for the RMS criterion \[s\].
    pub rms_window: f64,
    /// Fail unless the RMS of the true `theta` over the final window is below this \[rad\].
    pub max_rms_theta: f64,
    /// Episodes per start, each with its own measurement-noise draw; every one must pass. One
    /// draw can let a policy without a working position loop through by luck: the end effector's
    /// drift is a random walk driven by the noise.
    #[serde(default = "default_noise_repeats")]
    pub noise_repeats: u32,
}

/// The default [`StabilityCriteria::noise_repeats`].
pub const DEFAULT_NOISE_REPEATS: u32 = 3;

/// Upper bound of [`StabilityCriteria::noise_repeats`].
pub const MAX_NOISE_REPEATS: u32 = 1000;

fn default_noise_repeats() -> u32 {
    DEFAULT_NOISE_REPEATS
}

impl Default for StabilityCriteria {
    /// Five starts (±0.03, ±0.015, 0 rad), three noise draws each, 10 s, `|θ| < 0.1`,
    /// `|x| < 0.3`, RMS θ over the last 5 s < 0.03.
    fn default() -> Self {
        Self {
            initial_thetas: vec![-0.03, -0.015, 0.0, 0.015, 0.03],
            seconds: 10.0,
            max_abs_theta: 0.1,
            max_abs_x: 0.3,
            rms_window: 5.0,
            max_rms_theta: 0.03,
            noise_repeats: DEFAULT_NOISE_REPEATS,
        }
    }
}

/// Outcome of one start.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StartReport {
    /// Initial pole angle \[rad\].
    pub initial_theta: f64,
    /// Noise draw of this start (0-based).
    #[serde(default)]
    pub repeat: u32,
    /// Whether this start met every criterion.
    pub passed: bool,
    /// Largest true `|theta|` over the samples \[rad\].
    pub max_abs_theta: f64,
    /// Largest true `|x|` over the samples \[m\].
    pub max_abs_x: f64,
    /// RMS of the true `theta` over the final window \[rad\] (over the recorded samples in the
    /// window if the episode stopped early; NaN if there were none).
    pub rms_theta_final: f64,
    /// Simulated time before the episode ended \[s\].
    pub duration: f64,
    /// Why it failed; `None` when it passed.
    pub failure: Option<String>,
}

/// Outcome of the whole test.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct StabilityReport {
    /// True iff every start passed.
    pub passed: bool,
    /// Gains tested.
    pub gains: PidPdGains,
    /// Seed of the measurement noise (start `i` uses a stream derived from it).
    pub seed: u64,
    /// One report per start and noise draw: the draws of the first start, then of the next, in
    /// the order of `initial_thetas`.
    pub starts: Vec<StartReport>,
}

/// Runs the stability test: `noise_repeats` noisy episodes per start angle on `params` (with its
/// measurement noise, delay and lag), checked on the *true* states at the control rate.
/// The plant's early-stop limits are widened so they cannot end an episode before the
/// criteria do.
pub fn stability_test(
    params: &PendulumParams,
    gains: &PidPdGains,
    seed: u64,
    criteria: &StabilityCriteria,
) -> Result<StabilityReport, SimError> {
    if criteria.initial_thetas.is_empty() {
        return Err(SimError::invalid(
            "initial_thetas",
            0.0,
            "needs at least one start angle",
        ));
    }
    require_positive("max_abs_theta", criteria.max_abs_theta)?;
    require_positive("max_abs_x", criteria.max_abs_x)?;
    require_positive("rms_window", criteria.rms_window)?;
    require_positive("max_rms_theta", criteria.max_rms_theta)?;
    if !(1..=MAX_NOISE_REPEATS).contains(&criteria.noise_repeats) {
        return Err(SimError::invalid(
            "noise_repeats",
            f64::from(criteria.noise_repeats),
            "needs 1 to 1000 noise draws per start",
        ));
    }
    let plant = PendulumParams {
        stop_theta: params.stop_theta.max(criteria.max_abs_theta),
        stop_x: params.stop_x.max(criteria.max_abs_x),
        ..*params
    };
    let mut starts = Vec::with_capacity(criteria.initial_thetas.len());
    let runs = criteria
        .initial_thetas
        .iter()
        .enumerate()
        .flat_map(|(i, &theta0)| {
            (0..criteria.noise_repeats).map(move |repeat| (i, theta0, repeat))
        });
    for (i, theta0, repeat) in runs {
        let mut policy = PidPdPolicy::new(*gains, &plant)?;
        let index = u32::try_from(i).unwrap_or(u32::MAX);
        // the first draw keeps the stream the test had before it repeated starts
        let stream = if repeat == 0 {
            Stream::StabilityStart(index)
        } else {
            Stream::StabilityRepeat {
                start: index,
                repeat,
            }
        };
        let episode = run_episode(
            &plant,
            &mut policy,
            &EpisodeConfig {
                seconds: criteria.seconds,
                seed: rng_for(seed, stream),
                initial_theta: Some(theta0),
            },
        )?;
        let samples = &episode.samples;
        let max_abs_theta = samples
            .iter()
            .map(|s| s.latent.theta.abs())
            .fold(0.0, f64::max);
        let max_abs_x = samples.iter().map(|s| s.latent.x.abs()).fold(0.0, f64::max);
        let window_start = criteria.seconds - criteria.rms_window;
        let window: Vec<f64> = samples
            .iter()
            .filter(|s| s.t > window_start + 1e-9)
            .map(|s| s.latent.theta)
            .collect();
        let rms_theta_final = if window.is_empty() {
            f64::NAN
        } else {
            (window.iter().map(|t| t * t).sum::<f64>() / window.len() as f64).sqrt()
        };
        let duration = samples.last().map_or(0.0, |s| s.t);
        let failure = if max_abs_theta >= criteria.max_abs_theta {
            Some(format!(
                "|theta| reached {max_abs_theta:.4} rad (limit {})",
                criteria.max_abs_theta
            ))
        } else if max_abs_x >= criteria.max_abs_x {
            Some(format!(
                "|x| reached {max_abs_x:.4} m (limit {})",
                criteria.max_abs_x
            ))
        } else if episode.info.termination != Termination::Completed {
            Some(format!("episode stopped early at t = {duration} s"))
        } else if rms_theta_final.is_nan() || rms_theta_final >= criteria.max_rms_theta {
            Some(format!(
                "RMS theta over the last {} s is {rms_theta_final:.4} rad (limit {})",
                criteria.rms_window, criteria.max_rms_theta
            ))
        } else {
            None
        };
        starts.push(StartReport {
            initial_theta: theta0,
            repeat,
            passed: failure.is_none(),
            max_abs_theta,
            max_abs_x,
            rms_theta_final,
            duration,
            failure,
        });
    }
    Ok(StabilityReport {
        passed: starts.iter().all(|s| s.passed),
        gains: *gains,
        seed,
        starts,
    })
}
