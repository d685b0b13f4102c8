//! `msgp demo`: the README's first command.

use std::time::Instant;

use crate::args::DemoArgs;
use anyhow::Context;
use msgp_core::data::{NoiseScale, SyntheticSystem};
use msgp_core::fit::{FitSettings, Overrides, fit};
use msgp_core::model::Method;
use msgp_core::numeric::parallel::Threads;

/// Runs the demo.
pub fn run(args: &DemoArgs) -> anyhow::Result<()> {
    let system = SyntheticSystem::new(args.system)?;
    let bench = system
        .generate(args.seed, NoiseScale::StdDev)
        .context("generating the synthetic system")?;
    eprintln!(
        "synthetic system {}: {} training and {} test samples, history l_y={}, l_u={}",
        args.system,
        bench.train.len(),
        bench.test.len(),
        bench.ly,
        bench.lu
    );
    let paper = [
        (0.2265, 0.3805),
        (0.3535, 0.3424),
        (0.1572, 0.1341),
        (0.5711, 0.3287),
        (0.0164, 0.0143),
    ][usize::from(args.system - 1)];
    crate::render::output::out(
        "method    test RMSE   NLL/step  2σ coverage  train time  (paper RMSE)",
    )?;
    for (method, paper_rmse) in [(Method::GpNarx, paper.0), (Method::Msgp, paper.1)] {
        let base = FitSettings {
            ly: bench.ly,
            lu: bench.lu,
            seed: args.seed,
            threads: Threads::from_env()?,
            ..FitSettings::new(method)
        };
        let settings = Overrides {
            inducing: Some(args.inducing),
            // `--iters` are MSGP's; the baseline runs its default
            iterations: args.iters.filter(|_| method == Method::Msgp),
            ..Overrides::default()
        }
        .apply(base)?;
        let started = Instant::now();
        let mut last_print = Instant::now();
        let (model, report) = fit(std::slice::from_ref(&bench.train), &settings, &mut |p| {
            if last_print.elapsed().as_secs_f64() > 2.0 || p.iteration == p.iterations {
                last_print = Instant::now();
                eprintln!(
                    "  {} iteration {}/{}: loss {:.4}{} ({:.1} s)",
                    method.name(),
                    p.iteration,
                    p.iterations,
                    p.loss,
                    p.validation
                        .map_or(String::new(), |v| format!(", validation NLL {v:.4}")),
                    p.elapsed
                );
            }
        })
        .with_context(|| format!("fitting {}", method.name()))?;
        let metrics = model.evaluate(&bench.test)?;
        crate::render::output::out(&format!(
            "{:<9} {:>9.4}  {:>9.3}  {:>11.3}  {:>8.1} s  ({paper_rmse:.4})",
            method.name(),
            metrics.rmse,
            metrics.nll,
            metrics.coverage_2sigma,
            started.elapsed().as_secs_f64()
        ))?;
        if method == Method::Msgp {
            eprintln!(
                "  {} iterations over {} recipes; {}",
                report.iterations_run,
                report.recipes.len(),
                crate::commands::fit::kept(&report)
            );
            if let Some(line) = crate::commands::fit::calibrated(&report, &["y".to_string()]) {
                eprintln!("  {line}");
            }
            if let Some(why) = &report.diverged {
                eprintln!("  warning: the fitted model diverges: {why}");
            }
        }
    }
    Ok(())
}
