//! `msgp fit`: fit a model on the first part of each trajectory, save it, and score its free
//! simulation of the held-out rest.

use std::ops::ControlFlow;
use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use msgp_core::MsgpError;
use msgp_core::data::Trajectory;
use msgp_core::fit::calibration::Judge;
use msgp_core::fit::history::{HistoryChoice, HistoryEvent, HistorySearch, with_chosen_history};
use msgp_core::fit::{
    FitOptimizer, FitOptions, FitProgress, FitReport, MsgpStart, Overrides, Switches, fit,
};
use msgp_core::model::Method;
use msgp_core::model_file::{FitRecord, ModelFile};
use msgp_core::numeric::parallel::Threads;
use serde_json::json;

use crate::args::{DEFAULT_TRAIN_FRAC, FitArgs, FitHistory, HistoryArg};
use crate::render::output::{out, out_json};
use crate::render::plot::plot;
use crate::render::progress::FitBar;
use crate::render::report::{metrics_json, metrics_line, trajectories};
use msgp_core::data::dataset::{Dataset, Part, Split, check_lengths, split};
use msgp_core::fit::FitSettings;
use msgp_core::model::{Metrics, Model, pool};

/// `<stem>.model.json` in the current folder.
fn default_model_path(data: &Path) -> PathBuf {
    let stem = data
        .file_stem()
        .map_or_else(|| "model".into(), |s| s.to_string_lossy().into_owned());
    PathBuf::from(format!("{stem}.model.json"))
}

/// The data files, comma-separated.
fn files(paths: &[PathBuf]) -> String {
    paths
        .iter()
        .map(|p| p.display().to_string())
        .collect::<Vec<_>>()
        .join(", ")
}

/// A finished fit as `msgp fit` reports it: the model, its report and settings, the file as
/// written, and the model as saved scored on the test part.
struct Fitted {
    method: Method,
    model: Model,
    report: FitReport,
    file: ModelFile,
    model_path: PathBuf,
    metrics: Option<Metrics>,
    n_train: usize,
    n_test: usize,
    warnings: Vec<String>,
}

/// Runs `msgp fit`.
pub fn run(args: &FitArgs) -> anyhow::Result<()> {
    let data = Dataset::load(&args.data.data, &args.data.selection())?;
    let (train, test) = parts(args, &data)?;
    let trajs: Vec<Trajectory> = train.iter().map(|p| p.traj.clone()).collect();
    let (options, history_choice) = match args.history {
        FitHistory::Given(h) => (options(args, h)?, None),
        FitHistory::Auto => {
            // (the search's judge: these options with each candidate's history)
            let judge = options(args, HistoryArg { ly: 1, lu: 1 })?;
            let (options, choice) = choose(&judge, &trajs, args.quiet || args.json)?;
            (options, Some(choice))
        }
    };
    let warmup = options.ly.max(options.lu);
    check_lengths(&train, warmup, "training")?;
    check_lengths(&test, warmup, "test")?;
    let settings = options.settings(&trajs).map_err(flagged)?;
    let mut warnings = data.warnings.clone();
    warnings.extend(options.history_warning(&trajs));
    warnings.extend(options.inducing_warning(&trajs));
    for w in &warnings {
        eprintln!("warning: {w}");
    }
    let (model, mut report) = train_model(args, &settings, &trajs)?;
    report.history_choice = history_choice;
    let file = ModelFile::from_fit(
        &model,
        &FitRecord {
            inputs: &data.inputs,
            outputs: &data.outputs,
            settings: &settings,
            report: &report,
            train: &trajs,
        },
    )?;
    let model_path = args
        .out
        .clone()
        .unwrap_or_else(|| default_model_path(&args.data.data[0]));
    file.write(&model_path)
        .with_context(|| format!("cannot write the model to {}", model_path.display()))?;
    // score with the model as saved, so `msgp eval` reproduces these numbers exactly
    let sims = file.to_model()?.simulate_parts(&test)?;
    let metrics = pool(
        &sims.iter().map(|s| s.metrics).collect::<Vec<_>>(),
        data.outputs.len(),
    );
    if let Some(p) = &args.plot {
        if sims.is_empty() {
            bail!("--plot needs a test part (lower --train or --train-frac)");
        }
        let title = format!("{} free simulation", settings.method().name());
        plot(p, &title, &data.outputs, &sims)?;
    }
    let fitted = Fitted {
        method: settings.method(),
        model,
        report,
        file,
        model_path,
        metrics,
        n_train: trajs.iter().map(Trajectory::len).sum(),
        n_test: test.iter().map(|p| p.traj.len()).sum(),
        warnings,
    };
    match args.json {
        true => out_json(&summary_json(args, &data, &fitted)),
        false => out(&summary_text(args, &data, &fitted)),
    }
}

