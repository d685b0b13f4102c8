//! The vectorised f64 moment-matching kernel (what `moment_match`, rollouts and the loss run for
//! `f64`) against the generic implementation it replaces (`moment_match_generic`, and the real
//! part of a dual-number run, which executes the generic code operation for operation): single
//! steps on random GPs and inputs (D = 2, 4, 20; E = 1, 2, 3; m not a multiple of the SIMD
//! block), and whole open- and closed-loop rollouts and losses on seeded problems.

mod common;

use common::{
    config, linear_feedback_episodes, normal, random_cov, random_gp, rng, sys4_problem,
    two_output_trajectory,
};
use msgp_core::data::Trajectory;
use msgp_core::gp::{GpParams, PreparedGp};
use msgp_core::loss::{Complexity, msgp_loss};
use msgp_core::moments::{moment_match, moment_match_generic};
use msgp_core::narx::NarxSpec;
use msgp_core::numeric::dual::Dual;
use msgp_core::numeric::linalg::JitterLog;
use msgp_core::numeric::scalar::Scalar;
use msgp_core::rollout::Episode;
use msgp_core::rollout::{Control, simulate};
use nalgebra::{DMatrix, DVector};

/// max |a − b| / max(max |b|, floor) over the entries.
fn rel(a: &[f64], b: &[f64], floor: f64) -> f64 {
    let scale = b.iter().fold(floor, |m, v| m.max(v.abs()));
    a.iter()
        .zip(b)
        .map(|(x, y)| (x - y).abs())
        .fold(0.0, f64::max)
        / scale
}

#[test]
fn single_steps_match_generic() {
    let mut worst = 0.0f64;
    let mut case = 0u64;
    for &(m, d, e) in &[
        (1, 2, 1),
        (7, 2, 2),
        (13, 4, 1),
        (100, 4, 1),
        (37, 4, 2),
        (50, 4, 3),
        (100, 20, 1),
        (29, 20, 2),
    ] {
        for scale in [0.0, 0.05, 1.0] {
            case += 1;
            let mut r = rng(1000 + case);
            let mut params = random_gp(&mut r, m, d, e);
            // length-scales that grow like √D keep the kernel values away from underflow
            params
                .log_lengthscales
                .add_scalar_mut(0.5 * (d as f64 / 4.0).ln());
            let mut log = JitterLog::default();
            let gp = PreparedGp::new(&params, &config(), &mut log).expect("prepare");
            let mu = DVector::from_fn(d, |_, _| 0.5 * normal(&mut r));
            let mut sigma = if scale == 0.0 {
                DMatrix::zeros(d, d)
            } else {
                random_cov(&mut r, d, scale)
            };
            // a deterministic component (singular Σ), as for the inputs of an open-loop window
            if scale > 0.0 {
                for k in 0..d {
                    sigma[(d - 1, k)] = 0.0;
                    sigma[(k, d - 1)] = 0.0;
                }
            }
            let mut l1 = JitterLog::default();
            let mut l2 = JitterLog::default();
            let fast = moment_match(&gp, &mu, &sigma, &mut l1).expect("fast");
            let slow = moment_match_generic(&gp, &mu, &sigma, &mut l2).expect("generic");
            assert_eq!(l1, l2, "jitter decisions differ");
            // a GP whose variance weights were not prepared (built field by field rather than
            // by PreparedGp::new) gets them made on the fly: the same bits
            let mut bare = gp.clone();
            for o in &mut bare.outputs {
                o.q_weights.clear();
            }
            let again = moment_match(&bare, &mu, &sigma, &mut JitterLog::default()).expect("bare");
            assert_eq!(again.cov, fast.cov, "m {m} D {d} E {e}: unprepared weights");
            // a variance is a difference of terms of the size of σ_f² (σ_f² − tr(K̃⁻¹Q), βᵀQβ − M²):
            // its rounding error is relative to σ_f², not to the (possibly tiny) result
            let sf2 = gp.outputs.iter().fold(0.0f64, |m, o| m.max(o.sf2));
            let errs = [
                rel(fast.mean.as_slice(), slow.mean.as_slice(), 1e-300),
                rel(fast.cov.as_slice(), slow.cov.as_slice(), sf2),
                rel(fast.io_cov.as_slice(), slow.io_cov.as_slice(), 1e-300),
                rel(fast.v.as_slice(), slow.v.as_slice(), 1e-300),
            ];
            println!(
                "m {m} D {d} E {e} Σ scale {scale}: mean/cov/io_cov/V rel. diff {:.2e} {:.2e} {:.2e} {:.2e}",
                errs[0], errs[1], errs[2], errs[3]
            );
            for err in errs {
                worst = worst.max(err);
                assert!(err <= 1e-12, "m {m} D {d} E {e} scale {scale}: {errs:?}");
            }
        }
    }
    println!("worst relative difference {worst:.2e}");
}

/// The generic loss: the real part of a one-direction dual run.
fn generic_loss(
    params: &GpParams<f64>,
    spec: &NarxSpec,
    episodes: &[Episode],
    complexity: Complexity,
) -> f64 {
    let pd: GpParams<Dual> = params.map(Dual::from_re);
    let mut log = JitterLog::default();
    msgp_loss(&pd, &config(), spec, episodes, complexity, &mut log)
        .expect("generic loss")
        .total()
        .re()
}

fn fast_loss(
    params: &GpParams<f64>,
    spec: &NarxSpec,
    episodes: &[Episode],
    complexity: Complexity,
) -> f64 {
    let mut log = JitterLog::default();
    msgp_loss(params, &config(), spec, episodes, complexity, &mut log)
        .expect("fast loss")
        .total()
}

