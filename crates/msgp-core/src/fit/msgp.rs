//! MSGP training (paper section 3): the one-step sparse GP-NARX fit as the start, then Adam or
//! L-BFGS on the trajectory likelihood ([`crate::loss`]) with its exact adjoint gradient, early
//! stopping on a held-out tail of the training data, and an optional refit on all of it. With
//! an alternative recipe ([`MsgpSettings::alternative`]) both recipes train this way and the one
//! with the lower validation NLL is chosen; with [`MsgpSettings::full_data_iterations`] (the
//! default) the chosen recipe then trains once more from its start on all the training data,
//! for a fixed number of iterations, and that model is returned: the tail judges *which* recipe
//! well, but on short series it is a poor judge of *how long* to train (`docs/design.md`).
//! With [`MsgpSettings::calibrate`] (the default) a proxy of that final training, on the head
//! alone, then judges on the tail how much output variance the model must add
//! ([`super::calibration`]). Where the chosen zero-mean recipe's final training blows up, its
//! fallback heads ([`MsgpSettings::blow_up_fallback`]) train and the first whose final training
//! completes, in the tail's order, is returned.
//!
//! ## Guarding against noise collapse
//! The trajectory likelihood can be lowered by shrinking the noise variances while the free
//! simulation gets worse. Two guards, both documented in `docs/design.md`:
//! 1. a variance floor on `σ_x²` and `σ_y²` ([`MsgpSettings::noise_floor`], normalised units),
//!    built into the parametrisation `σ² = floor + e^θ`;
//! 2. early stopping on a held-out tail of the *training* data: the last
//!    [`MsgpSettings::validation_fraction`] of each training trajectory is kept out of training,
//!    its free-simulation NLL is computed every [`MsgpSettings::eval_every`] iterations, and the
//!    parameters with the best validation NLL are returned. The test data are never seen.

use std::ops::ControlFlow;
use std::sync::Mutex;
use std::sync::atomic::{AtomicBool, Ordering};
use std::time::Instant;

use super::blow_up::BlowUp;
use super::calibration::{CalibrationReport, Judge, tail_calibration};
use super::continuation;
use super::divergence::check_divergence;
use super::linear_kf::{KF_NOISE_FLOOR, fit_linear_kf};
use super::one_step::{OneStepSettings, column_std, fit_one_step, one_step_pairs};
use super::proxy_watch::{ProxyOutcome, ProxyWatch};
use super::segments::Batches;
use super::{
    CLEARLY_BETTER, FIT_LBFGS, FitOptimizer, FitProgress, FitReport, FitSettings, MsgpSettings,
    MsgpStart, NoiseStart, RecipeOutcome, TrainingEpisode, final_budgets,
};
use crate::data::{Normalizer, Trajectory};
use crate::error::{MsgpError, Result};
use crate::gp::integrator::Structure;
use crate::gp::integrator::{IGNORED_LENGTHSCALE, NO_GP_SIGNAL_VAR};
use crate::gp::kmeans::{gp_inputs, place_pseudo_inputs};
use crate::gp::{GpConfig, GpParams, GpShape, MeanFunction, ParamGroup, PreparedGp};
use crate::loss::{
    Complexity, Likelihood, LossValue, filter_loss, msgp_loss, weighted_filter_loss_and_gradient,
    weighted_loss_and_gradient,
};
use crate::model::{Method, Model};
use crate::narx::NarxSpec;
use crate::numeric::linalg::JitterLog;
use crate::numeric::parallel::Threads;
use crate::optim::{Adam, Flow, Objective, Solver, minimize};
use crate::rollout::{Control, Episode, Excitation, simulate};
use nalgebra::{DMatrix, DVector};

