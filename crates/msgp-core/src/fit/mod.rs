//! Fitting a model to trajectories: MSGP (`msgp`: the trajectory likelihood), the one-step
//! baselines GP-NARX and PILCO GP-NARX ([`one_step`]: the marginal likelihood of one-step
//! pairs) and linear-kf ([`linear_kf`]: the window model without a GP, by the exact
//! Kalman-filter likelihood).
//!
//! Data path: trajectories in original units → [`Normalizer`] (fitted on the training data) →
//! the method's own fit → a [`Model`] in normalised units that carries its normaliser. The
//! entry points ([`fit`], [`fit_episodes`], [`refit_episodes`] and their `_observed` forms) all
//! run [`fit_episodes_observed`]; front ends build their [`FitSettings`] from the user's
//! [`FitOptions`].

pub mod linear_kf;
mod msgp;
pub mod one_step;

use std::ops::ControlFlow;
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::data::{Normalizer, Trajectory};
use crate::error::{MsgpError, Result};
use crate::gp::integrator::{self, Integrator, Structure};
use crate::gp::{GpConfig, MeanFunction, ParamGroup};
use crate::loss::Complexity;
use crate::model::{Method, Model};
use crate::narx::NarxSpec;
use crate::narx::start_window::StartWindow;
use crate::numeric::linalg::JitterLog;
use crate::numeric::parallel::Threads;
use crate::optim::Lbfgs;
use crate::policy::PolicySpec;
use one_step::{OneStepSettings, fit_one_step, one_step_pairs};

/// Everything that controls a fit.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct FitSettings {
    /// Training method.
    pub method: Method,
    /// `l_y`.
    pub ly: usize,
    /// `l_u`.
    pub lu: usize,
    /// Number of pseudo-inputs `m`.
    pub inducing: usize,
    /// Solver iterations on the MSGP loss.
    pub iterations: usize,
    /// Solver of the MSGP loss.
    #[serde(default)]
    pub optimizer: FitOptimizer,
    /// Adam step size for MSGP.
    pub learning_rate: f64,
    /// Seed for every random choice (k-means).
    pub seed: u64,
    /// Complexity term of the MSGP loss.
    pub complexity: Complexity,
    /// Fraction of each training trajectory held out for early stopping (MSGP).
    pub validation_fraction: f64,
    /// Adam iterations between validation checks (L-BFGS checks after every iteration: one of
    /// its steps goes as far as many of Adam's).
    pub eval_every: usize,
    /// Stop after this many validation checks without improvement.
    pub patience: usize,
    /// Floor on the MSGP noise variances (normalised units).
    pub noise_floor: f64,
    /// Parameter groups kept fixed during MSGP training.
    pub frozen: Vec<ParamGroup>,
    /// Adam iterations on the one-step marginal likelihood.
    pub one_step_iterations: usize,
    /// After early stopping, refit on all training data for the chosen number of iterations.
    pub refit: bool,
    /// Prior mean of the GP (the paper's model has none).
    #[serde(default)]
    pub mean: MeanFunction,
    /// Outputs known to integrate the rest of the system ([`crate::gp::integrator`]); needs the
    /// linear mean, whose coefficients on their own lags they fix.
    #[serde(default)]
    pub integrators: Vec<Integrator>,
    /// How the MSGP loss starts each training trajectory's rollout ([`StartWindow`]).
    #[serde(default)]
    pub start_window: StartWindow,
    /// Threads of the fit's independent work (the loss gradient's episodes, the one-step fits'
    /// outputs); the result does not depend on it. Not part of a model's training record.
    #[serde(skip)]
    pub threads: Threads,
}

impl Default for FitSettings {
    fn default() -> Self {
        Self {
            method: Method::Msgp,
            ly: 2,
            lu: 2,
            inducing: 100,
            iterations: 400,
            optimizer: FitOptimizer::Adam,
            learning_rate: 0.002,
            seed: 0,
            complexity: Complexity::PseudoDataNll,
            validation_fraction: 0.2,
            eval_every: 10,
            patience: 20,
            noise_floor: 1e-4,
            // the paper optimises "the GP hyperparameters and targets"; moving the pseudo-inputs
            // too overfits (docs/design.md)
            frozen: vec![ParamGroup::PseudoInputs],
            one_step_iterations: 300,
            refit: false,
            mean: MeanFunction::Zero,
            integrators: Vec::new(),
            start_window: StartWindow::Measured,
            threads: Threads::default(),
        }
    }
}

