//! Every command-line type of `msgp`: the commands, their options and the value parsers (one
//! file, as ripgrep and uv keep theirs). The commands themselves live in [`crate::commands`].
//!
//! The doc comments here are clap's help text, read in a terminal: units stay in plain brackets
//! (`[s]`, `[rad]`) and placeholders in angle brackets (`<model>`), which rustdoc would otherwise
//! take for links and HTML.
#![allow(rustdoc::broken_intra_doc_links, rustdoc::invalid_html_tags)]

use std::path::PathBuf;

use clap::{Args, Parser, Subcommand, ValueEnum};
use msgp_core::data::table::TimeSource;
use msgp_core::fit::{FitOptimizer, MsgpStart, OneStepObjective};
use msgp_core::gp::MeanFunction;
use msgp_core::gp::integrator::Integrator;
use msgp_core::learner::LoopModel;
use msgp_core::loss::Likelihood;
use msgp_core::model::{Method, Rollout};
use msgp_reproduce::table1::TableHistory;
use msgp_sim::Saturation;
use msgp_sim::learn::{Budget, LearnSettings};
use msgp_sim::plant_tasks::PlantTask;

/// Gaussian-process dynamics models optimised for long-term predictions (MSGP).
#[derive(Debug, Parser)]
#[command(name = "msgp", version, about)]
pub struct Cli {
    #[command(subcommand)]
    pub command: Command,
}

#[derive(Debug, Subcommand)]
pub enum Command {
    /// Fit a model on CSV or MCAP data, save it, and score it on the held-out part.
    Fit(Box<FitArgs>),
    /// Free simulation of data files with a saved model: RMSE, NLL and 2σ coverage.
    Eval(Box<EvalArgs>),
    /// Free simulation with a saved model, written as CSV (mean, std, measured per step).
    Simulate(Box<SimulateArgs>),
    /// Learn a controller with PILCO on a simulated system (MSGP, GP-NARX or linear-kf models).
    LearnPolicy(Box<LearnArgs>),
    /// Reproduce the paper's results.
    #[command(subcommand)]
    Reproduce(ReproduceCommand),
    /// Generate the paper's synthetic system 4, fit GP-NARX and MSGP, print test RMSE.
    Demo(DemoArgs),
    /// Simulate the pole on the robot end effector (rapier), run stability tests.
    #[command(subcommand)]
    Sim(Box<SimCommand>),
    /// Policy files: the next policy from the episodes logged on a machine, a policy's
    /// predicted cost on a model.
    #[command(subcommand)]
    Policy(PolicyCommand),
}

/// `msgp policy …`.
#[derive(Debug, Subcommand)]
pub enum PolicyCommand {
    /// The next policy from the episodes logged so far (a real robot's loop: run the policy,
    /// log the episode, improve, repeat): the loop's model fits replayed on the episodes, then
    /// one fit and search.
    Improve(Box<ImproveArgs>),
    /// A policy's expected cost on a model (the task of the policy file).
    Eval(PolicyEvalArgs),
    /// The loop's first policy file for a machine no simulator describes: its signals, the
    /// task (target, widths, episode and horizon) and the loop's settings, with the first
    /// policy drawn from the seed. Then: log the random episodes, `improve`, repeat.
    Init(Box<PolicyInitArgs>),
}

/// The policy family of `msgp policy init`.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum PolicyFamilyArg {
    /// PILCO's RBF network on the observation (`--basis` functions).
    Rbf,
    /// A linear feedback with offset on the observation.
    Linear,
}

/// Options of `msgp policy init`.
#[derive(Debug, Args)]
pub struct PolicyInitArgs {
    /// The machine's signals as JSON: `{"period": s, "commands": [{"name", "low", "high"}],
    /// "outputs": [{"name", "angle"?, "low"?, "high"?}]}` (docs/policy-format.md, `plant`).
    #[arg(long, value_name = "FILE")]
    pub plant: PathBuf,
    /// The cost's target per output, comma-separated (an angle in radians: costed on its
    /// pole's tip).
    #[arg(
        long,
        value_name = "Y,…",
        value_delimiter = ',',
        allow_hyphen_values = true
    )]
    pub target: Vec<f64>,
    /// The cost's width per output, comma-separated; `none`: the output does not count.
    #[arg(long, value_name = "W,…", value_delimiter = ',')]
    pub widths: Vec<String>,
    /// PILCO's several widths: the cost is the mean of the saturating costs at the widths
    /// times each of these scales, comma-separated (e.g. `1,4`: a wide cost's slope far from
    /// the target, the widths' precision near it).
    #[arg(long, value_name = "S,…", value_delimiter = ',', default_value = "1")]
    pub width_scales: Vec<f64>,
    /// Control steps of an episode.
    #[arg(long, value_name = "N")]
    pub episode_steps: usize,
    /// Control steps of the rollouts the policy is optimised on [default: the episode's].
    #[arg(long, value_name = "N")]
    pub horizon: Option<usize>,
    /// The policy the search moves.
    #[arg(long, value_enum, default_value_t = PolicyFamilyArg::Rbf)]
    pub policy: PolicyFamilyArg,
    /// Basis functions of the RBF network.
    #[arg(long, value_name = "N", default_value_t = 30)]
    pub basis: usize,
    /// Search from each of the latest N episodes' first observations (for episodes that start
    /// anywhere) instead of one Gaussian over them.
    #[arg(long, value_name = "N")]
    pub separate_starts: Option<usize>,
    /// Episodes of your own excitation before the first policy episode.
    #[arg(long, value_name = "N", default_value_t = 1)]
    pub random_episodes: usize,
    /// The model's window `l_y,l_u`.
    #[arg(long, value_name = "LY,LU", value_delimiter = ',', num_args = 2)]
    pub history: Option<Vec<usize>>,
    /// Also fit the MSGP model's one-step start (GP-NARX) every iteration, and search on it
    /// whenever the MSGP model's closed-loop free run of the latest episode, which neither had
    /// seen, was no better than that start's.
    #[arg(long)]
    pub one_step_guard: bool,
    /// Seed of the first policy's draw and of the loop's fits and searches.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// The policy file to write (atomically).
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
}

