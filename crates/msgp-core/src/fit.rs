//! Fitting: the one-step baselines and MSGP (sparse GP-NARX initialisation, then Adam on the
//! trajectory likelihood with exact adjoint gradients).
//!
//! ## Guarding against noise collapse
//! The trajectory likelihood can be lowered by shrinking the noise variances while the free
//! simulation gets worse. Two guards, both documented in `docs/design.md`:
//! 1. a variance floor on `σ_x²` and `σ_y²` ([`FitSettings::noise_floor`], normalised units),
//!    built into the parametrisation `σ² = floor + e^θ`;
//! 2. early stopping on a held-out tail of the *training* data: the last
//!    [`FitSettings::validation_fraction`] of each training trajectory is kept out of training,
//!    its free-simulation NLL is computed every [`FitSettings::eval_every`] iterations, and the
//!    parameters with the best validation NLL are returned. The test data are never seen.

use std::ops::ControlFlow;
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::baseline::{OneStepSettings, fit_one_step, one_step_pairs};
use crate::data::Normalizer;
use crate::error::{MsgpError, Result};
use crate::gp::{GpConfig, GpParams, GpShape, MeanFunction, ParamGroup, PreparedGp};
use crate::grad::adjoint::loss_and_gradient;
use crate::integrator::{self, Integrator, Structure};
use crate::linalg::JitterLog;
use crate::loss::{Complexity, gaussian_nll};
use crate::model::{Method, Model};
use crate::narx::NarxSpec;
use crate::optim::{Adam, Flow, Lbfgs, Objective, Solver, minimize};
use crate::policy::PolicySpec;
use crate::rollout::{Control, rollout_started};
use crate::start_window::StartWindow;
use crate::trajectory::{Episode, Excitation, Trajectory};

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
    /// Outputs known to integrate the rest of the system ([`crate::integrator`]); needs the
    /// linear mean, whose coefficients on their own lags they fix.
    #[serde(default)]
    pub integrators: Vec<Integrator>,
    /// How the MSGP loss starts each training trajectory's rollout ([`StartWindow`]).
    #[serde(default)]
    pub start_window: StartWindow,
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
    /// Outputs declared integrating ([`crate::integrator`]; needs the linear mean).
    pub integrators: Vec<Integrator>,
    /// Solver of the MSGP loss.
    pub optimizer: FitOptimizer,
}

impl FitOptions {
    /// The full settings for fitting `train`, every other field at its default. Checks that
    /// there is training data and that every trajectory is longer than the history.
    pub fn settings(&self, train: &[Trajectory]) -> Result<FitSettings> {
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
        }
        if self.inducing == Some(0) {
            return Err(MsgpError::InvalidSetting {
                name: "inducing",
                reason: "need at least one pseudo-input".into(),
            });
        }
        let windows: usize = train.iter().map(|t| t.len() - warmup).sum();
        let inducing = self
            .inducing
            .unwrap_or_else(|| DEFAULT_MAX_INDUCING.min((windows / 2).max(1)));
        let defaults = FitSettings::default();
        Ok(FitSettings {
            method: self.method,
            ly: self.ly,
            lu: self.lu,
            inducing,
            iterations: match (self.method, self.iterations) {
                (Method::Msgp | Method::LinearKf, Some(n)) => n,
                _ => defaults.iterations,
            },
            one_step_iterations: match (self.method, self.iterations) {
                (Method::Msgp, _) | (_, None) => defaults.one_step_iterations,
                (_, Some(n)) => n,
            },
            seed: self.seed,
            mean: self.mean,
            integrators: self.integrators.clone(),
            optimizer: self.optimizer,
            ..defaults
        })
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

struct MsgpObjective<'a> {
    shape: GpShape,
    spec: NarxSpec,
    config: GpConfig,
    episodes: &'a [Episode],
    complexity: Complexity,
    log: JitterLog,
    /// The numerical failure of the latest evaluation, if it failed (the loss is then reported
    /// as NaN).
    failure: Option<MsgpError>,
}

impl Objective for MsgpObjective<'_> {
    fn value_and_gradient(&mut self, x: &[f64]) -> Result<(f64, Vec<f64>)> {
        let params = GpParams::from_flat(self.shape, x)?;
        let evaluated = loss_and_gradient(
            &params,
            &self.config,
            &self.spec,
            self.episodes,
            self.complexity,
            &mut self.log,
        );
        let (v, mut g) = match evaluated {
            Err(e @ (MsgpError::NotPositiveDefinite { .. } | MsgpError::NonFinite(_))) => {
                self.failure = Some(e);
                return Ok((f64::NAN, vec![0.0; x.len()]));
            }
            other => other?,
        };
        // a line search may step back from a failed trial: only a failure at the end counts
        self.failure = None;
        let scale = 1.0 / v.steps.max(1) as f64;
        g.iter_mut().for_each(|gi| *gi *= scale);
        Ok((v.total() * scale, g))
    }
}

