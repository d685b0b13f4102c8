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
        linear_mean: DMatrix::zeros(e, d),
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

/// A single-output problem on synthetic system 4 (normalised): a random GP whose pseudo-inputs
/// sit near the trajectory's windows, and the first `len` samples.
pub fn sys4_problem(
    r: &mut StdRng,
    seed: u64,
    m: usize,
    spec: &msgp_core::narx::NarxSpec,
    len: usize,
) -> (GpParams<f64>, msgp_core::data::Trajectory) {
    let mut params = random_gp(r, m, spec.input_dim(), 1);
    let sys = msgp_core::data::SyntheticSystem::new(4).expect("sys");
    let bench = sys.generate(seed, Default::default()).expect("gen");
    let traj = bench.train.slice(0, len);
    let norm = msgp_core::data::Normalizer::fit(&[&traj]).expect("norm");
    let traj = norm.apply(&traj);
    for i in 0..m {
        let w = spec.window(&traj.y, &traj.u, 2 + 6 * i);
        for (k, v) in w.into_iter().enumerate() {
            params.pseudo_inputs[(i, k)] = v + 0.1 * normal(r);
        }
    }
    (params, traj)
}

/// Two outputs, one input, `n` samples of smooth signals with a little noise.
pub fn two_output_trajectory(r: &mut StdRng, n: usize) -> msgp_core::data::Trajectory {
    let y = DMatrix::from_fn(n, 2, |t, j| {
        0.5 * ((t as f64) * 0.2 + j as f64).sin() + 0.05 * normal(r)
    });
    let u = DMatrix::from_fn(n, 1, |t, _| 0.3 * ((t as f64) * 0.13).cos());
    msgp_core::data::Trajectory::new(u, y).expect("traj")
}

/// The trajectory once under a linear feedback policy (closed loop) and once open loop.
pub fn linear_feedback_episodes(
    traj: &msgp_core::data::Trajectory,
) -> Vec<msgp_core::rollout::Episode> {
    use msgp_core::policy::{LinearPolicy, PolicySpec};
    use msgp_core::rollout::{Episode, Excitation};
    let policy = LinearPolicy::new(
        DMatrix::from_row_slice(1, 2, &[-0.6, 0.3]),
        DVector::from_vec(vec![0.05]),
    )
    .expect("policy");
    vec![
        Episode {
            traj: traj.clone(),
            excitation: Excitation::Feedback(Box::new(PolicySpec::Linear(policy))),
        },
        Episode::feed_forward(traj.clone()),
    ]
}
