//! Output-variance calibration: how much variance a model's free simulation must add to each
//! output to be honest on data it was not trained on.
//!
//! The protocol's model is trained on all the training data for a fixed number of steps
//! ([`super::MsgpSettings::full_data_iterations`]), and the trajectory likelihood of data it
//! has seen keeps shrinking its predicted variance after the mean stops improving: on the test
//! parts of Table 1 its 2σ band held 46 % (furnace) to 81 % (synthetic 4) of the outputs
//! (`docs/design.md`). Nothing it was trained on can say by how much it is overconfident, so
//! the procedure that made it is cross-validated instead: the same recipe, from its start on
//! the head, trained the same number of steps on the head alone (the *proxy*), simulates the
//! validation tail it never saw, and the variance `δ_j ≥ 0` added to every simulated output
//! variance of output `j` that minimises the tail's NLL is the model's calibration
//! ([`crate::model::Model::calibration`]). Where the final training did not replace the head's
//! model (it blew up), the procedure that made the head's model is cross-validated the same way:
//! the chosen recipe trains on the head's first 80 % with early stopping on the head's last
//! 20 %, and simulates the tail ([`Judge::HeadProxy`]). The calibration moves no predicted
//! mean (it is added to the simulated outputs, not fed back), so every RMSE stays as it was.
//! The tail is simulated as a model's free simulation is reported, with the correlated function
//! uncertainty ([`crate::rollout::function_uncertainty`]): the calibration adds what that
//! still misses.
//!
//! `δ_j` is the best of a grid ([`GRID_PER_DECADE`] points per decade over
//! [`SMALLEST`]`..=`[`LARGEST`], and 0), in normalised units (multiples of the training
//! outputs' variance); [`LARGEST`] keeps the added standard deviation below
//! [`super::DIVERGENCE_RANGES`] ranges of any training output.

use serde::{Deserialize, Serialize};

use crate::data::Trajectory;
use crate::error::{MsgpError, Result};
use crate::gp::PreparedGp;
use crate::narx::NarxSpec;
use crate::numeric::linalg::JitterLog;
use crate::rollout::{Episode, Excitation, simulate_correlated};

/// The calibration a fit made ([`super::FitReport::calibration`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct CalibrationReport {
    /// Per output, the standard deviation of the added variance (original units).
    pub added_std: Vec<f64>,
    /// The model whose free simulation of the validation tail decided it.
    pub judge: Judge,
}

/// Which model's simulation of the validation tail decided the calibration.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Judge {
    /// The proxy of the final training (the chosen recipe trained on the head alone for the
    /// final training's iterations); `iteration`: its iterate of lowest training loss.
    Proxy {
        /// The proxy's iterate that judged.
        iteration: usize,
    },
    /// Where the final training did not replace the head's model: the head's own training,
    /// cross-validated — the chosen recipe trained on the head's first part with early stopping
    /// on the head's last part (split as the fit splits its data); `iteration`: the iterate it
    /// kept.
    HeadProxy {
        /// The iterate the head's proxy kept.
        iteration: usize,
    },
    /// The head's model on the tail it was early-stopped on, where no proxy could be trained
    /// (the final training's proxy blew up, or the head is too short to split again): a weak
    /// judge, which finds the model about as honest as that tail did.
    Head,
}

/// Grid points per decade of the added variance.
pub const GRID_PER_DECADE: usize = 20;
/// The smallest non-zero added variance tried (normalised units).
pub const SMALLEST: f64 = 1e-6;
/// The largest added variance tried (normalised units: ten times the training outputs'
/// variance, a standard deviation of 3.2 of theirs — less than two ranges of any output).
pub const LARGEST: f64 = 10.0;

