//! `msgp eval` and `msgp simulate`: free simulation of data files with a saved model (and,
//! with `--filtered`, one-step-ahead filtered predictions beside it).

use anyhow::{Context, bail};
use msgp_core::model::{Model, Rollout};
use msgp_core::model_file::{ModelFile, write_atomically};
use serde_json::json;

use crate::args::{DataArgs, EvalArgs, SimulateArgs};
use crate::render::output::{out, out_json};
use crate::render::plot::plot;
use crate::render::prediction;
use crate::render::report::{metrics_json, metrics_line, trajectories};
use msgp_core::data::dataset::{Dataset, Part, Selection, check_lengths};
use msgp_core::fit::OutputRange;
use msgp_core::model::{Simulated, pool};

/// The model, its file and the data sliced from `from`.
struct Loaded {
    file: ModelFile,
    model: Model,
    data: Dataset,
    parts: Vec<Part>,
}

fn load(model_path: &std::path::Path, args: &DataArgs, from: usize) -> anyhow::Result<Loaded> {
    let file = ModelFile::read(model_path)?;
    let model = file.to_model_at(model_path)?;
    let check = |given: &[String], saved: &[String], what: &str| -> anyhow::Result<()> {
        if !given.is_empty() && given.len() != saved.len() {
            bail!(
                "the model has {} {what}(s) ({}); --{what} names {}",
                saved.len(),
                saved.join(", "),
                given.len()
            );
        }
        Ok(())
    };
    check(&args.input, &file.inputs, "input")?;
    check(&args.output, &file.outputs, "output")?;
    let inputs = if args.input.is_empty() {
        &file.inputs
    } else {
        &args.input
    };
    let outputs = if args.output.is_empty() {
        &file.outputs
    } else {
        &args.output
    };
    let data = Dataset::load(
        &args.data,
        &Selection {
            inputs,
            outputs,
            topic: args.topic.as_deref(),
            time: args.time.into(),
            sort_time: args.sort_time,
        },
    )?;
    for w in &data.warnings {
        eprintln!("warning: {w}");
    }
    let mut parts = Vec::new();
    for p in &data.parts {
        if from >= p.traj.len() {
            bail!(
                "{}: --from {from} is past its {} samples",
                p.label(),
                p.traj.len()
            );
        }
        parts.push(p.slice(from, p.traj.len()));
    }
    check_lengths(&parts, model.spec.warmup(), "simulated")?;
    Ok(Loaded {
        file,
        model,
        data,
        parts,
    })
}

/// Why a free simulation of `sims` (each part simulated from its sample `from`) runs away from
/// its part's measured outputs (the fit's divergence test, held against the evaluated data:
/// `msgp_core::fit::OutputRange`), warned on stderr; `None` when every part stays in range.
fn divergence(sims: &[Simulated], from: usize) -> Option<String> {
    let why = sims.iter().find_map(|s| {
        // the test's steps count from the simulated slice's first sample: say which one
        let what = match from {
            0 => s.part.label(),
            n => format!("{} from sample {n}", s.part.label()),
        };
        OutputRange::of(&[&s.part.traj], s.sim.mean.ncols()).divergence(&s.sim, &what)
    });
    if let Some(why) = &why {
        eprintln!("warning: the model diverges on this data: {why}");
    }
    why
}

