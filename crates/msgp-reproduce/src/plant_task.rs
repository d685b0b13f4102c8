//! The loop's named plant tasks (`msgp_sim::plant_tasks`), each learned by the four loop models
//! ([`LoopModel`]) over seeds.
//!
//! A [`TaskPlan`] (task, models, seeds, iterations, folder) lists its runs (one model × seed
//! each, [`Unit`]); [`run_unit`] runs one loop with the task's preset and writes its record
//! ([`TaskRun`]: every iteration's report and the task's score of its policy) to
//! `<folder>/<model>-seed<k>.json`; a record with the plan's settings is reused. [`report`]
//! draws the score and cost bands and renders the markdown section: per model, the seeds that
//! succeeded, the interaction seconds, and which model each search ran on (the prequential
//! record). `msgp reproduce plant-task --task NAME` runs it.

use std::f64::consts::TAU;
use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use msgp_core::learner::{
    IterationReport, LearnEvent, Learner, LearnerSettings, LoopModel, SearchModel, SuccessTest,
    TargetTask,
};
use msgp_core::policy::Policy;
use msgp_core::policy_file::PolicyRecord;
use msgp_sim::SimError;
use msgp_sim::atomic::write_atomically;
use msgp_sim::plant_tasks::{PlantTask, SWING_UP_STARTS, success_episodes};
use msgp_sim::plot::CostPoint;
use msgp_sim::swing_up::swing_up_params;
use serde::{Deserialize, Serialize};

use crate::error::{ReproduceError, Result};
use crate::figure4::Unit;
use crate::plot::{SignalPanel, plot_cost_bands, plot_score_bands, plot_signals};
use crate::results::{Provenance, machine, today};

/// The task's score of every iteration's policy, kept as the loop's success test runs.
struct Scores {
    task: PlantTask,
    scores: Vec<f64>,
}

impl SuccessTest for Scores {
    fn passed(&mut self, policy: &Policy) -> msgp_core::Result<bool> {
        let (score, solved) = self.task.score(policy).map_err(|e| match e {
            SimError::Model(e) => e,
            e => msgp_sim::learn::plant_error(e),
        })?;
        self.scores.push(score);
        Ok(solved)
    }
}

/// One finished (or failed) learning run of a task.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct TaskRun {
    /// The task.
    pub task: PlantTask,
    /// The model and seed.
    pub unit: Unit,
    /// The loop's settings.
    pub settings: LearnerSettings,
    /// The task's target.
    pub target: TargetTask,
    /// Every iteration's report (its `success`: the task solved by its policy).
    pub iterations: Vec<IterationReport>,
    /// The task's score of every iteration's policy ([`PlantTask::score`]).
    pub scores: Vec<f64>,
    /// Why the loop stopped before its last iteration, if it did.
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub error: Option<String>,
    /// The policy of the last iteration (what a user gets).
    #[serde(default, skip_serializing_if = "Option::is_none")]
    pub last_policy: Option<PolicyRecord>,
    /// Wall-clock seconds.
    pub seconds: f64,
    /// When and where the run was made (`YYYY-MM-DD, <machine>`): a reused record keeps its
    /// own, so a section collected from records of several days says which (empty: a record
    /// written before runs kept it).
    #[serde(default, skip_serializing_if = "String::is_empty")]
    pub made: String,
}

impl TaskRun {
    /// The first iteration whose policy solved the task.
    pub fn first_success(&self) -> Option<&IterationReport> {
        self.iterations.iter().find(|r| r.success == Some(true))
    }

    /// Whether the last iteration's policy (what the user gets) solves the task.
    pub fn solved(&self) -> bool {
        self.error.is_none()
            && self
                .iterations
                .last()
                .is_some_and(|r| r.success == Some(true))
    }

