//! The policies' moments against Monte Carlo: the saturated PID (directly and through the
//! normalisation adapter), the saturated state feedback on a window, and the RBF network
//! (its network exactly, and with the saturation's moment-matching approximation); and PID
//! gradients through a 60-step closed-loop rollout against finite differences.

mod common;

use common::{config, normal, random_cov, random_gp, rng};
use msgp_core::data::Normalizer;
use msgp_core::data::Trajectory;
use msgp_core::gp::PreparedGp;
use msgp_core::moments::MomentMatch;
use msgp_core::narx::NarxSpec;
use msgp_core::numeric::dual::{Dual, gradient};
use msgp_core::numeric::linalg::{JitterLog, JitterPolicy, cholesky};
use msgp_core::numeric::scalar::Scalar;
use msgp_core::policy::{
    CommandBounds, FeedbackPolicy, Normalized, PidPolicy, RbfPolicy, StateFeedback,
};
use msgp_core::rollout::{Control, rollout};
use nalgebra::{DMatrix, DVector};

const N: usize = 200_000;

fn pid<T: Scalar>(g: &[T]) -> PidPolicy<T> {
    // d_u = 1, d_y = 2 (angle, position): PD on the angle, PID on the position
    let z = T::zero();
    PidPolicy::new(
        DMatrix::from_row_slice(1, 2, &[g[0], g[1]]),
        DMatrix::from_row_slice(1, 2, &[z, g[2]]),
        DMatrix::from_row_slice(1, 2, &[g[3], g[4]]),
        0.02,
        vec![3.0],
    )
    .expect("policy")
}

fn check_against_mc(
    policy: &dyn FeedbackPolicy<f64>,
    act: &dyn Fn(&[f64]) -> Vec<f64>,
    m: &DVector<f64>,
    s: &DMatrix<f64>,
    seed: u64,
) {
    let pm = policy.moments(m, s).expect("moments");
    let l = cholesky(s, &JitterPolicy::default(), "S").expect("chol").l;
    let mut r = rng(seed);
    let no = pm.mean.len();
    let nq = m.len();
    let mut sum_o = vec![0.0; no];
    let mut outs = Vec::with_capacity(N);
    let mut qs = Vec::with_capacity(N);
    for _ in 0..N {
        let q = m + &l * DVector::from_fn(nq, |_, _| normal(&mut r));
        let o = act(q.as_slice());
        for k in 0..no {
            sum_o[k] += o[k];
        }
        outs.push(o);
        qs.push(q);
    }
    let io = s * &pm.c;
    let tol = |samples: &Vec<f64>, exact: f64, what: String| {
        let n = samples.len() as f64;
        let mean = samples.iter().sum::<f64>() / n;
        let se = (samples.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0) / n).sqrt();
        assert!(
            (mean - exact).abs() <= 5.0 * se + 1e-10,
            "{what}: exact {exact:.6e} vs MC {mean:.6e} ± {se:.1e}"
        );
    };
    for i in 0..no {
        tol(
            &outs.iter().map(|o| o[i]).collect(),
            pm.mean[i],
            format!("mean[{i}]"),
        );
        for j in 0..no {
            let v = outs
                .iter()
                .map(|o| (o[i] - pm.mean[i]) * (o[j] - pm.mean[j]))
                .collect();
            tol(&v, pm.cov[(i, j)], format!("cov[{i},{j}]"));
        }
        for k in 0..nq {
            let v = qs
                .iter()
                .zip(&outs)
                .map(|(q, o)| (q[k] - m[k]) * (o[i] - pm.mean[i]))
                .collect();
            tol(&v, io[(k, i)], format!("cov(q[{k}], o[{i}])"));
        }
    }
}

#[test]
fn pid_moments_match_monte_carlo() {
    let mut r = rng(41);
    let policy = pid(&[20.0, 1.5, 0.3, 3.0, 1.2]);
    let m = DVector::from_vec(vec![0.02, 0.05, 0.018, 0.04, 0.002, 0.01]);
    let s = random_cov(&mut r, 6, 4e-4);
    let act = |q: &[f64]| {
        let (u, p) = policy.act(&q[..2], &q[2..]);
        u.into_iter().chain(p).collect::<Vec<f64>>()
    };
    check_against_mc(&policy, &act, &m, &s, 42);
}

#[test]
fn normalized_adapter_matches_monte_carlo() {
    let mut r = rng(43);
    let inner = pid(&[20.0, 1.5, 0.3, 3.0, 1.2]);
    let normalizer = Normalizer {
        u_mean: vec![0.1],
        u_std: vec![0.8],
        y_mean: vec![0.01, -0.03],
        y_std: vec![0.05, 0.2],
    };
    let policy = Normalized {
        inner: inner.clone(),
        normalizer: normalizer.clone(),
    };
    let m = DVector::from_vec(vec![0.3, -0.2, 0.018, 0.04, 0.002, 0.01]);
    let s = random_cov(&mut r, 6, 0.05);
    let act = |q: &[f64]| {
        let y = [q[0] * 0.05 + 0.01, q[1] * 0.2 - 0.03];
        let (u, p) = inner.act(&y, &q[2..]);
        std::iter::once((u[0] - 0.1) / 0.8)
            .chain(p)
            .collect::<Vec<f64>>()
    };
    check_against_mc(&policy, &act, &m, &s, 44);
}

