//! The adjoint gradient of the filter likelihood ([`msgp_core::loss::filter_loss_and_gradient`]):
//! 1. equals the forward-mode dual gradient through [`msgp_core::loss::filter_loss`] and
//!    central finite differences of its f64 value, for every parameter group, on ≥ 50-step
//!    episodes (several at once), zero and linear prior mean, one and two outputs, every
//!    complexity term;
//! 2. a feedback episode gives the same value and gradient as its trajectory fed forward;
//! 3. value and gradient are bit-identical on one and two threads;
//! 4. the value is `filter_loss::<f64>`'s, bit for bit.

mod common;

use common::{config, linear_feedback_episodes, random_gp, rng, sys4_problem};
use msgp_core::data::Trajectory;
use msgp_core::gp::{GpConfig, GpParams, GpShape, MeanFunction, ParamGroup};
use msgp_core::loss::{Complexity, LossValue, filter_loss, filter_loss_and_gradient};
use msgp_core::narx::NarxSpec;
use msgp_core::narx::start_window::StartWindow;
use msgp_core::numeric::dual;
use msgp_core::numeric::linalg::JitterLog;
use msgp_core::numeric::parallel::Threads;
use msgp_core::rollout::Episode;
use nalgebra::DMatrix;

fn adjoint(
    params: &GpParams<f64>,
    cfg: &GpConfig,
    spec: &NarxSpec,
    eps: &[Episode],
    complexity: Complexity,
    threads: Threads,
) -> (LossValue<f64>, Vec<f64>) {
    let mut log = JitterLog::default();
    filter_loss_and_gradient(params, cfg, spec, eps, complexity, threads, &mut log)
        .expect("adjoint gradient")
}

/// Fourth-order central difference, as `tests/filter.rs`.
fn fd(f: &dyn Fn(&[f64]) -> f64, x: &[f64], i: usize, h: f64) -> f64 {
    let at = |delta: f64| {
        let mut y = x.to_vec();
        y[i] += delta;
        f(&y)
    };
    (8.0 * (at(h) - at(-h)) - (at(2.0 * h) - at(-2.0 * h))) / (12.0 * h)
}

/// Worst errors of one parameter group, relative to its largest gradient entry (`group`) and
/// per entry (`entry`: `|a − b| / max(|b|, 1e-3 · scale)`).
#[derive(Clone, Copy, Debug, Default)]
struct Worst {
    group: f64,
    entry: f64,
}

fn worst(a: &[f64], b: &[f64]) -> (f64, Worst) {
    let scale = b.iter().fold(0.0f64, |m, v| m.max(v.abs()));
    let mut w = Worst::default();
    for (x, y) in a.iter().zip(b) {
        let err = (x - y).abs();
        w.group = w.group.max(err / scale);
        w.entry = w.entry.max(err / y.abs().max(1e-3 * scale));
    }
    (scale, w)
}

/// Worst per-group errors over every case of the test, for the report.
#[derive(Default)]
struct Summary(Vec<(ParamGroup, Worst, Worst)>);

impl Summary {
    fn add(&mut self, group: ParamGroup, dual: Worst, fd: Worst) {
        match self.0.iter_mut().find(|(g, _, _)| *g == group) {
            Some((_, d, f)) => {
                d.group = d.group.max(dual.group);
                d.entry = d.entry.max(dual.entry);
                f.group = f.group.max(fd.group);
                f.entry = f.entry.max(fd.entry);
            }
            None => self.0.push((group, dual, fd)),
        }
    }

    fn print(&self, what: &str) {
        for (g, d, f) in &self.0 {
            println!(
                "{what} {g:?}: adjoint vs dual {:.1e} (per entry {:.1e}); vs fd {:.1e} (per entry {:.1e})",
                d.group, d.entry, f.group, f.entry
            );
        }
    }
}

