//! A plant: a system the learning loop runs episodes on — a simulator, a Gymnasium environment
//! behind the Python bindings, a user's own model of their machine.
//!
//! The loop sees only what a controller on the machine would: [`Plant::reset`] with a seed
//! gives the first observation, [`Plant::step`] with a command gives the next one and whether
//! the episode ended there (the pole fell, the environment terminated or truncated). The
//! [`PlantSpec`] says what the signals are: the control period, each command's name and
//! bounds, each output's name and whether it is an angle. The observation is the model's
//! output vector, in the order of [`PlantSpec::outputs`].

use serde::{Deserialize, Serialize};

use crate::error::{MsgpError, Result};
use crate::policy::CommandBounds;

/// One command of a plant: its name and the range it accepts.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CommandSpec {
    /// Name (a log's column, a plot's label).
    pub name: String,
    /// Lowest accepted value.
    pub low: f64,
    /// Highest accepted value.
    pub high: f64,
}

/// One output of a plant: its name, its range where known, and whether it is an angle
/// (radians, wrapping at ±π).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct OutputSpec {
    /// Name.
    pub name: String,
    /// The output is an angle in radians.
    #[serde(default)]
    pub angle: bool,
    /// Lowest value it takes, when bounded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub low: Option<f64>,
    /// Highest value it takes, when bounded.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub high: Option<f64>,
}

impl OutputSpec {
    /// An unbounded output that is not an angle.
    pub fn named(name: &str) -> Self {
        Self {
            name: name.into(),
            angle: false,
            low: None,
            high: None,
        }
    }

    /// Its range's middle and half width when both ends are known and finite.
    pub fn range(&self) -> Option<(f64, f64)> {
        match (self.low, self.high) {
            (Some(l), Some(h)) if l.is_finite() && h.is_finite() && l < h => {
                Some((0.5 * (l + h), 0.5 * (h - l)))
            }
            _ => None,
        }
    }
}

/// What a plant's signals are.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct PlantSpec {
    /// Control period \[s\]: the time between two steps.
    pub period: f64,
    /// The commands, in the order [`Plant::step`] takes them.
    pub commands: Vec<CommandSpec>,
    /// The outputs, in the order observations hold them.
    pub outputs: Vec<OutputSpec>,
}

impl PlantSpec {
    /// Checks the spec: a positive finite period, at least one command with finite
    /// `low < high`, at least one output.
    pub fn validate(&self) -> Result<()> {
        if !(self.period.is_finite() && self.period > 0.0) {
            return Err(MsgpError::InvalidSetting {
                name: "plant period",
                reason: format!("must be positive and finite, got {}", self.period),
            });
        }
        if self.outputs.is_empty() {
            return Err(MsgpError::InvalidSetting {
                name: "plant outputs",
                reason: "a plant needs at least one output".into(),
            });
        }
        self.bounds().map(|_| ())
    }

    /// The commands' bounds.
    pub fn bounds(&self) -> Result<CommandBounds> {
        CommandBounds::new(
            self.commands.iter().map(|c| c.low).collect(),
            self.commands.iter().map(|c| c.high).collect(),
        )
    }

    /// Number of outputs.
    pub fn output_dim(&self) -> usize {
        self.outputs.len()
    }

    /// Per output: it is an angle.
    pub fn angles(&self) -> Vec<bool> {
        self.outputs.iter().map(|o| o.angle).collect()
    }

    /// Number of commands.
    pub fn command_dim(&self) -> usize {
        self.commands.len()
    }

    /// An observation as the plant returned it at `step` (0: the reset's), checked: as many
    /// values as outputs, all finite.
    pub fn check_observation(&self, observation: &[f64], step: usize) -> Result<()> {
        if observation.len() != self.outputs.len() {
            return Err(MsgpError::Plant(format!(
                "step {step}: the observation has {} values, the plant declares {} outputs",
                observation.len(),
                self.outputs.len()
            )));
        }
        if let Some(j) = observation.iter().position(|v| !v.is_finite()) {
            return Err(MsgpError::Plant(format!(
                "step {step}: output {j} (`{}`) is {}",
                self.outputs[j].name, observation[j]
            )));
        }
        Ok(())
    }
}

/// What a step returns.
#[derive(Clone, Debug, PartialEq)]
pub struct PlantStep {
    /// The observation after the step.
    pub observation: Vec<f64>,
    /// The episode ended at this observation (no further step is taken).
    pub done: bool,
    /// It ended on a limit of time or of the environment's own (Gymnasium's `truncated`), not
    /// because the task failed: the steps it did not run are not costed as failures.
    pub truncated: bool,
}

/// A system the learning loop runs episodes on (see the module docs).
pub trait Plant {
    /// The signals' description; the same for the plant's whole life.
    fn spec(&self) -> &PlantSpec;

    /// Starts an episode; the seed fixes everything random about it (initial state, noise).
    /// Returns the first observation.
    fn reset(&mut self, seed: u64) -> Result<Vec<f64>>;

    /// Applies `command` (one value per command, within the bounds) for one control period.
    fn step(&mut self, command: &[f64]) -> Result<PlantStep>;
}

impl<P: Plant + ?Sized> Plant for &mut P {
    fn spec(&self) -> &PlantSpec {
        (**self).spec()
    }
    fn reset(&mut self, seed: u64) -> Result<Vec<f64>> {
        (**self).reset(seed)
    }
    fn step(&mut self, command: &[f64]) -> Result<PlantStep> {
        (**self).step(command)
    }
}

impl<P: Plant + ?Sized> Plant for Box<P> {
    fn spec(&self) -> &PlantSpec {
        (**self).spec()
    }
    fn reset(&mut self, seed: u64) -> Result<Vec<f64>> {
        (**self).reset(seed)
    }
    fn step(&mut self, command: &[f64]) -> Result<PlantStep> {
        (**self).step(command)
    }
}
