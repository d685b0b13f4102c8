//! Loading data files (CSV or MCAP) into named trajectories, with the CLI's column defaults.
//!
//! Column defaults when `--input`/`--output` are not given:
//! - CSV: the candidate columns are all but the time column (`t`/`time`), `episode` and `step`.
//!   A `msgp sim` run log (`command`, `meas_theta`, `meas_x`) uses `command` →
//!   `meas_theta,meas_x`; otherwise the first candidate is the input and the last the output.
//! - MCAP: a `msgp sim` log uses `/pendulum/command:acceleration` →
//!   `/pendulum/measurement:theta,/pendulum/measurement:x`; a log with one JSON topic (or with
//!   `--topic`) uses that topic's numeric fields (without `t`, `time`, `step`, `episode`) like
//!   the CSV columns.
//!
//! Several files, or an `episode` column, give several trajectories.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use clap::Args;
use msgp_core::data::Trajectory;
use msgp_core::data::mcap::{McapLog, Signal};
use msgp_core::data::table::{EPISODE_COLUMN, Table};
use msgp_core::model::{Metrics, Simulation};

/// Options that select the data (shared by `fit`, `eval` and `simulate`).
#[derive(Debug, Args)]
pub struct DataArgs {
    /// Data file: CSV with a header line, or MCAP (`.mcap`). Repeat for several trajectories.
    #[arg(long = "data", value_name = "FILE", required = true)]
    pub data: Vec<PathBuf>,
    /// Input columns, comma-separated (MCAP: TOPIC:FIELD, or FIELD with --topic).
    #[arg(long, value_name = "COL,...", value_delimiter = ',')]
    pub input: Vec<String>,
    /// Output columns, comma-separated (MCAP: TOPIC:FIELD, or FIELD with --topic).
    #[arg(long, value_name = "COL,...", value_delimiter = ',')]
    pub output: Vec<String>,
    /// MCAP: topic of bare field names in --input/--output.
    #[arg(long, value_name = "TOPIC")]
    pub topic: Option<String>,
}

/// One trajectory with where it came from.
#[derive(Clone, Debug)]
pub struct Part {
    /// Source file.
    pub source: PathBuf,
    /// Value of the `episode` column, when there is one.
    pub episode: Option<f64>,
    /// Time stamps (time column, MCAP log time in seconds, or the row number).
    pub times: Vec<f64>,
    /// The data.
    pub traj: Trajectory,
}

impl Part {
    /// `file` or `file (episode 3)`.
    pub fn label(&self) -> String {
        match self.episode {
            Some(e) => format!("{} (episode {e})", self.source.display()),
            None => self.source.display().to_string(),
        }
    }

    /// Rows `start..end`.
    pub fn slice(&self, start: usize, end: usize) -> Self {
        Self {
            source: self.source.clone(),
            episode: self.episode,
            times: self.times[start..end].to_vec(),
            traj: self.traj.slice(start, end),
        }
    }
}

/// Trajectories with named inputs and outputs.
#[derive(Clone, Debug)]
pub struct Dataset {
    /// Input column names.
    pub inputs: Vec<String>,
    /// Output column names.
    pub outputs: Vec<String>,
    /// The trajectories.
    pub parts: Vec<Part>,
}

/// What the user asked for: explicit names, or the defaults above.
#[derive(Clone, Copy, Debug)]
pub struct Selection<'a> {
    /// Requested inputs (empty: default).
    pub inputs: &'a [String],
    /// Requested outputs (empty: default).
    pub outputs: &'a [String],
    /// Default MCAP topic.
    pub topic: Option<&'a str>,
}

const SKIP: [&str; 5] = ["t", "time", "step", EPISODE_COLUMN, "index"];

fn is_mcap(path: &Path, bytes: &[u8]) -> bool {
    bytes.starts_with(b"\x89MCAP")
        || path
            .extension()
            .is_some_and(|e| e.eq_ignore_ascii_case("mcap"))
}

