//! Where and when the plan's steps run ([`Scheduler::drive`]). The choice says which steps it
//! needs ([`Next::Run`]) and which it will probably need; the scheduler runs them, with two
//! threads or more on two workers (each on half the threads), else one at a time on all of
//! them. A worker with nothing needed to run trains a step the choice will probably need (the
//! final training of the head that leads while the other head trains, a final training's
//! proxy beside it) and drops it once the choice no longer wants it. Every step is a
//! deterministic function of its inputs, and the choice a function of the steps' outcomes, so
//! the model is the same, bit for bit, however the steps were scheduled.
//!
//! The observer (on the caller's thread) sees the steps of the main line
//! ([`Plan::main_line`]), or every step on one worker; stopping it stops every step.

use std::ops::ControlFlow;
use std::sync::atomic::{AtomicBool, Ordering};
use std::sync::mpsc::{self, Sender};
use std::sync::{Arc, Mutex};
use std::thread::{Scope, ScopedJoinHandle};

use super::super::FitProgress;
use super::outcomes::{Outcomes, StepOutcome};
use super::plan::{Next, Step};
use super::selection::can_be_chosen;
use super::steps::{Runner, Setting};
use crate::error::{MsgpError, Result};
use crate::numeric::parallel::Threads;

/// The steps the choice will probably need, from the outcomes so far, the racing heads'
/// running best validation NLLs and the steps it needs.
pub(super) type Likely<'l> = &'l dyn Fn(&Outcomes, &[Option<f64>], &[Step]) -> Vec<Step>;

/// Runs a plan's steps for its choice.
pub(super) struct Scheduler<'a, 'p> {
    pub runner: &'a Runner<'a>,
    pub threads: Threads,
    pub progress: &'p mut dyn FnMut(&FitProgress) -> ControlFlow<()>,
}

/// A worker's message to the caller's thread.
enum Message {
    /// An observed step's progress, and where the observer's answer goes.
    Progress(FitProgress, mpsc::SyncSender<ControlFlow<()>>),
    /// Flight `id` ended (or panicked).
    Done(usize, std::thread::Result<StepOutcome>),
}

/// A step under way.
struct Flight<'s> {
    id: usize,
    step: Step,
    /// Set when its outcome is no longer wanted: it stops at its next iteration.
    abort: Arc<AtomicBool>,
    /// Whether it runs on all the threads.
    full: bool,
    _handle: ScopedJoinHandle<'s, ()>,
}

/// What the running steps share.
struct Shared {
    /// The racing heads' running best validation NLLs.
    running: Mutex<Vec<Option<f64>>>,
    /// Set when the observer stopped the fit.
    stop: AtomicBool,
}

/// How the drive ended, so far.
struct Ending<T> {
    result: Option<Result<T>>,
    stopped: Option<MsgpError>,
    panic: Option<Box<dyn std::any::Any + Send>>,
}

impl<T> Ending<T> {
    fn new() -> Self {
        Self {
            result: None,
            stopped: None,
            panic: None,
        }
    }

    fn over(&self) -> bool {
        self.result.is_some() || self.stopped.is_some() || self.panic.is_some()
    }
}

impl Scheduler<'_, '_> {
    /// Runs the steps `decide` asks for (and those `likely` names, on a spare worker), its
    /// outcomes recorded in `o`, until it is done; the first stop or failure ends the drive
    /// once every step under way has stopped.
    pub fn drive<T>(
        &mut self,
        o: &mut Outcomes,
        decide: &mut dyn FnMut(&mut Outcomes) -> Result<Next<T>>,
        likely: Likely<'_>,
    ) -> Result<T> {
        let plan = self.runner.plan;
        let shared = Shared {
            running: Mutex::new(vec![None; plan.recipes.len()]),
            stop: AtomicBool::new(false),
        };
        let workers = if self.threads.get() >= 2 { 2 } else { 1 };
        let half = Threads::new((self.threads.get() / 2).max(1))?;
        let ending = std::thread::scope(|scope| {
            let (tx, rx) = mpsc::channel::<Message>();
            let mut flights: Vec<Flight<'_>> = Vec::new();
            let mut ids = 0..;
            let mut ending = Ending::<T>::new();
            let mut fresh = true;
            loop {
                if fresh && !ending.over() {
                    fresh = false;
                    match decide(o) {
                        Err(e) => ending.result = Some(Err(e)),
                        Ok(Next::Done(t)) => ending.result = Some(Ok(t)),
                        Ok(Next::Run(needed)) => {
                            let running = shared.running.lock().map(|r| r.clone());
                            let running = running.unwrap_or_else(|e| e.into_inner().clone());
                            let spare = likely(o, &running, &needed);
                            for f in &flights {
                                if !needed.contains(&f.step) && !spare.contains(&f.step) {
                                    f.abort.store(true, Ordering::Relaxed);
                                }
                            }
                            let wanted = wanted(o, &flights, &needed, &spare);
                            for step in &wanted {
                                if flights.len() >= workers || flights.iter().any(|f| f.full) {
                                    break;
                                }
                                let full =
                                    workers == 1 || (flights.is_empty() && wanted.len() == 1);
                                let threads = if full { self.threads } else { half };
                                let id = ids.next().unwrap_or(0);
                                let how = Launch {
                                    id,
                                    step: *step,
                                    threads,
                                    observed: workers == 1 || plan.main_line(*step),
                                };
                                flights.push(self.launch(scope, how, o, &shared, &tx, full));
                            }
                        }
                    }
                }
                if ending.over() {
                    flights
                        .iter()
                        .for_each(|f| f.abort.store(true, Ordering::Relaxed));
                }
                if flights.is_empty() {
                    break;
                }
                match rx.recv() {
                    Ok(Message::Progress(p, answer)) => {
                        // (once the drive is ending, a step's late events are not shown)
                        let flow = match shared.stop.load(Ordering::Relaxed) || ending.over() {
                            true => ControlFlow::Break(()),
                            false => (self.progress)(&p),
                        };
                        // the observer's stop ends the drive, whichever step it saw
                        if flow.is_break() && !shared.stop.swap(true, Ordering::Relaxed) {
                            let stop = MsgpError::Stopped {
                                iteration: p.iteration,
                            };
                            ending.stopped.get_or_insert(stop);
                        }
                        // (a closed answer: the step has gone, and the stop flag says why)
                        let _ = answer.send(flow);
                    }
                    Ok(Message::Done(id, outcome)) => {
                        let Some(i) = flights.iter().position(|f| f.id == id) else {
                            continue;
                        };
                        let flight = flights.remove(i);
                        fresh = true;
                        match outcome {
                            Err(payload) => ending.panic = Some(payload),
                            // (no longer wanted, or the drive is ending)
                            Ok(_) if flight.abort.load(Ordering::Relaxed) => {}
                            Ok(outcome) if outcome.stopped() => {
                                let e = outcome.into_error();
                                ending.stopped = ending.stopped.take().or(e);
                            }
                            Ok(outcome) => o.record(flight.step, outcome),
                        }
                    }
                    // (this thread holds a sender: never)
                    Err(_) => break,
                }
            }
            ending
        });
        if let Some(payload) = ending.panic {
            std::panic::resume_unwind(payload);
        }
        if let Some(e) = ending.stopped {
            return Err(e);
        }
        ending
            .result
            .unwrap_or_else(|| Err(MsgpError::NonFinite("the fit ended without a model".into())))
    }