    /// Of the searches from iteration 2 on, how many ran on the GP model, and how many there
    /// were (GP-NARX: every search; linear-kf: none).
    pub fn gp_searches(&self) -> (usize, usize) {
        let later: Vec<&IterationReport> = self
            .iterations
            .iter()
            .filter(|r| r.iteration >= 2)
            .collect();
        let gp = later
            .iter()
            .filter(|r| match r.search_model {
                Some(m) => m == SearchModel::Gp,
                None => self.unit.model != LoopModel::LinearKf,
            })
            .count();
        (gp, later.len())
    }
}

/// A validated plan of runs on a task.
#[derive(Clone, Debug, PartialEq)]
pub struct TaskPlan {
    /// The task.
    pub task: PlantTask,
    /// Models, in the table's order.
    pub models: Vec<LoopModel>,
    /// Seeds of every model.
    pub seeds: Vec<u64>,
    /// Policy iterations per run (`None`: the preset's).
    pub iterations: Option<usize>,
    /// Folder of the runs' records and plots.
    pub dir: PathBuf,
}

impl TaskPlan {
    /// Checks every run's settings; `dir` defaults to `results/plant-tasks/<task>`.
    pub fn new(
        task: PlantTask,
        models: Vec<LoopModel>,
        seeds: Vec<u64>,
        iterations: Option<usize>,
        dir: Option<PathBuf>,
    ) -> Result<Self> {
        let invalid = |option: &str, reason: &str| ReproduceError::Plan {
            option: option.to_string(),
            reason: reason.to_string(),
        };
        if models.is_empty() {
            return Err(invalid("models", "give at least one model"));
        }
        if seeds.is_empty() {
            return Err(invalid("seeds", "give at least one seed"));
        }
        if iterations == Some(0) {
            return Err(invalid("iterations", "must be at least 1"));
        }
        let plan = TaskPlan {
            dir: dir
                .unwrap_or_else(|| PathBuf::from(format!("results/plant-tasks/{}", task.name()))),
            task,
            models,
            seeds,
            iterations,
        };
        for &model in &plan.models {
            plan.settings(&Unit {
                model,
                seed: plan.seeds[0],
            })?;
        }
        Ok(plan)
    }

    /// The section of the results file: `plant-task-<task>`.
    pub fn section(&self) -> String {
        format!("plant-task-{}", self.task.name())
    }

    /// Every run, model by model, seeds in order.
    pub fn units(&self) -> Vec<Unit> {
        self.models
            .iter()
            .flat_map(|&model| self.seeds.iter().map(move |&seed| Unit { model, seed }))
            .collect()
    }

    /// The loop's settings of `unit`.
    pub fn settings(&self, unit: &Unit) -> Result<LearnerSettings> {
        let mut settings = self.task.settings(unit.model, unit.seed)?;
        if let Some(n) = self.iterations {
            settings.iterations = n;
        }
        Ok(settings)
    }

    /// The file of `unit`'s record.
    pub fn record_path(&self, unit: &Unit) -> PathBuf {
        self.dir.join(format!("{}.json", unit.name()))
    }

    /// `unit`'s record if its file holds one with this plan's settings and target.
    pub fn finished(&self, unit: &Unit) -> Result<Option<TaskRun>> {
        let Ok(text) = std::fs::read_to_string(self.record_path(unit)) else {
            return Ok(None);
        };
        let Ok(run) = serde_json::from_str::<TaskRun>(&text) else {
            return Ok(None);
        };
        let same = run.task == self.task
            && run.unit == *unit
            && run.settings == self.settings(unit)?.as_recorded()
            && run.target == self.task.target();
        Ok(same.then_some(run))
    }
}

