//! A dataset: data files (CSV or MCAP) loaded into named trajectories, each with where it came
//! from, and split into training and test parts. What `msgp fit`, `eval` and `simulate` read;
//! any front end that takes files loads them the same way.
//!
//! Column defaults when no inputs or outputs are named:
//! - CSV: the candidate columns are all but the time column (`t`/`time`), `episode`, `step` and
//!   `index`. A `msgp sim` run log (`command`, `meas_theta`, `meas_x`) uses `command` →
//!   `meas_theta,meas_x`; otherwise the first candidate is the input and the last the output.
//! - MCAP: a `msgp sim` log uses `/pendulum/command:acceleration` →
//!   `/pendulum/measurement:theta,/pendulum/measurement:x`; a log with one readable topic (JSON
//!   or ROS 2 CDR), or a default topic, uses that topic's numeric fields (without `t`, `time`,
//!   `step`, `episode` and a ROS `header`) like the CSV columns.
//!
//! Several files, or an `episode` column, give several trajectories.

use std::path::{Path, PathBuf};

#[cfg(feature = "mcap")]
use super::mcap::{McapLog, Signal};
use super::table::{EPISODE_COLUMN, IRREGULAR_STEP_TOLERANCE, Table, TimeSource};
use super::trajectory::Trajectory;
use crate::error::{MsgpError, Result};

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
    /// What a user should know about the data but that does not stop the load (an irregular
    /// time step), one line each, naming the file.
    pub warnings: Vec<String>,
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
    /// MCAP: where the message times come from.
    pub time: TimeSource,
    /// CSV: sort each trajectory's rows by the time column instead of refusing a time that
    /// goes back (a warning says how many rows moved; repeated times are still an error).
    /// MCAP messages are always read in time order.
    pub sort_time: bool,
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
) -> Result<(Vec<String>, Vec<String>)> {
    let pick = |exclude: &[String], last: bool| {
        let mut it = candidates.iter().filter(|c| !exclude.contains(c));
        if last { it.next_back() } else { it.next() }.cloned()
    };
    let outputs = if outputs.is_empty() {
        match pick(inputs, true) {
            Some(c) => vec![c],
            None => {
                return Err(MsgpError::Data(format!(
                    "no column left for the output (candidates: {})",
                    candidates.join(", ")
                )));
            }
        }
    } else {
        outputs.to_vec()
    };
    let inputs = if inputs.is_empty() {
        match pick(&outputs, false) {
            Some(c) => vec![c],
            None => {
                return Err(MsgpError::Data(format!(
                    "need an input and an output column; found only {} (name them with \
                     --input/--output)",
                    candidates.join(", ")
                )));
            }
        }
    } else {
        inputs.to_vec()
    };
    Ok((inputs, outputs))
}

fn csv_names(table: &Table, sel: &Selection<'_>) -> Result<(Vec<String>, Vec<String>)> {
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
    default_columns(&candidates, sel.inputs, sel.outputs).map_err(|e| in_file(&table.path, e))
}

/// `e` said of the file `path`, unless it names a file already.
fn in_file(path: &Path, e: MsgpError) -> MsgpError {
    match e {
        e @ (MsgpError::File { .. } | MsgpError::FileAt { .. }) => e,
        MsgpError::Data(message) => MsgpError::File {
            path: path.to_path_buf(),
            message,
        },
        other => MsgpError::File {
            path: path.to_path_buf(),
            message: other.to_string(),
        },
    }
}

#[cfg(feature = "mcap")]
fn mcap_names(log: &McapLog, sel: &Selection<'_>) -> Result<(Vec<String>, Vec<String>)> {
    let signal = |s: &String| -> Result<String> {
        Ok(Signal::parse(s, sel.topic)
            .map_err(|e| in_file(&log.path, e))?
            .name())
    };
    let inputs: Vec<String> = sel.inputs.iter().map(signal).collect::<Result<_>>()?;
    let outputs: Vec<String> = sel.outputs.iter().map(signal).collect::<Result<_>>()?;
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
                .filter(|t| t.readable() && !t.latent)
                .collect();
            match json.as_slice() {
                [one] => one.topic.clone(),
                _ => {
                    return Err(MsgpError::File {
                        path: log.path.clone(),
                        message: format!(
                            "choose the signals with --input/--output TOPIC:FIELD or a --topic \
                             (topics: {})",
                            log.topic_list()
                        ),
                    });
                }
            }
        }
    };
    let fields = log.numeric_fields(&topic)?;
    let candidates: Vec<String> = fields
        .iter()
        .filter(|f| !SKIP.iter().any(|s| f.eq_ignore_ascii_case(s)) && !f.starts_with("header."))
        .map(|f| format!("{topic}:{f}"))
        .collect();
    default_columns(&candidates, &inputs, &outputs).map_err(|e| match e {
        MsgpError::Data(message) => MsgpError::File {
            path: log.path.clone(),
            message: format!("topic {topic}: {message}"),
        },
        other => other,
    })
}

