//! PILCO with MSGP (or one-step GP-NARX) models on the simulated pendulum: learning to balance
//! from scratch (paper section 4.2).
//!
//! The loop: `random_rollouts` episodes of smooth random excitation → fit the model on every
//! episode so far (random ones feed-forward, policy ones in closed loop under the gains that ran
//! them, the paper's `L_fb`) → optimise the PID + PD gains on the model (expected saturating
//! cost of a closed-loop moment-matching rollout from rest, exact dual gradients) → run them on
//! the simulator for one episode → repeat. After every iteration the simulator's stability test
//! judges the gains; it is neither interaction time nor training data. Optionally, from the
//! second iteration on, an MSGP fit continues the previous model ([`LearnSettings::warm_start`]).
//! In the filtered MSGP loop the search runs on the GP model only while it predicts the episodes
//! it had not seen better than the linear model of the same data (`choice`).
//!
//! Outputs are `[θ, x]` (measured), the input is the commanded acceleration; the modelled policy
//! is [`msgp_core::policy::PidPolicy`] with the sine saturation that the simulator's policy
//! applies when its gains say `saturation: sine`.

mod budget;
mod choice;
mod episodes;
mod problem;
mod record;
mod report;
mod settings;

pub use budget::{Budget, EXPERIMENT_KEYS, Experiment};
pub use choice::{HeldOut, ModelChoice, SearchModel};
pub use episodes::{episode_trajectory, segments};
use episodes::{expected_cost, feedback_episode, interact, msgp_segments};
use problem::gains_from;
pub use problem::{episode_cost, modelled_policy, pendulum_problem};
pub use record::{FinishedRun, finished_run, summary, write_run_dir};
pub use report::{IterationReport, LearnOutcome};
pub use settings::{
    END_EFFECTOR_INTEGRATOR, END_EFFECTOR_KINEMATIC, EVALUATION_EPISODES, FILTER_NOISE_FLOOR,
    FILTERED_MSGP_INDUCING, FILTERED_MSGP_ITERATIONS, FILTERED_MSGP_SEARCH_ITERATIONS,
    FILTERED_MSGP_WARM_START, LEARN_INDUCING, LINEAR_KF_POLICY_HORIZON_SECONDS,
    LINEAR_KF_WARM_START, LearnSettings, learn_excitation,
};

use std::ops::ControlFlow;

use nalgebra::{DMatrix, DVector};

use msgp_core::fit::{
    FitProgress, FitReport, FitSettings, TrainingEpisode, fit_episodes, fit_episodes_observed,
};
use msgp_core::model::{Method, Model};
use msgp_core::policy_search::cost::SaturatingCost;
use msgp_core::policy_search::{
    PidMask, PolicySearchResult, PolicySearchSettings, optimise_pid_scaled,
};

use crate::controller::{PidPdGains, RandomExcitation, Saturation};
use crate::episode::Episode;
use crate::error::SimError;
use crate::params::PendulumParams;
use crate::stability::{StabilityCriteria, stability_test};

/// What the loop reports while it runs ([`learn_policy_observed`]).
#[derive(Clone, Copy, Debug)]
pub enum LearnEvent<'a> {
    /// The model fit of policy iteration `iteration` (from 1) starts.
    FitStarted {
        /// The policy iteration.
        iteration: usize,
    },
    /// The model fit of policy iteration `iteration` finished a solver iteration (MSGP fits
    /// only: one-step and linear-kf fits report nothing until they end).
    Fit {
        /// The policy iteration.
        iteration: usize,
        /// The fit's own progress.
        progress: &'a FitProgress,
    },
    /// The policy search of an iteration starts (its fit has ended).
    SearchStarted {
        /// The policy iteration.
        iteration: usize,
    },
    /// A policy iteration completed.
    Iteration(&'a IterationReport),
}