/// Runs `unit` of `plan` (one learning loop, `observe` sees its events) and writes its record
/// atomically; a loop that fails is recorded with its error and the iterations it finished.
pub fn run_unit(
    plan: &TaskPlan,
    unit: Unit,
    threads: Option<msgp_core::numeric::parallel::Threads>,
    observe: &mut dyn FnMut(LearnEvent<'_>),
) -> Result<TaskRun> {
    let settings = plan.settings(&unit)?;
    let mut running = settings.clone();
    if let Some(t) = threads {
        running.fit.threads = t;
        running.search.threads = t;
    }
    let target = plan.task.target();
    let mut plant = plan.task.plant()?;
    let task = target.task(plant.spec(), unit.seed)?;
    let mut learner = Learner::new(task, running)?;
    let mut scores = Scores {
        task: plan.task,
        scores: Vec::new(),
    };
    let clock = std::time::Instant::now();
    let outcome = learner.run(plant.as_mut(), Some(&mut scores), &mut |e| {
        observe(e);
        std::ops::ControlFlow::Continue(())
    });
    let run = TaskRun {
        task: plan.task,
        unit,
        settings,
        target,
        iterations: learner.reports().to_vec(),
        scores: scores.scores,
        error: outcome.err().map(|e| e.to_string()),
        last_policy: Some(PolicyRecord::from(learner.policy())),
        seconds: clock.elapsed().as_secs_f64(),
        made: format!("{}, {}", today(), machine()),
    };
    std::fs::create_dir_all(&plan.dir).map_err(|source| ReproduceError::Io {
        action: "cannot create",
        path: plan.dir.clone(),
        source,
    })?;
    let path = plan.record_path(&unit);
    write_atomically(&path, |w| {
        serde_json::to_writer_pretty(&mut *w, &run).map_err(|e| SimError::MalformedLog {
            path: path.clone(),
            reason: e.to_string(),
        })
    })?;
    Ok(run)
}

/// Draws `scores.png` and `costs.png` into the plan's folder and returns the markdown section
/// for `runs` (every unit of the plan).
pub fn report(plan: &TaskPlan, runs: &[TaskRun], provenance: &Provenance) -> Result<String> {
    let per_model = |f: &dyn Fn(&TaskRun) -> Vec<f64>| -> Vec<(String, Vec<Vec<f64>>)> {
        plan.models
            .iter()
            .map(|&m| {
                let of: Vec<Vec<f64>> = runs.iter().filter(|r| r.unit.model == m).map(f).collect();
                (m.name().to_string(), of)
            })
            .collect()
    };
    let scores_png = plan.dir.join("scores.png");
    plot_score_bands(
        &scores_png,
        plan.task.score_name(),
        &per_model(&|r| r.scores.clone()),
    )?;
    let costs_png = plan.dir.join("costs.png");
    let bands: Vec<(String, Vec<Vec<CostPoint>>)> = plan
        .models
        .iter()
        .map(|&m| {
            let of = runs
                .iter()
                .filter(|r| r.unit.model == m)
                .map(|r| r.iterations.iter().map(cost_point).collect())
                .collect();
            (m.name().to_string(), of)
        })
        .collect();
    plot_cost_bands(&costs_png, &bands)?;
    let shown = match plan.task {
        PlantTask::SwingUp => shown_swing_up(runs),
        PlantTask::PendulumV1 => None,
    };
    let swing = match shown {
        Some((run, policy)) => {
            let path = plan.dir.join("swing-up.png");
            plot_swing_up(&path, run, &policy)?;
            Some((path, run))
        }
        None => None,
    };
    // every run's loop has the first unit's episodes and iterations (only the model and
    // seed differ), and the task's control period
    let settings = plan.settings(&Unit {
        model: plan.models[0],
        seed: plan.seeds[0],
    })?;
    let period = plan.task.plant()?.spec().period;
    let mut markdown = render(
        plan,
        runs,
        provenance,
        &scores_png,
        &costs_png,
        (&settings, period),
    );
    if let Some((path, run)) = swing {
        let _ = writeln!(
            markdown,
            "\n{} seed {}'s last policy from the success test's {SWING_UP_STARTS} starts near \
             hanging (the pole's angle from upright and the end effector's position; shaded: \
             what success asks of the angle): `{}`.",
            run.unit.model.name(),
            run.unit.seed,
            path.display()
        );
    }
    Ok(markdown)
}

/// The swing-up run whose last policy the report draws: the first whose last policy solves the
/// task, else the one whose last policy held the most starts, then the lowest last episode
/// cost; only runs that kept their policy.
fn shown_swing_up(runs: &[TaskRun]) -> Option<(&TaskRun, Policy)> {
    let key = |r: &TaskRun| {
        (
            r.solved(),
            r.scores.last().copied().unwrap_or(0.0),
            -r.iterations.last().map_or(f64::INFINITY, |i| i.actual_cost),
        )
    };
    let best = runs
        .iter()
        .filter(|r| r.last_policy.is_some())
        .reduce(|a, b| if key(b) > key(a) { b } else { a })?;
    let policy = best.last_policy.as_ref()?.to_policy().ok()?;
    Some((best, policy))
}

/// Draws `policy`'s episodes from the swing-up's success-test starts.
fn plot_swing_up(path: &Path, run: &TaskRun, policy: &Policy) -> Result<()> {
    let period = swing_up_params().control_period();
    let steps = run.target.episode_steps;
    let at = |i: usize| i as f64 * period;
    let mut angle = Vec::new();
    let mut position = Vec::new();
    for (k, ep) in success_episodes(policy, steps)?.iter().enumerate() {
        let label = format!("start {k}");
        // the angle unwrapped, from the upright position the episode ends nearest to
        let turns = ep.outputs.last().map_or(0.0, |y| (y[0] / TAU).round());
        angle.push((
            label.clone(),
            ep.outputs
                .iter()
                .enumerate()
                .map(|(i, y)| (at(i), y[0] - TAU * turns))
                .collect(),
        ));
        position.push((
            label,
            ep.outputs
                .iter()
                .enumerate()
                .map(|(i, y)| (at(i), y[2]))
                .collect(),
        ));
    }
    let end = steps as f64 * period;
    let hold = msgp_sim::swing_up::HOLD_SECONDS;
    let tolerance = msgp_sim::swing_up::HOLD_TOLERANCE;
    let panels = [
        SignalPanel {
            label: "angle from the upright it ends at [rad]".to_string(),
            lines: angle,
            band: Some((end - hold, end, -tolerance, tolerance)),
        },
        SignalPanel {
            label: "end effector x [m]".to_string(),
            lines: position,
            band: None,
        },
    ];
    let title = format!(
        "swing-up: {} seed {}, last policy ({} iterations)",
        run.unit.model.name(),
        run.unit.seed,
        run.iterations.len()
    );
    plot_signals(path, &title, &panels)
}

fn cost_point(r: &IterationReport) -> CostPoint {
    CostPoint {
        iteration: r.iteration,
        predicted: r.predicted_cost,
        predicted_std: r.predicted_cost_std,
        actual: r.actual_cost,
        stable: r.success == Some(true),
    }
}

/// The markdown section.
fn render(
    plan: &TaskPlan,
    runs: &[TaskRun],
    provenance: &Provenance,
    scores_png: &Path,
    costs_png: &Path,
    layout: (&LearnerSettings, f64),
) -> String {
    let task = plan.task;
    let target = task.target();
    let mut s = match task {
        PlantTask::PendulumV1 => "# PILCO on Gymnasium's Pendulum-v1, per model\n\n".to_string(),
        PlantTask::SwingUp => {
            "# PILCO on the arm-mounted pendulum's swing-up, per model\n\n".to_string()
        }
    };
    let _ = writeln!(
        s,
        "{} · {} · {:.0} s of learning runs, summed · {}\n",
        provenance.command, provenance.machine, provenance.seconds, provenance.date
    );
    let _ = writeln!(s, "{}\n", made_line(runs));
    let (settings, period) = layout;
    let iterations = settings.iterations;
    let _ = writeln!(
        s,
        "Each run: {} random episode, then {iterations} policy iterations of {} steps \
         ({:.1} s each); the policy is scored after every iteration by the task's own test — \
         {}; solved: {}. \"Solved\" counts runs whose *last* policy (what a user gets) solves \
         the task; \"first\" is the first iteration whose policy did, with the interaction \
         seconds up to it (the random episode included). \"GP searches\" counts, from \
         iteration 2 on, the searches that ran on the GP model (msgp: the prequential choice \
         decides; gp-narx has no other; linear-kf has none).\n",
        settings.random_rollouts,
        target.episode_steps,
        target.episode_steps as f64 * period,
        task.score_name(),
        match task {
            PlantTask::PendulumV1 => "mean return ≥ −200".to_string(),
            PlantTask::SwingUp => format!("all {SWING_UP_STARTS} starts held"),
        },
    );
    s.push_str("| model | solved | first success (iteration, s) per seed | last score per seed | best score per seed | lowest episode cost per seed | GP searches | search failures | run errors |\n");
    s.push_str("|---|---|---|---|---|---|---|---|---|\n");
    for &m in &plan.models {
        let of: Vec<&TaskRun> = runs.iter().filter(|r| r.unit.model == m).collect();
        s.push_str(&model_row(task, m, &of));
    }
    for r in runs.iter().filter(|r| r.error.is_some()) {
        let _ = writeln!(
            s,
            "\n{} seed {} stopped after {} iterations: {}",
            r.unit.model.name(),
            r.unit.seed,
            r.iterations.len(),
            r.error.as_deref().unwrap_or_default()
        );
    }
    let _ = writeln!(
        s,
        "\nThe task's score per iteration (mean ± 1 sd over seeds): `{}`; the episode cost \
         the model predicted and the one measured: `{}`. Per-run records (every iteration's \
         report, the model each search ran on, both models' held-out scores): `{}`.",
        scores_png.display(),
        costs_png.display(),
        plan.dir.display()
    );
    s
}

/// When and where the runs were made, with how many of each (a section may collect records
/// of earlier days, which `msgp reproduce` reuses while the settings are the same).
fn made_line(runs: &[TaskRun]) -> String {
    let mut made: Vec<(&str, usize)> = Vec::new();
    for r in runs {
        let key = if r.made.is_empty() {
            "not recorded"
        } else {
            r.made.as_str()
        };
        match made.iter_mut().find(|(k, _)| *k == key) {
            Some((_, n)) => *n += 1,
            None => made.push((key, 1)),
        }
    }
    let parts: Vec<String> = made
        .iter()
        .map(|(k, n)| format!("{k} ({n} of {})", runs.len()))
        .collect();
    format!("Runs made: {}.", parts.join("; "))
}

/// The table's row of `model` over its runs `of` (seeds in order).
fn model_row(task: PlantTask, model: LoopModel, of: &[&TaskRun]) -> String {
    let per_seed = |f: &dyn Fn(&TaskRun) -> Option<String>| -> String {
        of.iter()
            .map(|r| f(r).unwrap_or_else(|| "—".to_string()))
            .collect::<Vec<_>>()
            .join(", ")
    };
    let score = |v: f64| match task {
        PlantTask::PendulumV1 => format!("{v:.1}"),
        PlantTask::SwingUp => format!("{v:.0}"),
    };
    let first = per_seed(&|r| {
        r.first_success()
            .map(|it| format!("{} ({:.0} s)", it.iteration, it.interaction_seconds))
    });
    let last = per_seed(&|r| r.scores.last().map(|&v| score(v)));
    let best = per_seed(&|r| r.scores.iter().copied().reduce(f64::max).map(score));
    let lowest = per_seed(&|r| {
        r.iterations
            .iter()
            .map(|i| i.actual_cost)
            .reduce(f64::min)
            .map(|c| format!("{c:.1}"))
    });
    let (gp, n) = of
        .iter()
        .map(|r| r.gp_searches())
        .fold((0, 0), |a, b| (a.0 + b.0, a.1 + b.1));
    let searches = match n {
        0 => "—".to_string(),
        n => format!("{gp}/{n} ({:.0} %)", 100.0 * gp as f64 / n as f64),
    };
    let failures: usize = of
        .iter()
        .flat_map(|r| &r.iterations)
        .filter(|i| i.search_failure.is_some() || i.linear_search_failure.is_some())
        .count();
    let solved = of.iter().filter(|r| r.solved()).count();
    let errors = of.iter().filter(|r| r.error.is_some()).count();
    format!(
        "| {} | {solved}/{} | {first} | {last} | {best} | {lowest} | {searches} | {failures} | \
         {errors} |\n",
        model.name(),
        of.len(),
    )
}

#[cfg(test)]
mod tests {
    use super::*;
    use msgp_sim::swing_up::swing_up_task;

    #[test]
    fn the_record_counts_gp_searches_from_the_second_iteration() {
        let report = |iteration, m| IterationReport {
            iteration,
            predicted_cost: 1.0,
            predicted_cost_std: 0.0,
            actual_cost: 1.0,
            expected_cost: None,
            search_model: m,
            linear_fit_failure: None,
            linear_search_failure: None,
            held_out: None,
            interaction_seconds: 0.0,
            success: Some(iteration == 3),
            fit_seconds: 0.0,
            search_seconds: 0.0,
            fit_numerical_stop: None,
            search_failure: None,
            policy: None,
        };
        let (gp, lin) = (Some(SearchModel::Gp), Some(SearchModel::Linear));
        let mut run = TaskRun {
            task: PlantTask::SwingUp,
            unit: Unit {
                model: LoopModel::MsgpFilter,
                seed: 0,
            },
            settings: PlantTask::SwingUp
                .settings(LoopModel::MsgpFilter, 0)
                .expect("preset"),
            target: swing_up_task(),
            iterations: vec![report(1, lin), report(2, lin), report(3, gp), report(4, gp)],
            scores: vec![0.0, 0.0, 5.0, 4.0],
            error: None,
            last_policy: None,
            seconds: 1.0,
            made: String::new(),
        };
        assert_eq!(run.gp_searches(), (2, 3));
        assert_eq!(run.first_success().map(|r| r.iteration), Some(3));
        assert!(!run.solved(), "the last policy did not");
        run.unit.model = LoopModel::GpNarx;
        run.iterations
            .iter_mut()
            .for_each(|r| r.search_model = None);
        assert_eq!(run.gp_searches(), (3, 3));
        run.unit.model = LoopModel::LinearKf;
        assert_eq!(run.gp_searches(), (0, 3));
    }

    #[test]
    fn the_section_says_when_and_where_its_runs_were_made() {
        let run = |made: &str| TaskRun {
            task: PlantTask::SwingUp,
            unit: Unit {
                model: LoopModel::GpNarx,
                seed: 0,
            },
            settings: PlantTask::SwingUp
                .settings(LoopModel::GpNarx, 0)
                .expect("preset"),
            target: swing_up_task(),
            iterations: Vec::new(),
            scores: Vec::new(),
            error: None,
            last_policy: None,
            seconds: 1.0,
            made: made.into(),
        };
        let runs = [
            run("2026-12-06, 2 CPUs (A)"),
            run(""),
            run("2026-12-07, 2 CPUs (B)"),
            run("2026-12-06, 2 CPUs (A)"),
        ];
        assert_eq!(
            made_line(&runs),
            "Runs made: 2026-12-06, 2 CPUs (A) (2 of 4); not recorded (1 of 4); \
             2026-12-07, 2 CPUs (B) (1 of 4)."
        );
        // a record without the field (written before runs kept it) still reads
        let mut json = serde_json::to_value(run("")).expect("serialise");
        assert!(json.get("made").is_none());
        json["made"] = "2026-12-07, 2 CPUs (B)".into();
        let back: TaskRun = serde_json::from_value(json).expect("read back");
        assert_eq!(back.made, "2026-12-07, 2 CPUs (B)");
    }
}
