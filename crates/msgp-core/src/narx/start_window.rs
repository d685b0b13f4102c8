//! How a measured trajectory's free-running prediction starts: the Gaussian over its first NARX
//! window of latent outputs.
//!
//! The paper starts each rollout from the measured window: latent outputs `N(y, σ_y²)`,
//! independent. For an open-loop unstable plant measured with noise this overstates what is known
//! about the start: two noisy samples 20 ms apart leave the velocity uncertain by `√2 σ_y / T`,
//! and the plant amplifies that uncertainty exponentially. Under the per-step likelihood a model
//! then scores better by *damping* the plant, which keeps the spread small (`docs/experiments/2026-11-28-the-poles-row-errors-in-variables.md`,
//! "The pole's row"). [`StartWindow::Smoothed`] estimates the window instead from a
//! least-squares polynomial in time through the trajectory's first samples, with the covariance
//! that estimate really has (`σ_y²` times the smoother's `H Hᵀ`, correlated across lags), and
//! starts the rollout after those samples, so no measurement is both conditioned on and scored.

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use crate::error::{MsgpError, Result};

/// The start of a measured trajectory's rollout in the training loss (a setting, not optimised).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum StartWindow {
    /// The paper's start: the window's measured samples, each `N(y, σ_y²)`, independent; the
    /// rollout starts after the first `max(l_y, l_u)` samples.
    #[default]
    Measured,
    /// A polynomial of `degree` in time, fitted by least squares to each output's first `samples`
    /// measurements and evaluated at the window's times; covariance `σ_y² h_k·h_k'` between lags
    /// `k`, `k'` (rows `h` of the smoother). The rollout starts at sample `samples`. A trajectory
    /// shorter than `samples + 1` uses all but its last sample, down to `max(l_y, l_u, degree + 2)`
    /// samples; one shorter still starts from its measured window.
    Smoothed {
        /// Samples the polynomial is fitted to.
        samples: usize,
        /// Polynomial degree (2: constant acceleration).
        degree: usize,
    },
}

impl StartWindow {
    /// Checks the setting against the NARX window length `warmup = max(l_y, l_u)`.
    pub fn validate(&self, warmup: usize) -> Result<()> {
        match *self {
            Self::Measured => Ok(()),
            Self::Smoothed { samples, degree } => {
                if degree > 4 {
                    return Err(MsgpError::InvalidSetting {
                        name: "start_window.degree",
                        reason: format!("{degree}: at most 4"),
                    });
                }
                if samples < warmup.max(degree + 2) {
                    return Err(MsgpError::InvalidSetting {
                        name: "start_window.samples",
                        reason: format!(
                            "{samples}: needs at least {} (the window's {warmup} samples and \
                             degree {degree} + 2)",
                            warmup.max(degree + 2)
                        ),
                    });
                }
                Ok(())
            }
        }
    }

    /// The smoother for a trajectory of `len` samples, or `None` to start from the measured
    /// window.
    pub fn smoother(&self, warmup: usize, ly: usize, len: usize) -> Option<Smoother> {
        match *self {
            Self::Measured => None,
            Self::Smoothed { samples, degree } => {
                let k = samples.min(len.saturating_sub(1));
                if k < warmup.max(degree + 2) {
                    return None;
                }
                Smoother::new(k, degree, ly)
            }
        }
    }
}

/// Least-squares polynomial smoother of the first `samples` measurements, evaluated at the `l_y`
/// window times `samples − 1 − k`.
#[derive(Clone, Debug, PartialEq)]
pub struct Smoother {
    /// Samples fitted; the rollout starts at this time.
    pub samples: usize,
    /// `H` (l_y × samples): window value `k` is `Σ_s H[k, s] y_s`.
    pub weights: DMatrix<f64>,
    /// `H Hᵀ` (l_y × l_y): the window's covariance per unit observation-noise variance.
    pub pattern: DMatrix<f64>,
}

