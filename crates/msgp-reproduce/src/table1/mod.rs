//! The paper's Table 1: free-simulation test RMSE of GP-NARX, PILCO's GP-NARX and MSGP on five
//! synthetic and five real benchmarks, over several seeds, beside the paper's numbers, with
//! MSGP trained on both likelihoods, the baselines simulated both by moment matching and by
//! mean feedback, NLL and 2σ coverage.
//!
//! The reproduction is split so that any front end can spread it over workers and still write
//! the same table: a [`Plan`] (validated settings) lists its independent [`Unit`]s (one
//! benchmark × seed × column each), [`fit_unit`] computes one [`Cell`] (a seeded fit and its
//! two test simulations; the same numbers on any machine and thread count), and
//! [`assemble`] + [`render`] turn the cells into rows and the markdown section. `msgp
//! reproduce table1` runs the units one after another; the Python `msgp.sweep.table1` runs them
//! in processes or as Ray tasks.

//!
//! Its modules: this one holds the table's data (the paper's figures, columns, plans, units,
//! cells); `fit` fits a unit; `report` assembles the rows and writes the markdown.

mod fit;
mod report;
#[cfg(test)]
mod tests;

use std::path::{Path, PathBuf};

use msgp_core::MsgpError;
use msgp_core::data::real::RealSeries;
use msgp_core::fit::FitOptimizer;
use msgp_core::fit::history::HistoryChoice;
use msgp_core::loss::Likelihood;
use msgp_core::model::{Method, Metrics};
use serde::{Deserialize, Serialize};

use crate::error::{ReproduceError, Result};
pub use crate::results::Provenance;
pub use fit::{benchmark, fit_unit, fit_unit_simulated};
pub use report::{Row, assemble, mean_std, render, rmse_table, rows_json, targets};

/// One benchmark of Table 1 and the paper's RMSE in each of its columns.
#[derive(Clone, Copy, Debug)]
pub struct Task {
    /// Short name (`synthetic4`, `dryer`, …), as `--only` takes it.
    pub key: &'static str,
    /// Row label of the table.
    pub label: &'static str,
    /// The paper's RMSE in the order of [`PAPER_COLUMNS`].
    pub paper: [f64; 6],
    /// Where the data come from.
    pub source: Source,
}

impl Task {
    /// The lowest RMSE of the paper's six columns and the column's name.
    pub fn paper_best(&self) -> (f64, &'static str) {
        let k = (0..PAPER_COLUMNS.len())
            .min_by(|&i, &j| self.paper[i].total_cmp(&self.paper[j]))
            .unwrap_or(PAPER_MSGP);
        (self.paper[k], PAPER_COLUMNS[k])
    }
}

/// Where a benchmark's data come from.
#[derive(Clone, Copy, Debug)]
pub enum Source {
    /// Synthetic system `k` of Table 2, generated with the unit's seed.
    Synthetic(u8),
    /// A real series, read from the data folder.
    Real(RealSeries),
}

/// The paper's six columns of Table 1, in its order; [`Task::paper`] holds a row's figures.
/// NIGP, REVARB 1 and REVARB 2 are not fitted here: the table shows the paper's figures and
/// the targets count against them.
pub const PAPER_COLUMNS: [&str; 6] = [
    "GP-NARX",
    "PILCO GP-NARX",
    "NIGP",
    "REVARB 1",
    "REVARB 2",
    "MSGP",
];

/// The paper's columns that no method here fits (indices into [`PAPER_COLUMNS`]).
const PAPER_ONLY: [usize; 3] = [2, 3, 4];

/// The paper's MSGP column (an index into [`PAPER_COLUMNS`]).
const PAPER_MSGP: usize = 5;

/// The methods Table 1 compares.
pub const METHODS: [Method; 3] = [Method::GpNarx, Method::PilcoNarx, Method::Msgp];