/// Default input and output among `candidates` (CSV columns or MCAP fields).
fn default_columns(
    candidates: &[String],
    inputs: &[String],
    outputs: &[String],
) -> anyhow::Result<(Vec<String>, Vec<String>)> {
    let pick = |exclude: &[String], last: bool| {
        let mut it = candidates.iter().filter(|c| !exclude.contains(c));
        if last { it.next_back() } else { it.next() }.cloned()
    };
    let outputs = if outputs.is_empty() {
        match pick(inputs, true) {
            Some(c) => vec![c],
            None => bail!(
                "no column left for the output (candidates: {})",
                candidates.join(", ")
            ),
        }
    } else {
        outputs.to_vec()
    };
    let inputs = if inputs.is_empty() {
        match pick(&outputs, false) {
            Some(c) => vec![c],
            None => bail!(
                "need an input and an output column; found only {} (name them with --input/--output)",
                candidates.join(", ")
            ),
        }
    } else {
        inputs.to_vec()
    };
    Ok((inputs, outputs))
}

fn csv_names(table: &Table, sel: &Selection<'_>) -> anyhow::Result<(Vec<String>, Vec<String>)> {
    let has = |c: &str| table.columns.iter().any(|x| x == c);
    if sel.inputs.is_empty()
        && sel.outputs.is_empty()
        && has("command")
        && has("meas_theta")
        && has("meas_x")
    {
        return Ok((
            vec!["command".into()],
            vec!["meas_theta".into(), "meas_x".into()],
        ));
    }
    let candidates: Vec<String> = table
        .columns
        .iter()
        .filter(|c| !SKIP.iter().any(|s| c.eq_ignore_ascii_case(s)))
        .cloned()
        .collect();
    default_columns(&candidates, sel.inputs, sel.outputs)
}

fn mcap_names(log: &McapLog, sel: &Selection<'_>) -> anyhow::Result<(Vec<String>, Vec<String>)> {
    let signal = |s: &String| -> anyhow::Result<String> {
        Ok(Signal::parse(s, sel.topic)
            .with_context(|| format!("{}", log.path.display()))?
            .name())
    };
    let inputs: Vec<String> = sel
        .inputs
        .iter()
        .map(signal)
        .collect::<anyhow::Result<_>>()?;
    let outputs: Vec<String> = sel
        .outputs
        .iter()
        .map(signal)
        .collect::<anyhow::Result<_>>()?;
    if !inputs.is_empty() && !outputs.is_empty() {
        return Ok((inputs, outputs));
    }
    let has = |t: &str| log.topics.iter().any(|x| x.topic == t);
    if inputs.is_empty()
        && outputs.is_empty()
        && sel.topic.is_none()
        && has("/pendulum/command")
        && has("/pendulum/measurement")
    {
        return Ok((
            vec!["/pendulum/command:acceleration".into()],
            vec![
                "/pendulum/measurement:theta".into(),
                "/pendulum/measurement:x".into(),
            ],
        ));
    }
    let topic = match sel.topic {
        Some(t) => t.to_string(),
        None => {
            let json: Vec<_> = log
                .topics
                .iter()
                .filter(|t| t.encoding == "json" && !t.latent)
                .collect();
            match json.as_slice() {
                [one] => one.topic.clone(),
                _ => bail!(
                    "{}: choose the signals with --input/--output TOPIC:FIELD or a --topic (topics: {})",
                    log.path.display(),
                    log.topic_list()
                ),
            }
        }
    };
    let fields = log.numeric_fields(&topic)?;
    let candidates: Vec<String> = fields
        .iter()
        .filter(|f| !SKIP.iter().any(|s| f.eq_ignore_ascii_case(s)))
        .map(|f| format!("{topic}:{f}"))
        .collect();
    default_columns(&candidates, &inputs, &outputs)
        .with_context(|| format!("{}: topic {topic}", log.path.display()))
}

/// Reads one file into a table with the selected columns; resolves the names on the first call.
fn load_file(
    path: &Path,
    sel: &Selection<'_>,
    names: &mut Option<(Vec<String>, Vec<String>)>,
) -> anyhow::Result<Table> {
    let bytes = std::fs::read(path).with_context(|| format!("cannot read {}", path.display()))?;
    if is_mcap(path, &bytes) {
        let log = McapLog::parse(&bytes, path)?;
        let (inputs, outputs) = match names {
            Some(n) => n.clone(),
            None => mcap_names(&log, sel)?,
        };
        let signals: Vec<Signal> = inputs
            .iter()
            .chain(&outputs)
            .map(|s| Signal::parse(s, sel.topic))
            .collect::<Result<_, _>>()?;
        let base = signals[inputs.len()].topic.clone();
        let table = log.table(&signals, &base)?;
        *names = Some((inputs, outputs));
        Ok(table)
    } else {
        let table = Table::parse_csv(&bytes, path)?;
        if names.is_none() {
            *names = Some(csv_names(&table, sel)?);
        }
        Ok(table)
    }
}

