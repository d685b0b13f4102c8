//! `msgp`: the command-line front of msgp-core (a thin clap layer).

mod demo;
mod sim_cmd;

use clap::{Parser, Subcommand};

/// Gaussian-process dynamics models optimised for long-term predictions (MSGP).
#[derive(Debug, Parser)]
#[command(name = "msgp", version, about)]
struct Cli {
    #[command(subcommand)]
    command: Command,
}

#[derive(Debug, Subcommand)]
enum Command {
    /// Generate the paper's synthetic system 4, fit GP-NARX and MSGP, print test RMSE.
    Demo(demo::DemoArgs),
    /// Simulate the pole on the robot end effector (rapier), run stability tests.
    #[command(subcommand)]
    Sim(Box<sim_cmd::SimCommand>),
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    let result = match &cli.command {
        Command::Demo(args) => demo::run(args),
        Command::Sim(cmd) => sim_cmd::run(cmd),
    };
    match result {
        Ok(()) => std::process::ExitCode::SUCCESS,
        Err(e) => {
            eprintln!("error: {e:#}");
            std::process::ExitCode::FAILURE
        }
    }
}