/// Options of `msgp policy improve`.
#[derive(Debug, Args)]
pub struct ImproveArgs {
    /// The episodes so far, in the order they ran (`--data` repeated): first the loop's
    /// random episodes, then one per policy file after the first.
    #[command(flatten)]
    pub data: DataArgs,
    /// The policy files so far, in order (repeat): the loop's first policy (its task and
    /// settings), then the policy each policy episode ran; the last produced the last episode.
    #[arg(long = "policy", value_name = "FILE", required = true)]
    pub policies: Vec<PathBuf>,
    /// The next policy file.
    #[arg(long, value_name = "FILE")]
    pub out: PathBuf,
    /// Also save the loop's model of this iteration (the model file of `msgp fit`).
    #[arg(long, value_name = "FILE")]
    pub model_out: Option<PathBuf>,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
}

/// Options of `msgp policy eval`.
#[derive(Debug, Args)]
pub struct PolicyEvalArgs {
    /// The model file (`msgp fit --out`, `msgp policy improve --model-out`).
    #[arg(long, value_name = "FILE")]
    pub model: PathBuf,
    /// The policy file (its task says the cost, the start and the horizon).
    #[arg(long, value_name = "FILE")]
    pub policy: PathBuf,
    /// Control steps of the prediction [default: the task's episode].
    #[arg(long, value_name = "N")]
    pub horizon: Option<usize>,
    /// Print the result as JSON.
    #[arg(long)]
    pub json: bool,
}

/// Options that select the data (shared by `fit`, `eval` and `simulate`).
#[derive(Debug, Args)]
pub struct DataArgs {
    /// Data file: CSV with a header line, or MCAP (`.mcap`). Repeat for several trajectories.
    #[arg(long = "data", value_name = "FILE", required = true)]
    pub data: Vec<PathBuf>,
    /// Input columns, comma-separated (MCAP: TOPIC:FIELD, or FIELD with --topic).
    #[arg(long, value_name = "COL,...", value_delimiter = ',')]
    pub input: Vec<String>,
    /// Output columns, comma-separated (MCAP: TOPIC:FIELD, or FIELD with --topic).
    #[arg(long, value_name = "COL,...", value_delimiter = ',')]
    pub output: Vec<String>,
    /// MCAP: topic of bare field names in --input/--output.
    #[arg(long, value_name = "TOPIC")]
    pub topic: Option<String>,
    /// MCAP: the time of a message: its log time, or the `header.stamp` inside it (ROS
    /// messages with a header; every selected topic must have one).
    #[arg(long, value_name = "SOURCE", default_value = "log")]
    pub time: TimeArg,
    /// CSV: sort each trajectory's rows by the time column instead of refusing rows written
    /// out of order (a warning says how many moved; repeated times are still an error).
    #[arg(long)]
    pub sort_time: bool,
}

/// Where MCAP message times come from, on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum TimeArg {
    /// The MCAP log time.
    Log,
    /// The message's `header.stamp`.
    Header,
}

impl From<TimeArg> for TimeSource {
    fn from(t: TimeArg) -> Self {
        match t {
            TimeArg::Log => TimeSource::Log,
            TimeArg::Header => TimeSource::Header,
        }
    }
}

/// Default training fraction of each trajectory.
pub const DEFAULT_TRAIN_FRAC: f64 = 0.5;

/// Training method on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum MethodArg {
    /// Multi-step GP: trajectory likelihood (the paper's method).
    Msgp,
    /// One-step GP-NARX: a sparse GP by its marginal likelihood (the variational bound).
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

/// Where Table 1's fits take their history from, on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum TableHistoryArg {
    /// The paper's Table 3.
    Paper,
    /// Chosen on each fit's training part alone, as `msgp fit --history auto` does (minutes
    /// per MSGP fit); writes its own section of the results file.
    Auto,
}

impl From<TableHistoryArg> for TableHistory {
    fn from(h: TableHistoryArg) -> Self {
        match h {
            TableHistoryArg::Paper => TableHistory::Paper,
            TableHistoryArg::Auto => TableHistory::Auto,
        }
    }
}

/// Where an MSGP fit starts, on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum StartArg {
    /// The one-step sparse GP-NARX fit.
    OneStep,
    /// The linear-kf model under a GP that starts at zero.
    LinearKf,
    /// The one-step fit's starting point, not optimised (length-scales at the windows'
    /// spread): for densely sampled outputs whose one-step fit ignores the inputs.
    Spread,
}

impl From<StartArg> for MsgpStart {
    fn from(s: StartArg) -> Self {
        match s {
            StartArg::OneStep => MsgpStart::OneStep,
            StartArg::LinearKf => MsgpStart::LinearKf,
            StartArg::Spread => MsgpStart::Spread,
        }
    }
}

/// The objective of a one-step fit on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum OneStepArg {
    /// The full GP's marginal likelihood, then projected onto k-means pseudo-inputs.
    Exact,
    /// The variational sparse GP's bound: hyperparameters and pseudo-inputs jointly.
    Vfe,
}

impl From<OneStepArg> for OneStepObjective {
    fn from(o: OneStepArg) -> Self {
        match o {
            OneStepArg::Exact => OneStepObjective::Exact,
            OneStepArg::Vfe => OneStepObjective::Vfe,
        }
    }
}

/// The MSGP fit's likelihood on the command line.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum LikelihoodArg {
    /// The paper's: a free simulation's per-step marginals.
    FreeRun,
    /// The joint density of the observations by the moment-matched filter.
    Filter,
}

