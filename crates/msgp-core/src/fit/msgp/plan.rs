//! The MSGP fit protocol as data: the recipes it may train, in the order the choice prefers
//! them on a tie, and the steps that train them ([`Step`]). Which steps run, and which model
//! they end in, is [`super::selection`]'s; where and when they run is [`super::schedule`]'s.

use super::super::{FitOptimizer, MsgpSettings, MsgpStart};
use crate::gp::{GpConfig, MeanFunction};

/// One training of the protocol.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Step {
    /// Recipe `k` on the heads of the training data, early-stopped on their tails (or from the
    /// previous model, on all the data, without a tail).
    Head(usize),
    /// Recipe `k` again, from its start on all the training data, for a fixed length.
    Final(usize),
    /// The proxy of recipe `k`'s final training ([`super::super::calibration`]): from the
    /// start of its head, on the heads alone, for the same length.
    Proxy(usize),
    /// Where recipe `k`'s head model stands without a final training: its own training
    /// cross-validated inside the heads, the calibration's judge.
    InnerHead(usize),
}

/// What the protocol needs next.
#[derive(Debug)]
pub(super) enum Next<T> {
    /// These steps' outcomes (in any order, side by side or in turn).
    Run(Vec<Step>),
    /// Its end.
    Done(T),
}

/// The recipes and the lengths of the protocol's trainings.
#[derive(Debug)]
pub(super) struct Plan {
    /// The settings' own recipe first; then its alternative, where a validation tail can
    /// judge between them; then the own recipe's fallback heads, where it has them.
    pub recipes: Vec<MsgpSettings>,
    /// How many of `recipes` train their heads first and are chosen among by the tail.
    pub racing: usize,
    /// The recipes (indices) that train only where the first recipe's final training fails:
    /// the own zero-mean recipe from the spread start, and with a linear mean
    /// ([`MsgpSettings::blow_up_fallback`]).
    pub fallbacks: Vec<usize>,
    /// The length of the final training on all the data, where there is one: Adam fits with a
    /// tail and no previous model (L-BFGS would run to the training optimum, which early
    /// stopping avoids).
    pub final_iterations: Option<usize>,
    /// The length of the final training's proxy, where one is needed (the calibration, or the
    /// choice of the final training's length).
    pub proxy_iterations: Option<usize>,
}

impl Plan {
    /// The plan of `msgp`'s fit, with or without a validation tail and a previous model.
    pub fn new(msgp: &MsgpSettings, has_tails: bool, continues: bool) -> Self {
        let mut recipes = vec![msgp.clone()];
        if let (Some(r), true, false) = (msgp.alternative, has_tails, continues) {
            recipes.push(msgp.with_recipe(r));
        }
        let racing = recipes.len();
        let final_iterations = match (has_tails, continues, msgp.optimizer) {
            (true, false, FitOptimizer::Adam) => msgp.full_data_iterations,
            _ => None,
        };
        let mut fallbacks = Vec::new();
        if msgp.blow_up_fallback
            && msgp.mean == MeanFunction::Zero
            && msgp.start == MsgpStart::OneStep
            && final_iterations.is_some()
        {
            for fallback in [
                MsgpSettings {
                    start: MsgpStart::Spread,
                    alternative: None,
                    ..msgp.clone()
                },
                MsgpSettings {
                    mean: MeanFunction::Linear,
                    alternative: None,
                    ..msgp.clone()
                },
            ] {
                fallbacks.push(recipes.len());
                recipes.push(fallback);
            }
        }
        let proxy_iterations = final_iterations.filter(|_| msgp.calibrate);
        Self {
            recipes,
            racing,
            fallbacks,
            final_iterations,
            proxy_iterations,
        }
    }

    /// The GP configuration of recipe `k`'s models.
    pub fn config(&self, k: usize) -> GpConfig {
        let recipe = &self.recipes[k];
        GpConfig {
            noise_floor: recipe.noise_floor,
            mean: recipe.mean,
            start: recipe.start_window,
            ..GpConfig::default()
        }
    }

    /// The stage number a step's progress reports: 1 the first head, 2 a final training,
    /// 3 the other heads, 4 a proxy.
    pub fn stage(&self, step: Step) -> u8 {
        match step {
            Step::Head(0) => 1,
            Step::Head(_) => 3,
            Step::Final(_) => 2,
            Step::Proxy(_) | Step::InnerHead(_) => 4,
        }
    }

    /// Whether the observer sees `step` where trainings run side by side: the line of
    /// trainings the model comes from (the first head, the final trainings, the first fallback
    /// head and the calibration's own judge), not the heads racing them or the proxies.
    pub fn main_line(&self, step: Step) -> bool {
        match step {
            Step::Head(k) => k == 0 || self.fallbacks.first() == Some(&k),
            Step::Final(_) | Step::InnerHead(_) => true,
            Step::Proxy(_) => false,
        }
    }
}