/// Runs `msgp eval`.
pub fn run_eval(args: &EvalArgs) -> anyhow::Result<()> {
    let l = load(&args.model, &args.data, args.from)?;
    let rollout = Rollout::from(args.rollout);
    let sims = l.model.simulate_parts_as(&l.parts, rollout)?;
    let diverged = divergence(&sims, args.from);
    let metrics = pool(
        &sims.iter().map(|s| s.metrics).collect::<Vec<_>>(),
        l.model.spec.dy,
    );
    if let Some(p) = &args.plot {
        plot(
            p,
            &format!("{} free simulation{}", l.file.method, rollout_note(rollout)),
            &l.data.outputs,
            &sims,
        )?;
    }
    let filtered = match args.filtered {
        true => {
            let f = l.model.filtered_parts(&l.parts)?;
            pool(
                &f.iter().map(|s| s.metrics).collect::<Vec<_>>(),
                l.model.spec.dy,
            )
        }
        false => None,
    };
    let n: usize = l.parts.iter().map(|p| p.traj.len()).sum();
    if args.json {
        let mut v = json!({
            "command": "eval",
            "model": args.model.display().to_string(),
            "method": l.file.method,
            "history": [l.model.spec.ly, l.model.spec.lu],
            "inducing": l.model.params.pseudo_inputs.nrows(),
            "seed": l.file.training.seed,
            "trajectories": l.parts.len(),
            "n_test": n,
            "from": args.from,
            "rollout": rollout.name(),
            "plot": args.plot.as_ref().map(|p| p.display().to_string()),
            "diverged": diverged.is_some(),
            "divergence": diverged,
        });
        metrics_json(&mut v, metrics.as_ref());
        if args.filtered {
            let mut f = json!({});
            metrics_json(&mut f, filtered.as_ref());
            v["filtered"] = f;
        }
        return out_json(&v);
    }
    let mut text = format!(
        "{} model {} on {} ({n} samples from sample {})\n",
        l.file.method,
        args.model.display(),
        trajectories(l.parts.len()),
        args.from
    );
    text.push_str(&metrics_line(
        &format!("free simulation{}", rollout_note(rollout)),
        metrics.as_ref(),
    ));
    if args.filtered {
        text.push('\n');
        text.push_str(&metrics_line("one-step-ahead filtered", filtered.as_ref()));
    }
    if let Some(why) = &diverged {
        text.push_str(&format!(
            "\nWARNING: the model diverges on this data: {why}"
        ));
    }
    if let Some(p) = &args.plot {
        text.push_str(&format!("\nplot written to {}", p.display()));
    }
    out(&text)
}

/// What the reports add to "free simulation" for `rollout`: nothing for the default.
fn rollout_note(rollout: Rollout) -> &'static str {
    match rollout {
        Rollout::MomentMatching => "",
        Rollout::MomentMatchingIndependent => " (moment matching, independent function draws)",
        Rollout::MeanFeedback => " (mean feedback)",
    }
}

/// Runs `msgp simulate`.
pub fn run_simulate(args: &SimulateArgs) -> anyhow::Result<()> {
    let format = prediction::format_of(&args.out)?;
    let l = load(&args.model, &args.data, args.from)?;
    let rollout = Rollout::from(args.rollout);
    let sims = l.model.simulate_parts_as(&l.parts, rollout)?;
    let diverged = divergence(&sims, args.from);
    let filtered = match args.filtered {
        true => Some(l.model.filtered_parts(&l.parts)?),
        false => None,
    };
    let bytes = prediction::encode(format, &l.data.outputs, &sims, filtered.as_deref())?;
    write_atomically(&args.out, &bytes)
        .with_context(|| format!("cannot write predictions to {}", args.out.display()))?;
    let rows: usize = sims.iter().map(|s| s.sim.mean.nrows()).sum();
    let metrics = pool(
        &sims.iter().map(|s| s.metrics).collect::<Vec<_>>(),
        l.model.spec.dy,
    );
    if args.json {
        let mut v = json!({
            "command": "simulate",
            "model": args.model.display().to_string(),
            "method": l.file.method,
            "out": args.out.display().to_string(),
            "rows": rows,
            "rollout": rollout.name(),
            "trajectories": sims.len(),
            "diverged": diverged.is_some(),
            "divergence": diverged,
        });
        metrics_json(&mut v, metrics.as_ref());
        if let Some(f) = &filtered {
            let pooled = pool(
                &f.iter().map(|s| s.metrics).collect::<Vec<_>>(),
                l.model.spec.dy,
            );
            let mut fj = json!({});
            metrics_json(&mut fj, pooled.as_ref());
            v["filtered"] = fj;
        }
        return out_json(&v);
    }
    out(&format!(
        "wrote {rows} simulated steps of {} to {}\n{}{}",
        trajectories(sims.len()),
        args.out.display(),
        metrics_line(
            &format!("free simulation{}", rollout_note(rollout)),
            metrics.as_ref()
        ),
        diverged
            .map(|why| format!("\nWARNING: the model diverges on this data: {why}"))
            .unwrap_or_default()
    ))
}
