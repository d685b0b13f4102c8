//! The loop's named plant tasks: Gymnasium's `Pendulum-v1` (the Rust copy of its equations,
//! [`crate::gym_pendulum`]) and the arm-mounted pendulum's swing-up ([`crate::swing_up`]), each
//! with its plant, target, preset settings per model ([`msgp_core::learner::LoopModel`]) and
//! score. `msgp reproduce plant-task --task NAME` (crate `msgp-reproduce`) runs each task with
//! the four loop models over seeds.

use std::str::FromStr;

use msgp_core::learner::{
    Actor, Episode, LearnerSettings, LoopModel, TargetTask, run_episode, with_model,
};
use msgp_core::plant::Plant;
use msgp_core::policy::Policy;
use serde::{Deserialize, Serialize};

use crate::error::SimError;
use crate::gym_pendulum::{GymPendulum, GymPendulumParams, pendulum_v1_settings, pendulum_v1_task};
use crate::swing_up::{
    SwingUp, held_upright, success_seed, swing_up_params, swing_up_settings, swing_up_task,
};

/// `Pendulum-v1`'s evaluation: episodes of this many steps, as the environment's time limit.
pub const PENDULUM_V1_EVALUATION_STEPS: usize = 200;
/// … from this many seeded random starts.
pub const PENDULUM_V1_EVALUATION_STARTS: usize = 100;
/// … and the task is learned when their mean return reaches this.
pub const PENDULUM_V1_SOLVED_RETURN: f64 = -200.0;
/// The swing-up's success test: this many seeded starts near hanging, every one held.
pub const SWING_UP_STARTS: usize = 5;

/// A named task of the loop on a plant.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum PlantTask {
    /// Gymnasium's `Pendulum-v1`: pump the pole up with a torque of at most 2 and hold it.
    PendulumV1,
    /// The arm-mounted pendulum: swing up from hanging and balance on the end effector.
    SwingUp,
}

impl PlantTask {
    /// Every task.
    pub const ALL: [PlantTask; 2] = [PlantTask::PendulumV1, PlantTask::SwingUp];

    /// Name on the command line, in folders and sections.
    pub fn name(self) -> &'static str {
        match self {
            PlantTask::PendulumV1 => "pendulum-v1",
            PlantTask::SwingUp => "swing-up",
        }
    }

    /// A fresh plant of the task.
    pub fn plant(self) -> Result<Box<dyn Plant>, SimError> {
        Ok(match self {
            PlantTask::PendulumV1 => Box::new(GymPendulum::new(GymPendulumParams::default())),
            PlantTask::SwingUp => Box::new(SwingUp::new(&swing_up_params())?),
        })
    }

    /// The task's target, cost, episode and policy.
    pub fn target(self) -> TargetTask {
        match self {
            PlantTask::PendulumV1 => pendulum_v1_task(),
            PlantTask::SwingUp => swing_up_task(),
        }
    }

    /// The loop's settings of `model` and `seed`: the task's preset, its model replaced.
    pub fn settings(self, model: LoopModel, seed: u64) -> Result<LearnerSettings, SimError> {
        let plant = self.plant()?;
        let preset = match self {
            PlantTask::PendulumV1 => pendulum_v1_settings(plant.spec(), seed),
            PlantTask::SwingUp => swing_up_settings(plant.spec(), seed),
        };
        Ok(with_model(preset, model)?)
    }

    /// What the task's score of a policy is, for tables and plots.
    pub fn score_name(self) -> &'static str {
        match self {
            PlantTask::PendulumV1 => "mean return over 100 random starts (200 steps)",
            PlantTask::SwingUp => "starts near hanging held upright over the last 2 s (of 5)",
        }
    }

    /// The task's score of `policy` and whether it solves the task.
    pub fn score(self, policy: &Policy) -> Result<(f64, bool), SimError> {
        match self {
            PlantTask::PendulumV1 => {
                let r = pendulum_v1_return(policy, GymPendulumParams::default())?;
                Ok((r, r >= PENDULUM_V1_SOLVED_RETURN))
            }
            PlantTask::SwingUp => {
                let held = swing_up_held(policy)?;
                Ok((held as f64, held == SWING_UP_STARTS))
            }
        }
    }
}