impl Smoother {
    fn new(samples: usize, degree: usize, ly: usize) -> Option<Self> {
        let p = degree + 1;
        // centred and scaled times keep AᵀA well conditioned
        let mid = (samples as f64 - 1.0) / 2.0;
        let scale = (samples as f64 / 2.0).max(1.0);
        let basis = |s: f64| -> Vec<f64> {
            let z = (s - mid) / scale;
            (0..p).map(|i| z.powi(i as i32)).collect()
        };
        let a = DMatrix::from_fn(samples, p, |s, i| basis(s as f64)[i]);
        let ata_inv = (a.transpose() * &a).try_inverse()?;
        let proj = ata_inv * a.transpose(); // p × samples
        let eval = DMatrix::from_fn(ly, p, |k, i| basis((samples - 1 - k) as f64)[i]);
        let weights = eval * proj;
        let pattern = &weights * weights.transpose();
        Some(Self {
            samples,
            weights,
            pattern,
        })
    }

    /// The smoothed window of output column `j` of `y`.
    pub fn window(&self, y: &DMatrix<f64>, j: usize) -> DVector<f64> {
        DVector::from_fn(self.weights.nrows(), |k, _| {
            (0..self.samples)
                .map(|s| self.weights[(k, s)] * y[(s, j)])
                .sum()
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_quadratic_is_reproduced_exactly_and_the_variance_matches_the_hat_matrix() {
        let sm = StartWindow::Smoothed {
            samples: 10,
            degree: 2,
        }
        .smoother(3, 2, 40)
        .expect("smoother");
        assert_eq!(sm.samples, 10);
        let y = DMatrix::from_fn(40, 1, |s, _| 0.3 - 0.2 * s as f64 + 0.05 * (s * s) as f64);
        let w = sm.window(&y, 0);
        for k in 0..2 {
            let s = (9 - k) as f64;
            assert!((w[k] - (0.3 - 0.2 * s + 0.05 * s * s)).abs() < 1e-12);
        }
        // Monte Carlo of the smoothed window under white noise: covariance H Hᵀ
        let mut rng = 12345u64;
        let mut gauss = || {
            // Box–Muller from a 64-bit LCG
            let mut u = || {
                rng = rng
                    .wrapping_mul(6364136223846793005)
                    .wrapping_add(1442695040888963407);
                ((rng >> 11) as f64 + 0.5) / (1u64 << 53) as f64
            };
            let (a, b) = (u(), u());
            (-2.0 * a.ln()).sqrt() * (std::f64::consts::TAU * b).cos()
        };
        let n = 40_000;
        let mut acc = DMatrix::<f64>::zeros(2, 2);
        for _ in 0..n {
            let e = DMatrix::from_fn(10, 1, |_, _| gauss());
            let w = sm.window(&e, 0);
            acc += &w * w.transpose();
        }
        acc /= n as f64;
        for i in 0..2 {
            for j in 0..2 {
                let se = (sm.pattern[(i, i)] * sm.pattern[(j, j)]).sqrt() * (2.0 / n as f64).sqrt();
                assert!(
                    (acc[(i, j)] - sm.pattern[(i, j)]).abs() < 4.0 * se,
                    "{i},{j}: {} vs {}",
                    acc[(i, j)],
                    sm.pattern[(i, j)]
                );
            }
        }
        // the difference of the two lags (the velocity) is far better known than from raw samples
        let dvar = sm.pattern[(0, 0)] + sm.pattern[(1, 1)] - 2.0 * sm.pattern[(0, 1)];
        assert!(
            dvar < 0.25,
            "velocity variance per σ²: {dvar} (raw samples: 2)"
        );
    }

    #[test]
    fn short_trajectories_and_bad_settings() {
        let s = StartWindow::Smoothed {
            samples: 10,
            degree: 2,
        };
        assert_eq!(s.smoother(3, 2, 8).expect("short smoother").samples, 7);
        assert!(s.smoother(3, 2, 4).is_none());
        assert!(StartWindow::Measured.smoother(3, 2, 100).is_none());
        assert!(s.validate(3).is_ok());
        assert!(s.validate(12).is_err());
        assert!(
            StartWindow::Smoothed {
                samples: 3,
                degree: 2
            }
            .validate(2)
            .is_err()
        );
    }
}