/// How the MSGP loss is minimised.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum FitOptimizer {
    /// Adam with [`FitSettings::learning_rate`] (the paper's choice): runs every iteration
    /// (or until early stopping).
    #[default]
    Adam,
    /// L-BFGS with a backtracking line search ([`Lbfgs`]): far fewer iterations on these smooth,
    /// ill-conditioned losses; stops by itself when converged.
    Lbfgs,
}

impl FitOptimizer {
    /// Display name: "Adam" or "L-BFGS".
    pub fn name(&self) -> &'static str {
        match self {
            FitOptimizer::Adam => "Adam",
            FitOptimizer::Lbfgs => "L-BFGS",
        }
    }
}

/// The L-BFGS of [`FitOptimizer::Lbfgs`]: a first step that moves no parameter by more than
/// 0.01 (as far as a few Adam steps) and no later step by more than 0.3 (log length-scales,
/// log variances and normalised pseudo-targets alike), so that the validation checks, made
/// after every L-BFGS iteration, see the path to the training optimum rather than a jump to it.
pub const FIT_LBFGS: Lbfgs = Lbfgs {
    memory: 10,
    max_step: 0.3,
    first_step: 0.01,
    c1: 1e-4,
    max_backtracks: 30,
    tolerance: 1e-7,
    patience: 5,
};

/// Upper bound of the default number of pseudo-inputs ([`FitOptions::inducing`]).
pub const DEFAULT_MAX_INDUCING: usize = 100;

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
    /// Number of pseudo-inputs; `None`: `min(100, training windows / 2)` (at least 1), where a
    /// trajectory of `T` samples has `T − max(l_y, l_u)` windows.
    pub inducing: Option<usize>,
    /// Adam iterations of the method's own optimisation: on the trajectory likelihood for MSGP
    /// ([`FitSettings::iterations`]), on the one-step marginal likelihood for the baselines
    /// ([`FitSettings::one_step_iterations`]); `None`: the defaults (400 and 300). The MSGP
    /// initialisation always runs the default one-step iterations.
    pub iterations: Option<usize>,
    /// Seed of every random choice.
    pub seed: u64,
    /// Prior mean of the GP.
    pub mean: MeanFunction,
    /// Outputs declared integrating ([`crate::gp::integrator`]; needs the linear mean).
    pub integrators: Vec<Integrator>,
    /// Solver of the MSGP loss.
    pub optimizer: FitOptimizer,
    /// Threads of the fit ([`FitSettings::threads`]); front ends take it from
    /// [`Threads::from_env`].
    pub threads: Threads,
}

impl FitOptions {
    /// The full settings for fitting `train`, every other field at its default, checked against
    /// the data ([`FitSettings::validate`]).
    pub fn settings(&self, train: &[Trajectory]) -> Result<FitSettings> {
        if self.inducing == Some(0) {
            return Err(MsgpError::InvalidSetting {
                name: "inducing",
                reason: "need at least one pseudo-input".into(),
            });
        }
        let warmup = self.ly.max(self.lu);
        let windows: usize = train.iter().map(|t| t.len().saturating_sub(warmup)).sum();
        let inducing = self
            .inducing
            .unwrap_or_else(|| DEFAULT_MAX_INDUCING.min((windows / 2).max(1)));
        let settings = FitSettings {
            method: self.method,
            ly: self.ly,
            lu: self.lu,
            inducing,
            seed: self.seed,
            mean: self.mean,
            integrators: self.integrators.clone(),
            optimizer: self.optimizer,
            threads: self.threads,
            ..FitSettings::default()
        };
        let settings = match self.iterations {
            Some(n) => settings.with_solver_iterations(self.method, n),
            None => settings,
        };
        settings.validate(&train.iter().collect::<Vec<_>>())?;
        Ok(settings)
    }
}