impl Dataset {
    /// Loads every file; the column names chosen on the first file apply to all of them.
    pub fn load(files: &[PathBuf], sel: &Selection<'_>) -> anyhow::Result<Self> {
        let mut names = None;
        let mut parts = Vec::new();
        for path in files {
            let table = load_file(path, sel, &mut names)?;
            let Some((inputs, outputs)) = &names else {
                bail!("no columns selected");
            };
            for name in inputs {
                if outputs.contains(name) {
                    bail!("column `{name}` is both an input and an output");
                }
            }
            let ins: Vec<&str> = inputs.iter().map(String::as_str).collect();
            let outs: Vec<&str> = outputs.iter().map(String::as_str).collect();
            let trajs = table.trajectories(&ins, &outs)?;
            let ids = table.episode_ids();
            for (k, (range, traj)) in table.episodes().into_iter().zip(trajs).enumerate() {
                parts.push(Part {
                    source: path.clone(),
                    episode: ids.as_ref().map(|v| v[k]),
                    times: table.times(range),
                    traj,
                });
            }
        }
        let Some((inputs, outputs)) = names else {
            bail!("no data files given (--data FILE)");
        };
        Ok(Self {
            inputs,
            outputs,
            parts,
        })
    }
}

/// Where each trajectory is split into training and test part.
#[derive(Clone, Copy, Debug, PartialEq)]
pub enum Split {
    /// The first N samples of each trajectory train.
    Count(usize),
    /// The first round(F·T) samples of each trajectory train.
    Fraction(f64),
}

/// Splits every part; test parts that would be empty are left out.
pub fn split(parts: &[Part], how: Split) -> (Vec<Part>, Vec<Part>) {
    let mut train = Vec::new();
    let mut test = Vec::new();
    for p in parts {
        let n = p.traj.len();
        let k = match how {
            Split::Count(c) => c.min(n),
            Split::Fraction(f) => ((n as f64 * f).round() as usize).min(n),
        };
        if k > 0 {
            train.push(p.slice(0, k));
        }
        if k < n {
            test.push(p.slice(k, n));
        }
    }
    (train, test)
}

/// Checks that every part has more samples than the history needs.
pub fn check_lengths(parts: &[Part], warmup: usize, what: &str) -> anyhow::Result<()> {
    for p in parts {
        if p.traj.len() <= warmup {
            bail!(
                "{}: the {what} part has {} samples; the history needs more than {warmup} \
                 (shorten --history or change the split)",
                p.label(),
                p.traj.len()
            );
        }
    }
    Ok(())
}

pub use msgp_core::model::pool;

/// A simulated part, ready for metrics, plots and CSV.
#[derive(Clone, Debug)]
pub struct Simulated {
    /// The measured data.
    pub part: Part,
    /// The free simulation.
    pub sim: Simulation,
    /// Its metrics.
    pub metrics: Metrics,
}

/// Free simulation of every part with `model`.
pub fn simulate_all(
    model: &msgp_core::model::Model,
    parts: &[Part],
) -> anyhow::Result<Vec<Simulated>> {
    parts
        .iter()
        .map(|p| {
            let sim = model
                .simulate(&p.traj)
                .with_context(|| format!("simulating {}", p.label()))?;
            let metrics = msgp_core::model::score(&sim, &p.traj)
                .with_context(|| format!("scoring {}", p.label()))?;
            Ok(Simulated {
                part: p.clone(),
                sim,
                metrics,
            })
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn names(v: &[&str]) -> Vec<String> {
        v.iter().map(|s| s.to_string()).collect()
    }

    #[test]
    fn defaults_pick_first_input_and_last_output() {
        let c = names(&["u1", "u2", "y"]);
        let (i, o) = default_columns(&c, &[], &[]).expect("defaults");
        assert_eq!((i, o), (names(&["u1"]), names(&["y"])));
        let (i, o) = default_columns(&c, &[], &names(&["u1"])).expect("output given");
        assert_eq!((i, o), (names(&["u2"]), names(&["u1"])));
        assert!(default_columns(&names(&["y"]), &[], &[]).is_err());
    }
}
