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

use std::ops::ControlFlow;

use serde::{Deserialize, Serialize};

use super::settings::LearnerSettings;
use crate::MsgpError;
use crate::error::Result;
use crate::fit::{FitSettings, LinearKfSettings, TrainingEpisode, fit_episodes_observed};
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
}

/// What a model that cannot predict a held-out episode (its filter fails numerically) loses
/// it by.
const LOST: f64 = 1e9;

/// A model's filter likelihood of one held-out entry; infinite when its filter fails
/// numerically on it (the model predicts the episode impossible).
fn held_out_nll(model: &Model, e: &TrainingEpisode) -> Result<(f64, usize)> {
    match model.filter_nll(&e.traj) {
        Ok(v) => Ok(v),
        Err(MsgpError::NonFinite(_) | MsgpError::NotPositiveDefinite { .. }) => {
            Ok((f64::INFINITY, 0))
        }
        Err(e) => Err(e),
    }
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
        Ok(Self {
            settings: fit,
            warm_start: Some(LINEAR_FIT_ITERATIONS),
            previous: None,
            advantage: 0.0,
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

    /// The model the next search runs on: the GP model once its held-out predictions beat
    /// the linear model's in total, the linear model before.
    pub fn search_model(&self) -> SearchModel {
        if self.scored > 0 && self.advantage < 0.0 {
            SearchModel::Gp
        } else {
            SearchModel::Linear
        }
    }

    /// Scores both models of an iteration on the episode that iteration ran (`newest`: its
    /// training entries, which neither model saw) and adds the difference to the comparison.
    pub fn score(
        &mut self,
        gp: &Model,
        linear: &Model,
        newest: &[TrainingEpisode],
    ) -> Result<HeldOut> {
        let (mut g, mut l, mut steps) = (0.0, 0.0, 0);
        for e in newest {
            let (gn, n) = held_out_nll(gp, e)?;
            let (ln, _) = held_out_nll(linear, e)?;
            g += gn;
            l += ln;
            steps += n;
        }
        let held = HeldOut {
            gp_nll: g,
            linear_nll: l,
            steps,
        };
        // a model that cannot predict the episode loses it by more than any finite score
        // (an episode's NLL is a few hundred nats); both failing decides nothing
        let diff = match (g.is_finite(), l.is_finite()) {
            (true, true) => g - l,
            (false, true) => LOST,
            (true, false) => -LOST,
            (false, false) => 0.0,
        };
        self.advantage += diff;
        self.scored += 1;
        Ok(held)
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn an_infinite_held_out_score_reads_back_as_written() {
        let h = HeldOut {
            gp_nll: -12.5,
            linear_nll: f64::INFINITY,
            steps: 40,
        };
        let text = serde_json::to_string(&h).expect("JSON");
        assert_eq!(text, r#"{"gp_nll":-12.5,"linear_nll":null,"steps":40}"#);
        let back: HeldOut = serde_json::from_str(&text).expect("reads back");
        assert_eq!(back, h);
    }
}
