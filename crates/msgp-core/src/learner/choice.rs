//! The prequential choice between the GP model and the linear model of the same data.
//!
//! Every iteration fits, beside the filtered MSGP model (a linear prior mean under a GP), the
//! linear-Gaussian window model alone (linear-kf: the same window, the same filter likelihood,
//! no GP). The episode the iteration then runs is data neither model was trained on, so both
//! predict it honestly: each model's filter likelihood of it (the joint density of its
//! outputs given its inputs, [`crate::model::Model::filter_nll`], in original units) is
//! the model's score on that episode. Summed over the episodes so far this is Dawid's
//! *prequential* comparison: the GP model earns the policy search only while its predictions of
//! episodes it had not seen are, in total, better than the linear model's. Until then (and at the
//! first iteration, with nothing yet predicted) the search runs on the linear model: a GP must
//! pay for its freedom in predictions, because a model that explains noise by structure ranks
//! nearby gains wrongly (`docs/design.md`). The linear competitor is warm-started from its own
//! previous fit, as linear-kf's loop does; it adds 1.6–2.4 s to an iteration at the fifth
//! iteration's state, and its search is about 1 s cheaper than the GP model's (`BENCHMARKS.md`).
//!
//! With [`LearnerSettings::one_step_guard`] a third model enters: the MSGP fit's own one-step
//! start (GP-NARX on the same data, refitted every iteration). The trajectory training is then
//! kept for the search only where it predicted the latest episode better than that start did;
//! otherwise the search runs on the one-step model, and the report says so. Those two are
//! scored by what the search uses a model for: the episode's free run in closed loop under
//! the policy that ran it, from its first window ([`Model::rollout_nll`]), not its filter.
//! Only the latest episode counts, not the sum: a free run's log score has a heavy tail (one
//! overconfident early model loses an episode by 10⁵ nats), and the question is whether
//! *this* training helps the search, not whether an early one did (`docs/design.md`).

use std::ops::ControlFlow;

use serde::{Deserialize, Serialize};

use super::settings::LearnerSettings;
use crate::MsgpError;
use crate::error::Result;
use crate::fit::{
    FitSettings, LinearKfSettings, TrainingEpisode, fit_episodes, fit_episodes_observed,
};
use crate::model::{Method, Model};

/// Most L-BFGS iterations of the linear competitor's fit; from the second iteration on, it
/// continues the previous one for at most as many (the solver stops by itself when converged,
/// after 10–40 on the pendulum).
pub const LINEAR_FIT_ITERATIONS: usize = 300;

/// Which model a search ran on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum SearchModel {
    /// The loop's own model (the GP model).
    Gp,
    /// The linear competitor of the prequential choice.
    Linear,
    /// The MSGP fit's one-step start, under [`LearnerSettings::one_step_guard`].
    OneStep,
}

impl SearchModel {
    /// The name of the model a search ran on, in a loop whose own model is `method`.
    pub fn name(self, method: Method) -> &'static str {
        match self {
            SearchModel::Gp => method.name(),
            SearchModel::Linear => Method::LinearKf.name(),
            SearchModel::OneStep => Method::GpNarx.name(),
        }
    }
}

/// One held-out episode's scores: each model's filter likelihood of the episode it had not
/// seen (original units, summed over its scored steps).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct HeldOut {
    /// The GP model's negative log-likelihood of the episode.
    #[serde(with = "crate::numeric::infinite_as_null")]
    pub gp_nll: f64,
    /// The linear model's.
    #[serde(with = "crate::numeric::infinite_as_null")]
    pub linear_nll: f64,
    /// Scored steps.
    pub steps: usize,
    /// Under [`LearnerSettings::one_step_guard`], the GP model's and its one-step start's
    /// closed-loop free-run scores of the episode.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub rollout: Option<RolloutNll>,
}

/// Two models' free-run negative log-likelihoods of a held-out episode in closed loop under
/// the policy that ran it ([`Model::rollout_nll`], original units; infinite when the rollout
/// fails numerically).
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct RolloutNll {
    /// The GP (MSGP) model's.
    #[serde(with = "crate::numeric::infinite_as_null")]
    pub gp: f64,
    /// Its one-step start's.
    #[serde(with = "crate::numeric::infinite_as_null")]
    pub one_step: f64,
}

/// What a model that cannot predict a held-out episode (its filter fails numerically) loses
/// it by.
const LOST: f64 = 1e9;

/// How far `a` predicted a held-out episode worse than `b` (negative: better); a model that
/// cannot predict it loses by more than any finite score (an episode's NLL is a few hundred
/// nats), and both failing decides nothing.
fn difference(a: f64, b: f64) -> f64 {
    match (a.is_finite(), b.is_finite()) {
        (true, true) => a - b,
        (false, true) => LOST,
        (true, false) => -LOST,
        (false, false) => 0.0,
    }
}

