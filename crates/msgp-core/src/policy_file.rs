//! The versioned policy file: a JSON document holding a policy (any family, in original
//! units), the plant signals it acts on, the task it was searched for and what the model
//! predicted of it. Specified field by field in `docs/policy-format.md`.
//!
//! - [`PolicyRecord`] is a policy as data: `kind` (`pid`, `linear`, `rbf`) and its matrices
//!   row by row; [`PolicyRecord::to_policy`] checks every shape and value.
//! - [`PolicyFile::write`] writes atomically; [`PolicyFile::read`] refuses files of another
//!   major format version before looking at anything else.
//! - Floats are written as shortest round-trip decimals and parsed exactly, so a saved and
//!   reloaded policy acts bit-identically.

use std::path::Path;

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};
use serde_json::Value;

use crate::error::{MsgpError, Result};
use crate::learner::{LearnerSettings, StartDistribution, Task, stated_cost};
use crate::model_file::{parse_version, rows_of as rows, write_atomically};
use crate::plant::PlantSpec;
use crate::policy::{CommandBounds, PidPolicy, Policy, RbfPolicy, StateFeedback};
use crate::policy_search::SearchSpace;

/// Value of the `format` field.
pub const FORMAT: &str = "msgp-policy";
/// Major format version written and read by this build.
pub const FORMAT_MAJOR: u32 = 1;
/// Minor format version written by this build (readers accept any minor of their major).
pub const FORMAT_MINOR: u32 = 0;

/// Most observations or commands a linear policy's window holds.
const MAX_LAGS: usize = 1000;

/// A policy as data (see the module docs); matrices as lists of rows.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum PolicyRecord {
    /// Saturated PID on the observation.
    Pid {
        /// `K_p` (d_u × d_y).
        kp: Vec<Vec<f64>>,
        /// `K_i`.
        ki: Vec<Vec<f64>>,
        /// `K_d`.
        kd: Vec<Vec<f64>>,
        /// Control period \[s\] of its integral and derivative.
        period: f64,
        /// Saturation limit per command (`±u_max`).
        u_max: Vec<f64>,
    },
    /// Saturated linear feedback on a window of observations and commands.
    Linear {
        /// The gain (d_u × (output_lags·d_y + input_lags·d_u)).
        gain: Vec<Vec<f64>>,
        /// The offset (d_u).
        offset: Vec<f64>,
        /// Observations in the window (the newest first).
        output_lags: usize,
        /// Earlier commands in the window.
        input_lags: usize,
        /// Lower command bounds.
        low: Vec<f64>,
        /// Upper command bounds.
        high: Vec<f64>,
    },
    /// PILCO's RBF network, saturated.
    Rbf {
        /// Centres (n × d_y).
        centres: Vec<Vec<f64>>,
        /// Weights (n × d_u).
        weights: Vec<Vec<f64>>,
        /// Log length scales (d_y).
        log_widths: Vec<f64>,
        /// Lower command bounds.
        low: Vec<f64>,
        /// Upper command bounds.
        high: Vec<f64>,
    },
}

/// `rows` as a matrix of `ncols` columns (any number of rows), or a message naming `what`.
fn matrix(what: &str, rows: &[Vec<f64>]) -> Result<DMatrix<f64>> {
    let ncols = rows.first().map_or(0, Vec::len);
    if let Some(i) = rows.iter().position(|r| r.len() != ncols) {
        return Err(MsgpError::Data(format!(
            "policy `{what}`: row {i} has {} entries, row 0 has {ncols}",
            rows[i].len()
        )));
    }
    let m = DMatrix::from_fn(rows.len(), ncols, |i, j| rows[i][j]);
    finite(what, m.as_slice())?;
    Ok(m)
}

fn finite(what: &str, values: &[f64]) -> Result<()> {
    match values.iter().position(|v| !v.is_finite()) {
        Some(i) => Err(MsgpError::Data(format!(
            "policy `{what}`: entry {i} is not finite"
        ))),
        None => Ok(()),
    }
}

