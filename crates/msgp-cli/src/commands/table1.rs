//! `msgp reproduce table1`: the paper's Table 1 (`msgp_reproduce::table1`), its units fitted
//! `--jobs` at a time on this machine (one job: a progress bar each; more: a line per finished
//! fit), written as a section of the results file.

use std::path::Path;
use std::sync::atomic::{AtomicUsize, Ordering};
use std::time::Instant;

use anyhow::Context;
use msgp_core::data::Trajectory;
use msgp_core::fit::FitProgress;
use msgp_core::model::Method;
use msgp_core::model::{Simulated, Simulation};
use msgp_core::numeric::parallel::Threads;
use msgp_reproduce::results::{machine, today, update_section};
use msgp_reproduce::table1::{
    Cell, Column, Plan, Provenance, Unit, assemble, fit_unit_simulated, render, rmse_table,
    rows_json, targets, task,
};
use serde_json::json;

use crate::args::Table1Args;
use crate::commands::side_by_side;
use crate::render::output::{out, out_json};
use crate::render::plot::{plot_grid, simulated};
use crate::render::progress::FitBar;

/// The command line as a user would type it again, as markdown.
fn command_line() -> String {
    let args: Vec<String> = std::env::args().skip(1).collect();
    format!(
        "`cargo run --release --locked --bin msgp -- {0}` (i.e. `msgp {0}`)",
        args.join(" ")
    )
}

/// Runs `msgp reproduce table1`.
pub fn run(args: &Table1Args) -> anyhow::Result<()> {
    let started = Instant::now();
    let methods: Vec<Method> = args.methods.iter().map(|&m| m.into()).collect();
    let likelihoods: Vec<_> = args.likelihoods.iter().map(|&l| l.into()).collect();
    let plan = Plan::new(
        &args.common.seeds,
        &args.common.only,
        (&methods, &likelihoods),
        args.inducing,
        args.iters,
        args.optimizer.into(),
        &args.common.data_dir(),
    )?
    .with_history(args.history.into());
    // (the plots' folder before the fits, which it would outlast)
    if let Some(dir) = &args.plots {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create the plots' folder {}", dir.display()))?;
    }
    let units = plan.units();
    let total = units.len();
    let (jobs, per_fit) = side_by_side::share(args.common.jobs, Threads::from_env()?.get(), total)?;
    let threads = per_fit.unwrap_or(Threads::from_env()?);
    // one job shows each fit's progress bar; with more they would interleave, and a line per
    // finished fit says how far the table is
    let quiet = args.common.quiet || jobs > 1;
    let finished = AtomicUsize::new(0);
    let todo: Vec<_> = units.into_iter().enumerate().collect();
    let results = side_by_side::run(todo, jobs, |(k, unit)| {
        let what = unit.describe();
        let label = format!("[{}/{total}] {what}", k + 1);
        let mut bar = FitBar::new(&label, quiet);
        let fitted =
            fit_unit_simulated(&plan, &unit, threads, &mut |p: &FitProgress| bar.update(p));
        let (cell, test, sim) = match fitted {
            Ok(c) => c,
            Err(e) => {
                bar.abandon();
                return Err(e).context(format!("fitting {what}"));
            }
        };
        // (the simulation is kept only for a plot)
        let drawn = args.plots.as_ref().and(sim).map(|sim| (test, sim));
        let paper = match (unit.column.paper(), task(&unit.benchmark)) {
            (Some(i), Ok(t)) => format!(" (paper {:.4})", t.paper[i]),
            _ => String::new(),
        };
        let [mm, mean] = &cell.metrics;
        let history = cell
            .chosen_history
            .as_ref()
            .map_or(String::new(), |h| format!("history ({}, {}), ", h.ly, h.lu));
        let summary = format!(
            "{history}RMSE {:.4}{paper}, mean feedback {:.4}, NLL {:.3}, coverage {:.2}, {:.1} s",
            mm.rmse, mean.rmse, mm.nll, mm.coverage_2sigma, cell.train_seconds
        );
        bar.finish(&summary);
        let done = finished.fetch_add(1, Ordering::Relaxed) + 1;
        if jobs > 1 && !args.common.quiet {
            eprintln!(
                "{label}: {summary} ({done}/{total} done, {:.0} s)",
                started.elapsed().as_secs_f64()
            );
        }
        Ok((unit, cell, drawn))
    })?;
    let plots = match &args.plots {
        Some(dir) => draw(dir, &plan, &results)?,
        None => Vec::new(),
    };
    let results = results.into_iter().map(|(u, c, _)| (u, c)).collect();
    let rows = assemble(&plan, results)?;
    let seconds = started.elapsed().as_secs_f64();
    let provenance = Provenance {
        command: command_line(),
        seconds,
        machine: machine(),
        date: today(),
    };
    let mut markdown = render(&plan, &rows, &provenance);
    if let (Some(dir), Some(first)) = (&args.plots, plots.first()) {
        markdown.push_str(&format!(
            "\nPlots of the test part's simulations, one per benchmark and seed: \
             `{}/<benchmark>-seed<k>.png`, a row per column, the predicted mean ± 2σ (moment \
             matching) against the true (synthetic) or measured (real) test output (e.g. \
             [{first}]({first})).\n",
            dir.display()
        ));
    }
    update_section(&args.common.out, plan.section(), &markdown)?;
    if args.common.json {
        return out_json(&json!({
            "command": "reproduce table1",
            "out": args.common.out.display().to_string(),
            "seconds": seconds,
            "seeds": plan.seeds,
            "inducing": plan.inducing,
            "plots": plots,
            "rows": rows_json(&plan, &rows),
        }));
    }
    let columns: &[Column] = &plan.columns;
    out(&format!(
        "{}\n{}\nwritten to {} in {:.0} s{}",
        rmse_table(&rows, columns),
        targets(&rows, columns, &plan.seeds).join("\n"),
        args.common.out.display(),
        seconds,
        args.plots.as_ref().map_or(String::new(), |d| format!(
            "; {} plots in {}",
            plots.len(),
            d.display()
        ))
    ))
}

