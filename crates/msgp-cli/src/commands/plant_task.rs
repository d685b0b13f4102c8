//! `msgp reproduce plant-task --task NAME`: PILCO on a named plant task with each loop model
//! over seeds, `--jobs` runs at a time (`msgp_reproduce::plant_task`: plan → runs' records →
//! report); records in the folder with the plan's settings are reused.

use std::time::Instant;

use anyhow::Context;
use msgp_core::learner::LearnEvent;
use msgp_core::numeric::parallel::Threads;
use msgp_reproduce::figure4::Unit;
use msgp_reproduce::plant_task::{self as plant_tasks, TaskPlan, TaskRun};
use msgp_reproduce::results::{Provenance, machine, today, update_section};

use crate::args::PlantTaskArgs;
use crate::commands::figure4::invocation;
use crate::commands::learn::flagged_plan;
use crate::commands::side_by_side;

/// Runs `msgp reproduce plant-task`.
pub fn run(args: &PlantTaskArgs) -> anyhow::Result<()> {
    let plan = TaskPlan::new(
        args.task,
        args.models.clone(),
        (0..args.seeds).collect(),
        args.iterations,
        args.dir.clone(),
    )
    .map_err(flagged_plan)?;
    let (mut done, todo) = side_by_side::reuse(
        plan.units(),
        args.runs.quiet,
        |unit| Ok(plan.finished(unit)?),
        |unit| {
            format!(
                "{}: reusing {}",
                unit.name(),
                plan.record_path(unit).display()
            )
        },
    )?;
    let (jobs, per_run) =
        side_by_side::share(args.runs.jobs, Threads::from_env()?.get(), todo.len())?;
    let clock = Instant::now();
    let finished = side_by_side::run(todo, jobs, |(k, unit): (usize, Unit)| {
        let name = unit.name();
        let progress = !args.runs.quiet && jobs == 1;
        if !args.runs.quiet {
            eprintln!(
                "== {name}: started ({:.0} s)",
                clock.elapsed().as_secs_f64()
            );
        }
        let run = plant_tasks::run_unit(&plan, unit, per_run, &mut |e| {
            if let (true, LearnEvent::Iteration(r)) = (progress, e) {
                eprintln!(
                    "   iteration {:2}: model {:?}, predicted {:.1}, actual {:.1}, solved {:?} \
                     (fit {:.1} s, search {:.1} s)",
                    r.iteration,
                    r.search_model,
                    r.predicted_cost,
                    r.actual_cost,
                    r.success,
                    r.fit_seconds,
                    r.search_seconds
                );
            }
        })
        .with_context(|| format!("run {name}"))?;
        if !args.runs.quiet {
            eprintln!(
                "== {name}: done in {:.0} s, last score {:?}, first success {}{} ({:.0} s)",
                run.seconds,
                run.scores.last(),
                run.first_success()
                    .map_or("none".to_string(), |r| format!("iteration {}", r.iteration)),
                run.error
                    .as_ref()
                    .map_or(String::new(), |e| format!(", stopped: {e}")),
                clock.elapsed().as_secs_f64()
            );
        }
        Ok((k, run))
    })?;
    for (k, run) in finished {
        done[k] = Some(run);
    }
    let runs: Vec<TaskRun> = done.into_iter().flatten().collect();
    let provenance = Provenance {
        command: format!(
            "`cargo run --release --locked --bin msgp -- {}`",
            invocation()
        ),
        // the runs' own wall time, reused records included (this call may only collect them)
        seconds: runs.iter().map(|r| r.seconds).sum(),
        machine: machine(),
        date: today(),
    };
    let markdown = plant_tasks::report(&plan, &runs, &provenance)?;
    update_section(&args.out, &plan.section(), &markdown)?;
    crate::render::output::out(&markdown)
}