impl From<LikelihoodArg> for Likelihood {
    fn from(l: LikelihoodArg) -> Self {
        match l {
            LikelihoodArg::FreeRun => Likelihood::FreeRun,
            LikelihoodArg::Filter => Likelihood::Filter,
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

/// The history of `msgp fit`: given, or chosen from the training data.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FitHistory {
    /// `LY,LU`.
    Given(HistoryArg),
    /// `auto`: [`msgp_core::fit::history::with_chosen_history`].
    Auto,
}

/// Parses `LY,LU` or `auto`.
pub fn parse_fit_history(s: &str) -> Result<FitHistory, String> {
    match s.trim() {
        "auto" => Ok(FitHistory::Auto),
        _ => parse_history(s)
            .map(FitHistory::Given)
            .map_err(|e| format!("{e}, or `auto`")),
    }
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
    pub data: DataArgs,
    /// Training samples at the start of each trajectory; the rest is the test part.
    #[arg(long, value_name = "N", conflicts_with = "train_frac")]
    pub train: Option<usize>,
    /// Fraction of each trajectory used for training, in (0, 1] [default: 0.5].
    #[arg(long, value_name = "F")]
    pub train_frac: Option<f64>,
    /// NARX history: past outputs and past inputs in the GP input; `auto`: chosen on the
    /// training part alone (its first 80 % fits, its last 20 % judges: every history up to 10
    /// lags as a linear model, then the best few and the equal ones `(l, l)` each fitted by
    /// the method itself and judged by their free simulation; the shortest within one standard
    /// error of the best wins). `auto` takes one fit per judged candidate (minutes for msgp).
    #[arg(long, value_name = "LY,LU|auto", value_parser = parse_fit_history, default_value = "2,2")]
    pub history: FitHistory,
    /// Number of pseudo-inputs [default: min(100, training windows / 2)].
    #[arg(long, value_name = "M")]
    pub inducing: Option<usize>,
    /// MSGP on a long log: train on segments of N predicted steps, each started from the data,
    /// 2 of them per Adam step; 0: every trajectory whole [default: 1000 when the training part
    /// has more than 4000 windows, else whole].
    #[arg(long, value_name = "N")]
    pub segment_length: Option<usize>,
    /// Training method.
    #[arg(long, value_enum, default_value_t = MethodArg::Msgp)]
    pub method: MethodArg,
    /// The most solver iterations of any one training: for msgp, of each training on the
    /// trajectory likelihood (without it, the early-stopped run on the head stops by its tail
    /// within 1000 and the final training on all the data runs 400); for gp-narx and
    /// pilco-narx, L-BFGS on the one-step marginal likelihood, which stops by itself when
    /// converged [default: 300]; for linear-kf, L-BFGS on the filter likelihood [default: 400].
    #[arg(long, value_name = "N")]
    pub iters: Option<usize>,
    /// Solver of the MSGP loss.
    #[arg(long, value_enum, default_value_t = OptimizerArg::Adam)]
    pub optimizer: OptimizerArg,
    /// Likelihood of the MSGP fit: free-run (the paper's product of a free simulation's
    /// marginals) or filter (the joint density of the observations by the moment-matched
    /// filter) [default: free-run].
    #[arg(long, value_enum)]
    pub likelihood: Option<LikelihoodArg>,
    /// Where the MSGP training starts: one-step (the sparse GP-NARX fit, the paper's; where the
    /// zero-mean recipe's final training from it blows up, that recipe's fallback heads train,
    /// from the spread start and with a linear mean), spread (the one-step fit's own starting
    /// point, length-scales at the windows' spread, not optimised) or linear-kf (the linear-Gaussian window model by the
    /// Kalman-filter likelihood under a GP that starts at zero, as the filtered policy-learning
    /// loop fits; implies `--mean linear`) [default: one-step].
    #[arg(long, value_enum)]
    pub start: Option<StartArg>,
    /// How the one-step fit (gp-narx, pilco-narx, and msgp's one-step start) gets its
    /// hyperparameters and pseudo-inputs: vfe (the variational sparse GP's bound, both jointly)
    /// or exact (the full GP's marginal likelihood, then k-means pseudo-inputs) [default: vfe for
    /// gp-narx, exact for pilco-narx and for msgp's start].
    #[arg(long = "one-step", value_enum, value_name = "OBJECTIVE")]
    pub one_step: Option<OneStepArg>,
    /// msgp: report the free simulation's variance as the model predicts it, without the
    /// output-variance calibration the default protocol judges on the validation tail
    /// (`docs/experiments/2026-12-05-honest-uncertainty-on-data-the-model-never-saw.md`, "Honest uncertainty on data the model never saw").
    #[arg(long)]
    pub no_calibration: bool,
    /// msgp: keep the one-step head's model when the zero-mean recipe's final training on all
    /// the data blows up, instead of training that recipe's fallback heads (from the spread
    /// start; with a linear mean) and returning the first whose final training completes
    /// (`docs/experiments/2026-12-05-a-fallback-with-a-linear-mean.md`, "A fallback with a linear mean").
    #[arg(long)]
    pub no_blow_up_fallback: bool,
    /// Prior mean of the GP [default: msgp trains a zero-mean and a linear-mean recipe and
    /// keeps the one with the lower validation NLL; the baselines: zero].
    #[arg(long, value_enum)]
    pub mean: Option<MeanArg>,
    /// Declare output column OUTPUT (0-based) a pure ORDER-fold integrator (e.g. `0:2` for a
    /// position under a commanded acceleration): its own lags get the fixed coefficients of
    /// `(1 − z⁻¹)^ORDER` and enter nothing else. `OUTPUT:ORDER:linear` also drops its GP (its
    /// ORDER-th difference is linear in the window). Needs `--mean linear`; repeat for more
    /// outputs.
    #[arg(long, value_name = "OUTPUT:ORDER[:linear]", value_parser = parse_integrator)]
    pub integrating: Vec<Integrator>,
    /// Seed of every random choice.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Where to write the model [default: <first data file's stem>.model.json in the current
    /// folder].
    #[arg(long, value_name = "MODEL.json")]
    pub out: Option<PathBuf>,
    /// Write a PNG of the free simulation of the test part.
    #[arg(long, value_name = "FIT.png")]
    pub plot: Option<PathBuf>,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
    /// No progress output on stderr.
    #[arg(long)]
    pub quiet: bool,
}

/// Options of `msgp eval`.
#[derive(Debug, Args)]
pub struct EvalArgs {
    /// Model file written by `msgp fit`.
    #[arg(long, value_name = "MODEL.json")]
    pub model: PathBuf,
    #[command(flatten)]
    pub data: DataArgs,
    /// Simulate each trajectory from sample N on (the first max(l_y, l_u) samples from N seed
    /// the simulation).
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub from: usize,
    /// How the simulation propagates predictions: `mm` moment matching (the paper's means;
    /// variances that keep the function's uncertainty correlated over time), `mm-independent`
    /// the paper's moment matching as it is, `mean` feeding back predicted means only (how
    /// one-step GP-NARX baselines are often scored).
    #[arg(long, value_enum, default_value_t = RolloutArg::Mm)]
    pub rollout: RolloutArg,
    /// Write a PNG of the free simulation.
    #[arg(long, value_name = "OUT.png")]
    pub plot: Option<PathBuf>,
    /// Also score one-step-ahead filtered predictions (each step's prediction given the
    /// measured outputs before it, by the moment-matched filter of `--likelihood filter`),
    /// beside the free simulation.
    #[arg(long)]
    pub filtered: bool,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
}

/// Options of `msgp simulate`.
#[derive(Debug, Args)]
pub struct SimulateArgs {
    /// Model file written by `msgp fit`.
    #[arg(long, value_name = "MODEL.json")]
    pub model: PathBuf,
    #[command(flatten)]
    pub data: DataArgs,
    /// Simulate each trajectory from sample N on.
    #[arg(long, value_name = "N", default_value_t = 0)]
    pub from: usize,
    /// How the simulation propagates predictions (see `msgp eval --rollout`).
    #[arg(long, value_enum, default_value_t = RolloutArg::Mm)]
    pub rollout: RolloutArg,
    /// Output file; the extension chooses the format. CSV: `t, <output>_mean, <output>_std,
    /// <output>` per simulated step (and an `episode` column first when there are several
    /// trajectories). MCAP: one JSON message per step on `/msgp/prediction` with the measured
    /// value, mean, std and mean ± 2 std of every output, for Foxglove's plot panel.
    #[arg(long, value_name = "PRED.csv|PRED.mcap")]
    pub out: PathBuf,
    /// Add the one-step-ahead filtered predictions as `<output>_filtered_mean,
    /// <output>_filtered_std` columns (see `msgp eval --filtered`).
    #[arg(long)]
    pub filtered: bool,
    /// Print a JSON summary instead of text.
    #[arg(long)]
    pub json: bool,
}

/// How a free simulation propagates the model's predictions.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum RolloutArg {
    /// Moment matching over the window's joint Gaussian (the paper's means), with variances
    /// that keep the GP's uncertainty about its function correlated over time.
    Mm,
    /// The paper's moment matching as it is: each step's function uncertainty independent.
    MmIndependent,
    /// Predicted means fed back, no uncertainty propagated.
    Mean,
}

impl From<RolloutArg> for Rollout {
    fn from(r: RolloutArg) -> Self {
        match r {
            RolloutArg::Mm => Rollout::MomentMatching,
            RolloutArg::MmIndependent => Rollout::MomentMatchingIndependent,
            RolloutArg::Mean => Rollout::MeanFeedback,
        }
    }
}

/// Simulated systems the loop can learn on.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum SimArg {
    /// The inverted pendulum on the robot's end effector (crate msgp-sim).
    Pendulum,
}

