//! `msgp policy init`, `improve` and `eval`: the learning loop without a simulator in it.
//! On a real machine the loop is: run the policy, log the episode, `improve`, repeat; the
//! policy files carry the task and the loop's settings, so `improve` replays the loop's model
//! fits on the logged episodes ([`msgp_core::learner::Learner::from_episodes`]) and takes the
//! step the loop would have taken next.

use std::ops::ControlFlow;
use std::path::Path;

use anyhow::{Context, bail};
use msgp_core::data::dataset::{Dataset, Part, Selection};
use msgp_core::learner::{Episode, LearnEvent, Learner, LearnerSettings, PolicyFamily, TargetTask};
use msgp_core::model::Model;
use msgp_core::model_file::{FitRecord, ModelFile};
use msgp_core::plant::PlantSpec;
use msgp_core::policy_file::{PolicyFile, Prediction, TaskRecord};
use serde_json::json;

use crate::args::{
    DataArgs, ImproveArgs, PolicyCommand, PolicyEvalArgs, PolicyFamilyArg, PolicyInitArgs,
};
use crate::render::output::{out, out_json};

/// Runs `msgp policy …`.
pub fn run(cmd: &PolicyCommand) -> anyhow::Result<()> {
    match cmd {
        PolicyCommand::Improve(args) => improve(args),
        PolicyCommand::Eval(args) => eval(args),
        PolicyCommand::Init(args) => init(args),
    }
}

/// `msgp policy init`: the first policy file of a loop on the machine `--plant` describes.
fn init(args: &PolicyInitArgs) -> anyhow::Result<()> {
    let text = std::fs::read_to_string(&args.plant)
        .with_context(|| format!("reading {}", args.plant.display()))?;
    let plant: PlantSpec = serde_json::from_str(&text)
        .with_context(|| format!("{}: not a plant's signals", args.plant.display()))?;
    plant
        .validate()
        .with_context(|| format!("{}", args.plant.display()))?;
    let widths = args
        .widths
        .iter()
        .enumerate()
        .map(|(j, w)| match w.trim() {
            "none" | "null" => Ok(None),
            w => match w.parse::<f64>() {
                Ok(v) if v.is_finite() && v > 0.0 => Ok(Some(v)),
                _ => bail!("--widths: entry {j} is {w:?}, not a positive number or `none`"),
            },
        })
        .collect::<anyhow::Result<Vec<_>>>()?;
    let target = TargetTask {
        target: args.target.clone(),
        widths,
        width_scales: args.width_scales.clone(),
        episode_steps: args.episode_steps,
        policy_horizon: args.horizon.unwrap_or(args.episode_steps),
        policy: match args.policy {
            PolicyFamilyArg::Rbf => PolicyFamily::Rbf { basis: args.basis },
            PolicyFamilyArg::Linear => PolicyFamily::Linear,
        },
        separate_starts: args.separate_starts,
    };
    let task = target.task(&plant, args.seed)?;
    let mut settings = LearnerSettings::for_plant(&plant);
    settings.seed = args.seed;
    settings.random_rollouts = args.random_episodes;
    settings.one_step_guard = args.one_step_guard;
    if let Some([ly, lu]) = args.history.as_deref() {
        settings.fit.ly = *ly;
        settings.fit.lu = *lu;
    }
    // the loop these make must be one the learner accepts
    let learner = Learner::new(task, settings)?;
    learner.task().validate(&plant)?;
    let mut file = PolicyFile::new(learner.policy());
    file.plant = Some(plant);
    file.task = Some(TaskRecord::of(learner.task()));
    file.settings = Some(learner.settings().clone());
    file.iteration = Some(0);
    file.write(&args.out)?;
    out(&format!(
        "wrote {} ({} policy, {} parameters). Next: log {} episode(s) of your own excitation \
         ({} steps each), then `msgp policy improve --data … --policy {}`.",
        args.out.display(),
        learner.policy().kind(),
        learner.policy().param_len(),
        args.random_episodes,
        args.episode_steps,
        args.out.display()
    ))?;
    Ok(())
}

/// The parts of the first policy file a loop needs.
struct Loop {
    file: PolicyFile,
    plant: PlantSpec,
}

fn first_policy(path: &Path) -> anyhow::Result<Loop> {
    let file = PolicyFile::read(path)?;
    let missing = |what: &str| {
        anyhow::anyhow!(
            "{}: the loop's first policy file needs its {what} (policy files written by `msgp \
             learn-policy --out` and `msgp policy improve` carry it)",
            path.display()
        )
    };
    if file.task.is_none() {
        return Err(missing("task"));
    }
    if file.settings.is_none() {
        return Err(missing("loop settings"));
    }
    let plant = file.plant.clone().ok_or_else(|| missing("plant signals"))?;
    Ok(Loop { file, plant })
}