/// The ten benchmarks, in the paper's order.
pub fn tasks() -> Vec<Task> {
    let syn = |k: u8, key, label, paper| Task {
        key,
        label,
        paper,
        source: Source::Synthetic(k),
    };
    let real = |s, key, label, paper| Task {
        key,
        label,
        paper,
        source: Source::Real(s),
    };
    vec![
        syn(
            1,
            "synthetic1",
            "Synthetic system 1",
            [0.2265, 0.3511, 0.2453, 0.2129, 0.1717, 0.3805],
        ),
        syn(
            2,
            "synthetic2",
            "Synthetic system 2",
            [0.3535, 0.3467, 0.4100, 0.3395, 0.3726, 0.3424],
        ),
        syn(
            3,
            "synthetic3",
            "Synthetic system 3",
            [0.1572, 0.1487, 0.1950, 0.3657, 0.1695, 0.1341],
        ),
        syn(
            4,
            "synthetic4",
            "Synthetic system 4",
            [0.5711, 0.6016, 0.7814, 0.6978, 0.4554, 0.3287],
        ),
        syn(
            5,
            "synthetic5",
            "Synthetic system 5",
            [0.0164, 0.0150, 0.0101, 0.1193, 0.0035, 0.0143],
        ),
        real(
            RealSeries::Actuator,
            "actuator",
            "Actuator",
            [0.6376, 1.3767, 0.6483, 0.4328, 0.5522, 0.7124],
        ),
        real(
            RealSeries::Ballbeam,
            "ballbeam",
            "Balancing (ballbeam)",
            [0.0773, 0.0881, 0.0776, 0.1360, 0.0732, 0.0599],
        ),
        real(
            RealSeries::Drives,
            "drives",
            "Drives",
            [0.6888, 0.7024, 0.7525, 0.7463, 0.5620, 0.4217],
        ),
        real(
            RealSeries::Furnace,
            "furnace",
            "Furnace",
            [1.1996, 1.2012, 1.1949, 1.3434, 1.9569, 1.2013],
        ),
        real(
            RealSeries::Dryer,
            "dryer",
            "Dryer",
            [0.2856, 0.2956, 0.2802, 0.8764, 0.1286, 0.1523],
        ),
    ]
}

/// A column of the table: a method and, for MSGP, its likelihood.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Column {
    /// GP-NARX, one-step marginal likelihood.
    GpNarx,
    /// PILCO's GP-NARX (one-step, with its hyperparameter penalties).
    PilcoNarx,
    /// MSGP on the paper's free-run likelihood.
    Msgp,
    /// MSGP on the filter likelihood.
    MsgpFilter,
}

/// Every column, in table order.
pub const COLUMNS: [Column; 4] = [
    Column::GpNarx,
    Column::PilcoNarx,
    Column::Msgp,
    Column::MsgpFilter,
];

impl Column {
    /// The method fitted.
    pub fn method(self) -> Method {
        match self {
            Column::GpNarx => Method::GpNarx,
            Column::PilcoNarx => Method::PilcoNarx,
            Column::Msgp | Column::MsgpFilter => Method::Msgp,
        }
    }

    /// The paper's column of Table 1, if it has one.
    pub fn paper(self) -> Option<usize> {
        match self {
            Column::GpNarx => Some(0),
            Column::PilcoNarx => Some(1),
            Column::Msgp => Some(PAPER_MSGP),
            Column::MsgpFilter => None,
        }
    }

    /// Short name (`msgp-filter`, …).
    pub fn name(self) -> &'static str {
        match self {
            Column::GpNarx => "gp-narx",
            Column::PilcoNarx => "pilco-narx",
            Column::Msgp => "msgp",
            Column::MsgpFilter => "msgp-filter",
        }
    }

    /// Column heading.
    pub fn label(self) -> &'static str {
        match self {
            Column::GpNarx => "GP-NARX",
            Column::PilcoNarx => "PILCO GP-NARX",
            Column::Msgp => "MSGP",
            Column::MsgpFilter => "MSGP (filter)",
        }
    }

    /// The rollout the column is judged by: the baselines' mean feedback is reported beside
    /// their moment matching, MSGP is the paper's moment matching.
    pub fn is_baseline(self) -> bool {
        matches!(self, Column::GpNarx | Column::PilcoNarx)
    }

    /// Position in [`COLUMNS`].
    pub fn index(self) -> usize {
        COLUMNS.iter().position(|c| *c == self).unwrap_or(0)
    }
}