/// The MSGP fit of normalised trajectories `norm` (the `episodes`' own, in order), from the
/// one-step start or from `previous`'s parameters.
#[allow(clippy::too_many_arguments)]
pub(super) fn fit_msgp(
    episodes: &[TrainingEpisode],
    norm: &[Trajectory],
    normalizer: Normalizer,
    spec: NarxSpec,
    settings: &FitSettings,
    msgp: &MsgpSettings,
    previous: Option<&Model>,
    one_step: &OneStepSettings,
    start: Instant,
    progress: &mut dyn FnMut(&FitProgress) -> ControlFlow<()>,
    mut report: FitReport,
) -> Result<(Model, FitReport)> {
    // split each trajectory into a training head and a validation tail.
    // Feedback episodes train in closed loop under their (normalised) policy and are not split.
    let w = spec.warmup();
    let mut all_eps = Vec::new();
    for (t, ep) in norm.iter().zip(episodes) {
        all_eps.push(match &ep.policy {
            Some(p) => Episode {
                traj: t.clone(),
                excitation: Excitation::Feedback(Box::new(p.normalized(&normalizer)?)),
            },
            None => Episode::feed_forward(t.clone()),
        });
    }
    let (head_eps, tails) = split_tails(&all_eps, msgp.validation_fraction, w);
    // a long log trains by segments; its validation tails stay whole
    let (head_eps, all_eps) = match &msgp.segments {
        Some(s) => {
            let all = s.split(&all_eps, w)?;
            report.segments = Some((*s, all.len()));
            (s.split(&head_eps, w)?, all)
        }
        None => (head_eps, all_eps),
    };
    // a continuation on data that have outgrown the previous model's pseudo-inputs adds some
    let grown = match previous {
        Some(p) => {
            let structure = Structure::new(&settings.integrators, &spec);
            continuation::grown_pseudo_inputs(
                p,
                norm,
                spec,
                &structure,
                msgp.inducing,
                settings.seed,
            )?
            .map(|params| Model {
                params,
                ..p.clone()
            })
        }
        None => None,
    };
    let previous = grown.as_ref().or(previous);
    // the settings' own recipe, then the alternative (only where a validation tail can judge)
    let mut recipes = vec![msgp.clone()];
    if let (Some(r), false, None) = (msgp.alternative, tails.is_empty(), previous) {
        recipes.push(msgp.with_recipe(r));
    }
    // the final training on all the training data applies to Adam fits with a tail and no
    // previous model (L-BFGS would run to the training optimum, which early stopping avoids)
    let final_iterations = match (
        msgp.full_data_iterations,
        tails.is_empty(),
        previous,
        msgp.optimizer,
    ) {
        (Some(n), false, None, FitOptimizer::Adam) => Some(n),
        _ => None,
    };
    // the heads that train first (side by side on two threads)
    let racing = recipes.len();
    // the fallback heads of the settings' own zero-mean recipe: from the spread start, and with
    // a linear mean (its step and complexity otherwise); they train only if that recipe wins the
    // choice and its final training blows up (`MsgpSettings::blow_up_fallback`)
    let fallbacks: Vec<usize> = if msgp.blow_up_fallback
        && msgp.mean == MeanFunction::Zero
        && msgp.start == MsgpStart::OneStep
        && final_iterations.is_some()
    {
        let first = recipes.len();
        recipes.push(MsgpSettings {
            start: MsgpStart::Spread,
            alternative: None,
            ..msgp.clone()
        });
        recipes.push(MsgpSettings {
            mean: MeanFunction::Linear,
            alternative: None,
            ..msgp.clone()
        });
        (first..recipes.len()).collect()
    } else {
        Vec::new()
    };
    // the proxy of the final training, for the calibration and the choice of the final
    // training's length (only with the final training)
    let proxy_iterations = final_iterations.filter(|_| msgp.calibrate || msgp.choose_final_budget);
    // each recipe's start on the head (the proxy starts from it)
    let starts: Mutex<Vec<Option<GpParams<f64>>>> = Mutex::new(vec![None; recipes.len()]);
    // each recipe's proxy, read off its training on the head (`super::proxy_watch`)
    let proxies: Mutex<Vec<Option<FinalTraining>>> =
        Mutex::new((0..recipes.len()).map(|_| None).collect());
    // set when the user stops the fit: stops whatever trains on another thread
    let stop = AtomicBool::new(false);
    let config_of = |recipe: &MsgpSettings| GpConfig {
        noise_floor: recipe.noise_floor,
        mean: recipe.mean,
        start: recipe.start_window,
        ..GpConfig::default()
    };
    // what each racing head knows of the other (`Race`; untouched when the heads run in turn)
    let race = Mutex::new(Race::default());
    // one recipe's training under its own report and observer
    let run = |k: usize,
               recipe: &MsgpSettings,
               settings: &FitSettings,
               progress: &mut dyn FnMut(&FitProgress) -> ControlFlow<()>,
               report: &mut FitReport|
     -> Result<Trained> {
        // whether this head, at its early stop with validation NLL `best`, can still be chosen
        // (a racing head already behind the other's running best never is: its proxy would
        // be trained for nothing)
        let ahead = |best: f64| {
            let race = race.lock().unwrap_or_else(|e| e.into_inner());
            match k {
                0 => race.running.is_none_or(|b| b >= best),
                1 => race.running_first.is_none_or(|a| best < a),
                _ => true,
            }
        };
        let mut stage = Stage {
            spec,
            config: config_of(recipe),
            settings,
            msgp: recipe,
            start,
            progress,
            report,
            checkpoints: Vec::new(),
            snapshots: Vec::new(),
            proxy_watch: proxy_iterations.map(|n| proxy_watch(recipe, n)),
            proxy_ahead: Some(&ahead),
        };
        let stage_number = if k == 0 { 1 } else { 3 };
        let mut head_start = None;
        let trained = train_recipe(
            &mut stage,
            previous,
            one_step,
            &head_eps,
            &all_eps,
            &tails,
            stage_number,
            &mut head_start,
        );
        let watched = stage.proxy_watch.take().filter(|w| w.done());
        if let (Some(start), Some(watch)) = (&head_start, watched) {
            let proxy = read_proxy(k, watch.finish(), start);
            proxies.lock().unwrap_or_else(|e| e.into_inner())[k] = Some(proxy);
        }
        if head_start.is_some() {
            starts.lock().unwrap_or_else(|e| e.into_inner())[k] = head_start;
        }
        trained
    };
    // recipe `k` for a fixed number of iterations on `episodes` without a tail, from `init` or
    // (`None`) its own start on them, under its own report: the final training, or its proxy
    let fixed_training = |k: usize,
                          episodes: &[Episode],
                          init: Option<GpParams<f64>>,
                          stage_number: u8,
                          iterations: usize,
                          settings: &FitSettings,
                          progress: &mut dyn FnMut(&FitProgress) -> ControlFlow<()>|
     -> FinalTraining {
        let recipe = &recipes[k];
        let n = iterations.min(recipe.iterations);
        let checkpoints = if recipe.choose_final_budget {
            final_budgets(n)
        } else {
            Vec::new()
        };
        let mut own = FitReport::default();
        let mut stage = Stage {
            spec,
            config: config_of(recipe),
            settings,
            msgp: recipe,
            start,
            progress,
            report: &mut own,
            checkpoints,
            snapshots: Vec::new(),
            proxy_watch: None,
            proxy_ahead: None,
        };
        let init = match init {
            Some(init) => Ok(init),
            None => stage.start_params(episodes, one_step),
        };
        let trained = init.and_then(|init| {
            stage.train(
                init,
                episodes,
                &[],
                n,
                stage_number,
                Some(recipe.full_data_blow_up),
            )
        });
        let raw = std::mem::take(&mut stage.snapshots);
        let outcome = match trained {
            // a blow-up: the head's model stands (`train` wrote why into the report)
            Ok(_) if own.full_data_failed.is_some() => Ok(None),
            Ok((params, iteration, _)) => Ok(Some((params, iteration))),
            Err(e @ MsgpError::Stopped { .. }) => Err(e),
            // a numerical failure at the start: the head's model stands, and the report says so
            Err(e) => {
                own.full_data_failed = Some(e.to_string());
                Ok(None)
            }
        };
        // (the snapshots of a training that completed)
        let shape = match &outcome {
            Ok(Some((params, _))) => params.shape().ok(),
            _ => None,
        };
        let snapshots = shape.map_or_else(Vec::new, |shape| {
            raw.iter()
                .filter_map(|(b, x, it)| Some((*b, GpParams::from_flat(shape, x).ok()?, *it)))
                .collect()
        });
        FinalTraining {
            recipe: k,
            outcome,
            report: own,
            snapshots,
        }
    };
    // recipe `k` once more, from its start on all the training data
    let final_stage =
        |k: usize,
         iterations: usize,
         settings: &FitSettings,
         progress: &mut dyn FnMut(&FitProgress) -> ControlFlow<()>| {
            fixed_training(k, &all_eps, None, 2, iterations, settings, progress)
        };
    // the proxy of recipe `k`'s final training ([`calibration`]): the same training from the
    // recipe's start on the head, on the head alone (nothing without that start)
    let proxy_stage =
        |k: usize,
         iterations: usize,
         settings: &FitSettings,
         progress: &mut dyn FnMut(&FitProgress) -> ControlFlow<()>| {
            if let Some(read) = proxies.lock().unwrap_or_else(|e| e.into_inner())[k].take() {
                return read;
            }
            // (the lock is released before the training)
            let init = starts.lock().unwrap_or_else(|e| e.into_inner())[k].clone();
            match init {
                Some(init) => {
                    fixed_training(k, &head_eps, Some(init), 4, iterations, settings, progress)
                }
                None => FinalTraining {
                    recipe: k,
                    outcome: Ok(None),
                    report: FitReport::default(),
                    snapshots: Vec::new(),
                },
            }
        };
    // a quiet observer for work beside the observed one: it stops when the user stopped
    let quiet_stop = |_: &FitProgress| {
        if stop.load(Ordering::Relaxed) {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    };
    // the final training if it ran while the second recipe's head was still training
    let mut early_final: Option<FinalTraining> = None;
    // the proxy if the second recipe's thread trained it once both heads had ended
    let mut early_proxy: Option<FinalTraining> = None;
    let results: Vec<Result<Trained>> = if racing == 2 && settings.threads.get() >= 2 {
        // the two recipes side by side, each on half the threads; the observer sees the
        // first, and stopping it stops both. Once the first head is done, its thread trains
        // the recipe that leads on all the data while the second head goes on (`Race`)
        let half = FitSettings {
            threads: Threads::new((settings.threads.get() / 2).max(1))?,
            ..settings.clone()
        };
        let mut side = FitReport::default();
        // the progress of a final training on the second thread, for the observer on this one
        let (relay, relayed) = std::sync::mpsc::channel::<FitProgress>();
        let (first, second, proxy) = std::thread::scope(|scope| {
            let handle = scope.spawn(|| {
                // (moved here: the channel closes when this thread ends)
                let relay = relay;
                let mut quiet = |p: &FitProgress| {
                    if let Some(v) = p.validation {
                        race.lock().unwrap_or_else(|e| e.into_inner()).saw(v);
                    }
                    quiet_stop(p)
                };
                let second = run(1, &recipes[1], &half, &mut quiet, &mut side);
                race.lock()
                    .unwrap_or_else(|e| e.into_inner())
                    .finished(&second);
                // the second head ended first: this thread trains the recipe that leads on all
                // the data while the first head goes on (the mirror of the first thread's)
                let state = || race.lock().unwrap_or_else(|e| e.into_inner());
                let mut final_second = None;
                loop {
                    // (the guard is dropped at the end of this statement, not held in training)
                    let leader = state().second_leader();
                    let (Some(iterations), Some(k)) = (final_iterations, leader) else {
                        break;
                    };
                    let mut aborted = false;
                    let mut watched = |p: &FitProgress| {
                        if !state().second_keeps(k) {
                            aborted = true;
                            return ControlFlow::Break(());
                        }
                        // (a closed channel: the observer has gone, the stop flag says why)
                        let _ = relay.send(*p);
                        quiet_stop(p)
                    };
                    let trained = final_stage(k, iterations, &half, &mut watched);
                    if !(aborted && matches!(trained.outcome, Err(MsgpError::Stopped { .. }))) {
                        final_second = Some(trained);
                        break;
                    }
                }
                let chosen = state().chosen();
                // both heads have ended: this thread trains the chosen recipe's proxy while
                // the other finishes its final training
                let proxy = match (proxy_iterations, chosen) {
                    (Some(n), Some(k)) => Some(proxy_stage(k, n, &half, &mut quiet_stop.clone())),
                    _ => None,
                };
                (second, proxy, final_second)
            });
            // the observer sees this thread's events and those relayed from the other
            let mut show = |p: &FitProgress| {
                let flow = progress(p);
                if flow.is_break() {
                    stop.store(true, Ordering::Relaxed);
                }
                flow
            };
            let mut observed = |p: &FitProgress| {
                if let Some(v) = p.validation {
                    race.lock().unwrap_or_else(|e| e.into_inner()).saw_first(v);
                }
                for q in relayed.try_iter() {
                    let _ = show(&q);
                }
                show(p)
            };
            let first = run(0, &recipes[0], &half, &mut observed, &mut report);
            // the first head's outcome as the choice sees it: its validation NLL, or `None`
            // when it failed numerically (another failure decides nothing: it is returned)
            let first_outcome = match &first {
                Ok(t) => Some(Some(t.2)),
                Err(MsgpError::NotPositiveDefinite { .. } | MsgpError::NonFinite(_)) => Some(None),
                Err(_) => None,
            };
            if let Some(outcome) = first_outcome {
                race.lock().unwrap_or_else(|e| e.into_inner()).first = Some(outcome);
            }
            if let (Some(iterations), Some(first_outcome)) = (final_iterations, first_outcome) {
                let state = || race.lock().unwrap_or_else(|e| e.into_inner());
                loop {
                    // (the guard is dropped at the end of this statement, not held in training)
                    let leader = state().leader(first_outcome);
                    let Some(k) = leader else { break };
                    let mut aborted = false;
                    let mut watched = |p: &FitProgress| {
                        if !state().keeps(k, first_outcome) {
                            aborted = true;
                            return ControlFlow::Break(());
                        }
                        show(p)
                    };
                    let trained = final_stage(k, iterations, &half, &mut watched);
                    match (&trained.outcome, aborted) {
                        // the leader changed: the other recipe's final training
                        (Err(MsgpError::Stopped { .. }), true) => continue,
                        _ => {
                            early_final = Some(trained);
                            break;
                        }
                    }
                }
            }
            if matches!(first, Err(MsgpError::Stopped { .. }))
                || matches!(
                    early_final,
                    Some(FinalTraining {
                        outcome: Err(MsgpError::Stopped { .. }),
                        ..
                    })
                )
            {
                stop.store(true, Ordering::Relaxed);
            }
            // the other thread's final training, shown as it goes
            for q in relayed.iter() {
                let _ = show(&q);
            }
            let joined = handle.join().map_err(|_| {
                MsgpError::NonFinite("the alternative recipe's training panicked".into())
            });
            match joined {
                Ok((second, proxy, final_second)) => {
                    early_final = early_final.take().or(final_second);
                    (first, Ok(second), proxy)
                }
                Err(e) => (first, Err(e), None),
            }
        });
        let second = second?;
        early_proxy = proxy;
        report.iterations_run += side.iterations_run;
        report.jitter.merge(&side.jitter);
        report.history.extend(side.history);
        if report.numerical_stop.is_none() {
            report.numerical_stop = side.numerical_stop;
        }
        vec![first, second]
    } else {
        recipes
            .iter()
            .take(racing)
            .enumerate()
            .map(|(k, r)| run(k, r, settings, &mut *progress, &mut report))
            .collect()
    };
    if let Some(FinalTraining {
        outcome: Err(e @ MsgpError::Stopped { .. }),
        ..
    }) = early_final
    {
        return Err(e);
    }
    // every racing head that trained, with its validation NLL and kept iteration, in the tail's
    // order: the first is chosen, and where its model diverges, the others are tried in turn
    let mut raced: Vec<(f64, usize, GpParams<f64>, usize)> = Vec::new();
    let mut first_error = None;
    for (k, (trained, recipe)) in results.into_iter().zip(&recipes).enumerate() {
        let (params, best_iteration, validation) = match trained {
            Ok(t) => t,
            // a recipe whose start already fails numerically (e.g. an unstable linear map)
            // leaves the choice to the other
            Err(e @ (MsgpError::NotPositiveDefinite { .. } | MsgpError::NonFinite(_)))
                if recipes.len() > 1 =>
            {
                report.recipes.push(RecipeOutcome {
                    recipe: recipe.recipe(),
                    start: recipe.start,
                    validation: None,
                    failed: Some(e.to_string()),
                    final_failed: None,
                    diverged: None,
                    fallback_head: false,
                });
                first_error.get_or_insert(e);
                continue;
            }
            Err(e) => return Err(e),
        };
        report.recipes.push(RecipeOutcome {
            recipe: recipe.recipe(),
            start: recipe.start,
            validation: validation.is_finite().then_some(validation),
            failed: None,
            final_failed: None,
            diverged: None,
            fallback_head: false,
        });
        raced.push((validation, k, params, best_iteration));
    }
    // (a stable sort: on a tie, the training order)
    raced.sort_by(|a, b| a.0.total_cmp(&b.0));
    // why recipe `k`'s model with `params` diverges over the feed-forward training trajectories
    // (`check_divergence`, before any calibration), or `None`
    let open_loop: Vec<&Trajectory> = episodes
        .iter()
        .filter(|e| e.policy.is_none())
        .map(|e| &e.traj)
        .collect();
    let diverges = |k: usize, params: &GpParams<f64>| {
        let model = Model {
            method: Method::Msgp,
            spec,
            params: params.clone(),
            config: config_of(&recipes[k]),
            normalizer: normalizer.clone(),
            calibration: Vec::new(),
        };
        #[cfg(test)]
        if let Some(why) = DIVERGENCE_JUDGE.with_borrow_mut(|j| j.as_mut().map(|j| j(&model))) {
            return why;
        }
        check_divergence(&model, &open_loop)
    };
    let Some((_, first, chosen, best_iteration)) = raced.first().cloned() else {
        return Err(first_error.unwrap_or_else(|| MsgpError::NonFinite("no recipe trained".into())));
    };
    report.chosen_recipe = first;
    report.best_iteration = best_iteration;
    // the heads whose final training is tried, in turn: the chosen one, and where that is the
    // settings' own zero-mean recipe and its final training blows up, its fallback heads in the
    // order of their validation NLL (`MsgpSettings::blow_up_fallback`)
    let mut candidates: Vec<(usize, GpParams<f64>, usize)> =
        vec![(report.chosen_recipe, chosen, report.best_iteration)];
    let (mut k, mut chosen, _) = candidates[0].clone();
    let mut head_model = chosen.clone();
    let mut proxy = None;
    // the final model kept, with its head, kept iterations and calibration proxy; and the
    // first that diverged and was set aside for the next candidate's
    let mut accepted = None;
    let mut set_aside = None;
    if let Some(iterations) = final_iterations {
        let mut early_final = early_final;
        let mut early_proxy = early_proxy;
        let mut i = 0;
        while i < candidates.len() {
            let (c, head, best_iteration) = candidates[i].clone();
            let early = early_final.take_if(|t| t.recipe == c);
            proxy = early_proxy.take_if(|p| p.recipe == c);
            if proxy.is_none() {
                proxy = proxies.lock().unwrap_or_else(|e| e.into_inner())[c].take();
            }
            let proxy_needed = proxy_iterations.is_some() && proxy.is_none();
            let trained = match early {
                Some(t) => {
                    if proxy_needed {
                        proxy = Some(proxy_stage(c, iterations, settings, &mut *progress));
                    }
                    t
                }
                None if proxy_needed && settings.threads.get() >= 2 => {
                    // the final training and its proxy side by side, each on half the threads
                    let half = FitSettings {
                        threads: Threads::new((settings.threads.get() / 2).max(1))?,
                        ..settings.clone()
                    };
                    let (trained, side) = std::thread::scope(|scope| {
                        let handle = scope
                            .spawn(|| proxy_stage(c, iterations, &half, &mut quiet_stop.clone()));
                        let mut observed = |p: &FitProgress| {
                            let flow = progress(p);
                            if flow.is_break() {
                                stop.store(true, Ordering::Relaxed);
                            }
                            flow
                        };
                        let trained = final_stage(c, iterations, &half, &mut observed);
                        (trained, handle.join())
                    });
                    proxy = Some(side.map_err(|_| {
                        MsgpError::NonFinite("the calibration's proxy training panicked".into())
                    })?);
                    trained
                }
                None => {
                    let trained = final_stage(c, iterations, settings, &mut *progress);
                    // (where the head's model stands, it is its own judge: no proxy)
                    if proxy_needed && matches!(trained.outcome, Ok(Some(_))) {
                        proxy = Some(proxy_stage(c, iterations, settings, &mut *progress));
                    }
                    trained
                }
            };
            report.iterations_run += trained.report.iterations_run;
            report.jitter.merge(&trained.report.jitter);
            if trained.report.numerical_stop.is_some() {
                report.numerical_stop = trained.report.numerical_stop;
            }
            if let Some((params, iteration)) = trained.outcome? {
                // how long the final training is, where its proxy says so: the whole length
                // unless a shorter one's proxy simulates the tail clearly better
                // (`MsgpSettings::choose_final_budget`)
                let choice = match proxy.as_mut() {
                    Some(p) if !trained.snapshots.is_empty() => {
                        let config = config_of(&recipes[c]);
                        choose_budget(&trained.snapshots, p, &config, &spec, &tails)?
                    }
                    _ => None,
                };
                let kept = choice.and_then(|(length, budgets)| {
                    let (_, params, iteration) =
                        trained.snapshots.iter().find(|s| s.0 == length)?;
                    Some((params.clone(), *iteration, (Some(length), budgets)))
                });
                let (params, iteration, budgets) =
                    kept.unwrap_or((params, iteration, (None, Vec::new())));
                // a final model that diverges over the training inputs gives way to the racing
                // heads not yet tried, in the tail's order; where each of them diverges too,
                // the first diverging model stands
                let why = diverges(c, &params);
                let untried = || -> Vec<(usize, GpParams<f64>, usize)> {
                    raced
                        .iter()
                        .filter(|h| !candidates.iter().any(|t| t.0 == h.1))
                        .map(|h| (h.1, h.2.clone(), h.3))
                        .collect()
                };
                let untried = if why.is_some() { untried() } else { Vec::new() };
                match why {
                    Some(why) if !untried.is_empty() => {
                        if let Some(outcome) = report.recipes.get_mut(c) {
                            outcome.diverged = Some(why);
                        }
                        set_aside.get_or_insert((
                            c,
                            params,
                            head,
                            best_iteration,
                            iteration,
                            proxy,
                            budgets,
                        ));
                        proxy = None;
                        candidates.extend(untried);
                        i += 1;
                        continue;
                    }
                    // (the first set aside stands, below)
                    Some(_) if set_aside.is_some() => {}
                    _ => {
                        accepted = Some((
                            c,
                            params,
                            head,
                            best_iteration,
                            iteration,
                            proxy.take(),
                            budgets,
                        ))
                    }
                }
                break;
            }
            // this head's final training blew up (or failed numerically): the fallback heads
            // train, and their final trainings are tried in the order of their validation NLL;
            // the first head's model stands if none completes
            if let Some(outcome) = report.recipes.get_mut(c) {
                outcome.final_failed = trained.report.full_data_failed.clone();
            }
            if i == 0 {
                report.full_data_failed = trained.report.full_data_failed;
                // (only the settings' own recipe, the first, has fallback heads)
                let mut heads = Vec::new();
                for &s in fallbacks.iter().filter(|_| c == 0) {
                    let outcome = run(s, &recipes[s], settings, &mut *progress, &mut report);
                    let (validation, failed) = match outcome {
                        Ok((params, iteration, validation)) => {
                            heads.push((validation, s, params, iteration));
                            (validation.is_finite().then_some(validation), None)
                        }
                        Err(
                            e @ (MsgpError::NotPositiveDefinite { .. } | MsgpError::NonFinite(_)),
                        ) => (None, Some(e.to_string())),
                        Err(e) => return Err(e),
                    };
                    report.recipes.push(RecipeOutcome {
                        recipe: recipes[s].recipe(),
                        start: recipes[s].start,
                        validation,
                        failed,
                        final_failed: None,
                        diverged: None,
                        fallback_head: true,
                    });
                }
                // (a stable sort: on a tie, the training order)
                heads.sort_by(|a, b| a.0.total_cmp(&b.0));
                candidates.extend(heads.into_iter().map(|(_, s, p, it)| (s, p, it)));
            }
            // (a proxy of a final training that is not kept judges nothing, and whether it ran
            // depends on the schedule: it is not counted)
            proxy = None;
            i += 1;
        }
        // where no final model was kept, the first one set aside for diverging stands: it
        // was set aside for nothing
        if accepted.is_none() && set_aside.is_some() {
            report.recipes.iter_mut().for_each(|r| r.diverged = None);
            accepted = set_aside;
        }
        if let Some((c, params, head, best_iteration, iteration, kept_proxy, budgets)) = accepted {
            proxy = kept_proxy;
            (report.final_budget, report.final_budgets) = budgets;
            k = c;
            chosen = params;
            head_model = head;
            report.chosen_recipe = c;
            report.best_iteration = best_iteration;
            report.full_data_iteration = Some(iteration);
            report.full_data_failed = None;
        }
    } else if raced.len() > 1 {
        // no final training: a head whose model diverges over the training inputs gives way
        // to the next in the tail's order that does not
        if let Some(why) = diverges(k, &chosen) {
            let stable = raced
                .iter()
                .filter(|h| h.1 != k)
                .find(|h| diverges(h.1, &h.2).is_none());
            if let Some((_, c, params, best_iteration)) = stable {
                if let Some(outcome) = report.recipes.get_mut(k) {
                    outcome.diverged = Some(why);
                }
                k = *c;
                chosen = params.clone();
                head_model = chosen.clone();
                report.chosen_recipe = k;
                report.best_iteration = *best_iteration;
            }
        }
    }
    let config = config_of(&recipes[k]);
    // the calibration: the proxy judges the final training's model, the head's model itself
    let mut calibration = Vec::new();
    // (a proxy counts where the final training it stands for is the model)
    let proxy_outcome = match proxy {
        Some(p) if report.full_data_iteration.is_some() => {
            report.iterations_run += p.report.iterations_run;
            report.jitter.merge(&p.report.jitter);
            p.outcome?
        }
        _ => None,
    };
    if proxy_iterations.is_some() && msgp.calibrate {
        let (params, judge) = match (report.full_data_iteration, proxy_outcome) {
            (Some(_), Some((params, iteration))) => (params, Judge::Proxy { iteration }),
            // the head's model stands: its own training, cross-validated, judges it
            (None, _) => {
                let (inner_heads, inner_tails) =
                    split_tails(&head_eps, msgp.validation_fraction, w);
                let mut own = FitReport::default();
                let mut stage = Stage {
                    spec,
                    config,
                    settings,
                    msgp: &recipes[k],
                    start,
                    progress: &mut *progress,
                    report: &mut own,
                    checkpoints: Vec::new(),
                    snapshots: Vec::new(),
                    proxy_watch: None,
                    proxy_ahead: None,
                };
                let trained = if inner_tails.is_empty() {
                    None
                } else {
                    let mut inner_start = None;
                    match train_recipe(
                        &mut stage,
                        None,
                        one_step,
                        &inner_heads,
                        &inner_heads,
                        &inner_tails,
                        4,
                        &mut inner_start,
                    ) {
                        Ok(t) => Some(t),
                        Err(e @ MsgpError::Stopped { .. }) => return Err(e),
                        Err(_) => None,
                    }
                };
                report.iterations_run += own.iterations_run;
                report.jitter.merge(&own.jitter);
                match trained {
                    Some((params, iteration, _)) => (params, Judge::HeadProxy { iteration }),
                    None => (head_model, Judge::Head),
                }
            }
            (Some(_), None) => (head_model, Judge::Head),
        };
        let judged = PreparedGp::new(&params, &config, &mut report.jitter)
            .and_then(|gp| tail_calibration(&gp, &spec, &tails));
        match judged {
            Ok(delta) => {
                report.calibration = Some(CalibrationReport {
                    added_std: delta
                        .iter()
                        .enumerate()
                        .map(|(j, d)| normalizer.y_var_to_original(j, *d).sqrt())
                        .collect(),
                    judge,
                });
                calibration = delta;
            }
            // a judge whose simulation fails numerically decides nothing
            Err(MsgpError::NotPositiveDefinite { .. } | MsgpError::NonFinite(_)) => {}
            Err(e) => return Err(e),
        }
    }
    report.train_seconds = start.elapsed().as_secs_f64();
    let model = Model {
        method: Method::Msgp,
        spec,
        params: chosen,
        config,
        normalizer,
        calibration,
    };
    Ok((model, report))
}

#[cfg(test)]
thread_local! {
    /// A test's judge of which models diverge, in place of [`check_divergence`] where the
    /// protocol chooses among its recipes' models (on the test's own thread).
    pub(super) static DIVERGENCE_JUDGE: std::cell::RefCell<Option<DivergenceJudge>> =
        const { std::cell::RefCell::new(None) };
}

/// See [`DIVERGENCE_JUDGE`].
#[cfg(test)]
pub(super) type DivergenceJudge = Box<dyn FnMut(&Model) -> Option<String>>;

/// `episodes` split as the fit splits its training data: each feed-forward episode long enough
/// into a head and its last `fraction` as a tail (with the `warmup` samples before it);
/// feedback episodes and short ones stay whole in the heads.
fn split_tails(episodes: &[Episode], fraction: f64, warmup: usize) -> (Vec<Episode>, Vec<Episode>) {
    let mut heads = Vec::new();
    let mut tails = Vec::new();
    for ep in episodes {
        let t = &ep.traj;
        let n_val = (t.len() as f64 * fraction).round() as usize;
        let feed_forward = matches!(ep.excitation, Excitation::FeedForward);
        if feed_forward && fraction > 0.0 && n_val >= 10 && t.len() - n_val > warmup + 10 {
            heads.push(Episode::feed_forward(t.slice(0, t.len() - n_val)));
            tails.push(Episode::feed_forward(
                t.slice(t.len() - n_val - warmup, t.len()),
            ));
        } else {
            heads.push(ep.clone());
        }
    }
    (heads, tails)
}

/// A length of the final training and its proxy's RMSE on the validation tail (`None` where
/// its simulation failed): [`FitReport::final_budgets`].
type LengthScore = (usize, Option<f64>);

/// The length of the final training ([`MsgpSettings::choose_final_budget`]) among those both
/// it and its `proxy` reached, by [`shorter_if_clearly_better`] on the free simulations of the
/// validation `tails` (normalised) by the proxy's iterates; the proxy's outcome becomes the
/// chosen length's iterate. Returns that length with every length's tail RMSE (longest first;
/// `None` where the simulation failed), or `None` where the longest length's failed.
fn choose_budget(
    snapshots: &[(usize, GpParams<f64>, usize)],
    proxy: &mut FinalTraining,
    config: &GpConfig,
    spec: &NarxSpec,
    tails: &[Episode],
) -> Result<Option<(usize, Vec<LengthScore>)>> {
    let mut scored = Vec::new();
    for (budget, params, iteration) in proxy.snapshots.iter().rev() {
        if !snapshots.iter().any(|s| s.0 == *budget) {
            continue;
        }
        let rmse = match tail_rmse(params, config, spec, tails) {
            Ok(r) => Some(r),
            Err(MsgpError::NotPositiveDefinite { .. } | MsgpError::NonFinite(_)) => None,
            Err(e) => return Err(e),
        };
        scored.push((*budget, rmse, params, *iteration));
    }
    let rmses: Vec<Option<f64>> = scored.iter().map(|s| s.1).collect();
    let Some(k) = shorter_if_clearly_better(&rmses) else {
        return Ok(None);
    };
    let (budget, _, params, iteration) = &scored[k];
    proxy.outcome = Ok(Some(((*params).clone(), *iteration)));
    let budgets = scored.iter().map(|s| (s.0, s.1)).collect();
    Ok(Some((*budget, budgets)))
}

/// Which of the candidates' tail RMSEs — the longest training first, `None` where its
/// simulation failed — is chosen: the lowest among the first and those at least
/// [`CLEARLY_BETTER`] below the first; the first where none is. The longest training is the
/// protocol's default, chosen on the training data of every row; a short tail that chooses
/// among several close candidates chooses its own noise, so a shorter one replaces it only by a
/// clear margin (`docs/experiments/2026-12-05-how-long-the-final-training-is.md`, "How long the final training is"). `None` where the first
/// failed.
fn shorter_if_clearly_better(rmses: &[Option<f64>]) -> Option<usize> {
    let first = (*rmses.first()?)?;
    let bar = (1.0 - CLEARLY_BETTER) * first;
    let mut chosen = (0, first);
    for (k, r) in rmses.iter().enumerate().skip(1) {
        if let Some(r) = *r
            && r <= bar
            && r < chosen.1
        {
            chosen = (k, r);
        }
    }
    Some(chosen.0)
}

/// The RMSE of the moment-matching free simulation of the feed-forward `tails` (normalised
/// units, pooled over their steps and outputs) under the model of `params`: its means only,
/// which the correlated variances of a reported simulation do not move.
fn tail_rmse(
    params: &GpParams<f64>,
    config: &GpConfig,
    spec: &NarxSpec,
    tails: &[Episode],
) -> Result<f64> {
    let mut log = JitterLog::default();
    let gp = PreparedGp::new(params, config, &mut log)?;
    let (mut sum, mut count) = (0.0, 0usize);
    for tail in tails {
        let traj = &tail.traj;
        let steps = simulate(&gp, spec, traj, &Control::FeedForward, traj.len(), &mut log)?;
        for (i, s) in steps.iter().enumerate() {
            for j in 0..spec.dy {
                let r = traj.y[(spec.warmup() + i, j)] - s.mean[j];
                sum += r * r;
                count += 1;
            }
        }
    }
    if count == 0 || !sum.is_finite() {
        return Err(MsgpError::NonFinite(
            "the validation tail's simulation".into(),
        ));
    }
    Ok((sum / count as f64).sqrt())
}

/// The final training on all the data of one recipe, or its proxy on the head
/// ([`calibration`]): its outcome (the parameters and iteration kept; `None` where it blew up
/// or failed numerically — the head's model standing — or the proxy had no start) and the
/// report of that training alone.
struct FinalTraining {
    recipe: usize,
    outcome: Result<Option<(GpParams<f64>, usize)>>,
    report: FitReport,
    /// With [`MsgpSettings::choose_final_budget`], where it completed: at each length of
    /// [`final_budgets`] reached, `(length, its iterate of lowest loss so far, that iterate)`.
    snapshots: Vec<(usize, GpParams<f64>, usize)>,
}

/// What the first recipe's thread knows of the second recipe's head while both train side by
/// side. The choice between the recipes ([`fit_msgp`]) takes the second only if its best
/// validation NLL is strictly below the first's (or the first failed), and a running best only
/// falls, so once it is below the first's final value the second has won unless its head still
/// fails: the first thread can start the winner's final training before the second head ends,
/// and abandons it if that changes. The returned model is the same, bit for bit, as when
/// everything runs in turn.
#[derive(Default)]
struct Race {
    /// The second head's lowest validation NLL so far.
    running: Option<f64>,
    /// The first head's lowest validation NLL so far.
    running_first: Option<f64>,
    /// The second head's outcome once it ended: its validation NLL, or `None` if it failed.
    ended: Option<Option<f64>>,
    /// The first head's outcome once it ended (as [`Race::ended`]; a stopped head never ends).
    first: Option<Option<f64>>,
}

impl Race {
    /// A validation NLL of the second head.
    fn saw(&mut self, v: f64) {
        self.running = Some(self.running.map_or(v, |r| r.min(v)));
    }

    /// A validation NLL of the first head.
    fn saw_first(&mut self, v: f64) {
        self.running_first = Some(self.running_first.map_or(v, |r| r.min(v)));
    }

    /// Where the second head ended before the first: the recipe whose final training the second
    /// thread should run now (the second unless the first's running best is already at or below
    /// the second's final value); `None` once the first head has ended, or if the second failed.
    fn second_leader(&self) -> Option<usize> {
        if self.first.is_some() {
            return None;
        }
        let second = self.ended??;
        let first_ahead = self.running_first.is_some_and(|a| second >= a);
        Some(usize::from(!first_ahead))
    }

    /// Whether the final training of recipe `k` on the second thread is still worth finishing.
    fn second_keeps(&self, k: usize) -> bool {
        match self.first {
            None => self.second_leader() == Some(k),
            Some(first) => self.keeps(k, first),
        }
    }

    /// The second head ended with `outcome`.
    fn finished(&mut self, outcome: &Result<Trained>) {
        self.ended = Some(outcome.as_ref().ok().map(|t| t.2));
    }

    /// The recipe whose final training the first thread should run now, given the first head's
    /// validation NLL (`None`: it failed); `None` once the second head has ended (the choice is
    /// then made as when the recipes run in turn).
    fn leader(&self, first: Option<f64>) -> Option<usize> {
        if self.ended.is_some() {
            return None;
        }
        let second_ahead = match (first, self.running) {
            (None, _) => true,
            (Some(a), Some(b)) => b < a,
            (Some(_), None) => false,
        };
        Some(usize::from(second_ahead))
    }

    /// The recipe the choice takes once both heads have ended; `None` before, or when the
    /// recipe it would take failed.
    fn chosen(&self) -> Option<usize> {
        let (Some(first), Some(_)) = (self.first, self.ended) else {
            return None;
        };
        let k = usize::from(self.keeps(1, first));
        (k == 1 || first.is_some()).then_some(k)
    }

    /// Whether the final training of recipe `k`, under way, is still worth finishing: `k` leads,
    /// or, once the second head has ended, `k` is the recipe the choice takes.
    fn keeps(&self, k: usize, first: Option<f64>) -> bool {
        match self.ended {
            None => self.leader(first) == Some(k),
            Some(second) => {
                let second_chosen = match (first, second) {
                    (_, None) => false,
                    (None, Some(_)) => true,
                    (Some(a), Some(b)) => b < a,
                };
                usize::from(second_chosen) == k
            }
        }
    }
}

/// The watch of recipe `recipe`'s proxy of `iterations` steps ([`super::proxy_watch`]), as
/// its own run in the final stage would train it.
fn proxy_watch(recipe: &MsgpSettings, iterations: usize) -> ProxyWatch {
    let n = iterations.min(recipe.iterations);
    ProxyWatch::new(
        n,
        recipe.segments.is_some() && recipe.optimizer == FitOptimizer::Adam,
        Some(recipe.full_data_blow_up),
        match recipe.choose_final_budget {
            true => final_budgets(n),
            false => Vec::new(),
        },
    )
}

/// Recipe `k`'s proxy as its own run in the final stage would have returned it, from what its
/// watch read off the head's training (which started at `start`).
fn read_proxy(k: usize, read: ProxyOutcome, start: &GpParams<f64>) -> FinalTraining {
    let shape = start.shape().ok();
    let params = |x: &[f64]| shape.and_then(|s| GpParams::from_flat(s, x).ok());
    let outcome = read.outcome.and_then(|(x, it)| Some((params(&x)?, it)));
    let snapshots = match &outcome {
        Some(_) => read
            .snapshots
            .iter()
            .filter_map(|(b, x, it)| Some((*b, params(x)?, *it)))
            .collect(),
        None => Vec::new(),
    };
    FinalTraining {
        recipe: k,
        outcome: Ok(outcome),
        report: FitReport {
            full_data_failed: read.failed,
            numerical_stop: read.numerical_stop,
            ..FitReport::default()
        },
        snapshots,
    }
}

/// Most L-BFGS iterations of the Kalman-filter fit behind [`MsgpStart::LinearKf`] (it stops by
/// itself when converged, after 10–60 on the pendulum loop's data).
const KALMAN_START_ITERATIONS: usize = 300;

/// A recipe's trained parameters, the iteration they are from and their validation NLL per step
/// (`+∞` without a validation tail).
type Trained = (GpParams<f64>, usize, f64);

/// One recipe's training: its start (or `previous`), the solver with early stopping on
/// `tails`, the optional refit. Returns the parameters, the chosen iteration and the best
/// validation NLL per step (`+∞` without tails); its start (without `previous`) goes to
/// `head_start`.
#[allow(clippy::too_many_arguments)]
fn train_recipe(
    stage: &mut Stage<'_, '_>,
    previous: Option<&Model>,
    one_step: &OneStepSettings,
    head_eps: &[Episode],
    all_eps: &[Episode],
    tails: &[Episode],
    stage_number: u8,
    head_start: &mut Option<GpParams<f64>>,
) -> Result<Trained> {
    let init = match previous {
        Some(p) => p.params.clone(),
        None => stage.start_params(head_eps, one_step)?,
    };
    if previous.is_none() {
        *head_start = Some(init.clone());
    }
    let (mut chosen, best_iteration, validation) = stage.train(
        init,
        head_eps,
        tails,
        stage.msgp.iterations,
        stage_number,
        None,
    )?;
    if stage.msgp.refit && !tails.is_empty() {
        // the same number of iterations on the whole training data
        let init = match previous {
            Some(p) => p.params.clone(),
            None => stage.start_params(all_eps, one_step)?,
        };
        chosen = if best_iteration == 0 {
            init
        } else {
            stage.train(init, all_eps, &[], best_iteration, 2, None)?.0
        };
    }
    Ok((chosen, best_iteration, validation))
}

struct MsgpObjective<'a> {
    shape: GpShape,
    spec: NarxSpec,
    config: GpConfig,
    episodes: &'a [Episode],
    likelihood: Likelihood,
    complexity: Complexity,
    threads: Threads,
    log: JitterLog,
    /// The numerical failure of the latest evaluation, if it failed (the loss is then reported
    /// as NaN).
    failure: Option<MsgpError>,
    /// With segments and Adam: the batch of `episodes` each step evaluates.
    batches: Option<Batches>,
    /// Predicted steps of all of `episodes` (the batches' weight).
    all_steps: usize,
}

