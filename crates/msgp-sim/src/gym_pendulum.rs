//! Gymnasium's `Pendulum-v1` as a plant, with the environment's own equations (gymnasium 1.4,
//! `classic_control/pendulum.py`): `θ̈ = 3g/(2l)·sin θ + 3/(m l²)·u` integrated by
//! semi-implicit Euler over `dt`, `θ̇` clipped to ±`max_speed`, the torque to ±`max_torque`;
//! θ = 0 upright; observation `[cos θ, sin θ, θ̇]`; starts uniform in `θ ∈ [−π, π]`,
//! `θ̇ ∈ [−1, 1]` (this crate's seeded generator, not numpy's: the same distribution, other
//! draws); reward `−(θ² + 0.1 θ̇² + 0.001 u²)` with θ wrapped to `[−π, π]`. The torque is
//! float32 as the environment's action, and so are its products (NumPy's promotion); the
//! observation is float32 as the environment returns it (the loop's run from a seed diverges
//! with the last bits of its data: `docs/experiments/2026-12-06-the-plant-tasks-per-model.md`, "The plant tasks, per model").
//!
//! The Python bindings run the environment itself; this copy lets the Rust tests, benchmarks
//! and diagnostics run the task without Python. Its test replays a run of gymnasium's own
//! environment to the last bit of its state.

use std::f64::consts::PI;

use msgp_core::learner::{LearnerSettings, PolicyFamily, TargetTask};
use msgp_core::plant::{CommandSpec, OutputSpec, Plant, PlantSpec, PlantStep};
use rand::{RngExt, SeedableRng, rngs::StdRng};

/// The pendulum's constants (gymnasium's defaults: `g = 10`, `m = l = 1`, `dt = 0.05`,
/// `max_torque = 2`, `max_speed = 8`).
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct GymPendulumParams {
    /// Gravity \[m/s²\].
    pub g: f64,
    /// Mass \[kg\].
    pub m: f64,
    /// Length \[m\].
    pub l: f64,
    /// Control period \[s\].
    pub dt: f64,
    /// Torque limit \[N m\].
    pub max_torque: f64,
    /// Angular speed limit \[rad/s\].
    pub max_speed: f64,
}

impl Default for GymPendulumParams {
    fn default() -> Self {
        Self {
            g: 10.0,
            m: 1.0,
            l: 1.0,
            dt: 0.05,
            max_torque: 2.0,
            max_speed: 8.0,
        }
    }
}

/// The `Pendulum-v1` task as the Python preset (`msgp.gym.TASKS["Pendulum-v1"]`) states it:
/// the unit tip `(cos θ, sin θ)` upright with widths 0.5, the speed not costed, 100-step
/// episodes and rollouts, an RBF network of 50 basis functions searched from each of the
/// latest 8 episodes' starts.
pub fn pendulum_v1_task() -> TargetTask {
    TargetTask {
        target: vec![1.0, 0.0, 0.0],
        widths: vec![Some(0.5), Some(0.5), None],
        width_scales: vec![1.0],
        episode_steps: 100,
        policy_horizon: 100,
        policy: PolicyFamily::Rbf { basis: 50 },
        separate_starts: Some(8),
    }
}

/// The preset's loop settings: the defaults for a plant with a window of one step (the
/// observation is the whole state) and 14 iterations after the random episode.
pub fn pendulum_v1_settings(spec: &PlantSpec, seed: u64) -> LearnerSettings {
    let mut settings = LearnerSettings::for_plant(spec);
    settings.seed = seed;
    settings.iterations = 14;
    settings.fit.ly = 1;
    settings.fit.lu = 1;
    settings
}

/// `θ` wrapped to `[−π, π)`, as the environment's reward wraps it.
pub fn wrap_angle(theta: f64) -> f64 {
    (theta + PI).rem_euclid(2.0 * PI) - PI
}

/// The environment (see the module docs); `ret` accumulates the episode's return.
#[derive(Clone, Debug)]
pub struct GymPendulum {
    params: GymPendulumParams,
    spec: PlantSpec,
    theta: f64,
    omega: f64,
    /// The return of the episode so far.
    pub ret: f64,
}

impl GymPendulum {
    /// The environment with `params`.
    pub fn new(params: GymPendulumParams) -> Self {
        let spec = PlantSpec {
            period: params.dt,
            commands: vec![CommandSpec {
                name: "torque".into(),
                low: -params.max_torque,
                high: params.max_torque,
            }],
            outputs: vec![
                OutputSpec {
                    low: Some(-1.0),
                    high: Some(1.0),
                    ..OutputSpec::named("cos_theta")
                },
                OutputSpec {
                    low: Some(-1.0),
                    high: Some(1.0),
                    ..OutputSpec::named("sin_theta")
                },
                OutputSpec {
                    low: Some(-params.max_speed),
                    high: Some(params.max_speed),
                    ..OutputSpec::named("theta_dot")
                },
            ],
        };
        Self {
            params,
            spec,
            theta: 0.0,
            omega: 0.0,
            ret: 0.0,
        }
    }

