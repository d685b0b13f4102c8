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

use std::fmt::Write as _;
use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

use serde::{Deserialize, Serialize};

use msgp_core::MsgpError;
use msgp_core::data::real::RealSeries;
use msgp_core::data::{Benchmark, NoiseScale, SyntheticSystem, Trajectory};
use msgp_core::fit::history::{
    HistoryChoice, HistoryEvent, HistorySearch, choose_history_observed,
};
use msgp_core::fit::{
    FitOptimizer, FitOptions, FitProgress, FitSettings, MsgpSettings, OutputRange, fit,
};
use msgp_core::loss::Likelihood;
use msgp_core::model::{Method, Metrics, Rollout, Simulation, score};
use msgp_core::numeric::parallel::Threads;

use crate::error::{ReproduceError, Result};
pub use crate::results::Provenance;

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
    /// ([`Rollout::REPORTED`] order).
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

/// One benchmark's results: per column, one cell per seed.
#[derive(Debug)]
pub struct Row {
    /// The benchmark.
    pub task: Task,
    /// The first seed's data (sizes and history for the table).
    pub bench: Benchmark,
    /// Per column of [`COLUMNS`], the cells in seed order.
    pub cells: Vec<Vec<Cell>>,
}

/// Mean and sample standard deviation.
pub fn mean_std(v: &[f64]) -> Option<(f64, f64)> {
    if v.is_empty() {
        return None;
    }
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let var = if v.len() > 1 {
        v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)
    } else {
        0.0
    };
    Some((mean, var.sqrt()))
}

/// `mean ± std` of `f` over a column's cells (just the value for one seed; `—` for none).
fn stat(cells: &[Cell], digits: usize, f: impl Fn(&Cell) -> f64) -> String {
    let v: Vec<f64> = cells.iter().map(f).collect();
    match mean_std(&v) {
        None => "—".into(),
        Some((m, _)) if v.len() == 1 => format!("{m:.digits$}"),
        Some((m, sd)) => format!("{m:.digits$} ± {sd:.digits$}"),
    }
}

fn mean_of(cells: &[Cell], f: impl Fn(&Cell) -> f64) -> Option<f64> {
    mean_std(&cells.iter().map(f).collect::<Vec<_>>()).map(|(m, _)| m)
}

const MM: usize = 0;
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
    /// ([`msgp_core::fit::history::choose_history`] with [`HistorySearch::default`], the fit itself the judge): a
    /// user's fit on a log whose history nobody has told them.
    Auto,
}