fn check_loss(what: &str, params: &GpParams<f64>, spec: &NarxSpec, episodes: &[Episode]) {
    for c in [Complexity::PseudoDataNll, Complexity::None] {
        let (f, g) = (
            fast_loss(params, spec, episodes, c),
            generic_loss(params, spec, episodes, c),
        );
        let err = (f - g).abs() / g.abs().max(1.0);
        println!("{what} {c:?}: fast {f:.15e} generic {g:.15e} rel. diff {err:.2e}");
        assert!(err <= 1e-12, "{what} {c:?}: {f} vs {g}");
    }
}

/// Predicted means and covariances of every step, fast against generic. The two sum in different
/// orders (vector lanes, FMA), and a closed-loop rollout feeds each step's rounding into the next:
/// over 50+ steps that grows to ~1e-12 relative (which lanes and FMA the runtime dispatch picks
/// depends on the machine), so the bound is 1e-11 — a wrong term would be off by ≥ 1e-6.
fn check_predictions(
    what: &str,
    params: &GpParams<f64>,
    spec: &NarxSpec,
    traj: &Trajectory,
    episode: &Episode,
) {
    let mut log = JitterLog::default();
    let gp = PreparedGp::new(params, &config(), &mut log).expect("gp");
    let pd: GpParams<Dual> = params.map(Dual::from_re);
    let gpd = PreparedGp::new(&pd, &config(), &mut log).expect("gp dual");
    let (lf, ld) = match &episode.excitation {
        msgp_core::rollout::Excitation::FeedForward => (None, None),
        msgp_core::rollout::Excitation::Feedback(p) => {
            (Some(p.lift::<f64>()), Some(p.lift::<Dual>()))
        }
    };
    let cf = lf
        .as_ref()
        .map_or(Control::FeedForward, |p| Control::Feedback(p.as_ref()));
    let cd = ld
        .as_ref()
        .map_or(Control::FeedForward, |p| Control::Feedback(p.as_ref()));
    let fast = simulate(&gp, spec, traj, &cf, traj.len(), &mut log).expect("fast rollout");
    let slow = simulate(&gpd, spec, traj, &cd, traj.len(), &mut log).expect("generic rollout");
    assert_eq!(fast.len(), slow.len());
    // means relative to the trajectory's scale (a step whose mean crosses zero has no scale of
    // its own); covariances relative to each step's own
    let mscale = slow
        .iter()
        .flat_map(|p| p.mean.iter().map(|v| v.re().abs()))
        .fold(0.0f64, f64::max);
    let (mut wm, mut wc, mut first) = (0.0f64, 0.0f64, 0.0f64);
    for (s, (a, b)) in fast.iter().zip(&slow).enumerate() {
        let bm: Vec<f64> = b.mean.iter().map(|v| v.re()).collect();
        let bc: Vec<f64> = b.cov.iter().map(|v| v.re()).collect();
        let (em, ec) = (
            rel(a.mean.as_slice(), &bm, mscale),
            rel(a.cov.as_slice(), &bc, 1e-300),
        );
        if s < 10 {
            first = first.max(em).max(ec);
        }
        wm = wm.max(em);
        wc = wc.max(ec);
    }
    println!(
        "{what}: {} steps, worst relative difference of predicted means {wm:.2e}, covariances \
         {wc:.2e} (first 10 steps {first:.2e})",
        fast.len()
    );
    assert!(wm.max(wc) <= 1e-11, "{what}: {wm:e} {wc:e}");
}

#[test]
fn open_loop_losses_and_predictions_match_generic_d4() {
    for seed in [3u64, 4, 5] {
        let spec = NarxSpec::siso(2, 2);
        let mut r = rng(seed);
        let (params, traj) = sys4_problem(&mut r, seed, 20, &spec, 150);
        let eps = vec![Episode::feed_forward(traj.clone())];
        check_loss(&format!("D4 seed {seed}"), &params, &spec, &eps);
        check_predictions(&format!("D4 seed {seed}"), &params, &spec, &traj, &eps[0]);
    }
}

#[test]
fn open_loop_loss_matches_generic_d20() {
    let spec = NarxSpec::siso(10, 10);
    let mut r = rng(7);
    let (_, traj) = sys4_problem(&mut r, 7, 1, &NarxSpec::siso(2, 2), 120);
    let mut params = random_gp(&mut r, 23, spec.input_dim(), 1);
    params.log_lengthscales.add_scalar_mut(0.5 * 5f64.ln());
    for i in 0..23 {
        let w = spec.window(&traj.y, &traj.u, 10 + 4 * i);
        for (k, v) in w.into_iter().enumerate() {
            params.pseudo_inputs[(i, k)] = v + 0.1 * normal(&mut r);
        }
    }
    let eps = vec![Episode::feed_forward(traj.clone())];
    check_loss("D20", &params, &spec, &eps);
    check_predictions("D20", &params, &spec, &traj, &eps[0]);
}

#[test]
fn closed_and_open_loop_two_outputs_match_generic() {
    for seed in [8u64, 9] {
        let mut r = rng(seed);
        let spec = NarxSpec {
            ly: 2,
            lu: 1,
            dy: 2,
            du: 1,
        };
        let traj = two_output_trajectory(&mut r, 60);
        let mut params = random_gp(&mut r, 17, spec.input_dim(), 2);
        for i in 0..17 {
            let w = spec.window(&traj.y, &traj.u, 2 + 3 * i);
            for (k, v) in w.into_iter().enumerate() {
                params.pseudo_inputs[(i, k)] = v + 0.1 * normal(&mut r);
            }
        }
        let eps = linear_feedback_episodes(&traj);
        check_loss(&format!("E2 seed {seed}"), &params, &spec, &eps);
        for ep in &eps {
            check_predictions(&format!("E2 seed {seed}"), &params, &spec, &traj, ep);
        }
    }
}