/// Mean NLL per step of free simulations of `episodes` (normalised units).
fn validation_nll(
    params: &GpParams<f64>,
    config: &GpConfig,
    spec: &NarxSpec,
    episodes: &[Episode],
) -> Result<f64> {
    let mut log = JitterLog::default();
    let gp = PreparedGp::new(params, config, &mut log)?;
    let mut total = 0.0;
    let mut steps = 0usize;
    for ep in episodes {
        let mut row = vec![0.0; spec.dy];
        rollout_started(
            &gp,
            spec,
            &ep.traj,
            &Control::FeedForward,
            ep.traj.len(),
            gp.start,
            &mut log,
            |p| {
                for j in 0..spec.dy {
                    row[j] = ep.traj.y[(p.t, j)];
                }
                let mut l2 = JitterLog::default();
                total += gaussian_nll(&row, &p.mean, &p.cov, &config.jitter, &mut l2)?;
                steps += 1;
                Ok(())
            },
        )?;
    }
    Ok(total / steps.max(1) as f64)
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
    let train: Vec<Trajectory> = episodes.iter().map(|e| e.traj.clone()).collect();
    let first = train
        .first()
        .ok_or_else(|| MsgpError::Data("no training trajectories".into()))?;
    let spec = NarxSpec {
        ly: settings.ly,
        lu: settings.lu,
        dy: first.y.ncols(),
        du: first.u.ncols(),
    };
    spec.validate()?;
    integrator::validate(
        &settings.integrators,
        &spec,
        model_mean(settings.method, settings.mean),
    )?;
    settings.start_window.validate(spec.warmup())?;
    for (k, t) in train.iter().enumerate() {
        t.check(&spec)
            .map_err(|e| MsgpError::Data(format!("training trajectory {k}: {e}")))?;
    }
    if settings.inducing == 0 {
        return Err(MsgpError::InvalidSetting {
            name: "inducing",
            reason: "need at least one pseudo-input".into(),
        });
    }
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
    let refs: Vec<&Trajectory> = train.iter().collect();
    let normalizer = match previous {
        Some(p) => p.normalizer.clone(),
        None => Normalizer::fit(&refs)?,
    };
    let norm: Vec<Trajectory> = train.iter().map(|t| normalizer.apply(t)).collect();
    let mut report = FitReport::default();
    let one_step = OneStepSettings {
        iterations: settings.one_step_iterations,
        pilco_penalty: settings.method == Method::PilcoNarx,
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
        let norm: Vec<Trajectory> = train.iter().map(|t| scaled.apply(t)).collect();
        let warm = previous.map(|p| crate::kalman::KalmanParams {
            a: p.params.linear_mean.clone(),
            log_process_noise: p.params.log_process_noise.clone(),
            log_obs_noise: p.params.log_obs_noise.clone(),
        });
        let (model, kf) = crate::kalman::fit_linear_kf(
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

    // MSGP: split each trajectory into a training head and a validation tail.
    // Feedback episodes train in closed loop under their (normalised) policy and are not split.
    let w = spec.warmup();
    let mut head_eps = Vec::new();
    let mut all_eps = Vec::new();
    let mut tails = Vec::new();
    for (t, ep) in norm.iter().zip(episodes) {
        if let Some(p) = &ep.policy {
            let fb = Episode {
                traj: t.clone(),
                excitation: Excitation::Feedback(Box::new(p.normalized(&normalizer)?)),
            };
            head_eps.push(fb.clone());
            all_eps.push(fb);
            continue;
        }
        all_eps.push(Episode::feed_forward(t.clone()));
        let n_val = (t.len() as f64 * settings.validation_fraction).round() as usize;
        if settings.validation_fraction > 0.0 && n_val >= 10 && t.len() - n_val > w + 10 {
            head_eps.push(Episode::feed_forward(t.slice(0, t.len() - n_val)));
            tails.push(Episode::feed_forward(t.slice(t.len() - n_val - w, t.len())));
        } else {
            head_eps.push(Episode::feed_forward(t.clone()));
        }
    }
    let config = GpConfig {
        noise_floor: settings.noise_floor,
        mean: settings.mean,
        start: settings.start_window,
        ..GpConfig::default()
    };
    let mut stage = Stage {
        spec,
        config,
        settings,
        start,
        progress,
        report: &mut report,
    };
    let init = match previous {
        Some(p) => p.params.clone(),
        None => stage.initial(&head_eps, &one_step)?,
    };
    let (mut chosen, best_iteration) =
        stage.train(init, &head_eps, &tails, settings.iterations, 1)?;
    stage.report.best_iteration = best_iteration;
    if settings.refit && !tails.is_empty() {
        // stage 2: the same number of iterations on the whole training data
        let init = match previous {
            Some(p) => p.params.clone(),
            None => stage.initial(&all_eps, &one_step)?,
        };
        chosen = if best_iteration == 0 {
            init
        } else {
            stage.train(init, &all_eps, &[], best_iteration, 2)?.0
        };
    }
    report.train_seconds = start.elapsed().as_secs_f64();
    let model = Model {
        method: Method::Msgp,
        spec,
        params: chosen,
        config,
        normalizer,
    };
    Ok((model, report))
}

/// One MSGP training run: initialisation and Adam with optional early stopping.
struct Stage<'a, 'p> {
    spec: NarxSpec,
    config: GpConfig,
    settings: &'a FitSettings,
    start: Instant,
    progress: &'p mut dyn FnMut(&FitProgress) -> ControlFlow<()>,
    report: &'a mut FitReport,
}

impl Stage<'_, '_> {
    /// The sparse one-step GP-NARX fit on `episodes`, with the one-step noise split equally
    /// between process and observation noise.
    fn initial(
        &mut self,
        episodes: &[Episode],
        one_step: &OneStepSettings,
    ) -> Result<GpParams<f64>> {
        let refs: Vec<&Trajectory> = episodes.iter().map(|e| &e.traj).collect();
        let data = one_step_pairs(&self.spec, &refs)?;
        let mut init = fit_one_step(
            &data,
            self.settings.inducing,
            one_step,
            &self.config,
            &Structure::new(&self.settings.integrators, &self.spec),
            self.settings.seed,
            &mut self.report.jitter,
        )?;
        let floor = self.config.noise_floor;
        for a in 0..self.spec.dy {
            let total = init.log_process_noise[a].exp() + floor;
            let half = (0.5 * total - floor).max(1e-3 * floor);
            init.log_process_noise[a] = half.ln();
            init.log_obs_noise[a] = half.ln();
        }
        let m = init.pseudo_inputs.nrows();
        let predicted: usize = episodes
            .iter()
            .map(|e| e.traj.len() - self.spec.warmup())
            .sum();
        if self.settings.complexity == Complexity::NegHalfLogDet && predicted <= m {
            return Err(MsgpError::InvalidSetting {
                name: "inducing",
                reason: format!(
                    "the complexity term −½log|K̃| is bounded only when the training rollouts predict \
                     more steps ({predicted}) than there are pseudo-inputs ({m}); use fewer pseudo-inputs"
                ),
            });
        }
        Ok(init)
    }

    /// The solver from `init` for up to `iterations` steps. With validation episodes, checks them
    /// every `eval_every` steps, stops after `patience` checks without improvement and returns the
    /// parameters of the best validation NLL and their iteration; otherwise returns the iterate of
    /// the lowest training loss (the last one, unless a late Adam step threw the loss up).
    fn train(
        &mut self,
        init: GpParams<f64>,
        episodes: &[Episode],
        tails: &[Episode],
        iterations: usize,
        stage: u8,
    ) -> Result<(GpParams<f64>, usize)> {
        let shape = init.shape()?;
        let mut active = vec![true; shape.len()];
        let no_mean = (self.config.mean == MeanFunction::Zero).then_some(ParamGroup::LinearMean);
        for g in self.settings.frozen.iter().chain(no_mean.iter()) {
            for i in shape.group_range(*g) {
                active[i] = false;
            }
        }
        // what integrating outputs fix (`linear_mean` and `log_lengthscales` flatten by rows)
        let structure = Structure::new(&self.settings.integrators, &self.spec);
        let mean_start = shape.group_range(ParamGroup::LinearMean).start;
        for c in &structure.fixed {
            active[mean_start + c.row * shape.d + c.col] = false;
        }
        let ls_start = shape.group_range(ParamGroup::Lengthscales).start;
        for row in 0..shape.e {
            for &col in &structure.ignored {
                active[ls_start + row * shape.d + col] = false;
            }
        }
        // outputs without a GP (`pseudo_targets` flattens by pseudo-input, then output)
        let targets_start = shape.group_range(ParamGroup::PseudoTargets).start;
        let sf_start = shape.group_range(ParamGroup::SignalVar).start;
        for &a in &structure.without_gp {
            for i in 0..shape.m {
                active[targets_start + i * shape.e + a] = false;
            }
            for k in 0..shape.d {
                active[ls_start + a * shape.d + k] = false;
            }
            active[sf_start + a] = false;
        }
        let mut objective = MsgpObjective {
            shape,
            spec: self.spec,
            config: self.config,
            episodes,
            complexity: self.settings.complexity,
            log: JitterLog::default(),
            failure: None,
        };
        let solver = match self.settings.optimizer {
            FitOptimizer::Adam => Solver::Adam(Adam {
                learning_rate: self.settings.learning_rate,
                ..Adam::default()
            }),
            FitOptimizer::Lbfgs => Solver::Lbfgs(FIT_LBFGS),
        };
        let (spec, config, settings, start) = (self.spec, self.config, self.settings, self.start);
        let every = match settings.optimizer {
            FitOptimizer::Adam => settings.eval_every.max(1),
            FitOptimizer::Lbfgs => 1,
        };
        let mut best: (f64, Vec<f64>, usize) = (f64::INFINITY, init.to_flat(), 0);
        let mut since_best = 0usize;
        let mut good: Option<(Vec<f64>, usize)> = None;
        let report = &mut *self.report;
        let progress = &mut *self.progress;
        let mut last_it = iterations;
        let mut stopped = None;
        let (last_x, _) = minimize(
            &mut objective,
            &solver,
            init.to_flat(),
            &active,
            iterations + 1,
            |it, loss, x| {
                if loss.is_nan() {
                    // the parameters of this step failed numerically (see `failure`)
                    return Ok(Flow::Stop);
                }
                good = Some((x.to_vec(), it));
                last_it = it;
                // without a validation tail, the best iterate is the one of lowest training loss:
                // Adam's steps at the loop's step size throw the loss up now and then (by up to
                // 2.7 nats per step on the loop's data), for tens of iterations, also at the last
                if tails.is_empty() && loss < best.0 {
                    best = (loss, x.to_vec(), it);
                }
                let mut validation = None;
                if !tails.is_empty() && (it % every == 0 || it == iterations) {
                    let p = GpParams::from_flat(shape, x)?;
                    let v = validation_nll(&p, &config, &spec, tails)?;
                    validation = Some(v);
                    report.history.push((it, loss, v));
                    if v < best.0 {
                        best = (v, x.to_vec(), it);
                        since_best = 0;
                    } else {
                        since_best += 1;
                    }
                }
                report.iterations_run += 1;
                let seen = progress(&FitProgress {
                    stage,
                    iteration: it,
                    iterations,
                    loss,
                    validation,
                    elapsed: start.elapsed().as_secs_f64(),
                });
                if seen.is_break() {
                    stopped = Some(it);
                    return Ok(Flow::Stop);
                }
                if it == iterations || (!tails.is_empty() && since_best >= settings.patience) {
                    return Ok(Flow::Stop);
                }
                Ok(Flow::Continue)
            },
        )?;
        report.jitter.merge(&objective.log);
        if let Some(iteration) = stopped {
            return Err(MsgpError::Stopped { iteration });
        }
        let (x, it) = match (objective.failure.take(), good) {
            (Some(e), None) => return Err(e),
            (Some(e), Some((x, it))) => {
                report.numerical_stop = Some(format!(
                    "stage {stage}: stopped at iteration {} of {iterations}: {e}; kept iteration {it}",
                    it + 1
                ));
                if best.0.is_finite() {
                    (best.1, best.2)
                } else {
                    (x, it)
                }
            }
            (None, _) if tails.is_empty() && !best.0.is_finite() => (last_x, last_it),
            (None, _) => (best.1, best.2),
        };
        Ok((GpParams::from_flat(shape, &x)?, it))
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::rollout::rollout;
    use nalgebra::DMatrix;

    fn traj(n: usize) -> Trajectory {
        let u: Vec<f64> = (0..n).map(|i| (i as f64 * 0.3).sin()).collect();
        let y: Vec<f64> = (0..n).map(|i| (i as f64 * 0.2).cos()).collect();
        Trajectory::siso(&u, &y).expect("finite")
    }

    fn options(method: Method, inducing: Option<usize>, iterations: Option<usize>) -> FitOptions {
        FitOptions {
            method,
            ly: 2,
            lu: 3,
            inducing,
            iterations,
            seed: 7,
            mean: MeanFunction::Zero,
            integrators: Vec::new(),
            optimizer: FitOptimizer::Adam,
        }
    }

    /// A warm start continues the previous model: zero iterations give it back unchanged (same
    /// parameters and normaliser, although the new data would normalise differently), more
    /// iterations lower the loss on the new data from there, and a model of another shape is
    /// refused.
    #[test]
    fn a_warm_start_continues_the_previous_model() {
        let first: Vec<TrainingEpisode> = [traj(60), traj(50)]
            .into_iter()
            .map(|traj| TrainingEpisode { traj, policy: None })
            .collect();
        let settings = FitSettings {
            ly: 2,
            lu: 2,
            inducing: 12,
            iterations: 15,
            validation_fraction: 0.0,
            ..FitSettings::default()
        };
        let (previous, _) = fit_episodes(&first, &settings, &mut |_| {}).expect("first fit");
        // more data, with another mean and scale
        let mut more = first.clone();
        let u: Vec<f64> = (0..70).map(|i| 2.0 + (i as f64 * 0.17).sin()).collect();
        let y: Vec<f64> = (0..70)
            .map(|i| 1.0 + 3.0 * (i as f64 * 0.11).cos())
            .collect();
        more.push(TrainingEpisode {
            traj: Trajectory::siso(&u, &y).expect("finite"),
            policy: None,
        });
        let zero = FitSettings {
            iterations: 0,
            ..settings.clone()
        };
        let (same, _) = refit_episodes(&more, &zero, &previous, &mut |_| {}).expect("refit 0");
        assert_eq!(same.params, previous.params);
        assert_eq!(same.normalizer, previous.normalizer);
        let mut losses = Vec::new();
        let (cont, report) =
            refit_episodes(&more, &settings, &previous, &mut |p| losses.push(p.loss))
                .expect("refit");
        assert_eq!(report.iterations_run, 16);
        assert_eq!(cont.normalizer, previous.normalizer);
        assert_eq!(cont.params.pseudo_inputs, previous.params.pseudo_inputs);
        assert!(
            losses[losses.len() - 1] < losses[0] - 1e-3,
            "{} → {}",
            losses[0],
            losses[losses.len() - 1]
        );
        // from scratch on the same data, the start is the one-step fit: another first loss
        let mut scratch = Vec::new();
        fit_episodes(&more, &zero, &mut |p| scratch.push(p.loss)).expect("scratch");
        assert_ne!(scratch[0], losses[0]);
        for (bad, needle) in [
            (
                FitSettings {
                    inducing: 13,
                    ..settings.clone()
                },
                "13",
            ),
            (
                FitSettings {
                    method: Method::GpNarx,
                    ..settings.clone()
                },
                "only MSGP",
            ),
            (
                FitSettings {
                    lu: 3,
                    ..settings.clone()
                },
                "(2, 3)",
            ),
        ] {
            let e = refit_episodes(&more, &bad, &previous, &mut |_| {}).expect_err("refused");
            assert!(e.to_string().contains(needle), "{e}");
        }
    }

    /// 80 samples of `y_t = 0.9 y_{t−1} + 0.5 u_{t−1} + a sin(3 y_{t−1})` under a sine input.
    fn first_order(a: f64) -> Trajectory {
        let u: Vec<f64> = (0..80).map(|i| (i as f64 * 0.37).sin()).collect();
        let mut y = vec![0.0; 80];
        for t in 1..80 {
            y[t] = 0.9 * y[t - 1] + 0.5 * u[t - 1] + a * (y[t - 1] * 3.0).sin();
        }
        Trajectory::siso(&u, &y).expect("finite")
    }

    /// Without a validation tail the fit returns the iterate of lowest training loss: a step
    /// size large enough to throw the loss up near the end of the run (but not to fail
    /// numerically) ends above its best, and the fit still returns the best iterate, bit for
    /// bit the parameters of the same fit stopped at that iteration.
    #[test]
    fn without_validation_the_fit_returns_its_lowest_training_loss() {
        let traj = first_order(0.2);
        let settings = FitSettings {
            ly: 1,
            lu: 1,
            inducing: 10,
            iterations: 300,
            learning_rate: 0.04,
            validation_fraction: 0.0,
            mean: MeanFunction::Linear,
            ..FitSettings::default()
        };
        let mut losses = Vec::new();
        let (model, report) = fit(std::slice::from_ref(&traj), &settings, &mut |p| {
            losses.push(p.loss)
        })
        .expect("fit");
        assert!(
            report.numerical_stop.is_none(),
            "{:?}",
            report.numerical_stop
        );
        assert_eq!(losses.len(), settings.iterations + 1);
        let (best, lowest) = losses
            .iter()
            .copied()
            .enumerate()
            .fold((0, f64::INFINITY), |a, b| if b.1 < a.1 { b } else { a });
        assert!(
            best < settings.iterations && losses[settings.iterations] > lowest + 1e-2,
            "the run must end above its best for the test to mean anything: {losses:?}"
        );
        assert_eq!(report.best_iteration, best);
        let stopped = FitSettings {
            iterations: best,
            ..settings.clone()
        };
        let (at_best, _) =
            fit(std::slice::from_ref(&traj), &stopped, &mut |_| {}).expect("fit to the best");
        assert_eq!(model.params, at_best.params);
    }

    /// An observer that breaks stops the MSGP training at that iteration with
    /// [`MsgpError::Stopped`]; one that never breaks gives what [`fit_episodes`] gives.
    #[test]
    fn an_observer_can_stop_a_fit() {
        let episodes = [TrainingEpisode {
            traj: first_order(0.2),
            policy: None,
        }];
        let settings = FitSettings {
            ly: 1,
            lu: 1,
            inducing: 10,
            iterations: 40,
            validation_fraction: 0.0,
            mean: MeanFunction::Linear,
            ..FitSettings::default()
        };
        let mut seen = Vec::new();
        let err = fit_episodes_observed(&episodes, &settings, None, &mut |p| {
            seen.push(p.iteration);
            if p.iteration == 5 {
                ControlFlow::Break(())
            } else {
                ControlFlow::Continue(())
            }
        })
        .expect_err("stopped");
        assert!(matches!(err, MsgpError::Stopped { iteration: 5 }), "{err}");
        assert_eq!(seen, (0..=5).collect::<Vec<_>>());
        let (observed, _) = fit_episodes_observed(&episodes, &settings, None, &mut |_| {
            ControlFlow::Continue(())
        })
        .expect("fit");
        let (plain, _) = fit_episodes(&episodes, &settings, &mut |_| {}).expect("fit");
        assert_eq!(observed.params, plain.params);
    }

    #[test]
    fn a_numerically_failing_step_keeps_parameters_that_evaluate() {
        // an absurd step size drives the rollout covariances to overflow within a few steps
        let traj = first_order(0.0);
        let settings = FitSettings {
            ly: 1,
            lu: 1,
            inducing: 10,
            iterations: 200,
            learning_rate: 30.0,
            validation_fraction: 0.0,
            mean: MeanFunction::Linear,
            ..FitSettings::default()
        };
        let (model, report) =
            fit(std::slice::from_ref(&traj), &settings, &mut |_| {}).expect("fit survives");
        let stop = report
            .numerical_stop
            .expect("the step size is absurd enough to fail");
        assert!(stop.contains("kept iteration"), "{stop}");
        assert!(report.iterations_run < 201);
        // the kept parameters evaluate
        let mut log = JitterLog::default();
        let gp = PreparedGp::new(&model.params, &model.config, &mut log).expect("kept model");
        let norm = model.normalizer.apply(&traj);
        rollout(
            &gp,
            &model.spec,
            &norm,
            &Control::FeedForward,
            norm.len(),
            &mut log,
            |_| Ok(()),
        )
        .expect("kept model rolls out");
    }

    /// `y₀` a first-order lag `a y₀ + b u`, `y₁` a double integrator of `d u`, from rest, and
    /// their measurements with a deterministic ripple of amplitude `ripple`; returns the clean
    /// outputs too. `y₁` declared a kinematic double integrator: [`KINEMATIC_Y1`].
    fn lag_and_double_integrator(
        u: DMatrix<f64>,
        (a, b, d): (f64, f64, f64),
        ripple: f64,
    ) -> (DMatrix<f64>, Trajectory) {
        let n = u.nrows();
        let mut y = DMatrix::<f64>::zeros(n, 2);
        for t in 1..n - 1 {
            y[(t + 1, 0)] = a * y[(t, 0)] + b * u[(t, 0)];
            y[(t + 1, 1)] = 2.0 * y[(t, 1)] - y[(t - 1, 1)] + d * u[(t, 0)];
        }
        let measured = y.map(|v| v + ripple * (10.0 * v / ripple).sin());
        (y, Trajectory::new(u, measured).expect("trajectory"))
    }

    const KINEMATIC_Y1: crate::integrator::Integrator = crate::integrator::Integrator {
        output: 1,
        order: 2,
        linear: true,
    };

    /// A linear-kf fit of a double integrator driven by a command with a non-zero mean: the
    /// model is scaled, not centred (a centred linear model without intercept would lose the
    /// mean command's constant acceleration, and its free simulation would drift away
    /// quadratically), keeps the declared coefficients and has no GP.
    #[test]
    fn a_linear_kf_fit_simulates_an_integrator_under_a_mean_command() {
        let n = 200;
        let u = DMatrix::from_fn(n, 1, |t, _| 0.5 + 0.3 * (0.1 * t as f64).sin());
        let (clean, traj) = lag_and_double_integrator(u, (0.9, 0.1, 1e-3), 1e-4);
        let integrators = vec![KINEMATIC_Y1];
        let settings = FitSettings {
            method: Method::LinearKf,
            ly: 2,
            lu: 1,
            iterations: 200,
            integrators: integrators.clone(),
            ..FitSettings::default()
        };
        let (model, report) =
            fit(std::slice::from_ref(&traj), &settings, &mut |_| {}).expect("fit");
        assert_eq!(model.method, Method::LinearKf);
        assert!(report.iterations_run > 0);
        assert!(model.normalizer.u_mean.iter().all(|&m| m == 0.0));
        assert!(model.normalizer.y_mean.iter().all(|&m| m == 0.0));
        for c in &Structure::new(&integrators, &model.spec).fixed {
            assert_eq!(model.params.linear_mean[(c.row, c.col)], c.value);
        }
        assert!(model.params.pseudo_targets.iter().all(|&v| v == 0.0));
        // free simulation over 200 steps: the mean command alone moves y₁ by ≈ 10 units
        let sim = model.simulate(&traj).expect("simulate");
        let last = sim.mean.nrows() - 1;
        let err = (sim.mean[(last, 1)] - clean[(n - 1, 1)]).abs();
        assert!(
            err < 0.05 * clean[(n - 1, 1)].abs(),
            "end effector off by {err}"
        );
        let err0 = (sim.mean[(last, 0)] - clean[(n - 1, 0)]).abs();
        assert!(err0 < 0.01, "first output off by {err0}");
    }

    /// A linear-kf warm start continues the previous model: zero iterations return its
    /// parameters and units exactly, more iterations do not make the filter's likelihood of the
    /// new data worse than there, and a model of another method is refused.
    #[test]
    fn a_linear_kf_fit_continues_the_previous_model() {
        let n = 200;
        let u = DMatrix::from_fn(n, 1, |t, _| 0.5 + 0.3 * (0.1 * t as f64).sin());
        let (_, traj) = lag_and_double_integrator(u, (0.9, 0.1, 1e-3), 1e-4);
        let episode = |t: Trajectory| TrainingEpisode {
            traj: t,
            policy: None,
        };
        let settings = FitSettings {
            method: Method::LinearKf,
            ly: 2,
            lu: 1,
            iterations: 100,
            integrators: vec![KINEMATIC_Y1],
            ..FitSettings::default()
        };
        let (first, _) =
            fit_episodes(&[episode(traj.slice(0, 120))], &settings, &mut |_| {}).expect("fit");
        let all = [episode(traj.clone())];
        let again = |iterations| {
            refit_episodes(
                &all,
                &FitSettings {
                    iterations,
                    ..settings.clone()
                },
                &first,
                &mut |_| {},
            )
            .expect("warm start")
            .0
        };
        let same = again(0);
        assert_eq!(same.params, first.params);
        assert_eq!(same.normalizer, first.normalizer);
        let more = again(50);
        let nll = |m: &Model| {
            let t = m.normalizer.apply(&traj);
            let p = crate::kalman::KalmanParams {
                a: m.params.linear_mean.clone(),
                log_process_noise: m.params.log_process_noise.clone(),
                log_obs_noise: m.params.log_obs_noise.clone(),
            };
            let mut log = JitterLog::default();
            crate::kalman::kalman_nll(&p, &m.spec, &[&t], &m.config.jitter, &mut log)
                .expect("filter")
                .0
        };
        assert!(
            nll(&more) <= nll(&first),
            "{} > {}",
            nll(&more),
            nll(&first)
        );
        let (gp, _) = fit_episodes(
            &all,
            &FitSettings {
                method: Method::GpNarx,
                inducing: 10,
                one_step_iterations: 5,
                mean: MeanFunction::Linear,
                ..settings.clone()
            },
            &mut |_| {},
        )
        .expect("gp-narx fit");
        assert!(refit_episodes(&all, &settings, &gp, &mut |_| {}).is_err());
    }

    /// A driven double integrator `y₁` next to a damped output `y₀`: declared a linear
    /// integrator, `y₁`'s coefficients, the GP's length-scales on its lags and `y₁`'s absent GP
    /// come out of an MSGP fit exactly as the declaration set them, while the rest of the model
    /// was trained.
    #[test]
    fn an_msgp_fit_keeps_what_an_integrating_output_fixes() {
        use crate::integrator::{IGNORED_LENGTHSCALE, NO_GP_SIGNAL_VAR, Structure};
        let n = 120;
        let u = DMatrix::from_fn(n, 1, |t, _| {
            (0.3 * t as f64).sin() + (0.71 * t as f64).cos()
        });
        let (_, traj) = lag_and_double_integrator(u, (0.8, 0.3, 0.01), 1e-3);
        let integrators = vec![KINEMATIC_Y1];
        let settings = FitSettings {
            ly: 2,
            lu: 1,
            inducing: 15,
            iterations: 20,
            learning_rate: 0.01,
            validation_fraction: 0.0,
            mean: MeanFunction::Linear,
            integrators: integrators.clone(),
            ..FitSettings::default()
        };
        let (model, _) = fit(std::slice::from_ref(&traj), &settings, &mut |_| {}).expect("fit");
        let structure = Structure::new(&integrators, &model.spec);
        let p = &model.params;
        for c in &structure.fixed {
            assert_eq!(p.linear_mean[(c.row, c.col)], c.value, "{}", p.linear_mean);
        }
        for &col in &structure.ignored {
            assert_eq!(p.log_lengthscales[(0, col)], IGNORED_LENGTHSCALE.ln());
            assert!(p.pseudo_inputs.column(col).iter().all(|&v| v == 0.0));
        }
        // `linear`: y₁ has no GP
        assert_eq!(structure.without_gp, vec![1]);
        assert!(p.pseudo_targets.column(1).iter().all(|&v| v == 0.0));
        assert_eq!(p.log_signal_var[1], NO_GP_SIGNAL_VAR.ln());
        // the free part was trained: the same fit without Adam steps differs
        let (start, _) = fit(
            std::slice::from_ref(&traj),
            &FitSettings {
                iterations: 0,
                ..settings.clone()
            },
            &mut |_| {},
        )
        .expect("start");
        let u0 = model.spec.u_index(0, 0);
        assert_ne!(p.linear_mean[(1, u0)], start.params.linear_mean[(1, u0)]);
        // an integrator without the linear mean is refused
        let err = fit(
            std::slice::from_ref(&traj),
            &FitSettings {
                mean: MeanFunction::Zero,
                ..settings
            },
            &mut |_| {},
        )
        .expect_err("needs the linear mean");
        assert!(err.to_string().contains("integrators"), "{err}");
    }

    #[test]
    fn options_default_inducing_and_iterations() {
        // 2 × (50 − 3) = 94 windows → 47 pseudo-inputs; 1000 − 3 windows → capped at 100
        let s = options(Method::Msgp, None, Some(30))
            .settings(&[traj(50), traj(50)])
            .expect("settings");
        assert_eq!(
            (s.inducing, s.iterations, s.one_step_iterations),
            (47, 30, 300)
        );
        assert_eq!((s.ly, s.lu, s.seed), (2, 3, 7));
        let s = options(Method::GpNarx, None, Some(30))
            .settings(&[traj(1000)])
            .expect("settings");
        assert_eq!(
            (s.inducing, s.iterations, s.one_step_iterations),
            (100, 400, 30)
        );
        let s = options(Method::PilcoNarx, Some(5), None)
            .settings(&[traj(4)])
            .expect("settings");
        assert_eq!((s.inducing, s.one_step_iterations), (5, 300));
        let d = FitSettings::default();
        assert_eq!(
            (s.learning_rate, s.frozen.clone()),
            (d.learning_rate, d.frozen)
        );
    }

    #[test]
    fn options_refuse_bad_input_clearly() {
        let e = options(Method::Msgp, None, None)
            .settings(&[traj(10), traj(3)])
            .expect_err("short");
        assert!(
            e.to_string()
                .contains("training trajectory 1 has 3 samples"),
            "{e}"
        );
        let e = options(Method::Msgp, None, None)
            .settings(&[])
            .expect_err("empty");
        assert!(e.to_string().contains("no training trajectories"), "{e}");
        let e = options(Method::Msgp, Some(0), None)
            .settings(&[traj(10)])
            .expect_err("m = 0");
        assert!(e.to_string().contains("inducing"), "{e}");
        let e = FitOptions {
            ly: 0,
            ..options(Method::Msgp, None, None)
        }
        .settings(&[traj(10)])
        .expect_err("l_y = 0");
        assert!(e.to_string().contains("l_y"), "{e}");
    }
}
