//! The choice's [`Judge`] of models, as a fit runs it: the divergence check over the
//! feed-forward training trajectories, computed once per model (the choice is read again
//! after every step).

use std::cell::RefCell;

use super::super::divergence::check_divergence;
use super::plan::Plan;
use super::selection::Judge;
use crate::data::{Normalizer, Trajectory};
use crate::gp::GpParams;
use crate::model::{Method, Model};
use crate::narx::NarxSpec;

/// A model's key: its recipe and its parameters' bits.
type Key = (usize, Vec<u64>);

/// The fit's judge of its recipes' models.
pub(super) struct Checks<'a> {
    pub plan: &'a Plan,
    pub spec: NarxSpec,
    pub normalizer: &'a Normalizer,
    /// The feed-forward training trajectories (normalised).
    pub open_loop: Vec<&'a Trajectory>,
    diverged: RefCell<Vec<(Key, Option<String>)>>,
}

impl<'a> Checks<'a> {
    /// The judge of `plan`'s models over `open_loop`.
    pub fn new(
        plan: &'a Plan,
        spec: NarxSpec,
        normalizer: &'a Normalizer,
        open_loop: Vec<&'a Trajectory>,
    ) -> Self {
        Self {
            plan,
            spec,
            normalizer,
            open_loop,
            diverged: RefCell::new(Vec::new()),
        }
    }

    /// Recipe `k`'s model with `params`.
    pub fn model(&self, k: usize, params: &GpParams<f64>) -> Model {
        Model {
            method: Method::Msgp,
            spec: self.spec,
            params: params.clone(),
            config: self.plan.config(k),
            normalizer: self.normalizer.clone(),
            calibration: Vec::new(),
        }
    }
}

fn key(k: usize, params: &GpParams<f64>) -> Key {
    (k, params.to_flat().iter().map(|x| x.to_bits()).collect())
}

impl Judge for Checks<'_> {
    fn diverges(&self, k: usize, params: &GpParams<f64>) -> Option<String> {
        let key = key(k, params);
        if let Some((_, why)) = self.diverged.borrow().iter().find(|(c, _)| *c == key) {
            return why.clone();
        }
        let why = check_divergence(&self.model(k, params), &self.open_loop);
        self.diverged.borrow_mut().push((key, why.clone()));
        why
    }
}
