//! The hand-derived adjoint gradient against the forward-mode dual gradient (itself checked
//! against finite differences in `gradients_fd.rs`), on ≥ 50-step rollouts, open and closed
//! loop, one and two outputs, for every complexity variant.

mod common;

use common::{
    config, linear_feedback_episodes, normal, random_gp, rng, sys4_problem, two_output_trajectory,
};
use msgp_core::data::Trajectory;
use msgp_core::gp::{GpConfig, GpParams, GpShape, MeanFunction, ParamGroup};
use msgp_core::loss::{self, Complexity, msgp_loss};
use msgp_core::narx::NarxSpec;
use msgp_core::narx::start_window::StartWindow;
use msgp_core::numeric::dual;
use msgp_core::numeric::linalg::JitterLog;
use msgp_core::numeric::parallel::Threads;
use msgp_core::policy::PolicySpec;
use msgp_core::rollout::{Episode, Excitation};
use nalgebra::{DMatrix, DVector};

fn compare(params: &GpParams<f64>, spec: &NarxSpec, episodes: &[Episode], complexity: Complexity) {
    compare_with(params, &config(), spec, episodes, complexity);
}

fn compare_with(
    params: &GpParams<f64>,
    cfg: &GpConfig,
    spec: &NarxSpec,
    episodes: &[Episode],
    complexity: Complexity,
) {
    let shape: GpShape = params.shape().expect("shape");
    let x = params.to_flat();
    let active: Vec<usize> = (0..x.len()).collect();
    let (value, gd) = dual::gradient(&x, &active, 0, |xd| {
        let p = GpParams::from_flat(shape, xd)?;
        let mut log = JitterLog::default();
        Ok(msgp_loss(&p, cfg, spec, episodes, complexity, &mut log)?.total())
    })
    .expect("dual");
    let mut log = JitterLog::default();
    let (lv, ga) = loss::loss_and_gradient(
        params,
        cfg,
        spec,
        episodes,
        complexity,
        Threads::ONE,
        &mut log,
    )
    .expect("adjoint");
    assert!(
        (lv.total() - value).abs() <= 1e-11 * value.abs().max(1.0),
        "values {} vs {value}",
        lv.total()
    );
    for group in ParamGroup::ALL {
        let r = shape.group_range(group);
        let scale = gd[r.clone()].iter().fold(0.0f64, |m, v| m.max(v.abs()));
        let err = r
            .clone()
            .map(|i| (gd[i] - ga[i]).abs())
            .fold(0.0f64, f64::max);
        println!("{complexity:?} {group:?}: |g|∞ {scale:.3e}, max |adjoint − dual| {err:.2e}");
        assert!(
            err <= 1e-9 * scale.max(1e-12),
            "{group:?}: adjoint differs from dual by {err:e} (scale {scale:e})"
        );
    }
}

#[test]
fn open_loop_single_output() {
    let spec = NarxSpec::siso(2, 2);
    let mut r = rng(21);
    let (params, traj) = sys4_problem(&mut r, 21, 10, &spec, 70);
    let eps = vec![
        Episode::feed_forward(traj.clone()),
        Episode::feed_forward(traj.slice(5, 60)),
    ];
    for c in [
        Complexity::PseudoDataNll,
        Complexity::None,
        Complexity::NegHalfLogDet,
        Complexity::HalfLogDet,
    ] {
        compare(&params, &spec, &eps, c);
    }
}

/// Two outputs, one input, `(2, 1)` windows: a random GP over a stable ARX part (mostly the
/// last output, a little of the rest) and a two-output trajectory of 55 samples.
fn two_output_arx_problem(seed: u64) -> (NarxSpec, GpParams<f64>, Trajectory) {
    let mut r = rng(seed);
    let spec = NarxSpec {
        ly: 2,
        lu: 1,
        dy: 2,
        du: 1,
    };
    let mut params = random_gp(&mut r, 9, spec.input_dim(), 2);
    params.linear_mean = DMatrix::from_fn(2, spec.input_dim(), |a, k| {
        if k == a { 0.8 } else { 0.1 * normal(&mut r) }
    });
    let traj = two_output_trajectory(&mut r, 55);
    (spec, params, traj)
}

#[test]
fn linear_prior_mean_open_and_closed_loop() {
    let (spec, params, traj) = two_output_arx_problem(24);
    let cfg = GpConfig {
        mean: MeanFunction::Linear,
        ..config()
    };
    compare_with(
        &params,
        &cfg,
        &spec,
        &linear_feedback_episodes(&traj),
        Complexity::PseudoDataNll,
    );
}

/// The smoothed start window (`σ_y² H Hᵀ`, correlated across lags; rollouts start after the
/// smoother's samples): open and closed loop, two outputs, zero and linear prior means.
#[test]
fn smoothed_start_window_open_and_closed_loop() {
    let (spec, params, traj) = two_output_arx_problem(25);
    // 12 samples of a quadratic; the last episode is shorter than that (uses 7)
    let mut eps = linear_feedback_episodes(&traj);
    eps.push(Episode::feed_forward(traj.slice(10, 18)));
    for mean in [MeanFunction::Zero, MeanFunction::Linear] {
        let cfg = GpConfig {
            mean,
            start: StartWindow::Smoothed {
                samples: 12,
                degree: 2,
            },
            ..config()
        };
        compare_with(&params, &cfg, &spec, &eps, Complexity::PseudoDataNll);
    }
}

#[test]
fn closed_and_open_loop_two_outputs() {
    let mut r = rng(22);
    let spec = NarxSpec {
        ly: 2,
        lu: 1,
        dy: 2,
        du: 1,
    };
    let params = random_gp(&mut r, 9, spec.input_dim(), 2);
    let traj = two_output_trajectory(&mut r, 55);
    compare(
        &params,
        &spec,
        &linear_feedback_episodes(&traj),
        Complexity::PseudoDataNll,
    );
}

