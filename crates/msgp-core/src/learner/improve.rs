//! One iteration's model fit and policy search: the step from the episodes so far to the next
//! policy. The loop runs it between episodes on its plant; `msgp policy improve` runs it on
//! episodes logged on a real machine.

use std::ops::ControlFlow;

use super::LearnEvent;
use super::choice::{ModelChoice, SearchModel};
use super::episode::{Episode, segments};
use super::settings::LearnerSettings;
use super::task::Task;
use crate::error::{MsgpError, Result};
use crate::fit::{FitReport, FitSettings, TrainingEpisode, fit_episodes, fit_episodes_observed};
use crate::model::{Method, Model};
use crate::policy::{Policy, PolicySpec};
use crate::policy_search::{PolicySearchResult, PolicySearchSettings, optimise_over};

/// How an episode enters the model loss: an open-loop one feed-forward (in segments for a
/// free-run MSGP fit, [`LearnerSettings::ff_segment`]), a policy's whole under that policy.
pub fn training_entries(ep: &Episode, settings: &LearnerSettings) -> Result<Vec<TrainingEpisode>> {
    let traj = ep.trajectory()?;
    Ok(match &ep.policy {
        Some(policy) => vec![TrainingEpisode {
            traj,
            policy: Some(PolicySpec::Direct(policy.clone())),
        }],
        None => {
            let parts = match settings.segment_length() {
                Some(len) => segments(&traj, len, settings.fit.ly.max(settings.fit.lu) + 5)?,
                None => vec![traj],
            };
            parts
                .into_iter()
                .map(|traj| TrainingEpisode { traj, policy: None })
                .collect()
        }
    })
}

/// What one iteration's fit and search produced ([`fit_and_search`]).
#[derive(Debug)]
pub struct FitAndSearch {
    /// The fitted model (the one-step GP-NARX model when an MSGP fit failed at its start; its
    /// report says so).
    pub model: Model,
    /// The fit's report.
    pub fit_report: FitReport,
    /// Under the prequential choice, the linear competitor fitted on the same data.
    pub linear: Option<Model>,
    /// Under the one-step guard, the MSGP fit's one-step start fitted on the same data.
    pub one_step: Option<Model>,
    /// Under the prequential choice, the model the search ran on.
    pub search_model: Option<SearchModel>,
    /// Under the prequential choice, why the linear competitor's fit failed numerically (the
    /// search then ran on the GP model).
    pub linear_fit_failure: Option<String>,
    /// Under the prequential choice, why the search on the linear model failed numerically
    /// (the search then ran on the GP model).
    pub linear_search_failure: Option<String>,
    /// The search's best policy, or why every start failed numerically (the model's rollouts
    /// diverge whatever the policy: it predicts failure).
    pub searched: Result<PolicySearchResult>,
    /// Wall seconds of the fit (both fits under the prequential choice).
    pub fit_seconds: f64,
    /// Wall seconds of the search.
    pub search_seconds: f64,
}

impl FitAndSearch {
    /// The model the search ran on.
    pub fn searched_model(&self) -> &Model {
        match (self.search_model, &self.linear) {
            (Some(SearchModel::Linear), Some(l)) => l,
            _ => &self.model,
        }
    }
}