/// The training and test parts of `data` as the options split it.
fn parts(args: &FitArgs, data: &Dataset) -> anyhow::Result<(Vec<Part>, Vec<Part>)> {
    let how = match (args.train, args.train_frac) {
        (Some(n), _) => Split::Count(n),
        (None, Some(f)) if f > 0.0 && f <= 1.0 => Split::Fraction(f),
        (None, Some(f)) => bail!("--train-frac must be in (0, 1], got {f}"),
        (None, None) => Split::Fraction(DEFAULT_TRAIN_FRAC),
    };
    let (train, test) = split(&data.parts, how);
    if train.is_empty() {
        bail!("no training samples: raise --train or --train-frac");
    }
    Ok((train, test))
}

/// The fit's options from the flags, with history `history`: the same as the Python
/// `msgp.Msgp` makes of the same choices; what the method does not have is refused here, named
/// by its flag ([`FitOptions::check`]).
fn options(args: &FitArgs, history: HistoryArg) -> anyhow::Result<FitOptions> {
    let method = Method::from(args.method);
    let options = FitOptions {
        method,
        ly: history.ly,
        lu: history.lu,
        seed: args.seed,
        integrators: args.integrating.clone(),
        optimizer: args.optimizer.into(),
        start: args.start.map(Into::into),
        threads: Threads::from_env()?,
        segment_length: args.segment_length,
        overrides: Overrides {
            iterations: args.iters,
            inducing: args.inducing,
            mean: args.mean.map(Into::into),
            likelihood: args.likelihood.map(Into::into),
            switches: Switches {
                one_step_objective: args.one_step.map(Into::into),
                calibrate: args.no_calibration.then_some(false),
                blow_up_fallback: args.no_blow_up_fallback.then_some(false),
            },
            settings: None,
        },
    };
    options.check().map_err(flagged)?;
    Ok(options)
}

/// The fit of `trajs` under `settings`, its progress on a bar; a diverging model is a
/// warning (it is saved for inspection and says so itself), a failed fit an error.
fn train_model(
    args: &FitArgs,
    settings: &FitSettings,
    trajs: &[Trajectory],
) -> anyhow::Result<(Model, FitReport)> {
    let method = settings.method();
    let file_name = args.data.data[0]
        .file_name()
        .map_or_else(String::new, |n| n.to_string_lossy().into_owned());
    let mut bar = FitBar::new(
        &format!("{} on {file_name}", method.name()),
        args.quiet || args.json,
    );
    let (model, report) = match fit(trajs, settings, &mut |p: &FitProgress| bar.update(p)) {
        Ok(r) => r,
        Err(e) => {
            bar.abandon();
            let n_train: usize = trajs.iter().map(Trajectory::len).sum();
            return Err(e).context(format!(
                "fitting {} on {} ({n_train} training samples, history l_y={}, l_u={})",
                method.name(),
                files(&args.data.data),
                settings.ly,
                settings.lu
            ));
        }
    };
    bar.finish(&format!("trained in {:.1} s", report.train_seconds));
    if let Some(why) = &report.diverged {
        eprintln!("warning: the fitted model diverges: {why}");
    }
    Ok((model, report))
}

/// `msgp fit --json`'s object.
fn summary_json(args: &FitArgs, data: &Dataset, f: &Fitted) -> serde_json::Value {
    let report = &f.report;
    let mut v = json!({
        "command": "fit",
        "method": f.method.name(),
        "n_train": f.n_train,
        "n_test": f.n_test,
        "trajectories": data.parts.len(),
        "inputs": data.inputs,
        "outputs": data.outputs,
        "history": [f.model.spec.ly, f.model.spec.lu],
        "history_choice": report.history_choice,
        // what the model has (a linear-kf model has one idle pseudo-input and no GP)
        "inducing": f.model.params.pseudo_inputs.nrows(),
        "seed": args.seed,
        "train_seconds": report.train_seconds,
        "iterations_run": report.iterations_run,
        "best_iteration": report.best_iteration,
        "full_data_iteration": report.full_data_iteration,
        "full_data_failed": report.full_data_failed,
        "chosen_recipe": report.chosen_recipe,
        "recipes": report.recipes,
        "calibration": report.calibration,
        "segments": report.segments.map(|(s, count)| json!({
            "length": s.length, "batch": s.batch, "count": count
        })),
        "diverged": report.diverged.is_some(),
        "divergence": report.diverged,
        "model": f.model_path.display().to_string(),
        "plot": args.plot.as_ref().map(|p| p.display().to_string()),
        "data_hash": f.file.training.data_hash,
        "warnings": f.warnings,
    });
    metrics_json(&mut v, f.metrics.as_ref());
    v
}

