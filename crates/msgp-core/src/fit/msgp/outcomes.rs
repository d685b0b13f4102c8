//! What the protocol's trainings ([`super::plan::Step`]) returned, as the choice reads them.

use super::super::FitReport;
use super::plan::{Plan, Step};
use crate::error::{MsgpError, Result};
use crate::gp::GpParams;

/// A recipe's trained parameters, the iteration they are from and their validation NLL per step
/// (`+∞` without a validation tail).
pub(super) type Trained = (GpParams<f64>, usize, f64);

/// A head's training ([`Step::Head`]) or the calibration's inner one ([`Step::InnerHead`]).
#[derive(Debug)]
pub(super) struct HeadRun {
    pub trained: Result<Trained>,
    /// Its own report (history, iterations, jitter).
    pub report: FitReport,
    /// Where it started (without a previous model): the start of its recipe's proxy.
    pub start: Option<GpParams<f64>>,
}

/// A training of fixed length without a tail: a final training on all the data, or its proxy
/// on the heads. Its outcome is the parameters and iteration kept, or `None` where it blew up or
/// failed numerically (the head's model standing) or the proxy had no start.
#[derive(Debug)]
pub(super) struct FinalTraining {
    pub outcome: Result<Option<(GpParams<f64>, usize)>>,
    /// The report of this training alone.
    pub report: FitReport,
}

impl FinalTraining {
    /// A training that did not run, for want of a start.
    pub fn without_start() -> Self {
        Self {
            outcome: Ok(None),
            report: FitReport::default(),
        }
    }
}

/// What one step returned.
#[derive(Debug)]
pub(super) enum StepOutcome {
    Head(Box<HeadRun>),
    /// A head and the proxy read off its training ([`super::super::proxy_watch`]).
    HeadWithProxy(Box<(HeadRun, FinalTraining)>),
    Fixed(Box<FinalTraining>),
}

impl StepOutcome {
    /// Whether the step was stopped (by the observer, or as no longer needed).
    pub fn stopped(&self) -> bool {
        let stopped = |r: &Result<_>| matches!(r, Err(MsgpError::Stopped { .. }));
        match self {
            Self::Head(h) => stopped(&h.trained),
            Self::HeadWithProxy(hp) => stopped(&hp.0.trained),
            Self::Fixed(f) => match &f.outcome {
                Err(e) => matches!(e, MsgpError::Stopped { .. }),
                Ok(_) => false,
            },
        }
    }

    /// The stop's error, where [`StepOutcome::stopped`].
    pub fn into_error(self) -> Option<MsgpError> {
        match self {
            Self::Head(h) => h.trained.err(),
            Self::HeadWithProxy(hp) => hp.0.trained.err(),
            Self::Fixed(f) => f.outcome.err(),
        }
    }
}

/// Every step's outcome so far, by recipe.
#[derive(Debug)]
pub(super) struct Outcomes {
    pub heads: Vec<Option<HeadRun>>,
    pub finals: Vec<Option<FinalTraining>>,
    pub proxies: Vec<Option<FinalTraining>>,
    pub inner: Option<HeadRun>,
}

impl Outcomes {
    /// Nothing run yet, of `plan`.
    pub fn new(plan: &Plan) -> Self {
        let n = plan.recipes.len();
        Self {
            heads: (0..n).map(|_| None).collect(),
            finals: (0..n).map(|_| None).collect(),
            proxies: (0..n).map(|_| None).collect(),
            inner: None,
        }
    }

    /// Whether `step` has an outcome.
    pub fn has(&self, step: Step) -> bool {
        match step {
            Step::Head(k) => self.heads[k].is_some(),
            Step::Final(k) => self.finals[k].is_some(),
            Step::Proxy(k) => self.proxies[k].is_some(),
            Step::InnerHead(_) => self.inner.is_some(),
        }
    }

    /// `step` returned `outcome` (a proxy read off a head counts as the proxy's; a proxy
    /// already read is kept).
    pub fn record(&mut self, step: Step, outcome: StepOutcome) {
        match (step, outcome) {
            (Step::InnerHead(_), StepOutcome::Head(h)) => self.inner = Some(*h),
            (Step::Head(k), StepOutcome::Head(h)) => self.heads[k] = Some(*h),
            (Step::Head(k), StepOutcome::HeadWithProxy(hp)) => {
                let (h, p) = *hp;
                self.heads[k] = Some(h);
                self.proxies[k].get_or_insert(p);
            }
            (Step::Final(k), StepOutcome::Fixed(f)) => self.finals[k] = Some(*f),
            (Step::Proxy(k), StepOutcome::Fixed(f)) => {
                self.proxies[k].get_or_insert(*f);
            }
            // (a step returns its own kind of outcome)
            _ => {}
        }
    }

    /// Where recipe `k`'s head started, if it has.
    pub fn start(&self, k: usize) -> Option<&GpParams<f64>> {
        self.heads[k].as_ref()?.start.as_ref()
    }
}