impl MsgpObjective<'_> {
    /// The loss (NLL and complexity) and its gradient on `episodes`.
    fn evaluate(
        &mut self,
        params: &GpParams<f64>,
        episodes: &[Episode],
        complexity: (Complexity, f64),
    ) -> Result<(LossValue<f64>, Vec<f64>)> {
        let evaluate = match self.likelihood {
            Likelihood::FreeRun => weighted_loss_and_gradient,
            Likelihood::Filter => weighted_filter_loss_and_gradient,
        };
        evaluate(
            params,
            &self.config,
            &self.spec,
            episodes,
            complexity,
            self.threads,
            &mut self.log,
        )
    }

    /// The loss per predicted step and its gradient: of every episode, or with batches an
    /// unbiased estimate from the next batch (its NLL per step, plus the complexity term over
    /// all the steps).
    fn per_step(&mut self, params: &GpParams<f64>) -> Result<(f64, Vec<f64>)> {
        let Some(batches) = self.batches.as_mut() else {
            let (v, mut g) = self.evaluate(params, self.episodes, (self.complexity, 1.0))?;
            let scale = 1.0 / v.steps.max(1) as f64;
            g.iter_mut().for_each(|gi| *gi *= scale);
            return Ok((v.total() * scale, g));
        };
        let picked = batches.draw();
        self.on_batch(params, &picked)
    }

    /// The estimate of the loss per predicted step and its gradient from the episodes
    /// `picked`: their NLL per step plus the complexity term over all the steps.
    fn on_batch(&mut self, params: &GpParams<f64>, picked: &[usize]) -> Result<(f64, Vec<f64>)> {
        let batch: Vec<Episode> = picked.iter().map(|&k| self.episodes[k].clone()).collect();
        let steps = predicted_steps(&batch, &self.spec);
        // (NLL_batch + w · complexity) / steps_batch with w = steps_batch / steps_all
        let b = 1.0 / steps.max(1) as f64;
        let weight = steps as f64 / self.all_steps.max(1) as f64;
        let (v, mut g) = self.evaluate(params, &batch, (self.complexity, weight))?;
        g.iter_mut().for_each(|gi| *gi *= b);
        Ok((v.total() * b, g))
    }
}

