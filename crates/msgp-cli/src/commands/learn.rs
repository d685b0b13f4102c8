//! `msgp learn-policy --sim pendulum`: PILCO policy search on the simulated pole, with MSGP or
//! one-step GP-NARX models (paper section 4.2, Figure 4).
//!
//! Writes the run's folder into `--out DIR` (`msgp_sim::learn::write_run_dir`: policy.json,
//! best_policy.json, iterations.csv, episodes as MCAP, cost.png, and summary.json, which
//! `--json` prints).

use std::ops::ControlFlow;
use std::path::PathBuf;
use std::time::Instant;

use anyhow::Context;
use msgp_core::model::Method;
use msgp_sim::learn::{
    IterationReport, LearnEvent, LearnOutcome, LearnSettings, SearchModel, learn_policy_observed,
    summary, write_run_dir,
};
use msgp_sim::{PendulumParams, SimError};

use crate::args::{LearnArgs, LikelihoodArg, ModelArg, SimArg};
use crate::render::output::{out, out_json};
use crate::render::progress::FitBar;

/// The model's name in file names and tables.
pub fn model_name(m: ModelArg) -> &'static str {
    Method::from(m).name()
}

/// A budget error in the command line's words: the option as its flag (`--episode-seconds`);
/// other errors as they are.
pub fn flagged(e: SimError) -> anyhow::Error {
    match e {
        SimError::Budget { option, reason } => {
            anyhow::anyhow!("invalid --{option}: {reason}")
        }
        other => other.into(),
    }
}

/// [`flagged`] for a reproduction's plan: its option errors as flags, the simulator's as
/// [`flagged`] says them.
pub fn flagged_plan(e: msgp_reproduce::ReproduceError) -> anyhow::Error {
    match e {
        msgp_reproduce::ReproduceError::Plan { option, reason } => {
            anyhow::anyhow!("invalid --{option}: {reason}")
        }
        msgp_reproduce::ReproduceError::Sim(e) => flagged(e),
        other => other.into(),
    }
}

/// A progress line for one iteration.
pub fn progress_line(r: &IterationReport, started: Instant) -> String {
    let mut notes = String::new();
    if let Some(stop) = &r.fit_numerical_stop {
        notes.push_str(&format!("\n  fit stopped early: {stop}"));
    }
    if let Some(why) = &r.search_failure {
        notes.push_str(&format!(
            "\n  policy search failed ({why}): the previous gains ran again"
        ));
    }
    if let (Some(m), Some(h)) = (r.search_model, r.held_out) {
        notes.push_str(&format!(
            "\n  searched on the {} model; on the episode run, which neither model saw: GP {:.1}, \
             linear {:.1} nats",
            match m {
                SearchModel::Gp => "GP",
                SearchModel::Linear => "linear",
                SearchModel::OneStep => "one-step",
            },
            h.gp_nll,
            h.linear_nll
        ));
        if let Some(r) = h.rollout {
            notes.push_str(&format!(
                "; its closed-loop free run: GP {:.1}, one-step {:.1} nats",
                r.gp, r.one_step
            ));
        }
    }
    let line = format!(
        "iteration {:>2}: predicted cost {:7.2} ± {:5.2} (2σ), actual {:7.2}, interaction {:5.1} s, stable {:<3} gains [{:.3}, {:.3}, {:.3}, {:.2}, {:.3}]  [fit {:.0} s, search {:.0} s, total {:.0} s]",
        r.iteration,
        r.predicted_cost,
        2.0 * r.predicted_cost_std,
        r.actual_cost,
        r.interaction_seconds,
        if r.stable { "yes" } else { "no" },
        r.gains.kp_x,
        r.gains.ki_x,
        r.gains.kd_x,
        r.gains.kp_theta,
        r.gains.kd_theta,
        r.fit_seconds,
        r.search_seconds,
        started.elapsed().as_secs_f64()
    );
    line + &notes
}