/// Dynamics model of the loop.
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum ModelArg {
    /// Multi-step GP trained on the trajectory likelihood (the paper's method).
    Msgp,
    /// One-step GP-NARX trained on the marginal likelihood (standard PILCO).
    GpNarx,
    /// The linear-Gaussian window model (no GP) by the exact Kalman-filter likelihood; the end
    /// effector declared kinematic, fits warm-started, gains optimised over 10 s (balanced the
    /// default pendulum in 5 of 5 seeds, RESULTS.md).
    LinearKf,
}

impl From<ModelArg> for Method {
    fn from(m: ModelArg) -> Self {
        match m {
            ModelArg::Msgp => Method::Msgp,
            ModelArg::GpNarx => Method::GpNarx,
            ModelArg::LinearKf => Method::LinearKf,
        }
    }
}

/// Sizes of the loop: data, model, policy search.
#[derive(Clone, Debug, Args)]
#[command(next_help_heading = "Budget")]
pub struct BudgetArgs {
    /// Likelihood of the MSGP fits (free-run or filter; see `msgp fit --likelihood`)
    /// [default: filter, with the filtered loop's defaults: every fit starts from the
    /// linear-kf model of the data, m = 30, 100 L-BFGS iterations, warm starts,
    /// 12 Adam steps per search start, 10 s policy horizon, and each search on the GP model
    /// only while it predicts the episodes it had not seen better than the linear-kf model of
    /// the same data; free-run: the paper's loss
    /// with the MSGP defaults].
    #[arg(long, value_enum)]
    pub likelihood: Option<LikelihoodArg>,
    /// Random-excitation episodes before the first policy.
    #[arg(long, default_value_t = Budget::default().random_rollouts)]
    pub random_rollouts: usize,
    /// Length of every interaction episode [s].
    #[arg(long, default_value_t = Budget::default().episode_seconds)]
    pub episode_seconds: f64,
    /// Solver iterations of each model fit [default: 100 L-BFGS for msgp on the filter
    /// likelihood, 300 Adam on the free-run one; at most 300 L-BFGS iterations of the one-step
    /// fit for gp-narx, and from each of two starts for linear-kf].
    #[arg(long, value_name = "N")]
    pub fit_iters: Option<usize>,
    /// From the second iteration on, continue the previous MSGP or linear-kf model for N solver
    /// iterations (same normaliser and hyperparameters; pseudo-inputs re-placed over all the
    /// data, up to `--inducing`, while the first episodes capped their count) instead of
    /// fitting from scratch; 0: always from scratch [default: 40 for msgp on the filter
    /// likelihood, 0 for msgp on the free-run one and for gp-narx, 300 for linear-kf].
    #[arg(long, value_name = "N")]
    pub warm_start: Option<usize>,
    /// Pseudo-inputs of the model [default: 30 for msgp on the filter likelihood, 50 for the
    /// other GP models].
    #[arg(long, value_name = "M")]
    pub inducing: Option<usize>,
    /// Adam steps of each policy optimisation start [default: 12 for msgp on the filter
    /// likelihood, 20 for the other models].
    #[arg(long, value_name = "N")]
    pub search_iters: Option<usize>,
    /// Random gain candidates screened on the model before each policy optimisation.
    #[arg(long, value_name = "N", default_value_t = Budget::default().candidates)]
    pub candidates: usize,
    /// Prior mean of the GP model, for both models (zero: the paper's GP; linear: an ARX map
    /// under the GP, started by instrumental variables; see docs/design.md).
    #[arg(long, value_enum, default_value_t = MeanArg::Linear)]
    pub mean: MeanArg,
    /// Horizon of the predicted rollouts the gains are optimised on [s] [default: 5 for msgp
    /// and gp-narx, 10 for linear-kf (the stability test's length)].
    #[arg(long, value_name = "S")]
    pub policy_horizon: Option<f64>,
    /// Widths of the saturating cost on the pole angle [rad] and the end-effector position [m]:
    /// `c = 1 − exp(−½ ((θ/w_θ)² + (x/w_x)²))` per step.
    #[arg(long, value_name = "W_THETA,W_X", value_delimiter = ',',
          default_values_t = Budget::default().cost_widths)]
    pub cost_widths: Vec<f64>,
}