/// A model's score of one held-out entry; infinite when it fails numerically on it (the
/// model predicts the episode impossible).
fn held_out(score: Result<(f64, usize)>) -> Result<(f64, usize)> {
    match score {
        Err(e) if e.is_numerical() => Ok((f64::INFINITY, 0)),
        other => other,
    }
}

/// A model's filter likelihood of held-out entries, and their scored steps.
fn filter_nll(model: &Model, entries: &[TrainingEpisode]) -> Result<(f64, usize)> {
    let (mut total, mut steps) = (0.0, 0);
    for e in entries {
        let (v, n) = held_out(model.filter_nll(&e.traj))?;
        total += v;
        steps += n;
    }
    Ok((total, steps))
}

/// A model's closed-loop free-run likelihood of held-out entries (each under its policy).
fn rollout_nll(model: &Model, entries: &[TrainingEpisode]) -> Result<f64> {
    let mut total = 0.0;
    for e in entries {
        total += held_out(model.rollout_nll(&e.traj, e.policy.as_ref()))?.0;
    }
    Ok(total)
}

/// The running prequential comparison and the linear competitor's state.
#[derive(Clone, Debug)]
pub struct ModelChoice {
    /// The linear model's fit settings (the linear-kf loop's, on the GP model's history).
    settings: FitSettings,
    /// Solver iterations of a continued linear fit.
    warm_start: Option<usize>,
    /// The linear model of the last iteration.
    previous: Option<Model>,
    /// `Σ (GP NLL − linear NLL)` over the held-out episodes so far: negative favours the GP.
    advantage: f64,
    /// Under the one-step guard, the one-step model's fit settings (the MSGP fit's start).
    one_step: Option<FitSettings>,
    /// `GP NLL − one-step NLL` of the free runs of the latest held-out episode, under the
    /// guard: negative keeps the GP model.
    one_step_last: Option<f64>,
    /// Held-out episodes scored so far.
    scored: usize,
}

impl ModelChoice {
    /// The choice for the loop of `settings` (an MSGP loop): the competitor is the linear-kf
    /// model on the same history, outputs, integrators and threads.
    pub fn new(settings: &LearnerSettings) -> Result<Self> {
        if settings.method() != Method::Msgp {
            return Err(MsgpError::InvalidSetting {
                name: "prequential_choice",
                reason: "the choice between a GP model and its linear part needs an MSGP loop"
                    .into(),
            });
        }
        let fit = FitSettings {
            seed: settings.seed,
            ly: settings.fit.ly,
            lu: settings.fit.lu,
            threads: settings.fit.threads,
            integrators: settings.fit.integrators.clone(),
            method: LinearKfSettings {
                iterations: LINEAR_FIT_ITERATIONS,
            }
            .into(),
        };
        // seeded by the loop, as the gp-narx loop's fits and the linear competitor's
        let one_step = match settings.one_step_guard {
            true => Some(FitSettings {
                seed: settings.seed,
                ..settings
                    .fit
                    .one_step_start()
                    .ok_or(MsgpError::InvalidSetting {
                        name: "one_step_guard",
                        reason: "the guard compares an MSGP fit with its one-step start".into(),
                    })?
            }),
            false => None,
        };
        Ok(Self {
            settings: fit,
            warm_start: Some(LINEAR_FIT_ITERATIONS),
            previous: None,
            advantage: 0.0,
            one_step,
            one_step_last: None,
            scored: 0,
        })
    }

    /// Fits the linear model of `training` for iteration `it` (seeded by the loop's seed and
    /// the iteration, as the GP model's fit), continuing the previous one when the linear-kf
    /// loop would. A linear model of strongly nonlinear data can fail numerically (its filter
    /// diverges): the error is returned, and the next fit starts over.
    pub fn fit(&mut self, training: &[TrainingEpisode], it: usize) -> Result<Model> {
        let seeded = FitSettings {
            seed: self.settings.seed.wrapping_add(it as u64),
            ..self.settings.clone()
        };
        let warm = self.warm_start.zip(self.previous.as_ref());
        let settings = match warm {
            Some((n, _)) => seeded.with_solver_iterations(n),
            None => seeded,
        };
        let fitted = fit_episodes_observed(training, &settings, warm.map(|(_, m)| m), &mut |_| {
            ControlFlow::Continue(())
        });
        // a failed fit is not continued: the next one starts over
        self.previous = fitted.as_ref().ok().map(|(m, _)| m.clone());
        fitted.map(|(m, _)| m)
    }

