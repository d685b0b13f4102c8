//! What the loop reports: one record per iteration.

use serde::{Deserialize, Serialize};

use super::choice::{HeldOut, SearchModel};
use crate::policy::Policy;

/// One iteration of the loop.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct IterationReport {
    /// 1-based iteration.
    pub iteration: usize,
    /// Expected total cost on the model from the start distribution, over the episode's
    /// scored steps (the policy is optimised over the task's policy horizon; when that is
    /// shorter than the episode, over the horizon's steps only, and then not comparable with
    /// `actual_cost`).
    pub predicted_cost: f64,
    /// Its standard deviation (per-step variances summed; correlations over time ignored).
    pub predicted_cost_std: f64,
    /// Cost of the episode run, on the measured outputs.
    pub actual_cost: f64,
    /// The mean measured cost of the evaluation episodes
    /// ([`LearnerSettings::evaluation_episodes`](super::LearnerSettings::evaluation_episodes)),
    /// what `predicted_cost` predicts; `None` without them.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub expected_cost: Option<f64>,
    /// Under the prequential choice, the model this iteration's search ran on.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub search_model: Option<SearchModel>,
    /// Under the prequential choice, why the linear competitor could not be fitted (its
    /// filter failed numerically): the search ran on the GP model, and the episode is not
    /// scored.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub linear_fit_failure: Option<String>,
    /// Under the prequential choice, why the search on the linear model it chose failed
    /// numerically (every start's rollout diverged); the search then ran on the GP model.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub linear_search_failure: Option<String>,
    /// Under the prequential choice, both models' scores on the episode this iteration ran.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub held_out: Option<HeldOut>,
    /// Interaction time so far, random episodes included \[s\].
    pub interaction_seconds: f64,
    /// The task's success test of the policy, when the loop has one.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub success: Option<bool>,
    /// Wall-clock seconds of the model fit (both fits under the prequential choice).
    pub fit_seconds: f64,
    /// Wall-clock seconds of the policy search.
    pub search_seconds: f64,
    /// Why the model fit stopped early or fell back (the one-step model when the MSGP fit
    /// failed at its start).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub fit_numerical_stop: Option<String>,
    /// Set when every search start diverged on the model: the previous policy ran again and
    /// the predicted cost is the episode's maximum (every step 1).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub search_failure: Option<String>,
    /// The policy run in this iteration.
    #[serde(skip)]
    pub policy: Option<Policy>,
}