    /// Starts `how.step` on a thread of `scope`.
    fn launch<'s, 'e>(
        &self,
        scope: &'s Scope<'s, 'e>,
        how: Launch,
        o: &Outcomes,
        shared: &'e Shared,
        tx: &Sender<Message>,
        full: bool,
    ) -> Flight<'s>
    where
        Self: 'e,
    {
        let abort = Arc::new(AtomicBool::new(false));
        let init = match how.step {
            Step::Proxy(k) => o.start(k).cloned(),
            _ => None,
        };
        let (runner, plan) = (self.runner, self.runner.plan);
        let (tx, flag) = (tx.clone(), abort.clone());
        let handle = scope.spawn(move || {
            let run = || {
                let ahead = |best: f64| match how.step {
                    Step::Head(k) => {
                        let running = shared.running.lock();
                        let running = running.unwrap_or_else(|e| e.into_inner());
                        can_be_chosen(plan, &running, k, best)
                    }
                    _ => true,
                };
                let mut observer = |p: &FitProgress| observe(how, p, shared, &flag, &tx);
                let setting = Setting {
                    threads: how.threads,
                    init,
                    ahead: &ahead,
                    observer: &mut observer,
                };
                runner.run(how.step, setting)
            };
            let outcome = std::panic::catch_unwind(std::panic::AssertUnwindSafe(run));
            // (a closed channel: the drive has ended)
            let _ = tx.send(Message::Done(how.id, outcome));
        });
        Flight {
            id: how.id,
            step: how.step,
            abort,
            full,
            _handle: handle,
        }
    }
}

/// A step to start: its flight's id, its threads, and whether the observer sees it.
#[derive(Clone, Copy)]
struct Launch {
    id: usize,
    step: Step,
    threads: Threads,
    observed: bool,
}

/// A running step's observer: a head's validation NLL goes to the running bests; a stop or
/// an abort stops the step; an observed step's progress goes to the observer, whose answer
/// it waits for.
fn observe(
    how: Launch,
    p: &FitProgress,
    shared: &Shared,
    abort: &AtomicBool,
    tx: &Sender<Message>,
) -> ControlFlow<()> {
    if let (Step::Head(k), Some(v)) = (how.step, p.validation) {
        let mut running = shared.running.lock().unwrap_or_else(|e| e.into_inner());
        running[k] = Some(running[k].map_or(v, |r: f64| r.min(v)));
    }
    if abort.load(Ordering::Relaxed) || shared.stop.load(Ordering::Relaxed) {
        return ControlFlow::Break(());
    }
    if !how.observed {
        return ControlFlow::Continue(());
    }
    let (answer, answered) = mpsc::sync_channel(1);
    if tx.send(Message::Progress(*p, answer)).is_err() {
        return ControlFlow::Break(());
    }
    answered.recv().unwrap_or(ControlFlow::Break(()))
}

/// The steps to start, in order: the needed ones, then the likely ones, each without an
/// outcome and not under way (a flight being dropped still counts: its worker is busy).
fn wanted(o: &Outcomes, flights: &[Flight<'_>], needed: &[Step], spare: &[Step]) -> Vec<Step> {
    let mut steps: Vec<Step> = Vec::new();
    for &step in needed.iter().chain(spare) {
        let under_way = flights.iter().any(|f| f.step == step);
        if !under_way && !o.has(step) && !steps.contains(&step) {
            steps.push(step);
        }
    }
    steps
}
