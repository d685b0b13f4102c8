//! Fitting a model to trajectories: MSGP (`msgp`: the trajectory likelihood), the one-step
//! baselines GP-NARX and PILCO GP-NARX ([`one_step`]: the marginal likelihood of one-step
//! pairs) and linear-kf ([`linear_kf`]: the window model without a GP, by the exact
//! Kalman-filter likelihood); [`history`] chooses the NARX history from the data.
//!
//! Data path: trajectories in original units → [`Normalizer`] (fitted on the training data) →
//! the method's own fit → a [`Model`] in normalised units that carries its normaliser. The
//! entry points ([`fit`], [`fit_episodes`], [`refit_episodes`] and their `_observed` forms) all
//! run [`fit_episodes_observed`]; front ends build their [`FitSettings`] from the user's
//! [`FitOptions`].

mod blow_up;
pub mod calibration;
mod continuation;
mod divergence;
pub mod history;
mod hyper;
pub mod linear_kf;
mod msgp;
pub mod one_step;
mod options;
mod proxy_watch;
pub mod resolve;
pub mod segments;
mod settings;
mod vfe;

pub use divergence::{DIVERGENCE_RANGES, OutputRange, check_divergence};
pub use history::{HistoryChoice, HistoryScore, HistorySearch, choose_history};
pub use options::{FEW_INDUCING, FitOptions, MANY_GP_INPUTS};
pub use resolve::{Overrides, Switches};
pub use segments::{LONG_LOG_WINDOWS, Segments};
pub use settings::{
    DEFAULT_FULL_DATA_BLOW_UP, DEFAULT_FULL_DATA_ITERATIONS, DEFAULT_MAX_INDUCING,
    DEFAULT_ONE_STEP_ITERATIONS, FIT_LBFGS, FitOptimizer, FitSettings, LINEAR_RECIPE,
    LinearKfSettings, MethodSettings, MsgpSettings, MsgpStart, NoiseStart, OneStepFitSettings,
    OneStepObjective, OneStepSolver, Recipe,
};

use std::ops::ControlFlow;
use std::time::Instant;

use serde::{Deserialize, Serialize};

use crate::data::{Normalizer, Trajectory};
use crate::error::{MsgpError, Result};
use crate::gp::integrator::Structure;
use crate::gp::{GpConfig, MeanFunction};
use crate::model::Model;
use crate::numeric::linalg::JitterLog;
use crate::policy::PolicySpec;
use one_step::{OneStepSettings, fit_one_step, one_step_pairs};

/// One line of fit progress.
#[derive(Clone, Copy, Debug)]
pub struct FitProgress {
    /// 1: training with early stopping on the held-out tail; 2: the final training on all the
    /// training data ([`MsgpSettings::full_data_iterations`]); 3: training the
    /// alternative recipe ([`MsgpSettings::alternative`]). On two or more threads the final
    /// training on all the data may start while the alternative recipe still trains, for the
    /// recipe leading at that moment; if the other one overtakes it, stage 2 starts again at
    /// iteration 0 for that one (the model returned does not depend on it). 4: the
    /// calibration's proxy of the final training, on the head alone ([`calibration`]; shown
    /// only when it does not run beside the final training).
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
    /// Adam iterations run (all stages; a head's iterations past its early stop that the
    /// calibration's proxy reads off it included).
    pub iterations_run: usize,
    /// Where the history was chosen from the data (`--history auto`): the choice and every
    /// score ([`history::with_chosen_history`]; set by the front end that searched).
    #[serde(default)]
    pub history_choice: Option<history::HistoryChoice>,
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
    /// Set when the fitted model's free simulation over its feed-forward training trajectories
    /// diverges ([`check_divergence`]): why. The model is returned all the same.
    #[serde(default)]
    pub diverged: Option<String>,
    /// MSGP: each recipe trained ([`MsgpSettings::alternative`]) and its best validation NLL.
    #[serde(default)]
    pub recipes: Vec<RecipeOutcome>,
    /// MSGP: the index in `recipes` of the returned model's recipe.
    #[serde(default)]
    pub chosen_recipe: usize,
    /// MSGP with [`MsgpSettings::full_data_iterations`]: the iterate of the final training on
    /// all the data that the fit returns (its lowest training loss).
    #[serde(default)]
    pub full_data_iteration: Option<usize>,
    /// MSGP: why the final training on all the data failed, if it did (the model trained on
    /// the head is returned then).
    #[serde(default)]
    pub full_data_failed: Option<String>,
    /// MSGP with the final training and [`MsgpSettings::calibrate`]: the output-variance
    /// calibration of the returned model ([`calibration`]).
    #[serde(default)]
    pub calibration: Option<calibration::CalibrationReport>,
    /// MSGP with [`MsgpSettings::segments`]: the segments and how many the training data made.
    #[serde(default)]
    pub segments: Option<(Segments, usize)>,
}