impl FitSettings {
    /// `n` iterations of a `method` fit's own solver: on the trajectory likelihood for MSGP
    /// ([`FitSettings::iterations`]; its one-step start keeps its own), on the filter likelihood
    /// for linear-kf (the same field), on the one-step marginal likelihood for the baselines
    /// ([`FitSettings::one_step_iterations`]). (`method` is explicit because the learning loop
    /// keeps one `FitSettings` and sets the method per fit.)
    pub fn with_solver_iterations(self, method: Method, n: usize) -> Self {
        match method {
            Method::Msgp | Method::LinearKf => Self {
                iterations: n,
                ..self
            },
            Method::GpNarx | Method::PilcoNarx => Self {
                one_step_iterations: n,
                ..self
            },
        }
    }

    /// The NARX spec of `train` under these settings, with every setting checked against the
    /// data once, here: the history, the integrators against the history and the prior mean,
    /// the start window, every trajectory's length and values, the pseudo-input count.
    pub fn validate(&self, train: &[&Trajectory]) -> Result<NarxSpec> {
        let first = train
            .first()
            .ok_or_else(|| MsgpError::Data("no training trajectories".into()))?;
        let spec = NarxSpec {
            ly: self.ly,
            lu: self.lu,
            dy: first.y.ncols(),
            du: first.u.ncols(),
        };
        spec.validate()?;
        integrator::validate(&self.integrators, &spec, model_mean(self.method, self.mean))?;
        self.start_window.validate(spec.warmup())?;
        let warmup = spec.warmup();
        for (k, t) in train.iter().enumerate() {
            if t.len() <= warmup {
                return Err(MsgpError::Data(format!(
                    "training trajectory {k} has {} samples; the history (l_y={}, l_u={}) needs \
                     more than {warmup}",
                    t.len(),
                    self.ly,
                    self.lu
                )));
            }
            t.check(&spec)
                .map_err(|e| MsgpError::Data(format!("training trajectory {k}: {e}")))?;
        }
        if self.inducing == 0 {
            return Err(MsgpError::InvalidSetting {
                name: "inducing",
                reason: "need at least one pseudo-input".into(),
            });
        }
        Ok(spec)
    }
}

/// One line of fit progress.
#[derive(Clone, Copy, Debug)]
pub struct FitProgress {
    /// 1: training with early stopping on the held-out tail; 2: refit on all training data.
    pub stage: u8,
    /// Adam iteration.
    pub iteration: usize,
    /// Total iterations planned.
    pub iterations: usize,
    /// Training loss per predicted step.
    pub loss: f64,
    /// Validation NLL per step, when checked at this iteration.
    pub validation: Option<f64>,
    /// Seconds since the fit started.
    pub elapsed: f64,
}

/// What happened during a fit.
#[derive(Clone, Debug, Default, Serialize, Deserialize)]
pub struct FitReport {
    /// Adam iterations run (all stages).
    pub iterations_run: usize,
    /// Iteration chosen by early stopping (the refit runs this many); without a validation
    /// tail, the iteration of the lowest training loss, whose parameters the fit returns.
    pub best_iteration: usize,
    /// (iteration, training loss per step, validation NLL per step).
    pub history: Vec<(usize, f64, f64)>,
    /// Wall-clock seconds.
    pub train_seconds: f64,
    /// Jitter added along the way.
    pub jitter: JitterLog,
    /// Set when an Adam step led to parameters whose rollouts fail numerically (a predictive
    /// covariance that is not positive definite even with jitter, or non-finite values): training
    /// stopped there and kept the last parameters that evaluated.
    #[serde(default)]
    pub numerical_stop: Option<String>,
}

/// The prior mean a `method` model gets when `requested`: a linear-kf model is its linear mean.
fn model_mean(method: Method, requested: MeanFunction) -> MeanFunction {
    match method {
        Method::LinearKf => MeanFunction::Linear,
        _ => requested,
    }
}

/// Fits a model on training trajectories given in original units.
pub fn fit(
    train: &[Trajectory],
    settings: &FitSettings,
    progress: &mut dyn FnMut(&FitProgress),
) -> Result<(Model, FitReport)> {
    fit_observed(train, settings, &mut |p| {
        progress(p);
        ControlFlow::Continue(())
    })
}

