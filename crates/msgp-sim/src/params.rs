//! Plant parameters of the pendulum-on-end-effector simulator.

use serde::{Deserialize, Serialize};

use crate::error::{SimError, require_finite, require_non_negative, require_positive};

/// Largest accepted command delay, in control steps.
pub const MAX_DELAY_STEPS: u32 = 1000;

/// Largest accepted number of physics steps per control step.
pub const MAX_SUBSTEPS: u32 = 100_000;

/// Physical and interface parameters of the simulated robot + pole.
///
/// Defaults follow the public Apollo-robot pole and the paper's robot setup (section 4.2), with
/// the measurement noise of the [`PlantTier::Apollo`] tier; [`PendulumParams::tier`] gives the
/// other.
/// All fields are SI units. Construct with [`Default`] and override fields, then call
/// [`PendulumParams::validate`] (every simulator entry point validates again).
///
/// Conventions: the end effector moves along the world x axis; `theta` is the pole angle
/// from the upward vertical, **positive when the pole leans toward +x**. A positive
/// acceleration command accelerates the end effector toward +x, which tips the pole toward
/// −x (it decreases `theta`'s acceleration).
///
/// In JSON every field is optional; missing fields take their default values.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct PendulumParams {
    /// Pole length \[m\] (used for the default inertia; the geometry itself is not simulated).
    pub pole_length: f64,
    /// Pole mass \[kg\].
    pub pole_mass: f64,
    /// Distance of the pole's centre of mass from the pivot \[m\], `0 < com <= pole_length`.
    pub pole_com: f64,
    /// Pole moment of inertia about its centre of mass, perpendicular to the pole \[kg·m²\].
    /// Default: a uniform rod, `pole_mass · pole_length² / 12` (the real pole's inertia is not
    /// public; with `pole_com` this gives 0.1453 kg·m² about the pivot).
    pub pole_inertia_com: f64,
    /// Viscous hinge damping \[N·m·s/rad\]: torque `-hinge_damping · theta_dot`.
    pub hinge_damping: f64,
    /// Gravitational acceleration \[m/s²\], pointing down. A negative value hangs the pole
    /// (its "upright" position becomes stable); the model tests use that to check damping.
    pub gravity: f64,
    /// Commands are clipped to `±action_limit` \[m/s²\].
    pub action_limit: f64,
    /// Control (measurement and command) rate \[Hz\].
    pub control_rate_hz: f64,
    /// Physics rate \[Hz\]; must be an integer multiple of `control_rate_hz`.
    pub physics_rate_hz: f64,
    /// Commands reach the actuator this many control steps after they are issued.
    pub command_delay_steps: u32,
    /// Time constant of the first-order lag between the delayed command and the
    /// end-effector acceleration \[s\]; 0 disables the lag.
    pub lag_time_constant: f64,
    /// Standard deviation of the additive Gaussian noise on the measured pole angle \[rad\].
    pub sigma_theta: f64,
    /// Standard deviation of the additive Gaussian noise on the measured end-effector
    /// position \[m\].
    pub sigma_x: f64,
    /// Standard deviation of the random initial pole angle \[rad\] (mean 0).
    pub initial_theta_std: f64,
    /// An episode stops early once the true `|theta|` exceeds this \[rad\].
    pub stop_theta: f64,
    /// An episode stops early once the true `|x|` exceeds this \[m\].
    pub stop_x: f64,
}

impl Default for PendulumParams {
    fn default() -> Self {
        let pole_length = 1.067;
        let pole_mass = 0.2903;
        Self {
            pole_length,
            pole_mass,
            pole_com: 0.637,
            pole_inertia_com: pole_mass * pole_length * pole_length / 12.0,
            hinge_damping: 0.0116,
            gravity: 9.81,
            action_limit: 3.0,
            control_rate_hz: 50.0,
            physics_rate_hz: 1000.0,
            command_delay_steps: 1,
            lag_time_constant: 0.03,
            sigma_theta: APOLLO_SIGMA_THETA,
            sigma_x: APOLLO_SIGMA_X,
            initial_theta_std: 0.02,
            stop_theta: 0.5,
            stop_x: 0.5,
        }
    }
}

/// Measurement-noise tiers of the plant: everything else (pole, delay, lag, rates) is the same.
#[derive(Debug, Clone, Copy, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum PlantTier {
    /// As precise as the paper's robot (the default): the angle noise of the Apollo code's own
    /// simulator ([`APOLLO_SIGMA_THETA`]), the end-effector position as joint encoders give it
    /// ([`APOLLO_SIGMA_X`]).
    #[default]
    Apollo,
    /// The stress tier: `σθ` = [`NOISY_SIGMA_THETA`] = 5 mrad, `σx` = [`NOISY_SIGMA_X`] = 2 mm,
    /// about 100× the robot's angle noise (the project's first plant).
    Noisy,
}

impl PlantTier {
    /// Name on the command line.
    pub fn name(&self) -> &'static str {
        match self {
            PlantTier::Apollo => "apollo",
            PlantTier::Noisy => "noisy",
        }
    }
}

/// Angle noise of the Apollo tier \[rad\]: `sigma_n` of the simulator in the public code of the
/// Apollo pole-balancing setup (github `alonrot/lqr_control_robot_apollo`,
/// `config/task_parameters.yaml`), where Vicon measures the angle at 200 Hz.
pub const APOLLO_SIGMA_THETA: f64 = 5.1985e-5;

