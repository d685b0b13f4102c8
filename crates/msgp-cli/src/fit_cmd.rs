//! `msgp fit`: fit a model on the first part of each trajectory, save it, and score its free
//! simulation of the held-out rest.

use std::path::{Path, PathBuf};

use anyhow::{Context, bail};
use clap::{Args, ValueEnum};
use msgp_core::data::Trajectory;
use msgp_core::fit::{FitOptimizer, FitOptions, FitProgress, fit};
use msgp_core::gp::MeanFunction;
use msgp_core::gp::integrator::Integrator;
use msgp_core::model::Method;
use msgp_core::model_file::{FitRecord, ModelFile};
use msgp_core::numeric::parallel::Threads;
use serde_json::json;

use crate::dataset::{
    DataArgs, Dataset, Selection, Split, check_lengths, pool, simulate_all, split,
};
use crate::output::{out, out_json};
use crate::plot::plot;
use crate::progress::FitBar;
use crate::report::{metrics_json, metrics_line, trajectories};

/// Default training fraction of each trajectory.
pub const DEFAULT_TRAIN_FRAC: f64 = 0.5;

/// Training method on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum MethodArg {
    /// Multi-step GP: trajectory likelihood (the paper's method).
    Msgp,
    /// One-step GP-NARX, marginal likelihood.
    GpNarx,
    /// One-step GP-NARX with PILCO's hyperparameter penalties.
    PilcoNarx,
    /// Linear-Gaussian window model (no GP) by the exact Kalman-filter likelihood.
    LinearKf,
}

impl From<MethodArg> for Method {
    fn from(m: MethodArg) -> Self {
        match m {
            MethodArg::Msgp => Method::Msgp,
            MethodArg::GpNarx => Method::GpNarx,
            MethodArg::PilcoNarx => Method::PilcoNarx,
            MethodArg::LinearKf => Method::LinearKf,
        }
    }
}

/// Prior mean of the GP on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum MeanArg {
    /// No prior mean (the paper's model).
    Zero,
    /// A trained linear (ARX) map of the window; the GP models what it leaves over.
    Linear,
}

impl From<MeanArg> for MeanFunction {
    fn from(m: MeanArg) -> Self {
        match m {
            MeanArg::Zero => MeanFunction::Zero,
            MeanArg::Linear => MeanFunction::Linear,
        }
    }
}

/// Solver of the MSGP loss on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum OptimizerArg {
    /// Adam (the paper's choice).
    Adam,
    /// L-BFGS with a backtracking line search: several times faster to the same loss; stops by
    /// itself when converged.
    Lbfgs,
}

impl From<OptimizerArg> for FitOptimizer {
    fn from(o: OptimizerArg) -> Self {
        match o {
            OptimizerArg::Adam => FitOptimizer::Adam,
            OptimizerArg::Lbfgs => FitOptimizer::Lbfgs,
        }
    }
}

/// NARX history lengths `l_y,l_u`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct HistoryArg {
    /// Past outputs.
    pub ly: usize,
    /// Past inputs.
    pub lu: usize,
}

/// Parses `LY,LU`.
pub fn parse_history(s: &str) -> Result<HistoryArg, String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    let [ly, lu] = parts.as_slice() else {
        return Err(format!("expected LY,LU (e.g. 2,2), got `{s}`"));
    };
    let ly: usize = ly.parse().map_err(|_| format!("bad l_y `{ly}`"))?;
    let lu: usize = lu.parse().map_err(|_| format!("bad l_u `{lu}`"))?;
    if ly == 0 {
        return Err("l_y must be at least 1".into());
    }
    Ok(HistoryArg { ly, lu })
}

/// Parses `OUTPUT:ORDER[:linear]`.
pub fn parse_integrator(s: &str) -> Result<Integrator, String> {
    let expected = || format!("expected OUTPUT:ORDER or OUTPUT:ORDER:linear (e.g. 0:2), got `{s}`");
    let parts: Vec<&str> = s.split(':').collect();
    let (output, order, linear) = match parts.as_slice() {
        [output, order] => (*output, *order, false),
        [output, order, kind] if kind.trim() == "linear" => (*output, *order, true),
        _ => return Err(expected()),
    };
    let number = |text: &str, what: &str| -> Result<usize, String> {
        text.trim()
            .parse()
            .map_err(|_| format!("bad {what} `{text}`"))
    };
    let (output, order) = (number(output, "output column")?, number(order, "order")?);
    Ok(Integrator {
        output,
        order,
        linear,
    })
}