/// Runs one learning loop on `params`, printing progress unless `quiet`.
pub fn learn(
    params: &PendulumParams,
    settings: &LearnSettings,
    quiet: bool,
) -> anyhow::Result<(LearnOutcome, f64)> {
    let started = Instant::now();
    // each iteration's model fit gets a bar (a line every few seconds when stderr is not a
    // terminal): an MSGP fit takes up to a minute
    let mut bar: Option<FitBar> = None;
    let method = settings.method().name();
    let learned = learn_policy_observed(params, settings, &mut |e| {
        match e {
            LearnEvent::FitStarted { iteration } => {
                let stage = match (settings.method(), settings.warm_start, iteration) {
                    (Method::LinearKf, _, _) => "filter likelihood",
                    (Method::Msgp, Some(_), 2..) => "continuing the previous model",
                    _ => "one-step initialisation",
                };
                let label = format!("iteration {iteration}: {method} fit");
                bar = Some(FitBar::starting(&label, quiet, stage));
            }
            LearnEvent::Fit { progress, .. } => {
                if let Some(b) = bar.as_mut() {
                    b.update(progress);
                }
            }
            LearnEvent::SearchStarted { .. } => {
                if let Some(b) = bar.take() {
                    b.abandon();
                }
            }
            LearnEvent::Iteration(r) => {
                if !quiet {
                    eprintln!("{}", progress_line(r, started));
                }
            }
        }
        ControlFlow::Continue(())
    });
    if let Some(b) = bar.take() {
        b.abandon();
    }
    let outcome = learned.context("policy learning failed")?;
    Ok((outcome, started.elapsed().as_secs_f64()))
}

/// Runs `msgp learn-policy`.
pub fn run(args: &LearnArgs) -> anyhow::Result<()> {
    let SimArg::Pendulum = args.sim;
    let params = args.plant.resolve()?;
    let settings = args
        .budget
        .budget()
        .settings(args.model.into(), args.seed, args.iterations)
        .map_err(flagged)?;
    let dir = args.out.clone().unwrap_or_else(|| {
        PathBuf::from(format!(
            "learn-{}-seed{}",
            model_name(args.model),
            args.seed
        ))
    });
    let quiet = args.quiet || args.json;
    if !quiet {
        eprintln!(
            "learning to balance the pendulum with {} models: {} random rollouts, then {} iterations of {} s episodes (seed {})",
            model_name(args.model),
            settings.random_rollouts,
            settings.iterations,
            settings.episode_seconds,
            settings.seed
        );
    }
    let (outcome, seconds) = learn(&params, &settings, quiet)?;
    let summary = summary(&outcome, &settings, &params, seconds);
    write_run_dir(
        &dir,
        &outcome,
        (&settings, &params),
        &summary,
        model_name(args.model),
    )?;
    if args.json {
        return out_json(&summary);
    }
    let first = outcome.first_stable_iteration();
    out(&match first {
        Some(i) => format!(
            "first stable policy at iteration {i} after {:.1} s of interaction",
            summary["interaction_seconds_to_stable"]
                .as_f64()
                .unwrap_or(f64::NAN)
        ),
        // what RESULTS.md measured (Figure 4, both plant tiers)
        None if args.model == ModelArg::GpNarx
            || args.budget.likelihood == Some(LikelihoodArg::FreeRun) =>
        {
            "no iteration passed the stability test (the free-run msgp and the gp-narx loops \
             rarely find a stable policy; try --model msgp (the filter likelihood, the default) \
             or --model linear-kf: RESULTS.md, Figure 4)"
                .to_string()
        }
        None => "no iteration passed the stability test".to_string(),
    })?;
    out(&format!(
        "final gains kp_x {:.4}, ki_x {:.4}, kd_x {:.4}, kp_theta {:.4}, kd_theta {:.4}",
        outcome.final_gains.kp_x,
        outcome.final_gains.ki_x,
        outcome.final_gains.kd_x,
        outcome.final_gains.kp_theta,
        outcome.final_gains.kd_theta
    ))?;
    out(&format!(
        "wrote {}/policy.json, iterations.csv, cost.png, summary.json and {} episodes (MCAP) in {seconds:.0} s",
        dir.display(),
        outcome.episodes.len()
    ))
}
