//! What a training run keeps track of, iteration by iteration ([`Training`]): the best
//! iterate (by validation NLL, or by training loss without a tail), early stopping, the
//! blow-up test, the proxy it carries and the observer.

use std::ops::ControlFlow;
use std::time::Instant;

use super::super::blow_up::BlowUp;
use super::super::proxy_watch::ProxyWatch;
use super::super::{FitOptimizer, FitProgress, FitReport, MsgpSettings};
use super::objective::validation_nll;
use super::outcomes::Trained;
use crate::error::{MsgpError, Result};
use crate::gp::{GpConfig, GpParams, GpShape};
use crate::narx::NarxSpec;
use crate::optim::Flow;
use crate::rollout::Episode;

/// A training run's bookkeeping, fed each iterate by the solver.
pub(super) struct Training<'s> {
    report: &'s mut FitReport,
    progress: &'s mut dyn FnMut(&FitProgress) -> ControlFlow<()>,
    tails: &'s [Episode],
    spec: NarxSpec,
    config: GpConfig,
    msgp: &'s MsgpSettings,
    start: Instant,
    proxy_ahead: Option<&'s dyn Fn(f64) -> bool>,
    /// Validation checks every so many iterations.
    every: usize,
    iterations: usize,
    stage: u8,
    batched: bool,
    shape: GpShape,
    blow_up: Option<BlowUp>,
    /// Past the early stop, the training goes on only for the proxy it carries.
    watch: Option<ProxyWatch>,
    end: Ending,
}

/// What the run's result is made of once the solver has stopped.
pub(super) struct Ending {
    /// `(validation NLL or training loss, flat parameters, iteration)` of the best iterate.
    best: (f64, Vec<f64>, usize),
    since_best: usize,
    /// The last iterate that evaluated, before any early stop.
    good: Option<(Vec<f64>, usize)>,
    /// A batched training without a tail returns the mean of its iterates over its second
    /// half (Polyak–Ruppert averaging: the batches' noise averages out).
    average: Option<(Vec<f64>, usize)>,
    last_it: usize,
    /// The iteration the observer broke on.
    stopped: Option<usize>,
    /// Whether the early stop has come (the best iterate is then fixed).
    frozen: bool,
    with_tails: bool,
}

/// What goes back to the stage.
pub(super) struct Leftovers {
    pub watch: Option<ProxyWatch>,
    pub result: Ending,
}

/// What a training run reports to and is set by: the stage's report, observer, model and
/// recipe, and the proxy it may carry.
pub(super) struct Context<'s> {
    pub report: &'s mut FitReport,
    pub progress: &'s mut dyn FnMut(&FitProgress) -> ControlFlow<()>,
    pub spec: NarxSpec,
    pub config: GpConfig,
    pub msgp: &'s MsgpSettings,
    pub start: Instant,
    pub proxy_ahead: Option<&'s dyn Fn(f64) -> bool>,
    pub proxy_watch: Option<ProxyWatch>,
}

impl<'s> Training<'s> {
    /// The bookkeeping of a run in `stage` from `init` on `tails` (may be empty), for
    /// `iterations` steps of stage number `stage_number`.
    pub fn new(
        stage: Context<'s>,
        init: &GpParams<f64>,
        tails: &'s [Episode],
        (iterations, stage_number): (usize, u8),
        blow_up: Option<f64>,
        batched: bool,
    ) -> Result<Self> {
        let every = match stage.msgp.optimizer {
            FitOptimizer::Adam => stage.msgp.eval_every.max(1),
            FitOptimizer::Lbfgs => 1,
        };
        let watch = match tails.is_empty() {
            true => None,
            false => stage.proxy_watch,
        };
        Ok(Self {
            report: stage.report,
            progress: stage.progress,
            tails,
            spec: stage.spec,
            config: stage.config,
            msgp: stage.msgp,
            start: stage.start,
            proxy_ahead: stage.proxy_ahead,
            every,
            iterations,
            stage: stage_number,
            batched,
            shape: init.shape()?,
            blow_up: blow_up.map(BlowUp::new),
            watch,
            end: Ending {
                best: (f64::INFINITY, init.to_flat(), 0),
                since_best: 0,
                good: None,
                average: None,
                last_it: iterations,
                stopped: None,
                frozen: false,
                with_tails: !tails.is_empty(),
            },
        })
    }

