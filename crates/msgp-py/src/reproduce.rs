//! The paper's reproductions as independent units, for `msgp.sweep`: a plan, one unit's fit
//! (Table 1) or learning run (Figure 4), and the report (markdown section, rows, plot) from
//! every unit's result — the same library calls as `msgp reproduce table1|figure4`, so a sweep
//! spread over processes or a Ray cluster writes the numbers of the serial command line run.

use std::path::PathBuf;

use msgp_core::fit::{FitOptimizer, FitProgress};
use msgp_core::loss::Likelihood;
use msgp_core::numeric::parallel::Threads;
use msgp_reproduce::results::{machine, today, update_section};
use msgp_reproduce::table1::{self, Cell, Plan, Provenance, TableHistory, Unit};
use pyo3::prelude::*;
use pyo3::types::PyDict;
use serde::de::DeserializeOwned;

use msgp_core::learner::LoopModel;
use msgp_reproduce::figure4 as fig4;
use msgp_sim::learn::{Budget, learn_policy_observed, summary, write_run_dir};
use msgp_sim::{PendulumParams, PlantTier};

use crate::convert::{to_json, to_python, with_overrides};
use crate::error::{Error, Result, detached, input, with_python};
use crate::options::{count, method};

/// A plan, unit or cell given back by Python (a dict made by the functions below).
fn parse<T: DeserializeOwned>(obj: &Bound<'_, PyAny>, what: &str) -> Result<T> {
    serde_json::from_value(to_json(obj, what)?)
        .map_err(|e| input(format!("{what} is not a {what} of this msgp version: {e}")))
}

fn likelihood(name: &str) -> Result<Likelihood> {
    match name {
        "free-run" => Ok(Likelihood::FreeRun),
        "filter" => Ok(Likelihood::Filter),
        _ => Err(input(format!(
            "unknown likelihood {name:?}: expected \"free-run\" or \"filter\""
        ))),
    }
}

/// The validated plan of a Table 1 reproduction (as `msgp reproduce table1` takes its options)
/// as a dict, with its independent `units` (one benchmark × seed × column each, in the serial
/// run's order). `data_dir` holds the real series (default: `$MSGP_DATA_DIR`, else
/// `../shared/data/real`, as the command line).
#[pyfunction]
#[pyo3(signature = (seeds, *, data_dir = None, only = None, methods = None, likelihoods = None, inducing = 100, iters = None, optimizer = "adam", history = "paper"))]
#[allow(clippy::too_many_arguments)]
pub fn table1_plan<'py>(
    py: Python<'py>,
    seeds: Vec<u64>,
    data_dir: Option<PathBuf>,
    only: Option<Vec<String>>,
    methods: Option<Vec<String>>,
    likelihoods: Option<Vec<String>>,
    inducing: usize,
    iters: Option<usize>,
    optimizer: &str,
    history: &str,
) -> PyResult<Bound<'py, PyDict>> {
    let history = match history {
        "paper" => TableHistory::Paper,
        "auto" => TableHistory::Auto,
        other => {
            return Err(input(format!(
                "unknown history {other:?}: expected \"paper\" (Table 3's) or \"auto\" (chosen \
                 on each fit's training part)"
            ))
            .into());
        }
    };
    let methods = methods
        .unwrap_or_default()
        .iter()
        .map(|m| method(m))
        .collect::<Result<Vec<_>>>()?;
    let likelihoods = likelihoods
        .unwrap_or_default()
        .iter()
        .map(|l| likelihood(l))
        .collect::<Result<Vec<_>>>()?;
    let optimizer = match optimizer {
        "adam" => FitOptimizer::Adam,
        "lbfgs" => FitOptimizer::Lbfgs,
        other => {
            return Err(input(format!(
                "unknown optimizer {other:?}: expected \"adam\" or \"lbfgs\""
            ))
            .into());
        }
    };
    let plan = Plan::new(
        &seeds,
        &only.unwrap_or_default(),
        (&methods, &likelihoods),
        inducing,
        iters,
        optimizer,
        &data_dir.unwrap_or_else(|| msgp_core::data::real::data_dir(std::path::Path::new("."))),
    )
    .map_err(crate::error::Error::from)?
    .with_history(history);
    let out = PyDict::new(py);
    out.set_item("plan", to_python(py, &plan)?)?;
    out.set_item("units", to_python(py, &plan.units())?)?;
    out.set_item("section", plan.section())?;
    Ok(out)
}