impl Plan {
    /// Checks and orders the settings: `only` (benchmark keys; empty: all ten), `methods`
    /// (empty: all three), `likelihoods` of the MSGP columns (empty: both), at least one seed.
    pub fn new(
        seeds: &[u64],
        only: &[String],
        methods: &[Method],
        likelihoods: &[Likelihood],
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

/// The data of `task` for `seed` (synthetic: generated; real: read from `data_dir`).
pub fn benchmark(task: &Task, seed: u64, data_dir: &Path) -> Result<Benchmark> {
    match task.source {
        Source::Synthetic(k) => Ok(SyntheticSystem::new(k)?.generate(seed, NoiseScale::StdDev)?),
        Source::Real(s) => Ok(s.load(data_dir).map_err(|e| match e {
            MsgpError::File { path, message } => MsgpError::File {
                path,
                message: format!(
                    "{message} (the real series {} of Table 1; set the data folder or \
                     MSGP_DATA_DIR)",
                    s.name()
                ),
            },
            other => other,
        })?),
    }
}

/// Fits `unit` of `plan` and simulates the test part both ways; `progress` sees the fit.
pub fn fit_unit(
    plan: &Plan,
    unit: &Unit,
    threads: Threads,
    progress: &mut dyn FnMut(&FitProgress),
) -> Result<Cell> {
    Ok(fit_unit_simulated(plan, unit, threads, progress)?.0)
}

/// [`fit_unit`], with the test part and its moment-matching simulation, which the cell's
/// first metrics score (`None` where that simulation failed numerically), for a plot.
pub fn fit_unit_simulated(
    plan: &Plan,
    unit: &Unit,
    threads: Threads,
    progress: &mut dyn FnMut(&FitProgress),
) -> Result<(Cell, Trajectory, Option<Simulation>)> {
    let task = task(&unit.benchmark)?;
    let bench = benchmark(&task, unit.seed, &plan.data_dir)?;
    let method = unit.column.method();
    let chosen = match plan.history {
        TableHistory::Paper => None,
        TableHistory::Auto => Some(search_history(plan, unit, &bench, threads, progress)?),
    };
    let (ly, lu) = chosen
        .as_ref()
        .map_or((bench.ly, bench.lu), |c| (c.ly, c.lu));
    let mut settings = FitSettings {
        ly,
        lu,
        seed: unit.seed,
        threads,
        ..FitSettings::new(method)
    }
    .with_inducing(plan.inducing);
    if let Some(msgp) = settings.msgp_mut() {
        msgp.optimizer = plan.optimizer;
        if unit.column == Column::MsgpFilter {
            msgp.likelihood = Likelihood::Filter;
        }
    }
    if let (Some(n), Method::Msgp) = (plan.iters, method) {
        settings = settings.with_solver_iterations(n);
    }
    let (model, report) = fit(std::slice::from_ref(&bench.train), &settings, progress)?;
    // the moment-matching simulation is scored and held against the test outputs; a simulation
    // that fails numerically is a diverged cell (scored +∞), not the end of the table
    let failed = |e: MsgpError| match e {
        MsgpError::NonFinite(_) | MsgpError::NotPositiveDefinite { .. } => Ok(Metrics {
            rmse: f64::INFINITY,
            nll: f64::INFINITY,
            coverage_2sigma: 0.0,
            steps: bench.test.len().saturating_sub(model.spec.warmup()),
        }),
        e => Err(e),
    };
    let (mm, mut diverged, simulated) = match model.simulate_as(&bench.test, Rollout::REPORTED[MM])
    {
        Ok(sim) => (
            score(&sim, &bench.test)?,
            OutputRange::of(&[&bench.test], model.spec.dy).divergence(&sim, "the test part"),
            Some(sim),
        ),
        Err(e) => {
            let why = format!("the test part's simulation fails: {e}");
            (failed(e)?, Some(why), None)
        }
    };
    let mean = model
        .evaluate_as(&bench.test, Rollout::REPORTED[MEAN])
        .or_else(failed)?;
    if report.diverged.is_some() {
        diverged = report.diverged.clone();
    }
    let cell = Cell {
        metrics: [mm, mean],
        train_seconds: report.train_seconds,
        iterations_run: report.iterations_run,
        best_iteration: report.best_iteration,
        full_data_iteration: report.full_data_iteration,
        added_std: report
            .calibration
            .as_ref()
            .and_then(|c| c.added_std.first().copied()),
        fallback: report.fallback().map(|r| r.fallback_label().to_string()),
        set_aside: report.set_aside().map(|r| r.fallback_label().to_string()),
        diverged,
        chosen_history: chosen,
    };
    Ok((cell, bench.test, simulated))
}

/// The history of `unit`'s fit chosen on `bench`'s training part alone, as `msgp fit
/// --history auto` chooses it: the judge is the unit's own fit (its method, likelihood,
/// pseudo-inputs, iterations, solver and seed), `progress` sees each candidate's fit.
fn search_history(
    plan: &Plan,
    unit: &Unit,
    bench: &Benchmark,
    threads: Threads,
    progress: &mut dyn FnMut(&FitProgress),
) -> Result<HistoryChoice> {
    let method = unit.column.method();
    let judge = FitOptions {
        inducing: Some(plan.inducing),
        iterations: plan.iters.filter(|_| method == Method::Msgp),
        seed: unit.seed,
        optimizer: plan.optimizer,
        likelihood: match unit.column {
            Column::MsgpFilter => Likelihood::Filter,
            _ => Likelihood::FreeRun,
        },
        threads,
        ..FitOptions::new(method, bench.ly, bench.lu)
    };
    Ok(choose_history_observed(
        std::slice::from_ref(&bench.train),
        &HistorySearch::default(),
        &judge,
        &mut |event| {
            if let HistoryEvent::Fit(p) = event {
                progress(p);
            }
            ControlFlow::Continue(())
        },
    )?)
}

/// The rows of the table from every unit's cell (any order; each unit exactly once).
pub fn assemble(plan: &Plan, results: Vec<(Unit, Cell)>) -> Result<Vec<Row>> {
    let units = plan.units();
    let mut slots: Vec<Option<Cell>> = units.iter().map(|_| None).collect();
    for (unit, cell) in results {
        let Some(k) = units.iter().position(|u| *u == unit) else {
            return Err(MsgpError::Data(format!(
                "a result for {} is not part of this plan",
                unit.describe()
            ))
            .into());
        };
        if slots[k].replace(cell).is_some() {
            return Err(MsgpError::Data(format!("two results for {}", unit.describe())).into());
        }
    }
    let mut cells = units.into_iter().zip(slots);
    let mut rows = Vec::with_capacity(plan.benchmarks.len());
    for key in &plan.benchmarks {
        let task = task(key)?;
        let mut by_column: Vec<Vec<Cell>> = COLUMNS.iter().map(|_| Vec::new()).collect();
        for _ in 0..plan.seeds.len() * plan.columns.len() {
            match cells.next() {
                Some((unit, Some(cell))) => by_column[unit.column.index()].push(cell),
                Some((unit, None)) => {
                    return Err(
                        MsgpError::Data(format!("no result for {}", unit.describe())).into(),
                    );
                }
                None => return Err(MsgpError::Data("fewer units than the plan".into()).into()),
            }
        }
        let bench = benchmark(&task, plan.seeds[0], &plan.data_dir)?;
        rows.push(Row {
            task,
            bench,
            cells: by_column,
        });
    }
    Ok(rows)
}

/// The rows as JSON records, one per cell and rollout (what `--json` prints).
pub fn rows_json(plan: &Plan, rows: &[Row]) -> Vec<serde_json::Value> {
    let mut list = Vec::new();
    for row in rows {
        for &column in &plan.columns {
            for (cell, seed) in row.cells[column.index()].iter().zip(&plan.seeds) {
                for (k, rollout) in Rollout::REPORTED.into_iter().enumerate() {
                    let m = &cell.metrics[k];
                    list.push(serde_json::json!({
                        "benchmark": row.task.key,
                        "method": column.method().name(),
                        "column": column.name(),
                        "seed": seed,
                        "rollout": rollout.name(),
                        "rmse": m.rmse,
                        "paper_rmse": column.paper().map(|i| row.task.paper[i]),
                        "nll": m.nll,
                        "coverage_2sigma": m.coverage_2sigma,
                        "train_seconds": cell.train_seconds,
                        "diverged": cell.diverged,
                        "history": cell.chosen_history.as_ref()
                            .map_or([row.bench.ly, row.bench.lu], |c| [c.ly, c.lu]),
                        "history_choice": cell.chosen_history,
                        "n_train": row.bench.train.len(),
                        "n_test": row.bench.test.len(),
                    }));
                }
            }
        }
    }
    list
}

/// The RMSE table: ours (mean ± std over the seeds) beside the paper's; the baselines with
/// moment-matching and mean-feedback simulations.
pub fn rmse_table(rows: &[Row], columns: &[Column]) -> String {
    let mut head = String::from("| Task ");
    let mut rule = String::from("|---");
    for c in columns {
        if c.paper().is_some() {
            let _ = write!(head, "| {} (paper) ", c.label());
            rule.push_str("|---:");
        }
        if c.is_baseline() {
            let _ = write!(head, "| {0} (ours, MM) | {0} (ours, mean) ", c.label());
            rule.push_str("|---:|---:");
        } else {
            let _ = write!(head, "| {} (ours) ", c.label());
            rule.push_str("|---:");
        }
    }
    for k in PAPER_ONLY {
        let _ = write!(head, "| {} (paper) ", PAPER_COLUMNS[k]);
        rule.push_str("|---:");
    }
    let mut s = format!("{head}|\n{rule}|\n");
    for row in rows {
        let _ = write!(s, "| {} ", row.task.label);
        for c in columns {
            let cells = &row.cells[c.index()];
            if let Some(i) = c.paper() {
                let _ = write!(s, "| {:.4} ", row.task.paper[i]);
            }
            let _ = write!(s, "| {} ", stat(cells, 4, |x| x.metrics[MM].rmse));
            if c.is_baseline() {
                let _ = write!(s, "| {} ", stat(cells, 4, |x| x.metrics[MEAN].rmse));
            }
        }
        for k in PAPER_ONLY {
            let _ = write!(s, "| {:.4} ", row.task.paper[k]);
        }
        s.push_str("|\n");
    }
    s
}

/// The targets, counted over the rows (seed means).
pub fn targets(rows: &[Row], columns: &[Column], seeds: &[u64]) -> Vec<String> {
    let mut lines = Vec::new();
    let rmse =
        |row: &Row, c: Column, k: usize| mean_of(&row.cells[c.index()], |x| x.metrics[k].rmse);
    for c in [Column::Msgp, Column::MsgpFilter] {
        if !columns.contains(&c) {
            continue;
        }
        let (mut at_paper, mut at_best, mut nll_better, mut n) = (0, 0, 0, 0);
        let mut behind = Vec::new();
        for row in rows {
            let Some(r) = rmse(row, c, MM) else { continue };
            n += 1;
            let paper_msgp = row.task.paper[PAPER_MSGP];
            let (best, best_column) = row.task.paper_best();
            at_paper += usize::from(r <= paper_msgp);
            at_best += usize::from(r <= best);
            if r > best {
                behind.push(format!(
                    "{} {r:.4} vs {best_column} {best:.4}",
                    row.task.label
                ));
            }
            let nll = mean_of(&row.cells[c.index()], |x| x.metrics[MM].nll);
            let base = mean_of(&row.cells[Column::GpNarx.index()], |x| x.metrics[MM].nll);
            if let (Some(a), Some(b)) = (nll, base) {
                nll_better += usize::from(a < b);
            }
        }
        lines.push(format!(
            "- {}: seed-mean RMSE at or below the paper's MSGP on {at_paper}/{n} rows, at or \
             below the best of the paper's six columns on {at_best}/{n}; NLL below GP-NARX's (MM) on \
             {nll_better}/{n}{}",
            c.label(),
            if behind.is_empty() {
                String::new()
            } else {
                format!(" (behind the best on {})", behind.join(", "))
            }
        ));
    }
    for c in [Column::GpNarx, Column::PilcoNarx] {
        if !columns.contains(&c) {
            continue;
        }
        let (mut within, mut n) = (0, 0);
        for row in rows {
            let (Some(r), Some(i)) = (rmse(row, c, MEAN), c.paper()) else {
                continue;
            };
            n += 1;
            within += usize::from((r - row.task.paper[i]).abs() <= 0.1 * row.task.paper[i]);
        }
        lines.push(format!(
            "- {} (mean feedback): within 10 % of the paper's column on {within}/{n} rows",
            c.label()
        ));
    }
    lines.push(divergences(rows, columns, seeds));
    lines
}

/// The line naming every diverging model ([`Cell::diverged`]) by column, row and seed (`seeds`:
/// the cells' seeds, in order).
fn divergences(rows: &[Row], columns: &[Column], seeds: &[u64]) -> String {
    let mut found = Vec::new();
    for &c in columns {
        for row in rows {
            let diverging: Vec<String> = row.cells[c.index()]
                .iter()
                .zip(seeds)
                .filter(|(x, _)| x.diverged.is_some())
                .map(|(_, seed)| seed.to_string())
                .collect();
            if diverging.is_empty() {
                continue;
            }
            found.push(format!(
                "{} on {} (seed {})",
                c.label(),
                row.task.label,
                diverging.join(", ")
            ));
        }
    }
    let list = match found.is_empty() {
        true => "none".to_string(),
        false => found.join("; "),
    };
    format!(
        "- Diverging models (the fit's check on its training inputs, or the test part's \
         simulation leaving the test outputs by 5 ranges, `msgp eval`'s check): {list}"
    )
}

/// The markdown section for `rows` (see [`Plan::section`]).
pub fn render(plan: &Plan, rows: &[Row], provenance: &Provenance) -> String {
    let columns = &plan.columns[..];
    let (title, solver) = match plan.optimizer {
        FitOptimizer::Adam => ("# Table 1, reproduced", "Adam"),
        FitOptimizer::Lbfgs => (
            "# Table 1, reproduced with MSGP fitted by L-BFGS",
            "L-BFGS (`msgp_core::fit::FIT_LBFGS`, validation after every iteration)",
        ),
    };
    let seeds: Vec<String> = plan.seeds.iter().map(|s| s.to_string()).collect();
    let mut s = String::from(title);
    s.push_str(match plan.history {
        TableHistory::Paper => "\n\n",
        TableHistory::Auto => ", histories chosen from the data\n\n",
    });
    let _ = writeln!(
        s,
        "Free-simulation RMSE on the test part (original units) of the paper's Table 1 \
         (Doerr et al., CoRL 2017), ours beside the paper's, as mean ± sample standard \
         deviation over seeds {seeds}. Synthetic systems: generated as in Table 2 with each \
         seed, training noise `N(0, s)` read as a standard deviation (`docs/design.md`), \
         noise-free test outputs. Real series: the paper's Table 3 splits{lengths} \
         (first samples train, the rest test; only the fits' seeds vary). Every method: m = {m} \
         pseudo-inputs; GP-NARX: a sparse GP by the variational bound (hyperparameters and \
         pseudo-inputs jointly); PILCO GP-NARX: the full GP's penalised marginal likelihood, \
         then projected onto k-means pseudo-inputs; MSGP: the default protocol of \
         `msgp_core::fit::MsgpSettings` (two recipes trained on the first 80 % of the training \
         data, with at most {iters} {solver} iterations each and early stopping on the last \
         20 %, which also chooses the recipe; the chosen recipe then trains again from its start \
         on all the training data for {full} iterations). MM: \
         moment-matching simulation (the paper's method for every column and our default), \
         whose variances keep the function's uncertainty correlated over time (the same means; \
         `msgp_core::rollout::function_uncertainty`); \
         mean: the predicted means fed back, no uncertainty propagated (`msgp eval --rollout \
         mean`).\n",
        seeds = seeds.join(", "),
        lengths = match plan.history {
            TableHistory::Paper => " and history lengths",
            TableHistory::Auto => "",
        },
        m = plan.inducing,
        iters = plan.iters.unwrap_or(MsgpSettings::default().iterations),
        full = plan
            .iters
            .unwrap_or(MsgpSettings::default().iterations)
            .min(msgp_core::fit::DEFAULT_FULL_DATA_ITERATIONS),
    );
    if plan.history == TableHistory::Auto {
        s.push_str(AUTO_HISTORY_NOTE);
    }
    let _ = writeln!(s, "- Command: {}", provenance.command);
    let _ = writeln!(
        s,
        "- Wall time: {:.0} s ({:.1} min) for {} fits, msgp {} on {}",
        provenance.seconds,
        provenance.seconds / 60.0,
        rows.iter()
            .map(|r| r.cells.iter().map(Vec::len).sum::<usize>())
            .sum::<usize>(),
        env!("CARGO_PKG_VERSION"),
        provenance.machine
    );
    let _ = writeln!(s, "- Date (UTC): {}\n", provenance.date);
    s.push_str("## RMSE\n\n");
    s.push_str(&rmse_table(rows, columns));
    s.push('\n');
    for line in targets(rows, columns, &plan.seeds) {
        let _ = writeln!(s, "{line}");
    }
    let _ = write!(
        s,
        "\n## Our calibration\n\nMean negative log predictive density per step (NLL, original \
         units) and the fraction of test outputs inside mean ± 2σ, per rollout, with the \
         training time (means ± standard deviations over the seeds). MSGP's iterations: all \
         solver iterations of the fit, then in brackets the iteration the validation tail kept \
         (\"spread\", \"linear\": the zero-mean recipe's final training blew up and its fallback head from \
         the spread start, or with a linear prior mean, is the model: `msgp_core::fit::MsgpSettings::blow_up_fallback`; \
         \"linear set aside\", \"zero set aside\": the recipe the tail preferred, with that prior mean, \
         had a model whose free simulation of the training inputs diverges, and the next recipe's \
         is the model: `msgp_core::fit::FitReport::set_aside`) \
         and, where the chosen recipe trained again on all the training data, the iterate of \
         that training the model is; after them, the standard deviation (original units) the \
         output-variance calibration adds to every simulated output (`msgp_core::fit::calibration`: \
         judged on the validation tail by the final training's proxy; it moves no mean).\n\n\
         | Task | method | rollout | RMSE | NLL/step | 2σ coverage | train s | {} iterations (kept) |\n\
         |---|---|---|---:|---:|---:|---:|---:|\n",
        plan.optimizer.name()
    );
    for row in rows {
        for &c in columns {
            let cells = &row.cells[c.index()];
            if cells.is_empty() {
                continue;
            }
            for (k, rollout) in Rollout::REPORTED.into_iter().enumerate() {
                let iters = if c.method() == Method::Msgp {
                    cells
                        .iter()
                        .map(|x| {
                            let start = x
                                .fallback
                                .as_ref()
                                .map_or(String::new(), |f| format!("{f} "));
                            let aside = x
                                .set_aside
                                .as_ref()
                                .map_or(String::new(), |r| format!(", {r} set aside"));
                            let (run, best) = (x.iterations_run, x.best_iteration);
                            let kept = match x.full_data_iteration {
                                Some(j) => format!("{run} ({start}{best}{aside}; {j})"),
                                None => format!("{run} ({start}{best}{aside})"),
                            };
                            match x.added_std {
                                Some(a) => format!("{kept} +{a:.3}"),
                                None => kept,
                            }
                        })
                        .collect::<Vec<_>>()
                        .join(", ")
                } else {
                    "—".to_string()
                };
                let _ = writeln!(
                    s,
                    "| {} | {} | {} | {} | {} | {} | {} | {} |",
                    row.task.label,
                    c.name(),
                    rollout.name(),
                    stat(cells, 4, |x| x.metrics[k].rmse),
                    stat(cells, 3, |x| x.metrics[k].nll),
                    stat(cells, 3, |x| x.metrics[k].coverage_2sigma),
                    stat(cells, 1, |x| x.train_seconds),
                    iters
                );
            }
        }
    }
    if plan.history == TableHistory::Auto {
        s.push_str(&chosen_histories(rows, columns));
    }
    s.push_str(match plan.history {
        TableHistory::Paper => {
            "\n## Data\n\n| Task | training samples | test samples | l_y, l_u |\n|---|---:|---:|---|\n"
        }
        TableHistory::Auto => {
            "\n## Data\n\n| Task | training samples | test samples | the paper's l_y, l_u |\n|---|---:|---:|---|\n"
        }
    });
    for row in rows {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {}, {} |",
            row.task.label,
            row.bench.train.len(),
            row.bench.test.len(),
            row.bench.ly,
            row.bench.lu
        );
    }
    s
}

/// What a section of histories chosen from the data adds to the table's description.
const AUTO_HISTORY_NOTE: &str = "Here the history `l_y, l_u` of every fit is not the paper's \
     Table 3 but chosen on that fit's training part alone, as `msgp fit --history auto` chooses \
     it (`msgp_core::fit::history`): the first 80 % of the training part fits, the last 20 % \
     judges; every history up to 10 lags is scored as a linear ARX model, and the best three \
     with the equal histories `(l, l)` are each fitted by the column's own fit and scored by \
     their free simulation of the judged part; the shortest within one standard error of the \
     best wins. The test part plays no part in the choice.\n\n";

/// The section's table of the histories chosen per row, column and seed, with each one's
/// judged score and the runner-up.
fn chosen_histories(rows: &[Row], columns: &[Column]) -> String {
    let mut s = String::from(
        "\n## Chosen histories\n\nPer fit (seed order): the history chosen on the training \
         part, its judged score (free-simulation RMSE of the judged 20 % per output standard \
         deviation) and the best other judged history's (lower where the \
         one-standard-error rule took the shorter history).\n\n\
         | Task | column | paper's l_y, l_u | chosen (score; next) |\n|---|---|---|---|\n",
    );
    let score = |x: f64| match x.is_finite() {
        true => format!("{x:.4}"),
        false => "diverged".into(),
    };
    for row in rows {
        for &c in columns {
            let picks: Vec<String> = row.cells[c.index()]
                .iter()
                .filter_map(|cell| cell.chosen_history.as_ref())
                .map(|h| {
                    let own = h.judged.iter().find(|j| (j.ly, j.lu) == (h.ly, h.lu));
                    let next = h.judged.iter().find(|j| (j.ly, j.lu) != (h.ly, h.lu));
                    format!(
                        "({}, {}) ({}; {})",
                        h.ly,
                        h.lu,
                        own.map_or("—".into(), |j| score(j.score)),
                        next.map_or("—".into(), |j| format!(
                            "({}, {}) {}",
                            j.ly,
                            j.lu,
                            score(j.score)
                        ))
                    )
                })
                .collect();
            if picks.is_empty() {
                continue;
            }
            let _ = writeln!(
                s,
                "| {} | {} | {}, {} | {} |",
                row.task.label,
                c.name(),
                row.bench.ly,
                row.bench.lu,
                picks.join(", ")
            );
        }
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mean_and_sample_standard_deviation() {
        assert_eq!(mean_std(&[]), None);
        assert_eq!(mean_std(&[2.0]), Some((2.0, 0.0)));
        let (m, sd) = mean_std(&[1.0, 2.0, 3.0]).expect("three");
        assert!((m - 2.0).abs() < 1e-15 && (sd - 1.0).abs() < 1e-15);
    }

    /// A plan of MSGP on the free-run likelihood alone over `seeds` and `benchmarks`.
    fn free_run_msgp_plan(seeds: &[u64], benchmarks: &[&str]) -> Plan {
        let only: Vec<String> = benchmarks.iter().map(|b| b.to_string()).collect();
        Plan::new(
            seeds,
            &only,
            &[Method::Msgp],
            &[Likelihood::FreeRun],
            10,
            None,
            FitOptimizer::Adam,
            Path::new("nowhere"),
        )
        .expect("plan")
    }

    fn cell(x: f64) -> Cell {
        let m = Metrics {
            rmse: x,
            nll: -x,
            coverage_2sigma: 0.5,
            steps: 10,
        };
        Cell {
            metrics: [m, m],
            train_seconds: 0.0,
            iterations_run: 1,
            best_iteration: 1,
            full_data_iteration: None,
            added_std: None,
            fallback: None,
            set_aside: None,
            diverged: None,
            chosen_history: None,
        }
    }

    #[test]
    fn results_assemble_in_any_order_and_every_unit_exactly_once() {
        let only = ["synthetic2".to_string(), "synthetic5".to_string()];
        let plan = Plan::new(
            &[3, 1],
            &only,
            &[Method::GpNarx, Method::Msgp],
            &[Likelihood::Filter],
            10,
            None,
            FitOptimizer::Adam,
            Path::new("nowhere"),
        )
        .expect("plan");
        assert_eq!(plan.columns, [Column::GpNarx, Column::MsgpFilter]);
        let units = plan.units();
        assert_eq!(units.len(), 8);
        assert_eq!(units[1].describe(), "msgp-filter on synthetic2 (seed 3)");
        let numbered: Vec<(Unit, Cell)> = units
            .iter()
            .enumerate()
            .map(|(k, u)| (u.clone(), cell(k as f64)))
            .collect();
        let in_order = assemble(&plan, numbered.clone()).expect("rows");
        let reversed = assemble(&plan, numbered.iter().rev().cloned().collect()).expect("rows");
        for (a, b) in in_order.iter().zip(&reversed) {
            assert_eq!(a.cells, b.cells);
        }
        // the targets' last line names the diverging models by column, row and seed
        let none = targets(&in_order, &plan.columns, &plan.seeds);
        assert!(
            none.last().is_some_and(|l| l.ends_with(": none")),
            "{none:?}"
        );
        let mut flagged = numbered.clone();
        flagged[7].1.diverged = Some("runs away".into());
        let rows = assemble(&plan, flagged).expect("rows");
        let lines = targets(&rows, &plan.columns, &plan.seeds);
        assert!(
            lines
                .last()
                .is_some_and(|l| l.ends_with(": MSGP (filter) on Synthetic system 5 (seed 1)")),
            "{lines:?}"
        );
        // synthetic5, msgp-filter: units 5 (seed 3) and 7 (seed 1), in seed order
        let col = &in_order[1].cells[Column::MsgpFilter.index()];
        assert_eq!(
            col.iter().map(|c| c.metrics[0].rmse).collect::<Vec<_>>(),
            [5.0, 7.0]
        );
        let e = assemble(&plan, numbered[1..].to_vec()).expect_err("missing");
        assert!(
            e.to_string()
                .contains("no result for gp-narx on synthetic2 (seed 3)"),
            "{e}"
        );
        let mut twice = numbered.clone();
        twice.push(numbered[0].clone());
        let e = assemble(&plan, twice).expect_err("duplicate");
        assert!(e.to_string().contains("two results for"), "{e}");
        let mut foreign = numbered.clone();
        foreign[0].0.seed = 9;
        let e = assemble(&plan, foreign).expect_err("foreign");
        assert!(e.to_string().contains("not part of this plan"), "{e}");
        let e = Plan::new(
            &[0],
            &["x".into()],
            &[],
            &[],
            10,
            None,
            FitOptimizer::Adam,
            Path::new("."),
        )
        .expect_err("unknown benchmark");
        assert!(e.to_string().contains("unknown benchmark `x`"), "{e}");
    }

    /// The iteration column says which MSGP models are not the tail's first recipe's own: a
    /// fallback head's, or the next recipe's after the first diverged.
    #[test]
    fn the_iteration_column_marks_fallback_heads_and_set_aside_recipes() {
        let plan = free_run_msgp_plan(&[0, 1, 2], &["synthetic4"]);
        let marked = |k: usize| {
            let mut c = cell(k as f64);
            c.iterations_run = 1000 + k;
            c.best_iteration = 10 * k;
            match k {
                0 => c.fallback = Some("linear".into()),
                1 => {
                    c.set_aside = Some("linear".into());
                    c.full_data_iteration = Some(388);
                    c.added_std = Some(0.079);
                }
                _ => c.full_data_iteration = Some(400),
            }
            c
        };
        let results = plan
            .units()
            .iter()
            .enumerate()
            .map(|(k, u)| (u.clone(), marked(k)))
            .collect();
        let rows = assemble(&plan, results).expect("rows");
        let provenance = Provenance {
            command: "msgp reproduce table1".into(),
            seconds: 1.0,
            machine: "test".into(),
            date: "2026-12-05".into(),
        };
        let text = render(&plan, &rows, &provenance);
        let line = text
            .lines()
            .find(|l| l.starts_with("| Synthetic system 4 | msgp | mm |"))
            .expect("the MSGP line");
        assert!(
            line.ends_with(
                "| 1000 (linear 0), 1001 (10, linear set aside; 388) +0.079, 1002 (20; 400) |"
            ),
            "{line}"
        );
    }

    /// The target line counts a row at the best only when it is at or below all six of the
    /// paper's columns: synthetic system 1 at 0.2079 is below the paper's GP-NARX, PILCO and
    /// MSGP but behind REVARB 2 (0.1717); synthetic system 2 at 0.29 is below all six.
    #[test]
    fn the_best_column_is_the_best_of_all_six() {
        let plan = free_run_msgp_plan(&[0], &["synthetic1", "synthetic2"]);
        let results = plan
            .units()
            .iter()
            .map(|u| {
                let x = if u.benchmark == "synthetic1" {
                    0.2079
                } else {
                    0.29
                };
                (u.clone(), cell(x))
            })
            .collect();
        let rows = assemble(&plan, results).expect("rows");
        let lines = targets(&rows, &plan.columns, &plan.seeds);
        assert_eq!(
            lines[0],
            "- MSGP: seed-mean RMSE at or below the paper's MSGP on 2/2 rows, at or below the \
             best of the paper's six columns on 1/2; NLL below GP-NARX's (MM) on 0/2 (behind \
             the best on Synthetic system 1 0.2079 vs REVARB 2 0.1717)"
        );
        let table = rmse_table(&rows, &plan.columns);
        let head = table.lines().next().expect("a heading");
        assert!(
            head.ends_with("| NIGP (paper) | REVARB 1 (paper) | REVARB 2 (paper) |"),
            "{head}"
        );
        assert!(table.contains("| 0.2453 | 0.2129 | 0.1717 |"), "{table}");
    }

    /// With histories from the data, each unit fits the history chosen on its training part by
    /// the column's own fit as judge, and the section lists the choices.
    #[test]
    fn an_auto_history_unit_fits_the_history_its_training_part_chooses() {
        let plan = Plan::new(
            &[0],
            &["synthetic1".into()],
            &[Method::GpNarx],
            &[],
            10,
            None,
            FitOptimizer::Adam,
            Path::new("nowhere"),
        )
        .expect("plan")
        .with_history(TableHistory::Auto);
        assert_eq!(plan.section(), "table1-auto-history");
        let unit = plan.units().remove(0);
        let threads = Threads::new(1).expect("one thread");
        let (cell, test, _) =
            fit_unit_simulated(&plan, &unit, threads, &mut |_| {}).expect("fitted");
        let bench = benchmark(&task("synthetic1").expect("task"), 0, Path::new("")).expect("data");
        let judge = FitOptions {
            inducing: Some(10),
            threads,
            ..FitOptions::new(Method::GpNarx, 1, 1)
        };
        let expected = msgp_core::fit::history::choose_history(
            std::slice::from_ref(&bench.train),
            &HistorySearch::default(),
            &judge,
        )
        .expect("a choice");
        assert_eq!(cell.chosen_history.as_ref(), Some(&expected));
        // the paper's (2, 1) is not what the search picks here (it does on systems 2–5), so the test
        // tells the two apart
        assert_ne!((expected.ly, expected.lu), (bench.ly, bench.lu));
        let settings = FitSettings {
            ly: expected.ly,
            lu: expected.lu,
            threads,
            ..FitSettings::new(Method::GpNarx)
        }
        .with_inducing(10);
        let (model, _) =
            fit(std::slice::from_ref(&bench.train), &settings, &mut |_| {}).expect("fit");
        let sim = model
            .simulate_as(&test, Rollout::REPORTED[MM])
            .expect("simulated");
        assert_eq!(
            score(&sim, &test).expect("scored").rmse,
            cell.metrics[MM].rmse
        );
        let rows = assemble(&plan, vec![(unit, cell)]).expect("rows");
        let provenance = Provenance {
            command: "c".into(),
            seconds: 1.0,
            machine: "m".into(),
            date: "d".into(),
        };
        let markdown = render(&plan, &rows, &provenance);
        assert!(markdown.starts_with("# Table 1, reproduced, histories chosen from the data"));
        let line = format!(
            "| Synthetic system 1 | gp-narx | 2, 1 | ({}, {}) (",
            expected.ly, expected.lu
        );
        assert!(markdown.contains(&line), "{markdown}");
    }

    #[test]
    fn ten_tasks_with_paper_numbers() {
        let t = tasks();
        assert_eq!(t.len(), 10);
        assert_eq!(t[3].paper, [0.5711, 0.6016, 0.7814, 0.6978, 0.4554, 0.3287]);
        assert_eq!(t[0].paper_best(), (0.1717, "REVARB 2"));
        assert_eq!(t[8].paper_best(), (1.1949, "NIGP"));
        assert_eq!(t[9].key, "dryer");
    }
}
