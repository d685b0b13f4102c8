//! Smooth random excitation for the loop's first, open-loop episodes: per command a random sum
//! of sines, `u(t) = mid + Σ_i a_i sin(2π f_i t + φ_i)`, with `f_i ~ U[min_hz, max_hz]`,
//! `φ_i ~ U[0, 2π)` and raw weights `w_i ~ U[0.5, 1]` scaled so that `Σ a_i² / 2 = rms²` (the
//! long-run RMS of sines of distinct frequencies). Fully determined by its seed.

use rand::{RngExt, SeedableRng};
use serde::{Deserialize, Serialize};

use crate::error::{MsgpError, Result};
use crate::numeric::seed::derive;
use crate::policy::CommandBounds;

/// The stream tag of an episode's excitation ([`derive()`]).
pub const EXCITATION_STREAM: u64 = 3;

/// The shape of the excitation, relative to each command's range.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct ExcitationConfig {
    /// Sine components per command.
    pub components: u32,
    /// Lowest component frequency \[Hz\].
    pub min_hz: f64,
    /// Highest component frequency \[Hz\].
    pub max_hz: f64,
    /// Root-mean-square of each command's signal as a fraction of half its range (the plant
    /// clips to the range; 1/3 keeps 99.7 % of a Gaussian's values inside).
    pub rms_fraction: f64,
}

impl Default for ExcitationConfig {
    fn default() -> Self {
        Self {
            components: 20,
            min_hz: 0.1,
            max_hz: 10.0,
            rms_fraction: 1.0 / 3.0,
        }
    }
}

impl ExcitationConfig {
    /// Checks ranges: 1..=10000 components, `0 < min_hz <= max_hz`, a positive fraction.
    pub fn validate(&self) -> Result<()> {
        let bad = |reason: String| MsgpError::InvalidSetting {
            name: "excitation",
            reason,
        };
        if !(1..=10_000).contains(&self.components) {
            return Err(bad(format!(
                "components must be in 1..=10000, got {}",
                self.components
            )));
        }
        if !(self.min_hz.is_finite() && self.min_hz > 0.0 && self.max_hz.is_finite())
            || self.max_hz < self.min_hz
        {
            return Err(bad(format!(
                "need finite 0 < min_hz <= max_hz, got {} and {}",
                self.min_hz, self.max_hz
            )));
        }
        if !(self.rms_fraction.is_finite() && self.rms_fraction > 0.0) {
            return Err(bad(format!(
                "rms_fraction must be positive, got {}",
                self.rms_fraction
            )));
        }
        Ok(())
    }
}

/// One sine component: amplitude, frequency \[Hz\], phase \[rad\].
type Sine = (f64, f64, f64);

/// A random sum of sines per command (see the module docs).
#[derive(Debug, Clone, PartialEq)]
pub struct Multisine {
    /// Per command, its centre and its components.
    channels: Vec<(f64, Vec<Sine>)>,
}

impl Multisine {
    /// Draws the components from `seed`'s excitation stream, command after command; channel
    /// `k` is centred on `centre[k]` with RMS `rms[k]`.
    pub fn new(
        seed: u64,
        components: u32,
        (min_hz, max_hz): (f64, f64),
        centre: &[f64],
        rms: &[f64],
    ) -> Self {
        let mut rng =
            rand::rngs::Xoshiro256PlusPlus::seed_from_u64(derive(seed, EXCITATION_STREAM));
        let channels = centre
            .iter()
            .zip(rms)
            .map(|(&mid, &rms)| {
                let mut parts: Vec<Sine> = (0..components)
                    .map(|_| {
                        let f = if max_hz > min_hz {
                            rng.random_range(min_hz..max_hz)
                        } else {
                            min_hz
                        };
                        let phase = rng.random_range(0.0..std::f64::consts::TAU);
                        let weight = rng.random_range(0.5..=1.0);
                        (weight, f, phase)
                    })
                    .collect();
                let power: f64 = parts.iter().map(|(w, _, _)| 0.5 * w * w).sum();
                let scale = rms / power.sqrt();
                for p in &mut parts {
                    p.0 *= scale;
                }
                (mid, parts)
            })
            .collect();
        Self { channels }
    }

    /// The excitation of `config` for commands within `bounds`.
    pub fn for_bounds(seed: u64, config: &ExcitationConfig, bounds: &CommandBounds) -> Self {
        let rms: Vec<f64> = bounds
            .half_range()
            .iter()
            .map(|h| config.rms_fraction * h)
            .collect();
        Self::new(
            seed,
            config.components,
            (config.min_hz, config.max_hz),
            &bounds.mid(),
            &rms,
        )
    }

    /// The commands at time `t` \[s\].
    pub fn value(&self, t: f64) -> Vec<f64> {
        self.channels
            .iter()
            .map(|(mid, parts)| {
                let wave: f64 = parts
                    .iter()
                    .map(|&(a, f, phase)| a * (std::f64::consts::TAU * f * t + phase).sin())
                    .sum();
                mid + wave
            })
            .collect()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The long-run RMS is the configured fraction of the half range around the centre, each
    /// command has its own signal, and the seed fixes every value.
    #[test]
    fn rms_centre_and_determinism() {
        let bounds = CommandBounds::new(vec![-3.0, 1.0], vec![3.0, 2.0]).expect("valid");
        let config = ExcitationConfig::default();
        let a = Multisine::for_bounds(7, &config, &bounds);
        let b = Multisine::for_bounds(7, &config, &bounds);
        let c = Multisine::for_bounds(8, &config, &bounds);
        let n = 200_000;
        let values: Vec<Vec<f64>> = (0..n).map(|k| a.value(k as f64 * 0.01)).collect();
        for (k, (mid, half)) in [(0.0, 3.0), (1.5, 0.5)].into_iter().enumerate() {
            let mean = values.iter().map(|v| v[k]).sum::<f64>() / n as f64;
            let rms = (values.iter().map(|v| (v[k] - mid).powi(2)).sum::<f64>() / n as f64).sqrt();
            assert!((mean - mid).abs() < 0.02 * half, "mean {mean}");
            assert!((rms / half - 1.0 / 3.0).abs() < 0.03, "rms {rms}");
        }
        assert_eq!(a.value(1.234), b.value(1.234));
        assert_ne!(a.value(1.234), c.value(1.234));
        assert!(
            ExcitationConfig {
                min_hz: 3.0,
                max_hz: 2.0,
                ..config
            }
            .validate()
            .is_err()
        );
    }
}
