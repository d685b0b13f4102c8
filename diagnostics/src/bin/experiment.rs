//! Fits one benchmark with one method and prints test metrics; used for the design experiments
//! recorded in docs/design.md.
//!
//! `cargo run --release -p msgp-diagnostics --bin experiment -- [system] [method] [iters] [seed]
//! [complexity] [noise] [lr=F] [lbfgs=true] [every=N] [patience=N] [valfrac=F] [floor=F]
//! [inducing=N] [freeze_x=true] [free_x=true] [nstart=full] [onestep=N] [filter=true] [dump=true]
//! [threads=N] [ly=N] [lu=N] [mean=linear] [init=adam|lbfgs] [alt=false] [sparse=exact|vfe]
//! [from=N] [to=N] [evaltail=true] [evalhead=true] [final=N|none] [calibrate=false] (train
//! on samples `from..to` of the training part only; `evaltail`/`evalhead` evaluate on the
//! training part after `to`/before `from` instead of the test part)
//!`
//!
//! Positional: `system` `sys1`…`sys5` or a real series (`actuator`, `ballbeam`, `drives`,
//! `furnace`, `dryer`; read from `MSGP_DATA_DIR`), default `sys4`; `method` `msgp` (default),
//! `gp-narx` or `pilco-narx`; `iters` default 400; `seed` default 0; `complexity` `pseudo`
//! (default), `none`, `neg` or `pos`; `noise` (synthetic systems) `var` (default) or `std`.
//!
//! Switches (each left at the `FitSettings` default unless given): `lr` the learning rate,
//! `lbfgs=true` the L-BFGS solver, `every` the validation interval, `patience`, `valfrac` the
//! validation fraction, `floor` the noise floor, `inducing` the pseudo-inputs, `freeze_x=true`
//! freeze the pseudo-inputs, `free_x=true` let them move, `nstart=full` start both noises at
//! the one-step noise (default: split it between them), `ly`/`lu` override the benchmark's
//! history, `mean=linear` the linear prior mean, `init` the one-step start's solver,
//! `sparse=exact|vfe` the one-step baselines' objective (`OneStepFitSettings::objective`),
//! `init_sparse=exact|vfe` that of MSGP's one-step start (`MsgpSettings::one_step_objective`), `alt=false` train the settings' recipe alone (default: the protocol's linear-mean recipe
//! beside it, `MsgpSettings::alternative`), `onestep` the one-step iterations, `final` the
//! final training's iterations on all the data (`none`: no final training), `calibrate=false`
//! no calibration, `filter=true` train on the
//! filter likelihood instead of the free run's, `dump=true` print the settings
//! (JSON, stderr), `threads` the fit's threads (default every core; results do not depend on it).

use std::path::Path;

use msgp_core::data::real::{RealSeries, data_dir};
use msgp_core::data::{NoiseScale, SyntheticSystem};
use msgp_core::fit::{
    FitSettings, MethodSettings, MsgpSettings, OneStepFitSettings, OneStepObjective, fit,
};
use msgp_core::loss::Complexity;
use msgp_core::model::Method;
use msgp_diagnostics::{Switches, usage_error};

const USAGE: &str = "experiment [sys1..sys5|actuator|ballbeam|drives|furnace|dryer] \
    [msgp|gp-narx|pilco-narx] [iters] [seed] [pseudo|none|neg|pos] [var|std] [lr=F] [lbfgs=true] \
    [every=N] [patience=N] [valfrac=F] [floor=F] [inducing=N] [freeze_x=true] [free_x=true] \
    [nstart=split|full] [onestep=N] \
    [filter=true] [dump=true] [threads=N] [sparse=exact|vfe] \
    [init_sparse=exact|vfe] [from=N] [to=N] [final=N|none] [calibrate=false]";

const SWITCHES: &[&str] = &[
    "lr",
    "lbfgs",
    "every",
    "patience",
    "valfrac",
    "floor",
    "inducing",
    "freeze_x",
    "free_x",
    "nstart",
    "onestep",
    "filter",
    "dump",
    "threads",
    "ly",
    "lu",
    "mean",
    "init",
    "alt",
    "sparse",
    "init_sparse",
    "from",
    "to",
    "evaltail",
    "evalhead",
    "final",
    "calibrate",
];

enum Bench {
    Synthetic(SyntheticSystem),
    Real(RealSeries),
}

struct Options {
    name: String,
    bench: Bench,
    scale: NoiseScale,
    /// Everything but the history lengths, which the benchmark sets.
    settings: FitSettings,
    dump: bool,
    ly: Option<usize>,
    lu: Option<usize>,
    /// Train on samples `from..to` of the training part only.
    from: Option<usize>,
    to: Option<usize>,
    /// Evaluate on the training part after `to` (from the window before it) instead of the test part.
    evaltail: bool,
    /// Evaluate on the training part before `from` instead of the test part.
    evalhead: bool,
}