impl From<&Policy> for PolicyRecord {
    fn from(p: &Policy) -> Self {
        match p {
            Policy::Pid(p) => PolicyRecord::Pid {
                kp: rows(&p.kp),
                ki: rows(&p.ki),
                kd: rows(&p.kd),
                period: p.period,
                u_max: p.u_max.clone(),
            },
            Policy::StateFeedback(p) => PolicyRecord::Linear {
                gain: rows(&p.gain),
                offset: p.offset.iter().copied().collect(),
                output_lags: p.output_lags,
                input_lags: p.input_lags,
                low: p.bounds.low().to_vec(),
                high: p.bounds.high().to_vec(),
            },
            Policy::Rbf(p) => PolicyRecord::Rbf {
                centres: rows(&p.centres),
                weights: rows(&p.weights),
                log_widths: p.log_widths.iter().copied().collect(),
                low: p.bounds.low().to_vec(),
                high: p.bounds.high().to_vec(),
            },
        }
    }
}

impl PolicyRecord {
    /// The policy, every shape and value checked.
    pub fn to_policy(&self) -> Result<Policy> {
        Ok(match self {
            PolicyRecord::Pid {
                kp,
                ki,
                kd,
                period,
                u_max,
            } => {
                finite("u_max", u_max)?;
                Policy::Pid(PidPolicy::new(
                    matrix("kp", kp)?,
                    matrix("ki", ki)?,
                    matrix("kd", kd)?,
                    *period,
                    u_max.clone(),
                )?)
            }
            PolicyRecord::Linear {
                gain,
                offset,
                output_lags,
                input_lags,
                low,
                high,
            } => {
                finite("offset", offset)?;
                if *output_lags > MAX_LAGS || *input_lags > MAX_LAGS {
                    return Err(MsgpError::Data(format!(
                        "policy `output_lags`/`input_lags`: at most {MAX_LAGS}, got {output_lags} \
                         and {input_lags}"
                    )));
                }
                let bounds = CommandBounds::new(low.clone(), high.clone())?;
                let gain = matrix("gain", gain)?;
                let du = bounds.len();
                let window = gain.ncols().saturating_sub(input_lags * du);
                let dy = window / (*output_lags).max(1);
                Policy::StateFeedback(StateFeedback::new(
                    gain,
                    DVector::from_column_slice(offset),
                    dy,
                    (*output_lags, *input_lags),
                    bounds,
                )?)
            }
            PolicyRecord::Rbf {
                centres,
                weights,
                log_widths,
                low,
                high,
            } => {
                finite("log_widths", log_widths)?;
                Policy::Rbf(RbfPolicy::new(
                    matrix("centres", centres)?,
                    matrix("weights", weights)?,
                    DVector::from_column_slice(log_widths),
                    CommandBounds::new(low.clone(), high.clone())?,
                )?)
            }
        })
    }
}

/// Where a task's rollouts start, as data.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(tag = "kind", rename_all = "snake_case", deny_unknown_fields)]
pub enum StartRecord {
    /// A known Gaussian.
    Fixed {
        /// Mean per output.
        mean: Vec<f64>,
        /// Variance per output.
        var: Vec<f64>,
    },
    /// Estimated from the episodes' first observations.
    Observed {
        /// Smallest variance.
        floor: f64,
    },
    /// Each of the latest episodes' first observations, a start of its own.
    EachObserved {
        /// Variance of each start.
        floor: f64,
        /// Most starts.
        most: usize,
    },
}

/// A task as data: what [`Task`] holds besides the policy.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct TaskRecord {
    /// The cost's target per output.
    pub target: Vec<f64>,
    /// The cost's width per output; `null`: the output does not count.
    pub widths: Vec<Option<f64>>,
    /// The widths' scales (PILCO's several widths; absent: `[1.0]`, the widths alone).
    #[serde(
        default = "crate::learner::one_width",
        skip_serializing_if = "crate::learner::is_one_width"
    )]
    pub width_scales: Vec<f64>,
    /// Per output: an angle, costed on its unit tip (absent: none is).
    #[serde(default, skip_serializing_if = "Vec::is_empty")]
    pub angles: Vec<bool>,
    /// Control steps of an episode.
    pub episode_steps: usize,
    /// Control steps of the rollouts the policy is optimised on.
    pub policy_horizon: usize,
    /// Where they start.
    pub start: StartRecord,
    /// The command at rest.
    pub rest_command: Vec<f64>,
    /// Which entries of the policy's flat parameter vector the search moves.
    pub free: Vec<bool>,
    /// Typical magnitude of each free entry.
    pub typical: Vec<f64>,
}

