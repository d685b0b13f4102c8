//! The divergence check run after every fit: the fitted model's free (moment-matching)
//! simulation over its own training inputs, compared with the training outputs.
//!
//! A model whose free simulation leaves the range its training outputs span by several times
//! that range, or whose predicted standard deviation grows beyond it, or whose simulation fails
//! numerically, has not learned a usable long-horizon model even of the data it saw; the fit
//! still returns it (it may be wanted for inspection), but says so in
//! [`FitReport::diverged`](super::FitReport::diverged), which the front ends print as a warning
//! and store in the model file. Only feed-forward training trajectories are simulated: a
//! feedback episode's open-loop replay of an unstable plant may rightly run away.
//!
//! The same test, held against the measured outputs of other data ([`OutputRange`]), tells
//! `msgp eval` and `msgp simulate` that a model runs away on data it was not trained on (a model
//! can stay in range on its training inputs and leave it on a test part's).

use crate::data::Trajectory;
use crate::model::{Model, Simulation};

/// How far outside the training outputs' range (in multiples of that range) a simulated mean,
/// or how large a simulated standard deviation, counts as divergence.
pub const DIVERGENCE_RANGES: f64 = 5.0;

/// Why `model`'s free simulation over the training trajectories `train` (original units)
/// diverges, or `None` when it stays within [`DIVERGENCE_RANGES`] of the training outputs.
pub fn check_divergence(model: &Model, train: &[&Trajectory]) -> Option<String> {
    let range = OutputRange::of(train, model.spec.dy);
    for (k, t) in train.iter().enumerate() {
        let what = format!("training trajectory {k}");
        let why = match model.simulate(t) {
            Ok(sim) => range.divergence(&sim, &what),
            Err(e) => Some(format!("the free simulation of {what} fails: {e}")),
        };
        if why.is_some() {
            return why;
        }
    }
    None
}

/// The span of measured outputs a free simulation is held against, per output.
#[derive(Clone, Debug, PartialEq)]
pub struct OutputRange {
    lo: Vec<f64>,
    hi: Vec<f64>,
}

impl OutputRange {
    /// The smallest and largest value of each of the `dy` outputs over `trajs`.
    pub fn of(trajs: &[&Trajectory], dy: usize) -> Self {
        let mut lo = vec![f64::INFINITY; dy];
        let mut hi = vec![f64::NEG_INFINITY; dy];
        for t in trajs {
            for j in 0..dy.min(t.y.ncols()) {
                for &y in t.y.column(j).iter() {
                    lo[j] = lo[j].min(y);
                    hi[j] = hi[j].max(y);
                }
            }
        }
        Self { lo, hi }
    }

    /// Why the free simulation `sim` (of `what`, for messages) diverges against this range: a
    /// mean or variance that is not finite, a mean more than [`DIVERGENCE_RANGES`] widths
    /// outside it, or a predicted standard deviation larger than that many widths; `None` when
    /// none of these happens (or no output was measured).
    pub fn divergence(&self, sim: &Simulation, what: &str) -> Option<String> {
        let (lo, hi) = (&self.lo, &self.hi);
        for j in 0..lo.len().min(sim.mean.ncols()) {
            if !(lo[j].is_finite() && hi[j].is_finite()) {
                continue;
            }
            let range = (hi[j] - lo[j]).max(1e-12 * hi[j].abs().max(lo[j].abs()).max(1.0));
            let (low, high) = (
                lo[j] - DIVERGENCE_RANGES * range,
                hi[j] + DIVERGENCE_RANGES * range,
            );
            for i in 0..sim.mean.nrows() {
                let (m, v) = (sim.mean[(i, j)], sim.var[(i, j)]);
                let step = sim.start + i;
                if !(m.is_finite() && v.is_finite()) {
                    return Some(format!(
                        "the free simulation of {what} is not finite at step {step} (output {j})"
                    ));
                }
                if m < low || m > high {
                    return Some(format!(
                        "the free simulation of {what} leaves the measured outputs' range \
                         [{:.4e}, {:.4e}] by more than {DIVERGENCE_RANGES} times its width: \
                         output {j} reaches {m:.4e} at step {step}",
                        lo[j], hi[j]
                    ));
                }
                if v.sqrt() > DIVERGENCE_RANGES * range {
                    return Some(format!(
                        "the free simulation of {what} has a predicted standard deviation of \
                         {:.4e} for output {j} at step {step}, more than {DIVERGENCE_RANGES} \
                         times the measured outputs' range ({range:.4e})",
                        v.sqrt()
                    ));
                }
            }
        }
        None
    }
}