/// A window of two observations (d_y = 2) and two past commands (d_u = 1), bounds [−1, 3]:
/// the saturation active (the command's mean sits off the range's middle).
#[test]
fn state_feedback_moments_match_monte_carlo() {
    let mut r = rng(47);
    let bounds = CommandBounds::new(vec![-1.0], vec![3.0]).expect("bounds");
    let policy = StateFeedback::new(
        DMatrix::from_row_slice(1, 6, &[2.0, -1.5, 0.8, 0.4, -0.3, 0.2]),
        DVector::from_vec(vec![0.7]),
        2,
        (2, 2),
        bounds,
    )
    .expect("policy");
    assert_eq!(FeedbackPolicy::<f64>::state_dim(&policy), 4);
    let m = DVector::from_vec(vec![0.3, -0.2, 0.25, -0.1, 0.5, 0.4]);
    let s = random_cov(&mut r, 6, 0.2);
    let act = |q: &[f64]| {
        let (u, p) = policy.act(&q[..2], &q[2..]).expect("act");
        u.into_iter().chain(p).collect::<Vec<f64>>()
    };
    check_against_mc(&policy, &act, &m, &s, 48);
}

/// An RBF network of five centres on three observations, two commands.
fn rbf(bounds: CommandBounds, r: &mut rand::rngs::StdRng) -> RbfPolicy<f64> {
    RbfPolicy::new(
        DMatrix::from_fn(5, 3, |_, _| 0.6 * normal(r)),
        DMatrix::from_fn(5, 2, |_, _| 1.5 * normal(r)),
        DVector::from_vec(vec![-0.3, 0.0, -0.6]),
        bounds,
    )
    .expect("rbf")
}

/// With bounds far wider than the network's output the saturation is the identity to 1e-8
/// (`sat(ũ) = ũ − 2ũ³/(9h²) + …`), so the policy's moments are the network's: exact.
#[test]
fn rbf_network_moments_match_monte_carlo() {
    let mut r = rng(49);
    let wide = CommandBounds::new(vec![-1e5, -1e5], vec![1e5, 1e5]).expect("bounds");
    let policy = rbf(wide, &mut r);
    let m = DVector::from_vec(vec![0.2, -0.1, 0.3]);
    let s = random_cov(&mut r, 3, 0.4);
    let act = |q: &[f64]| policy.act(q).expect("act");
    check_against_mc(&policy, &act, &m, &s, 50);
}