/// Fits one unit of `plan` (both from `table1_plan`) and returns its cell: the test metrics of
/// the moment-matching and mean-feedback simulations, train time and iterations. Releases the
/// GIL; the same numbers on every machine and thread count.
#[pyfunction]
pub fn table1_unit<'py>(
    py: Python<'py>,
    plan: &Bound<'py, PyAny>,
    unit: &Bound<'py, PyAny>,
) -> PyResult<Bound<'py, PyAny>> {
    let plan: Plan = parse(plan, "plan")?;
    let unit: Unit = parse(unit, "unit")?;
    let threads = Threads::from_env().map_err(crate::error::Error::from)?;
    let cell = detached(py, || {
        table1::fit_unit(&plan, &unit, threads, &mut |_: &FitProgress| {})
            .map_err(crate::error::Error::from)
    })?;
    to_python(py, &cell)
}

/// The report of a finished plan from `results`, a list of `(unit, cell)` pairs in any order:
/// `{"section", "markdown", "rows"}` — the markdown section `msgp reproduce table1` writes and
/// the rows its `--json` prints. `command` (markdown) and `seconds` go into the provenance
/// lines, `machine` too (default: this machine's CPUs).
#[pyfunction]
#[pyo3(signature = (plan, results, command, seconds, machine = None))]
pub fn table1_report<'py>(
    py: Python<'py>,
    plan: &Bound<'py, PyAny>,
    results: Vec<(Bound<'py, PyAny>, Bound<'py, PyAny>)>,
    command: String,
    seconds: f64,
    machine: Option<String>,
) -> PyResult<Bound<'py, PyDict>> {
    let plan: Plan = parse(plan, "plan")?;
    let results = results
        .iter()
        .map(|(u, c)| Ok((parse::<Unit>(u, "unit")?, parse::<Cell>(c, "cell")?)))
        .collect::<Result<Vec<_>>>()?;
    let rows = table1::assemble(&plan, results).map_err(crate::error::Error::from)?;
    let provenance = Provenance {
        command,
        seconds,
        machine: machine.unwrap_or_else(self::machine),
        date: today(),
    };
    let out = PyDict::new(py);
    out.set_item("section", plan.section())?;
    out.set_item("markdown", table1::render(&plan, &rows, &provenance))?;
    out.set_item("rows", to_python(py, &table1::rows_json(&plan, &rows))?)?;
    Ok(out)
}

/// Replaces section `name` of the markdown file `path` (created when missing) by `body`,
/// atomically, as the `msgp reproduce` commands do.
#[pyfunction]
pub fn update_results_section(path: PathBuf, name: &str, body: &str) -> PyResult<()> {
    update_section(&path, name, body).map_err(crate::error::Error::from)?;
    Ok(())
}

/// The validated plan of a Figure 4 reproduction (as `msgp reproduce figure4` takes its
/// options) as a dict, with its `units` (one model × seed each, in the serial run's order),
/// the `pending` ones (no finished run in the plan's folder yet: the command line reuses
/// finished runs, so does the sweep) and the results file's `section`. `tier`: "apollo" or
/// "noisy"; `params` overrides the tier's plant parameters; `models`: "msgp" (free-run
/// likelihood), "msgp-filter", "gp-narx", "linear-kf" (default: all four); `budget` overrides
/// `figure4_budget()` (the command line's budget options, snake_case); `dir`: default
/// `results/figure4-<tier>`.
#[pyfunction]
#[pyo3(signature = (seeds, *, tier = "apollo", params = None, models = None, iterations = 8, budget = None, dir = None))]
#[allow(clippy::too_many_arguments)]
pub fn figure4_plan<'py>(
    py: Python<'py>,
    seeds: Vec<u64>,
    tier: &str,
    params: Option<&Bound<'py, PyAny>>,
    models: Option<Vec<String>>,
    iterations: i128,
    budget: Option<&Bound<'py, PyAny>>,
    dir: Option<PathBuf>,
) -> PyResult<Bound<'py, PyDict>> {
    let tier = [PlantTier::Apollo, PlantTier::Noisy]
        .into_iter()
        .find(|t| t.name() == tier)
        .ok_or_else(|| {
            input(format!(
                "unknown plant tier {tier:?}: expected \"apollo\" or \"noisy\""
            ))
        })?;
    let plant: PendulumParams = with_overrides(&PendulumParams::tier(tier), params, "params")?;
    let models = match models {
        None => LoopModel::ALL.to_vec(),
        Some(names) => names
            .iter()
            .map(|m| m.parse::<LoopModel>().map_err(input))
            .collect::<Result<Vec<_>>>()?,
    };
    let budget: Budget = with_overrides(&Budget::default(), budget, "budget")?;
    let plan = fig4::Plan::new(
        tier.name(),
        plant,
        models,
        seeds,
        count(iterations, "iterations")?,
        budget,
        dir,
    )
    .map_err(Error::from)?;
    let mut pending = Vec::new();
    for unit in plan.units() {
        if plan.finished(&unit).map_err(Error::from)?.is_none() {
            pending.push(unit);
        }
    }
    let out = PyDict::new(py);
    out.set_item("plan", to_python(py, &plan)?)?;
    out.set_item("units", to_python(py, &plan.units())?)?;
    out.set_item("pending", to_python(py, &pending)?)?;
    out.set_item("section", plan.section())?;
    out.set_item("dir", plan.dir.clone())?;
    Ok(out)
}

