//! Seeded episodes: run a controller on the plant and record everything.

use rand::SeedableRng;
use rand::rngs::Xoshiro256PlusPlus;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use crate::controller::Controller;
use crate::error::SimError;
use crate::params::PendulumParams;
use crate::plant::{LatentState, Measurement, Plant};
use crate::seed::{Stream, rng_for};

/// Longest accepted episode \[s\].
pub const MAX_EPISODE_SECONDS: f64 = 86_400.0;

/// One control step.
///
/// Row `k` holds the state at `t = k·T`, the measurement taken then, and the command issued
/// in response. The command of the last row of an episode is never applied.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Sample {
    /// Control-step index `k`.
    pub step: u64,
    /// Time \[s\] = `k / control_rate_hz`.
    pub t: f64,
    /// Issued acceleration command after clipping \[m/s²\].
    pub command: f64,
    /// What the controller saw.
    pub measurement: Measurement,
    /// The true state (not available to controllers).
    pub latent: LatentState,
}

/// Why an episode ended.
#[derive(Debug, Clone, Copy, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "snake_case")]
pub enum Termination {
    /// Ran for the requested duration.
    Completed,
    /// Stopped early: true `|theta| > stop_theta`.
    ThetaLimit,
    /// Stopped early: true `|x| > stop_x`.
    PositionLimit,
}

/// Everything needed to reproduce an episode, stored alongside its samples.
#[derive(Debug, Clone, PartialEq, Serialize, Deserialize)]
pub struct EpisodeInfo {
    /// Plant parameters.
    pub params: PendulumParams,
    /// Episode seed (initial angle and measurement noise).
    pub seed: u64,
    /// True initial pole angle \[rad\].
    pub initial_theta: f64,
    /// Requested duration \[s\].
    pub seconds: f64,
    /// The controller's [`describe`](Controller::describe) string.
    pub controller: String,
    /// Why the episode ended.
    pub termination: Termination,
}

/// A recorded episode.
#[derive(Debug, Clone, PartialEq)]
pub struct Episode {
    /// Setup and outcome.
    pub info: EpisodeInfo,
    /// One sample per control step, starting at `t = 0`.
    pub samples: Vec<Sample>,
}

/// Episode settings besides the plant and the controller.
#[derive(Debug, Clone, Copy, PartialEq)]
pub struct EpisodeConfig {
    /// Duration \[s\]; the episode has `round(seconds · control_rate_hz) + 1` samples unless
    /// it stops early.
    pub seconds: f64,
    /// Seeds the initial angle and the measurement noise (independent streams).
    pub seed: u64,
    /// Fixed initial angle \[rad\]; `None` draws it from N(0, `initial_theta_std`²).
    pub initial_theta: Option<f64>,
}

/// Runs `controller` on a fresh plant. Same inputs → bit-identical output.
pub fn run_episode(
    params: &PendulumParams,
    controller: &mut dyn Controller,
    config: &EpisodeConfig,
) -> Result<Episode, SimError> {
    params.validate()?;
    if !(config.seconds.is_finite() && (0.0..=MAX_EPISODE_SECONDS).contains(&config.seconds)) {
        return Err(SimError::invalid(
            "seconds",
            config.seconds,
            "must be finite and within 0..=86400",
        ));
    }
    let theta0 = match config.initial_theta {
        Some(theta) => theta,
        None => {
            let mut rng =
                Xoshiro256PlusPlus::seed_from_u64(rng_for(config.seed, Stream::InitialState));
            let n: f64 = StandardNormal.sample(&mut rng);
            params.initial_theta_std * n
        }
    };
    // a balancing episode starts near upright (the swing-up has its own plant)
    if !(theta0.is_finite() && theta0.abs() < std::f64::consts::FRAC_PI_2) {
        return Err(SimError::invalid(
            "initial_theta",
            theta0,
            "must be finite with |theta| < pi/2",
        ));
    }
    let mut plant = Plant::new(params, theta0)?;
    let mut noise =
        Xoshiro256PlusPlus::seed_from_u64(rng_for(config.seed, Stream::MeasurementNoise));
    // Bounded by MAX_EPISODE_SECONDS and MAX_SUBSTEPS-limited rates, so it fits in u64.
    let last_step = (config.seconds * params.control_rate_hz).round() as u64;
    let mut samples = Vec::with_capacity(usize::try_from(last_step + 1).unwrap_or(0));
    let mut termination = Termination::Completed;
    controller.reset();
    for step in 0..=last_step {
        let t = plant.time();
        let measurement = plant.measure(&mut noise);
        let raw = controller.command(t, &measurement);
        if !raw.is_finite() {
            return Err(SimError::NonFiniteCommand {
                controller: controller.describe(),
                value: raw,
                t,
            });
        }
        let command = plant.clip(raw);
        let latent = plant.latent(command);
        samples.push(Sample {
            step,
            t,
            command,
            measurement,
            latent,
        });
        if latent.theta.abs() > params.stop_theta {
            termination = Termination::ThetaLimit;
            break;
        }
        if latent.x.abs() > params.stop_x {
            termination = Termination::PositionLimit;
            break;
        }
        if step < last_step {
            plant.step(command)?;
        }
    }
    Ok(Episode {
        info: EpisodeInfo {
            params: *params,
            seed: config.seed,
            initial_theta: theta0,
            seconds: config.seconds,
            controller: controller.describe(),
            termination,
        },
        samples,
    })
}
