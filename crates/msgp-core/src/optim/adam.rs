//! Adam (Kingma & Ba 2015): the paper's optimiser for the MSGP loss, and the policy search's.

use serde::{Deserialize, Serialize};

use super::{Flow, Objective};
use crate::error::Result;

/// Adam (Kingma & Ba) settings.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Adam {
    /// Step size.
    pub learning_rate: f64,
    /// First-moment decay.
    pub beta1: f64,
    /// Second-moment decay.
    pub beta2: f64,
    /// Denominator guard.
    pub epsilon: f64,
}

impl Default for Adam {
    fn default() -> Self {
        Self {
            learning_rate: 1e-2,
            beta1: 0.9,
            beta2: 0.999,
            epsilon: 1e-8,
        }
    }
}

/// Adam's running state.
#[derive(Clone, Debug)]
pub struct AdamState {
    m: Vec<f64>,
    v: Vec<f64>,
    t: i32,
}

impl AdamState {
    /// Fresh state for `n` parameters.
    pub fn new(n: usize) -> Self {
        Self {
            m: vec![0.0; n],
            v: vec![0.0; n],
            t: 0,
        }
    }
}

impl Adam {
    /// One step on the coordinates where `active[i]` is true.
    pub fn step(&self, state: &mut AdamState, x: &mut [f64], grad: &[f64], active: &[bool]) {
        state.t += 1;
        let b1t = 1.0 - self.beta1.powi(state.t);
        let b2t = 1.0 - self.beta2.powi(state.t);
        for i in 0..x.len() {
            if !active[i] || !grad[i].is_finite() {
                continue;
            }
            state.m[i] = self.beta1 * state.m[i] + (1.0 - self.beta1) * grad[i];
            state.v[i] = self.beta2 * state.v[i] + (1.0 - self.beta2) * grad[i] * grad[i];
            let mh = state.m[i] / b1t;
            let vh = state.v[i] / b2t;
            x[i] -= self.learning_rate * mh / (vh.sqrt() + self.epsilon);
        }
    }
}

pub(super) fn minimize_adam(
    objective: &mut dyn Objective,
    adam: &Adam,
    x0: Vec<f64>,
    active: &[bool],
    iterations: usize,
    mut observe: impl FnMut(usize, f64, &[f64]) -> Result<Flow>,
) -> Result<(Vec<f64>, f64)> {
    let mut x = x0;
    let mut state = AdamState::new(x.len());
    let mut last = f64::NAN;
    for it in 0..iterations {
        let (v, g) = objective.value_and_gradient(&x)?;
        last = v;
        if observe(it, v, &x)? == Flow::Stop {
            return Ok((x, v));
        }
        adam.step(&mut state, &mut x, &g, active);
    }
    Ok((x, last))
}