    /// Under the one-step guard, the one-step model of `training` for iteration `it`, seeded
    /// as the `gp-narx` loop's fit of that iteration (the same model on the same data);
    /// `None` without the guard, or when that fit fails numerically (no competitor this
    /// iteration).
    pub fn fit_one_step(&self, training: &[TrainingEpisode], it: usize) -> Result<Option<Model>> {
        let Some(settings) = &self.one_step else {
            return Ok(None);
        };
        let seeded = FitSettings {
            seed: settings.seed.wrapping_add(it as u64),
            ..settings.clone()
        };
        match fit_episodes(training, &seeded, &mut |_| {}) {
            Ok((model, _)) => Ok(Some(model)),
            Err(e) if e.is_numerical() => Ok(None),
            Err(e) => Err(e),
        }
    }

    /// The model the next search runs on: the GP model once its held-out predictions beat
    /// the linear model's in total, the linear model before; under the one-step guard, a GP
    /// model whose free run of the latest episode was no better than its one-step start's
    /// gives the search to that start (`one_step`: whether this iteration has one).
    pub fn search_model(&self, one_step: bool) -> SearchModel {
        if !(self.scored > 0 && self.advantage < 0.0) {
            SearchModel::Linear
        } else if one_step && self.one_step_last.is_some_and(|d| d >= 0.0) {
            SearchModel::OneStep
        } else {
            SearchModel::Gp
        }
    }

    /// Scores the models of an iteration (the one-step model under the guard) on the episode
    /// that iteration ran (`newest`: its training entries, which no model saw) and adds the
    /// differences to the comparison.
    pub fn score(
        &mut self,
        gp: &Model,
        linear: &Model,
        one_step: Option<&Model>,
        newest: &[TrainingEpisode],
    ) -> Result<HeldOut> {
        let (g, steps) = filter_nll(gp, newest)?;
        let (l, _) = filter_nll(linear, newest)?;
        self.advantage += difference(g, l);
        let rollout = match one_step {
            Some(o) => {
                let scores = RolloutNll {
                    gp: rollout_nll(gp, newest)?,
                    one_step: rollout_nll(o, newest)?,
                };
                self.one_step_last = Some(difference(scores.gp, scores.one_step));
                Some(scores)
            }
            None => None,
        };
        self.scored += 1;
        Ok(HeldOut {
            gp_nll: g,
            linear_nll: l,
            steps,
            rollout,
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::plant::{CommandSpec, OutputSpec, PlantSpec};

    fn guarded(guard: bool) -> ModelChoice {
        let spec = PlantSpec {
            period: 0.1,
            commands: vec![CommandSpec {
                name: "u".into(),
                low: -1.0,
                high: 1.0,
            }],
            outputs: vec![OutputSpec::named("y")],
        };
        let settings = LearnerSettings {
            one_step_guard: guard,
            ..LearnerSettings::for_plant(&spec)
        };
        ModelChoice::new(&settings).expect("an MSGP loop")
    }

    /// Linear until the GP model has beaten it; then, under the guard, the one-step start
    /// when the GP model did not beat it on the latest episode (a tie keeps the simpler
    /// model); without the guard, or in an iteration without a one-step model, the GP model.
    #[test]
    fn the_guard_hands_the_search_to_the_one_step_start_until_beaten() {
        let mut c = guarded(true);
        assert!(c.one_step.is_some());
        assert_eq!(c.search_model(true), SearchModel::Linear);
        (c.scored, c.advantage, c.one_step_last) = (1, 3.0, Some(-5.0));
        assert_eq!(c.search_model(true), SearchModel::Linear);
        c.advantage = -3.0;
        assert_eq!(c.search_model(true), SearchModel::Gp);
        for o in [0.0, 5.0] {
            c.one_step_last = Some(o);
            assert_eq!(c.search_model(true), SearchModel::OneStep);
            assert_eq!(c.search_model(false), SearchModel::Gp);
        }
        let mut plain = guarded(false);
        assert!(plain.one_step.is_none());
        (plain.scored, plain.advantage, plain.one_step_last) = (1, -3.0, Some(5.0));
        assert_eq!(plain.search_model(false), SearchModel::Gp);
        assert_eq!(difference(f64::INFINITY, -40.0), LOST);
        assert_eq!(difference(-40.0, f64::INFINITY), -LOST);
        assert_eq!(difference(f64::INFINITY, f64::INFINITY), 0.0);
        assert_eq!(SearchModel::OneStep.name(Method::Msgp), "gp-narx");
        assert_eq!(SearchModel::Gp.name(Method::Msgp), "msgp");
    }

    #[test]
    fn an_infinite_held_out_score_reads_back_as_written() {
        let h = HeldOut {
            gp_nll: -12.5,
            linear_nll: f64::INFINITY,
            steps: 40,
            rollout: None,
        };
        let text = serde_json::to_string(&h).expect("JSON");
        assert_eq!(text, r#"{"gp_nll":-12.5,"linear_nll":null,"steps":40}"#);
        let back: HeldOut = serde_json::from_str(&text).expect("reads back");
        assert_eq!(back, h);
    }
}