/// The added variance per output (normalised units) that minimises the NLL of the free
/// simulations of the feed-forward `tails` (normalised units) by `gp`.
pub(super) fn tail_calibration(
    gp: &PreparedGp<f64>,
    spec: &NarxSpec,
    tails: &[Episode],
) -> Result<Vec<f64>> {
    let mut pairs: Vec<Vec<(f64, f64)>> = vec![Vec::new(); spec.dy];
    for tail in tails {
        if !matches!(tail.excitation, Excitation::FeedForward) {
            return Err(MsgpError::Shape(
                "a validation tail is a feed-forward episode".into(),
            ));
        }
        let traj: &Trajectory = &tail.traj;
        let mut log = JitterLog::default();
        let steps = simulate_correlated(gp, spec, traj, traj.len(), &mut log)?;
        for (i, s) in steps.iter().enumerate() {
            for (j, p) in pairs.iter_mut().enumerate() {
                let r = traj.y[(spec.warmup() + i, j)] - s.mean[j];
                p.push((r * r, s.cov[(j, j)]));
            }
        }
    }
    Ok(pairs.iter().map(|p| added_variance(p)).collect())
}

/// The `δ ≥ 0` of the grid minimising `Σ (r² / (v + δ) + ln(v + δ))` over the pairs
/// `(r², v)` of squared residuals and predicted variances; 0 without pairs or where no `δ`
/// gives a finite sum.
pub fn added_variance(pairs: &[(f64, f64)]) -> f64 {
    let nll = |d: f64| -> f64 {
        pairs
            .iter()
            .map(|&(r2, v)| {
                let s = (v + d).max(f64::MIN_POSITIVE);
                r2 / s + s.ln()
            })
            .sum()
    };
    let decades = (LARGEST / SMALLEST).log10();
    let points = (decades * GRID_PER_DECADE as f64).round() as usize;
    let grid = std::iter::once(0.0)
        .chain((0..=points).map(|k| SMALLEST * 10f64.powf(k as f64 / GRID_PER_DECADE as f64)));
    let mut best = (0.0, f64::INFINITY);
    for d in grid {
        let v = nll(d);
        // strictly lower only: ties keep the smaller variance
        if v < best.1 {
            best = (d, v);
        }
    }
    best.0
}

#[cfg(test)]
mod tests {
    use super::*;
    use rand::SeedableRng;
    use rand_distr::{Distribution, Normal};

    /// Residuals drawn with variance `v + δ` while the model says `v`: the calibration finds
    /// `δ` (within the grid's step of 12 % and the sampling error of 20 000 draws); residuals
    /// as wide as the model says get nothing worth speaking of, and narrower ones exactly 0.
    #[test]
    fn the_added_variance_is_the_missing_variance() {
        let mut rng = rand::rngs::StdRng::seed_from_u64(7);
        let draw = |v: &[f64], extra: f64, rng: &mut rand::rngs::StdRng| -> Vec<(f64, f64)> {
            v.iter()
                .map(|&v| {
                    let r = Normal::new(0.0, (v + extra).sqrt())
                        .expect("normal")
                        .sample(rng);
                    (r * r, v)
                })
                .collect()
        };
        // the predicted variance grows along the rollout, as a free simulation's does
        let v: Vec<f64> = (0..20_000)
            .map(|i| 0.01 + 0.1 * (i % 100) as f64 / 100.0)
            .collect();
        for extra in [0.02, 0.3, 2.0] {
            let d = added_variance(&draw(&v, extra, &mut rng));
            assert!(
                (d / extra - 1.0).abs() < 0.15,
                "missing {extra}, calibrated {d}"
            );
        }
        let honest = added_variance(&draw(&v, 0.0, &mut rng));
        assert!(honest < 2e-3, "{honest}");
        let narrow: Vec<(f64, f64)> = v.iter().map(|&v| (0.25 * v, v)).collect();
        assert_eq!(added_variance(&narrow), 0.0);
        // far too wide a miss is held at the largest calibration
        let wild: Vec<(f64, f64)> = v.iter().map(|&v| (1e4, v)).collect();
        assert!((added_variance(&wild) / LARGEST - 1.0).abs() < 1e-9);
        assert_eq!(added_variance(&[]), 0.0);
    }
}