/// [`fit`] under an observer that can stop the MSGP training ([`fit_episodes_observed`]).
pub fn fit_observed(
    train: &[Trajectory],
    settings: &FitSettings,
    observe: &mut dyn FnMut(&FitProgress) -> ControlFlow<()>,
) -> Result<(Model, FitReport)> {
    let episodes: Vec<TrainingEpisode> = train
        .iter()
        .map(|t| TrainingEpisode {
            traj: t.clone(),
            policy: None,
        })
        .collect();
    fit_episodes_observed(&episodes, settings, None, observe)
}

/// A training trajectory in original units and, for a feedback trajectory, the policy (in
/// original units) that produced its inputs. MSGP rolls feedback trajectories out in closed
/// loop under their policy (`L_fb`); the one-step baselines use them as data like any other.
#[derive(Clone, Debug, PartialEq)]
pub struct TrainingEpisode {
    /// Inputs and outputs, original units.
    pub traj: Trajectory,
    /// The feedback policy that chose the inputs, if any.
    pub policy: Option<PolicySpec>,
}

/// Fits a model on feed-forward and feedback episodes (original units).
pub fn fit_episodes(
    episodes: &[TrainingEpisode],
    settings: &FitSettings,
    progress: &mut dyn FnMut(&FitProgress),
) -> Result<(Model, FitReport)> {
    fit_episodes_observed(episodes, settings, None, &mut |p| {
        progress(p);
        ControlFlow::Continue(())
    })
}

/// [`fit_episodes`], or with `previous` [`refit_episodes`], under an observer that sees every
/// solver iteration of the MSGP training and can stop it: after a [`ControlFlow::Break`] the
/// fit ends with [`MsgpError::Stopped`]. (The one-step start and the one-step and linear-kf
/// fits report nothing and run to their end.)
pub fn fit_episodes_observed(
    episodes: &[TrainingEpisode],
    settings: &FitSettings,
    previous: Option<&Model>,
    observe: &mut dyn FnMut(&FitProgress) -> ControlFlow<()>,
) -> Result<(Model, FitReport)> {
    if let Some(previous) = previous {
        check_continuation(settings, previous)?;
    }
    fit_episodes_from(episodes, settings, previous, observe)
}

/// Continues training an MSGP model fitted earlier (a *warm start*), typically on fewer of the
/// same episodes, as a policy-search loop adds one episode per iteration: `settings.iterations`
/// solver steps on `episodes` from `previous`'s parameters, in `previous`'s normalised units
/// and with its pseudo-inputs, instead of a new normaliser, one-step fit and k-means. The
/// settings must describe the same model (method MSGP, history, outputs and inputs, pseudo-input
/// count and prior mean). A linear-kf fit continues likewise: L-BFGS from the previous `A` and
/// noise levels alone, instead of its two cold starts.
pub fn refit_episodes(
    episodes: &[TrainingEpisode],
    settings: &FitSettings,
    previous: &Model,
    progress: &mut dyn FnMut(&FitProgress),
) -> Result<(Model, FitReport)> {
    fit_episodes_observed(episodes, settings, Some(previous), &mut |p| {
        progress(p);
        ControlFlow::Continue(())
    })
}