impl BudgetArgs {
    /// The budget these options state (checked by [`Budget::settings`]).
    pub fn budget(&self) -> Budget {
        Budget {
            likelihood: self.likelihood.map(Into::into),
            random_rollouts: self.random_rollouts,
            episode_seconds: self.episode_seconds,
            fit_iters: self.fit_iters,
            warm_start: self.warm_start,
            inducing: self.inducing,
            search_iters: self.search_iters,
            candidates: self.candidates,
            mean: self.mean.into(),
            policy_horizon: self.policy_horizon,
            cost_widths: self.cost_widths.clone(),
        }
    }
}

/// A `--models` entry of `msgp reproduce figure4`.
fn model4(s: &str) -> Result<LoopModel, String> {
    s.trim().parse()
}

/// Options of `msgp learn-policy`.
#[derive(Debug, Args)]
pub struct LearnArgs {
    /// The simulated system.
    #[arg(long, value_enum)]
    pub sim: SimArg,
    /// Dynamics model.
    #[arg(long, value_enum, default_value_t = ModelArg::Msgp)]
    pub model: ModelArg,
    /// Policy-learning iterations after the random rollouts.
    #[arg(long, default_value_t = LearnSettings::default().iterations)]
    pub iterations: usize,
    #[command(flatten)]
    pub budget: BudgetArgs,
    /// Seed of every random choice (episodes, excitation, fits, restarts).
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Output folder [default: learn-<model>-seed<S>].
    #[arg(long, value_name = "DIR")]
    pub out: Option<PathBuf>,
    /// Print one JSON object instead of text.
    #[arg(long)]
    pub json: bool,
    /// No progress lines on stderr.
    #[arg(long)]
    pub quiet: bool,
    #[command(flatten)]
    pub plant: PlantChoiceArgs,
}

/// Subcommands of `msgp reproduce`.
#[derive(Debug, Subcommand)]
pub enum ReproduceCommand {
    /// Table 1 of the paper: GP-NARX, PILCO's GP-NARX and MSGP on the ten benchmarks.
    Table1(Table1Args),
    /// Figure 4 of the paper: PILCO on the pendulum with MSGP and GP-NARX models, several
    /// seeds; iterations and interaction time to the first stable policy.
    Figure4(Box<Figure4Args>),
    /// How MSGP and GP-NARX models generalise: the synthetic systems on three excitations they
    /// were not trained on, the real series split the other way round.
    Generalisation(GeneralisationArgs),
    /// PILCO on a named plant task (Gymnasium's Pendulum-v1, the arm swing-up) with each loop
    /// model, several seeds: the seeds that solved it, the interaction seconds, which model
    /// each search ran on.
    PlantTask(PlantTaskArgs),
}

/// How the runs of a reproduction over learning runs go: how many at a time, how quietly.
#[derive(Debug, Args)]
pub struct RunsArgs {
    /// Runs at a time, the threads (`MSGP_THREADS`, else the machine's cores) shared between
    /// them; results do not depend on it [default: the threads].
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u16).range(1..))]
    pub jobs: Option<u16>,
    /// No progress lines on stderr.
    #[arg(long)]
    pub quiet: bool,
}