impl TaskRecord {
    /// The record of `task`.
    pub fn of(task: &Task) -> Self {
        let cost = &task.cost;
        Self {
            target: cost.target.iter().copied().collect(),
            widths: cost
                .widths
                .iter()
                .map(|w| w.is_finite().then_some(*w))
                .collect(),
            width_scales: cost.scales.clone(),
            angles: if cost.angles.contains(&true) {
                cost.angles.clone()
            } else {
                Vec::new()
            },
            episode_steps: task.episode_steps,
            policy_horizon: task.policy_horizon,
            start: match &task.start {
                StartDistribution::Fixed { mean, var } => StartRecord::Fixed {
                    mean: mean.clone(),
                    var: var.clone(),
                },
                StartDistribution::Observed { floor } => StartRecord::Observed { floor: *floor },
                StartDistribution::EachObserved { floor, most } => StartRecord::EachObserved {
                    floor: *floor,
                    most: *most,
                },
            },
            rest_command: task.rest_command.clone(),
            free: task.space.free.clone(),
            typical: task.typical.clone(),
        }
    }

    /// The angle flag per output (none when the record has none).
    fn angles(&self) -> Vec<bool> {
        if self.angles.is_empty() {
            vec![false; self.target.len()]
        } else {
            self.angles.clone()
        }
    }

    /// The task with `policy` as its searched policy.
    pub fn to_task(&self, policy: Policy) -> Result<Task> {
        Ok(Task {
            cost: stated_cost(
                &self.target,
                &self.widths,
                &self.angles(),
                &self.width_scales,
            )?,
            episode_steps: self.episode_steps,
            policy_horizon: self.policy_horizon,
            start: match &self.start {
                StartRecord::Fixed { mean, var } => StartDistribution::Fixed {
                    mean: mean.clone(),
                    var: var.clone(),
                },
                StartRecord::Observed { floor } => StartDistribution::Observed { floor: *floor },
                StartRecord::EachObserved { floor, most } => StartDistribution::EachObserved {
                    floor: *floor,
                    most: *most,
                },
            },
            rest_command: self.rest_command.clone(),
            space: SearchSpace {
                base: policy,
                free: self.free.clone(),
            },
            typical: self.typical.clone(),
        })
    }
}

/// What the model predicted of the policy when it was searched.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct Prediction {
    /// Expected cost over the task's episode (its scored steps).
    pub cost: f64,
    /// Its standard deviation.
    pub cost_std: f64,
    /// The model the search ran on (`msgp`, `linear-kf`, …).
    pub model: String,
}

/// The policy file (see the module docs).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct PolicyFile {
    /// Always [`FORMAT`].
    pub format: String,
    /// `MAJOR.MINOR`.
    pub format_version: String,
    /// The policy.
    pub policy: PolicyRecord,
    /// The plant signals it acts on (names, bounds, period), when known.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub plant: Option<PlantSpec>,
    /// The task it was searched for, when known (`msgp policy improve` continues it).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub task: Option<TaskRecord>,
    /// What the model predicted of it, when it was searched.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub prediction: Option<Prediction>,
    /// The loop iteration that produced it (0: the first policy, before any search).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub iteration: Option<usize>,
    /// The loop's settings (its model, search, seeds), when it came from a loop: what
    /// `msgp policy improve` continues with.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub settings: Option<LearnerSettings>,
}

fn invalid(path: &Path, message: String) -> MsgpError {
    MsgpError::File {
        path: path.to_path_buf(),
        message: format!("invalid policy file: {message}"),
    }
}

/// The signals a policy acts on, unnamed (period 1 s).
fn signals_of(policy: &Policy) -> PlantSpec {
    let bounds = policy.bounds();
    PlantSpec {
        period: 1.0,
        commands: (0..bounds.len())
            .map(|j| crate::plant::CommandSpec {
                name: format!("command{j}"),
                low: bounds.low()[j],
                high: bounds.high()[j],
            })
            .collect(),
        outputs: (0..policy.observation_dim())
            .map(|j| crate::plant::OutputSpec::named(&format!("output{j}")))
            .collect(),
    }
}

