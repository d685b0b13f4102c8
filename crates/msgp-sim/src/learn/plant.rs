//! The simulated pendulum as a plant of the learning loop ([`msgp_core::plant::Plant`]):
//! outputs `[θ, x]` (measured, the angle flagged), the commanded end-effector acceleration,
//! the control period of its parameters. A reset with seed `s` starts the episode
//! [`run_episode`](crate::episode::run_episode) would run with `s` (initial angle and noise
//! from their own streams); the episode ends where that one stops (the pole fell, the arm left
//! its range). The plant records every episode in full (latent states included) for the run's
//! folder and plots.

use msgp_core::MsgpError;
use msgp_core::plant::{CommandSpec, OutputSpec, Plant as LoopPlant, PlantSpec, PlantStep};
use rand::SeedableRng;
use rand::rngs::Xoshiro256PlusPlus;
use rand_distr::{Distribution, StandardNormal};

use crate::episode::{Episode, EpisodeInfo, Sample, Termination};
use crate::error::SimError;
use crate::params::PendulumParams;
use crate::plant::{Measurement, Plant};
use crate::seed::{Stream, rng_for};

/// An episode in progress.
#[derive(Debug)]
struct Running {
    plant: Plant,
    noise: Xoshiro256PlusPlus,
    episode: Episode,
    /// The measurement of the step whose command has not come yet.
    pending: Measurement,
}

/// The pendulum as the loop's plant (see the module docs).
#[derive(Debug)]
pub struct PendulumPlant {
    params: PendulumParams,
    /// The episodes' requested length \[s\] (their record's).
    seconds: f64,
    spec: PlantSpec,
    running: Option<Running>,
    recorded: Vec<Episode>,
}

impl PendulumPlant {
    /// The plant of `params` (checked), for episodes of `seconds` (their record's length).
    pub fn new(params: &PendulumParams, seconds: f64) -> Result<Self, SimError> {
        params.validate()?;
        let spec = PlantSpec {
            period: params.control_period(),
            commands: vec![acceleration_command(params)],
            outputs: vec![
                OutputSpec {
                    angle: true,
                    ..OutputSpec::named("theta")
                },
                OutputSpec::named("x"),
            ],
        };
        Ok(Self {
            params: *params,
            seconds,
            spec,
            running: None,
            recorded: Vec::new(),
        })
    }

    /// Every episode run so far, in full; the last one's final command is the one the loop
    /// chose for its last observation (`commands`), which a plant never receives.
    pub fn take_episodes(&mut self, last_commands: &[(u64, f64)]) -> Vec<Episode> {
        self.finish();
        let mut out = std::mem::take(&mut self.recorded);
        for ep in &mut out {
            if let Some((_, u)) = last_commands.iter().find(|(s, _)| *s == ep.info.seed)
                && let Some(last) = ep.samples.last_mut()
                && last.command.is_nan()
            {
                last.command = *u;
                if last.latent.delayed_command.is_nan() {
                    last.latent.delayed_command = *u;
                }
            }
        }
        out
    }

    /// Closes the running episode: its last measurement becomes its last sample, with the
    /// command still unknown (NaN until [`PendulumPlant::take_episodes`] fills it in).
    fn finish(&mut self) {
        if let Some(mut r) = self.running.take() {
            let step = r.episode.samples.len() as u64;
            let t = r.plant.time();
            r.episode.samples.push(Sample {
                step,
                t,
                command: f64::NAN,
                measurement: r.pending,
                latent: r.plant.latent(f64::NAN),
            });
            self.recorded.push(r.episode);
        }
    }

    fn termination(&self, r: &Running) -> Termination {
        let latent = r.plant.latent(0.0);
        if latent.theta.abs() > self.params.stop_theta {
            Termination::ThetaLimit
        } else if latent.x.abs() > self.params.stop_x {
            Termination::PositionLimit
        } else {
            Termination::Completed
        }
    }
}

/// The end effector's acceleration command within the action limit.
pub(crate) fn acceleration_command(params: &PendulumParams) -> CommandSpec {
    CommandSpec {
        name: "acceleration".into(),
        low: -params.action_limit,
        high: params.action_limit,
    }
}

/// A simulator error as the loop's plant error.
pub fn plant_error(e: SimError) -> MsgpError {
    MsgpError::Plant(e.to_string())
}

impl LoopPlant for PendulumPlant {
    fn spec(&self) -> &PlantSpec {
        &self.spec
    }

    fn reset(&mut self, seed: u64) -> msgp_core::Result<Vec<f64>> {
        self.finish();
        let mut rng = Xoshiro256PlusPlus::seed_from_u64(rng_for(seed, Stream::InitialState));
        let n: f64 = StandardNormal.sample(&mut rng);
        let theta0 = self.params.initial_theta_std * n;
        let plant = Plant::new(&self.params, theta0).map_err(plant_error)?;
        let mut noise = Xoshiro256PlusPlus::seed_from_u64(rng_for(seed, Stream::MeasurementNoise));
        let pending = plant.measure(&mut noise);
        self.running = Some(Running {
            plant,
            noise,
            pending,
            episode: Episode {
                info: EpisodeInfo {
                    params: self.params,
                    seed,
                    initial_theta: theta0,
                    seconds: self.seconds,
                    controller: "msgp learner".into(),
                    termination: Termination::Completed,
                },
                samples: Vec::new(),
            },
        });
        Ok(vec![pending.theta, pending.x])
    }

    fn step(&mut self, command: &[f64]) -> msgp_core::Result<PlantStep> {
        let Some(r) = self.running.as_mut() else {
            return Err(MsgpError::Plant("step before the first reset".into()));
        };
        let [u] = command else {
            return Err(MsgpError::Plant(format!(
                "the pendulum takes one command, got {}",
                command.len()
            )));
        };
        if !u.is_finite() {
            return Err(plant_error(SimError::NonFiniteCommand {
                controller: "msgp learner".into(),
                value: *u,
                t: r.plant.time(),
            }));
        }
        let u = r.plant.clip(*u);
        let step = r.episode.samples.len() as u64;
        r.episode.samples.push(Sample {
            step,
            t: r.plant.time(),
            command: u,
            measurement: r.pending,
            latent: r.plant.latent(u),
        });
        r.plant.step(u).map_err(plant_error)?;
        r.pending = r.plant.measure(&mut r.noise);
        let observation = vec![r.pending.theta, r.pending.x];
        let termination = match self.running.as_ref() {
            Some(r) => self.termination(r),
            None => Termination::Completed,
        };
        if let Some(r) = self.running.as_mut() {
            r.episode.info.termination = termination;
        }
        Ok(PlantStep {
            observation,
            done: termination != Termination::Completed,
            truncated: false,
        })
    }
}
