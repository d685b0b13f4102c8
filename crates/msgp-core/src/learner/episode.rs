//! Episodes on a plant: what acts (the random excitation or a policy), how a run is recorded,
//! and how it enters the model loss and is scored.
//!
//! Row `k` of an episode holds the observation at `t = k·T` and the command issued in response;
//! the command of the last row is never applied (also when the plant ended the episode there) (the NARX convention of
//! [`Trajectory`]). An episode runs `steps` control steps (`steps + 1` rows) unless the plant
//! ends it earlier.

use nalgebra::DMatrix;

use super::excitation::Multisine;
use crate::data::Trajectory;
use crate::error::{MsgpError, Result};
use crate::plant::Plant;
use crate::policy::{Policy, RestEntry};
use crate::policy_search::cost::SaturatingCost;

/// What chooses an episode's commands.
#[derive(Clone, Debug)]
pub enum Actor<'a> {
    /// Open loop: the excitation's value at each step's time.
    Excitation(&'a Multisine),
    /// A policy on the observations; its state starts at rest, earlier commands at `rest`.
    Policy {
        /// The policy.
        policy: &'a Policy,
        /// The command at rest (what a window policy's earlier commands hold at the start).
        rest: &'a [f64],
    },
}

/// A recorded episode.
#[derive(Clone, Debug, PartialEq)]
pub struct Episode {
    /// The seed the plant was reset with.
    pub seed: u64,
    /// Row `k`: the observation at step `k`.
    pub outputs: Vec<Vec<f64>>,
    /// Row `k`: the command issued at step `k` (the last never applied).
    pub commands: Vec<Vec<f64>>,
    /// The plant ended the episode before its length.
    pub ended_early: bool,
    /// It ended early on a limit, not a failure ([`crate::plant::PlantStep::truncated`]).
    pub truncated: bool,
    /// The policy that chose the commands; `None` for the excitation.
    pub policy: Option<Policy>,
}

impl Episode {
    /// Number of rows.
    pub fn len(&self) -> usize {
        self.outputs.len()
    }

    /// True without rows (never for a run episode).
    pub fn is_empty(&self) -> bool {
        self.outputs.is_empty()
    }

    /// The episode as a trajectory (original units).
    pub fn trajectory(&self) -> Result<Trajectory> {
        let n = self.len();
        let dy = self.outputs.first().map_or(0, Vec::len);
        let du = self.commands.first().map_or(0, Vec::len);
        let ragged = (0..n).find(|&k| {
            self.outputs[k].len() != dy || self.commands.get(k).is_none_or(|u| u.len() != du)
        });
        if let Some(k) = ragged.or((self.commands.len() != n).then_some(n)) {
            return Err(MsgpError::Data(format!(
                "episode (seed {}): row {k} has another number of outputs or commands than row 0",
                self.seed
            )));
        }
        let y = DMatrix::from_fn(n, dy, |k, j| self.outputs[k][j]);
        let u = DMatrix::from_fn(n, du, |k, j| self.commands[k][j]);
        Trajectory::new(u, y)
    }

    /// The measured cost over rows `from..from + steps`; rows after an early end count the
    /// full cost 1 each when the plant ended the episode because it failed, the measured rows'
    /// mean when it was truncated (a limit, not a failure).
    pub fn cost(&self, cost: &SaturatingCost, from: usize, steps: usize) -> f64 {
        let measured: Vec<f64> = self
            .outputs
            .iter()
            .skip(from)
            .take(steps)
            .map(|y| cost.at(y))
            .collect();
        let sum = measured.iter().sum::<f64>();
        let missing = (steps - measured.len()) as f64;
        match (self.truncated, measured.len()) {
            (true, n) if n > 0 => sum + missing * sum / n as f64,
            _ => sum + missing,
        }
    }
}

