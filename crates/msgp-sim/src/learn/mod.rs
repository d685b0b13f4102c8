//! PILCO with MSGP (or one-step GP-NARX) models on the simulated pendulum: learning to balance
//! from scratch (paper section 4.2), the pendulum's preset of the generic loop
//! ([`msgp_core::learner`]).
//!
//! The pendulum is the loop's plant ([`PendulumPlant`]); its task ([`pendulum_task`]) is the
//! saturating cost on `[θ, x]` around upright, rollouts from rest, and the PID + PD gains of
//! the simulator's policy (the modelled [`msgp_core::policy::PidPolicy`] with the sine
//! saturation) as the searched policy. After every iteration the simulator's stability test
//! judges the gains (the task's success test); it is neither interaction time nor training
//! data. The loop's settings and their defaults per model are [`LearnSettings`].

mod budget;
mod episodes;
pub(crate) mod plant;
mod problem;
mod record;
mod report;
mod settings;

pub use budget::Budget;
pub use episodes::episode_trajectory;
pub use msgp_core::learner::{HeldOut, ModelChoice, SearchModel, segments};
pub use plant::{PendulumPlant, plant_error};
pub use problem::{
    episode_cost, gains_from, learner_settings, modelled_policy, pendulum_problem, pendulum_task,
};
pub use record::{FinishedRun, finished_run, summary, write_run_dir};
pub use report::{IterationReport, LearnOutcome};
pub use settings::{
    END_EFFECTOR_INTEGRATOR, END_EFFECTOR_KINEMATIC, EVALUATION_EPISODES, FILTER_NOISE_FLOOR,
    FILTERED_MSGP_INDUCING, FILTERED_MSGP_ITERATIONS, FILTERED_MSGP_SEARCH_ITERATIONS,
    FILTERED_MSGP_WARM_START, LEARN_INDUCING, LINEAR_KF_POLICY_HORIZON_SECONDS,
    LINEAR_KF_WARM_START, LearnSettings, learn_excitation,
};

use std::ops::ControlFlow;

use msgp_core::MsgpError;
use msgp_core::fit::FitProgress;
use msgp_core::learner::{self, Learner, SuccessTest};
use msgp_core::policy::Policy;

use crate::error::SimError;
use crate::params::PendulumParams;
use crate::stability::{StabilityCriteria, stability_test};

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

/// The stability test as the task's success test.
struct Stability<'a> {
    params: &'a PendulumParams,
    seed: u64,
}

impl SuccessTest for Stability<'_> {
    fn passed(&mut self, policy: &Policy) -> msgp_core::Result<bool> {
        let stable = gains_from(policy)
            .and_then(|g| stability_test(self.params, &g, self.seed, &StabilityCriteria::default()))
            .map_err(|e| MsgpError::Plant(e.to_string()))?;
        Ok(stable.passed)
    }
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
    let task = pendulum_task(params, settings)?;
    let mut learner = Learner::new(task, learner_settings(params, settings)?)?;
    let mut plant = PendulumPlant::new(params, settings.episode_seconds)?;
    let mut judge = Stability {
        params,
        seed: settings.seed,
    };
    let mut reports = Vec::new();
    let mut failure = None;
    let run = learner.run(&mut plant, Some(&mut judge), &mut |e| {
        let event = match e {
            learner::LearnEvent::Episode { .. } => return ControlFlow::Continue(()),
            learner::LearnEvent::FitStarted { iteration } => LearnEvent::FitStarted { iteration },
            learner::LearnEvent::Fit {
                iteration,
                progress,
            } => LearnEvent::Fit {
                iteration,
                progress,
            },
            learner::LearnEvent::SearchStarted { iteration } => {
                LearnEvent::SearchStarted { iteration }
            }
            learner::LearnEvent::Iteration(r) => match IterationReport::from_loop(r) {
                Ok(report) => {
                    let flow = observe(LearnEvent::Iteration(&report));
                    reports.push(report);
                    return flow;
                }
                Err(e) => {
                    failure = Some(e);
                    return ControlFlow::Break(());
                }
            },
        };
        observe(event)
    });
    if let Some(e) = failure {
        return Err(e);
    }
    match run {
        Ok(()) => {}
        Err(MsgpError::Stopped { iteration }) => return Err(SimError::Stopped { iteration }),
        Err(e) => return Err(e.into()),
    }
    let last: Vec<(u64, f64)> = learner
        .episodes()
        .iter()
        .filter_map(|e| Some((e.seed, *e.commands.last()?.first()?)))
        .collect();
    let recorded = plant.take_episodes(&last);
    // the interaction episodes, in the loop's order (the plant also ran the evaluations)
    let episodes = learner
        .episodes()
        .iter()
        .filter_map(|e| recorded.iter().find(|r| r.info.seed == e.seed).cloned())
        .collect();
    Ok(LearnOutcome {
        iterations: reports,
        episodes,
        final_gains: gains_from(learner.policy())?,
    })
}

#[cfg(test)]
mod tests;