impl FromStr for PlantTask {
    type Err = String;

    fn from_str(s: &str) -> Result<Self, String> {
        PlantTask::ALL
            .into_iter()
            .find(|t| t.name() == s)
            .ok_or_else(|| format!("unknown task `{s}` (known: pendulum-v1, swing-up)"))
    }
}

/// `Pendulum-v1`'s score of `policy`: the mean return of [`PENDULUM_V1_EVALUATION_STARTS`]
/// episodes of [`PENDULUM_V1_EVALUATION_STEPS`] steps from seeded random starts (seeds
/// `1_000_000 + k`, apart from every loop's episode seeds), as the environment scores them.
pub fn pendulum_v1_return(policy: &Policy, params: GymPendulumParams) -> Result<f64, SimError> {
    let mut env = GymPendulum::new(params);
    let actor = Actor::Policy {
        policy,
        rest: &[0.0],
    };
    let mut total = 0.0;
    for k in 0..PENDULUM_V1_EVALUATION_STARTS {
        run_episode(
            &mut env,
            &actor,
            1_000_000 + k as u64,
            PENDULUM_V1_EVALUATION_STEPS,
        )?;
        total += env.ret;
    }
    Ok(total / PENDULUM_V1_EVALUATION_STARTS as f64)
}

/// The swing-up's score of `policy`: of [`SWING_UP_STARTS`] seeded starts near hanging
/// ([`success_seed`]), how many whole episodes end held upright ([`held_upright`]).
pub fn swing_up_held(policy: &Policy) -> Result<usize, SimError> {
    let period = swing_up_params().control_period();
    let held = success_episodes(policy, swing_up_task().episode_steps)?
        .iter()
        .filter(|ep| {
            let thetas: Vec<f64> = ep.outputs.iter().map(|y| y[0]).collect();
            !ep.ended_early && held_upright(&thetas, period)
        })
        .count();
    Ok(held)
}

/// `policy`'s episodes of `steps` control steps from the swing-up's [`SWING_UP_STARTS`]
/// success-test starts ([`success_seed`]).
pub fn success_episodes(policy: &Policy, steps: usize) -> Result<Vec<Episode>, SimError> {
    let mut plant = SwingUp::new(&swing_up_params())?;
    let rest = plant.spec().bounds()?.mid();
    let actor = Actor::Policy {
        policy,
        rest: &rest,
    };
    (0..SWING_UP_STARTS)
        .map(|k| Ok(run_episode(&mut plant, &actor, success_seed(k), steps)?))
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use msgp_core::gp::MeanFunction;
    use msgp_core::loss::Likelihood;
    use msgp_core::model::Method;

    #[test]
    fn each_model_replaces_only_the_presets_model() {
        let preset = PlantTask::SwingUp
            .settings(LoopModel::MsgpFilter, 3)
            .expect("preset");
        assert_eq!(preset.seed, 3);
        assert!(preset.prequential_choice);
        let free = with_model(preset.clone(), LoopModel::Msgp).expect("msgp");
        assert_eq!(
            free.fit.msgp().map(|m| m.likelihood),
            Some(Likelihood::FreeRun)
        );
        assert!(free.prequential_choice);
        let narx = with_model(preset.clone(), LoopModel::GpNarx).expect("gp-narx");
        assert_eq!(narx.method(), Method::GpNarx);
        assert_eq!(narx.fit.inducing(), preset.fit.inducing());
        assert_eq!(narx.fit.mean(), MeanFunction::Linear);
        assert!(!narx.prequential_choice);
        assert_eq!((narx.fit.ly, narx.fit.lu), (preset.fit.ly, preset.fit.lu));
        let linear = with_model(preset.clone(), LoopModel::LinearKf).expect("linear-kf");
        assert_eq!(linear.method(), Method::LinearKf);
        assert_eq!(linear.search, preset.search);
        // a preset without an MSGP fit has no MSGP to take the models from
        let e = with_model(linear, LoopModel::GpNarx).expect_err("no MSGP");
        assert!(e.to_string().contains("fit.method"), "{e}");
    }
}