impl FitReport {
    /// MSGP: the returned model's recipe when it is a fallback head
    /// ([`MsgpSettings::blow_up_fallback`]): the settings' own recipe's final training failed
    /// and this head's completed ([`RecipeOutcome::fallback_head`]); `None` otherwise.
    pub fn fallback(&self) -> Option<&RecipeOutcome> {
        self.recipes
            .get(self.chosen_recipe)
            .filter(|r| r.fallback_head && self.full_data_iteration.is_some())
    }

    /// MSGP: the recipe the validation tail preferred whose model diverged over the training
    /// inputs and was set aside for the returned one's ([`RecipeOutcome::diverged`]); `None`
    /// when the returned model is the tail's first choice.
    pub fn set_aside(&self) -> Option<&RecipeOutcome> {
        self.recipes
            .iter()
            .enumerate()
            .find(|(k, r)| *k != self.chosen_recipe && r.diverged.is_some())
            .map(|(_, r)| r)
    }
}

impl RecipeOutcome {
    /// How a fallback head differs from the zero-mean recipe from the one-step start, in a word:
    /// `spread` (its start) or `linear` (its prior mean); `zero` for that recipe itself.
    pub fn fallback_label(&self) -> &'static str {
        match (self.start, self.recipe.mean) {
            (MsgpStart::Spread, _) => "spread",
            (_, MeanFunction::Linear) => "linear",
            _ => "zero",
        }
    }
}

/// How one MSGP recipe did on the validation tail.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct RecipeOutcome {
    /// The recipe.
    pub recipe: Recipe,
    /// Where its training started (records before 2026-12-05, second session: the one-step
    /// fit, or the settings' start).
    #[serde(default)]
    pub start: MsgpStart,
    /// Why its final training on all the data failed, if it ran and did (the zero-mean recipe
    /// from the one-step start then trains its fallback heads:
    /// [`MsgpSettings::blow_up_fallback`]).
    #[serde(default)]
    pub final_failed: Option<String>,
    /// Why its model (its final training's, or its head's where none ran) diverges over the
    /// training inputs ([`check_divergence`]), when that set it aside: another recipe's model,
    /// next in the tail's order, did not diverge and is returned instead.
    #[serde(default)]
    pub diverged: Option<String>,
    /// A fallback head ([`MsgpSettings::blow_up_fallback`]): trained because the settings' own
    /// recipe's final training failed (records before 2026-12-05, sixth session, do not mark
    /// them).
    #[serde(default)]
    pub fallback_head: bool,
    /// Its best validation NLL per step (`None` without a validation tail, or when it failed).
    pub validation: Option<f64>,
    /// Why its training failed numerically, if it did.
    pub failed: Option<String>,
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
        continuation::check(settings, previous)?;
    }
    fit_episodes_from(episodes, settings, previous, observe)
}

/// Continues training an MSGP model fitted earlier (a *warm start*), typically on fewer of the
/// same episodes, as a policy-search loop adds one episode per iteration: `settings.iterations`
/// solver steps on `episodes` from `previous`'s parameters, in `previous`'s normalised units
/// and with its pseudo-inputs, instead of a new normaliser, one-step fit and k-means. The
/// settings must describe the same model (method MSGP, history, outputs and inputs, prior mean,
/// and at least the previous model's pseudo-inputs: a first fit on few windows has fewer than
/// asked, and a continuation on more windows places up to the count asked afresh, their targets
/// the previous GP's mean there: see `continuation`). A linear-kf fit continues likewise:
/// L-BFGS from the previous `A` and noise levels alone, instead of its two cold starts.
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

/// The fit, then the divergence check on its feed-forward training trajectories.
fn fit_episodes_from(
    episodes: &[TrainingEpisode],
    settings: &FitSettings,
    previous: Option<&Model>,
    progress: &mut dyn FnMut(&FitProgress) -> ControlFlow<()>,
) -> Result<(Model, FitReport)> {
    let (model, mut report) = fit_unchecked(episodes, settings, previous, progress, None)?;
    let open_loop: Vec<&Trajectory> = episodes
        .iter()
        .filter(|e| e.policy.is_none())
        .map(|e| &e.traj)
        .collect();
    report.diverged = check_divergence(&model, &open_loop);
    Ok((model, report))
}