/// A fitted unit: its cell and, where plots are drawn, the test part and its simulation.
type Fitted = (Unit, Cell, Option<(Trajectory, Simulation)>);

/// Draws one plot per benchmark and seed of `plan` into `dir` from the units' simulations, a
/// row per column (in the table's order; a column whose simulation failed is left out), and
/// returns the paths written.
fn draw(dir: &Path, plan: &Plan, results: &[Fitted]) -> anyhow::Result<Vec<String>> {
    let mut written = Vec::new();
    let mut seen: Vec<(String, u64)> = Vec::new();
    for u in plan.units() {
        let key = (u.benchmark.clone(), u.seed);
        if seen.contains(&key) {
            continue;
        }
        seen.push(key);
        let mut panels: Vec<(String, Simulated)> = Vec::new();
        for column in &plan.columns {
            let found = results.iter().find(|(r, _, _)| {
                r.benchmark == u.benchmark && r.seed == u.seed && r.column == *column
            });
            let Some((_, cell, Some((test, sim)))) = found else {
                continue;
            };
            panels.push((
                format!("{} (seed {}): {}", u.benchmark, u.seed, column.label()),
                simulated("test part", test, sim.clone(), cell.metrics[0]),
            ));
        }
        if panels.is_empty() {
            continue;
        }
        let rows: Vec<Vec<(String, &Simulated)>> =
            panels.iter().map(|(t, s)| vec![(t.clone(), s)]).collect();
        let data = if u.benchmark.starts_with("synthetic") {
            "true output"
        } else {
            "measured"
        };
        let path = dir.join(format!("{}-seed{}.png", u.benchmark, u.seed));
        plot_grid(&path, &rows, data)?;
        written.push(path.display().to_string());
    }
    Ok(written)
}