/// Runs one episode of `steps` control steps on `plant`, reset with `seed`. Every observation
/// is checked against the plant's spec; excitation commands are clipped into the plant's
/// bounds, a policy's must lie within them.
pub fn run_episode(
    plant: &mut dyn Plant,
    actor: &Actor<'_>,
    seed: u64,
    steps: usize,
) -> Result<Episode> {
    let spec = plant.spec().clone();
    let bounds = spec.bounds()?;
    let mut y = plant.reset(seed)?;
    spec.check_observation(&y, 0)?;
    let mut state = match actor {
        Actor::Policy { policy, rest } => rest_state(policy, &y, rest),
        Actor::Excitation(_) => Vec::new(),
    };
    let mut episode = Episode {
        seed,
        outputs: Vec::with_capacity(steps + 1),
        commands: Vec::with_capacity(steps + 1),
        ended_early: false,
        truncated: false,
        policy: match actor {
            Actor::Policy { policy, .. } => Some((*policy).clone()),
            Actor::Excitation(_) => None,
        },
    };
    let mut done = false;
    for k in 0..=steps {
        let u = match actor {
            Actor::Excitation(signal) => {
                let raw = signal.value(k as f64 * spec.period);
                raw.iter()
                    .enumerate()
                    .map(|(j, v)| v.clamp(bounds.low()[j], bounds.high()[j]))
                    .collect()
            }
            Actor::Policy { policy, .. } => {
                let (u, next) = policy.act(&y, &state)?;
                check_command(&u, &bounds, k)?;
                state = next;
                // a sine saturation reaches its bound up to rounding
                u.iter()
                    .enumerate()
                    .map(|(j, v)| v.clamp(bounds.low()[j], bounds.high()[j]))
                    .collect()
            }
        };
        episode.outputs.push(std::mem::take(&mut y));
        episode.commands.push(u);
        if k == steps || done {
            episode.ended_early = k < steps;
            break;
        }
        let step = plant.step(&episode.commands[k])?;
        spec.check_observation(&step.observation, k + 1)?;
        (y, done) = (step.observation, step.done);
        episode.truncated = step.done && step.truncated;
    }
    Ok(episode)
}

/// A policy's state before its first action on `y0`: earlier observations at `y0`, earlier
/// commands at `rest`, integrals at zero (the policy search's start, [`RestEntry`]).
pub fn rest_state(policy: &Policy, y0: &[f64], rest: &[f64]) -> Vec<f64> {
    policy
        .lift::<f64>()
        .rest_state()
        .into_iter()
        .map(|e| match e {
            RestEntry::Observation(j) => y0[j],
            RestEntry::Command(j) => rest[j],
            RestEntry::Zero => 0.0,
        })
        .collect()
}

/// A command is finite and within the plant's bounds.
fn check_command(u: &[f64], bounds: &crate::policy::CommandBounds, step: usize) -> Result<()> {
    if u.len() != bounds.len() {
        return Err(MsgpError::Shape(format!(
            "step {step}: the policy gives {} commands, the plant takes {}",
            u.len(),
            bounds.len()
        )));
    }
    for (j, v) in u.iter().enumerate() {
        // a sine saturation reaches its bound up to rounding
        let slack = 1e-12 * (bounds.high()[j] - bounds.low()[j]);
        if !(v.is_finite() && *v >= bounds.low()[j] - slack && *v <= bounds.high()[j] + slack) {
            return Err(MsgpError::Plant(format!(
                "step {step}: command {j} = {v} is outside the plant's bounds [{}, {}]",
                bounds.low()[j],
                bounds.high()[j]
            )));
        }
    }
    Ok(())
}

/// `traj` as overlapping segments of `len` samples with stride `len / 2` (the last one ends
/// at the end); segments shorter than `min_len` are dropped.
pub fn segments(traj: &Trajectory, len: usize, min_len: usize) -> Result<Vec<Trajectory>> {
    let n = traj.len();
    let len = len.max(min_len).max(2);
    let stride = (len / 2).max(1);
    let mut out = Vec::new();
    let mut start = 0;
    while start + min_len <= n {
        let end = (start + len).min(n);
        out.push(Trajectory::new(
            traj.u.rows(start, end - start).into_owned(),
            traj.y.rows(start, end - start).into_owned(),
        )?);
        if end == n {
            break;
        }
        start += stride;
    }
    Ok(out)
}