impl Objective for MsgpObjective<'_> {
    fn value_and_gradient(&mut self, x: &[f64]) -> Result<(f64, Vec<f64>)> {
        let params = GpParams::from_flat(self.shape, x)?;
        match self.per_step(&params) {
            Err(e @ (MsgpError::NotPositiveDefinite { .. } | MsgpError::NonFinite(_))) => {
                self.failure = Some(e);
                Ok((f64::NAN, vec![0.0; x.len()]))
            }
            Err(e) => Err(e),
            Ok(evaluated) => {
                // a line search may step back from a failed trial: only a failure at the end
                // counts
                self.failure = None;
                Ok(evaluated)
            }
        }
    }
}

/// The steps a loss predicts over `episodes`: every sample after each one's first window.
fn predicted_steps(episodes: &[Episode], spec: &NarxSpec) -> usize {
    episodes
        .iter()
        .map(|e| e.traj.len().saturating_sub(spec.warmup()))
        .sum()
}

/// Mean NLL per step of `episodes` (normalised units) under `likelihood`: the MSGP loss
/// without its complexity term.
fn validation_nll(
    params: &GpParams<f64>,
    config: &GpConfig,
    spec: &NarxSpec,
    likelihood: Likelihood,
    episodes: &[Episode],
) -> Result<f64> {
    let mut log = JitterLog::default();
    let v = match likelihood {
        Likelihood::FreeRun => {
            msgp_loss(params, config, spec, episodes, Complexity::None, &mut log)?
        }
        Likelihood::Filter => {
            filter_loss(params, config, spec, episodes, Complexity::None, &mut log)?
        }
    };
    Ok(v.nll / v.steps.max(1) as f64)
}

