//! Dual-number gradients of the MSGP loss against central finite differences, for every
//! parameter group, on rollouts of ≥ 50 steps, open loop and closed loop; and the real part of
//! the dual run against the f64 run.
//!
//! Finite differences use the fourth-order central stencil
//! `(8[f(x+h) − f(x−h)] − [f(x+2h) − f(x−2h)]) / 12h`, h = 1e-3 (truncation ~h⁴, rounding
//! ~1e-16·|f|/h), so agreement to 1e-6 relative is a real check of the derivative code.

mod common;

use common::{
    config, linear_feedback_episodes, random_gp, rng, sys4_problem, two_output_trajectory,
};
use msgp_core::gp::{GpConfig, GpParams, GpShape, MeanFunction, ParamGroup};
use msgp_core::loss::{Complexity, msgp_loss};
use msgp_core::moments::MomentMatch;
use msgp_core::narx::NarxSpec;
use msgp_core::narx::start_window::StartWindow;
use msgp_core::numeric::dual::gradient;
use msgp_core::numeric::linalg::JitterLog;
use msgp_core::rollout::Episode;
use nalgebra::DMatrix;

fn loss_at<T: MomentMatch>(
    shape: GpShape,
    flat: &[T],
    cfg: &GpConfig,
    spec: &NarxSpec,
    episodes: &[Episode],
    complexity: Complexity,
) -> msgp_core::Result<T> {
    let params = GpParams::from_flat(shape, flat)?;
    let mut log = JitterLog::default();
    Ok(msgp_loss(&params, cfg, spec, episodes, complexity, &mut log)?.total())
}

fn fd(f: &dyn Fn(&[f64]) -> f64, x: &[f64], i: usize, h: f64) -> f64 {
    let at = |delta: f64| {
        let mut y = x.to_vec();
        y[i] += delta;
        f(&y)
    };
    (8.0 * (at(h) - at(-h)) - (at(2.0 * h) - at(-2.0 * h))) / (12.0 * h)
}

/// Checks every group under the zero prior mean (where `A` must have an exactly zero gradient)
/// and again with a linear prior mean `A` (small random entries).
fn check_gradients(
    params: &GpParams<f64>,
    spec: &NarxSpec,
    episodes: &[Episode],
    complexity: Complexity,
) {
    check_gradients_with(params, &config(), spec, episodes, complexity);
    let mut with_mean = params.clone();
    let (e, d) = with_mean.linear_mean.shape();
    with_mean.linear_mean = DMatrix::from_fn(e, d, |a, k| {
        0.05 * ((3 * a + 7 * k) as f64).sin() + if a == k { 0.5 } else { 0.0 }
    });
    let cfg = GpConfig {
        mean: MeanFunction::Linear,
        ..config()
    };
    check_gradients_with(&with_mean, &cfg, spec, episodes, complexity);
}

fn check_gradients_with(
    params: &GpParams<f64>,
    cfg: &GpConfig,
    spec: &NarxSpec,
    episodes: &[Episode],
    complexity: Complexity,
) {
    let shape = params.shape().expect("shape");
    let x = params.to_flat();
    let active: Vec<usize> = (0..x.len()).collect();
    let (value, grad) = gradient(&x, &active, 0, |xd| {
        loss_at(shape, xd, cfg, spec, episodes, complexity)
    })
    .expect("dual gradient");
    let f64_value = loss_at(shape, &x, cfg, spec, episodes, complexity).expect("f64 loss");
    assert!(
        (value - f64_value).abs() <= 1e-14 * f64_value.abs().max(1.0),
        "dual real part {value:e} vs f64 {f64_value:e}"
    );
    let f = |y: &[f64]| loss_at(shape, y, cfg, spec, episodes, complexity).expect("loss");
    for group in ParamGroup::ALL {
        let range = shape.group_range(group);
        if group == ParamGroup::LinearMean && cfg.mean == MeanFunction::Zero {
            assert!(
                grad[range].iter().all(|g| *g == 0.0),
                "A has a gradient under the zero mean"
            );
            continue;
        }
        let gd: Vec<f64> = grad[range.clone()].to_vec();
        let gf: Vec<f64> = range.clone().map(|i| fd(&f, &x, i, 1e-3)).collect();
        let scale = gf.iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let err = gd
            .iter()
            .zip(&gf)
            .fold(0.0f64, |m, (a, b)| m.max((a - b).abs()));
        println!(
            "{group:?}: |g|∞ = {scale:.3e}, max |dual − fd| = {err:.3e}, rel {:.2e}",
            err / scale
        );
        assert!(scale > 0.0, "{group:?}: zero gradient cannot test anything");
        assert!(
            err <= 1e-6 * scale,
            "{group:?}: relative error {:.3e} > 1e-6",
            err / scale
        );
        for (k, (a, b)) in gd.iter().zip(&gf).enumerate() {
            assert!(
                (a - b).abs() <= 1e-6 * b.abs().max(1e-2 * scale),
                "{group:?}[{k}]: dual {a:e} vs fd {b:e}"
            );
        }
    }
}

#[test]
fn open_loop_gradients_match_finite_differences() {
    let mut r = rng(11);
    let spec = NarxSpec::siso(2, 1);
    let (params, traj) = sys4_problem(&mut r, 3, 8, &spec, 60);
    let episodes = vec![
        Episode::feed_forward(traj.clone()),
        Episode::feed_forward(traj.slice(10, 60)),
    ];
    check_gradients(&params, &spec, &episodes, Complexity::PseudoDataNll);
    // the smoothed start window: the observation noise enters the start as `σ_y² H Hᵀ`
    let smoothed = GpConfig {
        start: StartWindow::Smoothed {
            samples: 10,
            degree: 2,
        },
        ..config()
    };
    check_gradients_with(
        &params,
        &smoothed,
        &spec,
        &episodes,
        Complexity::PseudoDataNll,
    );
}

#[test]
fn closed_loop_gradients_match_finite_differences() {
    let mut r = rng(12);
    let spec = NarxSpec {
        ly: 1,
        lu: 1,
        dy: 2,
        du: 1,
    };
    let params = random_gp(&mut r, 8, spec.input_dim(), 2);
    let traj = two_output_trajectory(&mut r, 55);
    check_gradients(
        &params,
        &spec,
        &linear_feedback_episodes(&traj),
        Complexity::PseudoDataNll,
    );
}
