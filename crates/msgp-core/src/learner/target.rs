//! A task stated by its target: "bring the outputs to `target`, each on the scale of its
//! width", with a policy family to search — how a user poses a task on their own plant
//! (`msgp.learn_policy(env=..., target=..., widths=...)`). The first policy is drawn from the
//! plant's signals (seeded); the rollouts start where the episodes so far started.

use nalgebra::{DMatrix, DVector};
use rand::{RngExt, SeedableRng};
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use super::task::{StartDistribution, Task, stated_cost};
use crate::error::{MsgpError, Result};
use crate::numeric::seed::derive;
use crate::plant::PlantSpec;
use crate::policy::{Policy, RbfPolicy, StateFeedback};
use crate::policy_search::SearchSpace;

/// The stream tag of the first policy's draw ([`derive()`]).
const POLICY_STREAM: u64 = 5;

/// Which policy the search moves.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum PolicyFamily {
    /// PILCO's RBF network of `basis` Gaussian basis functions on the observation.
    Rbf {
        /// Number of basis functions.
        basis: usize,
    },
    /// A linear feedback with offset on the observation.
    Linear,
}

/// A task stated by its target (see the module docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TargetTask {
    /// The target per output.
    pub target: Vec<f64>,
    /// The cost's width per output; `None`: the output does not count.
    pub widths: Vec<Option<f64>>,
    /// PILCO's several widths: the cost is the mean of the saturating costs at the widths
    /// times each scale (`[1.0]`, the default: the widths alone;
    /// [`crate::policy_search::cost`]).
    #[serde(
        default = "super::one_width",
        skip_serializing_if = "super::is_one_width"
    )]
    pub width_scales: Vec<f64>,
    /// Control steps of an episode.
    pub episode_steps: usize,
    /// Control steps of the predicted rollouts the policy is optimised on.
    pub policy_horizon: usize,
    /// The searched policy.
    pub policy: PolicyFamily,
    /// Where the predicted rollouts start: `None`, one Gaussian over the episodes' first
    /// observations; `Some(k)`, each of the latest `k` episodes' first observation, a start
    /// of its own ([`StartDistribution::EachObserved`]: for episodes that start anywhere).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub separate_starts: Option<usize>,
}

/// The middle and half width of output `j`'s range, `(0, 1)` when unbounded.
fn output_scale(spec: &PlantSpec, j: usize) -> (f64, f64) {
    spec.outputs[j].range().unwrap_or((0.0, 1.0))
}

impl TargetTask {
    /// The task on `spec`, its first policy drawn from `seed`.
    pub fn task(&self, spec: &PlantSpec, seed: u64) -> Result<Task> {
        spec.validate()?;
        let dy = spec.output_dim();
        if self.widths.len() != dy || self.target.len() != dy {
            return Err(MsgpError::InvalidSetting {
                name: "target",
                reason: format!(
                    "the plant has {dy} outputs; got {} targets and {} widths",
                    self.target.len(),
                    self.widths.len()
                ),
            });
        }
        let (policy, typical) = self.first_policy(spec, seed)?;
        let free = vec![true; policy.param_len()];
        Ok(Task {
            cost: stated_cost(
                &self.target,
                &self.widths,
                &spec.angles(),
                &self.width_scales,
            )?,
            episode_steps: self.episode_steps,
            policy_horizon: self.policy_horizon,
            start: match self.separate_starts {
                None => StartDistribution::Observed { floor: 1e-6 },
                Some(most) => StartDistribution::EachObserved { floor: 1e-6, most },
            },
            rest_command: spec.bounds()?.mid(),
            space: SearchSpace { base: policy, free },
            typical,
        })
    }

    /// The first policy and each parameter's typical magnitude.
    fn first_policy(&self, spec: &PlantSpec, seed: u64) -> Result<(Policy, Vec<f64>)> {
        let bounds = spec.bounds()?;
        let (dy, du) = (spec.output_dim(), spec.command_dim());
        let half = bounds.half_range();
        let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(derive(seed, POLICY_STREAM));
        match self.policy {
            PolicyFamily::Linear => {
                let policy = StateFeedback::new(
                    DMatrix::zeros(du, dy),
                    DVector::zeros(du),
                    dy,
                    (1, 0),
                    bounds,
                )?;
                // the gain's entry (i, j) moves command i by its half range over output j's
                let typical = (0..dy)
                    .flat_map(|j| (0..du).map(move |i| (i, j)))
                    .map(|(i, j)| half[i] / output_scale(spec, j).1)
                    .chain(half.iter().copied())
                    .collect();
                Ok((Policy::StateFeedback(policy), typical))
            }
            PolicyFamily::Rbf { basis } => {
                if basis == 0 {
                    return Err(MsgpError::InvalidSetting {
                        name: "policy basis",
                        reason: "an RBF network needs at least one basis function".into(),
                    });
                }
                // centres uniform over the outputs' ranges, widths a quarter of each range,
                // small random weights (PILCO's start)
                let centres = DMatrix::from_fn(basis, dy, |_, j| {
                    let (mid, h) = output_scale(spec, j);
                    mid + h * rng.random_range(-1.0..1.0)
                });
                let weights = DMatrix::from_fn(basis, du, |_, i| {
                    let n: f64 = StandardNormal.sample(&mut rng);
                    0.1 * half[i] * n
                });
                let log_widths = DVector::from_fn(dy, |j, _| (0.5 * output_scale(spec, j).1).ln());
                let policy = RbfPolicy::new(centres, weights, log_widths, bounds)?;
                let typical = (0..dy)
                    .flat_map(|j| std::iter::repeat_n(output_scale(spec, j).1, basis))
                    .chain((0..du).flat_map(|i| std::iter::repeat_n(half[i], basis)))
                    .chain(std::iter::repeat_n(1.0, dy))
                    .collect();
                Ok((Policy::Rbf(policy), typical))
            }
        }
    }
}
