//! The protocol's choice, a function of the steps' outcomes ([`decide`]): which steps it still
//! needs, or which model it ends in. The validation tail orders the recipes' heads (ties to the
//! earlier recipe); the first one's final training is tried; where it blows up, the fallback
//! heads train and their final trainings are tried in the tail's order; where a final model
//! diverges over the training inputs, the racing heads not yet tried follow, and where every
//! one diverges, the first that did stands. [`likely`] names the steps the choice will
//! probably need, for a scheduler with a worker to spare.

use super::outcomes::{FinalTraining, Outcomes, Trained};
use super::plan::{Next, Plan, Step};
use crate::error::{MsgpError, Result};
use crate::fit::RecipeOutcome;
use crate::gp::GpParams;

/// What the choice asks of a model beyond the steps' outcomes: deterministic functions of the
/// model, which the protocol's tests may replace.
pub(super) trait Judge {
    /// Why recipe `k`'s model with `params` diverges over the feed-forward training
    /// trajectories, or `None`.
    fn diverges(&self, k: usize, params: &GpParams<f64>) -> Option<String>;
}

/// A head the tail has judged: its recipe, validation NLL, parameters and kept iteration.
#[derive(Clone, Debug)]
struct Head {
    k: usize,
    validation: f64,
    params: GpParams<f64>,
    best_iteration: usize,
}

/// The final training of the chosen model.
#[derive(Clone, Debug)]
pub(super) struct FinalChoice {
    /// The final training's kept iteration.
    pub iteration: usize,
    /// The proxy's model standing for it, where a proxy ran and completed: the
    /// calibration's judge.
    pub proxy: Option<(GpParams<f64>, usize)>,
}

/// The model the protocol ends in and what the report says of the choice.
#[derive(Clone, Debug)]
pub(super) struct Selection {
    /// The recipe chosen.
    pub recipe: usize,
    /// The model's parameters.
    pub params: GpParams<f64>,
    /// Its head's model.
    pub head: GpParams<f64>,
    /// The head's kept iteration.
    pub best_iteration: usize,
    /// Its final training, where it is that training's model.
    pub final_training: Option<FinalChoice>,
    /// Every head trained, in the recipes' order.
    pub recipes: Vec<RecipeOutcome>,
    /// The heads whose outcomes the report counts, in order.
    pub heads_run: Vec<usize>,
    /// The final trainings tried, in order.
    pub finals_tried: Vec<usize>,
    /// Why the first final training tried failed, where no final model was kept.
    pub full_data_failed: Option<String>,
}

/// What the choice needs next, from the `outcomes` so far. A head whose training failed
/// numerically leaves the choice to the others; any other failure ends the fit (its error is
/// taken out of `outcomes`).
pub(super) fn decide(plan: &Plan, o: &mut Outcomes, judge: &dyn Judge) -> Result<Next<Selection>> {
    let racing: Vec<usize> = (0..plan.racing).collect();
    if let Some(run) = missing_heads(o, &racing) {
        return Ok(Next::Run(run));
    }
    let mut walk = Walk::default();
    let raced = walk.judge_heads(plan, o, &racing, false)?;
    let Some(first) = raced.first().cloned() else {
        let error = walk.first_failure(o);
        return Err(error.unwrap_or_else(|| MsgpError::NonFinite("no recipe trained".into())));
    };
    let Some(_) = plan.final_iterations else {
        return Ok(Next::Done(walk.without_final(&raced, judge)));
    };
    walk.with_final(plan, o, raced, first, judge)
}

/// The steps the choice will probably need besides `needed`: while racing heads train, the
/// final training of the one that leads (ended heads by their validation NLL, running ones
/// by their `running` best, ties to the earlier recipe: a running best only falls, so a head
/// ahead of an ended one stays ahead unless it fails); beside a final training, its proxy.
pub(super) fn likely(
    plan: &Plan,
    o: &Outcomes,
    running: &[Option<f64>],
    needed: &[Step],
) -> Vec<Step> {
    let mut steps = Vec::new();
    let racing = needed
        .iter()
        .any(|s| matches!(s, Step::Head(k) if *k < plan.racing));
    if racing && plan.final_iterations.is_some() {
        let standing = (0..plan.racing).filter_map(|k| match &o.heads[k] {
            Some(h) => h.trained.as_ref().ok().map(|t| (t.2, k)),
            None => Some((running[k].unwrap_or(f64::INFINITY), k)),
        });
        let leader = standing.min_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
        if let Some((_, k)) = leader
            && o.finals[k].is_none()
        {
            steps.push(Step::Final(k));
        }
    }
    if plan.proxy_iterations.is_some() {
        for step in needed {
            if let Step::Final(k) = *step
                && o.proxies[k].is_none()
                && o.start(k).is_some()
            {
                steps.push(Step::Proxy(k));
            }
        }
    }
    steps
}

