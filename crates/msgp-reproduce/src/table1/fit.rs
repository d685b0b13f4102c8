//! Fitting one unit of Table 1: its benchmark's data, the history (the paper's, or chosen on
//! the training part), the seeded fit and its two test simulations.

use std::ops::ControlFlow;
use std::path::Path;

use msgp_core::MsgpError;
use msgp_core::data::{Benchmark, NoiseScale, SyntheticSystem, Trajectory};
use msgp_core::fit::history::{
    HistoryChoice, HistoryEvent, HistorySearch, choose_history_observed,
};
use msgp_core::fit::{FitOptions, FitProgress, FitSettings, OutputRange, Overrides, fit};
use msgp_core::loss::Likelihood;
use msgp_core::model::{Method, Metrics, Rollout, Simulation, score};
use msgp_core::numeric::parallel::Threads;

use super::*;
use crate::error::Result;

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
    let mut base = FitSettings {
        ly,
        lu,
        seed: unit.seed,
        threads,
        ..FitSettings::new(method)
    };
    if let Some(msgp) = base.msgp_mut() {
        msgp.optimizer = plan.optimizer;
    }
    let settings = overrides(plan, unit).apply(base)?;
    let (model, report) = fit(std::slice::from_ref(&bench.train), &settings, progress)?;
    // the moment-matching simulation is scored and held against the test outputs; a simulation
    // that fails numerically is a diverged cell (scored +∞), not the end of the table
    let failed = |e: MsgpError| match e {
        e if e.is_numerical() => Ok(Metrics {
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

/// What `unit`'s fit changes of its method's defaults: the plan's pseudo-inputs, its
/// iterations (MSGP's), the filter column's likelihood.
fn overrides(plan: &Plan, unit: &Unit) -> Overrides {
    let msgp = unit.column.method() == Method::Msgp;
    Overrides {
        inducing: Some(plan.inducing),
        iterations: plan.iters.filter(|_| msgp),
        likelihood: (unit.column == Column::MsgpFilter).then_some(Likelihood::Filter),
        ..Overrides::default()
    }
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
    let judge = FitOptions {
        seed: unit.seed,
        optimizer: plan.optimizer,
        threads,
        overrides: overrides(plan, unit),
        ..FitOptions::new(unit.column.method(), bench.ly, bench.lu)
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