/// Two outputs, one input, `l_y = l_u = 2`: a random GP of 9 pseudo-inputs and an `n`-sample
/// trajectory of noisy sines drawn from `seed`, and the normaliser of the closed-loop
/// episodes' policies.
fn closed_loop_setting(
    seed: u64,
    n: usize,
) -> (
    NarxSpec,
    GpParams<f64>,
    Trajectory,
    msgp_core::data::Normalizer,
) {
    let mut r = rng(seed);
    let spec = NarxSpec {
        ly: 2,
        lu: 2,
        dy: 2,
        du: 1,
    };
    let params = random_gp(&mut r, 9, spec.input_dim(), 2);
    let y = DMatrix::from_fn(n, 2, |t, j| {
        0.3 * ((t as f64) * 0.2 + j as f64).sin() + 0.05 * normal(&mut r)
    });
    let u = DMatrix::from_fn(n, 1, |t, _| 0.3 * ((t as f64) * 0.13).cos());
    let traj = Trajectory::new(u, y).expect("traj");
    let normalizer = msgp_core::data::Normalizer {
        u_mean: vec![0.1],
        u_std: vec![0.7],
        y_mean: vec![0.02, -0.1],
        y_std: vec![0.5, 1.5],
    };
    (spec, params, traj, normalizer)
}

#[test]
fn closed_loop_with_saturated_pid_policies() {
    use msgp_core::policy::{Normalized, PidPolicy};
    let (spec, params, traj, normalizer) = closed_loop_setting(23, 55);
    let pid = PidPolicy::new(
        DMatrix::from_row_slice(1, 2, &[1.5, 0.4]),
        DMatrix::from_row_slice(1, 2, &[0.0, 0.2]),
        DMatrix::from_row_slice(1, 2, &[0.05, 0.02]),
        0.1,
        vec![1.2],
    )
    .expect("pid");
    let eps = vec![
        Episode {
            traj: traj.clone(),
            excitation: Excitation::Feedback(Box::new(PolicySpec::Direct(
                msgp_core::policy::Policy::Pid(pid.clone()),
            ))),
        },
        Episode {
            traj: traj.slice(3, 55),
            excitation: Excitation::Feedback(Box::new(PolicySpec::Normalized(Normalized {
                inner: msgp_core::policy::Policy::Pid(pid),
                normalizer: normalizer.clone(),
            }))),
        },
    ];
    compare(&params, &spec, &eps, Complexity::PseudoDataNll);
}

/// The same for episodes run by the state feedback on a window (duals through its map in the
/// sweep) and by the RBF network (its closed-form VJP), in the model's units and normalised.
#[test]
fn state_feedback_and_rbf_episodes_match_duals() {
    use msgp_core::policy::{CommandBounds, Normalized, Policy, RbfPolicy, StateFeedback};
    let (spec, params, traj, normalizer) = closed_loop_setting(29, 45);
    let mut r = rng(30);
    let n = traj.len();
    let bounds = CommandBounds::new(vec![-1.0], vec![1.5]).expect("bounds");
    let sf = StateFeedback::new(
        DMatrix::from_row_slice(1, 6, &[0.8, -0.3, 0.2, 0.1, 0.3, -0.1]),
        DVector::from_vec(vec![0.1]),
        2,
        (2, 2),
        bounds.clone(),
    )
    .expect("state feedback");
    let rbf = RbfPolicy::new(
        DMatrix::from_fn(4, 2, |_, _| 0.4 * normal(&mut r)),
        DMatrix::from_fn(4, 1, |_, _| normal(&mut r)),
        DVector::from_vec(vec![-0.5, -0.2]),
        bounds,
    )
    .expect("rbf");
    let mut eps = Vec::new();
    for policy in [Policy::StateFeedback(sf), Policy::Rbf(rbf)] {
        eps.push(Episode {
            traj: traj.clone(),
            excitation: Excitation::Feedback(Box::new(PolicySpec::Direct(policy.clone()))),
        });
        eps.push(Episode {
            traj: traj.slice(3, n),
            excitation: Excitation::Feedback(Box::new(PolicySpec::Normalized(Normalized {
                inner: policy,
                normalizer: normalizer.clone(),
            }))),
        });
    }
    compare(&params, &spec, &eps, Complexity::PseudoDataNll);
}

#[test]
fn gradient_is_bit_identical_for_any_thread_count() {
    let spec = NarxSpec::siso(2, 2);
    let mut r = rng(31);
    let (params, traj) = sys4_problem(&mut r, 31, 12, &spec, 90);
    let eps: Vec<Episode> = (0..5)
        .map(|k| Episode::feed_forward(traj.slice(3 * k, 60 + 5 * k)))
        .collect();
    let run = |threads: usize| {
        let mut log = JitterLog::default();
        loss::loss_and_gradient(
            &params,
            &config(),
            &spec,
            &eps,
            Complexity::PseudoDataNll,
            Threads::new(threads).expect("threads"),
            &mut log,
        )
        .expect("adjoint")
    };
    let (v1, g1) = run(1);
    for threads in [2, 3, 8] {
        let (v, g) = run(threads);
        assert_eq!(
            v.total().to_bits(),
            v1.total().to_bits(),
            "{threads} threads"
        );
        assert_eq!(v.steps, v1.steps);
        assert!(
            g.iter().zip(&g1).all(|(a, b)| a.to_bits() == b.to_bits()),
            "{threads} threads: gradient differs"
        );
    }
}