/// Whether head `k`, at its early stop with validation NLL `best`, can still be chosen over
/// the other racing heads' `running` bests (ties to the earlier recipe): where not, its
/// proxy would be read for nothing.
pub(super) fn can_be_chosen(plan: &Plan, running: &[Option<f64>], k: usize, best: f64) -> bool {
    k >= plan.racing
        || (0..plan.racing).all(|j| match (running[j], j.cmp(&k)) {
            (Some(v), std::cmp::Ordering::Less) => best < v,
            (Some(v), std::cmp::Ordering::Greater) => best <= v,
            _ => true,
        })
}

/// The heads among `ks` without an outcome, as steps; `None` where every one has one.
fn missing_heads(o: &Outcomes, ks: &[usize]) -> Option<Vec<Step>> {
    let run: Vec<Step> = ks
        .iter()
        .filter(|&&k| o.heads[k].is_none())
        .map(|&k| Step::Head(k))
        .collect();
    (!run.is_empty()).then_some(run)
}

/// The choice's way through the outcomes, and what the report will say of it.
#[derive(Default)]
struct Walk {
    recipes: Vec<RecipeOutcome>,
    heads_run: Vec<usize>,
    finals_tried: Vec<usize>,
    full_data_failed: Option<String>,
    /// The heads that failed numerically, in order.
    failed: Vec<usize>,
}

/// A final model with its head and final training: accepted, or set aside for diverging.
type Kept = (Head, usize, FinalProxy);

/// A kept final model's proxy model, where one completed.
type FinalProxy = Option<(GpParams<f64>, usize)>;

impl Walk {
    /// The heads `ks` (all with outcomes) in the tail's order (a stable sort: ties to the
    /// training order), each written into the report's recipes; a head that failed
    /// numerically is left out, any other failure returned.
    fn judge_heads(
        &mut self,
        plan: &Plan,
        o: &mut Outcomes,
        ks: &[usize],
        fallback: bool,
    ) -> Result<Vec<Head>> {
        let mut heads = Vec::new();
        for &k in ks {
            let Some(run) = o.heads[k].as_mut() else {
                continue;
            };
            self.heads_run.push(k);
            let (validation, failed) = match &run.trained {
                Ok((params, best_iteration, validation)) => {
                    heads.push(Head {
                        k,
                        validation: *validation,
                        params: params.clone(),
                        best_iteration: *best_iteration,
                    });
                    (validation.is_finite().then_some(*validation), None)
                }
                Err(e) if e.is_numerical() => {
                    self.failed.push(k);
                    (None, run.trained.as_ref().err().map(ToString::to_string))
                }
                Err(_) => {
                    std::mem::replace(&mut run.trained, Ok(placeholder()))?;
                    continue;
                }
            };
            self.recipes.push(RecipeOutcome {
                recipe: plan.recipes[k].recipe(),
                start: plan.recipes[k].start,
                validation,
                failed,
                final_failed: None,
                diverged: None,
                fallback_head: fallback,
            });
        }
        heads.sort_by(|a, b| a.validation.total_cmp(&b.validation));
        Ok(heads)
    }

    /// The first numerical failure of a head, taken out of `o`.
    fn first_failure(&self, o: &mut Outcomes) -> Option<MsgpError> {
        let k = *self.failed.first()?;
        let run = o.heads[k].as_mut()?;
        std::mem::replace(&mut run.trained, Ok(placeholder())).err()
    }