/// One MSGP training run: initialisation and Adam with optional early stopping.
struct Stage<'a, 'p> {
    spec: NarxSpec,
    config: GpConfig,
    settings: &'a FitSettings,
    msgp: &'a MsgpSettings,
    start: Instant,
    progress: &'p mut dyn FnMut(&FitProgress) -> ControlFlow<()>,
    report: &'a mut FitReport,
    /// Iterations at which a training without a validation tail keeps a snapshot of its
    /// iterate of lowest loss so far, into `snapshots` (the final training and its proxy, for
    /// [`MsgpSettings::choose_final_budget`]).
    checkpoints: Vec<usize>,
    /// `(checkpoint, flat parameters, their iteration)`, in the order reached.
    snapshots: Vec<(usize, Vec<f64>, usize)>,
    /// The calibration's proxy, read off a training with a validation tail, which then goes on
    /// past its early stop until the proxy's length ([`super::proxy_watch`]).
    proxy_watch: Option<ProxyWatch>,
    /// Whether a head at its early stop, with its best validation NLL, can still be chosen:
    /// where not, it drops its proxy instead of training on for it.
    proxy_ahead: Option<&'a dyn Fn(f64) -> bool>,
}

impl Stage<'_, '_> {
    /// The start of a training run on `episodes`, as [`MsgpSettings::start`] says.
    fn start_params(
        &mut self,
        episodes: &[Episode],
        one_step: &OneStepSettings,
    ) -> Result<GpParams<f64>> {
        match self.msgp.start {
            MsgpStart::OneStep => self.initial(episodes, one_step),
            MsgpStart::Spread => self.initial(
                episodes,
                &OneStepSettings {
                    iterations: 0,
                    ..*one_step
                },
            ),
            MsgpStart::LinearKf => self.initial_from_kalman(episodes),
        }
    }

