//! Gradient-based optimisation with a problem/solver split (in the spirit of argmin): an
//! [`Objective`] knows how to evaluate value and gradient; [`Adam`] and [`Lbfgs`] know how to
//! step.
//!
//! L-BFGS is written here rather than taken from argmin because the MSGP objective has regions
//! where it cannot be evaluated (a predictive covariance that is not positive definite: the value
//! comes back NaN), and the line search must treat them as "too far" and shrink the step; argmin's
//! line searches stop with an error there.
//!
//! Modules: [`adam`], [`lbfgs`]; the loop that runs either under an observer is [`minimize`].

pub mod adam;
pub mod lbfgs;

use serde::{Deserialize, Serialize};

pub use adam::{Adam, AdamState};
pub use lbfgs::Lbfgs;

use crate::error::Result;

/// A differentiable objective to minimise.
pub trait Objective {
    /// Value and gradient at `x`.
    fn value_and_gradient(&mut self, x: &[f64]) -> Result<(f64, Vec<f64>)>;
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
        Solver::Adam(adam) => adam::minimize_adam(objective, adam, x0, active, iterations, observe),
        Solver::Lbfgs(lbfgs) => {
            lbfgs::minimize_lbfgs(objective, lbfgs, x0, active, iterations, observe)
        }
    }
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