/// One fitted cell: a column on one benchmark with one seed.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Cell {
    /// Test metrics of the moment-matching and the mean-feedback simulation
    /// ([`msgp_core::model::Rollout::REPORTED`] order).
    pub metrics: [Metrics; 2],
    /// Training wall time \[s\].
    pub train_seconds: f64,
    /// Solver iterations run.
    pub iterations_run: usize,
    /// The iteration whose parameters were kept: the head's, chosen on the validation tail.
    pub best_iteration: usize,
    /// MSGP: the kept iterate of the final training on all the data, when it ran
    /// ([`msgp_core::fit::MsgpSettings::full_data_iterations`]).
    #[serde(default)]
    pub full_data_iteration: Option<usize>,
    /// MSGP: the standard deviation its output-variance calibration adds (original units;
    /// [`msgp_core::fit::calibration`]), when it has one.
    #[serde(default)]
    pub added_std: Option<f64>,
    /// MSGP: the kept model is a fallback head's ([`msgp_core::fit::MsgpSettings::blow_up_fallback`]),
    /// named by [`msgp_core::fit::RecipeOutcome::fallback_label`]: `spread` or `linear`.
    #[serde(default)]
    pub fallback: Option<String>,
    /// MSGP: the recipe the validation tail preferred whose model diverged over the training
    /// inputs and was set aside for this one's ([`msgp_core::fit::FitReport::set_aside`]), named
    /// by [`msgp_core::fit::RecipeOutcome::fallback_label`]'s word for its mean or start.
    #[serde(default)]
    pub set_aside: Option<String>,
    /// Why the model diverges: the fit's check on its training inputs, else the moment-matching
    /// simulation of the test part held against the test outputs (`msgp eval`'s test);
    /// `None` when neither fires.
    #[serde(default)]
    pub diverged: Option<String>,
    /// With [`TableHistory::Auto`], the history chosen from the training part for this fit.
    #[serde(default)]
    pub chosen_history: Option<HistoryChoice>,
}

/// Index of the moment-matching simulation's metrics in a [`Cell`] ([`msgp_core::model::Rollout::REPORTED`] order).
const MM: usize = 0;
/// … and of the mean-feedback simulation's.
const MEAN: usize = 1;

/// The validated settings of one reproduction.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Plan {
    /// Seeds of data generation (synthetic systems) and of the fits.
    pub seeds: Vec<u64>,
    /// Benchmark keys, in table order.
    pub benchmarks: Vec<String>,
    /// Columns, in table order.
    pub columns: Vec<Column>,
    /// Pseudo-inputs of every fit.
    pub inducing: usize,
    /// Most solver iterations on the MSGP loss (per recipe); `None`: the fit default.
    pub iters: Option<usize>,
    /// Solver of the MSGP loss.
    pub optimizer: FitOptimizer,
    /// Folder of the real series.
    pub data_dir: PathBuf,
    /// Where each fit's history comes from.
    #[serde(default)]
    pub history: TableHistory,
}

/// Where the fits of a Table 1 reproduction take their NARX history `(l_y, l_u)` from.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum TableHistory {
    /// The paper's Table 3 (the paper's own setting).
    #[default]
    Paper,
    /// Chosen on each fit's training part alone, as `msgp fit --history auto` chooses it
    /// ([`msgp_core::fit::history::choose_history`] with [`msgp_core::fit::history::HistorySearch::default`], the fit itself the judge): a
    /// user's fit on a log whose history nobody has told them.
    Auto,
}