/// Runs the loop; `progress` sees each iteration as it completes.
pub fn learn_policy(
    params: &PendulumParams,
    settings: &LearnSettings,
    progress: &mut dyn FnMut(&IterationReport),
) -> Result<LearnOutcome, SimError> {
    learn_policy_observed(params, settings, &mut |e| {
        if let LearnEvent::Iteration(r) = e {
            progress(r)
        }
        ControlFlow::Continue(())
    })
}

/// Runs the loop; `observe` sees its fits' and iterations' progress ([`LearnEvent`]) and can
/// stop it: after a [`ControlFlow::Break`] the loop ends there, returning [`SimError::Stopped`]
/// (an MSGP fit stops at its next solver iteration; its one-step start, and one-step and
/// linear-kf fits, which report nothing, run to their end first).
pub fn learn_policy_observed(
    params: &PendulumParams,
    settings: &LearnSettings,
    observe: &mut dyn FnMut(LearnEvent<'_>) -> ControlFlow<()>,
) -> Result<LearnOutcome, SimError> {
    params.validate()?;
    let (cost, policy_horizon) = search_objective(settings, params)?;
    let horizon = (settings.episode_seconds * params.control_rate_hz).round() as usize;
    // an episode's samples after the model's window, the steps its cost is scored on (predicted
    // and measured alike); a full episode has `horizon + 1` samples
    let window = settings.fit.ly.max(settings.fit.lu);
    let scored = (horizon + 1).saturating_sub(window);
    if horizon == 0 || scored == 0 {
        return Err(SimError::invalid(
            "episode_seconds",
            settings.episode_seconds,
            "an episode needs at least one control step after the model's window",
        ));
    }
    let mut episodes: Vec<Episode> = Vec::new();
    let mut training: Vec<TrainingEpisode> = Vec::new();
    let mut seconds = 0.0;
    if let Some(bad) = settings.gain_scale.iter().find(|g| !g.is_finite()) {
        return Err(SimError::invalid(
            "gain_scale",
            *bad,
            "typical gain magnitudes must be finite",
        ));
    }
    if settings.random_policies > settings.random_rollouts {
        return Err(SimError::invalid(
            "random_policies",
            settings.random_policies as f64,
            "at most random_rollouts of the random episodes can run a random policy",
        ));
    }
    let mut random_policies = Vec::new();
    for k in 0..settings.random_rollouts {
        let seed = settings.seed.wrapping_mul(1000).wrapping_add(k as u64);
        if k < settings.random_policies {
            let gains = random_gains(seed, &settings.gain_scale);
            let (ep, entries) = feedback_episode(params, &gains, settings, seed, &mut seconds)?;
            training.extend(entries);
            episodes.push(ep);
            let stable =
                stability_test(params, &gains, settings.seed, &StabilityCriteria::default())?
                    .passed;
            random_policies.push((gains, stable));
            continue;
        }
        let mut excitation = RandomExcitation::new(seed, &settings.excitation)?;
        let ep = interact(
            params,
            &mut excitation,
            settings.episode_seconds,
            seed,
            &mut seconds,
        )?;
        let parts = msgp_segments(episode_trajectory(&ep)?, settings.ff_segment, settings)?;
        training.extend(
            parts
                .into_iter()
                .map(|traj| TrainingEpisode { traj, policy: None }),
        );
        episodes.push(ep);
    }
    let mut gains = initial_gains(&settings.gain_scale);
    let mut reports = Vec::new();
    let mut previous_model: Option<Model> = None;
    let mut choice = match settings.prequential_choice {
        true => Some(ModelChoice::new(settings)?),
        false => None,
    };
    for it in 1..=settings.iterations {
        let step = fit_and_search(
            params,
            settings,
            &training,
            previous_model.as_ref(),
            &gains,
            it,
            choice.as_mut(),
            observe,
        )?;
        // a one-step fallback model is not continued: the next fit starts over
        if settings.warm_start.is_some() {
            previous_model = (step.model.method == settings.method()).then(|| step.model.clone());
        }
        let FitAndSearch {
            model,
            mut fit_report,
            linear,
            search_model,
            searched,
            fit_seconds,
            search_seconds,
        } = step;
        let problem = pendulum_problem(
            searched_on(&model, linear.as_ref(), search_model),
            params,
            cost.clone(),
            policy_horizon,
        );
        let mut held = false;
        let (predicted, var, search_failure) = match searched {
            Ok(result) => {
                // the running gains stay unless this iteration's model predicts the new ones
                // to pay by `hold_margin` standard deviations of their predicted cost
                // ([`LearnSettings::hold_margin`]); the first gains have not run yet
                let current = match (settings.hold_margin > 0.0, it > 1) {
                    (true, true) => problem
                        .evaluate(&modelled_policy(&gains, params)?)
                        .ok()
                        .filter(|(total, _)| total.is_finite()),
                    _ => None,
                };
                let spread = result.steps.iter().map(|(_, v)| v).sum::<f64>().sqrt();
                let steps = match current {
                    Some((total, steps))
                        if result.expected_cost > total - settings.hold_margin * spread =>
                    {
                        held = true;
                        steps
                    }
                    _ => {
                        gains = gains_from(&result.policy)?;
                        result.steps
                    }
                };
                // reported over the episode's length, comparable with the cost measured on the
                // system
                let episode_steps = &steps[..scored.min(steps.len())];
                let predicted: f64 = episode_steps.iter().map(|(m, _)| m).sum();
                let var: f64 = episode_steps.iter().map(|(_, v)| v).sum();
                (predicted, var, None)
            }
            // the model's rollouts diverge for every start: it predicts failure whatever the
            // gains (every step costs 1); the gains stay and the episode adds data
            Err(e) => (scored as f64, 0.0, Some(e.to_string())),
        };

        let seed = settings
            .seed
            .wrapping_mul(1000)
            .wrapping_add(500 + it as u64);
        let (ep, entries) = feedback_episode(params, &gains, settings, seed, &mut seconds)?;
        let actual = episode_cost(&ep, &cost, window, scored);
        // both models of this iteration predict the episode neither was trained on (a
        // one-step fallback model is not the loop's model and is not scored)
        let held_out = match (choice.as_mut(), &linear) {
            (Some(c), Some(l)) if model.method == settings.method() => {
                Some(c.score(&model, l, &entries)?)
            }
            _ => None,
        };
        training.extend(entries);
        episodes.push(ep);
        let stable =
            stability_test(params, &gains, settings.seed, &StabilityCriteria::default())?.passed;
        let expected = expected_cost(params, &gains, settings, it, &cost, (window, scored))?;
        let report = IterationReport {
            iteration: it,
            predicted_cost: predicted,
            predicted_cost_std: var.sqrt(),
            actual_cost: actual,
            expected_cost: expected,
            held,
            search_model,
            held_out,
            interaction_seconds: seconds,
            stable,
            fit_seconds,
            search_seconds,
            fit_numerical_stop: fit_report.numerical_stop.take(),
            search_failure,
            gains,
        };
        if observe(LearnEvent::Iteration(&report)).is_break() {
            return Err(SimError::Stopped { iteration: it });
        }
        reports.push(report);
    }
    Ok(LearnOutcome {
        iterations: reports,
        episodes,
        final_gains: gains,
        random_policies,
    })
}

/// What one iteration's model fit and policy search produced ([`fit_and_search`]).
#[derive(Debug)]
pub struct FitAndSearch {
    /// The fitted model (the one-step GP-NARX model when an MSGP fit failed at its start; its
    /// report says so).
    pub model: Model,
    /// The fit's report.
    pub fit_report: FitReport,
    /// Under the prequential choice, the linear competitor fitted on the same data.
    pub linear: Option<Model>,
    /// Under the prequential choice, the model the search ran on.
    pub search_model: Option<SearchModel>,
    /// The search's best gains, or why every start failed numerically (the model's rollouts
    /// diverge whatever the gains: it predicts failure).
    pub searched: Result<PolicySearchResult, msgp_core::MsgpError>,
    /// Wall seconds of the fit (both fits under the prequential choice).
    pub fit_seconds: f64,
    /// Wall seconds of the search.
    pub search_seconds: f64,
}

/// One iteration's model fit and policy search as [`learn_policy_observed`] runs them: the fit
/// of `settings` on `training` (seeded by the iteration; continuing `previous` for
/// [`LearnSettings::warm_start`] solver iterations when given and the method continues), then
/// the gains optimised on it from `gains`, within the trust region. `observe` sees
/// [`LearnEvent::FitStarted`], the fit's progress and [`LearnEvent::SearchStarted`]; a
/// [`ControlFlow::Break`] ends it with [`SimError::Stopped`]. The criterion bench of a loop
/// iteration times this function (`benches/benches/policy.rs`).
pub fn fit_and_search(
    params: &PendulumParams,
    settings: &LearnSettings,
    training: &[TrainingEpisode],
    previous: Option<&Model>,
    gains: &PidPdGains,
    iteration: usize,
    choice: Option<&mut ModelChoice>,
    observe: &mut dyn FnMut(LearnEvent<'_>) -> ControlFlow<()>,
) -> Result<FitAndSearch, SimError> {
    let it = iteration;
    let method = settings.method();
    let fit_settings = FitSettings {
        seed: settings.seed.wrapping_add(it as u64),
        ..settings.fit.clone()
    };
    let clock = std::time::Instant::now();
    let stopped = SimError::Stopped { iteration: it };
    if observe(LearnEvent::FitStarted { iteration: it }).is_break() {
        return Err(stopped);
    }
    let warm = match (previous, settings.warm_start) {
        (Some(prev), Some(n)) if matches!(method, Method::Msgp | Method::LinearKf) => {
            Some((prev, n))
        }
        _ => None,
    };
    let fitted = fit_episodes_observed(
        training,
        &match warm {
            Some((_, n)) => fit_settings.clone().with_solver_iterations(n),
            None => fit_settings.clone(),
        },
        warm.map(|(prev, _)| prev),
        &mut |p| {
            observe(LearnEvent::Fit {
                iteration: it,
                progress: p,
            })
        },
    );
    let (model, fit_report) = match fitted {
        Ok(fitted) => fitted,
        // the MSGP start (the one-step model rolled out over every episode) can already
        // fail numerically; the iteration then runs on that one-step model
        Err(
            e @ (msgp_core::MsgpError::NonFinite(_)
            | msgp_core::MsgpError::NotPositiveDefinite { .. }),
        ) if method == Method::Msgp => {
            let Some(one_step) = fit_settings.one_step_start() else {
                return Err(e.into());
            };
            let (model, mut report) = fit_episodes(training, &one_step, &mut |_| {})?;
            report.numerical_stop = Some(format!(
                "the MSGP fit failed at its start ({e}); this iteration used the one-step \
                 GP-NARX model"
            ));
            (model, report)
        }
        Err(msgp_core::MsgpError::Stopped { .. }) => return Err(stopped),
        Err(e) => return Err(e.into()),
    };
    let (linear, search_model) = match choice {
        Some(c) => (Some(c.fit(training, it)?), Some(c.search_model())),
        None => (None, None),
    };
    let fit_seconds = clock.elapsed().as_secs_f64();
    let (cost, policy_horizon) = search_objective(settings, params)?;
    let problem = pendulum_problem(
        searched_on(&model, linear.as_ref(), search_model),
        params,
        cost,
        policy_horizon,
    );
    let search = PolicySearchSettings {
        seed: settings
            .search
            .seed
            .wrapping_add(settings.seed)
            .wrapping_add(it as u64),
        ..settings.search
    };
    if observe(LearnEvent::SearchStarted { iteration: it }).is_break() {
        return Err(stopped);
    }
    let clock = std::time::Instant::now();
    let mask = gain_mask();
    let searched = optimise_pid_scaled(
        &problem,
        &modelled_policy(gains, params)?,
        &mask,
        &typical_gains(settings, params, &mask)?,
        &search,
    );
    let search_seconds = clock.elapsed().as_secs_f64();
    let searched = match searched {
        Ok(found) => Ok(found),
        Err(
            e @ (msgp_core::MsgpError::NonFinite(_)
            | msgp_core::MsgpError::NotPositiveDefinite { .. }),
        ) => Err(e),
        Err(msgp_core::MsgpError::Stopped { .. }) => return Err(stopped),
        Err(e) => return Err(e.into()),
    };
    Ok(FitAndSearch {
        model,
        fit_report,
        linear,
        search_model,
        searched,
        fit_seconds,
        search_seconds,
    })
}

/// The model a search runs on: the linear competitor when the prequential choice says so, else
/// the loop's own model.
fn searched_on<'a>(
    model: &'a Model,
    linear: Option<&'a Model>,
    choice: Option<SearchModel>,
) -> &'a Model {
    match (choice, linear) {
        (Some(SearchModel::Linear), Some(l)) => l,
        _ => model,
    }
}