    /// Without a final training: the first head in the tail's order, unless its model
    /// diverges and another's does not.
    fn without_final(mut self, raced: &[Head], judge: &dyn Judge) -> Selection {
        let mut chosen = raced[0].clone();
        if raced.len() > 1
            && let Some(why) = judge.diverges(chosen.k, &chosen.params)
            && let Some(stable) = raced[1..]
                .iter()
                .find(|h| judge.diverges(h.k, &h.params).is_none())
        {
            if let Some(outcome) = self.outcome(chosen.k) {
                outcome.diverged = Some(why);
            }
            chosen = stable.clone();
        }
        self.selection(chosen, None)
    }

    /// With a final training: the candidates' final trainings in turn (see the module).
    fn with_final(
        mut self,
        plan: &Plan,
        o: &mut Outcomes,
        raced: Vec<Head>,
        first: Head,
        judge: &dyn Judge,
    ) -> Result<Next<Selection>> {
        let mut candidates = vec![first.clone()];
        let mut set_aside: Option<Kept> = None;
        let mut accepted = None;
        let mut i = 0;
        while i < candidates.len() {
            let head = candidates[i].clone();
            let c = head.k;
            let trained = match o.finals[c].as_mut() {
                None => return Ok(Next::Run(vec![Step::Final(c)])),
                Some(FinalTraining {
                    outcome: Err(e), ..
                }) => return Err(std::mem::replace(e, MsgpError::NonFinite(String::new()))),
                Some(trained) => &*trained,
            };
            let completed = trained.outcome.as_ref().ok().cloned().flatten();
            let Some((params, iteration)) = completed else {
                // blown up: the fallback heads, after the first candidate
                let failed = trained.report.full_data_failed.clone();
                self.finals_tried.push(c);
                if let Some(outcome) = self.outcome(c) {
                    outcome.final_failed = failed.clone();
                }
                if i == 0 {
                    self.full_data_failed = failed;
                    if c == 0 && !plan.fallbacks.is_empty() {
                        if let Some(run) = missing_heads(o, &plan.fallbacks) {
                            return Ok(Next::Run(run));
                        }
                        candidates.extend(self.judge_heads(plan, o, &plan.fallbacks, true)?);
                    }
                }
                i += 1;
                continue;
            };
            let proxy = match (plan.proxy_iterations, o.proxies[c].as_ref()) {
                (Some(_), None) => return Ok(Next::Run(vec![Step::Proxy(c)])),
                (_, proxy) => proxy,
            };
            self.finals_tried.push(c);
            let proxy_model = proxy.and_then(|p| p.outcome.as_ref().ok().cloned().flatten());
            let kept: Kept = (head, iteration, proxy_model);
            let why = judge.diverges(c, &params);
            let untried: Vec<Head> = raced
                .iter()
                .filter(|h| !candidates.iter().any(|t| t.k == h.k))
                .cloned()
                .collect();
            match why {
                Some(why) if !untried.is_empty() => {
                    if let Some(outcome) = self.outcome(c) {
                        outcome.diverged = Some(why);
                    }
                    set_aside.get_or_insert((Head { params, ..kept.0 }, kept.1, kept.2));
                    candidates.extend(untried);
                    i += 1;
                    continue;
                }
                // (the first set aside stands, below)
                Some(_) if set_aside.is_some() => {}
                _ => accepted = Some((Head { params, ..kept.0 }, kept.1, kept.2)),
            }
            break;
        }
        // where no final model was kept, the first set aside for diverging stands: it was
        // set aside for nothing
        if accepted.is_none() && set_aside.is_some() {
            self.recipes.iter_mut().for_each(|r| r.diverged = None);
            accepted = set_aside;
        }
        Ok(Next::Done(match accepted {
            Some(kept) => self.kept_final(o, kept),
            None => self.selection(first, None),
        }))
    }

    /// The selection of an accepted final model (its parameters in the head's place).
    fn kept_final(self, o: &Outcomes, (model, iteration, proxy): Kept) -> Selection {
        let k = model.k;
        let head = o.heads[k]
            .as_ref()
            .and_then(|h| h.trained.as_ref().ok())
            .map(|t| t.0.clone())
            .unwrap_or_else(|| model.params.clone());
        let final_training = FinalChoice { iteration, proxy };
        let mut selection = self.selection(model, Some(final_training));
        selection.head = head;
        selection.full_data_failed = None;
        selection
    }

