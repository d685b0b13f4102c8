//! `msgp reproduce figure4`: the paper's Figure 4 on the simulated pendulum, `--jobs` of its runs
//! at a time (`msgp_reproduce::figure4`: plan → units → runs' folders → report); finished runs in the
//! folder are reused, so runs can be split over processes (`msgp learn-policy --out`) or
//! machines (`python -m msgp.sweep figure4`) and collected here.

use std::time::Instant;

use anyhow::Context;
use msgp_core::numeric::parallel::Threads;
use msgp_reproduce::figure4::{self, Plan, Run, Unit};
use msgp_reproduce::results::{Provenance, machine, today, update_section};
use msgp_sim::learn::{summary, write_run_dir};

use crate::args::Figure4Args;
use crate::commands::learn::{flagged_plan, learn};
use crate::commands::side_by_side;

/// Runs `msgp reproduce figure4`.
pub fn run(args: &Figure4Args) -> anyhow::Result<()> {
    let started = Instant::now();
    let plant = args.plant.resolve()?;
    let plan = Plan::new(
        msgp_sim::PlantTier::from(args.plant.plant).name(),
        plant,
        args.models.clone(),
        (0..args.seeds).collect(),
        args.iterations,
        args.budget.budget(),
        args.dir.clone(),
    )
    .map_err(flagged_plan)?;
    let (mut done, todo) = side_by_side::reuse(
        plan.units(),
        args.runs.quiet,
        |unit| Ok(plan.finished(unit)?.map(|run| Run { unit: *unit, run })),
        |unit| {
            format!(
                "{}: reusing {}",
                unit.name(),
                plan.run_dir(unit).join("summary.json").display()
            )
        },
    )?;
    let (jobs, per_run) =
        side_by_side::share(args.runs.jobs, Threads::from_env()?.get(), todo.len())?;
    for (k, run) in run_side_by_side(&plan, todo, jobs, per_run, args.runs.quiet)? {
        done[k] = Some(run);
    }
    let runs: Vec<Run> = done.into_iter().flatten().collect();
    let provenance = Provenance {
        command: format!(
            "`cargo run --release --locked --bin msgp -- {}`",
            invocation()
        ),
        seconds: started.elapsed().as_secs_f64(),
        machine: machine(),
        date: today(),
    };
    let markdown = figure4::report(&plan, &runs, &provenance)?;
    update_section(&args.out, &plan.section(), &markdown)?;
    crate::render::output::out(&markdown)
}

/// One unit's run, written to its folder and read back; on `threads` threads when given (the
/// settings' own otherwise: results do not depend on them).
fn run_unit(plan: &Plan, unit: Unit, threads: Option<Threads>, quiet: bool) -> anyhow::Result<Run> {
    let run_dir = plan.run_dir(&unit);
    // the folder records the plan's settings: a rerun on other threads reuses it
    let settings = plan.settings(&unit)?;
    let mut running = settings.clone();
    if let Some(t) = threads {
        running.fit.threads = t;
        running.search.threads = t;
    }
    let (outcome, seconds) = learn(&plan.plant, &running, quiet)?;
    let summary = summary(&outcome, &settings, &plan.plant, seconds);
    let label = format!("{} seed {}", unit.model.name(), unit.seed);
    write_run_dir(
        &run_dir,
        &outcome,
        (&settings, &plan.plant),
        &summary,
        &label,
    )
    .with_context(|| format!("writing {}", run_dir.display()))?;
    let run = plan
        .finished(&unit)?
        .with_context(|| format!("{} does not read back", run_dir.display()))?;
    Ok(Run { unit, run })
}

/// The units of `todo` (with their places in the plan) on `jobs` workers, each run on
/// `per_run` threads (the settings' own with one job); one line per started and finished run,
/// and with one job the run's own progress too (with more it would interleave).
fn run_side_by_side(
    plan: &Plan,
    todo: Vec<(usize, Unit)>,
    jobs: usize,
    per_run: Option<Threads>,
    quiet: bool,
) -> anyhow::Result<Vec<(usize, Run)>> {
    let run_quiet = quiet || jobs > 1;
    let clock = Instant::now();
    side_by_side::run(todo, jobs, |(k, unit)| {
        let name = unit.name();
        if !quiet {
            eprintln!(
                "== {name}: started ({:.0} s)",
                clock.elapsed().as_secs_f64()
            );
        }
        let run =
            run_unit(plan, unit, per_run, run_quiet).with_context(|| format!("run {name}"))?;
        if !quiet {
            let first = run
                .first_stable()
                .map_or("none".to_string(), |r| r.iteration.to_string());
            eprintln!(
                "== {name}: done in {:.0} s, first stable iteration {first} ({:.0} s)",
                run.run.seconds,
                clock.elapsed().as_secs_f64()
            );
        }
        Ok((k, run))
    })
}

/// This process's arguments after the binary, quoted for a POSIX shell where needed: the
/// section names exactly what made it, budget flags included.
pub(crate) fn invocation() -> String {
    std::env::args_os()
        .skip(1)
        .map(|a| {
            let a = a.to_string_lossy().into_owned();
            let plain = !a.is_empty()
                && a.chars()
                    .all(|c| c.is_ascii_alphanumeric() || "-_=.,/:+@%".contains(c));
            if plain {
                a
            } else {
                format!("'{}'", a.replace('\'', "'\\''"))
            }
        })
        .collect::<Vec<_>>()
        .join(" ")
}
