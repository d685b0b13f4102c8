//! Shared set-ups for the criterion benchmarks in `benches/`.

use msgp_core::data::Normalizer;
use msgp_core::data::Trajectory;
use msgp_core::data::{NoiseScale, SyntheticSystem};
use msgp_core::gp::GpParams;
use msgp_core::narx::NarxSpec;
use msgp_core::rollout::Episode;
use nalgebra::{DMatrix, DVector};

/// A seeded MSGP problem: `m` pseudo-inputs, history (l_y, l_u) = (d/2, d − d/2), `t` predicted
/// steps, data from synthetic system 4 driven by its random training input.
///
/// Pseudo-inputs are `m` measured windows spread over the trajectory, pseudo-targets the outputs
/// that follow them; `log ℓ = 0.3 + ½ ln(d/4)` (so the typical scaled distance between windows,
/// and with it the size of the kernel values, does not shrink as `d` grows; `d = 4` gives the
/// original 0.3), `σ_f² = 1`, `σ_x² = σ_y² = 0.01 + floor`.
pub fn problem(
    m: usize,
    d: usize,
    t: usize,
    seed: u64,
) -> msgp_core::Result<(GpParams<f64>, NarxSpec, Vec<Episode>)> {
    let spec = NarxSpec::siso(d / 2, d - d / 2);
    let sys = SyntheticSystem::new(4)?;
    let mut u = Vec::new();
    let mut s = seed;
    while u.len() < t + spec.warmup() {
        let b = sys.generate(s, NoiseScale::StdDev)?;
        u.extend(b.train.u.iter().copied());
        s += 1;
    }
    u.truncate(t + spec.warmup());
    let y = sys.respond(&u);
    let traj = Trajectory::siso(&u, &y)?;
    let norm = Normalizer::fit(&[&traj])?;
    let traj = norm.apply(&traj);
    let n = traj.len();
    let pseudo = DMatrix::from_fn(m, spec.input_dim(), |i, k| {
        let tt = spec.warmup() - 1 + (i * (n - spec.warmup())) / m;
        spec.window(&traj.y, &traj.u, tt)[k]
    });
    let targets = DMatrix::from_fn(m, 1, |i, _| {
        let tt = spec.warmup() + (i * (n - spec.warmup())) / m;
        traj.y[(tt.min(n - 1), 0)]
    });
    let params = GpParams {
        pseudo_inputs: pseudo,
        pseudo_targets: targets,
        log_lengthscales: DMatrix::from_element(
            1,
            spec.input_dim(),
            0.3 + 0.5 * (spec.input_dim() as f64 / 4.0).ln(),
        ),
        log_signal_var: DVector::from_element(1, 0.0),
        log_process_noise: DVector::from_element(1, (0.01f64).ln()),
        log_obs_noise: DVector::from_element(1, (0.01f64).ln()),
        linear_mean: DMatrix::zeros(1, spec.input_dim()),
    };
    Ok((params, spec, vec![Episode::feed_forward(traj)]))
}

/// A window state for timing one moment-matching step: the mean is the measured window at the
/// start of the episode, the covariance is dense, `0.01·0.5^{|i−j|}`, plus `0.01` on the diagonal.
pub fn window_state(spec: &NarxSpec, episode: &Episode) -> (DVector<f64>, DMatrix<f64>) {
    let traj = &episode.traj;
    let w = spec.window(&traj.y, &traj.u, spec.warmup() - 1);
    let d = w.len();
    let sigma = DMatrix::from_fn(d, d, |i, j| {
        0.01 * 0.5f64.powi((i as i32 - j as i32).abs()) + if i == j { 0.01 } else { 0.0 }
    });
    (DVector::from_vec(w), sigma)
}