/// The fit without the final divergence check; an MSGP fit's choice among its recipes'
/// models judges their divergence by `diverges` where given (the protocol's tests), else by
/// [`check_divergence`].
fn fit_unchecked(
    episodes: &[TrainingEpisode],
    settings: &FitSettings,
    previous: Option<&Model>,
    progress: &mut dyn FnMut(&FitProgress) -> ControlFlow<()>,
    diverges: Option<msgp::Diverges<'_>>,
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
    let structure = Structure::new(&settings.integrators, &spec);
    let mut report = FitReport::default();
    let (pilco_penalty, one_step) = match &settings.method {
        MethodSettings::LinearKf(kf) => {
            // scaled, not centred: the linear model has no intercept, and centring would turn
            // the data's mean command into a constant acceleration of the plant
            let scaled = normalizer.uncentred();
            let norm: Vec<Trajectory> = refs.iter().map(|t| scaled.apply(t)).collect();
            let warm = previous.map(|p| linear_kf::KalmanParams {
                a: p.params.linear_mean.clone(),
                log_process_noise: p.params.log_process_noise.clone(),
                log_obs_noise: p.params.log_obs_noise.clone(),
            });
            let (model, kf) = linear_kf::fit_linear_kf(
                &norm,
                spec,
                &structure,
                scaled,
                kf.iterations,
                warm.as_ref(),
            )?;
            report.iterations_run = kf.iterations_run;
            report.best_iteration = kf.iterations_run;
            report.jitter = kf.jitter;
            report.train_seconds = start.elapsed().as_secs_f64();
            return Ok((model, report));
        }
        MethodSettings::Msgp(msgp) => {
            // the linear-kf start is the linear model's units: scaled, not centred
            let normalizer = match (msgp.start, previous) {
                (MsgpStart::LinearKf, None) => normalizer.uncentred(),
                _ => normalizer,
            };
            let norm: Vec<Trajectory> = refs.iter().map(|t| normalizer.apply(t)).collect();
            let one_step = OneStepSettings {
                iterations: msgp.one_step_iterations,
                solver: msgp.one_step_solver,
                objective: msgp.one_step_objective,
                threads: settings.threads,
                ..OneStepSettings::default()
            };
            let fit = msgp::MsgpFit {
                episodes,
                norm: &norm,
                normalizer: &normalizer,
                spec,
                settings,
                msgp,
                previous,
                one_step: &one_step,
                start,
            };
            return stop_named(progress, |observed| {
                msgp::fit_msgp(fit, observed, report, diverges)
            });
        }
        MethodSettings::GpNarx(s) => (false, s),
        MethodSettings::PilcoNarx(s) => (true, s),
    };
    let norm: Vec<Trajectory> = refs.iter().map(|t| normalizer.apply(t)).collect();
    let config = GpConfig {
        mean: one_step.mean,
        ..GpConfig::default()
    };
    let nrefs: Vec<&Trajectory> = norm.iter().collect();
    let data = one_step_pairs(&spec, &nrefs)?;
    let params = fit_one_step(
        &data,
        one_step.inducing,
        &OneStepSettings {
            iterations: one_step.iterations,
            solver: one_step.solver,
            objective: one_step.objective,
            pilco_penalty,
            threads: settings.threads,
            ..OneStepSettings::default()
        },
        &config,
        &structure,
        settings.seed,
        &mut report.jitter,
    )?;
    report.train_seconds = start.elapsed().as_secs_f64();
    let model = Model {
        method: settings.method(),
        spec,
        params,
        config,
        normalizer,
        calibration: Vec::new(),
    };
    Ok((model, report))
}

/// `fit(progress)`, its stop named by the event `progress` broke on: a training on the other
/// thread, whose events reach the observer relayed, stops a step or more after that event, and
/// the error names the event, as a fit on one thread does.
fn stop_named<T>(
    progress: &mut dyn FnMut(&FitProgress) -> ControlFlow<()>,
    fit: impl FnOnce(&mut dyn FnMut(&FitProgress) -> ControlFlow<()>) -> Result<T>,
) -> Result<T> {
    let mut broke_at = None;
    let fitted = fit(&mut |p: &FitProgress| {
        let flow = progress(p);
        if flow.is_break() && broke_at.is_none() {
            broke_at = Some(p.iteration);
        }
        flow
    });
    match (fitted, broke_at) {
        (Err(MsgpError::Stopped { .. }), Some(iteration)) => Err(MsgpError::Stopped { iteration }),
        (fitted, _) => fitted,
    }
}

#[cfg(test)]
mod tests;