/// A logged episode checked against the plant: as many outputs and commands, every command
/// within the bounds.
fn episode(
    part: &Part,
    plant: &PlantSpec,
    policy: Option<msgp_core::policy::Policy>,
) -> anyhow::Result<Episode> {
    let traj = &part.traj;
    let (dy, du) = (plant.output_dim(), plant.command_dim());
    if traj.y.ncols() != dy || traj.u.ncols() != du {
        bail!(
            "{}: {} output and {} input columns, the policy's plant has {dy} outputs and {du} \
             commands (choose them with --output and --input)",
            part.label(),
            traj.y.ncols(),
            traj.u.ncols()
        );
    }
    for (j, c) in plant.commands.iter().enumerate() {
        let slack = 1e-9 * (c.high - c.low);
        if let Some(row) = (0..traj.len()).find(|&k| {
            let v = traj.u[(k, j)];
            v < c.low - slack || v > c.high + slack
        }) {
            bail!(
                "{}: row {}: command {j} (`{}`) = {} is outside the plant's bounds [{}, {}]",
                part.label(),
                row + 1,
                c.name,
                traj.u[(row, j)],
                c.low,
                c.high
            );
        }
    }
    let rows = |m: &nalgebra::DMatrix<f64>| -> Vec<Vec<f64>> {
        (0..m.nrows())
            .map(|i| m.row(i).iter().copied().collect())
            .collect()
    };
    Ok(Episode {
        seed: 0,
        outputs: rows(&traj.y),
        commands: rows(&traj.u),
        ended_early: false,
        truncated: false,
        policy,
    })
}

/// The logged episodes: the columns `--output`/`--input` name; without either, the plant's own
/// signal names when the logs have them all (in any column order), else the logs' default
/// columns (`msgp fit`'s) matched to the plant's signals by position when they are as many,
/// which a warning spells out.
fn logged_episodes(data: &DataArgs, plant: &PlantSpec) -> anyhow::Result<Dataset> {
    let chosen = data.selection();
    if !data.output.is_empty() || !data.input.is_empty() {
        return Ok(Dataset::load(&data.data, &chosen)?);
    }
    let outputs: Vec<String> = plant.outputs.iter().map(|o| o.name.clone()).collect();
    let inputs: Vec<String> = plant.commands.iter().map(|c| c.name.clone()).collect();
    let by_name = Selection {
        inputs: &inputs,
        outputs: &outputs,
        ..chosen
    };
    if let Ok(named) = Dataset::load(&data.data, &by_name) {
        return Ok(named);
    }
    let loaded = Dataset::load(&data.data, &chosen)?;
    if loaded.outputs.len() != outputs.len() || loaded.inputs.len() != inputs.len() {
        bail!(
            "the logs do not have the plant's signals as columns (commands {}; outputs {}), \
             and their default columns are {} commands and {} outputs: name the columns with \
             --input and --output",
            inputs.join(", "),
            outputs.join(", "),
            loaded.inputs.len(),
            loaded.outputs.len()
        );
    }
    if loaded.outputs != outputs || loaded.inputs != inputs {
        let pairs = |logged: &[String], signals: &[String]| -> String {
            logged
                .iter()
                .zip(signals)
                .map(|(l, s)| format!("{l} as {s}"))
                .collect::<Vec<_>>()
                .join(", ")
        };
        eprintln!(
            "warning: the logs do not name every signal of the plant; matched by position: \
             commands {}; outputs {} (name them with --input and --output)",
            pairs(&loaded.inputs, &inputs),
            pairs(&loaded.outputs, &outputs)
        );
    }
    Ok(loaded)
}