    /// The sparse one-step GP-NARX fit on `episodes`, its noise variance starting both the
    /// process and the observation noise as [`MsgpSettings::noise_start`] says.
    fn initial(
        &mut self,
        episodes: &[Episode],
        one_step: &OneStepSettings,
    ) -> Result<GpParams<f64>> {
        let refs: Vec<&Trajectory> = episodes.iter().map(|e| &e.traj).collect();
        let data = one_step_pairs(&self.spec, &refs)?;
        let mut init = fit_one_step(
            &data,
            self.msgp.inducing,
            one_step,
            &self.config,
            &Structure::new(&self.settings.integrators, &self.spec),
            self.settings.seed,
            &mut self.report.jitter,
        )?;
        let floor = self.config.noise_floor;
        let share = match self.msgp.noise_start {
            NoiseStart::Split => 0.5,
            NoiseStart::Full => 1.0,
        };
        for a in 0..self.spec.dy {
            let total = init.log_process_noise[a].exp() + floor;
            let part = (share * total - floor).max(1e-3 * floor);
            init.log_process_noise[a] = part.ln();
            init.log_obs_noise[a] = part.ln();
        }
        let m = init.pseudo_inputs.nrows();
        let predicted: usize = episodes
            .iter()
            .map(|e| e.traj.len() - self.spec.warmup())
            .sum();
        if self.msgp.complexity == Complexity::NegHalfLogDet && predicted <= m {
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

    /// The linear-kf start ([`MsgpStart::LinearKf`]): the Kalman-filter fit of the linear window
    /// model on `episodes` (inputs as logged, feedback episodes included) gives the linear mean
    /// and both noise levels; the GP starts at zero on top of it: `m` pseudo-inputs by k-means
    /// over the training windows, pseudo-targets 0 (so the predictive mean is the filter's),
    /// length-scales at the windows' spread, and a signal variance equal to the filter's
    /// process noise (so the predictive variance at most doubles it). Outputs without a GP and
    /// ignored window coordinates get their [`Structure`] values.
    fn initial_from_kalman(&mut self, episodes: &[Episode]) -> Result<GpParams<f64>> {
        let trajs: Vec<Trajectory> = episodes.iter().map(|e| e.traj.clone()).collect();
        let structure = Structure::new(&self.settings.integrators, &self.spec);
        let (linear, kf) = fit_linear_kf(
            &trajs,
            self.spec,
            &structure,
            Normalizer::identity(self.spec.dy, self.spec.du),
            KALMAN_START_ITERATIONS,
            None,
        )?;
        self.report.jitter.merge(&kf.jitter);
        let refs: Vec<&Trajectory> = trajs.iter().collect();
        let data = one_step_pairs(&self.spec, &refs)?;
        let d = data.x.ncols();
        let gx = gp_inputs(&data.x, &structure.ignored);
        let pseudo = place_pseudo_inputs(&gx, self.msgp.inducing, self.settings.seed)?;
        let e = self.spec.dy;
        let floor = self.config.noise_floor;
        // the filter's noise variances (its floor is far below any setting's) as `floor + e^θ`
        let above_floor = |log_var: f64| {
            (log_var.exp() + KF_NOISE_FLOOR - floor)
                .max(1e-3 * floor)
                .ln()
        };
        let lengthscales: Vec<f64> = (0..d)
            .map(|k| match structure.ignored.contains(&k) {
                true => IGNORED_LENGTHSCALE.ln(),
                false => column_std(&gx, k).max(1e-6).ln(),
            })
            .collect();
        let lp = &linear.params;
        let mut params = GpParams {
            pseudo_targets: DMatrix::zeros(pseudo.nrows(), e),
            pseudo_inputs: pseudo,
            log_lengthscales: DMatrix::from_fn(e, d, |_, k| lengthscales[k]),
            log_signal_var: DVector::from_fn(e, |a, _| {
                (lp.log_process_noise[a].exp() + KF_NOISE_FLOOR).ln()
            }),
            log_process_noise: lp.log_process_noise.map(above_floor),
            log_obs_noise: lp.log_obs_noise.map(above_floor),
            linear_mean: lp.linear_mean.clone(),
        };
        for &a in &structure.without_gp {
            params.log_signal_var[a] = NO_GP_SIGNAL_VAR.ln();
        }
        Ok(params)
    }

    /// The solver from `init` for up to `iterations` steps. With validation episodes, checks them
    /// every `eval_every` steps, stops after `patience` checks without improvement and returns the
    /// parameters of the best validation NLL and their iteration; otherwise returns the iterate of
    /// the lowest training loss (the last one, unless a late Adam step threw the loss up). With
    /// `blow_up` (and no validation episodes), a training loss that rises by more than that (per
    /// predicted step) above its lowest since iteration 10 ([`super::blow_up`]) stops the run and is
    /// reported in [`FitReport::full_data_failed`].
    fn train(
        &mut self,
        init: GpParams<f64>,
        episodes: &[Episode],
        tails: &[Episode],
        iterations: usize,
        stage: u8,
        blow_up: Option<f64>,
    ) -> Result<Trained> {
        let shape = init.shape()?;
        // which parameters move: the frozen groups (and `A` without a linear mean) stay
        let mut free = GpParams::filled(shape, true);
        let no_mean = (self.config.mean == MeanFunction::Zero).then_some(ParamGroup::LinearMean);
        for g in self.msgp.frozen.iter().chain(no_mean.iter()) {
            free.fill_group(*g, false);
        }
        // … and what integrating outputs fix: their rows of `A` on their own lags, the
        // length-scales of ignored inputs, the GP of outputs without one
        let structure = Structure::new(&self.settings.integrators, &self.spec);
        for c in &structure.fixed {
            free.linear_mean[(c.row, c.col)] = false;
        }
        for &col in &structure.ignored {
            free.log_lengthscales.column_mut(col).fill(false);
        }
        for &a in &structure.without_gp {
            free.pseudo_targets.column_mut(a).fill(false);
            free.log_lengthscales.row_mut(a).fill(false);
            free.log_signal_var[a] = false;
        }
        let active = free.to_flat();
        let mut objective = MsgpObjective {
            shape,
            spec: self.spec,
            config: self.config,
            episodes,
            likelihood: self.msgp.likelihood,
            complexity: self.msgp.complexity,
            threads: self.settings.threads,
            log: JitterLog::default(),
            failure: None,
            batches: match (self.msgp.segments, self.msgp.optimizer) {
                (Some(s), FitOptimizer::Adam) => Batches::new(
                    episodes.len(),
                    s.batch,
                    self.settings.seed ^ (u64::from(stage) << 32),
                ),
                _ => None,
            },
            all_steps: predicted_steps(episodes, &self.spec),
        };
        let batched = objective.batches.is_some();
        let solver = match self.msgp.optimizer {
            FitOptimizer::Adam => Solver::Adam(Adam {
                learning_rate: self.msgp.learning_rate,
                ..Adam::default()
            }),
            FitOptimizer::Lbfgs => Solver::Lbfgs(FIT_LBFGS),
        };
        let (spec, config, msgp, start) = (self.spec, self.config, self.msgp, self.start);
        let every = match msgp.optimizer {
            FitOptimizer::Adam => msgp.eval_every.max(1),
            FitOptimizer::Lbfgs => 1,
        };
        let mut best: (f64, Vec<f64>, usize) = (f64::INFINITY, init.to_flat(), 0);
        let checkpoints = std::mem::take(&mut self.checkpoints);
        let mut snapshots = Vec::new();
        let mut blow_up = blow_up.map(BlowUp::new);
        let mut since_best = 0usize;
        let mut good: Option<(Vec<f64>, usize)> = None;
        // a batched training without a tail returns the mean of its iterates over its second
        // half (Polyak–Ruppert averaging: the batches' noise averages out)
        let mut average: Option<(Vec<f64>, usize)> = None;
        let report = &mut *self.report;
        let progress = &mut *self.progress;
        let mut last_it = iterations;
        let mut stopped = None;
        // past the early stop, the training goes on only for the proxy it carries
        let mut watch = match tails.is_empty() {
            true => None,
            false => self.proxy_watch.take(),
        };
        let mut frozen = false;
        let proxy_ahead = self.proxy_ahead;
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
                if let Some(w) = watch.as_mut() {
                    w.observe(it, loss, x);
                }
                if !frozen {
                    good = Some((x.to_vec(), it));
                    last_it = it;
                }
                if batched && tails.is_empty() && 2 * it >= iterations {
                    let (sum, count) = average.get_or_insert_with(|| (vec![0.0; x.len()], 0));
                    sum.iter_mut().zip(x).for_each(|(s, x)| *s += x);
                    *count += 1;
                }
                // without a validation tail, the best iterate is the one of lowest training loss:
                // Adam's steps at the loop's step size throw the loss up now and then (by up to
                // 2.7 nats per step on the loop's data), for tens of iterations, also at the last
                // (a batch's loss is too noisy for that: batched trainings return their mean)
                if tails.is_empty() && !batched && loss < best.0 {
                    best = (loss, x.to_vec(), it);
                }
                if tails.is_empty() && best.0.is_finite() && checkpoints.contains(&it) {
                    snapshots.push((it, best.1.clone(), best.2));
                }
                if let (true, Some(watch)) = (tails.is_empty(), blow_up.as_mut())
                    && let Some(why) = watch.observe(it, loss)
                {
                    report.full_data_failed = Some(why);
                    report.iterations_run += 1;
                    return Ok(Flow::Stop);
                }
                let mut validation = None;
                if !tails.is_empty() && !frozen && (it % every == 0 || it == iterations) {
                    let p = GpParams::from_flat(shape, x)?;
                    let v = validation_nll(&p, &config, &spec, msgp.likelihood, tails)?;
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
                if !frozen && !tails.is_empty() && since_best >= msgp.patience {
                    frozen = true;
                    if proxy_ahead.is_some_and(|ahead| !ahead(best.0)) {
                        watch = None;
                    }
                }
                if it == iterations || (frozen && watch.as_ref().is_none_or(|w| w.done())) {
                    return Ok(Flow::Stop);
                }
                Ok(Flow::Continue)
            },
        )?;
        report.jitter.merge(&objective.log);
        self.checkpoints = checkpoints;
        self.snapshots = snapshots;
        if let Some(iteration) = stopped {
            return Err(MsgpError::Stopped { iteration });
        }
        let mut failure = objective.failure.take();
        if let (Some(w), Some(e)) = (watch.as_mut(), failure.as_ref()) {
            w.failed(e.to_string());
        }
        self.proxy_watch = watch;
        // a failure past the early stop was the proxy's alone
        if frozen {
            failure = None;
        }
        let validation = if tails.is_empty() {
            f64::INFINITY
        } else {
            best.0
        };
        let (x, it) = match (failure, good) {
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
            (None, _) if tails.is_empty() && !best.0.is_finite() => match average {
                Some((sum, count)) if count > 0 => {
                    (sum.iter().map(|s| s / count as f64).collect(), last_it)
                }
                _ => (last_x, last_it),
            },
            (None, _) => (best.1, best.2),
        };
        Ok((GpParams::from_flat(shape, &x)?, it, validation))
    }
}

#[cfg(test)]
mod budget_tests {
    use super::{CLEARLY_BETTER, shorter_if_clearly_better};