/// Iteration `it`'s fit of `settings` on `training` (seeded by the iteration; continuing
/// `previous` for [`LearnerSettings::warm_start`] solver iterations when given and the method
/// continues), then the search from `policy` on it within the trust region. `episodes` are the
/// episodes behind `training` (an observed start distribution is estimated from them).
/// `observe` sees the fit's start and progress and the search's start; a
/// [`ControlFlow::Break`] ends it with [`MsgpError::Stopped`].
#[allow(clippy::too_many_arguments)]
pub fn fit_and_search(
    task: &Task,
    settings: &LearnerSettings,
    (episodes, training): (&[Episode], &[TrainingEpisode]),
    previous: Option<&Model>,
    policy: &Policy,
    it: usize,
    choice: Option<&mut ModelChoice>,
    observe: &mut dyn FnMut(LearnEvent<'_>) -> ControlFlow<()>,
) -> Result<FitAndSearch> {
    let stopped = MsgpError::Stopped { iteration: it };
    if observe(LearnEvent::FitStarted { iteration: it }).is_break() {
        return Err(stopped);
    }
    let clock = std::time::Instant::now();
    let (model, fit_report) = fit(settings, training, previous, it, observe)?;
    // a linear competitor that cannot be fitted cannot be searched either: the GP model is
    // the only model of this iteration
    let mut linear_failure = None;
    let (linear, one_step, search_model) = match choice {
        Some(c) => {
            // a one-step fallback model needs no one-step competitor (it is one)
            let one_step = match model.method == settings.method() {
                true => c.fit_one_step(training, it)?,
                false => None,
            };
            match c.fit(training, it) {
                Ok(l) => {
                    let search_model = c.search_model(one_step.is_some());
                    (Some(l), one_step, Some(search_model))
                }
                Err(e) if e.is_numerical() => {
                    linear_failure = Some(e.to_string());
                    (None, one_step, Some(SearchModel::Gp))
                }
                Err(e) => return Err(e),
            }
        }
        None => (None, None, None),
    };
    let fit_seconds = clock.elapsed().as_secs_f64();
    if observe(LearnEvent::SearchStarted { iteration: it }).is_break() {
        return Err(stopped);
    }
    let mut step = FitAndSearch {
        model,
        fit_report,
        linear,
        one_step,
        search_model,
        linear_fit_failure: linear_failure,
        linear_search_failure: None,
        searched: Err(stopped),
        fit_seconds,
        search_seconds: 0.0,
    };
    let clock = std::time::Instant::now();
    let search = PolicySearchSettings {
        seed: settings
            .search
            .seed
            .wrapping_add(settings.seed)
            .wrapping_add(it as u64),
        ..settings.search
    };
    let fresh: Vec<Vec<f64>> = settings
        .search_from_first
        .then(|| task.space.start())
        .into_iter()
        .collect();
    let search_on = |model: &Model| {
        optimise_over(
            &task.problems(model, episodes),
            &task.space_at(policy),
            &task.typical,
            &search,
            &fresh,
        )
    };
    let mut searched = search_on(step.searched_model());
    // a linear model whose every rollout diverges predicts nothing a search can use: the
    // iteration searches on the GP model instead, and says so
    if step.search_model == Some(SearchModel::Linear)
        && let Err(e) = &searched
        && e.is_numerical()
    {
        step.linear_search_failure = Some(e.to_string());
        step.search_model = Some(SearchModel::Gp);
        searched = search_on(&step.model);
    }
    step.search_seconds = clock.elapsed().as_secs_f64();
    step.searched = match searched {
        Err(MsgpError::Stopped { .. }) => return Err(MsgpError::Stopped { iteration: it }),
        Err(e) if !e.is_numerical() => return Err(e),
        other => other,
    };
    Ok(step)
}

/// The model fit of iteration `it`, falling back to the one-step model when an MSGP fit fails
/// numerically at its start (its report says so).
pub(super) fn fit(
    settings: &LearnerSettings,
    training: &[TrainingEpisode],
    previous: Option<&Model>,
    it: usize,
    observe: &mut dyn FnMut(LearnEvent<'_>) -> ControlFlow<()>,
) -> Result<(Model, FitReport)> {
    let method = settings.method();
    let seeded = FitSettings {
        seed: settings.seed.wrapping_add(it as u64),
        ..settings.fit.clone()
    };
    let warm = match (previous, settings.warm_start) {
        (Some(prev), Some(n)) if matches!(method, Method::Msgp | Method::LinearKf) => {
            Some((prev, n))
        }
        _ => None,
    };
    let fitted = fit_episodes_observed(
        training,
        &match warm {
            Some((_, n)) => seeded.clone().with_solver_iterations(n),
            None => seeded.clone(),
        },
        warm.map(|(prev, _)| prev),
        &mut |p| {
            observe(LearnEvent::Fit {
                iteration: it,
                progress: p,
            })
        },
    );
    match fitted {
        Ok(fitted) => Ok(fitted),
        // the MSGP start (the one-step model rolled out over every episode) can already fail
        // numerically; the iteration then runs on that one-step model
        Err(e) if e.is_numerical() && method == Method::Msgp => {
            let Some(one_step) = seeded.one_step_start() else {
                return Err(e);
            };
            let (model, mut report) = fit_episodes(training, &one_step, &mut |_| {})?;
            report.numerical_stop = Some(format!(
                "the MSGP fit failed at its start ({e}); this iteration used the one-step \
                 GP-NARX model"
            ));
            Ok((model, report))
        }
        Err(MsgpError::Stopped { .. }) => Err(MsgpError::Stopped { iteration: it }),
        Err(e) => Err(e),
    }
}
