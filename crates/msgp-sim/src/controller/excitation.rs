//! Smooth random excitation for the initial (open-loop) rollouts.

use msgp_core::learner::excitation::Multisine;
use serde::{Deserialize, Serialize};

use super::Controller;
use crate::error::{SimError, require_positive};
use crate::plant::Measurement;

/// Shape of the random sum of sines.
#[derive(Debug, Clone, Copy, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct ExcitationConfig {
    /// Number of sine components.
    pub components: u32,
    /// Lowest component frequency \[Hz\].
    pub min_hz: f64,
    /// Highest component frequency \[Hz\].
    pub max_hz: f64,
    /// Root-mean-square of the signal \[m/s²\] (before the plant's clipping).
    pub rms: f64,
}

impl Default for ExcitationConfig {
    fn default() -> Self {
        Self {
            components: 8,
            min_hz: 0.1,
            max_hz: 2.0,
            rms: 1.0,
        }
    }
}

impl ExcitationConfig {
    /// Checks ranges: at least one component, `0 < min_hz <= max_hz`, `rms > 0`.
    pub fn validate(&self) -> Result<(), SimError> {
        if self.components == 0 || self.components > 10_000 {
            return Err(SimError::invalid(
                "components",
                f64::from(self.components),
                "must be in 1..=10000",
            ));
        }
        require_positive("min_hz", self.min_hz)?;
        require_positive("max_hz", self.max_hz)?;
        if self.max_hz < self.min_hz {
            return Err(SimError::invalid(
                "max_hz",
                self.max_hz,
                "must be >= min_hz",
            ));
        }
        require_positive("rms", self.rms)
    }
}

/// `u(t) = Σ_i a_i sin(2π f_i t + φ_i)` with, per component, `f_i ~ U[min_hz, max_hz]`,
/// `φ_i ~ U[0, 2π)` and raw weights `w_i ~ U[0.5, 1]` scaled so that `Σ a_i² / 2 = rms²`
/// (the long-run RMS of a sum of sines with distinct frequencies). Open loop: measurements
/// are ignored. Fully determined by the seed.
/// The command's channel of [`msgp_core::learner::excitation::Multisine`].
#[derive(Debug, Clone)]
pub struct RandomExcitation {
    seed: u64,
    components: u32,
    signal: Multisine,
}

impl RandomExcitation {
    /// Draws the components from `seed`.
    pub fn new(seed: u64, config: &ExcitationConfig) -> Result<Self, SimError> {
        config.validate()?;
        let signal = Multisine::new(
            seed,
            config.components,
            (config.min_hz, config.max_hz),
            &[0.0],
            &[config.rms],
        );
        Ok(Self {
            seed,
            components: config.components,
            signal,
        })
    }

    /// Signal value at time `t` \[s\].
    pub fn value(&self, t: f64) -> f64 {
        self.signal.value(t)[0]
    }
}

impl Controller for RandomExcitation {
    fn reset(&mut self) {}

    fn command(&mut self, t: f64, _measurement: &Measurement) -> f64 {
        self.value(t)
    }

    fn describe(&self) -> String {
        format!(
            "random_excitation seed={} components={}",
            self.seed, self.components
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn rms_and_determinism() {
        let cfg = ExcitationConfig::default();
        let a = RandomExcitation::new(7, &cfg).expect("valid");
        let b = RandomExcitation::new(7, &cfg).expect("valid");
        let c = RandomExcitation::new(8, &cfg).expect("valid");
        let n = 200_000;
        let dt = 0.01;
        let ms: f64 = (0..n).map(|k| a.value(k as f64 * dt).powi(2)).sum::<f64>() / n as f64;
        assert!((ms.sqrt() - 1.0).abs() < 0.1, "rms {}", ms.sqrt());
        assert_eq!(a.value(1.234).to_bits(), b.value(1.234).to_bits());
        assert_ne!(a.value(1.234), c.value(1.234));
    }

    #[test]
    fn rejects_bad_config() {
        let bad = ExcitationConfig {
            min_hz: 3.0,
            ..Default::default()
        };
        assert!(RandomExcitation::new(0, &bad).is_err());
    }
}