fn check(
    params: &GpParams<f64>,
    cfg: &GpConfig,
    spec: &NarxSpec,
    eps: &[Episode],
    complexity: Complexity,
    summary: &mut Summary,
) {
    let shape: GpShape = params.shape().expect("shape");
    let x = params.to_flat();
    let loss = |flat: &[f64]| -> f64 {
        let p = GpParams::from_flat(shape, flat).expect("params");
        let mut log = JitterLog::default();
        filter_loss(&p, cfg, spec, eps, complexity, &mut log)
            .expect("filter loss")
            .total()
    };
    let (lv, ga) = adjoint(params, cfg, spec, eps, complexity, Threads::ONE);
    // 4. the value is filter_loss's, bit for bit
    let mut log = JitterLog::default();
    let fv = filter_loss(params, cfg, spec, eps, complexity, &mut log).expect("filter loss");
    assert_eq!(lv.nll.to_bits(), fv.nll.to_bits(), "nll");
    assert_eq!(lv.complexity.to_bits(), fv.complexity.to_bits());
    assert_eq!(lv.steps, fv.steps);
    assert!(eps.iter().all(|e| e.traj.len() - spec.warmup() >= 50));

    let active: Vec<usize> = (0..x.len()).collect();
    let (dv, gd) = dual::gradient(&x, &active, 0, |xd| {
        let p = GpParams::from_flat(shape, xd)?;
        let mut log = JitterLog::default();
        Ok(filter_loss(&p, cfg, spec, eps, complexity, &mut log)?.total())
    })
    .expect("dual gradient");
    assert!(
        (dv - lv.total()).abs() <= 1e-12 * dv.abs().max(1.0),
        "dual value {dv} vs adjoint {}",
        lv.total()
    );
    for group in ParamGroup::ALL {
        let r = shape.group_range(group);
        if group == ParamGroup::LinearMean && cfg.mean == MeanFunction::Zero {
            assert!(ga[r.clone()].iter().all(|g| *g == 0.0));
            assert!(gd[r].iter().all(|g| *g == 0.0));
            continue;
        }
        let gf: Vec<f64> = r.clone().map(|i| fd(&loss, &x, i, 1e-3)).collect();
        let (scale, vs_dual) = worst(&ga[r.clone()], &gd[r.clone()]);
        let (_, vs_fd) = worst(&ga[r.clone()], &gf);
        println!(
            "{:?} {complexity:?} {group:?}: |g|∞ {scale:.3e}; adjoint vs dual {:.1e} (entry {:.1e}), \
             vs fd {:.1e} (entry {:.1e})",
            cfg.mean, vs_dual.group, vs_dual.entry, vs_fd.group, vs_fd.entry
        );
        assert!(scale > 0.0, "{group:?}: a zero gradient tests nothing");
        assert!(
            vs_dual.entry <= 1e-8,
            "{group:?}: adjoint vs dual, relative {:e}",
            vs_dual.entry
        );
        assert!(
            vs_fd.group <= 1e-6 && vs_fd.entry <= 1e-6,
            "{group:?}: adjoint vs finite differences {vs_fd:?}"
        );
        summary.add(group, vs_dual, vs_fd);
    }
}

/// Under the zero prior mean and with a linear prior mean (near the identity on the lag-0
/// outputs), for each complexity term of `kinds`.
fn check_all(
    params: &GpParams<f64>,
    spec: &NarxSpec,
    eps: &[Episode],
    kinds: &[Complexity],
    what: &str,
) {
    let mut summary = Summary::default();
    let mut with_mean = params.clone();
    let (e, d) = with_mean.linear_mean.shape();
    with_mean.linear_mean = DMatrix::from_fn(e, d, |a, k| {
        0.05 * ((3 * a + 7 * k) as f64).sin() + if a == k { 0.5 } else { 0.0 }
    });
    let linear = GpConfig {
        mean: MeanFunction::Linear,
        ..config()
    };
    for &kind in kinds {
        check(params, &config(), spec, eps, kind, &mut summary);
        check(&with_mean, &linear, spec, eps, kind, &mut summary);
    }
    summary.print(what);
}

/// Two outputs, one input, `(2, 1)` windows: a random GP and `n` samples of two coupled smooth
/// signals with a little noise.
fn two_output_problem(seed: u64, n: usize) -> (NarxSpec, GpParams<f64>, Trajectory) {
    let mut r = rng(seed);
    let spec = NarxSpec {
        ly: 2,
        lu: 1,
        dy: 2,
        du: 1,
    };
    let params = random_gp(&mut r, 8, spec.input_dim(), 2);
    let traj = common::two_output_trajectory(&mut r, n);
    (spec, params, traj)
}

#[test]
fn single_output_adjoint_matches_duals_and_finite_differences() {
    let mut r = rng(61);
    let spec = NarxSpec::siso(2, 1);
    let (params, traj) = sys4_problem(&mut r, 3, 8, &spec, 64);
    let eps = vec![
        Episode::feed_forward(traj.clone()),
        Episode::feed_forward(traj.slice(8, 64)),
        Episode::feed_forward(traj.slice(0, 53)),
    ];
    check_all(
        &params,
        &spec,
        &eps,
        &[
            Complexity::None,
            Complexity::PseudoDataNll,
            Complexity::NegHalfLogDet,
            Complexity::HalfLogDet,
        ],
        "one output",
    );
}