/// The arguments: `FitSettings` defaults, the positional arguments, then the switches.
fn options() -> Result<Options, String> {
    let sw = Switches::from_args(6, SWITCHES)?;
    let name = sw.arg::<String>(0, "system")?.unwrap_or("sys4".into());
    let bench = if let Some(k) = name.strip_prefix("sys") {
        let k = k.parse().map_err(|e| format!("system `{name}`: {e}"))?;
        Bench::Synthetic(SyntheticSystem::new(k).map_err(|e| e.to_string())?)
    } else {
        Bench::Real(
            RealSeries::ALL
                .into_iter()
                .find(|s| s.name() == name)
                .ok_or_else(|| format!("unknown series `{name}`"))?,
        )
    };
    let method = match sw.arg::<String>(1, "method")?.as_deref() {
        None | Some("msgp") => Method::Msgp,
        Some("gp-narx") => Method::GpNarx,
        Some("pilco-narx") => Method::PilcoNarx,
        Some(other) => return Err(format!("unknown method `{other}`")),
    };
    let complexity = match sw.arg::<String>(4, "complexity")?.as_deref() {
        None | Some("pseudo") => Complexity::PseudoDataNll,
        Some("none") => Complexity::None,
        Some("neg") => Complexity::NegHalfLogDet,
        Some("pos") => Complexity::HalfLogDet,
        Some(other) => return Err(format!("unknown complexity `{other}`")),
    };
    let scale = match sw.arg::<String>(5, "noise")?.as_deref() {
        None | Some("var") => NoiseScale::Variance,
        Some("std") => NoiseScale::StdDev,
        Some(other) => return Err(format!("unknown noise reading `{other}`")),
    };
    // the MSGP settings; a one-step method takes their pseudo-inputs and one-step iterations
    let mut msgp = MsgpSettings {
        iterations: sw.arg(2, "iters")?.unwrap_or(400),
        complexity,
        ..MsgpSettings::default()
    };
    if let Some(v) = sw.get("lr")? {
        msgp.learning_rate = v;
    }
    if sw.get("lbfgs")? == Some(true) {
        msgp.optimizer = msgp_core::fit::FitOptimizer::Lbfgs;
    }
    if let Some(v) = sw.get("every")? {
        msgp.eval_every = v;
    }
    if let Some(v) = sw.get("patience")? {
        msgp.patience = v;
    }
    if let Some(v) = sw.get("valfrac")? {
        msgp.validation_fraction = v;
    }
    if let Some(v) = sw.get("floor")? {
        msgp.noise_floor = v;
    }
    if let Some(v) = sw.get("inducing")? {
        msgp.inducing = v;
    }
    if sw.get("freeze_x")? == Some(true) {
        msgp.frozen.push(msgp_core::gp::ParamGroup::PseudoInputs);
    }
    if sw.get::<String>("mean")?.as_deref() == Some("linear") {
        msgp.mean = msgp_core::gp::MeanFunction::Linear;
    }
    match sw.get::<String>("init")?.as_deref() {
        None => {}
        Some("adam") => msgp.one_step_solver = msgp_core::fit::OneStepSolver::Adam,
        Some("lbfgs") => msgp.one_step_solver = msgp_core::fit::OneStepSolver::Lbfgs,
        Some(other) => return Err(format!("unknown init `{other}`")),
    }
    if sw.get("alt")? == Some(false) {
        msgp.alternative = None;
    }
    if sw.get("free_x")? == Some(true) {
        msgp.frozen.clear();
    }
    match sw.get::<String>("nstart")?.as_deref() {
        None | Some("split") => {}
        Some("full") => msgp.noise_start = msgp_core::fit::NoiseStart::Full,
        Some(other) => return Err(format!("unknown noise start `{other}`")),
    }
    if let Some(v) = sw.get("onestep")? {
        msgp.one_step_iterations = v;
    }
    match sw.get::<String>("final")?.as_deref() {
        None => {}
        Some("none") => msgp.full_data_iterations = None,
        Some(n) => {
            msgp.full_data_iterations = Some(n.parse().map_err(|e| format!("final `{n}`: {e}"))?)
        }
    }
    if sw.get("calibrate")? == Some(false) {
        msgp.calibrate = false;
    }
    if sw.get("filter")? == Some(true) {
        msgp.likelihood = msgp_core::loss::Likelihood::Filter;
    }
    let mut one_step = OneStepFitSettings {
        inducing: msgp.inducing,
        mean: msgp.mean,
        iterations: msgp.one_step_iterations,
        ..match method {
            Method::PilcoNarx => OneStepFitSettings::pilco(),
            _ => OneStepFitSettings::default(),
        }
    };
    match sw.get::<String>("init_sparse")?.as_deref() {
        None => {}
        Some("exact") => msgp.one_step_objective = OneStepObjective::Exact,
        Some("vfe") => msgp.one_step_objective = OneStepObjective::Vfe,
        Some(other) => return Err(format!("unknown sparse start `{other}`")),
    }
    match sw.get::<String>("sparse")?.as_deref() {
        None => {}
        Some("exact") => one_step.objective = OneStepObjective::Exact,
        Some("vfe") => one_step.objective = OneStepObjective::Vfe,
        Some(other) => return Err(format!("unknown sparse fit `{other}`")),
    }
    let settings = FitSettings {
        seed: sw.arg(3, "seed")?.unwrap_or(0),
        threads: sw.threads()?,
        method: match method {
            Method::GpNarx => MethodSettings::GpNarx(one_step),
            Method::PilcoNarx => MethodSettings::PilcoNarx(one_step),
            _ => msgp.into(),
        },
        ..FitSettings::default()
    };
    Ok(Options {
        name,
        bench,
        scale,
        settings,
        dump: sw.get("dump")? == Some(true),
        ly: sw.get("ly")?,
        lu: sw.get("lu")?,
        from: sw.get("from")?,
        to: sw.get("to")?,
        evaltail: sw.get("evaltail")? == Some(true),
        evalhead: sw.get("evalhead")? == Some(true),
    })
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let o = options().unwrap_or_else(|e| usage_error(USAGE, &e));
    let seed = o.settings.seed;
    let mut bench = match &o.bench {
        Bench::Synthetic(s) => s.generate(seed, o.scale)?,
        Bench::Real(s) => s.load(&data_dir(Path::new(".")))?,
    };
    if let (true, Some(to)) = (o.evaltail, o.to) {
        let l = o.ly.unwrap_or(bench.ly).max(o.lu.unwrap_or(bench.lu));
        bench.test = bench.train.slice(to - l, bench.train.len());
    }
    if let (true, Some(from)) = (o.evalhead, o.from) {
        bench.test = bench.train.slice(0, from);
    }
    if o.from.is_some() || o.to.is_some() {
        let n = bench.train.len();
        bench.train = bench
            .train
            .slice(o.from.unwrap_or(0), o.to.unwrap_or(n).min(n));
    }
    let settings = FitSettings {
        ly: o.ly.unwrap_or(bench.ly),
        lu: o.lu.unwrap_or(bench.lu),
        ..o.settings
    };
    if o.dump {
        eprintln!("{}", serde_json::to_string(&settings)?);
    }
    let dump = o.dump;
    let mut rise: (f64, f64, usize) = (f64::NAN, 0.0, 0);
    let (model, report) = fit(std::slice::from_ref(&bench.train), &settings, &mut |p| {
        // (lowest loss so far, largest rise above it, its iteration)
        if p.iteration == 0 {
            rise = (p.loss, 0.0, 0);
        } else {
            if p.loss - rise.0 > rise.1 {
                rise = (rise.0, p.loss - rise.0, p.iteration);
            }
            rise.0 = rise.0.min(p.loss);
        }
        if let (Some(v), true) = (p.validation, p.iteration % 50 == 0) {
            eprintln!(
                "it {:4} loss {:.4} val {:.4} ({:.1}s)",
                p.iteration, p.loss, v, p.elapsed
            );
        } else if p.validation.is_none() && (p.iteration % 20 == 0 || p.iteration < 24) {
            eprintln!(
                "it {:4} loss {:.4} ({:.1}s)",
                p.iteration, p.loss, p.elapsed
            );
        }
    })?;
    if dump {
        let p = &model.params;
        eprintln!(
            "sf2 {:.4e} sx2 {:.4e} sy2 {:.4e} log_l {:?} targets |.|max {:.3}",
            p.log_signal_var.map(f64::exp),
            p.log_process_noise.map(f64::exp),
            p.log_obs_noise.map(f64::exp),
            p.log_lengthscales.map(|v| (v * 100.0).round() / 100.0),
            p.pseudo_targets.amax(),
        );
        for (i, l, v) in &report.history {
            eprintln!("hist {i} {l:.4} {v:.4}");
        }
    }
    eprintln!(
        "last stage: lowest loss {:.4}, largest rise above the lowest before it {:.4} at iteration {}",
        rise.0, rise.1, rise.2
    );
    let m = model.evaluate(&bench.test)?;
    let mf = model.evaluate_as(&bench.test, msgp_core::model::Rollout::MeanFeedback)?;
    if !report.recipes.is_empty() {
        eprintln!(
            "recipes {:?} chose {}",
            report
                .recipes
                .iter()
                .map(|r| r.validation)
                .collect::<Vec<_>>(),
            report.chosen_recipe
        );
    }
    println!(
        "{} {} rmse {:.4} (mean feedback {:.4}) nll {:.3} cov {:.3} best_it {} of {} val {:.4} \
         time {:.1}s jitter {:?}{}",
        o.name,
        settings.method().name(),
        m.rmse,
        mf.rmse,
        m.nll,
        m.coverage_2sigma,
        report.best_iteration,
        report.iterations_run,
        report
            .history
            .iter()
            .map(|h| h.2)
            .fold(f64::INFINITY, f64::min),
        report.train_seconds,
        report.jitter,
        report
            .diverged
            .map_or_else(String::new, |d| format!(" DIVERGED: {d}"))
    );
    Ok(())
}