    /// The selection of `chosen`'s model, with its final training where that is the model.
    fn selection(self, chosen: Head, final_training: Option<FinalChoice>) -> Selection {
        Selection {
            recipe: chosen.k,
            head: chosen.params.clone(),
            params: chosen.params,
            best_iteration: chosen.best_iteration,
            final_training,
            recipes: self.recipes,
            heads_run: self.heads_run,
            finals_tried: self.finals_tried,
            full_data_failed: self.full_data_failed,
        }
    }

    /// The report's outcome of recipe `k` (one per head trained, in the recipes' order; a
    /// recipe with a model has trained its head).
    fn outcome(&mut self, k: usize) -> Option<&mut RecipeOutcome> {
        let i = self.heads_run.iter().position(|&h| h == k)?;
        self.recipes.get_mut(i)
    }
}

/// What stands in a head's outcome once its error has been taken out.
fn placeholder() -> Trained {
    (
        GpParams::filled(crate::gp::GpShape { m: 0, d: 0, e: 0 }, 0.0),
        0,
        f64::NAN,
    )
}

#[cfg(test)]
mod tests {
    use super::super::outcomes::HeadRun;
    use super::*;
    use crate::fit::{FitReport, MsgpSettings};
    use crate::gp::GpShape;

    /// The default protocol's plan: two racing recipes, two fallback heads, a final training
    /// and its proxy.
    fn plan() -> Plan {
        let plan = Plan::new(&MsgpSettings::default(), true, false);
        assert_eq!((plan.racing, plan.fallbacks.clone()), (2, vec![2, 3]));
        assert!(plan.final_iterations.is_some() && plan.proxy_iterations.is_some());
        plan
    }

    /// Parameters told apart by `v`.
    fn params(v: f64) -> GpParams<f64> {
        GpParams::filled(GpShape { m: 1, d: 1, e: 1 }, v)
    }

    fn head(k: usize, validation: f64) -> HeadRun {
        HeadRun {
            trained: Ok((params(k as f64), 10 + k, validation)),
            report: FitReport::default(),
            start: Some(params(-(k as f64))),
        }
    }

    fn failed_head() -> HeadRun {
        HeadRun {
            trained: Err(MsgpError::NonFinite("at its start".into())),
            report: FitReport::default(),
            start: None,
        }
    }

    /// Recipe `k`'s completed final training (its model told apart from its head's).
    fn completed(k: usize) -> FinalTraining {
        FinalTraining {
            outcome: Ok(Some((params(100.0 + k as f64), 400))),
            report: FitReport::default(),
        }
    }

    fn blown_up() -> FinalTraining {
        FinalTraining {
            outcome: Ok(None),
            report: FitReport {
                full_data_failed: Some("blew up".into()),
                ..FitReport::default()
            },
        }
    }

    /// A judge for which the final models of the recipes in `diverging` diverge.
    struct Diverging(Vec<usize>);

    impl Judge for Diverging {
        fn diverges(&self, k: usize, params: &GpParams<f64>) -> Option<String> {
            let is_final = params.to_flat()[0] >= 100.0;
            (is_final && self.0.contains(&k)).then(|| format!("recipe {k} runs away"))
        }
    }

    fn run(plan: &Plan, o: &mut Outcomes, judge: &dyn Judge) -> Vec<Step> {
        match decide(plan, o, judge).expect("no failure") {
            Next::Run(steps) => steps,
            Next::Done(s) => panic!("done early: {s:?}"),
        }
    }

    fn done(plan: &Plan, o: &mut Outcomes, judge: &dyn Judge) -> Selection {
        match decide(plan, o, judge).expect("no failure") {
            Next::Done(s) => s,
            Next::Run(steps) => panic!("still needs {steps:?}"),
        }
    }