/// The selected signals of an MCAP log as a table; resolves the names on the first call.
fn mcap_table(
    path: &Path,
    bytes: &[u8],
    sel: &Selection<'_>,
    names: &mut Option<(Vec<String>, Vec<String>)>,
) -> Result<Table> {
    #[cfg(feature = "mcap")]
    {
        let log = McapLog::parse(bytes, path)?;
        let (inputs, outputs) = match names {
            Some(n) => n.clone(),
            None => mcap_names(&log, sel)?,
        };
        let signals: Vec<Signal> = inputs
            .iter()
            .chain(&outputs)
            .map(|s| Signal::parse(s, sel.topic).map_err(|e| in_file(path, e)))
            .collect::<Result<_>>()?;
        let base = signals[inputs.len()].topic.clone();
        let table = log.table(&signals, &base, sel.time)?;
        *names = Some((inputs, outputs));
        Ok(table)
    }
    #[cfg(not(feature = "mcap"))]
    {
        let _ = (bytes, sel, names);
        Err(MsgpError::File {
            path: path.to_path_buf(),
            message: "this build of msgp-core reads no MCAP (its `mcap` feature is off)".into(),
        })
    }
}

/// Reads one file into a table with the selected columns; resolves the names on the first call.
fn load_file(
    path: &Path,
    sel: &Selection<'_>,
    names: &mut Option<(Vec<String>, Vec<String>)>,
    warnings: &mut Vec<String>,
) -> Result<Table> {
    let bytes = std::fs::read(path).map_err(|e| MsgpError::File {
        path: path.to_path_buf(),
        message: format!("cannot read: {e}"),
    })?;
    if is_mcap(path, &bytes) {
        mcap_table(path, &bytes, sel, names)
    } else {
        let mut table = Table::parse_csv(&bytes, path)?;
        if sel.sort_time {
            warnings.extend(table.sort_by_time());
        }
        table.check_time_order()?;
        if names.is_none() {
            *names = Some(csv_names(&table, sel)?);
        }
        Ok(table)
    }
}

impl Dataset {
    /// Loads every file; the column names chosen on the first file apply to all of them.
    pub fn load(files: &[PathBuf], sel: &Selection<'_>) -> Result<Self> {
        let mut names = None;
        let mut parts = Vec::new();
        let mut warnings = Vec::new();
        for path in files {
            let table = load_file(path, sel, &mut names, &mut warnings)?;
            warnings.extend(table.irregular_steps(IRREGULAR_STEP_TOLERANCE));
            let Some((inputs, outputs)) = &names else {
                return Err(MsgpError::Data("no columns selected".into()));
            };
            for name in inputs {
                if outputs.contains(name) {
                    return Err(MsgpError::Data(format!(
                        "column `{name}` is both an input and an output"
                    )));
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
            return Err(MsgpError::Data("no data files given (--data FILE)".into()));
        };
        Ok(Self {
            inputs,
            outputs,
            parts,
            warnings,
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
pub fn check_lengths(parts: &[Part], warmup: usize, what: &str) -> Result<()> {
    for p in parts {
        if p.traj.len() <= warmup {
            return Err(MsgpError::Data(format!(
                "{}: the {what} part has {} samples; the history needs more than {warmup} \
                 (shorten --history or change the split)",
                p.label(),
                p.traj.len()
            )));
        }
    }
    Ok(())
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

    #[test]
    fn a_split_keeps_sources_and_drops_empty_parts() {
        let traj = Trajectory::siso(&[0.0; 10], &[1.0; 10]).expect("finite");
        let part = Part {
            source: PathBuf::from("a.csv"),
            episode: Some(2.0),
            times: (0..10).map(f64::from).collect(),
            traj,
        };
        let (train, test) = split(std::slice::from_ref(&part), Split::Fraction(0.3));
        assert_eq!((train[0].traj.len(), test[0].traj.len()), (3, 7));
        assert_eq!(test[0].times[0], 3.0);
        assert_eq!(test[0].label(), "a.csv (episode 2)");
        let (train, test) = split(&[part], Split::Count(20));
        assert_eq!((train.len(), test.len()), (1, 0));
        assert!(check_lengths(&train, 10, "training").is_err());
        assert!(check_lengths(&train, 9, "training").is_ok());
    }
}