#[test]
fn two_output_adjoint_matches_duals_and_finite_differences() {
    let (spec, params, traj) = two_output_problem(62, 60);
    let eps = vec![
        Episode::feed_forward(traj.clone()),
        Episode::feed_forward(traj.slice(4, 58)),
    ];
    check_all(
        &params,
        &spec,
        &eps,
        &[Complexity::None, Complexity::PseudoDataNll],
        "two outputs",
    );
}

/// Longer input than output lags (the start window covers `l_u` samples, and the latent
/// outputs start deeper in the window).
#[test]
fn more_input_lags_adjoint_matches_duals_and_finite_differences() {
    let mut r = rng(63);
    let spec = NarxSpec {
        ly: 1,
        lu: 3,
        dy: 1,
        du: 1,
    };
    let (params, traj) = sys4_problem(&mut r, 5, 7, &spec, 58);
    check_all(
        &params,
        &spec,
        &[Episode::feed_forward(traj)],
        &[Complexity::PseudoDataNll],
        "l_u > l_y",
    );
}

fn assert_same_bits(a: &(LossValue<f64>, Vec<f64>), b: &(LossValue<f64>, Vec<f64>), what: &str) {
    assert_eq!(a.0.nll.to_bits(), b.0.nll.to_bits(), "{what}: nll");
    assert_eq!(
        a.0.complexity.to_bits(),
        b.0.complexity.to_bits(),
        "{what}: complexity"
    );
    assert_eq!(a.0.steps, b.0.steps, "{what}: steps");
    assert_eq!(a.1.len(), b.1.len());
    for (k, (x, y)) in a.1.iter().zip(&b.1).enumerate() {
        assert_eq!(
            x.to_bits(),
            y.to_bits(),
            "{what}: gradient[{k}] {x:e} vs {y:e}"
        );
    }
}

#[test]
fn feedback_episode_is_filtered_on_its_measured_inputs() {
    let (spec, params, traj) = two_output_problem(64, 55);
    let eps = linear_feedback_episodes(&traj);
    let (fb, ff) = (&eps[..1], &eps[1..]);
    for mean in [MeanFunction::Zero, MeanFunction::Linear] {
        let cfg = GpConfig { mean, ..config() };
        let a = adjoint(
            &params,
            &cfg,
            &spec,
            fb,
            Complexity::PseudoDataNll,
            Threads::ONE,
        );
        let b = adjoint(
            &params,
            &cfg,
            &spec,
            ff,
            Complexity::PseudoDataNll,
            Threads::ONE,
        );
        assert_same_bits(&a, &b, "feedback vs feed-forward");
    }
    // the filter always starts from the measured window, whatever config.start says
    let smoothed = GpConfig {
        start: StartWindow::Smoothed {
            samples: 12,
            degree: 2,
        },
        ..config()
    };
    let a = adjoint(
        &params,
        &smoothed,
        &spec,
        ff,
        Complexity::None,
        Threads::ONE,
    );
    let b = adjoint(
        &params,
        &config(),
        &spec,
        ff,
        Complexity::None,
        Threads::ONE,
    );
    assert_same_bits(&a, &b, "smoothed vs measured start setting");
}

#[test]
fn one_and_two_threads_give_the_same_bits() {
    let (spec, params, traj) = two_output_problem(65, 60);
    let mut eps = linear_feedback_episodes(&traj);
    eps.push(Episode::feed_forward(traj.slice(3, 60)));
    eps.push(Episode::feed_forward(traj.slice(0, 40)));
    let cfg = GpConfig {
        mean: MeanFunction::Linear,
        ..config()
    };
    let one = adjoint(
        &params,
        &cfg,
        &spec,
        &eps,
        Complexity::PseudoDataNll,
        Threads::ONE,
    );
    let two = adjoint(
        &params,
        &cfg,
        &spec,
        &eps,
        Complexity::PseudoDataNll,
        Threads::new(2).expect("threads"),
    );
    assert_same_bits(&one, &two, "1 vs 2 threads");
    let mut log = JitterLog::default();
    let fv = filter_loss(
        &params,
        &cfg,
        &spec,
        &eps,
        Complexity::PseudoDataNll,
        &mut log,
    )
    .expect("filter loss");
    assert_eq!(one.0.total().to_bits(), fv.total().to_bits());
}
