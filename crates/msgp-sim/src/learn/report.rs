//! What the loop reports: one record per iteration and the whole outcome.

use serde::{Deserialize, Serialize};

use msgp_core::learner::{self, HeldOut, SearchModel};

use super::problem::gains_from;
use crate::controller::PidPdGains;
use crate::episode::Episode;
use crate::error::SimError;

/// One iteration of the loop.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct IterationReport {
    /// 1-based iteration.
    pub iteration: usize,
    /// Expected total cost on the model, from rest, over the episode's length (the policy is
    /// optimised over the longer `policy_horizon_seconds`).
    pub predicted_cost: f64,
    /// Its standard deviation (per-step variances summed; correlations over time ignored).
    pub predicted_cost_std: f64,
    /// Cost of the episode actually run, on the measured outputs.
    pub actual_cost: f64,
    /// The gains' expected cost on the system: the mean measured cost of
    /// [`LearnSettings::evaluation_episodes`](super::LearnSettings::evaluation_episodes)
    /// evaluation episodes from the same initial distribution, what `predicted_cost` predicts
    /// (one episode's cost is a single draw, dominated by its random initial angle). `None`
    /// without evaluation episodes (and in runs made before it was measured).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub expected_cost: Option<f64>,
    /// Under the prequential choice ([`msgp_core::learner::choice`]), the model this iteration's search
    /// ran on.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub search_model: Option<SearchModel>,
    /// Under the prequential choice, both models' scores on the episode this iteration ran
    /// (data neither was trained on).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub held_out: Option<HeldOut>,
    /// Interaction time so far, random rollouts included \[s\].
    pub interaction_seconds: f64,
    /// Whether the gains passed the simulator's stability test.
    pub stable: bool,
    /// Wall-clock seconds of the model fit.
    #[serde(default)]
    pub fit_seconds: f64,
    /// Wall-clock seconds of the policy optimisation.
    #[serde(default)]
    pub search_seconds: f64,
    /// Why the model fit stopped early, when a training step failed numerically (the fit then
    /// keeps the parameters of lowest loss among those that evaluated).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fit_numerical_stop: Option<String>,
    /// Set when every policy-search start diverged on the model: the previous gains ran again
    /// and the predicted cost is the episode's maximum (every step 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub search_failure: Option<String>,
    /// The gains run in this iteration.
    pub gains: PidPdGains,
}

impl IterationReport {
    /// The loop's report with the pendulum's names: the success test is the stability test,
    /// the policy its PID + PD gains.
    pub fn from_loop(r: &learner::IterationReport) -> Result<Self, SimError> {
        let Some(policy) = &r.policy else {
            return Err(SimError::invalid(
                "iteration report",
                r.iteration as f64,
                "carries no policy",
            ));
        };
        Ok(Self {
            iteration: r.iteration,
            predicted_cost: r.predicted_cost,
            predicted_cost_std: r.predicted_cost_std,
            actual_cost: r.actual_cost,
            expected_cost: r.expected_cost,
            search_model: r.search_model,
            held_out: r.held_out,
            interaction_seconds: r.interaction_seconds,
            stable: r.success.unwrap_or(false),
            fit_seconds: r.fit_seconds,
            search_seconds: r.search_seconds,
            fit_numerical_stop: r.fit_numerical_stop.clone(),
            search_failure: r.search_failure.clone(),
            gains: gains_from(policy)?,
        })
    }
}

/// Everything the loop produced.
#[derive(Clone, Debug)]
pub struct LearnOutcome {
    /// Per-iteration reports.
    pub iterations: Vec<IterationReport>,
    /// Every interaction episode, random ones first.
    pub episodes: Vec<Episode>,
    /// The last gains.
    pub final_gains: PidPdGains,
}

impl LearnOutcome {
    /// First iteration whose gains passed the stability test.
    pub fn first_stable_iteration(&self) -> Option<usize> {
        self.iterations
            .iter()
            .find(|r| r.stable)
            .map(|r| r.iteration)
    }

    /// The iteration whose gains to keep: the first that passed the stability test, else the
    /// one with the lowest measured episode cost (the earliest on ties; NaN costs never win).
    /// The loop itself ends on its last gains, which a later bad model may have spoiled.
    pub fn best_iteration(&self) -> Option<&IterationReport> {
        self.iterations.iter().find(|r| r.stable).or_else(|| {
            self.iterations
                .iter()
                .filter(|r| !r.actual_cost.is_nan())
                .fold(None, |best: Option<&IterationReport>, r| match best {
                    Some(b) if b.actual_cost <= r.actual_cost => Some(b),
                    _ => Some(r),
                })
        })
    }
}
