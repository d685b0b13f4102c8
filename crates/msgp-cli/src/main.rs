//! `msgp`: the command-line front of msgp-core and msgp-sim. A thin layer: [`args`] holds every
//! clap type, [`commands`] turns parsed options into library calls, [`render`] writes what
//! people read (text, JSON, markdown, PNG plots, progress).

mod args;
mod commands;
mod render;

use clap::Parser;

use args::{Cli, Command, ReproduceCommand};

/// mimalloc instead of the system allocator: the one-step fit frees and allocates `n × n`
/// matrices of 2–8 MB hundreds of times per fit, which glibc's malloc returns to the system and
/// faults back in each time (`BENCHMARKS.md`, sixth session).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    let result = match &cli.command {
        Command::Fit(args) => commands::fit::run(args),
        Command::Eval(args) => commands::eval::run_eval(args),
        Command::Simulate(args) => commands::eval::run_simulate(args),
        Command::LearnPolicy(args) => commands::learn::run(args),
        Command::Reproduce(ReproduceCommand::Table1(args)) => commands::table1::run(args),
        Command::Reproduce(ReproduceCommand::Figure4(args)) => commands::figure4::run(args),
        Command::Reproduce(ReproduceCommand::PlantTask(args)) => commands::plant_task::run(args),
        Command::Reproduce(ReproduceCommand::Generalisation(args)) => {
            commands::generalisation::run(args)
        }
        Command::Demo(args) => commands::demo::run(args),
        Command::Sim(cmd) => commands::sim::run(cmd),
        Command::Policy(cmd) => commands::policy::run(cmd),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