/// Options of `msgp reproduce plant-task`.
#[derive(Debug, Args)]
pub struct PlantTaskArgs {
    /// The task: pendulum-v1 (Gymnasium's, by its own equations) or swing-up (the arm-mounted
    /// pendulum from hanging).
    #[arg(long, value_parser = plant_task)]
    pub task: PlantTask,
    /// Markdown file whose `plant-task-<task>` section is (re)written.
    #[arg(long, value_name = "RESULTS.md", default_value = "RESULTS.md")]
    pub out: PathBuf,
    /// Folder for every run's record and the plots [default: results/plant-tasks/<task>].
    #[arg(long, value_name = "DIR")]
    pub dir: Option<PathBuf>,
    /// Seeds 0..N per model.
    #[arg(long, default_value_t = 5)]
    pub seeds: u64,
    /// Policy iterations per run [default: the task's preset].
    #[arg(long, value_name = "N")]
    pub iterations: Option<usize>,
    /// Models to run, comma-separated: msgp (MSGP on the free-run likelihood), msgp-filter
    /// (MSGP on the filter likelihood, the loop's default), gp-narx (one-step GP-NARX,
    /// standard PILCO), linear-kf (the linear-Gaussian window model).
    #[arg(long, value_name = "MODEL,...", value_delimiter = ',', value_parser = model4,
          default_values = ["msgp-filter", "msgp", "gp-narx", "linear-kf"])]
    pub models: Vec<LoopModel>,
    #[command(flatten)]
    pub runs: RunsArgs,
}

fn plant_task(s: &str) -> Result<PlantTask, String> {
    s.parse()
}

/// Options of `msgp reproduce generalisation`.
#[derive(Debug, Args)]
pub struct GeneralisationArgs {
    #[command(flatten)]
    pub common: BenchmarkArgs,
    /// Also draw every fit's simulations: one PNG per benchmark and seed in DIR
    /// (`<benchmark>-seed<k>.png`), a row per test with MSGP and GP-NARX side by side, each the
    /// predicted mean ± 2σ against the true (synthetic) or measured (real) output (a test that
    /// either model fails to simulate is left out).
    #[arg(long, value_name = "DIR")]
    pub plots: Option<PathBuf>,
}

/// The options every reproduction over the ten benchmarks shares.
#[derive(Debug, Args)]
pub struct BenchmarkArgs {
    /// Markdown file whose section of this reproduction is (re)written.
    #[arg(long, value_name = "RESULTS.md", default_value = "RESULTS.md")]
    pub out: PathBuf,
    /// Folder with the real series (actuator.csv, …) [default: $MSGP_DATA_DIR, else
    /// ../shared/data/real].
    #[arg(long, value_name = "DIR")]
    pub data_dir: Option<PathBuf>,
    /// Only these benchmarks (comma-separated): synthetic1 … synthetic5, actuator, ballbeam,
    /// drives, furnace, dryer.
    #[arg(long, value_name = "NAME,...", value_delimiter = ',')]
    pub only: Vec<String>,
    /// Seeds of data generation (synthetic systems) and of the fits, comma-separated; tables
    /// report mean ± standard deviation over them.
    #[arg(
        long,
        alias = "seed",
        value_name = "S,...",
        value_delimiter = ',',
        default_value = "0"
    )]
    pub seeds: Vec<u64>,
    /// Fits at a time (table1: units; generalisation: benchmark and seed pairs), the threads
    /// (`MSGP_THREADS`, else the machine's cores) shared between them; every figure but the
    /// times is the same for any N [default: the threads].
    #[arg(long, value_name = "N", value_parser = clap::value_parser!(u16).range(1..))]
    pub jobs: Option<u16>,
    /// Print the rows as one JSON object.
    #[arg(long)]
    pub json: bool,
    /// No progress output on stderr.
    #[arg(long)]
    pub quiet: bool,
}

/// Options of `msgp reproduce table1`.
#[derive(Debug, Args)]
pub struct Table1Args {
    #[command(flatten)]
    pub common: BenchmarkArgs,
    /// Only these methods (comma-separated).
    #[arg(long, value_enum, value_name = "METHOD,...", value_delimiter = ',')]
    pub methods: Vec<MethodArg>,
    /// Most solver iterations on the MSGP loss, per recipe [default: the fit default, 1000].
    #[arg(long, value_name = "N")]
    pub iters: Option<usize>,
    /// Solver of the MSGP loss; `lbfgs` writes its own section of the results file, next to
    /// the paper's Adam.
    #[arg(long, value_enum, default_value_t = OptimizerArg::Adam)]
    pub optimizer: OptimizerArg,
    /// Number of pseudo-inputs.
    #[arg(long, value_name = "M", default_value_t = 100)]
    pub inducing: usize,
    /// Where each fit's history `l_y, l_u` comes from.
    #[arg(long, value_enum, default_value_t = TableHistoryArg::Paper)]
    pub history: TableHistoryArg,
    /// Likelihoods of the MSGP columns, comma-separated [default: both].
    #[arg(long, value_enum, value_name = "L,...", value_delimiter = ',')]
    pub likelihoods: Vec<LikelihoodArg>,
    /// Also draw the test part's simulations: one PNG per benchmark and seed in DIR
    /// (`<benchmark>-seed<k>.png`), a row per column of the table, each the predicted mean ±
    /// 2σ (moment matching) against the true (synthetic) or measured (real) test output.
    #[arg(long, value_name = "DIR")]
    pub plots: Option<PathBuf>,
}

/// Options of `msgp reproduce figure4`.
#[derive(Debug, Args)]
pub struct Figure4Args {
    /// Markdown file whose `figure4` section is (re)written.
    #[arg(long, value_name = "RESULTS.md", default_value = "RESULTS.md")]
    pub out: PathBuf,
    /// Folder for every run's artefacts and the cost-curve plot [default:
    /// results/figure4-<plant tier>].
    #[arg(long, value_name = "DIR")]
    pub dir: Option<PathBuf>,
    /// Seeds 0..N per model.
    #[arg(long, default_value_t = 5)]
    pub seeds: u64,
    /// Policy iterations per run.
    #[arg(long, default_value_t = LearnSettings::default().iterations)]
    pub iterations: usize,
    /// Models to run, comma-separated: msgp (MSGP on the free-run likelihood, the paper's),
    /// msgp-filter (MSGP on the filter likelihood), gp-narx (one-step GP-NARX, standard PILCO),
    /// linear-kf (the linear-Gaussian window model by the Kalman-filter likelihood).
    #[arg(long, value_name = "MODEL,...", value_delimiter = ',', value_parser = model4,
          default_values = ["msgp", "msgp-filter", "gp-narx", "linear-kf"])]
    pub models: Vec<LoopModel>,
    #[command(flatten)]
    pub runs: RunsArgs,
    #[command(flatten)]
    pub budget: BudgetArgs,
    #[command(flatten)]
    pub plant: PlantChoiceArgs,
}

