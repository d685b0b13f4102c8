//! The choices a user makes for a fit — what `msgp fit` and the Python `msgp.Msgp` take — and
//! how they become a fit's [`FitSettings`] (the method's defaults, the mean's recipe, the
//! segments of a long log, the default pseudo-input count), with the warnings a front end gives
//! before the work starts (a long history, few pseudo-inputs).

use super::segments::{LONG_LOG_WINDOWS, Segments};
use super::settings::{
    DEFAULT_MAX_INDUCING, FitOptimizer, FitSettings, LINEAR_RECIPE, LinearKfSettings,
    MethodSettings, MsgpSettings, MsgpStart, OneStepFitSettings, OneStepObjective,
};
use crate::data::Trajectory;
use crate::error::{MsgpError, Result};
use crate::gp::MeanFunction;
use crate::gp::integrator::Integrator;
use crate::loss::Likelihood;
use crate::model::Method;
use crate::numeric::parallel::Threads;

/// The choices a user makes for a fit: what `msgp fit` and the Python `msgp.Msgp` take. Turned
/// into [`FitSettings`] by [`FitOptions::settings`], so both front ends fit with identical
/// settings (and give identical numbers) for the same data, options and seed.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct FitOptions {
    /// Training method.
    pub method: Method,
    /// `l_y`.
    pub ly: usize,
    /// `l_u`.
    pub lu: usize,
    /// Number of pseudo-inputs (GP methods); `None`: `min(100, training windows / 2)` (at least
    /// 1), where a trajectory of `T` samples has `T − max(l_y, l_u)` windows.
    pub inducing: Option<usize>,
    /// Iterations of the method's own solver ([`FitSettings::with_solver_iterations`]): on the
    /// trajectory likelihood for MSGP, on the one-step marginal likelihood for the baselines, on
    /// the filter likelihood for linear-kf; `None`: the method's default. The MSGP
    /// initialisation always runs the default one-step iterations.
    pub iterations: Option<usize>,
    /// Seed of every random choice.
    pub seed: u64,
    /// Prior mean of the GP (a linear-kf model is always linear); `None`: MSGP trains both
    /// recipes of the default protocol (zero mean, and [`LINEAR_RECIPE`] as the alternative)
    /// and keeps the better on the validation tail, the one-step baselines have no mean. Given,
    /// MSGP trains that mean's recipe alone.
    pub mean: Option<MeanFunction>,
    /// Outputs declared integrating ([`crate::gp::integrator`]; needs the linear mean).
    pub integrators: Vec<Integrator>,
    /// Solver of the MSGP loss.
    pub optimizer: FitOptimizer,
    /// The MSGP fit's likelihood.
    pub likelihood: Likelihood,
    /// Where the MSGP training starts ([`MsgpStart`]); the linear-kf start is a linear prior
    /// mean, so it trains the linear recipe alone (a zero `mean` is refused).
    pub start: MsgpStart,
    /// Threads of the fit ([`FitSettings::threads`]); front ends take it from
    /// [`Threads::from_env`].
    pub threads: Threads,
    /// Train MSGP on segments of this many predicted steps ([`super::segments`]), a batch of
    /// [`Segments::DEFAULT`]'s size per Adam step; `Some(0)`: every trajectory whole; `None`:
    /// segments of [`Segments::DEFAULT`] when the training part has more than
    /// [`LONG_LOG_WINDOWS`] windows, whole trajectories otherwise.
    pub segment_length: Option<usize>,
    /// The protocol's switches a user may turn; each refused by a method without it.
    pub switches: Switches,
}

/// Switches of a fit's protocol that the front ends offer beside [`FitOptions`]' own choices
/// (`None`: the method's default). [`FitOptions::settings`] applies them and refuses one the
/// method does not have, naming the setting.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Switches {
    /// The one-step fit's objective: the baselines' own fit, MSGP's one-step start
    /// ([`OneStepFitSettings::objective`], [`MsgpSettings::one_step_objective`]).
    pub one_step_objective: Option<OneStepObjective>,
    /// MSGP: the output-variance calibration ([`MsgpSettings::calibrate`]).
    pub calibrate: Option<bool>,
    /// MSGP: the final training's length chosen by its proxy
    /// ([`MsgpSettings::choose_final_budget`]).
    pub choose_final_budget: Option<bool>,
    /// MSGP: the fallback heads where the zero-mean recipe's final training blows up
    /// ([`MsgpSettings::blow_up_fallback`]).
    pub blow_up_fallback: Option<bool>,
}

