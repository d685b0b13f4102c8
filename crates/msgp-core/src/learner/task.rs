//! A task: what the loop asks of a plant — the cost on its outputs, how long an episode runs
//! and how far ahead the policy is judged, where rollouts start, and which policy is searched
//! from where.

use nalgebra::DVector;

use crate::error::{MsgpError, Result};
use crate::plant::PlantSpec;
use crate::policy::Policy;
use crate::policy_search::cost::SaturatingCost;
use crate::policy_search::{PolicyProblem, SearchSpace};

use super::episode::Episode;

/// Where the predicted rollouts of the policy search start.
#[derive(Clone, Debug, PartialEq)]
pub enum StartDistribution {
    /// At rest at a known Gaussian: mean and variance per output (original units).
    Fixed {
        /// Mean per output.
        mean: Vec<f64>,
        /// Variance per output.
        var: Vec<f64>,
    },
    /// At the mean and variance of the first observations of the episodes run so far; each
    /// variance at least `floor` (PILCO's start distribution, estimated).
    Observed {
        /// Smallest variance per output.
        floor: f64,
    },
}

/// A task (see the module docs).
#[derive(Clone, Debug)]
pub struct Task {
    /// The cost on the outputs (original units).
    pub cost: SaturatingCost,
    /// Control steps of an episode on the plant.
    pub episode_steps: usize,
    /// Control steps of the predicted rollouts the policy is optimised on.
    pub policy_horizon: usize,
    /// Where they start.
    pub start: StartDistribution,
    /// The command at rest (before the first step; what a window policy's earlier commands
    /// hold).
    pub rest_command: Vec<f64>,
    /// The first policy and which of its parameters the search moves.
    pub space: SearchSpace,
    /// Typical magnitude of each free parameter: the optimiser's coordinate scales.
    pub typical: Vec<f64>,
}

fn invalid(name: &'static str, reason: String) -> MsgpError {
    MsgpError::InvalidSetting { name, reason }
}

impl Task {
    /// Checks the task against the plant it runs on.
    pub fn validate(&self, spec: &PlantSpec) -> Result<()> {
        spec.validate()?;
        let (dy, du) = (spec.output_dim(), spec.command_dim());
        if self.cost.target.len() != dy {
            return Err(invalid(
                "cost target",
                format!(
                    "has {} values, the plant {dy} outputs",
                    self.cost.target.len()
                ),
            ));
        }
        if self.episode_steps == 0 || self.policy_horizon == 0 {
            return Err(invalid(
                "task horizons",
                "an episode and the policy horizon need at least one control step each".into(),
            ));
        }
        if let StartDistribution::Fixed { mean, var } = &self.start
            && (mean.len() != dy
                || var.len() != dy
                || mean.iter().any(|m| !m.is_finite())
                || var.iter().any(|v| !(v.is_finite() && *v >= 0.0)))
        {
            return Err(invalid(
                "start distribution",
                format!("needs {dy} finite means and variances ≥ 0"),
            ));
        }
        if let StartDistribution::Observed { floor } = self.start
            && !(floor.is_finite() && floor > 0.0)
        {
            return Err(invalid(
                "start distribution",
                format!("the variance floor must be positive, got {floor}"),
            ));
        }
        if self.rest_command.len() != du {
            return Err(invalid(
                "rest command",
                format!(
                    "has {} values, the plant {du} commands",
                    self.rest_command.len()
                ),
            ));
        }
        self.space.validate()?;
        let policy = &self.space.base;
        if policy.command_dim() != du {
            return Err(invalid(
                "policy",
                format!(
                    "gives {} commands, the plant takes {du}",
                    policy.command_dim()
                ),
            ));
        }
        if policy.observation_dim() != dy {
            return Err(invalid(
                "policy",
                format!(
                    "acts on {} outputs, the plant has {dy}",
                    policy.observation_dim()
                ),
            ));
        }
        let (pb, sb) = (policy.bounds(), spec.bounds()?);
        for j in 0..du {
            if pb.low()[j] < sb.low()[j] || pb.high()[j] > sb.high()[j] {
                return Err(invalid(
                    "policy",
                    format!(
                        "command {j}: its bounds [{}, {}] exceed the plant's [{}, {}]",
                        pb.low()[j],
                        pb.high()[j],
                        sb.low()[j],
                        sb.high()[j]
                    ),
                ));
            }
        }
        if self.typical.len() != self.space.len()
            || self.typical.iter().any(|t| !(t.is_finite() && *t > 0.0))
        {
            return Err(invalid(
                "typical parameter magnitudes",
                format!("need {} positive values", self.space.len()),
            ));
        }
        Ok(())
    }

    /// The policy problem on `model`, starting as [`Task::start`] says (estimated from
    /// `episodes` for [`StartDistribution::Observed`]).
    pub fn problem<'a>(
        &self,
        model: &'a crate::model::Model,
        episodes: &[Episode],
    ) -> PolicyProblem<'a> {
        let (y0_mean, y0_var) = match &self.start {
            StartDistribution::Fixed { mean, var } => (mean.clone(), var.clone()),
            StartDistribution::Observed { floor } => observed_start(episodes, *floor),
        };
        PolicyProblem {
            model,
            y0_mean,
            y0_var,
            u0: self.rest_command.clone(),
            cost: self.cost.clone(),
            horizon: self.policy_horizon,
        }
    }

    /// Checks that `model` predicts this task's outputs from its commands.
    pub fn check_model(&self, model: &crate::model::Model) -> Result<()> {
        let (dy, du) = (model.spec.dy, model.spec.du);
        if dy != self.cost.target.len() || du != self.rest_command.len() {
            return Err(invalid(
                "model",
                format!(
                    "predicts {dy} outputs from {du} inputs; the task has {} outputs and {} \
                     commands",
                    self.cost.target.len(),
                    self.rest_command.len()
                ),
            ));
        }
        Ok(())
    }

    /// The search space from `policy` (the task's free parameters).
    pub fn space_at(&self, policy: &Policy) -> SearchSpace {
        SearchSpace {
            base: policy.clone(),
            free: self.space.free.clone(),
        }
    }
}

/// Mean and variance (at least `floor`) of the episodes' first observations.
fn observed_start(episodes: &[Episode], floor: f64) -> (Vec<f64>, Vec<f64>) {
    let firsts: Vec<&Vec<f64>> = episodes.iter().filter_map(|e| e.outputs.first()).collect();
    let dy = firsts.first().map_or(0, |y| y.len());
    let n = firsts.len().max(1) as f64;
    let mean: Vec<f64> = (0..dy)
        .map(|j| firsts.iter().map(|y| y[j]).sum::<f64>() / n)
        .collect();
    let var = (0..dy)
        .map(|j| {
            let v = firsts.iter().map(|y| (y[j] - mean[j]).powi(2)).sum::<f64>() / n;
            v.max(floor)
        })
        .collect();
    (mean, var)
}

/// A saturating cost around `target` with `widths` (∞: the output does not count).
pub fn target_cost(target: &[f64], widths: &[f64]) -> Result<SaturatingCost> {
    SaturatingCost::with_widths(DVector::from_column_slice(target), widths)
}