/// Options of `msgp demo`.
#[derive(Debug, Args)]
pub struct DemoArgs {
    /// Synthetic system of the paper's Table 2 (1–5).
    #[arg(long, default_value_t = 4)]
    pub system: u8,
    /// Seed for data generation and initialisation.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Most Adam iterations for MSGP [default: the fit default, 1000; early stopping ends
    /// sooner].
    #[arg(long, value_name = "N")]
    pub iters: Option<usize>,
    /// Number of pseudo-inputs.
    #[arg(long, default_value_t = 100)]
    pub inducing: usize,
}

/// Subcommands of `msgp sim`.
#[derive(Debug, Subcommand)]
pub enum SimCommand {
    /// Simulate one episode of the pole on the robot end effector and write a CSV or MCAP log.
    Pendulum(PendulumArgs),
    /// Stability test of PID + PD gains: 5 starts (±0.03, ±0.015, 0 rad), 3 noise draws each,
    /// 10 s each; pass iff every episode keeps |θ| < 0.1 rad and |x| < 0.3 m throughout and RMS θ
    /// over the last 5 s < 0.03 rad.
    Stability(StabilityArgs),
}

/// Options of `msgp sim pendulum`.
#[derive(Debug, Args)]
pub struct PendulumArgs {
    #[command(flatten)]
    pub controller: ControllerArgs,
    /// Episode length in seconds (the episode stops early if |θ| > stop-theta or |x| > stop-x).
    #[arg(long, default_value_t = 10.0, allow_negative_numbers = true)]
    pub seconds: f64,
    /// Seed of the initial angle, the measurement noise and the random excitation.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Fixed initial pole angle [rad] instead of a draw from N(0, theta0-std²).
    #[arg(long, allow_negative_numbers = true)]
    pub theta0: Option<f64>,
    /// RMS of the random excitation [m/s²] (with --random).
    #[arg(long, default_value_t = 1.0)]
    pub excitation_rms: f64,
    #[command(flatten)]
    pub saturation: SaturationArgs,
    /// Output run log; the extension selects the format: .csv or .mcap.
    #[arg(long)]
    pub out: PathBuf,
    /// Print the summary as JSON.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub plant: PlantArgs,
}

/// Options of `msgp sim stability`.
#[derive(Debug, Args)]
pub struct StabilityArgs {
    #[command(flatten)]
    pub gains: GainArgs,
    #[command(flatten)]
    pub saturation: SaturationArgs,
    /// Seed of the measurement noise.
    #[arg(long, default_value_t = 0)]
    pub seed: u64,
    /// Print the report as JSON.
    #[arg(long)]
    pub json: bool,
    #[command(flatten)]
    pub plant: PlantArgs,
}

/// Exactly one controller for an episode.
#[derive(Debug, Args)]
#[group(required = true, multiple = false)]
pub struct ControllerArgs {
    /// PID + PD policy file (JSON: kp_x, ki_x, kd_x, kp_theta, kd_theta).
    #[arg(long, value_name = "POLICY.json")]
    pub policy: Option<PathBuf>,
    /// PID + PD gains "kp_x,ki_x,kd_x,kp_theta,kd_theta" (use --gains=-1,... for a leading minus).
    #[arg(long, value_name = "KP,KI,KD,KPθ,KDθ", value_parser = parse_gains, allow_hyphen_values = true)]
    pub gains: Option<[f64; 5]>,
    /// Built-in gains.
    #[arg(long, value_enum)]
    pub preset: Option<Preset>,
    /// Smooth random excitation (seeded sum of sines, 0.1–2 Hz) instead of a policy.
    #[arg(long)]
    pub random: bool,
}

/// Exactly one set of gains for the stability test.
#[derive(Debug, Args)]
#[group(required = true, multiple = false)]
pub struct GainArgs {
    /// PID + PD policy file (JSON: kp_x, ki_x, kd_x, kp_theta, kd_theta).
    #[arg(long, value_name = "POLICY.json")]
    pub policy: Option<PathBuf>,
    /// PID + PD gains "kp_x,ki_x,kd_x,kp_theta,kd_theta" (use --gains=-1,... for a leading minus).
    #[arg(long, value_name = "KP,KI,KD,KPθ,KDθ", value_parser = parse_gains, allow_hyphen_values = true)]
    pub gains: Option<[f64; 5]>,
    /// Built-in gains.
    #[arg(long, value_enum)]
    pub preset: Option<Preset>,
}

/// How the gains' command is limited to `±action-limit`.
#[derive(Debug, Args)]
pub struct SaturationArgs {
    /// Command saturation: `clip` (the default of --gains and --preset) or `sine` (PILCO's
    /// smooth saturation, which `msgp learn-policy` uses). With --policy it overrides the file's.
    #[arg(long, value_enum)]
    pub saturation: Option<SaturationKind>,
}

/// [`Saturation`] as a command-line value.
#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum SaturationKind {
    /// Hard clipping.
    Clip,
    /// PILCO's sine saturation.
    Sine,
}

impl From<SaturationKind> for Saturation {
    fn from(kind: SaturationKind) -> Self {
        match kind {
            SaturationKind::Clip => Saturation::Clip,
            SaturationKind::Sine => Saturation::Sine,
        }
    }
}