impl Switches {
    /// Turns the switches that are set in `settings`.
    fn apply(&self, settings: &mut FitSettings) -> Result<()> {
        let name = settings.method().name();
        let method = &mut settings.method;
        let refused = |setting: &'static str, reason: String| MsgpError::InvalidSetting {
            name: setting,
            reason,
        };
        if let Some(o) = self.one_step_objective {
            match method {
                MethodSettings::GpNarx(s) | MethodSettings::PilcoNarx(s) => s.objective = o,
                MethodSettings::Msgp(s) if s.start == MsgpStart::OneStep => {
                    s.one_step_objective = o
                }
                MethodSettings::Msgp(s) => {
                    let start = match s.start {
                        MsgpStart::Spread => "spread",
                        _ => "linear-kf",
                    };
                    Err(refused(
                        "one_step_objective",
                        format!(
                            "the objective of a one-step fit; method {name} started from \
                             {start} has none"
                        ),
                    ))?
                }
                MethodSettings::LinearKf(_) => Err(refused(
                    "one_step_objective",
                    format!("the objective of a one-step fit; method {name} has none"),
                ))?,
            }
        }
        if let Some(on) = self.calibrate {
            msgp(method, name, "calibrate", "only msgp fits are calibrated")?.calibrate = on;
        }
        if let Some(on) = self.choose_final_budget {
            let what = "only msgp fits train on all the data after a validation tail";
            msgp(method, name, "choose_final_budget", what)?.choose_final_budget = on;
        }
        if let Some(on) = self.blow_up_fallback {
            let what = "where an msgp fit's zero-mean recipe may retrain";
            msgp(method, name, "blow_up_fallback", what)?.blow_up_fallback = on;
        }
        Ok(())
    }
}

/// `method`'s MSGP settings, or the refusal of `setting` (`what` it is) by method `name`.
fn msgp<'a>(
    method: &'a mut MethodSettings,
    name: &str,
    setting: &'static str,
    what: &str,
) -> Result<&'a mut MsgpSettings> {
    if let MethodSettings::Msgp(s) = method {
        return Ok(s);
    }
    Err(MsgpError::InvalidSetting {
        name: setting,
        reason: format!("{what}; method {name} has none"),
    })
}

/// More GP inputs (`l_y·d_y + l_u·d_u`) than this make [`FitOptions::history_warning`] say
/// the fit will be slow: every predicted step moment-matches a Gaussian over the whole window,
/// whose work grows with the square of its size (Table 1's longest histories have 20).
pub const MANY_GP_INPUTS: usize = 64;

/// Fewer default pseudo-inputs than this make [`FitOptions::inducing_warning`] speak up.
pub const FEW_INDUCING: usize = 10;

impl FitOptions {
    /// `method` with history `(ly, lu)` and every other choice at its default (seed 0, the
    /// default threads).
    pub fn new(method: Method, ly: usize, lu: usize) -> Self {
        Self {
            method,
            ly,
            lu,
            inducing: None,
            iterations: None,
            seed: 0,
            mean: None,
            integrators: Vec::new(),
            optimizer: FitOptimizer::default(),
            likelihood: Likelihood::default(),
            start: MsgpStart::default(),
            threads: Threads::default(),
            segment_length: None,
            switches: Switches::default(),
        }
    }

    /// Training windows of `train`: per trajectory, the samples after the history.
    fn windows(&self, train: &[Trajectory]) -> usize {
        let warmup = self.ly.max(self.lu);
        train.iter().map(|t| t.len().saturating_sub(warmup)).sum()
    }

    /// The pseudo-inputs a GP fit of `train` gets: the requested number, or the default.
    fn chosen_inducing(&self, windows: usize) -> usize {
        self.inducing
            .unwrap_or_else(|| DEFAULT_MAX_INDUCING.min((windows / 2).max(1)))
    }

    /// A warning when the pseudo-inputs the fit of `train` gets are not what a user would
    /// expect: more requested than there are training windows (all windows are used instead),
    /// or so few windows that the default gives fewer than `FEW_INDUCING` (10).
    pub fn inducing_warning(&self, train: &[Trajectory]) -> Option<String> {
        if self.method == Method::LinearKf {
            return None;
        }
        let windows = self.windows(train);
        if windows == 0 {
            // nothing to fit: the fit's own error says so
            return None;
        }
        let m = self.chosen_inducing(windows);
        match self.inducing {
            Some(asked) if asked > windows => Some(format!(
                "{asked} pseudo-inputs requested but the training part has only {windows} \
                 windows (samples after the history l_y={}, l_u={}): all {windows} are used",
                self.ly, self.lu
            )),
            None if m < FEW_INDUCING => Some(format!(
                "the training part has only {windows} windows (samples after the history \
                 l_y={}, l_u={}), so the model gets {m} pseudo-input{} (the default is \
                 min({DEFAULT_MAX_INDUCING}, windows / 2)); expect a poor model: give more \
                 data, a larger training part or a shorter history",
                self.ly,
                self.lu,
                if m == 1 { "" } else { "s" }
            )),
            _ => None,
        }
    }