/// Options of `msgp fit`.
#[derive(Debug, Args)]
pub struct FitArgs {
    #[command(flatten)]
    data: DataArgs,
    /// Training samples at the start of each trajectory; the rest is the test part.
    #[arg(long, value_name = "N", conflicts_with = "train_frac")]
    train: Option<usize>,
    /// Fraction of each trajectory used for training, in (0, 1] [default: 0.5].
    #[arg(long, value_name = "F")]
    train_frac: Option<f64>,
    /// NARX history: past outputs and past inputs in the GP input.
    #[arg(long, value_name = "LY,LU", value_parser = parse_history, default_value = "2,2")]
    history: HistoryArg,
    /// Number of pseudo-inputs [default: min(100, training windows / 2)].
    #[arg(long, value_name = "M")]
    inducing: Option<usize>,
    /// Training method.
    #[arg(long, value_enum, default_value_t = MethodArg::Msgp)]
    method: MethodArg,
    /// Solver iterations: on the trajectory likelihood for msgp [default: 400]; Adam
    /// iterations on the one-step marginal likelihood for gp-narx and pilco-narx [default: 300].
    #[arg(long, value_name = "N")]
    iters: Option<usize>,
    /// Solver of the MSGP loss.
    #[arg(long, value_enum, default_value_t = OptimizerArg::Adam)]
    optimizer: OptimizerArg,
    /// Prior mean of the GP.
    #[arg(long, value_enum, default_value_t = MeanArg::Zero)]
    mean: MeanArg,
    /// Declare output column OUTPUT (0-based) a pure ORDER-fold integrator (e.g. `0:2` for a
    /// position under a commanded acceleration): its own lags get the fixed coefficients of
    /// `(1 − z⁻¹)^ORDER` and enter nothing else. `OUTPUT:ORDER:linear` also drops its GP (its
    /// ORDER-th difference is linear in the window). Needs `--mean linear`; repeat for more
    /// outputs.
    #[arg(long, value_name = "OUTPUT:ORDER[:linear]", value_parser = parse_integrator)]
    integrating: Vec<Integrator>,
    /// Seed of every random choice.
    #[arg(long, default_value_t = 0)]
    seed: u64,
    /// Where to write the model [default: <first data file's stem>.model.json in the current
    /// folder].
    #[arg(long, value_name = "MODEL.json")]
    out: Option<PathBuf>,
    /// Write a PNG of the free simulation of the test part.
    #[arg(long, value_name = "FIT.png")]
    plot: Option<PathBuf>,
    /// Print one JSON object instead of text.
    #[arg(long)]
    json: bool,
    /// No progress output on stderr.
    #[arg(long)]
    quiet: bool,
}

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