/// The budget options of `msgp learn-policy` / `msgp reproduce figure4` at their defaults, as
/// a dict (`None`: the model's own default).
#[pyfunction]
pub fn figure4_budget(py: Python<'_>) -> PyResult<Bound<'_, PyAny>> {
    to_python(py, &Budget::default())
}

/// Runs one unit of `plan` (both from `figure4_plan`): the learning loop, its folder written
/// into `dir` (policy, iterations.csv, episodes, cost.png, summary.json last) — a scratch folder
/// on a worker, whose files the sweep brings to the plan's folder; returns the run's summary.
/// Takes minutes; releases the GIL; Ctrl-C stops it within one model fit.
#[pyfunction]
pub fn figure4_unit<'py>(
    py: Python<'py>,
    plan: &Bound<'py, PyAny>,
    unit: &Bound<'py, PyAny>,
    dir: PathBuf,
) -> PyResult<Bound<'py, PyAny>> {
    let plan: fig4::Plan = parse(plan, "plan")?;
    let unit: fig4::Unit = parse(unit, "unit")?;
    let settings = plan.settings(&unit).map_err(Error::from)?;
    let (done, raised) = detached(py, || {
        let started = std::time::Instant::now();
        let mut raised: Option<PyErr> = None;
        let learned = learn_policy_observed(&plan.plant, &settings, &mut |_| {
            with_python(&mut raised, |_| Ok(()))
        });
        let done = learned.and_then(|outcome| {
            let summary = summary(
                &outcome,
                &settings,
                &plan.plant,
                started.elapsed().as_secs_f64(),
            );
            let label = format!("{} seed {}", unit.model.name(), unit.seed);
            write_run_dir(&dir, &outcome, (&settings, &plan.plant), &summary, &label)?;
            Ok(summary)
        });
        Ok((done, raised))
    })?;
    if let Some(err) = raised {
        return Err(err);
    }
    to_python(py, &done.map_err(Error::from)?)
}

/// The report of a plan whose every unit has its finished run in the plan's folder:
/// `{"section", "markdown", "plot"}` — the section `msgp reproduce figure4` writes, and the
/// cost-band plot it draws (`<dir>/figure4.png`). `command` (markdown) and `seconds` go into
/// the provenance lines, `machine` too (default: this machine's CPUs).
#[pyfunction]
#[pyo3(signature = (plan, command, seconds, machine = None))]
pub fn figure4_report<'py>(
    py: Python<'py>,
    plan: &Bound<'py, PyAny>,
    command: String,
    seconds: f64,
    machine: Option<String>,
) -> PyResult<Bound<'py, PyDict>> {
    let plan: fig4::Plan = parse(plan, "plan")?;
    let runs = fig4::collect(&plan).map_err(Error::from)?;
    let provenance = Provenance {
        command,
        seconds,
        machine: machine.unwrap_or_else(self::machine),
        date: today(),
    };
    let markdown = fig4::report(&plan, &runs, &provenance).map_err(Error::from)?;
    let out = PyDict::new(py);
    out.set_item("section", plan.section())?;
    out.set_item("markdown", markdown)?;
    out.set_item("plot", plan.dir.join("figure4.png"))?;
    Ok(out)
}