    #[test]
    fn a_shorter_training_replaces_the_longest_only_where_clearly_better() {
        let longest = 1.0;
        let margin = 1.0 - CLEARLY_BETTER;
        let clearly = margin - 1e-9;
        let barely = margin + 1e-9;
        assert_eq!(
            shorter_if_clearly_better(&[Some(longest), Some(clearly)]),
            Some(1)
        );
        assert_eq!(
            shorter_if_clearly_better(&[Some(longest), Some(barely)]),
            Some(0)
        );
        // among the clearly better ones, the lowest; failed and worse ones are passed over
        let best = 0.5;
        let worse = 1.5;
        assert_eq!(
            shorter_if_clearly_better(&[Some(longest), Some(clearly), None, Some(best)]),
            Some(3)
        );
        assert_eq!(
            shorter_if_clearly_better(&[Some(longest), Some(best), Some(clearly)]),
            Some(1)
        );
        assert_eq!(
            shorter_if_clearly_better(&[Some(longest), Some(worse), Some(barely)]),
            Some(0)
        );
        // the longest failed: no choice
        assert_eq!(shorter_if_clearly_better(&[None, Some(clearly)]), None);
        assert_eq!(shorter_if_clearly_better(&[]), None);
    }
}

#[cfg(test)]
mod race_tests {
    use super::*;