    /// Both heads, then the final training of the lower validation NLL (ties to the earlier
    /// recipe), then its proxy; the model is the final training's, the report names the head.
    #[test]
    fn the_tail_chooses_the_recipe_whose_final_training_is_the_model() {
        let plan = plan();
        let judge = Diverging(Vec::new());
        for (validations, chosen) in [([0.5, 0.4], 1), ([0.4, 0.5], 0), ([0.5, 0.5], 0)] {
            let mut o = Outcomes::new(&plan);
            assert_eq!(run(&plan, &mut o, &judge), [Step::Head(0), Step::Head(1)]);
            o.heads[0] = Some(head(0, validations[0]));
            assert_eq!(run(&plan, &mut o, &judge), [Step::Head(1)]);
            o.heads[1] = Some(head(1, validations[1]));
            assert_eq!(run(&plan, &mut o, &judge), [Step::Final(chosen)]);
            o.finals[chosen] = Some(completed(chosen));
            assert_eq!(run(&plan, &mut o, &judge), [Step::Proxy(chosen)]);
            o.proxies[chosen] = Some(completed(chosen));
            let s = done(&plan, &mut o, &judge);
            assert_eq!(s.recipe, chosen);
            assert_eq!(s.params, params(100.0 + chosen as f64));
            assert_eq!(s.head, params(chosen as f64));
            assert_eq!(s.best_iteration, 10 + chosen);
            assert_eq!(s.final_training.map(|f| f.iteration), Some(400));
            assert_eq!((s.heads_run, s.finals_tried), (vec![0, 1], vec![chosen]));
            assert_eq!(s.recipes[1].validation, Some(validations[1]));
        }
    }

    /// The first recipe's final training blows up: the fallback heads train, and the first
    /// in the tail's order whose final training completes is the model; where none does, the
    /// first head's model stands and the report says why.
    #[test]
    fn a_blown_up_final_training_falls_back_to_the_fallback_heads() {
        let plan = plan();
        let judge = Diverging(Vec::new());
        let mut o = Outcomes::new(&plan);
        o.heads[0] = Some(head(0, 0.4));
        o.heads[1] = Some(head(1, 0.5));
        o.finals[0] = Some(blown_up());
        assert_eq!(run(&plan, &mut o, &judge), [Step::Head(2), Step::Head(3)]);
        o.heads[2] = Some(head(2, 0.7));
        o.heads[3] = Some(head(3, 0.6));
        assert_eq!(run(&plan, &mut o, &judge), [Step::Final(3)]);
        o.finals[3] = Some(blown_up());
        assert_eq!(run(&plan, &mut o, &judge), [Step::Final(2)]);
        o.finals[2] = Some(completed(2));
        o.proxies[2] = Some(completed(2));
        let s = done(&plan, &mut o, &judge);
        assert_eq!((s.recipe, s.full_data_failed.clone()), (2, None));
        assert_eq!(s.finals_tried, [0, 3, 2]);
        assert!(s.recipes[2].fallback_head && s.recipes[3].fallback_head);
        assert_eq!(s.recipes[0].final_failed.as_deref(), Some("blew up"));
        // none completes: the first head stands
        o.finals[2] = Some(blown_up());
        let s = done(&plan, &mut o, &judge);
        assert_eq!((s.recipe, s.params.clone()), (0, params(0.0)));
        assert!(s.final_training.is_none());
        assert_eq!(s.full_data_failed.as_deref(), Some("blew up"));
        // the alternative chosen: its blow-up has no fallback heads
        let mut o = Outcomes::new(&plan);
        o.heads[0] = Some(head(0, 0.5));
        o.heads[1] = Some(head(1, 0.4));
        o.finals[1] = Some(blown_up());
        let s = done(&plan, &mut o, &judge);
        assert_eq!((s.recipe, s.heads_run), (1, vec![0, 1]));
    }

    /// A final model that diverges gives way to the racing head not yet tried; where that
    /// one diverges too, the first set aside stands and no recipe is marked as diverged.
    #[test]
    fn a_diverging_final_model_gives_way_to_the_next_head() {
        let plan = plan();
        let mut o = Outcomes::new(&plan);
        o.heads[0] = Some(head(0, 0.4));
        o.heads[1] = Some(head(1, 0.5));
        for k in [0, 1] {
            o.finals[k] = Some(completed(k));
            o.proxies[k] = Some(completed(k));
        }
        let s = done(&plan, &mut o, &Diverging(vec![0]));
        assert_eq!((s.recipe, s.finals_tried.clone()), (1, vec![0, 1]));
        assert_eq!(s.recipes[0].diverged.as_deref(), Some("recipe 0 runs away"));
        let s = done(&plan, &mut o, &Diverging(vec![0, 1]));
        assert_eq!((s.recipe, s.params.clone()), (0, params(100.0)));
        assert!(s.recipes.iter().all(|r| r.diverged.is_none()));
        // the next head's final training is needed only once the first diverged
        o.finals[1] = None;
        assert_eq!(run(&plan, &mut o, &Diverging(vec![0])), [Step::Final(1)]);
        assert_eq!(done(&plan, &mut o, &Diverging(Vec::new())).recipe, 0);
    }