impl PolicyFile {
    /// A file of `policy` with nothing else known.
    pub fn new(policy: &Policy) -> Self {
        Self {
            format: FORMAT.into(),
            format_version: format!("{FORMAT_MAJOR}.{FORMAT_MINOR}"),
            policy: policy.into(),
            plant: None,
            task: None,
            prediction: None,
            iteration: None,
            settings: None,
        }
    }

    /// The policy.
    pub fn to_policy(&self) -> Result<Policy> {
        self.policy.to_policy()
    }

    /// Parses and checks a policy file's bytes; `path` is used in messages.
    pub fn from_json(bytes: &[u8], path: &Path) -> Result<Self> {
        let value: Value = serde_json::from_slice(bytes)
            .map_err(|e| invalid(path, format!("not valid JSON: {e}")))?;
        let Value::Object(obj) = &value else {
            return Err(invalid(path, "not a JSON object".into()));
        };
        match obj.get("format") {
            Some(Value::String(f)) if f == FORMAT => {}
            _ => {
                return Err(invalid(
                    path,
                    format!("not an msgp policy file (no \"format\": \"{FORMAT}\")"),
                ));
            }
        }
        let Some(Value::String(version)) = obj.get("format_version") else {
            return Err(invalid(path, "no \"format_version\" string".into()));
        };
        match parse_version(version) {
            Some((major, _)) if major == FORMAT_MAJOR => {}
            _ => {
                return Err(MsgpError::File {
                    path: path.to_path_buf(),
                    message: format!(
                        "policy file format version {version} is not supported (this build \
                         reads {FORMAT_MAJOR}.x)"
                    ),
                });
            }
        }
        let file: Self = serde_json::from_value(value).map_err(|e| invalid(path, e.to_string()))?;
        let policy = file.to_policy().map_err(|e| invalid(path, e.to_string()))?;
        file.check(&policy)
            .map_err(|e| invalid(path, e.to_string()))?;
        Ok(file)
    }

    /// The parts agree: the plant's signals with the policy's, the task with both (without a
    /// plant, with the signals the policy acts on).
    fn check(&self, policy: &Policy) -> Result<()> {
        let spec = match &self.plant {
            Some(spec) => spec.clone(),
            None => signals_of(policy),
        };
        match &self.task {
            Some(task) => task.to_task(policy.clone())?.validate(&spec),
            None if spec.command_dim() != policy.command_dim()
                || spec.output_dim() != policy.observation_dim() =>
            {
                Err(MsgpError::Shape(format!(
                    "the policy maps {} outputs to {} commands, the plant has {} and {}",
                    policy.observation_dim(),
                    policy.command_dim(),
                    spec.output_dim(),
                    spec.command_dim()
                )))
            }
            None => Ok(()),
        }
    }

    /// Reads and checks a policy file.
    pub fn read(path: &Path) -> Result<Self> {
        let bytes = std::fs::read(path).map_err(|e| MsgpError::File {
            path: path.to_path_buf(),
            message: format!("cannot read the policy: {e}"),
        })?;
        Self::from_json(&bytes, path)
    }

    /// Pretty-printed JSON text.
    pub fn to_json(&self) -> Result<String> {
        serde_json::to_string_pretty(self)
            .map_err(|e| MsgpError::Data(format!("cannot serialise the policy: {e}")))
    }

