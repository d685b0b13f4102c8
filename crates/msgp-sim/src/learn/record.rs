//! A learning run's folder: what `msgp learn-policy --out DIR` leaves and what the Figure 4
//! reproduction collects again.
//!
//! `policy.json` (the last gains, runnable by `msgp sim pendulum --policy`), `best_policy.json`
//! (the first stable gains, else those with the lowest measured cost), `policies/NN.json` (the
//! loop's policy files: `00` its first policy, `NN` iteration NN's, each with the task and the
//! loop's settings, what `msgp policy improve` continues), `iterations.csv` (one row per
//! iteration), `episodes/NN-<kind>.mcap` (every interaction episode), `cost.png`
//! (predicted and actual cost per iteration) and, written last, `summary.json` (the plant, the
//! settings, every iteration). A folder whose summary names the same plant and settings is a
//! finished run ([`finished_run`]), so runs can be made anywhere and collected afterwards.

use std::path::Path;

use serde_json::{Value, json};

use super::plant::PendulumPlant;
use super::problem::{learner_settings, modelled_policy, pendulum_task};
use super::report::{IterationReport, LearnOutcome};
use super::settings::LearnSettings;
use crate::error::SimError;
use crate::log::write_run;
use crate::params::PendulumParams;
use crate::plot::{CostCurve, CostPoint, plot_costs};

impl From<&IterationReport> for CostPoint {
    fn from(r: &IterationReport) -> Self {
        CostPoint {
            iteration: r.iteration,
            predicted: r.predicted_cost,
            predicted_std: r.predicted_cost_std,
            actual: r.actual_cost,
            stable: r.stable,
        }
    }
}

/// The summary `summary.json` holds (and `msgp learn-policy --json` prints).
pub fn summary(
    outcome: &LearnOutcome,
    settings: &LearnSettings,
    params: &PendulumParams,
    seconds: f64,
) -> Value {
    let first = outcome.first_stable_iteration();
    let to_stable = first.and_then(|i| {
        outcome
            .iterations
            .iter()
            .find(|r| r.iteration == i)
            .map(|r| r.interaction_seconds)
    });
    json!({
        "sim": "pendulum",
        "model": settings.method().name(),
        "seed": settings.seed,
        "random_rollouts": settings.random_rollouts,
        "episode_seconds": settings.episode_seconds,
        "plant": params,
        "settings": settings,
        "iterations": &outcome.iterations,
        "first_stable_iteration": first,
        "interaction_seconds_to_stable": to_stable,
        "best_iteration": outcome.best_iteration().map(|r| r.iteration),
        "wall_seconds": seconds,
    })
}

/// `iterations.csv`.
fn iterations_csv(reports: &[IterationReport]) -> String {
    let mut s = String::from(
        "iteration,predicted_cost,predicted_cost_std,actual_cost,interaction_seconds,stable,kp_x,ki_x,kd_x,kp_theta,kd_theta\n",
    );
    for r in reports {
        let g = r.gains;
        s.push_str(&format!(
            "{},{},{},{},{},{},{},{},{},{},{}\n",
            r.iteration,
            r.predicted_cost,
            r.predicted_cost_std,
            r.actual_cost,
            r.interaction_seconds,
            r.stable,
            g.kp_x,
            g.ki_x,
            g.kd_x,
            g.kp_theta,
            g.kd_theta
        ));
    }
    s
}

fn json_text(value: &impl serde::Serialize, context: &str) -> Result<String, SimError> {
    serde_json::to_string_pretty(value).map_err(|source| SimError::Json {
        context: context.to_string(),
        source,
    })
}

fn write_file(path: &Path, text: &str) -> Result<(), SimError> {
    crate::atomic::write_atomically(path, |w| {
        std::io::Write::write_all(w, text.as_bytes()).map_err(|source| SimError::Io {
            action: "cannot write",
            path: path.to_path_buf(),
            source,
        })
    })
}

