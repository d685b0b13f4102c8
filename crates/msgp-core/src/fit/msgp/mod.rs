//! MSGP training (paper section 3): the one-step sparse GP-NARX fit as the start, then Adam or
//! L-BFGS on the trajectory likelihood ([`crate::loss`]) with its exact adjoint gradient, early
//! stopping on a held-out tail of the training data. With
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
//!
//! ## The protocol as a plan
//! The fit is a [`plan::Plan`] (the recipes and the lengths of their trainings), a choice that
//! is a function of its steps' outcomes ([`selection::decide`]), and a [`schedule::Scheduler`]
//! that runs the steps the choice asks for, side by side where there are threads for it.

mod judge;
mod objective;
mod outcomes;
mod plan;
mod schedule;
mod selection;
mod stage;
mod steps;
mod training;

use std::ops::ControlFlow;
use std::time::Instant;

use super::calibration::{CalibrationReport, Judge as CalibrationJudge, tail_calibration};
use super::continuation;
use super::one_step::OneStepSettings;
use super::{FitProgress, FitReport, FitSettings, MsgpSettings, TrainingEpisode};
use crate::data::{Normalizer, Trajectory};
use crate::error::{MsgpError, Result};
use crate::gp::integrator::Structure;
use crate::gp::{GpParams, PreparedGp};
use crate::model::Model;
use crate::narx::NarxSpec;
use crate::rollout::{Episode, Excitation};
use judge::Checks;
use outcomes::Outcomes;
use plan::{Next, Plan, Step};
use schedule::Scheduler;
use selection::{Judge, Selection, decide, likely};
use steps::{Data, Runner};

/// A check of which models diverge, in place of [`super::divergence::check_divergence`].
pub(super) type Diverges<'a> = &'a dyn Fn(&Model) -> Option<String>;

/// An MSGP fit's problem: the training episodes and their normalised trajectories (in order),
/// the window, the settings, and the model it continues.
#[derive(Clone, Copy)]
pub(super) struct MsgpFit<'a> {
    pub episodes: &'a [TrainingEpisode],
    pub norm: &'a [Trajectory],
    pub normalizer: &'a Normalizer,
    pub spec: NarxSpec,
    pub settings: &'a FitSettings,
    pub msgp: &'a MsgpSettings,
    pub previous: Option<&'a Model>,
    pub one_step: &'a OneStepSettings,
    pub start: Instant,
}

/// The MSGP fit of `fit`, from the one-step start or from the previous model's parameters;
/// the divergence of its recipes' models judged by `judge` where given (the protocol's tests),
/// else by [`super::divergence::check_divergence`].
pub(super) fn fit_msgp(
    fit: MsgpFit<'_>,
    progress: &mut dyn FnMut(&FitProgress) -> ControlFlow<()>,
    mut report: FitReport,
    judge: Option<Diverges<'_>>,
) -> Result<(Model, FitReport)> {
    let (data, grown) = prepare(&fit, &mut report)?;
    let previous = grown.as_ref().or(fit.previous);
    let plan = Plan::new(fit.msgp, !data.tails.is_empty(), previous.is_some());
    let runner = Runner {
        plan: &plan,
        spec: fit.spec,
        normalizer: fit.normalizer,
        settings: fit.settings,
        one_step: fit.one_step,
        previous,
        data: &data,
        start: fit.start,
    };
    let open_loop = fit
        .episodes
        .iter()
        .filter(|e| e.policy.is_none())
        .map(|e| &e.traj)
        .collect();
    let checks = Checks::new(&plan, fit.spec, fit.normalizer, open_loop);
    let replaced = judge.map(|j| Replaced { checks: &checks, j });
    let judged: &dyn Judge = match &replaced {
        Some(r) => r,
        None => &checks,
    };
    let mut scheduler = Scheduler {
        runner: &runner,
        threads: fit.settings.threads,
        progress,
    };
    let mut o = Outcomes::new(&plan);
    let selection = scheduler.drive(
        &mut o,
        &mut |o: &mut Outcomes| decide(&plan, o, judged),
        &|o: &Outcomes, running: &[Option<f64>], needed: &[Step]| likely(&plan, o, running, needed),
    )?;
    write_report(&mut report, &selection, &o);
    let calibration = calibrate(&mut scheduler, &mut o, &selection, &mut report)?;
    report.train_seconds = fit.start.elapsed().as_secs_f64();
    let model = Model {
        calibration,
        ..checks.model(selection.recipe, &selection.params)
    };
    Ok((model, report))
}

/// A judge whose divergence check is replaced.
struct Replaced<'c, 'j> {
    checks: &'c Checks<'c>,
    j: &'j dyn Fn(&Model) -> Option<String>,
}

impl Judge for Replaced<'_, '_> {
    fn diverges(&self, k: usize, params: &GpParams<f64>) -> Option<String> {
        (self.j)(&self.checks.model(k, params))
    }
}