    /// Writes the file atomically (a temporary sibling, fsync, rename).
    pub fn write(&self, path: &Path) -> Result<()> {
        let mut text = self.to_json()?;
        text.push('\n');
        write_atomically(path, text.as_bytes())
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::policy::CommandBounds;

    fn policies() -> Vec<Policy> {
        let bounds = CommandBounds::new(vec![-2.0, 0.0], vec![2.0, 1.0]).expect("valid");
        vec![
            Policy::Pid(
                PidPolicy::new(
                    DMatrix::from_row_slice(1, 2, &[34.55, 1.98]),
                    DMatrix::from_row_slice(1, 2, &[0.0, 0.3]),
                    DMatrix::from_row_slice(1, 2, &[7.03, 3.73]),
                    0.02,
                    vec![3.0],
                )
                .expect("valid"),
            ),
            Policy::StateFeedback(
                StateFeedback::new(
                    DMatrix::from_fn(2, 3 * 2 + 2, |i, j| 0.1 * (i + j) as f64 - 0.3),
                    DVector::from_column_slice(&[0.1, -0.2]),
                    3,
                    (2, 1),
                    bounds.clone(),
                )
                .expect("valid"),
            ),
            Policy::Rbf(
                RbfPolicy::new(
                    DMatrix::from_fn(4, 3, |i, j| (i as f64 - j as f64) / 7.0),
                    DMatrix::from_fn(4, 2, |i, j| 1.0 / (1.0 + i as f64 + j as f64)),
                    DVector::from_column_slice(&[0.1, -0.4, 0.3]),
                    bounds,
                )
                .expect("valid"),
            ),
        ]
    }

    /// Every family survives JSON exactly: the same parameters, the same action bit for bit.
    #[test]
    fn every_family_round_trips_exactly() {
        for p in policies() {
            let file = PolicyFile::new(&p);
            let text = file.to_json().expect("json");
            let back = PolicyFile::from_json(text.as_bytes(), Path::new("p.json")).expect("reads");
            let q = back.to_policy().expect("valid");
            assert_eq!(p, q, "{}", p.kind());
            let dy = match &p {
                Policy::Pid(p) => p.kp.ncols(),
                Policy::StateFeedback(p) => p.dy(),
                Policy::Rbf(p) => p.centres.ncols(),
            };
            let y: Vec<f64> = (0..dy).map(|j| 0.1 * j as f64 - 0.05).collect();
            let state = vec![0.0; p.lift::<f64>().state_dim()];
            assert_eq!(
                p.act(&y, &state).expect("acts"),
                q.act(&y, &state).expect("acts")
            );
        }
    }

    /// Another major version, another format, broken shapes and non-finite values are refused
    /// with the file named.
    #[test]
    fn bad_files_are_refused_clearly() {
        let good = PolicyFile::new(&policies()[2]).to_json().expect("json");
        let path = Path::new("dir/p.json");
        let cases = [
            (
                good.replace("\"1.0\"", "\"2.0\""),
                "format version 2.0 is not supported",
            ),
            (
                good.replace("msgp-policy", "msgp-model"),
                "not an msgp policy file",
            ),
            (good.replace("\"rbf\"", "\"mlp\""), "invalid policy file"),
            ("[1, 2]".to_string(), "not a JSON object"),
        ];
        for (text, needle) in cases {
            let e = PolicyFile::from_json(text.as_bytes(), path)
                .expect_err("refused")
                .to_string();
            assert!(e.contains(needle) && e.contains("dir/p.json"), "{e}");
        }
        let mut file = PolicyFile::new(&policies()[2]);
        if let PolicyRecord::Rbf { weights, .. } = &mut file.policy {
            weights[1].pop();
        }
        let e = PolicyFile::from_json(file.to_json().expect("json").as_bytes(), path)
            .expect_err("ragged")
            .to_string();
        assert!(e.contains("`weights`: row 1"), "{e}");
        // a task that does not fit the policy (without a plant: the policy's own signals)
        let policy = &policies()[1];
        let mut file = PolicyFile::new(policy);
        file.task = Some(TaskRecord {
            target: vec![0.0; 3],
            widths: vec![Some(1.0); 3],
            width_scales: vec![1.0],
            angles: Vec::new(),
            episode_steps: 10,
            policy_horizon: 10,
            start: StartRecord::Observed { floor: 1e-6 },
            rest_command: vec![0.0],
            free: vec![true; policy.param_len()],
            typical: vec![1.0; policy.param_len()],
        });
        let e = PolicyFile::from_json(file.to_json().expect("json").as_bytes(), path)
            .expect_err("short rest command")
            .to_string();
        assert!(e.contains("rest command"), "{e}");
        if let Some(t) = &mut file.task {
            t.rest_command = vec![0.0, 0.5];
        }
        assert!(PolicyFile::from_json(file.to_json().expect("json").as_bytes(), path).is_ok());
        // absurd window lengths are refused before anything is allocated
        let mut file = PolicyFile::new(policy);
        if let PolicyRecord::Linear { input_lags, .. } = &mut file.policy {
            *input_lags = usize::MAX / 2;
        }
        let e = PolicyFile::from_json(file.to_json().expect("json").as_bytes(), path)
            .expect_err("huge lags")
            .to_string();
        assert!(e.contains("at most 1000"), "{e}");
    }
}