    /// The first thread trains on all the data the recipe that leads, and keeps at it only while
    /// the choice can still fall on it; once the second head ended, the choice is exactly the
    /// one of the recipes run in turn (strictly lower validation NLL wins, ties to the first).
    #[test]
    fn the_final_training_follows_the_leading_recipe() {
        let mut race = Race::default();
        // the second head has not validated yet: the first leads
        assert_eq!(race.leader(Some(0.5)), Some(0));
        // … nor when the second only ties it
        race.saw(0.5);
        assert_eq!(race.leader(Some(0.5)), Some(0));
        assert!(race.keeps(0, Some(0.5)) && !race.keeps(1, Some(0.5)));
        // a running best below the first's final value: the second has won (its best only falls)
        race.saw(0.7);
        race.saw(0.4);
        assert_eq!(race.running, Some(0.4));
        assert_eq!(race.leader(Some(0.5)), Some(1));
        assert!(!race.keeps(0, Some(0.5)) && race.keeps(1, Some(0.5)));
        // a first head that failed numerically leaves the lead to the second
        assert_eq!(Race::default().leader(None), Some(1));
        // once the second head ended: no new speculation, the exact choice
        let ended = |second: Result<Trained>| {
            let mut race = Race::default();
            race.finished(&second);
            race
        };
        let params = GpParams::filled(GpShape { m: 1, d: 1, e: 1 }, 0.0);
        let trained = |v: f64| Ok((params.clone(), 3, v));
        let race = ended(trained(0.4));
        assert_eq!(race.leader(Some(0.5)), None);
        assert!(race.keeps(1, Some(0.5)) && !race.keeps(0, Some(0.5)));
        let race = ended(trained(0.5));
        assert!(race.keeps(0, Some(0.5)), "ties go to the first recipe");
        assert!(race.keeps(1, None), "the first failed");
        // the second failed late (after leading): the first is chosen
        let race = ended(Err(MsgpError::NonFinite("late".into())));
        assert!(race.keeps(0, Some(0.5)) && !race.keeps(1, Some(0.5)));
        // the choice the second recipe's thread trains the calibration's proxy for: known only
        // once both heads have ended, and never a recipe that failed
        let chosen = |first: Option<Option<f64>>, second: Option<Result<Trained>>| {
            let mut race = Race {
                first,
                ..Race::default()
            };
            if let Some(s) = second {
                race.finished(&s);
            }
            race.chosen()
        };
        assert_eq!(
            chosen(None, Some(trained(0.4))),
            None,
            "the first still trains"
        );
        assert_eq!(
            chosen(Some(Some(0.5)), None),
            None,
            "the second still trains"
        );
        assert_eq!(chosen(Some(Some(0.5)), Some(trained(0.4))), Some(1));
        assert_eq!(chosen(Some(Some(0.5)), Some(trained(0.5))), Some(0));
        assert_eq!(chosen(Some(None), Some(trained(0.9))), Some(1));
        let failed = || Some(Err(MsgpError::NonFinite("late".into())));
        assert_eq!(chosen(Some(Some(0.5)), failed()), Some(0));
        assert_eq!(chosen(Some(None), failed()), None, "both failed");
    }

    #[test]
    fn a_second_head_that_ends_first_trains_the_leader() {
        let params = GpParams::filled(GpShape { m: 1, d: 1, e: 1 }, 0.0);
        let second = |v: f64| {
            let mut race = Race::default();
            race.finished(&Ok((params.clone(), 3, v)));
            race
        };
        // the first has not validated yet: the second leads
        let mut race = second(0.4);
        assert_eq!(race.second_leader(), Some(1));
        assert!(race.second_keeps(1) && !race.second_keeps(0));
        // the first's running best above the second's: still the second; at or below: the
        // first has won (its best only falls, and ties go to the first)
        race.saw_first(0.6);
        assert_eq!(race.second_leader(), Some(1));
        race.saw_first(0.4);
        assert_eq!(race.second_leader(), Some(0));
        assert!(race.second_keeps(0) && !race.second_keeps(1));
        // once the first has ended, no new speculation: the exact choice
        race.first = Some(Some(0.4));
        assert_eq!(race.second_leader(), None);
        assert!(race.second_keeps(0) && !race.second_keeps(1));
        let mut race = second(0.4);
        race.saw_first(0.6);
        race.first = Some(None);
        assert!(race.second_keeps(1), "the first failed numerically");
        // a second head that failed leads nothing
        let mut race = Race::default();
        race.finished(&Err(MsgpError::NonFinite("late".into())));
        assert_eq!(race.second_leader(), None);
    }
}

#[cfg(test)]
mod split_tests {
    use super::*;

    /// The head's proxy splits the head as the fit splits its data: a long feed-forward
    /// episode into its first part and its last fifth (with the window before it), feedback
    /// and short episodes whole.
    #[test]
    fn the_heads_proxy_splits_the_head_as_the_fit_splits_the_data() {
        let traj = |n: usize| {
            let u: Vec<f64> = (0..n).map(|i| (i as f64 * 0.3).sin()).collect();
            let y: Vec<f64> = (0..n).map(|i| i as f64).collect();
            Trajectory::siso(&u, &y).expect("finite")
        };
        let (heads, tails) = split_tails(
            &[
                Episode::feed_forward(traj(100)),
                Episode::feed_forward(traj(30)),
            ],
            0.2,
            3,
        );
        assert_eq!(heads.len(), 2);
        assert_eq!(tails.len(), 1);
        assert_eq!((heads[0].traj.len(), heads[1].traj.len()), (80, 30));
        // the tail: the last 20 samples and the 3 before them
        assert_eq!(tails[0].traj.len(), 23);
        assert_eq!(tails[0].traj.y[(0, 0)], 77.0);
        assert_eq!(tails[0].traj.y[(22, 0)], 99.0);
        // no fraction: nothing split
        let (heads, tails) = split_tails(&[Episode::feed_forward(traj(100))], 0.0, 3);
        assert!(tails.is_empty() && heads[0].traj.len() == 100);
    }
}

#[cfg(test)]
mod batch_tests {
    use super::*;
    use crate::fit::{FitSettings, TrainingEpisode, fit_episodes};

    /// The batched loss is an unbiased estimate of the whole one: over three segments of equal
    /// length, the mean of the three single-segment estimates is the loss per step of all of
    /// them, value and gradient (the complexity term weighted by all the steps, the NLL by the
    /// batch's), for both likelihoods.
    #[test]
    fn batches_estimate_the_whole_loss_without_bias() {
        // `y_t = 0.9 y_{t−1} + 0.5 u_{t−1} + 0.2 sin(3 y_{t−1})` under a sine input
        let n = 3 * 20 + 2;
        let u: Vec<f64> = (0..n).map(|i| (i as f64 * 0.37).sin()).collect();
        let mut y = vec![0.0; n];
        for t in 1..n {
            y[t] = 0.9 * y[t - 1] + 0.5 * u[t - 1] + 0.2 * (y[t - 1] * 3.0).sin();
        }
        let traj = Trajectory::siso(&u, &y).expect("finite");
        let settings = FitSettings {
            ly: 2,
            lu: 2,
            method: MsgpSettings {
                inducing: 8,
                iterations: 30,
                validation_fraction: 0.0,
                ..MsgpSettings::default()
            }
            .into(),
            ..FitSettings::default()
        };
        let whole = [TrainingEpisode {
            traj: traj.clone(),
            policy: None,
        }];
        let (model, _) = fit_episodes(&whole, &settings, &mut |_| {}).expect("fit");
        let episodes = crate::fit::Segments {
            length: 20,
            batch: 1,
        }
        .split(&[Episode::feed_forward(model.normalizer.apply(&traj))], 2)
        .expect("split");
        assert_eq!(episodes.len(), 3);
        for likelihood in [Likelihood::FreeRun, Likelihood::Filter] {
            let mut objective = MsgpObjective {
                shape: model.params.shape().expect("shape"),
                spec: model.spec,
                config: model.config,
                episodes: &episodes,
                likelihood,
                complexity: Complexity::HalfLogDet,
                threads: Threads::default(),
                log: JitterLog::default(),
                failure: None,
                batches: None,
                all_steps: 60,
            };
            let (value, gradient) = objective.per_step(&model.params).expect("whole");
            let mut mean = (0.0, vec![0.0; gradient.len()]);
            for k in 0..3 {
                let (v, g) = objective.on_batch(&model.params, &[k]).expect("batch");
                mean.0 += v / 3.0;
                mean.1.iter_mut().zip(&g).for_each(|(m, g)| *m += g / 3.0);
            }
            assert!(
                (mean.0 - value).abs() < 1e-12 * value.abs().max(1.0),
                "{mean:?} {value}"
            );
            let size = gradient.iter().fold(0.0_f64, |a, g| a.max(g.abs()));
            for (m, g) in mean.1.iter().zip(&gradient) {
                // (each rollout's jitter is its own: the sums agree to about 1e-8)
                assert!((m - g).abs() < 1e-6 * size, "{m} vs {g}");
            }
            // one segment alone is not the whole: the test could tell a wrong weighting
            let (v0, _) = objective.on_batch(&model.params, &[0]).expect("batch");
            assert!((v0 - value).abs() > 1e-6, "{v0} {value}");
        }
    }
}
