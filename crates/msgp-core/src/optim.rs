//! Gradient-based optimisation with a problem/solver split (in the spirit of argmin): an
//! [`Objective`] knows how to evaluate value and gradient; [`Adam`] knows how to step.

use serde::{Deserialize, Serialize};

use crate::error::Result;

/// A differentiable objective to minimise.
pub trait Objective {
    /// Value and gradient at `x`.
    fn value_and_gradient(&mut self, x: &[f64]) -> Result<(f64, Vec<f64>)>;
}

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

/// What an iteration callback tells the solver.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Flow {
    /// Keep going.
    Continue,
    /// Stop now.
    Stop,
}

/// Runs Adam for up to `iterations` steps; `observe(iteration, value, x)` runs before each step.
/// Returns the final point and the last value.
pub fn minimize(
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

#[cfg(test)]
mod tests {
    use super::*;

    struct Quadratic;
    impl Objective for Quadratic {
        fn value_and_gradient(&mut self, x: &[f64]) -> Result<(f64, Vec<f64>)> {
            let v = (x[0] - 3.0).powi(2) + 10.0 * (x[1] + 1.0).powi(2);
            Ok((v, vec![2.0 * (x[0] - 3.0), 20.0 * (x[1] + 1.0)]))
        }
    }

    #[test]
    fn adam_minimises_a_quadratic_and_respects_frozen_coordinates() {
        let adam = Adam {
            learning_rate: 0.05,
            ..Adam::default()
        };
        let (x, v) = minimize(
            &mut Quadratic,
            &adam,
            vec![0.0, 0.0],
            &[true, true],
            3000,
            |_, _, _| Ok(Flow::Continue),
        )
        .expect("runs");
        assert!(
            (x[0] - 3.0).abs() < 1e-3 && (x[1] + 1.0).abs() < 1e-3,
            "{x:?} {v}"
        );
        let (x, _) = minimize(
            &mut Quadratic,
            &adam,
            vec![0.0, 0.0],
            &[true, false],
            3000,
            |_, _, _| Ok(Flow::Continue),
        )
        .expect("runs");
        assert_eq!(x[1], 0.0);
    }
}
