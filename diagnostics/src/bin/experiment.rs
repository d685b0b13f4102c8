//! Fits one benchmark with one method and prints test metrics; used for the design experiments
//! recorded in docs/design.md.
//!
//! `cargo run --release -p msgp-core --example experiment -- <sys1..sys5|dryer|...> <method> [iters] [seed] [complexity] [noise: var|std]`
//!
//! Environment switches: `LR`, `LBFGS` (the L-BFGS solver), `EVERY`, `PATIENCE`, `VALFRAC`,
//! `FLOOR`, `INDUCING`, `FREEZE_X`, `ONESTEP` (one-step iterations), `DUMP` (print the settings).

use std::path::Path;

use msgp_core::data::real::{RealSeries, data_dir};
use msgp_core::data::{NoiseScale, SyntheticSystem};
use msgp_core::fit::{FitSettings, fit};
use msgp_core::loss::Complexity;
use msgp_core::model::Method;

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let name = args.get(1).map_or("sys4", String::as_str);
    let method = match args.get(2).map_or("msgp", String::as_str) {
        "gp-narx" => Method::GpNarx,
        "pilco-narx" => Method::PilcoNarx,
        _ => Method::Msgp,
    };
    let iterations: usize = args.get(3).map_or(Ok(400), |s| s.parse())?;
    let seed: u64 = args.get(4).map_or(Ok(0), |s| s.parse())?;
    let complexity = match args.get(5).map_or("pseudo", String::as_str) {
        "none" => Complexity::None,
        "neg" => Complexity::NegHalfLogDet,
        "pos" => Complexity::HalfLogDet,
        _ => Complexity::PseudoDataNll,
    };
    let scale = match args.get(6).map_or("var", String::as_str) {
        "std" => NoiseScale::StdDev,
        _ => NoiseScale::Variance,
    };
    let bench = if let Some(k) = name.strip_prefix("sys") {
        SyntheticSystem::new(k.parse()?)?.generate(seed, scale)?
    } else {
        let s = RealSeries::ALL
            .into_iter()
            .find(|s| s.name() == name)
            .ok_or("unknown series")?;
        s.load(&data_dir(Path::new(".")))?
    };
    let settings = FitSettings {
        method,
        ly: bench.ly,
        lu: bench.lu,
        iterations,
        seed,
        complexity,
        ..FitSettings::default()
    };
    let env = |k: &str| std::env::var(k).ok();
    let mut settings = settings;
    if let Some(v) = env("LR") {
        settings.learning_rate = v.parse()?;
    }
    if env("LBFGS").is_some() {
        settings.optimizer = msgp_core::fit::FitOptimizer::Lbfgs;
    }
    if let Some(v) = env("EVERY") {
        settings.eval_every = v.parse()?;
    }
    if let Some(v) = env("PATIENCE") {
        settings.patience = v.parse()?;
    }
    if let Some(v) = env("VALFRAC") {
        settings.validation_fraction = v.parse()?;
    }
    if let Some(v) = env("FLOOR") {
        settings.noise_floor = v.parse()?;
    }
    if let Some(v) = env("INDUCING") {
        settings.inducing = v.parse()?;
    }
    if env("FREEZE_X").is_some() {
        settings
            .frozen
            .push(msgp_core::gp::ParamGroup::PseudoInputs);
    }
    if let Some(v) = env("ONESTEP") {
        settings.one_step_iterations = v.parse()?;
    }
    if env("DUMP").is_some() {
        eprintln!("{}", serde_json::to_string(&settings)?);
    }
    let (model, report) = fit(std::slice::from_ref(&bench.train), &settings, &mut |p| {
        if let (Some(v), true) = (p.validation, p.iteration % 50 == 0) {
            eprintln!(
                "it {:4} loss {:.4} val {:.4} ({:.1}s)",
                p.iteration, p.loss, v, p.elapsed
            );
        }
    })?;
    let m = model.evaluate(&bench.test)?;
    println!(
        "{name} {} rmse {:.4} nll {:.3} cov {:.3} best_it {} of {} time {:.1}s jitter {:?}",
        method.name(),
        m.rmse,
        m.nll,
        m.coverage_2sigma,
        report.best_iteration,
        report.iterations_run,
        report.train_seconds,
        report.jitter
    );
    Ok(())
}
