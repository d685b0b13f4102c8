//! Dual-number gradients of the MSGP loss against central finite differences, for every
//! parameter group, on rollouts of ≥ 50 steps, open loop and closed loop; and the real part of
//! the dual run against the f64 run.
//!
//! Finite differences use the fourth-order central stencil
//! `(8[f(x+h) − f(x−h)] − [f(x+2h) − f(x−2h)]) / 12h`, h = 1e-3 (truncation ~h⁴, rounding
//! ~1e-16·|f|/h), so agreement to 1e-6 relative is a real check of the derivative code.

mod common;

use common::{config, normal, random_gp, rng};
use msgp_core::gp::{GpParams, GpShape, ParamGroup};
use msgp_core::grad::dual::gradient;
use msgp_core::linalg::JitterLog;
use msgp_core::loss::{Complexity, msgp_loss};
use msgp_core::narx::NarxSpec;
use msgp_core::policy::{LinearPolicy, PolicySpec};
use msgp_core::scalar::Scalar;
use msgp_core::trajectory::{Episode, Excitation, Trajectory};
use nalgebra::{DMatrix, DVector};

fn loss_at<T: Scalar>(
    shape: GpShape,
    flat: &[T],
    spec: &NarxSpec,
    episodes: &[Episode],
    complexity: Complexity,
) -> msgp_core::Result<T> {
    let params = GpParams::from_flat(shape, flat)?;
    let mut log = JitterLog::default();
    Ok(msgp_loss(&params, &config(), spec, episodes, complexity, &mut log)?.total())
}

fn fd(f: &dyn Fn(&[f64]) -> f64, x: &[f64], i: usize, h: f64) -> f64 {
    let at = |delta: f64| {
        let mut y = x.to_vec();
        y[i] += delta;
        f(&y)
    };
    (8.0 * (at(h) - at(-h)) - (at(2.0 * h) - at(-2.0 * h))) / (12.0 * h)
}

fn check_gradients(
    params: &GpParams<f64>,
    spec: &NarxSpec,
    episodes: &[Episode],
    complexity: Complexity,
) {
    let shape = params.shape().expect("shape");
    let x = params.to_flat();
    let active: Vec<usize> = (0..x.len()).collect();
    let (value, grad) = gradient(&x, &active, 0, |xd| {
        loss_at(shape, xd, spec, episodes, complexity)
    })
    .expect("dual gradient");
    let f64_value = loss_at(shape, &x, spec, episodes, complexity).expect("f64 loss");
    assert!(
        (value - f64_value).abs() <= 1e-14 * f64_value.abs().max(1.0),
        "dual real part {value:e} vs f64 {f64_value:e}"
    );
    let f = |y: &[f64]| loss_at(shape, y, spec, episodes, complexity).expect("loss");
    for group in ParamGroup::ALL {
        let range = shape.group_range(group);
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
    let mut params = random_gp(&mut r, 8, spec.input_dim(), 1);
    // data from synthetic system 4 (normalised roughly), 60 samples
    let sys = msgp_core::data::SyntheticSystem::new(4).expect("sys");
    let bench = sys.generate(3, Default::default()).expect("gen");
    let traj = bench.train.slice(0, 60);
    let norm = msgp_core::data::Normalizer::fit(&[&traj]).expect("norm");
    let traj = norm.apply(&traj);
    for i in 0..8 {
        let w = spec.window(&traj.y, &traj.u, 2 + 6 * i);
        for (k, v) in w.into_iter().enumerate() {
            params.pseudo_inputs[(i, k)] = v + 0.1 * normal(&mut r);
        }
    }
    let episodes = vec![
        Episode::feed_forward(traj.clone()),
        Episode::feed_forward(traj.slice(10, 60)),
    ];
    check_gradients(&params, &spec, &episodes, Complexity::PseudoDataNll);
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
    let n = 55;
    let y = DMatrix::from_fn(n, 2, |t, j| {
        0.5 * ((t as f64) * 0.2 + j as f64).sin() + 0.05 * normal(&mut r)
    });
    let u = DMatrix::from_fn(n, 1, |t, _| 0.3 * ((t as f64) * 0.13).cos());
    let traj = Trajectory::new(u, y).expect("traj");
    let policy = LinearPolicy::new(
        DMatrix::from_row_slice(1, 2, &[-0.6, 0.3]),
        DVector::from_vec(vec![0.05]),
    )
    .expect("policy");
    let episodes = vec![
        Episode {
            traj: traj.clone(),
            excitation: Excitation::Feedback(Box::new(PolicySpec::Linear(policy))),
        },
        Episode::feed_forward(traj),
    ];
    check_gradients(&params, &spec, &episodes, Complexity::PseudoDataNll);
}