/// `policies/NN.json`: the loop's policy files (`docs/policy-format.md`), `00.json` its first
/// policy (before any search) and `NN.json` the one iteration `NN` ran, each with the task and
/// the loop's settings: what `msgp policy improve` continues from logged episodes.
fn write_policy_files(
    dir: &Path,
    outcome: &LearnOutcome,
    settings: &LearnSettings,
    params: &PendulumParams,
) -> Result<(), SimError> {
    use msgp_core::policy::Policy;
    use msgp_core::policy_file::{PolicyFile, Prediction, TaskRecord};

    std::fs::create_dir_all(dir).map_err(|source| SimError::Io {
        action: "cannot create",
        path: dir.to_path_buf(),
        source,
    })?;
    let task = pendulum_task(params, settings)?;
    let plant = PendulumPlant::new(params, settings.episode_seconds)?;
    let file = |policy: &Policy, iteration: usize| {
        let mut f = PolicyFile::new(policy);
        f.plant = Some(msgp_core::plant::Plant::spec(&plant).clone());
        f.task = Some(TaskRecord::of(&task));
        f.settings = learner_settings(params, settings).ok();
        f.iteration = Some(iteration);
        f
    };
    let first = file(&task.space.base, 0);
    first.write(&dir.join("00.json"))?;
    for r in &outcome.iterations {
        let mut f = file(
            &Policy::Pid(modelled_policy(&r.gains, params)?),
            r.iteration,
        );
        f.prediction = Some(Prediction {
            cost: r.predicted_cost,
            cost_std: r.predicted_cost_std,
            model: r
                .search_model
                .map_or(settings.method().name(), |m| m.name(settings.method()))
                .into(),
        });
        f.write(&dir.join(format!("{:02}.json", r.iteration)))?;
    }
    Ok(())
}

/// Writes every artefact of a run into `dir` (created if missing), each file atomically and
/// `summary.json` last; `label` titles the cost plot.
pub fn write_run_dir(
    dir: &Path,
    outcome: &LearnOutcome,
    (settings, params): (&LearnSettings, &PendulumParams),
    summary: &Value,
    label: &str,
) -> Result<(), SimError> {
    let episodes = dir.join("episodes");
    std::fs::create_dir_all(&episodes).map_err(|source| SimError::Io {
        action: "cannot create",
        path: episodes.clone(),
        source,
    })?;
    write_file(
        &dir.join("policy.json"),
        &json_text(&outcome.final_gains, "policy.json")?,
    )?;
    if let Some(best) = outcome.best_iteration() {
        write_file(
            &dir.join("best_policy.json"),
            &json_text(&best.gains, "best_policy.json")?,
        )?;
    }
    write_file(
        &dir.join("iterations.csv"),
        &iterations_csv(&outcome.iterations),
    )?;
    write_policy_files(&dir.join("policies"), outcome, settings, params)?;
    for (k, ep) in outcome.episodes.iter().enumerate() {
        let kind = if k < settings.random_rollouts {
            "random".to_string()
        } else {
            format!("policy-it{}", k + 1 - settings.random_rollouts)
        };
        write_run(&episodes.join(format!("{k:02}-{kind}.mcap")), ep)?;
    }
    if !outcome.iterations.is_empty() {
        plot_costs(
            &dir.join("cost.png"),
            &format!("PILCO on the pendulum, {label}"),
            &[CostCurve {
                label: label.to_string(),
                points: outcome.iterations.iter().map(CostPoint::from).collect(),
            }],
        )?;
    }
    write_file(
        &dir.join("summary.json"),
        &json_text(summary, "summary.json")?,
    )
}

/// A run read back from its folder.
#[derive(Clone, Debug, PartialEq)]
pub struct FinishedRun {
    /// Its iterations.
    pub iterations: Vec<IterationReport>,
    /// Its wall time \[s\] (NaN when the summary lacks it).
    pub seconds: f64,
}

/// The run in `dir` (its `summary.json`) if it was made on `params` with exactly `settings`
/// (seed, budget, fit and search settings, integrators, all of them) and finished all its
/// iterations. The stored settings are read back as [`LearnSettings`], so a setting added after
/// the run was made takes its default, which is what the run used; a summary without settings
/// (older runs) is not a finished run.
pub fn finished_run(
    dir: &Path,
    settings: &LearnSettings,
    params: &PendulumParams,
) -> Option<FinishedRun> {
    let text = std::fs::read_to_string(dir.join("summary.json")).ok()?;
    let v: Value = serde_json::from_str(&text).ok()?;
    let iterations: Vec<IterationReport> =
        serde_json::from_value(v.get("iterations")?.clone()).ok()?;
    let stored: LearnSettings = serde_json::from_value(v.get("settings")?.clone()).ok()?;
    let stored_plant: PendulumParams = serde_json::from_value(v.get("plant")?.clone()).ok()?;
    let same = v["model"] == settings.method().name()
        && stored == settings.as_recorded()
        && stored_plant == *params
        && iterations.len() == settings.iterations;
    same.then(|| FinishedRun {
        iterations,
        seconds: v["wall_seconds"].as_f64().unwrap_or(f64::NAN),
    })
}