impl Plan {
    /// Checks and orders the settings: `only` (benchmark keys; empty: all ten), `methods`
    /// (empty: all three), `likelihoods` of the MSGP columns (empty: both), at least one seed.
    pub fn new(
        seeds: &[u64],
        only: &[String],
        (methods, likelihoods): (&[Method], &[Likelihood]),
        inducing: usize,
        iters: Option<usize>,
        optimizer: FitOptimizer,
        data_dir: &Path,
    ) -> Result<Self> {
        let invalid =
            |name, reason: String| ReproduceError::from(MsgpError::InvalidSetting { name, reason });
        if seeds.is_empty() {
            return Err(invalid("seeds", "give at least one seed".into()));
        }
        if inducing == 0 {
            return Err(invalid("inducing", "must be at least 1".into()));
        }
        if iters == Some(0) {
            return Err(invalid("iters", "must be at least 1".into()));
        }
        let all = tasks();
        if let Some(name) = only
            .iter()
            .find(|n| !all.iter().any(|t| t.key == n.as_str()))
        {
            return Err(invalid(
                "only",
                format!(
                    "unknown benchmark `{name}` (choose from {})",
                    all.iter().map(|t| t.key).collect::<Vec<_>>().join(", ")
                ),
            ));
        }
        if let Some(other) = methods.iter().find(|m| !METHODS.contains(m)) {
            return Err(invalid(
                "methods",
                format!(
                    "{}: table 1 compares the paper's methods (msgp, gp-narx, pilco-narx)",
                    other.name()
                ),
            ));
        }
        let likelihoods = if likelihoods.is_empty() {
            &[Likelihood::FreeRun, Likelihood::Filter][..]
        } else {
            likelihoods
        };
        let columns = COLUMNS
            .into_iter()
            .filter(|c| methods.is_empty() || methods.contains(&c.method()))
            .filter(|c| match c {
                Column::Msgp => likelihoods.contains(&Likelihood::FreeRun),
                Column::MsgpFilter => likelihoods.contains(&Likelihood::Filter),
                _ => true,
            })
            .collect();
        Ok(Self {
            seeds: seeds.to_vec(),
            benchmarks: all
                .iter()
                .filter(|t| only.is_empty() || only.iter().any(|n| n == t.key))
                .map(|t| t.key.to_string())
                .collect(),
            columns,
            inducing,
            iters,
            optimizer,
            data_dir: data_dir.to_path_buf(),
            history: TableHistory::Paper,
        })
    }

    /// The plan with its fits' histories from `history`.
    pub fn with_history(self, history: TableHistory) -> Self {
        Self { history, ..self }
    }

    /// The independent units, in the order a serial run does them (benchmark, seed, column).
    pub fn units(&self) -> Vec<Unit> {
        let mut out = Vec::new();
        for b in &self.benchmarks {
            for &seed in &self.seeds {
                for &column in &self.columns {
                    out.push(Unit {
                        benchmark: b.clone(),
                        seed,
                        column,
                    });
                }
            }
        }
        out
    }

    /// The `RESULTS.md` section this plan writes: `table1`, `table1-lbfgs` for L-BFGS, each
    /// with `-auto-history` for histories chosen from the data.
    pub fn section(&self) -> &'static str {
        match (self.optimizer, self.history) {
            (FitOptimizer::Adam, TableHistory::Paper) => "table1",
            (FitOptimizer::Lbfgs, TableHistory::Paper) => "table1-lbfgs",
            (FitOptimizer::Adam, TableHistory::Auto) => "table1-auto-history",
            (FitOptimizer::Lbfgs, TableHistory::Auto) => "table1-lbfgs-auto-history",
        }
    }
}

/// One independent piece of work: a column fitted on one benchmark with one seed.
#[derive(Clone, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Unit {
    /// Benchmark key.
    pub benchmark: String,
    /// Seed of the data (synthetic) and of the fit.
    pub seed: u64,
    /// What is fitted.
    pub column: Column,
}

impl Unit {
    /// `msgp on dryer (seed 0)`.
    pub fn describe(&self) -> String {
        format!(
            "{} on {} (seed {})",
            self.column.name(),
            self.benchmark,
            self.seed
        )
    }
}

/// The benchmark `key`.
pub fn task(key: &str) -> Result<Task> {
    tasks().into_iter().find(|t| t.key == key).ok_or_else(|| {
        MsgpError::InvalidSetting {
            name: "benchmark",
            reason: format!("unknown benchmark `{key}`"),
        }
        .into()
    })
}
