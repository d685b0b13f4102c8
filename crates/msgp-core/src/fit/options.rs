//! The choices a user makes for a fit — what `msgp fit` and the Python `msgp.Msgp` take — and
//! the base of defaults they make for the data (the method's own, the default pseudo-input
//! count, the segments of a long log, the start's recipe), which the user's [`Overrides`] then
//! change ([`super::resolve`]), with the warnings a front end gives before the work starts (a
//! long history, few pseudo-inputs).

use super::resolve::{Overrides, refused};
use super::segments::{LONG_LOG_WINDOWS, Segments};
use super::settings::{
    DEFAULT_MAX_INDUCING, FitOptimizer, FitSettings, LINEAR_RECIPE, LinearKfSettings,
    MethodSettings, MsgpSettings, MsgpStart, OneStepFitSettings,
};
use crate::data::Trajectory;
use crate::error::Result;
use crate::gp::integrator::Integrator;
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
    /// Seed of every random choice.
    pub seed: u64,
    /// Outputs declared integrating ([`crate::gp::integrator`]; needs the linear mean).
    pub integrators: Vec<Integrator>,
    /// Solver of the MSGP loss.
    pub optimizer: FitOptimizer,
    /// Where the MSGP training starts ([`MsgpStart`]; `None`: the default); the linear-kf start
    /// is a linear prior mean, so it trains the linear recipe alone (a zero `mean` is refused).
    /// Another method has its own fit and refuses one ([`FitOptions::check`]).
    pub start: Option<MsgpStart>,
    /// Threads of the fit ([`FitSettings::threads`]); front ends take it from
    /// [`Threads::from_env`].
    pub threads: Threads,
    /// Train MSGP on segments of this many predicted steps ([`super::segments`]), a batch of
    /// [`Segments::DEFAULT`]'s size per Adam step; `Some(0)`: every trajectory whole; `None`:
    /// segments of [`Segments::DEFAULT`] when the training part has more than
    /// [`LONG_LOG_WINDOWS`] windows, whole trajectories otherwise. MSGP's alone
    /// ([`FitOptions::check`]).
    pub segment_length: Option<usize>,
    /// What the user changes of the defaults: iterations, pseudo-inputs (`None`:
    /// `min(100, training windows / 2)`, at least 1, where a trajectory of `T` samples has
    /// `T − max(l_y, l_u)` windows), the prior mean (`None`: MSGP trains both recipes of the
    /// default protocol, zero mean and [`LINEAR_RECIPE`], and keeps the better on the
    /// validation tail; the one-step baselines have no mean), the likelihood, the switches
    /// and any other setting by name ([`Overrides`]).
    pub overrides: Overrides,
}

/// The default pseudo-input count of a fit on `windows` training windows:
/// `min(DEFAULT_MAX_INDUCING, windows / 2)`, at least 1.
fn default_inducing(windows: usize) -> usize {
    DEFAULT_MAX_INDUCING.min((windows / 2).max(1))
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
            seed: 0,
            integrators: Vec::new(),
            optimizer: FitOptimizer::default(),
            start: None,
            threads: Threads::default(),
            segment_length: None,
            overrides: Overrides::default(),
        }
    }

    /// Training windows of `train`: per trajectory, the samples after the history.
    fn windows(&self, train: &[Trajectory]) -> usize {
        let warmup = self.ly.max(self.lu);
        train.iter().map(|t| t.len().saturating_sub(warmup)).sum()
    }

    /// The pseudo-inputs a GP fit of `windows` training windows gets: the requested number, or
    /// the default.
    fn chosen_inducing(&self, windows: usize) -> usize {
        self.overrides
            .inducing
            .unwrap_or_else(|| default_inducing(windows))
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
        match self.overrides.inducing {
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

    /// Refuses, by name, what the method does not have — MSGP's own choices (`start`,
    /// `segment_length`) by another method, and the [`Overrides`] the resolver refuses — so a
    /// front end can say so before it reads any data.
    pub fn check(&self) -> Result<()> {
        if self.method != Method::Msgp {
            if self.start.is_some() {
                return Err(refused("start", "where an MSGP fit starts", self.method));
            }
            if self.segment_length.is_some() {
                return Err(refused(
                    "segment_length",
                    "segments of the trajectory likelihood, an MSGP fit's",
                    self.method,
                ));
            }
        }
        self.overrides
            .apply(FitSettings::new(self.method))
            .map(drop)
    }

    /// The full settings for fitting `train`: the [`FitOptions::base`] with the user's
    /// [`Overrides`], checked ([`FitOptions::check`]) and checked against the data
    /// ([`FitSettings::validate`]).
    pub fn settings(&self, train: &[Trajectory]) -> Result<FitSettings> {
        self.check()?;
        let settings = self.overrides.apply(self.base(train))?;
        settings.validate(&train.iter().collect::<Vec<_>>())?;
        Ok(settings)
    }

    /// The defaults these options make for `train`: the method's own settings with the
    /// history, seed, integrators and threads, the default pseudo-inputs, and for MSGP the
    /// solver, the start (the linear-kf start trains the linear recipe alone: it is a linear
    /// prior mean) and the segments of a long log.
    pub fn base(&self, train: &[Trajectory]) -> FitSettings {
        let inducing = default_inducing(self.windows(train));
        let one_step = OneStepFitSettings {
            inducing,
            ..match self.method {
                Method::PilcoNarx => OneStepFitSettings::pilco(),
                _ => OneStepFitSettings::default(),
            }
        };
        let start = self.start.unwrap_or_default();
        let recipes = match start {
            MsgpStart::LinearKf => MsgpSettings::default().with_recipe(LINEAR_RECIPE),
            _ => MsgpSettings::default(),
        };
        let method = match self.method {
            Method::Msgp => MethodSettings::Msgp(MsgpSettings {
                inducing,
                segments: self.segments(train),
                optimizer: self.optimizer,
                start,
                ..recipes
            }),
            Method::GpNarx => MethodSettings::GpNarx(one_step),
            Method::PilcoNarx => MethodSettings::PilcoNarx(one_step),
            Method::LinearKf => MethodSettings::LinearKf(LinearKfSettings::default()),
        };
        FitSettings {
            ly: self.ly,
            lu: self.lu,
            seed: self.seed,
            integrators: self.integrators.clone(),
            method,
            threads: self.threads,
        }
    }
}