/// Squashed into [−1, 2] and [0, 1]: the network's output `ũ` is moment-matched as a Gaussian
/// jointly with the observation (PILCO's approximation), and the policy's moments are then
/// exact for that Gaussian. Monte Carlo over `[q; ũ] ~ N([m; M], [[Σ, ΣV], [VᵀΣ, S]])` (the
/// network's exact moments, from the wide-bounds policy) checks the saturation into
/// asymmetric bounds, its covariance and `C` to five standard errors.
#[test]
fn rbf_policy_moments_match_monte_carlo_of_the_moment_matched_network() {
    let mut r = rng(51);
    let wide = CommandBounds::new(vec![-1e5, -1e5], vec![1e5, 1e5]).expect("bounds");
    let network = rbf(wide, &mut r);
    let bounds = CommandBounds::new(vec![-1.0, 0.0], vec![2.0, 1.0]).expect("bounds");
    let policy = RbfPolicy {
        bounds: bounds.clone(),
        ..network.clone()
    };
    let m = DVector::from_vec(vec![0.2, -0.1, 0.3]);
    let s = random_cov(&mut r, 3, 0.4);
    let net = network.moments(&m, &s).expect("network");
    let pm = policy.moments(&m, &s).expect("moments");
    assert!(pm.cov[(0, 0)] > 0.05 && pm.cov[(1, 1)] > 0.01, "{}", pm.cov);
    // the joint Gaussian of [q; ũ]
    let sv = &s * &net.c;
    let mut joint = DMatrix::zeros(5, 5);
    joint.view_mut((0, 0), (3, 3)).copy_from(&s);
    joint.view_mut((0, 3), (3, 2)).copy_from(&sv);
    joint.view_mut((3, 0), (2, 3)).copy_from(&sv.transpose());
    joint.view_mut((3, 3), (2, 2)).copy_from(&net.cov);
    let jm = DVector::from_iterator(5, m.iter().chain(net.mean.iter()).copied());
    let l = cholesky(&joint, &JitterPolicy::default(), "joint")
        .expect("chol")
        .l;
    let mut r = rng(52);
    let (mut u_sum, mut uu, mut qu) = ([0.0; 2], [[0.0; 2]; 2], [[0.0; 2]; 3]);
    let mut samples = Vec::with_capacity(N);
    for _ in 0..N {
        let x = &jm + &l * DVector::from_fn(5, |_, _| normal(&mut r));
        let u = bounds.saturate(&[x[3], x[4]]);
        samples.push((x, u));
    }
    for (_, u) in &samples {
        for i in 0..2 {
            u_sum[i] += u[i] / N as f64;
        }
    }
    let se = |v: &[f64]| {
        let n = v.len() as f64;
        let mean = v.iter().sum::<f64>() / n;
        let var = v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0);
        (mean, (var / n).sqrt())
    };
    let io = &s * &pm.c;
    for i in 0..2 {
        let (mc, err) = se(&samples.iter().map(|(_, u)| u[i]).collect::<Vec<_>>());
        assert!(
            (mc - pm.mean[i]).abs() <= 5.0 * err,
            "mean[{i}]: {} vs MC {mc} ± {err}",
            pm.mean[i]
        );
        for j in 0..2 {
            let v: Vec<f64> = samples
                .iter()
                .map(|(_, u)| (u[i] - u_sum[i]) * (u[j] - u_sum[j]))
                .collect();
            let (mc, err) = se(&v);
            uu[i][j] = mc;
            assert!(
                (mc - pm.cov[(i, j)]).abs() <= 5.0 * err + 1e-9,
                "cov[{i},{j}]: {} vs MC {mc} ± {err}",
                pm.cov[(i, j)]
            );
        }
        for k in 0..3 {
            let v: Vec<f64> = samples
                .iter()
                .map(|(x, u)| (x[k] - m[k]) * (u[i] - u_sum[i]))
                .collect();
            let (mc, err) = se(&v);
            qu[k][i] = mc;
            assert!(
                (mc - io[(k, i)]).abs() <= 5.0 * err + 1e-9,
                "cov(q[{k}], u[{i}]): {} vs MC {mc} ± {err}",
                io[(k, i)]
            );
        }
    }
    println!("Cov[u] MC {uu:?}, Cov(q, u) MC {qu:?}");
}

#[test]
fn policy_gradients_through_a_closed_loop_rollout_match_finite_differences() {
    let mut r = rng(45);
    let spec = NarxSpec {
        ly: 2,
        lu: 1,
        dy: 2,
        du: 1,
    };
    let params = random_gp(&mut r, 10, spec.input_dim(), 2);
    let n = 60;
    let y = DMatrix::from_fn(n, 2, |t, j| 0.1 * ((t as f64) * 0.2 + j as f64).sin());
    let traj = Trajectory::new(DMatrix::zeros(n, 1), y).expect("traj");
    let gains = [0.8, 0.3, 0.1, 0.2, 0.05];
    // a cost-like functional of the whole predicted trajectory
    fn total<T: MomentMatch>(
        params: &msgp_core::gp::GpParams<f64>,
        spec: &NarxSpec,
        traj: &Trajectory,
        g: &[T],
    ) -> msgp_core::Result<T> {
        let p = params.map(msgp_core::numeric::scalar::c::<T>);
        let mut log = JitterLog::default();
        let gp = PreparedGp::new(&p, &config(), &mut log)?;
        let policy = pid(g);
        let mut acc = T::zero();
        rollout(
            &gp,
            spec,
            traj,
            &Control::Feedback(&policy),
            traj.len(),
            &mut log,
            |s| {
                acc += s.mean[0] * s.mean[0] + s.cov[(0, 0)] + s.mean[1] * s.cov[(1, 1)];
                Ok(())
            },
        )?;
        Ok(acc)
    }
    let active: Vec<usize> = (0..5).collect();
    let (value, g) = gradient(&gains, &active, 1, |x: &[Dual]| {
        total(&params, &spec, &traj, x)
    })
    .expect("dual");
    let f64_value = total(&params, &spec, &traj, &gains).expect("f64");
    assert!((value - f64_value).abs() <= 1e-14 * f64_value.abs());
    for k in 0..5 {
        let h = 1e-4;
        let at = |d: f64| {
            let mut x = gains;
            x[k] += d;
            total(&params, &spec, &traj, &x).expect("f64")
        };
        let fd = (8.0 * (at(h) - at(-h)) - (at(2.0 * h) - at(-2.0 * h))) / (12.0 * h);
        assert!(
            (fd - g[k]).abs() <= 1e-6 * fd.abs().max(1e-3),
            "gain {k}: dual {} vs fd {fd}",
            g[k]
        );
    }
}
