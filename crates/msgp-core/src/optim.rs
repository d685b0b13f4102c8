//! Gradient-based optimisation with a problem/solver split (in the spirit of argmin): an
//! [`Objective`] knows how to evaluate value and gradient; [`Adam`] and [`Lbfgs`] know how to
//! step.
//!
//! L-BFGS is written here rather than taken from argmin because the MSGP objective has regions
//! where it cannot be evaluated (a predictive covariance that is not positive definite: the value
//! comes back NaN), and the line search must treat them as "too far" and shrink the step; argmin's
//! line searches stop with an error there.

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

/// Limited-memory BFGS (Nocedal & Wright, algorithm 7.4) with a backtracking Armijo line
/// search. A trial point whose value is NaN or infinite (the objective could not be evaluated
/// there) counts as a failed Armijo test. A curvature pair with `sᵀy ≤ 0` is skipped, so the
/// inverse-Hessian approximation stays positive definite.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Lbfgs {
    /// Curvature pairs kept.
    pub memory: usize,
    /// Largest change of any coordinate in one step (a trust cap in parameter units).
    pub max_step: f64,
    /// The first step (and any step after a restart), without curvature information, moves the
    /// largest-gradient coordinate by this much.
    pub first_step: f64,
    /// Armijo constant.
    pub c1: f64,
    /// Step halvings before the line search gives up (the run then ends at the last point).
    pub max_backtracks: usize,
    /// Converged when the value decreased by less than `tolerance · max(|f|, 1)` over
    /// `patience` consecutive iterations.
    pub tolerance: f64,
    /// See `tolerance`.
    pub patience: usize,
}

impl Default for Lbfgs {
    fn default() -> Self {
        Self {
            memory: 10,
            max_step: 1.0,
            first_step: 0.1,
            c1: 1e-4,
            max_backtracks: 30,
            tolerance: 1e-7,
            patience: 5,
        }
    }
}

/// Which solver [`minimize`] runs.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub enum Solver {
    /// Adam with the given settings: one evaluation per iteration, runs all its iterations.
    Adam(Adam),
    /// L-BFGS: usually one evaluation per iteration (more when the line search backtracks);
    /// stops early when converged or when no step along its direction decreases the value.
    Lbfgs(Lbfgs),
}

/// What an iteration callback tells the solver.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Flow {
    /// Keep going.
    Continue,
    /// Stop now.
    Stop,
}

/// Runs `solver` for up to `iterations` steps on the coordinates where `active[i]` is true;
/// `observe(iteration, value, x)` runs at every accepted point, before the step from it (a NaN
/// value at the start point is passed on for the caller to stop). Returns the final point and its
/// value.
pub fn minimize(
    objective: &mut dyn Objective,
    solver: &Solver,
    x0: Vec<f64>,
    active: &[bool],
    iterations: usize,
    observe: impl FnMut(usize, f64, &[f64]) -> Result<Flow>,
) -> Result<(Vec<f64>, f64)> {
    match solver {
        Solver::Adam(adam) => minimize_adam(objective, adam, x0, active, iterations, observe),
        Solver::Lbfgs(lbfgs) => minimize_lbfgs(objective, lbfgs, x0, active, iterations, observe),
    }
}

