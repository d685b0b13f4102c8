//! The plant as a controller sees it: noisy measurements in, acceleration commands out.

use std::f64::consts::{PI, TAU};

use rand::Rng;
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use crate::actuator::Actuator;
use crate::error::SimError;
use crate::params::PendulumParams;
use crate::physics::PoleWorld;

/// What a controller may see: noisy pole angle and end-effector position.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct Measurement {
    /// Measured pole angle \[rad\] (true angle + N(0, `sigma_theta`²)).
    pub theta: f64,
    /// Measured end-effector position \[m\] (true position + N(0, `sigma_x`²)).
    pub x: f64,
}

/// The true, unmeasured state — recorded for analysis only, never given to controllers.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
pub struct LatentState {
    /// True pole angle \[rad\].
    pub theta: f64,
    /// True pole angular velocity \[rad/s\].
    pub theta_dot: f64,
    /// True end-effector position \[m\].
    pub x: f64,
    /// True end-effector velocity \[m/s\].
    pub x_dot: f64,
    /// Lag state = true end-effector acceleration \[m/s²\].
    pub lag_acceleration: f64,
    /// The command waiting in the delay line that drives the lag during the next control
    /// period (issued `command_delay_steps` periods earlier) \[m/s²\]. With zero delay it is
    /// the command issued at this step.
    pub delayed_command: f64,
}

/// Simulated robot arm + pole, stepped one control period at a time. The pole angle is
/// continuous: a full turn adds 2π (the rapier world's angle wraps at ±π; the turns are
/// counted every physics step, far below half a turn apart).
#[derive(Debug)]
pub struct Plant {
    params: PendulumParams,
    actuator: Actuator,
    world: PoleWorld,
    time: f64,
    steps: u64,
    /// Whole turns added to the world's angle (0 while it never crossed ±π).
    turns: f64,
    /// The world's angle at the last physics step.
    last_raw: f64,
}

impl Plant {
    /// Validates `params` and builds the plant at rest with the pole at `theta0` \[rad\]
    /// (any finite angle: π hangs it).
    pub fn new(params: &PendulumParams, theta0: f64) -> Result<Self, SimError> {
        params.validate()?;
        if !theta0.is_finite() {
            return Err(SimError::invalid("initial_theta", theta0, "must be finite"));
        }
        let world = PoleWorld::new(params, theta0);
        let last_raw = world.theta();
        let turns = ((theta0 - last_raw) / TAU).round();
        Ok(Self {
            params: *params,
            actuator: Actuator::new(params.command_delay_steps, params.lag_time_constant),
            world,
            time: 0.0,
            steps: 0,
            turns,
            last_raw,
        })
    }

    /// The true pole angle, continuous over turns \[rad\].
    pub fn theta(&self) -> f64 {
        self.last_raw + TAU * self.turns
    }

    /// The plant's parameters.
    pub fn params(&self) -> &PendulumParams {
        &self.params
    }

    /// Simulation time \[s\] (control steps × control period).
    pub fn time(&self) -> f64 {
        self.time
    }

    /// Draws a noisy measurement of the current state. Always consumes two normal samples
    /// from `rng` (also when a σ is zero), so the noise stream does not depend on σ.
    pub fn measure<R: Rng + ?Sized>(&self, rng: &mut R) -> Measurement {
        let n_theta: f64 = StandardNormal.sample(rng);
        let n_x: f64 = StandardNormal.sample(rng);
        Measurement {
            theta: self.theta() + self.params.sigma_theta * n_theta,
            x: self.actuator.position() + self.params.sigma_x * n_x,
        }
    }

    /// The true state. `pending_command` is the command about to be issued at this step;
    /// it only matters for zero command delay (see [`LatentState::delayed_command`]).
    pub fn latent(&self, pending_command: f64) -> LatentState {
        LatentState {
            theta: self.theta(),
            theta_dot: self.world.theta_dot(),
            x: self.actuator.position(),
            x_dot: self.actuator.velocity(),
            lag_acceleration: self.actuator.acceleration(),
            delayed_command: self.actuator.next_applied().unwrap_or(pending_command),
        }
    }

    /// Clips a command to the action limit (NaN stays NaN and is rejected by [`step`](Self::step)).
    pub fn clip(&self, command: f64) -> f64 {
        command.clamp(-self.params.action_limit, self.params.action_limit)
    }

    /// Issues `command` (clipped to the action limit) and simulates one control period.
    pub fn step(&mut self, command: f64) -> Result<(), SimError> {
        if !command.is_finite() {
            return Err(SimError::NonFiniteCommand {
                controller: "plant input".to_owned(),
                value: command,
                t: self.time,
            });
        }
        self.actuator.issue(self.clip(command));
        let h = self.params.physics_step();
        for _ in 0..self.params.substeps() {
            self.actuator.advance(h);
            self.world.step(self.actuator.position());
            let raw = self.world.theta();
            if raw - self.last_raw > PI {
                self.turns -= 1.0;
            } else if raw - self.last_raw < -PI {
                self.turns += 1.0;
            }
            self.last_raw = raw;
        }
        self.steps += 1;
        self.time = self.steps as f64 * self.params.control_period();
        let theta = self.theta();
        if !(theta.is_finite() && self.world.theta_dot().is_finite()) {
            return Err(SimError::NonFiniteState { t: self.time });
        }
        Ok(())
    }

    /// Pivot position as integrated by rapier \[m\]; equals the commanded end-effector
    /// position up to the joint solver's error.
    pub fn pivot_x(&self) -> f64 {
        self.world.pivot_x()
    }
}