    /// Starts from a given state (for comparisons with gymnasium's).
    pub fn set_state(&mut self, theta: f64, omega: f64) -> Vec<f64> {
        self.theta = theta;
        self.omega = omega;
        self.ret = 0.0;
        self.observation()
    }

    /// `[cos θ, sin θ, θ̇]` as float32, as the environment returns it.
    fn observation(&self) -> Vec<f64> {
        [self.theta.cos(), self.theta.sin(), self.omega]
            .map(|v| f64::from(v as f32))
            .to_vec()
    }
}

impl Plant for GymPendulum {
    fn spec(&self) -> &PlantSpec {
        &self.spec
    }

    fn reset(&mut self, seed: u64) -> msgp_core::Result<Vec<f64>> {
        let mut rng = StdRng::seed_from_u64(seed);
        let theta = rng.random_range(-PI..PI);
        let omega = rng.random_range(-1.0..1.0);
        Ok(self.set_state(theta, omega))
    }

    fn step(&mut self, command: &[f64]) -> msgp_core::Result<PlantStep> {
        let p = &self.params;
        // the action is float32, and NumPy keeps the products with it in float32
        let u = command.first().copied().unwrap_or(0.0) as f32;
        let u = u.clamp(-p.max_torque as f32, p.max_torque as f32);
        let (th, w) = (self.theta, self.omega);
        self.ret -= wrap_angle(th).powi(2) + 0.1 * w * w + f64::from(0.001f32 * (u * u));
        let torque = f64::from((3.0 / (p.m * p.l * p.l)) as f32 * u);
        let accel = 3.0 * p.g / (2.0 * p.l) * th.sin() + torque;
        let w = (w + accel * p.dt).clamp(-p.max_speed, p.max_speed);
        self.theta = th + w * p.dt;
        self.omega = w;
        Ok(PlantStep {
            observation: self.observation(),
            done: false,
            truncated: false,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_hanging_pole_stays_and_upright_torque_free_falls() {
        let mut env = GymPendulum::new(GymPendulumParams::default());
        env.set_state(PI, 0.0);
        for _ in 0..10 {
            env.step(&[0.0]).expect("steps");
        }
        assert!((env.theta - PI).abs() < 1e-12 && env.omega.abs() < 1e-10);
        // from upright nudged by 0.01 rad, the first step gains 15·sin(0.01)·dt in speed
        env.set_state(0.01, 0.0);
        env.step(&[0.0]).expect("steps");
        assert!((env.omega - 15.0 * 0.01f64.sin() * 0.05).abs() < 1e-15);
        assert!((env.theta - (0.01 + env.omega * 0.05)).abs() < 1e-15);
        assert!((env.ret + 1e-4).abs() < 1e-15);
    }

    /// gymnasium 1.4's own run: `env.unwrapped.state = [2.5, −0.7]`, then these torques (as
    /// float32, the action space's type): its final state and its return.
    #[test]
    fn steps_as_gymnasium_does() {
        let torques: [f32; 8] = [2.0, -2.0, 1.3, 3.5, -0.4, 0.0, 1.9, -1.1];
        let mut env = GymPendulum::new(GymPendulumParams::default());
        env.set_state(2.5, -0.7);
        for u in torques {
            let y = env.step(&[f64::from(u)]).expect("steps").observation;
            assert!(
                y.iter().all(|&v| f64::from(v as f32) == v),
                "float32: {y:?}"
            );
            assert!(
                (y[2] - env.omega).abs() < 1e-6 && y[2] != env.omega,
                "{y:?}"
            );
        }
        assert!(
            (env.theta - 3.097_569_834_353_038_2).abs() < 1e-12,
            "{}",
            env.theta
        );
        assert!(
            (env.omega - 2.638_767_712_624_561_2).abs() < 1e-12,
            "{}",
            env.omega
        );
        assert!(
            (env.ret + 58.410_824_674_976_26).abs() < 1e-9,
            "{}",
            env.ret
        );
    }

    #[test]
    fn wrapping_keeps_angles_in_the_half_open_circle() {
        assert!((wrap_angle(3.0 * PI / 2.0) + PI / 2.0).abs() < 1e-12);
        assert!((wrap_angle(-PI) + PI).abs() < 1e-12);
        assert!((wrap_angle(0.3) - 0.3).abs() < 1e-15);
    }
}