/// Whether `settings` describe a model that can continue `previous` ([`refit_episodes`]).
fn check_continuation(settings: &FitSettings, previous: &Model) -> Result<()> {
    let refuse = |what: String| {
        Err(MsgpError::InvalidSetting {
            name: "warm start",
            reason: what,
        })
    };
    if settings.method != previous.method
        || !matches!(settings.method, Method::Msgp | Method::LinearKf)
    {
        return refuse(format!(
            "only MSGP and linear-kf fits continue from a previous model of their own method \
             (settings: {}, model: {})",
            settings.method.name(),
            previous.method.name()
        ));
    }
    if settings.method == Method::LinearKf {
        if (settings.ly, settings.lu) != (previous.spec.ly, previous.spec.lu) {
            return refuse(format!(
                "the previous model has history ({}, {}); the settings ask for ({}, {})",
                previous.spec.ly, previous.spec.lu, settings.ly, settings.lu
            ));
        }
        return Ok(());
    }
    if (settings.ly, settings.lu) != (previous.spec.ly, previous.spec.lu)
        || settings.inducing != previous.params.pseudo_inputs.nrows()
        || settings.mean != previous.config.mean
    {
        return refuse(format!(
            "the previous model has history ({}, {}), {} pseudo-inputs and a {:?} mean; the \
             settings ask for ({}, {}), {} and {:?}",
            previous.spec.ly,
            previous.spec.lu,
            previous.params.pseudo_inputs.nrows(),
            previous.config.mean,
            settings.ly,
            settings.lu,
            settings.inducing,
            settings.mean
        ));
    }
    Ok(())
}

fn fit_episodes_from(
    episodes: &[TrainingEpisode],
    settings: &FitSettings,
    previous: Option<&Model>,
    progress: &mut dyn FnMut(&FitProgress) -> ControlFlow<()>,
) -> Result<(Model, FitReport)> {
    let start = Instant::now();
    let refs: Vec<&Trajectory> = episodes.iter().map(|e| &e.traj).collect();
    let spec = settings.validate(&refs)?;
    if let Some(p) = previous
        && (p.spec.dy, p.spec.du) != (spec.dy, spec.du)
    {
        return Err(MsgpError::InvalidSetting {
            name: "warm start",
            reason: format!(
                "the previous model has {} outputs and {} inputs, the data {} and {}",
                p.spec.dy, p.spec.du, spec.dy, spec.du
            ),
        });
    }
    let normalizer = match previous {
        Some(p) => p.normalizer.clone(),
        None => Normalizer::fit(&refs)?,
    };
    let norm: Vec<Trajectory> = refs.iter().map(|t| normalizer.apply(t)).collect();
    let mut report = FitReport::default();
    let one_step = OneStepSettings {
        iterations: settings.one_step_iterations,
        pilco_penalty: settings.method == Method::PilcoNarx,
        threads: settings.threads,
        ..OneStepSettings::default()
    };

    if settings.method == Method::LinearKf {
        // scaled, not centred: the linear model has no intercept, and centring would turn the
        // data's mean command into a constant acceleration of the plant
        let scaled = Normalizer {
            u_mean: vec![0.0; spec.du],
            y_mean: vec![0.0; spec.dy],
            ..normalizer
        };
        let norm: Vec<Trajectory> = refs.iter().map(|t| scaled.apply(t)).collect();
        let warm = previous.map(|p| linear_kf::KalmanParams {
            a: p.params.linear_mean.clone(),
            log_process_noise: p.params.log_process_noise.clone(),
            log_obs_noise: p.params.log_obs_noise.clone(),
        });
        let (model, kf) = linear_kf::fit_linear_kf(
            &norm,
            spec,
            &Structure::new(&settings.integrators, &spec),
            scaled,
            settings.iterations,
            warm.as_ref(),
        )?;
        report.iterations_run = kf.iterations_run;
        report.best_iteration = kf.iterations_run;
        report.jitter = kf.jitter;
        report.train_seconds = start.elapsed().as_secs_f64();
        return Ok((model, report));
    }
    if settings.method != Method::Msgp {
        let config = GpConfig {
            mean: settings.mean,
            ..GpConfig::default()
        };
        let nrefs: Vec<&Trajectory> = norm.iter().collect();
        let data = one_step_pairs(&spec, &nrefs)?;
        let params = fit_one_step(
            &data,
            settings.inducing,
            &one_step,
            &config,
            &Structure::new(&settings.integrators, &spec),
            settings.seed,
            &mut report.jitter,
        )?;
        report.train_seconds = start.elapsed().as_secs_f64();
        let model = Model {
            method: settings.method,
            spec,
            params,
            config,
            normalizer,
        };
        return Ok((model, report));
    }

    msgp::fit_msgp(
        episodes, &norm, normalizer, spec, settings, previous, &one_step, start, progress, report,
    )
}

#[cfg(test)]
mod tests;