    /// The solver's iterate `x` at iteration `it`, of training loss `loss`.
    pub fn observe(&mut self, it: usize, loss: f64, x: &[f64]) -> Result<Flow> {
        if loss.is_nan() {
            // the parameters of this step failed numerically (the objective knows why)
            return Ok(Flow::Stop);
        }
        if let Some(w) = self.watch.as_mut() {
            w.observe(it, loss, x);
        }
        self.keep(it, loss, x);
        let tails = !self.tails.is_empty();
        if let (false, Some(watch)) = (tails, self.blow_up.as_mut())
            && let Some(why) = watch.observe(it, loss)
        {
            self.report.full_data_failed = Some(why);
            self.report.iterations_run += 1;
            return Ok(Flow::Stop);
        }
        let validation = self.validate(it, loss, x)?;
        self.report.iterations_run += 1;
        let seen = (self.progress)(&FitProgress {
            stage: self.stage,
            iteration: it,
            iterations: self.iterations,
            loss,
            validation,
            elapsed: self.start.elapsed().as_secs_f64(),
        });
        if seen.is_break() {
            self.end.stopped = Some(it);
            return Ok(Flow::Stop);
        }
        let end = &mut self.end;
        if !end.frozen && tails && end.since_best >= self.msgp.patience {
            end.frozen = true;
            if self.proxy_ahead.is_some_and(|ahead| !ahead(end.best.0)) {
                self.watch = None;
            }
        }
        if it == self.iterations || (end.frozen && self.watch.as_ref().is_none_or(|w| w.done())) {
            return Ok(Flow::Stop);
        }
        Ok(Flow::Continue)
    }

    /// Keeps what a run without a tail returns: the iterate of lowest training loss (Adam's
    /// steps at the loop's step size throw the loss up now and then, by up to 2.7 nats per
    /// step on the loop's data, for tens of iterations, also at the last), or with batches,
    /// whose loss is too noisy for that, the mean of the second half.
    fn keep(&mut self, it: usize, loss: f64, x: &[f64]) {
        let end = &mut self.end;
        if !end.frozen {
            end.good = Some((x.to_vec(), it));
            end.last_it = it;
        }
        let tails = !self.tails.is_empty();
        if self.batched && !tails && 2 * it >= self.iterations {
            let (sum, count) = end.average.get_or_insert_with(|| (vec![0.0; x.len()], 0));
            sum.iter_mut().zip(x).for_each(|(s, x)| *s += x);
            *count += 1;
        }
        if !tails && !self.batched && loss < end.best.0 {
            end.best = (loss, x.to_vec(), it);
        }
    }

    /// The validation NLL at iteration `it`, where one is due (and its history entry).
    fn validate(&mut self, it: usize, loss: f64, x: &[f64]) -> Result<Option<f64>> {
        let end = &mut self.end;
        let due = it.is_multiple_of(self.every) || it == self.iterations;
        if self.tails.is_empty() || end.frozen || !due {
            return Ok(None);
        }
        let p = GpParams::from_flat(self.shape, x)?;
        let v = validation_nll(
            &p,
            &self.config,
            &self.spec,
            self.msgp.likelihood,
            self.tails,
        )?;
        self.report.history.push((it, loss, v));
        if v < end.best.0 {
            end.best = (v, x.to_vec(), it);
            end.since_best = 0;
        } else {
            end.since_best += 1;
        }
        Ok(Some(v))
    }

    /// What goes back to the stage once the solver has stopped.
    pub fn leftovers(self) -> Leftovers {
        Leftovers {
            watch: self.watch,
            result: self.end,
        }
    }
}

impl Ending {
    /// The run's result: the best iterate, or where the last step failed numerically
    /// (`failure`) the last good one (reported as a numerical stop); a failure past the
    /// early stop was the proxy's alone (its `watch` is told).
    pub fn finish(
        self,
        report: &mut FitReport,
        (shape, last_x): (GpShape, Vec<f64>),
        mut failure: Option<MsgpError>,
        (iterations, stage): (usize, u8),
        watch: &mut Option<ProxyWatch>,
    ) -> Result<Trained> {
        if let Some(iteration) = self.stopped {
            return Err(MsgpError::Stopped { iteration });
        }
        if let (Some(w), Some(e)) = (watch.as_mut(), failure.as_ref()) {
            w.failed(e.to_string());
        }
        if self.frozen {
            failure = None;
        }
        let best = self.best;
        let validation = match self.with_tails {
            true => best.0,
            false => f64::INFINITY,
        };
        let (x, it) = match (failure, self.good) {
            (Some(e), None) => return Err(e),
            (Some(e), Some((x, it))) => {
                report.numerical_stop = Some(format!(
                    "stage {stage}: stopped at iteration {} of {iterations}: {e}; kept iteration {it}",
                    it + 1
                ));
                match best.0.is_finite() {
                    true => (best.1, best.2),
                    false => (x, it),
                }
            }
            (None, _) if !self.with_tails && !best.0.is_finite() => match self.average {
                Some((sum, count)) if count > 0 => {
                    (sum.iter().map(|s| s / count as f64).collect(), self.last_it)
                }
                _ => (last_x, self.last_it),
            },
            (None, _) => (best.1, best.2),
        };
        Ok((GpParams::from_flat(shape, &x)?, it, validation))
    }
}