fn improve(args: &ImproveArgs) -> anyhow::Result<()> {
    let Some((first_path, _)) = args.policies.split_first() else {
        bail!("--policy: at least the loop's first policy file");
    };
    let first = first_policy(first_path)?;
    let (Some(task), Some(settings)) = (&first.file.task, &first.file.settings) else {
        unreachable!("checked by first_policy");
    };
    let mut ran = Vec::new();
    for path in &args.policies[1..] {
        let policy = PolicyFile::read(path)?.to_policy()?;
        task.to_task(policy.clone())?
            .validate(&first.plant)
            .with_context(|| {
                format!(
                    "{}: the policy does not fit the loop of {}",
                    path.display(),
                    first_path.display()
                )
            })?;
        ran.push(policy);
    }
    let data = logged_episodes(&args.data, &first.plant)?;
    for w in &data.warnings {
        eprintln!("warning: {w}");
    }
    let r = settings.random_rollouts;
    if data.parts.len() != r + ran.len() {
        bail!(
            "{} episodes for {r} random ones and {} policy episodes (one per --policy after the \
             first): the episodes and the policies that ran them do not match",
            data.parts.len(),
            ran.len()
        );
    }
    let mut episodes = Vec::new();
    for (k, part) in data.parts.iter().enumerate() {
        let policy = k.checked_sub(r).map(|i| ran[i].clone());
        episodes.push(episode(part, &first.plant, policy)?);
    }
    let task = task.to_task(first.file.to_policy()?)?;
    task.validate(&first.plant)?;
    let quiet = &mut |_: LearnEvent<'_>| ControlFlow::Continue(());
    let mut learner = Learner::from_episodes(task, settings.clone(), episodes, quiet)
        .context("replaying the loop on the logged episodes")?;
    let iteration = ran.len() + 1;
    let step = learner.improve(quiet)?;
    let (policy, prediction, failure) = match &step.searched {
        Ok(found) => {
            let scored =
                (task_steps(&first.file) + 1).saturating_sub(settings.fit.ly.max(settings.fit.lu));
            let steps = &found.steps[..scored.min(found.steps.len())];
            let cost: f64 = steps.iter().map(|(m, _)| m).sum();
            let var: f64 = steps.iter().map(|(_, v)| v).sum();
            let method = step.model.method;
            let model = step
                .search_model
                .map_or(method.name(), |m| m.name(method))
                .to_string();
            (
                found.policy.clone(),
                Some(Prediction {
                    cost,
                    cost_std: var.sqrt(),
                    model,
                }),
                None,
            )
        }
        Err(e) => (learner.policy().clone(), None, Some(e.to_string())),
    };
    let mut next = PolicyFile::new(&policy);
    next.plant = Some(first.plant.clone());
    next.task = first.file.task.clone();
    next.settings = Some(settings.clone());
    next.prediction = prediction.clone();
    next.iteration = Some(iteration);
    next.write(&args.out)?;
    if let Some(path) = &args.model_out {
        save_model(path, &step.model, &step.fit_report, &learner, &data)?;
    }
    let summary = json!({
        "iteration": iteration,
        "episodes": data.parts.len(),
        "policy": args.out,
        "kind": policy.kind(),
        "prediction": prediction,
        "search_failure": failure,
        "fit_seconds": step.fit_seconds,
        "search_seconds": step.search_seconds,
    });
    if args.json {
        return out_json(&summary);
    }
    if let Some(f) = &failure {
        eprintln!(
            "warning: every search start failed on the model ({f}); the running policy is written again"
        );
    }
    out(&match &prediction {
        Some(p) => format!(
            "iteration {iteration}: {} policy → {} (predicted cost {:.2} ± {:.2} on the {} model; fit {:.1} s, search {:.1} s)",
            policy.kind(),
            args.out.display(),
            p.cost,
            p.cost_std,
            p.model,
            step.fit_seconds,
            step.search_seconds
        ),
        None => format!(
            "iteration {iteration}: the running policy → {}",
            args.out.display()
        ),
    })
}

/// The task's episode length in control steps.
fn task_steps(file: &PolicyFile) -> usize {
    file.task.as_ref().map_or(0, |t| t.episode_steps)
}

/// Saves the loop's model of this iteration with its training record.
fn save_model(
    path: &Path,
    model: &Model,
    report: &msgp_core::fit::FitReport,
    learner: &Learner,
    data: &Dataset,
) -> anyhow::Result<()> {
    let train: Vec<_> = learner
        .episodes()
        .iter()
        .map(Episode::trajectory)
        .collect::<Result<_, _>>()?;
    let record = FitRecord {
        inputs: &data.inputs,
        outputs: &data.outputs,
        settings: &learner.settings().fit,
        report,
        train: &train,
    };
    ModelFile::from_fit(model, &record)?.write(path)?;
    Ok(())
}

fn eval(args: &PolicyEvalArgs) -> anyhow::Result<()> {
    let model = ModelFile::read(&args.model)?.to_model()?;
    let file = PolicyFile::read(&args.policy)?;
    let Some(task) = &file.task else {
        bail!(
            "{}: the policy file has no task (its cost, start and horizon)",
            args.policy.display()
        );
    };
    let policy = file.to_policy()?;
    let mut task = task.to_task(policy.clone())?;
    if matches!(
        task.start,
        msgp_core::learner::StartDistribution::Observed { .. }
            | msgp_core::learner::StartDistribution::EachObserved { .. }
    ) {
        bail!(
            "{}: the task's rollouts start where its episodes started; `msgp policy eval` \
             needs a task with a fixed start",
            args.policy.display()
        );
    }
    if let Some(h) = args.horizon {
        if h == 0 {
            bail!("--horizon must be at least 1");
        }
        task.policy_horizon = h;
    } else {
        task.policy_horizon = task.episode_steps;
    }
    task.check_model(&model).with_context(|| {
        format!(
            "{} and {} do not fit together",
            args.model.display(),
            args.policy.display()
        )
    })?;
    let problems = task.problems(&model, &[]);
    let Some(problem) = problems.first() else {
        bail!("the task has no start to roll out from");
    };
    let (total, steps) = problem.evaluate(policy.lift::<f64>().as_ref())?;
    let var: f64 = steps.iter().map(|(_, v)| v).sum();
    let value = json!({
        "expected_cost": total,
        "expected_cost_std": var.sqrt(),
        "steps": steps.len(),
        "kind": policy.kind(),
    });
    if args.json {
        return out_json(&value);
    }
    out(&format!(
        "expected cost {total:.3} ± {:.3} over {} steps ({} policy)",
        var.sqrt(),
        steps.len(),
        policy.kind()
    ))
}