/// Runs `msgp fit`.
pub fn run(args: &FitArgs) -> anyhow::Result<()> {
    let data = Dataset::load(
        &args.data.data,
        &Selection {
            inputs: &args.data.input,
            outputs: &args.data.output,
            topic: args.data.topic.as_deref(),
        },
    )?;
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
    let HistoryArg { ly, lu } = args.history;
    let warmup = ly.max(lu);
    check_lengths(&train, warmup, "training")?;
    check_lengths(&test, warmup, "test")?;
    let method = Method::from(args.method);
    let trajs: Vec<Trajectory> = train.iter().map(|p| p.traj.clone()).collect();
    // the same settings as the Python `msgp.Msgp` for the same options
    let settings = FitOptions {
        method,
        ly,
        lu,
        inducing: args.inducing,
        iterations: args.iters,
        seed: args.seed,
        mean: args.mean.into(),
        integrators: args.integrating.clone(),
        optimizer: args.optimizer.into(),
        threads: Threads::from_env()?,
    }
    .settings(&trajs)?;
    let n_train: usize = trajs.iter().map(Trajectory::len).sum();
    let label = format!(
        "{} on {}",
        method.name(),
        args.data.data[0]
            .file_name()
            .map_or_else(String::new, |n| n.to_string_lossy().into_owned())
    );
    let mut bar = FitBar::new(&label, args.quiet || args.json);
    let (model, report) = match fit(&trajs, &settings, &mut |p: &FitProgress| bar.update(p)) {
        Ok(r) => r,
        Err(e) => {
            bar.abandon();
            return Err(e).context(format!(
                "fitting {} on {} ({n_train} training samples, history l_y={ly}, l_u={lu})",
                method.name(),
                files(&args.data.data)
            ));
        }
    };
    // what the model has (a linear-kf model has one idle pseudo-input and no GP)
    let inducing = model.params.pseudo_inputs.nrows();
    bar.finish(&format!("trained in {:.1} s", report.train_seconds));
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
    let saved = file.to_model()?;
    let sims = simulate_all(&saved, &test)?;
    let metrics = pool(
        &sims.iter().map(|s| s.metrics).collect::<Vec<_>>(),
        data.outputs.len(),
    );
    if let Some(p) = &args.plot {
        if sims.is_empty() {
            bail!("--plot needs a test part (lower --train or --train-frac)");
        }
        plot(
            p,
            &format!("{} free simulation", method.name()),
            &data.outputs,
            &sims,
        )?;
    }
    let n_test: usize = test.iter().map(|p| p.traj.len()).sum();
    if args.json {
        let mut v = json!({
            "command": "fit",
            "method": method.name(),
            "n_train": n_train,
            "n_test": n_test,
            "trajectories": data.parts.len(),
            "inputs": data.inputs,
            "outputs": data.outputs,
            "history": [ly, lu],
            "inducing": inducing,
            "seed": args.seed,
            "train_seconds": report.train_seconds,
            "iterations_run": report.iterations_run,
            "best_iteration": report.best_iteration,
            "model": model_path.display().to_string(),
            "plot": args.plot.as_ref().map(|p| p.display().to_string()),
            "data_hash": file.training.data_hash,
        });
        metrics_json(&mut v, metrics.as_ref());
        return out_json(&v);
    }
    let gp = match method {
        Method::LinearKf => "no GP (linear-Gaussian, Kalman-filter likelihood)".to_string(),
        _ => format!("{inducing} pseudo-inputs"),
    };
    let mut text = format!(
        "{}: {}, {n_train} training and {n_test} test samples; inputs {}; outputs {}\n\
         history l_y={ly}, l_u={lu}; {gp}; seed {}\n\
         training time {:.1} s",
        method.name(),
        trajectories(data.parts.len()),
        data.inputs.join(", "),
        data.outputs.join(", "),
        args.seed,
        report.train_seconds,
    );
    if method == Method::Msgp {
        let solver = FitOptimizer::from(args.optimizer).name();
        text.push_str(&format!(
            " ({} {solver} iterations, kept iteration {})",
            report.iterations_run, report.best_iteration
        ));
    }
    text.push('\n');
    text.push_str(&metrics_line("test free simulation", metrics.as_ref()));
    text.push_str(&format!("\nmodel written to {}", model_path.display()));
    if let Some(p) = &args.plot {
        text.push_str(&format!("\nplot written to {}", p.display()));
    }
    out(&text)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn history_parses() {
        assert_eq!(parse_history("2,3"), Ok(HistoryArg { ly: 2, lu: 3 }));
        assert_eq!(parse_history(" 1 , 0 "), Ok(HistoryArg { ly: 1, lu: 0 }));
        assert!(parse_history("0,2").is_err());
        assert!(parse_history("2").is_err());
        assert!(parse_history("a,b").is_err());
    }

    #[test]
    fn default_model_path_uses_the_stem() {
        assert_eq!(
            default_model_path(Path::new("/x/dryer.csv")),
            PathBuf::from("dryer.model.json")
        );
    }
}
