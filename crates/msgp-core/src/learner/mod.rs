//! The learning loop of PILCO with MSGP models (paper section 4.2) on any [`Plant`]: random
//! episodes → fit the model on every episode so far (open-loop ones feed-forward, policy ones
//! in closed loop under the policy that ran them, the paper's `L_fb`) → search the policy on
//! the model (the expected saturating cost of a closed-loop moment-matching rollout, exact
//! gradients, [`crate::policy_search`]) → run it on the plant for one episode → repeat.
//!
//! A [`Task`] says what is asked of the plant; [`LearnerSettings`] how the loop fits and
//! searches. A [`Learner`] holds the loop's state — every episode run so far stays with it when
//! the plant fails or an observer stops the loop. [`improve`] is one iteration's fit and search
//! on episodes logged elsewhere (a real robot's). Under the prequential choice ([`choice`]) the
//! search runs on the GP model only while it predicts the episodes it had not seen better than
//! the linear model of the same data.

pub mod choice;
pub mod episode;
pub mod excitation;
pub mod improve;
pub mod loop_model;
pub mod report;
pub mod settings;
pub mod target;
pub mod task;

pub use choice::{HeldOut, ModelChoice, RolloutNll, SearchModel};
pub use episode::{Actor, Episode, run_episode, segments};
pub use excitation::{ExcitationConfig, Multisine};
pub use improve::{FitAndSearch, fit_and_search, training_entries};
pub use loop_model::{LoopModel, with_model};
pub use report::IterationReport;
pub use settings::LearnerSettings;
pub use target::{PolicyFamily, TargetTask};
pub use task::{StartDistribution, Task, stated_cost, target_cost};
pub(crate) use task::{is_one_width, one_width};

use std::ops::ControlFlow;

use crate::error::{MsgpError, Result};
use crate::fit::{FitProgress, TrainingEpisode};
use crate::model::Model;
use crate::numeric::seed::derive;
use crate::plant::Plant;
use crate::policy::Policy;

/// What the loop reports while it runs ([`Learner::run`]).
#[derive(Clone, Copy, Debug)]
pub enum LearnEvent<'a> {
    /// An episode on the plant ended (random, policy or evaluation episode).
    Episode {
        /// The episode.
        episode: &'a Episode,
        /// It is an evaluation episode (neither interaction nor training data).
        evaluation: bool,
    },
    /// The model fit of policy iteration `iteration` (from 1) starts.
    FitStarted {
        /// The policy iteration.
        iteration: usize,
    },
    /// The model fit finished a solver iteration (MSGP fits only).
    Fit {
        /// The policy iteration.
        iteration: usize,
        /// The fit's own progress.
        progress: &'a FitProgress,
    },
    /// The policy search of an iteration starts.
    SearchStarted {
        /// The policy iteration.
        iteration: usize,
    },
    /// A policy iteration completed.
    Iteration(&'a IterationReport),
}

/// The task's success test of a policy (the pendulum's stability test, a mean return over
/// seeded starts), run after every iteration; neither interaction nor training data.
pub trait SuccessTest {
    /// Whether `policy` passes.
    fn passed(&mut self, policy: &Policy) -> Result<bool>;
}

/// The tag of evaluation episode `episode` of `iteration` ([`derive()`]).
pub fn evaluation_stream(iteration: usize, episode: usize) -> u64 {
    let it = u64::try_from(iteration).unwrap_or(u64::MAX) & 0xFFFF_FFFF;
    (2 << 48) + (it << 16) + (episode as u64 & 0xFFFF)
}

/// The seed of random episode `k` of a loop seeded `seed`.
pub fn random_episode_seed(seed: u64, k: usize) -> u64 {
    seed.wrapping_mul(1000).wrapping_add(k as u64)
}

/// The seed of the episode of policy iteration `it`.
pub fn policy_episode_seed(seed: u64, it: usize) -> u64 {
    seed.wrapping_mul(1000).wrapping_add(500 + it as u64)
}

/// The loop's state (see the module docs).
#[derive(Clone, Debug)]
pub struct Learner {
    task: Task,
    settings: LearnerSettings,
    episodes: Vec<Episode>,
    training: Vec<TrainingEpisode>,
    reports: Vec<IterationReport>,
    policy: Policy,
    previous: Option<Model>,
    choice: Option<ModelChoice>,
    seconds: f64,
}

