//! `msgp`: the command-line front of msgp-core (a thin clap layer: commands parse their
//! arguments and call library functions).

mod cost_plot;
mod dataset;
mod demo;
mod eval_cmd;
mod figure4;
mod fit_cmd;
mod learn_cmd;
mod output;
mod plot;
mod progress;
mod report;
mod reproduce;
mod results_file;
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
    /// Fit a model on CSV or MCAP data, save it, and score it on the held-out part.
    Fit(Box<fit_cmd::FitArgs>),
    /// Free simulation of data files with a saved model: RMSE, NLL and 2σ coverage.
    Eval(Box<eval_cmd::EvalArgs>),
    /// Free simulation with a saved model, written as CSV (mean, std, measured per step).
    Simulate(Box<eval_cmd::SimulateArgs>),
    /// Learn a controller with PILCO on a simulated system (MSGP, GP-NARX or linear-kf models).
    LearnPolicy(Box<learn_cmd::LearnArgs>),
    /// Reproduce the paper's results.
    #[command(subcommand)]
    Reproduce(reproduce::ReproduceCommand),
    /// Generate the paper's synthetic system 4, fit GP-NARX and MSGP, print test RMSE.
    Demo(demo::DemoArgs),
    /// Simulate the pole on the robot end effector (rapier), run stability tests.
    #[command(subcommand)]
    Sim(Box<sim_cmd::SimCommand>),
}

fn main() -> std::process::ExitCode {
    let cli = Cli::parse();
    let result = match &cli.command {
        Command::Fit(args) => fit_cmd::run(args),
        Command::Eval(args) => eval_cmd::run_eval(args),
        Command::Simulate(args) => eval_cmd::run_simulate(args),
        Command::LearnPolicy(args) => learn_cmd::run(args),
        Command::Reproduce(cmd) => reproduce::run(cmd),
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