/// The training data split for the protocol (feedback episodes train in closed loop under
/// their normalised policy and are not split; a long log trains by segments, its tails
/// whole), and the previous model with pseudo-inputs added where the data have outgrown it.
fn prepare(fit: &MsgpFit<'_>, report: &mut FitReport) -> Result<(Data, Option<Model>)> {
    let w = fit.spec.warmup();
    let mut all = Vec::new();
    for (t, ep) in fit.norm.iter().zip(fit.episodes) {
        all.push(match &ep.policy {
            Some(p) => Episode {
                traj: t.clone(),
                excitation: Excitation::Feedback(Box::new(p.normalized(fit.normalizer)?)),
            },
            None => Episode::feed_forward(t.clone()),
        });
    }
    let fraction = fit.msgp.validation_fraction;
    let (heads, tails) = split_tails(&all, fraction, w);
    let (heads, all) = match &fit.msgp.segments {
        Some(s) => {
            let all_segments = s.split(&all, w)?;
            report.segments = Some((*s, all_segments.len()));
            (s.split(&heads, w)?, all_segments)
        }
        None => (heads, all),
    };
    let inner = split_tails(&heads, fraction, w);
    let grown = match fit.previous {
        Some(p) => {
            let structure = Structure::new(&fit.settings.integrators, &fit.spec);
            let inducing = fit.msgp.inducing;
            let seed = fit.settings.seed;
            continuation::grown_pseudo_inputs(p, fit.norm, fit.spec, &structure, inducing, seed)?
                .map(|params| Model {
                    params,
                    ..p.clone()
                })
        }
        None => None,
    };
    let data = Data {
        heads,
        all,
        tails,
        inner,
    };
    Ok((data, grown))
}

/// The report of the steps the choice counted: the heads (histories in the recipes' order),
/// the final trainings tried, and the kept final training's proxy.
fn write_report(report: &mut FitReport, selection: &Selection, o: &Outcomes) {
    for run in selection
        .heads_run
        .iter()
        .filter_map(|&k| o.heads[k].as_ref())
    {
        report.iterations_run += run.report.iterations_run;
        report.jitter.merge(&run.report.jitter);
        report.history.extend(run.report.history.iter().copied());
        if report.numerical_stop.is_none() {
            report.numerical_stop.clone_from(&run.report.numerical_stop);
        }
    }
    for trained in selection
        .finals_tried
        .iter()
        .filter_map(|&c| o.finals[c].as_ref())
    {
        report.iterations_run += trained.report.iterations_run;
        report.jitter.merge(&trained.report.jitter);
        if trained.report.numerical_stop.is_some() {
            report
                .numerical_stop
                .clone_from(&trained.report.numerical_stop);
        }
    }
    report.recipes.clone_from(&selection.recipes);
    report.chosen_recipe = selection.recipe;
    report.best_iteration = selection.best_iteration;
    report
        .full_data_failed
        .clone_from(&selection.full_data_failed);
    if let Some(f) = &selection.final_training {
        report.full_data_iteration = Some(f.iteration);
        // (a proxy counts where the plan has one and its final training is the model)
        if let Some(p) = o.proxies[selection.recipe].as_ref() {
            report.iterations_run += p.report.iterations_run;
            report.jitter.merge(&p.report.jitter);
        }
    }
}

/// The calibration ([`super::calibration`], where the settings ask for it and a proxy can
/// judge): the added output variance the judge's free simulation of the tails needs. The
/// judge is the final training's proxy where the final training is the model; where the
/// head's model stands, its own training cross-validated inside the heads (or the head
/// itself where that fails or cannot split).
fn calibrate(
    scheduler: &mut Scheduler<'_, '_>,
    o: &mut Outcomes,
    selection: &Selection,
    report: &mut FitReport,
) -> Result<Vec<f64>> {
    let runner = scheduler.runner;
    let (plan, data) = (runner.plan, runner.data);
    if plan.proxy_iterations.is_none() || !plan.recipes[0].calibrate {
        return Ok(Vec::new());
    }
    let head = || (selection.head.clone(), CalibrationJudge::Head);
    let (params, judge) = match &selection.final_training {
        Some(f) => match &f.proxy {
            Some((params, iteration)) => (
                params.clone(),
                CalibrationJudge::Proxy {
                    iteration: *iteration,
                },
            ),
            None => head(),
        },
        None if data.inner.1.is_empty() => head(),
        None => {
            let step = Step::InnerHead(selection.recipe);
            let mut inner = |o: &mut Outcomes| {
                Ok(match o.inner.take() {
                    Some(run) => Next::Done(run),
                    None => Next::Run(vec![step]),
                })
            };
            let run = scheduler.drive(o, &mut inner, &|_, _, _| Vec::new())?;
            report.iterations_run += run.report.iterations_run;
            report.jitter.merge(&run.report.jitter);
            match run.trained {
                Ok((params, iteration, _)) => (params, CalibrationJudge::HeadProxy { iteration }),
                Err(MsgpError::Stopped { iteration }) => {
                    return Err(MsgpError::Stopped { iteration });
                }
                Err(_) => head(),
            }
        }
    };
    let config = plan.config(selection.recipe);
    let judged = PreparedGp::new(&params, &config, &mut report.jitter)
        .and_then(|gp| tail_calibration(&gp, &runner.spec, &data.tails));
    match judged {
        Ok(delta) => {
            let normalizer = &runner.normalizer;
            report.calibration = Some(CalibrationReport {
                added_std: delta
                    .iter()
                    .enumerate()
                    .map(|(j, d)| normalizer.y_var_to_original(j, *d).sqrt())
                    .collect(),
                judge,
            });
            Ok(delta)
        }
        // a judge whose simulation fails numerically decides nothing
        Err(e) if e.is_numerical() => Ok(Vec::new()),
        Err(e) => Err(e),
    }
}
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
