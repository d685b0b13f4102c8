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
    /// At each of the first observations of the `most` latest episodes, each a Gaussian of
    /// variance `floor`: the policy is judged by its mean expected cost over these starts. For
    /// a plant whose episodes start anywhere in a region (Gymnasium's pendulum: any angle), one
    /// Gaussian over the starts is no state the plant is ever in, and a policy good from
    /// that Gaussian is good from none of them.
    EachObserved {
        /// Variance of each start.
        floor: f64,
        /// Most starts (the latest episodes'); the search's work grows with their number.
        most: usize,
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
        if let StartDistribution::Observed { floor } | StartDistribution::EachObserved { floor, .. } =
            self.start
            && !(floor.is_finite() && floor > 0.0)
        {
            return Err(invalid(
                "start distribution",
                format!("the variance floor must be positive, got {floor}"),
            ));
        }
        if let StartDistribution::EachObserved { most: 0, .. } = self.start {
            return Err(invalid(
                "start distribution",
                "needs at least one start (most ≥ 1)".into(),
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

    /// The policy problems on `model`, one per start ([`Task::start`]; estimated from
    /// `episodes` unless fixed): the search minimises their mean expected cost. Empty when the
    /// start is estimated and there are no episodes.
    pub fn problems<'a>(
        &self,
        model: &'a crate::model::Model,
        episodes: &[Episode],
    ) -> Vec<PolicyProblem<'a>> {
        let starts = self.starts(episodes);
        starts
            .into_iter()
            .map(|(y0_mean, y0_var)| PolicyProblem {
                model,
                y0_mean,
                y0_var,
                u0: self.rest_command.clone(),
                cost: self.cost.clone(),
                horizon: self.policy_horizon,
            })
            .collect()
    }

    /// The rollouts' starts (mean, variance per output) on `episodes`.
    fn starts(&self, episodes: &[Episode]) -> Vec<(Vec<f64>, Vec<f64>)> {
        match &self.start {
            StartDistribution::Fixed { mean, var } => vec![(mean.clone(), var.clone())],
            StartDistribution::Observed { floor } if !episodes.is_empty() => {
                vec![observed_start(episodes, *floor)]
            }
            StartDistribution::Observed { .. } => Vec::new(),
            StartDistribution::EachObserved { floor, most } => {
                let firsts: Vec<&Vec<f64>> =
                    episodes.iter().filter_map(|e| e.outputs.first()).collect();
                firsts[firsts.len().saturating_sub(*most)..]
                    .iter()
                    .map(|y| (y.to_vec(), vec![*floor; y.len()]))
                    .collect()
            }
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

/// The widths alone: the default of [`super::TargetTask::width_scales`].
pub(crate) fn one_width() -> Vec<f64> {
    vec![1.0]
}

/// Whether `scales` are the widths alone (left out of records).
pub(crate) fn is_one_width(scales: &[f64]) -> bool {
    scales == [1.0]
}

/// A task's cost as a task states it ([`super::TargetTask`], a policy file's task record):
/// `widths` per output (`None`: it does not count), `angles`, the widths' `scales`.
pub fn stated_cost(
    target: &[f64],
    widths: &[Option<f64>],
    angles: &[bool],
    scales: &[f64],
) -> Result<SaturatingCost> {
    let widths: Vec<f64> = widths.iter().map(|w| w.unwrap_or(f64::INFINITY)).collect();
    target_cost(target, &widths, angles)?.with_scales(scales)
}

/// A saturating cost around `target` with `widths` (∞: the output does not count), the
/// outputs flagged in `angles` costed on their unit tip.
pub fn target_cost(target: &[f64], widths: &[f64], angles: &[bool]) -> Result<SaturatingCost> {
    SaturatingCost::with_angles(DVector::from_column_slice(target), widths, angles)
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::policy::{CommandBounds, StateFeedback};
    use crate::policy_file::TaskRecord;
    use nalgebra::DMatrix;

    fn task(start: StartDistribution) -> Task {
        let bounds = CommandBounds::new(vec![-1.0], vec![1.0]).expect("bounds");
        let policy = StateFeedback::new(DMatrix::zeros(1, 2), DVector::zeros(1), 2, (1, 0), bounds)
            .expect("policy");
        let policy = Policy::StateFeedback(policy);
        let n = policy.param_len();
        Task {
            cost: target_cost(&[0.0, 0.0], &[1.0, f64::INFINITY], &[false; 2]).expect("cost"),
            episode_steps: 5,
            policy_horizon: 5,
            start,
            rest_command: vec![0.0],
            space: SearchSpace {
                base: policy,
                free: vec![true; n],
            },
            typical: vec![1.0; n],
        }
    }

    fn episode(y0: [f64; 2]) -> Episode {
        Episode {
            seed: 0,
            outputs: vec![y0.to_vec(), vec![0.0, 0.0]],
            commands: vec![vec![0.0], vec![0.0]],
            ended_early: false,
            truncated: false,
            policy: None,
        }
    }

    /// Each observed start is its own: the latest `most` episodes' first observations with
    /// the floor's variance; one Gaussian over them otherwise; `most = 0` is refused; the
    /// policy file keeps the choice.
    #[test]
    fn each_observed_start_is_a_start_of_its_own() {
        let episodes: Vec<Episode> = [[1.0, 2.0], [3.0, -2.0], [5.0, 0.0]]
            .into_iter()
            .map(episode)
            .collect();
        let each = task(StartDistribution::EachObserved {
            floor: 0.01,
            most: 2,
        });
        let starts = each.starts(&episodes);
        assert_eq!(
            starts,
            vec![
                (vec![3.0, -2.0], vec![0.01, 0.01]),
                (vec![5.0, 0.0], vec![0.01, 0.01])
            ]
        );
        assert!(each.starts(&[]).is_empty());
        let one = task(StartDistribution::Observed { floor: 0.01 }).starts(&episodes);
        assert_eq!(one.len(), 1);
        assert!((one[0].0[0] - 3.0).abs() < 1e-15 && (one[0].1[0] - 8.0 / 3.0).abs() < 1e-12);
        let spec = PlantSpec {
            period: 0.1,
            commands: vec![crate::plant::CommandSpec {
                name: "u".into(),
                low: -1.0,
                high: 1.0,
            }],
            outputs: vec![
                crate::plant::OutputSpec::named("a"),
                crate::plant::OutputSpec::named("b"),
            ],
        };
        assert!(each.validate(&spec).is_ok());
        let none = task(StartDistribution::EachObserved {
            floor: 0.01,
            most: 0,
        });
        assert!(none.validate(&spec).is_err());
        let back = TaskRecord::of(&each)
            .to_task(each.space.base.clone())
            .expect("task");
        assert_eq!(back.start, each.start);
        // several widths survive the record, and one is left out of it
        let several = Task {
            cost: each.cost.clone().with_scales(&[1.0, 3.0]).expect("scales"),
            ..each.clone()
        };
        let record = TaskRecord::of(&several);
        let text = serde_json::to_string(&record).expect("json");
        let read: TaskRecord = serde_json::from_str(&text).expect("reads");
        let back = read.to_task(several.space.base.clone()).expect("task");
        assert_eq!(back.cost, several.cost);
        let one = serde_json::to_string(&TaskRecord::of(&each)).expect("json");
        assert!(!one.contains("width_scales") && text.contains("\"width_scales\":[1.0,3.0]"));
    }
}
