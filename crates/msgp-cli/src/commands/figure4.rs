//! `msgp reproduce figure4`: the paper's Figure 4 on the simulated pendulum, its runs one after
//! another (`msgp_sim::figure4`: plan → units → runs' folders → report); finished runs in the
//! folder are reused, so runs can be split over processes (`msgp learn-policy --out`) or
//! machines (`python -m msgp.sweep figure4`) and collected here.

use std::time::Instant;

use anyhow::Context;
use msgp_core::reproduce::results::{Provenance, machine, today, update_section};
use msgp_sim::figure4::{self, Plan, Run};
use msgp_sim::learn::{summary, write_run_dir};

use crate::args::Figure4Args;
use crate::commands::learn::{flagged, learn};

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
    .map_err(flagged)?;
    let mut runs = Vec::new();
    for unit in plan.units() {
        let run_dir = plan.run_dir(&unit);
        if let Some(done) = plan.finished(&unit)? {
            if !args.quiet {
                eprintln!(
                    "== {}: reusing {}",
                    unit.name(),
                    run_dir.join("summary.json").display()
                );
            }
            runs.push(Run { unit, run: done });
            continue;
        }
        if !args.quiet {
            eprintln!("== {}", unit.name());
        }
        let settings = plan.settings(&unit)?;
        let (outcome, seconds) = learn(&plan.plant, &settings, args.quiet)?;
        let summary = summary(&outcome, &settings, &plan.plant, seconds);
        let label = format!("{} seed {}", unit.model.name(), unit.seed);
        write_run_dir(&run_dir, &outcome, &settings, &summary, &label)
            .with_context(|| format!("writing {}", run_dir.display()))?;
        let done = plan
            .finished(&unit)?
            .with_context(|| format!("{} does not read back", run_dir.display()))?;
        runs.push(Run { unit, run: done });
    }
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

/// This process's arguments after the binary, quoted for a POSIX shell where needed: the
/// section names exactly what made it, budget flags included.
fn invocation() -> String {
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