impl Learner {
    /// A loop of `task` under `settings` (both checked when it runs on a plant).
    pub fn new(task: Task, settings: LearnerSettings) -> Result<Self> {
        settings.validate()?;
        let choice = match settings.prequential_choice {
            true => Some(ModelChoice::new(&settings)?),
            false => None,
        };
        Ok(Self {
            policy: task.space.base.clone(),
            task,
            settings,
            episodes: Vec::new(),
            training: Vec::new(),
            reports: Vec::new(),
            previous: None,
            choice,
            seconds: 0.0,
        })
    }

    /// The learner after episodes run elsewhere (logged on a real machine): the random ones
    /// first, then one per iteration under the policy that ran it. Each iteration's model fits
    /// are replayed (not its search: the policies are given), so the warm-started models and
    /// the prequential choice's scores are the ones the loop would have had; [`Learner::improve`]
    /// then gives the policy the loop would run next, to the bit.
    pub fn from_episodes(
        task: Task,
        settings: LearnerSettings,
        episodes: Vec<Episode>,
        observe: &mut dyn FnMut(LearnEvent<'_>) -> ControlFlow<()>,
    ) -> Result<Self> {
        let mut l = Self::new(task, settings)?;
        let r = l.settings.random_rollouts;
        let misplaced = episodes
            .iter()
            .enumerate()
            .find(|(k, e)| (*k < r) == e.policy.is_some());
        if episodes.len() < r || misplaced.is_some() {
            return Err(MsgpError::Data(format!(
                "the loop's episodes are its {r} random ones, then one per iteration under its                  policy; got {} episodes, {} with a policy (episode {} out of place)",
                episodes.len(),
                episodes.iter().filter(|e| e.policy.is_some()).count(),
                misplaced.map_or(0, |(k, _)| k)
            )));
        }
        for (k, ep) in episodes.into_iter().enumerate() {
            if let Some(policy) = &ep.policy {
                l.replay(k + 1 - r, &ep, observe)?;
                l.policy = policy.clone();
            }
            l.training.extend(training_entries(&ep, &l.settings)?);
            l.episodes.push(ep);
        }
        Ok(l)
    }

    /// Iteration `it`'s model fits on the episodes so far, and their scores on `ep`, the
    /// episode its policy ran.
    fn replay(
        &mut self,
        it: usize,
        ep: &Episode,
        observe: &mut dyn FnMut(LearnEvent<'_>) -> ControlFlow<()>,
    ) -> Result<()> {
        let (model, _) = improve::fit(
            &self.settings,
            &self.training,
            self.previous.as_ref(),
            it,
            observe,
        )?;
        let method = self.settings.method();
        let (linear, one_step) = match self.choice.as_mut() {
            Some(c) => (
                Some(c.fit(&self.training, it)?),
                match model.method == method {
                    true => c.fit_one_step(&self.training, it)?,
                    false => None,
                },
            ),
            None => (None, None),
        };
        if let (Some(c), Some(l)) = (self.choice.as_mut(), &linear)
            && model.method == method
        {
            let entries = training_entries(ep, &self.settings)?;
            c.score(&model, l, one_step.as_ref(), &entries)?;
        }
        if self.settings.warm_start.is_some() {
            self.previous = (model.method == method).then_some(model);
        }
        Ok(())
    }

    /// The next iteration's fit and search on the episodes so far, from the running policy:
    /// the step `msgp policy improve` takes between two episodes on a real machine.
    pub fn improve(
        &mut self,
        observe: &mut dyn FnMut(LearnEvent<'_>) -> ControlFlow<()>,
    ) -> Result<FitAndSearch> {
        let it = self.policy_episodes() + 1;
        fit_and_search(
            &self.task,
            &self.settings,
            (&self.episodes, &self.training),
            self.previous.as_ref(),
            &self.policy,
            it,
            self.choice.as_mut(),
            observe,
        )
    }

    /// Episodes run by a policy so far.
    fn policy_episodes(&self) -> usize {
        self.episodes.iter().filter(|e| e.policy.is_some()).count()
    }

    /// Every interaction episode so far, random ones first.
    pub fn episodes(&self) -> &[Episode] {
        &self.episodes
    }

    /// The iterations completed so far.
    pub fn reports(&self) -> &[IterationReport] {
        &self.reports
    }

    /// The policy that runs next (the last searched).
    pub fn policy(&self) -> &Policy {
        &self.policy
    }

    /// The task.
    pub fn task(&self) -> &Task {
        &self.task
    }

    /// The settings.
    pub fn settings(&self) -> &LearnerSettings {
        &self.settings
    }

    /// Runs the loop on `plant` to its last iteration: the random episodes not yet run, then
    /// the policy iterations not yet done. `success` judges each iteration's policy; `observe`
    /// sees the loop's progress and can stop it ([`ControlFlow::Break`]: the loop ends with
    /// [`MsgpError::Stopped`] at the next event, an MSGP fit at its next solver iteration).
    /// On any error the episodes run so far stay in the learner.
    pub fn run(
        &mut self,
        plant: &mut dyn Plant,
        mut success: Option<&mut dyn SuccessTest>,
        observe: &mut dyn FnMut(LearnEvent<'_>) -> ControlFlow<()>,
    ) -> Result<()> {
        self.task.validate(plant.spec())?;
        if self.scored().1 == 0 {
            return Err(MsgpError::InvalidSetting {
                name: "episode_steps",
                reason: "an episode needs at least one control step after the model's window"
                    .into(),
            });
        }
        let spec = plant.spec().clone();
        let bounds = spec.bounds()?;
        let steps = self.task.episode_steps;
        while self.episodes.len() < self.settings.random_rollouts {
            let k = self.episodes.len();
            let seed = random_episode_seed(self.settings.seed, k);
            let signal = Multisine::for_bounds(seed, &self.settings.excitation, &bounds);
            let ep = run_episode(plant, &Actor::Excitation(&signal), seed, steps)?;
            if self.record(ep, spec.period, observe)?.is_break() {
                return Err(MsgpError::Stopped { iteration: 0 });
            }
        }
        while self.policy_episodes() < self.settings.iterations {
            let it = self.policy_episodes() + 1;
            let test = success.as_mut().map(|s| &mut **s as &mut dyn SuccessTest);
            self.iterate(plant, it, test, observe)?;
        }
        Ok(())
    }

    /// Keeps an interaction episode and its training entries; the observer's answer to it.
    fn record(
        &mut self,
        ep: Episode,
        period: f64,
        observe: &mut dyn FnMut(LearnEvent<'_>) -> ControlFlow<()>,
    ) -> Result<ControlFlow<()>> {
        self.seconds += ep.len().saturating_sub(1) as f64 * period;
        let entries = training_entries(&ep, &self.settings)?;
        let flow = observe(LearnEvent::Episode {
            episode: &ep,
            evaluation: false,
        });
        self.training.extend(entries);
        self.episodes.push(ep);
        Ok(flow)
    }

    /// The scored rows of an episode: those after the model's window.
    fn scored(&self) -> (usize, usize) {
        let window = self.settings.fit.ly.max(self.settings.fit.lu);
        (window, (self.task.episode_steps + 1).saturating_sub(window))
    }

    /// One policy iteration: fit, search, run, score, judge. Atomic for the loop's state: a
    /// failure before its episode has run leaves the state as it was (the episode, when the
    /// plant failed during it, is lost with it); once the episode has run, it, the new policy
    /// and the iteration's report are kept together (a failing success test or evaluation
    /// leaves the report without those figures and is then raised), so a resumed loop runs
    /// the iterations an uninterrupted one would.
    fn iterate(
        &mut self,
        plant: &mut dyn Plant,
        it: usize,
        success: Option<&mut dyn SuccessTest>,
        observe: &mut dyn FnMut(LearnEvent<'_>) -> ControlFlow<()>,
    ) -> Result<()> {
        let (window, scored) = self.scored();
        let saved = (self.previous.clone(), self.choice.clone());
        let ran = self.fit_search_run(plant, it, observe);
        let (step, next, ep) = match ran {
            Ok(ran) => ran,
            Err(e) => {
                (self.previous, self.choice) = saved;
                return Err(e);
            }
        };
        let (predicted, var, search_failure) = match &step.searched {
            Ok(result) => {
                let steps = &result.steps[..scored.min(result.steps.len())];
                let predicted: f64 = steps.iter().map(|(m, _)| m).sum();
                let var: f64 = steps.iter().map(|(_, v)| v).sum();
                (predicted, var, None)
            }
            // the model's rollouts diverge for every start: it predicts failure whatever the
            // policy (every step costs 1); the policy stays and the episode adds data
            Err(e) => (scored as f64, 0.0, Some(e.to_string())),
        };
        let actual = ep.cost(&self.task.cost, window, scored);
        let entries = training_entries(&ep, &self.settings)?;
        // both models of this iteration predict the episode neither was trained on (a
        // one-step fallback model is not the loop's model and is not scored)
        let held_out = match (self.choice.as_mut(), &step.linear) {
            (Some(c), Some(l)) if step.model.method == self.settings.method() => {
                Some(c.score(&step.model, l, step.one_step.as_ref(), &entries)?)
            }
            _ => None,
        };
        if self.settings.warm_start.is_some() {
            // a one-step fallback model is not continued: the next fit starts over
            self.previous =
                (step.model.method == self.settings.method()).then(|| step.model.clone());
        }
        self.policy = next;
        let mut stop = self.record(ep, plant.spec().period, observe)?.is_break();
        let mut failure = None;
        let success = match success.map(|t| t.passed(&self.policy)) {
            Some(Ok(passed)) => Some(passed),
            Some(Err(e)) => {
                failure = Some(e);
                None
            }
            None => None,
        };
        let expected = match failure {
            Some(_) => None,
            None => match self.expected_cost(plant, it, observe) {
                Ok((expected, broke)) => {
                    stop |= broke;
                    expected
                }
                Err(e) => {
                    failure = Some(e);
                    None
                }
            },
        };
        let report = IterationReport {
            iteration: it,
            predicted_cost: predicted,
            predicted_cost_std: var.sqrt(),
            actual_cost: actual,
            expected_cost: expected,
            search_model: step.search_model,
            linear_fit_failure: step.linear_fit_failure.clone(),
            linear_search_failure: step.linear_search_failure.clone(),
            held_out,
            interaction_seconds: self.seconds,
            success,
            fit_seconds: step.fit_seconds,
            search_seconds: step.search_seconds,
            fit_numerical_stop: step.fit_report.numerical_stop,
            search_failure,
            policy: Some(self.policy.clone()),
        };
        stop |= observe(LearnEvent::Iteration(&report)).is_break();
        self.reports.push(report);
        match (failure, stop) {
            (Some(e), _) => Err(e),
            (None, true) => Err(MsgpError::Stopped { iteration: it }),
            (None, false) => Ok(()),
        }
    }

    /// Iteration `it`'s fit and search, and the episode of the policy it found (the running
    /// policy when every search start failed).
    fn fit_search_run(
        &mut self,
        plant: &mut dyn Plant,
        it: usize,
        observe: &mut dyn FnMut(LearnEvent<'_>) -> ControlFlow<()>,
    ) -> Result<(FitAndSearch, Policy, Episode)> {
        let step = self.improve(observe)?;
        let next = match &step.searched {
            Ok(result) => result.policy.clone(),
            Err(_) => self.policy.clone(),
        };
        let actor = Actor::Policy {
            policy: &next,
            rest: &self.task.rest_command,
        };
        let seed = policy_episode_seed(self.settings.seed, it);
        let ep = run_episode(plant, &actor, seed, self.task.episode_steps)?;
        Ok((step, next, ep))
    }

    /// The mean measured cost of the evaluation episodes of the running policy after `it`.
    fn expected_cost(
        &self,
        plant: &mut dyn Plant,
        it: usize,
        observe: &mut dyn FnMut(LearnEvent<'_>) -> ControlFlow<()>,
    ) -> Result<(Option<f64>, bool)> {
        let n = self.settings.evaluation_episodes;
        if n == 0 {
            return Ok((None, false));
        }
        let (window, scored) = self.scored();
        let rest = &self.task.rest_command;
        let actor = Actor::Policy {
            policy: &self.policy,
            rest,
        };
        let mut total = 0.0;
        let mut broke = false;
        for k in 0..n {
            let seed = derive(self.settings.seed, evaluation_stream(it, k));
            let ep = run_episode(plant, &actor, seed, self.task.episode_steps)?;
            total += ep.cost(&self.task.cost, window, scored);
            broke |= observe(LearnEvent::Episode {
                episode: &ep,
                evaluation: true,
            })
            .is_break();
        }
        Ok((Some(total / n as f64), broke))
    }
}