/// End-effector position noise of the Apollo tier \[m\]: the arm's joint encoders through its
/// forward kinematics. Industrial arms of the Apollo arms' class are specified at a pose
/// repeatability of ±0.02–0.05 mm; 0.1 mm is taken (an assumption: no public source gives the
/// robot's own figure), twice the coarse end of that range.
pub const APOLLO_SIGMA_X: f64 = 1e-4;

/// Angle noise of the noisy tier \[rad\].
pub const NOISY_SIGMA_THETA: f64 = 5e-3;

/// End-effector position noise of the noisy tier \[m\].
pub const NOISY_SIGMA_X: f64 = 2e-3;

impl PendulumParams {
    /// The default plant with the measurement noise of `tier`.
    pub fn tier(tier: PlantTier) -> Self {
        match tier {
            PlantTier::Apollo => Self::default(),
            PlantTier::Noisy => Self {
                sigma_theta: NOISY_SIGMA_THETA,
                sigma_x: NOISY_SIGMA_X,
                ..Self::default()
            },
        }
    }

    /// Checks every field; returns the first violation found.
    pub fn validate(&self) -> Result<(), SimError> {
        require_positive("pole_length", self.pole_length)?;
        require_positive("pole_mass", self.pole_mass)?;
        require_positive("pole_com", self.pole_com)?;
        if self.pole_com > self.pole_length {
            return Err(SimError::invalid(
                "pole_com",
                self.pole_com,
                "must not exceed pole_length",
            ));
        }
        require_positive("pole_inertia_com", self.pole_inertia_com)?;
        require_non_negative("hinge_damping", self.hinge_damping)?;
        require_finite("gravity", self.gravity)?;
        require_positive("action_limit", self.action_limit)?;
        require_positive("control_rate_hz", self.control_rate_hz)?;
        require_positive("physics_rate_hz", self.physics_rate_hz)?;
        let ratio = self.physics_rate_hz / self.control_rate_hz;
        let rounded = ratio.round();
        if !(1.0..=f64::from(MAX_SUBSTEPS)).contains(&rounded)
            || (ratio - rounded).abs() > 1e-9 * rounded
        {
            return Err(SimError::invalid(
                "physics_rate_hz",
                self.physics_rate_hz,
                "must be an integer multiple (1..=100000) of control_rate_hz",
            ));
        }
        if self.command_delay_steps > MAX_DELAY_STEPS {
            return Err(SimError::invalid(
                "command_delay_steps",
                f64::from(self.command_delay_steps),
                "must be at most 1000",
            ));
        }
        require_non_negative("lag_time_constant", self.lag_time_constant)?;
        require_non_negative("sigma_theta", self.sigma_theta)?;
        require_non_negative("sigma_x", self.sigma_x)?;
        require_non_negative("initial_theta_std", self.initial_theta_std)?;
        require_positive("stop_theta", self.stop_theta)?;
        require_positive("stop_x", self.stop_x)?;
        Ok(())
    }

    /// Control period \[s\].
    pub fn control_period(&self) -> f64 {
        1.0 / self.control_rate_hz
    }

    /// Physics step \[s\].
    pub fn physics_step(&self) -> f64 {
        1.0 / self.physics_rate_hz
    }

    /// Physics steps per control step (valid after [`validate`](Self::validate)).
    pub fn substeps(&self) -> u32 {
        // Validation bounds the ratio to 1..=MAX_SUBSTEPS, so the cast is exact.
        (self.physics_rate_hz / self.control_rate_hz).round() as u32
    }

    /// Moment of inertia about the pivot \[kg·m²\]: `pole_inertia_com + pole_mass · pole_com²`.
    pub fn inertia_about_pivot(&self) -> f64 {
        self.pole_inertia_com + self.pole_mass * self.pole_com * self.pole_com
    }

    /// Same parameters with measurement noise switched off.
    pub fn noiseless(&self) -> Self {
        Self {
            sigma_theta: 0.0,
            sigma_x: 0.0,
            ..*self
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn defaults_are_valid() {
        PendulumParams::default()
            .validate()
            .expect("defaults validate");
        assert_eq!(PendulumParams::default().substeps(), 20);
        assert_eq!(
            PendulumParams::default(),
            PendulumParams::tier(PlantTier::default())
        );
        assert_eq!(PlantTier::default(), PlantTier::Apollo);
        let noisy = PendulumParams::tier(PlantTier::Noisy);
        assert_eq!((noisy.sigma_theta, noisy.sigma_x), (5e-3, 2e-3));
        noisy.validate().expect("the noisy tier validates");
    }

    #[test]
    fn rejects_bad_values() {
        let bad = [
            PendulumParams {
                pole_mass: -1.0,
                ..Default::default()
            },
            PendulumParams {
                pole_com: 2.0,
                ..Default::default()
            },
            PendulumParams {
                physics_rate_hz: 1010.0,
                ..Default::default()
            },
            PendulumParams {
                control_rate_hz: f64::NAN,
                ..Default::default()
            },
            PendulumParams {
                command_delay_steps: 5000,
                ..Default::default()
            },
            PendulumParams {
                sigma_x: f64::INFINITY,
                ..Default::default()
            },
        ];
        for p in bad {
            assert!(p.validate().is_err(), "{p:?} should be rejected");
        }
    }

    #[test]
    fn json_fields_are_optional_and_checked() {
        let p: PendulumParams =
            serde_json::from_str(r#"{"pole_mass": 0.5}"#).expect("partial params parse");
        assert_eq!(p.pole_mass, 0.5);
        assert_eq!(p.pole_com, 0.637);
        assert!(serde_json::from_str::<PendulumParams>(r#"{"pole_mas": 0.5}"#).is_err());
    }
}