/// Built-in gain sets.
#[derive(Debug, Clone, Copy, ValueEnum)]
pub enum Preset {
    /// Apollo LQR gains [−34.55, −7.03, −1.98, −3.73, −0.3] on [θ, θ̇, x, ẋ, ∫x], mapped.
    ApolloLqr,
    /// Apollo LQR with the position loop halved; balances the default noisy plant.
    HandTuned,
    /// All gains zero (the pole falls).
    Zero,
}

/// The plant of the learning commands: a tier and a parameter file.
#[derive(Debug, Args)]
#[command(next_help_heading = "Plant")]
pub struct PlantChoiceArgs {
    /// Measurement-noise tier: apollo (σθ 5.2e-5 rad as in the Apollo code's simulator, σx
    /// 0.1 mm: the default) or noisy (σθ 5e-3 rad, σx 2 mm: the stress tier); --params and
    /// the simulator's parameter flags override it.
    #[arg(long, value_enum, default_value_t = PlantArg::Apollo)]
    pub plant: PlantArg,
    /// JSON file with plant parameters (missing fields keep the tier's values; the fields of
    /// `msgp sim pendulum --help`'s flags, e.g. {"pole_length": 0.8, "action_limit": 5}).
    #[arg(long, value_name = "PARAMS.json")]
    pub params: Option<PathBuf>,
}

/// The simulator's plant: a tier, a parameter file and single-parameter overrides (defaults:
/// `msgp_sim::PendulumParams::default()`).
#[derive(Debug, Args)]
#[command(next_help_heading = "Plant")]
pub struct PlantArgs {
    #[command(flatten)]
    pub choice: PlantChoiceArgs,
    /// Pole length [m] (default 1.067).
    #[arg(long)]
    pub pole_length: Option<f64>,
    /// Pole mass [kg] (default 0.2903).
    #[arg(long)]
    pub pole_mass: Option<f64>,
    /// Distance pivot → centre of mass [m] (default 0.637).
    #[arg(long)]
    pub pole_com: Option<f64>,
    /// Pole inertia about its centre of mass [kg·m²] (default m·L²/12).
    #[arg(long)]
    pub pole_inertia: Option<f64>,
    /// Viscous hinge damping [N·m·s] (default 0.0116).
    #[arg(long)]
    pub hinge_damping: Option<f64>,
    /// Gravity [m/s²] (default 9.81; negative hangs the pole).
    #[arg(long, allow_negative_numbers = true)]
    pub gravity: Option<f64>,
    /// Command limit [m/s²] (default 3).
    #[arg(long)]
    pub action_limit: Option<f64>,
    /// Control rate [Hz] (default 50).
    #[arg(long)]
    pub control_hz: Option<f64>,
    /// Physics rate [Hz], an integer multiple of the control rate (default 1000).
    #[arg(long)]
    pub physics_hz: Option<f64>,
    /// Command delay in control steps (default 1).
    #[arg(long)]
    pub delay_steps: Option<u32>,
    /// First-order lag time constant [s] (default 0.03; 0 = none).
    #[arg(long)]
    pub lag: Option<f64>,
    /// Angle measurement noise σ [rad] (default: the tier's, 5e-3 for noisy).
    #[arg(long)]
    pub sigma_theta: Option<f64>,
    /// Position measurement noise σ [m] (default: the tier's, 2e-3 for noisy).
    #[arg(long)]
    pub sigma_x: Option<f64>,
    /// Switch off measurement noise (overrides --sigma-theta/--sigma-x).
    #[arg(long)]
    pub noiseless: bool,
    /// σ of the random initial angle [rad] (default 0.02).
    #[arg(long)]
    pub theta0_std: Option<f64>,
    /// Early stop when |θ| exceeds this [rad] (default 0.5).
    #[arg(long)]
    pub stop_theta: Option<f64>,
    /// Early stop when |x| exceeds this [m] (default 0.5).
    #[arg(long)]
    pub stop_x: Option<f64>,
}

/// A plant tier (`--plant`).
#[derive(Clone, Copy, Debug, PartialEq, Eq, ValueEnum)]
pub enum PlantArg {
    /// The paper's robot's precision.
    Apollo,
    /// Today's stress tier.
    Noisy,
}

impl From<PlantArg> for msgp_sim::PlantTier {
    fn from(p: PlantArg) -> Self {
        match p {
            PlantArg::Apollo => msgp_sim::PlantTier::Apollo,
            PlantArg::Noisy => msgp_sim::PlantTier::Noisy,
        }
    }
}

/// Parses "kp_x,ki_x,kd_x,kp_theta,kd_theta".
pub fn parse_gains(s: &str) -> Result<[f64; 5], String> {
    let parts: Vec<&str> = s.split(',').map(str::trim).collect();
    if parts.len() != 5 {
        return Err(format!(
            "expected 5 comma-separated gains kp_x,ki_x,kd_x,kp_theta,kd_theta, got {}",
            parts.len()
        ));
    }
    let mut gains = [0.0; 5];
    for (g, part) in gains.iter_mut().zip(&parts) {
        *g = part
            .parse::<f64>()
            .map_err(|e| format!("bad gain `{part}`: {e}"))?;
        if !g.is_finite() {
            return Err(format!("gain `{part}` is not finite"));
        }
    }
    Ok(gains)
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
        assert_eq!(parse_fit_history("auto"), Ok(FitHistory::Auto));
        assert_eq!(
            parse_fit_history("3,1"),
            Ok(FitHistory::Given(HistoryArg { ly: 3, lu: 1 }))
        );
        let e = parse_fit_history("auto,2").expect_err("neither");
        assert!(e.contains("`auto`"), "{e}");
    }

    #[test]
    fn gains_parse() {
        assert_eq!(
            parse_gains("1,2, 3,-4,5e-1").expect("valid"),
            [1.0, 2.0, 3.0, -4.0, 0.5]
        );
        assert!(parse_gains("1,2,3,4").is_err());
        assert!(parse_gains("1,2,3,4,x").is_err());
        assert!(parse_gains("1,2,3,4,inf").is_err());
    }
}
