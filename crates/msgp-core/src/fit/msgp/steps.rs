//! Running one step of the plan ([`Runner::run`]): a recipe's head, its final training, the
//! final training's proxy, or the calibration's inner head, each under its own report.

use std::ops::ControlFlow;
use std::time::Instant;

use super::super::one_step::OneStepSettings;
use super::super::proxy_watch::{ProxyOutcome, ProxyWatch};
use super::super::{FitOptimizer, FitProgress, FitReport, FitSettings, MsgpSettings};
use super::outcomes::{FinalTraining, HeadRun, StepOutcome};
use super::plan::{Plan, Step};
use super::stage::{Stage, train_recipe};
use crate::data::Normalizer;
use crate::error::MsgpError;
use crate::gp::GpParams;
use crate::model::Model;
use crate::narx::NarxSpec;
use crate::numeric::parallel::Threads;
use crate::rollout::Episode;

/// The training data as the protocol splits them.
#[derive(Debug)]
pub(super) struct Data {
    /// Every episode's head (feedback and short episodes whole), by segments with them.
    pub heads: Vec<Episode>,
    /// Every episode whole, by segments with them.
    pub all: Vec<Episode>,
    /// The validation tails (each with the window before it).
    pub tails: Vec<Episode>,
    /// The heads split once more, for the calibration's inner head: heads and tails.
    pub inner: (Vec<Episode>, Vec<Episode>),
}

/// What every step shares.
pub(super) struct Runner<'a> {
    pub plan: &'a Plan,
    pub spec: NarxSpec,
    pub normalizer: &'a Normalizer,
    pub settings: &'a FitSettings,
    pub one_step: &'a OneStepSettings,
    pub previous: Option<&'a Model>,
    pub data: &'a Data,
    pub start: Instant,
}

/// How a step runs: on how many threads, from which start (a proxy's: its head's), whether
/// a head at its early stop can still be chosen, and its observer.
pub(super) struct Setting<'o> {
    pub threads: Threads,
    pub init: Option<GpParams<f64>>,
    pub ahead: &'o dyn Fn(f64) -> bool,
    pub observer: &'o mut dyn FnMut(&FitProgress) -> ControlFlow<()>,
}

impl Runner<'_> {
    /// `step`'s training, set as `how` says.
    pub fn run(&self, step: Step, how: Setting<'_>) -> StepOutcome {
        let settings = FitSettings {
            threads: how.threads,
            ..self.settings.clone()
        };
        let data = self.data;
        match step {
            Step::Head(k) => self.head(k, step, &settings, how),
            Step::InnerHead(k) => {
                let (heads, tails) = (&data.inner.0, &data.inner.1);
                let mut report = FitReport::default();
                let mut stage = self.stage(k, &settings, how.observer, &mut report);
                let (trained, start) =
                    train_recipe(&mut stage, None, (heads, tails), self.plan.stage(step));
                StepOutcome::Head(Box::new(HeadRun {
                    trained,
                    report,
                    start,
                }))
            }
            Step::Final(k) => {
                let n = self.plan.final_iterations.unwrap_or(0);
                let trained = self.fixed(k, (&data.all, None), n, &settings, how.observer);
                StepOutcome::Fixed(Box::new(trained))
            }
            Step::Proxy(k) => StepOutcome::Fixed(Box::new(match how.init {
                Some(init) => {
                    let n = self.plan.proxy_iterations.unwrap_or(0);
                    self.fixed(k, (&data.heads, Some(init)), n, &settings, how.observer)
                }
                None => FinalTraining::without_start(),
            })),
        }
    }

    /// Recipe `k`'s head, and the proxy read off its training where it carried one to the end.
    fn head(&self, k: usize, step: Step, settings: &FitSettings, how: Setting<'_>) -> StepOutcome {
        let recipe = &self.plan.recipes[k];
        let data = self.data;
        let mut report = FitReport::default();
        let mut stage = self.stage(k, settings, how.observer, &mut report);
        stage.proxy_watch = self.plan.proxy_iterations.map(|n| proxy_watch(recipe, n));
        stage.proxy_ahead = Some(how.ahead);
        let (trained, start) = train_recipe(
            &mut stage,
            self.previous,
            (&data.heads, &data.tails),
            self.plan.stage(step),
        );
        let watched = stage.proxy_watch.take().filter(|w| w.done());
        let run = HeadRun {
            trained,
            report,
            start,
        };
        match (run.start.as_ref(), watched) {
            (Some(start), Some(watch)) => {
                let proxy = read_proxy(watch.finish(), start);
                StepOutcome::HeadWithProxy(Box::new((run, proxy)))
            }
            _ => StepOutcome::Head(Box::new(run)),
        }
    }

    /// A stage of recipe `k` reporting to `report` and `observer`.
    fn stage<'s, 'p>(
        &'s self,
        k: usize,
        settings: &'s FitSettings,
        observer: &'p mut dyn FnMut(&FitProgress) -> ControlFlow<()>,
        report: &'s mut FitReport,
    ) -> Stage<'s, 'p> {
        Stage {
            spec: self.spec,
            config: self.plan.config(k),
            settings,
            msgp: &self.plan.recipes[k],
            one_step: self.one_step,
            start: self.start,
            progress: observer,
            report,
            proxy_watch: None,
            proxy_ahead: None,
            batches_of: None,
        }
    }

    /// Recipe `k` for `iterations` steps on `episodes` without a tail, from `init` or (`None`)
    /// its own start on them: a final training, or its proxy.
    fn fixed(
        &self,
        k: usize,
        (episodes, init): (&[Episode], Option<GpParams<f64>>),
        iterations: usize,
        settings: &FitSettings,
        observer: &mut dyn FnMut(&FitProgress) -> ControlFlow<()>,
    ) -> FinalTraining {
        let recipe = &self.plan.recipes[k];
        let n = iterations.min(recipe.iterations);
        let mut own = FitReport::default();
        let mut stage = self.stage(k, settings, observer, &mut own);
        if init.is_some() {
            // a proxy: its head's batches
            stage.batches_of = Some(self.plan.stage(Step::Head(k)));
        }
        let stage_number = match init {
            Some(_) => 4,
            None => 2,
        };
        let init = match init {
            Some(init) => Ok(init),
            None => stage.start_params(episodes),
        };
        let blow_up = Some(recipe.full_data_blow_up);
        let trained =
            init.and_then(|init| stage.train(init, episodes, &[], n, stage_number, blow_up));
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
        FinalTraining {
            outcome,
            report: own,
        }
    }
}

/// The watch of `recipe`'s proxy of `iterations` steps ([`super::super::proxy_watch`]), as
/// its own run would train it.
fn proxy_watch(recipe: &MsgpSettings, iterations: usize) -> ProxyWatch {
    let n = iterations.min(recipe.iterations);
    ProxyWatch::new(
        n,
        recipe.segments.is_some() && recipe.optimizer == FitOptimizer::Adam,
        Some(recipe.full_data_blow_up),
    )
}

/// A proxy as its own run would have returned it, from what its watch read off the head's
/// training (which started at `start`).
fn read_proxy(read: ProxyOutcome, start: &GpParams<f64>) -> FinalTraining {
    let shape = start.shape().ok();
    let params = |x: &[f64]| shape.and_then(|s| GpParams::from_flat(s, x).ok());
    let outcome = read.outcome.and_then(|(x, it)| Some((params(&x)?, it)));
    FinalTraining {
        outcome: Ok(outcome),
        report: FitReport {
            full_data_failed: read.failed,
            numerical_stop: read.numerical_stop,
            ..FitReport::default()
        },
    }
}