/// `msgp fit`'s text.
fn summary_text(args: &FitArgs, data: &Dataset, f: &Fitted) -> String {
    let (report, method) = (&f.report, f.method);
    let gp = match method {
        Method::LinearKf => "no GP (linear-Gaussian, Kalman-filter likelihood)".to_string(),
        _ => format!("{} pseudo-inputs", f.model.params.pseudo_inputs.nrows()),
    };
    let mut text = format!(
        "{}: {}, {} training and {} test samples; inputs {}; outputs {}\n\
         history l_y={}, l_u={}; {gp}; seed {}\n\
         training time {:.1} s",
        method.name(),
        trajectories(data.parts.len()),
        f.n_train,
        f.n_test,
        data.inputs.join(", "),
        data.outputs.join(", "),
        f.model.spec.ly,
        f.model.spec.lu,
        args.seed,
        report.train_seconds,
    );
    if method == Method::Msgp {
        let solver = FitOptimizer::from(args.optimizer).name();
        text.push_str(&format!(
            " ({} {solver} iterations, {})",
            report.iterations_run,
            kept(report)
        ));
    }
    text.push('\n');
    if let Some(c) = &report.history_choice {
        text.push_str(&chosen_history(c, method));
        text.push('\n');
    }
    if let Some((s, count)) = report.segments {
        text.push_str(&format!(
            "trained by segments (a long log): {count} segments of up to {} predicted steps, \
             each started from the data, {} per Adam step (--segment-length 0: whole)\n",
            s.length, s.batch
        ));
    }
    if let Some(line) = calibrated(report, &data.outputs) {
        text.push_str(&line);
        text.push('\n');
    }
    if let Some(why) = &report.diverged {
        text.push_str(&format!("WARNING: the fitted model diverges: {why}\n"));
    }
    text.push_str(&metrics_line("test free simulation", f.metrics.as_ref()));
    text.push_str(&format!("\nmodel written to {}", f.model_path.display()));
    if let Some(p) = &args.plot {
        text.push_str(&format!("\nplot written to {}", p.display()));
    }
    text
}

/// `options` with the history chosen from `train` (`--history auto`), its progress on stderr
/// unless `quiet`.
fn choose(
    options: &FitOptions,
    train: &[Trajectory],
    quiet: bool,
) -> anyhow::Result<(FitOptions, HistoryChoice)> {
    let search = HistorySearch::default();
    if !quiet {
        eprintln!(
            "msgp: choosing the history on the training part: every (l_y, l_u) up to {} as a \
             linear model, then the best few and the equal ones each fitted by {} on the first \
             {:.0} % and simulated on the last {:.0} %",
            search.max_lag,
            options.method.name(),
            100.0 * (1.0 - search.validation),
            100.0 * search.validation
        );
    }
    let mut shown = |event: HistoryEvent<'_>| {
        if let (HistoryEvent::Judged(p), false) = (event, quiet) {
            eprintln!(
                "msgp: history ({}, {}): score {} ({}/{} judged, {:.0} s)",
                p.scored.ly,
                p.scored.lu,
                score(p.scored.score),
                p.done,
                p.of,
                p.elapsed
            );
        }
        ControlFlow::Continue(())
    };
    with_chosen_history(options, train, &search, &mut shown)
        .context("choosing the history (--history auto)")
}

/// A score as printed: four decimals, or "diverged".
fn score(s: f64) -> String {
    match s.is_finite() {
        true => format!("{s:.4}"),
        false => "diverged".into(),
    }
}

/// The line that says how the history was chosen.
fn chosen_history(c: &HistoryChoice, method: Method) -> String {
    let runner_up = c
        .judged
        .iter()
        .find(|s| (s.ly, s.lu) != (c.ly, c.lu))
        .map_or_else(String::new, |s| {
            format!("; next ({}, {}) at {}", s.ly, s.lu, score(s.score))
        });
    let own = c
        .judged
        .iter()
        .find(|s| (s.ly, s.lu) == (c.ly, c.lu))
        .map_or(f64::INFINITY, |s| s.score);
    format!(
        "history chosen from the training part: {} candidates fitted by {} and judged by their \
         free simulation of its last 20 % (RMSE per output std); ({}, {}) at {}{runner_up}",
        c.judged.len(),
        method.name(),
        c.ly,
        c.lu,
        score(own)
    )
}

