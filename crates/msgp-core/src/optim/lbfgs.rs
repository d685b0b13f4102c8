//! L-BFGS with a backtracking Armijo line search that treats points where the objective cannot
//! be evaluated as "too far".

use serde::{Deserialize, Serialize};

use super::{Flow, Objective};
use crate::error::Result;

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

fn dot(a: &[f64], b: &[f64]) -> f64 {
    a.iter().zip(b).map(|(x, y)| x * y).sum()
}

pub(super) fn minimize_lbfgs(
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