    /// A warning, given before the work starts, when the history is long for the data: more
    /// GP inputs than training windows (a lengthscale per input, fewer windows to set them),
    /// or more than [`MANY_GP_INPUTS`] inputs (a slow fit).
    pub fn history_warning(&self, train: &[Trajectory]) -> Option<String> {
        let first = train.first()?;
        if self.method == Method::LinearKf {
            return None;
        }
        let inputs = self.ly * first.y.ncols() + self.lu * first.u.ncols();
        let windows = self.windows(train);
        if windows == 0 {
            // nothing to fit: the fit's own error says so
            return None;
        }
        let history = format!("the history l_y={}, l_u={}", self.ly, self.lu);
        if inputs > windows {
            Some(format!(
                "{history} makes {inputs} GP inputs but the training part has only {windows} \
                 windows to fit their lengthscales: expect an overfitted model and a slow fit; \
                 give a shorter history"
            ))
        } else if inputs > MANY_GP_INPUTS {
            Some(format!(
                "{history} makes {inputs} GP inputs (more than {MANY_GP_INPUTS}): every \
                 predicted step moment-matches a Gaussian over the whole window, so expect a \
                 slow fit (minutes or more); a shorter history is much faster"
            ))
        } else {
            None
        }
    }

    /// The segments an MSGP fit of `train` trains on ([`FitOptions::segment_length`]).
    pub fn segments(&self, train: &[Trajectory]) -> Option<Segments> {
        let length = match self.segment_length {
            Some(0) => return None,
            Some(length) => length,
            None if self.windows(train) > LONG_LOG_WINDOWS => Segments::DEFAULT.length,
            None => return None,
        };
        Some(Segments {
            length,
            ..Segments::DEFAULT
        })
    }

    /// The full settings for fitting `train`, every other field at the method's default,
    /// checked against the data ([`FitSettings::validate`]).
    pub fn settings(&self, train: &[Trajectory]) -> Result<FitSettings> {
        if self.inducing == Some(0) {
            return Err(MsgpError::InvalidSetting {
                name: "inducing",
                reason: "need at least one pseudo-input".into(),
            });
        }
        let inducing = self.chosen_inducing(self.windows(train));
        let mean = self.mean.unwrap_or_default();
        let one_step = OneStepFitSettings {
            inducing,
            mean,
            ..match self.method {
                Method::PilcoNarx => OneStepFitSettings::pilco(),
                _ => OneStepFitSettings::default(),
            }
        };
        // a mean the user chose is not second-guessed: its recipe trains alone; the linear-kf
        // start is a linear mean (a zero one is refused by `validate`)
        let defaults = match self.mean {
            None if self.start == MsgpStart::LinearKf => {
                MsgpSettings::default().with_recipe(LINEAR_RECIPE)
            }
            None => MsgpSettings::default(),
            Some(MeanFunction::Linear) => MsgpSettings::default().with_recipe(LINEAR_RECIPE),
            Some(MeanFunction::Zero) => MsgpSettings {
                alternative: None,
                ..MsgpSettings::default()
            },
        };
        let method = match self.method {
            Method::Msgp => MethodSettings::Msgp(MsgpSettings {
                inducing,
                segments: self.segments(train),
                optimizer: self.optimizer,
                likelihood: self.likelihood,
                start: self.start,
                ..defaults
            }),
            Method::GpNarx => MethodSettings::GpNarx(one_step),
            Method::PilcoNarx => MethodSettings::PilcoNarx(one_step),
            Method::LinearKf => MethodSettings::LinearKf(LinearKfSettings::default()),
        };
        let settings = FitSettings {
            ly: self.ly,
            lu: self.lu,
            seed: self.seed,
            integrators: self.integrators.clone(),
            method,
            threads: self.threads,
        };
        let mut settings = match self.iterations {
            Some(n) => settings.with_solver_iterations(n),
            None => settings,
        };
        self.switches.apply(&mut settings)?;
        settings.validate(&train.iter().collect::<Vec<_>>())?;
        Ok(settings)
    }
}
