//! Mean-feedback simulation: the NARX window is filled with the model's own predicted *means*
//! and nothing else, each step a deterministic GP prediction (eq. 13) at that window.
//!
//! This is how one-step GP-NARX models are often simulated (and, as `../shared/notes/anchors.md`
//! found, how the paper's GP-NARX column reads): no uncertainty is propagated, so the reported
//! variance at step `t` is only that step's own predictive variance `Var[f(x̃_t)] + σ_x² + σ_y²`
//! at the mean window. The moment-matching rollout ([`super::forward`]) is the method's own
//! and stays the default everywhere; this one is the baseline's reading, offered beside it.

use nalgebra::DMatrix;

use crate::data::Trajectory;
use crate::error::{MsgpError, Result};
use crate::gp::PreparedGp;
use crate::narx::NarxSpec;

/// Open-loop mean-feedback simulation of `traj` (normalised units) from its first
/// `max(l_y, l_u)` measured samples, driven by its measured inputs, up to `horizon`.
/// Returns the predicted output means and variances (steps × d_y), the first row at time
/// `max(l_y, l_u)`.
pub fn simulate_mean_feedback(
    gp: &PreparedGp<f64>,
    spec: &NarxSpec,
    traj: &Trajectory,
    horizon: usize,
) -> Result<(DMatrix<f64>, DMatrix<f64>)> {
    let t0 = spec.warmup();
    let horizon = horizon.min(traj.len());
    if horizon <= t0 {
        return Err(MsgpError::Data(format!(
            "a simulation needs more than {t0} samples, got {horizon}"
        )));
    }
    if gp.output_dim() != spec.dy || gp.input_dim() != spec.input_dim() {
        return Err(MsgpError::Shape(format!(
            "a GP of {} inputs and {} outputs for a window of {} inputs and {} outputs",
            gp.input_dim(),
            gp.output_dim(),
            spec.input_dim(),
            spec.dy
        )));
    }
    // the outputs seen by the window: measured before t0, predicted means from t0 on
    let mut y = traj.y.rows(0, horizon).into_owned();
    let mut var = DMatrix::zeros(horizon - t0, spec.dy);
    for t in t0..horizon {
        let x = spec.window(&y, &traj.u, t - 1);
        for (a, (m, v)) in gp.predict(&x).into_iter().enumerate() {
            let o = &gp.outputs[a];
            if !m.is_finite() {
                return Err(MsgpError::NonFinite(format!(
                    "mean-feedback simulation: output {a} at step {t}"
                )));
            }
            y[(t, a)] = m;
            var[(t - t0, a)] = v.max(0.0) + o.sx2 + o.sy2;
        }
    }
    Ok((y.rows(t0, horizon - t0).into_owned(), var))
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::gp::{GpConfig, GpParams, GpShape, MeanFunction};
    use crate::numeric::linalg::JitterLog;
    use nalgebra::DVector;

    /// A linear mean only (the GP's pseudo-targets zero and its signal variance negligible):
    /// the mean-feedback simulation is the noise-free recursion of the linear model, computed
    /// here by hand, and its variance the two noises.
    #[test]
    fn equals_the_noise_free_recursion_of_a_linear_model() {
        let spec = NarxSpec::siso(2, 1);
        let shape = GpShape { m: 3, d: 3, e: 1 };
        let mut p = GpParams::filled(shape, 0.0);
        p.pseudo_inputs = DMatrix::from_fn(3, 3, |i, j| (i + 2 * j) as f64 * 0.3);
        p.log_signal_var = DVector::from_element(1, (1e-12f64).ln());
        p.log_process_noise = DVector::from_element(1, (0.01f64).ln());
        p.log_obs_noise = DVector::from_element(1, (0.02f64).ln());
        p.linear_mean = DMatrix::from_row_slice(1, 3, &[1.2, -0.5, 0.3]);
        let config = GpConfig {
            mean: MeanFunction::Linear,
            noise_floor: 0.0,
            ..GpConfig::default()
        };
        let mut log = JitterLog::default();
        let gp = PreparedGp::new(&p, &config, &mut log).expect("gp");
        let n = 30;
        let u = DMatrix::from_fn(n, 1, |t, _| (0.4 * t as f64).sin());
        let y = DMatrix::from_fn(n, 1, |t, _| 0.1 * t as f64);
        let traj = Trajectory::new(u.clone(), y.clone()).expect("traj");
        let (mean, var) = simulate_mean_feedback(&gp, &spec, &traj, n).expect("sim");
        let mut r = y.clone();
        for t in 2..n {
            r[(t, 0)] = 1.2 * r[(t - 1, 0)] - 0.5 * r[(t - 2, 0)] + 0.3 * u[(t - 1, 0)];
            assert!((mean[(t - 2, 0)] - r[(t, 0)]).abs() < 1e-9, "step {t}");
            assert!(
                (var[(t - 2, 0)] - 0.03).abs() < 1e-9,
                "variance at step {t}"
            );
        }
        assert_eq!(mean.nrows(), n - 2);
    }
}