    /// A head that fails numerically leaves the choice to the other; where both fail, the
    /// first failure is the fit's error; any other failure is the fit's error at once.
    #[test]
    fn a_failed_head_leaves_the_choice_to_the_other() {
        let plan = plan();
        let judge = Diverging(Vec::new());
        let mut o = Outcomes::new(&plan);
        o.heads[0] = Some(failed_head());
        o.heads[1] = Some(head(1, 0.9));
        assert_eq!(run(&plan, &mut o, &judge), [Step::Final(1)]);
        o.heads[1] = Some(failed_head());
        let e = decide(&plan, &mut o, &judge).expect_err("both failed");
        assert!(
            matches!(e, MsgpError::NonFinite(ref why) if why == "at its start"),
            "{e}"
        );
        let mut o = Outcomes::new(&plan);
        o.heads[0] = Some(head(0, 0.4));
        o.heads[1] = Some(HeadRun {
            trained: Err(MsgpError::Stopped { iteration: 3 }),
            ..failed_head()
        });
        let e = decide(&plan, &mut o, &judge).expect_err("stopped");
        assert!(matches!(e, MsgpError::Stopped { iteration: 3 }), "{e}");
    }

    /// While a racing head trains, the final training of the one that leads (an ended head
    /// by its validation NLL, a running one by its running best, ties to the earlier
    /// recipe, failed heads out); beside a needed final training, its proxy.
    #[test]
    fn the_likely_steps_follow_the_leading_head() {
        let plan = plan();
        let mut o = Outcomes::new(&plan);
        let racing = [Step::Head(0), Step::Head(1)];
        assert_eq!(likely(&plan, &o, &[None; 4], &racing), [Step::Final(0)]);
        o.heads[0] = Some(head(0, 0.5));
        let second = [Step::Head(1)];
        assert_eq!(likely(&plan, &o, &[None; 4], &second), [Step::Final(0)]);
        let running = |v: f64| [Some(0.5), Some(v), None, None];
        assert_eq!(likely(&plan, &o, &running(0.5), &second), [Step::Final(0)]);
        assert_eq!(likely(&plan, &o, &running(0.4), &second), [Step::Final(1)]);
        o.heads[0] = Some(failed_head());
        assert_eq!(likely(&plan, &o, &[None; 4], &second), [Step::Final(1)]);
        // the second ended first: the first leads once its running best is at or below
        let mut o = Outcomes::new(&plan);
        o.heads[1] = Some(head(1, 0.4));
        let first = [Step::Head(0)];
        let running = |v: f64| [Some(v), Some(0.4), None, None];
        assert_eq!(likely(&plan, &o, &running(0.6), &first), [Step::Final(1)]);
        assert_eq!(likely(&plan, &o, &running(0.4), &first), [Step::Final(0)]);
        // a final training under way needs no speculation, its proxy does (once its head
        // has a start)
        o.heads[0] = Some(head(0, 0.5));
        let proxy = likely(&plan, &o, &[None; 4], &[Step::Final(1)]);
        assert_eq!(proxy, [Step::Proxy(1)]);
        o.proxies[1] = Some(completed(1));
        assert!(likely(&plan, &o, &[None; 4], &[Step::Final(1)]).is_empty());
    }

    /// A head at its early stop can be chosen unless another racing head's running best is
    /// already below it (or equal, for a later recipe); fallback heads always can.
    #[test]
    fn a_head_behind_the_others_cannot_be_chosen() {
        let plan = plan();
        let running = [Some(0.5), Some(0.4), None, None];
        assert!(!can_be_chosen(&plan, &running, 0, 0.45));
        assert!(can_be_chosen(&plan, &running, 0, 0.4));
        assert!(can_be_chosen(&plan, &running, 1, 0.45));
        assert!(!can_be_chosen(&plan, &running, 1, 0.5));
        assert!(can_be_chosen(&plan, &[None; 4], 1, 9.0));
        assert!(can_be_chosen(&plan, &running, 2, 9.0));
    }
}