/// The cost the gains are optimised and scored on, and the policy horizon in control steps
/// (at least one).
fn search_objective(
    settings: &LearnSettings,
    params: &PendulumParams,
) -> Result<(SaturatingCost, usize), SimError> {
    let cost = SaturatingCost::with_widths(DVector::from_element(2, 0.0), &settings.cost_widths)?;
    let policy_horizon =
        (settings.policy_horizon_seconds * params.control_rate_hz).round() as usize;
    if policy_horizon == 0 {
        return Err(SimError::invalid(
            "policy_horizon_seconds",
            settings.policy_horizon_seconds,
            "the policy horizon needs at least one control step",
        ));
    }
    Ok((cost, policy_horizon))
}

/// The gains the search moves: `kp` and `kd` on both outputs, `ki` on the end effector.
fn gain_mask() -> PidMask {
    PidMask {
        kp: DMatrix::from_element(1, 2, true),
        ki: DMatrix::from_row_slice(1, 2, &[false, true]),
        kd: DMatrix::from_element(1, 2, true),
    }
}

/// The optimiser's coordinate scales: a gain near zero keeps its kind's typical magnitude
/// ([`LearnSettings::gain_scale`]).
fn typical_gains(
    settings: &LearnSettings,
    params: &PendulumParams,
    mask: &PidMask,
) -> Result<Vec<f64>, SimError> {
    let s = settings.gain_scale;
    let typical = initial_gains(&s);
    Ok(mask
        .pack(&modelled_policy(&typical, params)?)
        .into_iter()
        .map(f64::abs)
        .collect())
}

/// The gains of the loop's first search: [`LearnSettings::gain_scale`] with the sine saturation.
fn initial_gains(s: &[f64; 5]) -> PidPdGains {
    PidPdGains {
        kp_x: s[0],
        ki_x: s[1],
        kd_x: s[2],
        kp_theta: s[3],
        kd_theta: s[4],
        saturation: Saturation::Sine,
    }
}

/// A random policy's gains: each drawn uniformly in `[0, 2 scale]`, sine saturation.
pub fn random_gains(seed: u64, scale: &[f64; 5]) -> PidPdGains {
    use rand::{RngExt, SeedableRng};
    let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(crate::seed::rng_for(
        seed,
        crate::seed::Stream::RandomGains,
    ));
    let mut g = [0.0; 5];
    for (gk, s) in g.iter_mut().zip(scale) {
        *gk = rng.random_range(0.0..=2.0 * s.abs());
    }
    PidPdGains {
        saturation: Saturation::Sine,
        ..PidPdGains::from_array(g)
    }
}

#[cfg(test)]
mod tests;