fn minimize_adam(
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

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

fn minimize_lbfgs(
    objective: &mut dyn Objective,
    lbfgs: &Lbfgs,
    x0: Vec<f64>,
    active: &[bool],
    iterations: usize,
    mut observe: impl FnMut(usize, f64, &[f64]) -> Result<Flow>,
) -> Result<(Vec<f64>, f64)> {
    // the gradient seen by the solver: zero on frozen coordinates and where it is not finite
    let masked = |g: Vec<f64>| -> Vec<f64> {
        g.into_iter()
            .zip(active)
            .map(|(gi, &a)| if a && gi.is_finite() { gi } else { 0.0 })
            .collect()
    };
    let mut x = x0;
    let (mut f, g) = objective.value_and_gradient(&x)?;
    let mut g = masked(g);
    let mut pairs: std::collections::VecDeque<(Vec<f64>, Vec<f64>, f64)> =
        std::collections::VecDeque::with_capacity(lbfgs.memory);
    let mut flat = 0usize;
    for it in 0..iterations {
        if observe(it, f, &x)? == Flow::Stop || !f.is_finite() {
            return Ok((x, f));
        }
        if it + 1 == iterations {
            break;
        }
        // two-loop recursion: d = −H g
        let mut q = g.clone();
        let mut alphas = Vec::with_capacity(pairs.len());
        for (s, y, rho) in pairs.iter().rev() {
            let a = rho * dot(s, &q);
            q.iter_mut().zip(y).for_each(|(qi, yi)| *qi -= a * yi);
            alphas.push(a);
        }
        let gamma = pairs.back().map_or(1.0, |(s, y, _)| dot(s, y) / dot(y, y));
        q.iter_mut().for_each(|qi| *qi *= gamma);
        for ((s, y, rho), a) in pairs.iter().zip(alphas.iter().rev()) {
            let b = rho * dot(y, &q);
            q.iter_mut().zip(s).for_each(|(qi, si)| *qi += (a - b) * si);
        }
        let mut d: Vec<f64> = q.into_iter().map(|v| -v).collect();
        let mut slope = dot(&g, &d);
        if slope.is_nan() || slope >= 0.0 {
            // not a descent direction (rounding in the memory): restart from steepest descent
            pairs.clear();
            d = g.iter().map(|v| -v).collect();
            slope = dot(&g, &d);
        }
        // after a restart the slope is −|g|², negative unless the gradient vanishes
        let dmax = d.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        if dmax == 0.0 {
            return Ok((x, f)); // stationary on the active coordinates
        }
        let mut step = if pairs.is_empty() {
            lbfgs.first_step.min(lbfgs.max_step) / dmax
        } else {
            (lbfgs.max_step / dmax).min(1.0)
        };
        let mut accepted = None;
        for _ in 0..=lbfgs.max_backtracks {
            let trial: Vec<f64> = x.iter().zip(&d).map(|(xi, di)| xi + step * di).collect();
            let (ft, gt) = objective.value_and_gradient(&trial)?;
            if ft.is_finite() && ft <= f + lbfgs.c1 * step * slope {
                accepted = Some((trial, ft, masked(gt)));
                break;
            }
            step *= 0.5;
        }
        let Some((xn, fn_, gn)) = accepted else {
            // no decrease along the direction: the last accepted point is the answer
            return Ok((x, f));
        };
        let s: Vec<f64> = xn.iter().zip(&x).map(|(a, b)| a - b).collect();
        let y: Vec<f64> = gn.iter().zip(&g).map(|(a, b)| a - b).collect();
        let sy = dot(&s, &y);
        // keep only pairs with positive curvature, so H stays positive definite
        if sy > 1e-12 * dot(&y, &y).sqrt() * dot(&s, &s).sqrt() {
            if pairs.len() == lbfgs.memory.max(1) {
                pairs.pop_front();
            }
            pairs.push_back((s, y, 1.0 / sy));
        }
        if f - fn_ <= lbfgs.tolerance * f.abs().max(1.0) {
            flat += 1;
        } else {
            flat = 0;
        }
        x = xn;
        f = fn_;
        g = gn;
        if flat >= lbfgs.patience.max(1) {
            observe(it + 1, f, &x)?;
            return Ok((x, f));
        }
    }
    Ok((x, f))
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
        let adam = Solver::Adam(adam);
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

    /// Rosenbrock's valley, counting evaluations; NaN where `x₀ > wall`.
    struct Rosenbrock {
        evaluations: usize,
        failed: usize,
        wall: f64,
    }
    impl Objective for Rosenbrock {
        fn value_and_gradient(&mut self, x: &[f64]) -> Result<(f64, Vec<f64>)> {
            self.evaluations += 1;
            if x[0] > self.wall {
                self.failed += 1;
                return Ok((f64::NAN, vec![0.0; x.len()]));
            }
            let (a, b) = (1.0 - x[0], x[1] - x[0] * x[0]);
            let mut g = vec![-2.0 * a - 400.0 * x[0] * b, 200.0 * b];
            let mut v = a * a + 100.0 * b * b;
            // a third, separable coordinate to freeze
            if x.len() == 3 {
                v += (x[2] - 5.0).powi(2);
                g.push(2.0 * (x[2] - 5.0));
            }
            Ok((v, g))
        }
    }

    /// What [`lbfgs_on_rosenbrock`] saw.
    struct Run {
        x: Vec<f64>,
        value: f64,
        /// Accepted `(iteration, value)` pairs, in the order the callback saw them.
        seen: Vec<(usize, f64)>,
        evaluations: usize,
        /// Evaluations beyond the wall (NaN).
        failed: usize,
    }

    /// L-BFGS (default settings, up to 500 iterations) on Rosenbrock's valley with a NaN wall.
    fn lbfgs_on_rosenbrock(x0: Vec<f64>, active: &[bool], wall: f64) -> Run {
        let mut problem = Rosenbrock {
            evaluations: 0,
            failed: 0,
            wall,
        };
        let mut seen = Vec::new();
        let (x, v) = minimize(
            &mut problem,
            &Solver::Lbfgs(Lbfgs::default()),
            x0,
            active,
            500,
            |it, v, _| {
                seen.push((it, v));
                Ok(Flow::Continue)
            },
        )
        .expect("runs");
        Run {
            x,
            value: v,
            seen,
            evaluations: problem.evaluations,
            failed: problem.failed,
        }
    }

    #[test]
    fn lbfgs_solves_rosenbrock_in_few_evaluations() {
        let Run {
            x,
            value: v,
            seen,
            evaluations,
            ..
        } = lbfgs_on_rosenbrock(vec![-1.2, 1.0], &[true, true], f64::INFINITY);
        assert!(
            (x[0] - 1.0).abs() < 1e-5 && (x[1] - 1.0).abs() < 1e-5,
            "{x:?} {v}"
        );
        assert!(evaluations < 150, "{evaluations} evaluations");
        // every accepted point decreased the value, and the callback saw them in order
        assert!(
            seen.windows(2)
                .all(|w| w[1].1 < w[0].1 && w[1].0 == w[0].0 + 1)
        );
        assert!(
            seen.len() < 120,
            "converged early: {} iterations",
            seen.len()
        );
    }

    #[test]
    fn lbfgs_keeps_frozen_coordinates_and_backs_off_where_the_objective_fails() {
        // frozen third coordinate
        let x = lbfgs_on_rosenbrock(vec![-1.2, 1.0, 0.5], &[true, true, false], f64::INFINITY).x;
        assert_eq!(x[2], 0.5);
        assert!((x[0] - 1.0).abs() < 1e-5, "{x:?}");
        // the objective is NaN beyond x₀ = 0.5: the solver never accepts a point there and ends
        // on the wall, at the constrained minimum's neighbourhood
        let Run {
            x,
            value: v,
            seen,
            failed,
            ..
        } = lbfgs_on_rosenbrock(vec![-1.2, 1.0], &[true, true], 0.5);
        assert!(failed > 0, "the line search never tried beyond the wall");
        assert!(seen.iter().all(|s| s.1.is_finite()));
        assert!(x[0] <= 0.5 && x[0] > 0.45, "{x:?}");
        // the constrained minimum is (0.5, 0.25) with value 0.25; an unconstrained method stalls
        // against the wall near it (from the start, the value was 24.2)
        assert!(v < 0.26, "{v} at {x:?}");
    }
}