/// Which iterate an MSGP fit returned, in words: the head's (chosen on the validation tail) or
/// that of the final training on all the data ([`msgp_core::fit::MsgpSettings::full_data_iterations`]).
pub fn kept(report: &FitReport) -> String {
    let recipe = report
        .recipes
        .get(report.chosen_recipe)
        .filter(|_| report.recipes.len() > 1)
        .map_or(String::new(), |r| match r.recipe.mean {
            msgp_core::gp::MeanFunction::Zero => " the zero-mean recipe,".to_string(),
            msgp_core::gp::MeanFunction::Linear => " the linear-mean recipe,".to_string(),
        });
    // the zero-mean recipe's final training from the one-step start blew up, and a fallback
    // head's completed (`MsgpSettings::blow_up_fallback`)
    let fallback = report.fallback().map(|r| {
        let head = match r.start {
            MsgpStart::Spread => "the zero-mean recipe's fallback head from the spread start",
            _ => "the zero-mean recipe's fallback head with a linear mean",
        };
        let why = report
            .recipes
            .iter()
            .find_map(|r| r.final_failed.as_deref())
            .unwrap_or("it failed");
        (head, why)
    });
    // a recipe the tail preferred whose model diverged over the training inputs
    let set_aside = report.set_aside().map_or(String::new(), |r| {
        let mean = match r.recipe.mean {
            msgp_core::gp::MeanFunction::Zero => "zero",
            msgp_core::gp::MeanFunction::Linear => "linear",
        };
        let why = r.diverged.as_deref().unwrap_or("it diverges");
        format!(
            "; the {mean}-mean recipe the tail preferred was set aside, its model diverging \
             over the training inputs: {why}"
        )
    });
    // a final training on batches of segments returns the mean of its second half's iterates
    let batched = report.segments.is_some_and(|(s, count)| count > s.batch);
    let iterate = |j: usize| match batched {
        true => format!("the mean of iterations {}–{j}", j.div_ceil(2)),
        false => format!("iteration {j}"),
    };
    let kept = match (
        report.full_data_iteration,
        &report.full_data_failed,
        fallback,
    ) {
        (Some(j), _, Some((head, why))) => format!(
            "kept {} of the final training on all the data of {head} (the zero-mean \
             recipe's from the one-step start failed: {why}); the validation tail chose the \
             zero-mean recipe, then ordered its fallback heads, this one best at its iteration {}",
            iterate(j),
            report.best_iteration
        ),
        (Some(j), _, None) => format!(
            "kept {} of the final training on all the data; the validation tail chose{recipe} best at its iteration {}",
            iterate(j),
            report.best_iteration
        ),
        (None, Some(why), _) => format!(
            "kept iteration {} of the training on the head ({why}: the head's model stands)",
            report.best_iteration
        ),
        (None, None, _) => format!("kept iteration {}", report.best_iteration),
    };
    kept + &set_aside
}

/// The output-variance calibration of an MSGP fit, in words ([`msgp_core::fit::calibration`]);
/// `None` without one.
pub fn calibrated(report: &FitReport, outputs: &[String]) -> Option<String> {
    let c = report.calibration.as_ref()?;
    let added: Vec<String> = c
        .added_std
        .iter()
        .enumerate()
        .map(|(j, s)| match outputs.get(j) {
            Some(name) => format!("{s:.4} ({name})"),
            None => format!("{s:.4}"),
        })
        .collect();
    let judge = match c.judge {
        Judge::Proxy { iteration } => format!(
            "the final training's proxy on the head (its iteration {iteration}) simulating the \
             validation tail"
        ),
        Judge::HeadProxy { iteration } => format!(
            "the head's training repeated on the head's first part (its iteration {iteration}; \
             the final training blew up, the head's model stands) simulating the validation tail"
        ),
        Judge::Head => "the head's model simulating the validation tail".to_string(),
    };
    Some(format!(
        "output variance calibrated by {judge}: added standard deviation {}",
        added.join(", ")
    ))
}

/// A setting the method does not have (or one out of range), named by its flag
/// ([`msgp_core::fit::Overrides`]); other errors as they are.
fn flagged(e: MsgpError) -> anyhow::Error {
    let flag = match &e {
        MsgpError::InvalidSetting { name, .. } => match *name {
            "iterations" => "--iters",
            "inducing" => "--inducing",
            "mean" => "--mean",
            "likelihood" => "--likelihood",
            "one_step_objective" => "--one-step",
            "calibrate" => "--no-calibration",
            "blow_up_fallback" => "--no-blow-up-fallback",
            "start" => "--start",
            "segment_length" => "--segment-length",
            _ => return e.into(),
        },
        _ => return e.into(),
    };
    match e {
        MsgpError::InvalidSetting { reason, .. } => anyhow::anyhow!("{flag}: {reason}"),
        other => other.into(),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn default_model_path_uses_the_stem() {
        assert_eq!(
            default_model_path(Path::new("/x/dryer.csv")),
            PathBuf::from("dryer.model.json")
        );
    }
}
