//! Shared helpers for msgp-core integration tests.
#![allow(dead_code)]

use msgp_core::gp::{GpConfig, GpParams};
use nalgebra::{DMatrix, DVector};
use rand::{RngExt, SeedableRng, rngs::StdRng};
use rand_distr::{Distribution, StandardNormal};

pub fn rng(seed: u64) -> StdRng {
    StdRng::seed_from_u64(seed)
}

pub fn normal(rng: &mut StdRng) -> f64 {
    StandardNormal.sample(rng)
}

/// A random GP with `m` pseudo-inputs in `d` dimensions and `e` outputs.
pub fn random_gp(rng: &mut StdRng, m: usize, d: usize, e: usize) -> GpParams<f64> {
    GpParams {
        pseudo_inputs: DMatrix::from_fn(m, d, |_, _| rng.random_range(-1.5..1.5)),
        pseudo_targets: DMatrix::from_fn(m, e, |_, _| normal(rng)),
        log_lengthscales: DMatrix::from_fn(e, d, |_, _| rng.random_range(-0.4..0.6)),
        log_signal_var: DVector::from_fn(e, |_, _| rng.random_range(-0.5..0.5)),
        log_process_noise: DVector::from_fn(e, |_, _| rng.random_range(-4.0..-2.0)),
        log_obs_noise: DVector::from_fn(e, |_, _| rng.random_range(-5.0..-3.0)),
    }
}

/// A random SPD covariance `A Aᵀ · scale + small·I`.
pub fn random_cov(rng: &mut StdRng, d: usize, scale: f64) -> DMatrix<f64> {
    let a = DMatrix::from_fn(d, d, |_, _| normal(rng));
    &a * a.transpose() * (scale / d as f64) + DMatrix::identity(d, d) * (0.01 * scale)
}

pub fn config() -> GpConfig {
    GpConfig::default()
}
