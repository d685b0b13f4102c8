//! The filter likelihood ([`msgp_core::loss::filter`]):
//! 1. with the GP switched off it is the linear Kalman filter's likelihood (`kalman_nll`);
//! 2. its dual-number gradient matches central finite differences for every parameter group;
//! 3. its predicted moments match Monte Carlo propagation of the filtered window through the GP,
//!    and its update matches Gaussian conditioning in information form;
//! 4. its first step is the free run's, and on a noisy unstable plant (true model) it scores the
//!    data far better than the free run, with calibrated innovations.

mod common;

use common::{config, normal, random_gp, rng, sys4_problem, two_output_trajectory};
use msgp_core::data::Trajectory;
use msgp_core::fit::linear_kf::{KF_NOISE_FLOOR, KalmanParams, kalman_nll};
use msgp_core::gp::integrator::NO_GP_SIGNAL_VAR;
use msgp_core::gp::{GpConfig, GpParams, GpShape, MeanFunction, ParamGroup, PreparedGp};
use msgp_core::loss::{Complexity, filter_loss, filter_nll, filter_steps, msgp_loss};
use msgp_core::moments::MomentMatch;
use msgp_core::narx::NarxSpec;
use msgp_core::numeric::dual::gradient;
use msgp_core::numeric::linalg::JitterLog;
use msgp_core::rollout::Episode;
use nalgebra::{DMatrix, DVector};
use rand::rngs::StdRng;

// ---------------------------------------------------------------------------------------------
// linear plants

/// A linear window plant `f_{t+1} = A x̃_t + w`, `y = f + v`.
struct LinearPlant {
    spec: NarxSpec,
    a: DMatrix<f64>,
    q_std: f64,
    r_std: f64,
}

impl LinearPlant {
    /// Each output's own lags have the roots `roots[j]` (second order: `l_y = 2`); outputs
    /// are coupled by `0.03` at lag 0; inputs enter with small random gains.
    fn new(r: &mut StdRng, spec: NarxSpec, roots: &[(f64, f64)], q_std: f64, r_std: f64) -> Self {
        assert_eq!(spec.ly, 2);
        let mut a = DMatrix::zeros(spec.dy, spec.input_dim());
        for j in 0..spec.dy {
            let (r1, r2) = roots[j];
            a[(j, spec.y_index(0, j))] = r1 + r2;
            a[(j, spec.y_index(1, j))] = -r1 * r2;
            for i in 0..spec.dy {
                if i != j {
                    a[(j, spec.y_index(0, i))] = 0.03;
                }
            }
            for k in 0..spec.lu {
                for i in 0..spec.du {
                    a[(j, spec.u_index(k, i))] = 0.05 * normal(r);
                }
            }
        }
        Self {
            spec,
            a,
            q_std,
            r_std,
        }
    }

    fn simulate(&self, r: &mut StdRng, n: usize) -> Trajectory {
        let spec = self.spec;
        let phase: Vec<f64> = (0..4).map(|_| 3.0 * normal(r)).collect();
        let u = DMatrix::from_fn(n, spec.du, |t, i| {
            (0..4)
                .map(|k| (0.07 * (k as f64 + 1.0 + i as f64) * t as f64 + phase[k]).sin())
                .sum::<f64>()
        });
        let mut f = DMatrix::zeros(n, spec.dy);
        for t in 0..spec.warmup() {
            for j in 0..spec.dy {
                f[(t, j)] = 0.1 * normal(r);
            }
        }
        for t in spec.warmup() - 1..n - 1 {
            let w = DVector::from_vec(spec.window(&f, &u, t));
            let next = &self.a * w;
            for j in 0..spec.dy {
                f[(t + 1, j)] = next[j] + self.q_std * normal(r);
            }
        }
        let y = DMatrix::from_fn(n, spec.dy, |t, j| f[(t, j)] + self.r_std * normal(r));
        Trajectory::new(u, y).expect("trajectory")
    }

    /// The model of [`msgp_core::fit::linear_kf`]'s fits: the linear prior mean `A` and a GP that
    /// contributes nothing (one pseudo-input, zero pseudo-targets, signal variance
    /// `NO_GP_SIGNAL_VAR`), with the Kalman filter's noise floor.
    fn gp_off_model(&self) -> (GpParams<f64>, GpConfig) {
        let (e, d) = (self.spec.dy, self.spec.input_dim());
        let params = GpParams {
            pseudo_inputs: DMatrix::zeros(1, d),
            pseudo_targets: DMatrix::zeros(1, e),
            log_lengthscales: DMatrix::zeros(e, d),
            log_signal_var: DVector::from_element(e, NO_GP_SIGNAL_VAR.ln()),
            log_process_noise: DVector::from_element(e, (self.q_std * self.q_std).ln()),
            log_obs_noise: DVector::from_element(e, (self.r_std * self.r_std).ln()),
            linear_mean: self.a.clone(),
        };
        let cfg = GpConfig {
            mean: MeanFunction::Linear,
            noise_floor: KF_NOISE_FLOOR,
            ..GpConfig::default()
        };
        (params, cfg)
    }

    /// The Kalman filter's parameters for the same model. With zero pseudo-targets the GP adds
    /// no mean and no cross-covariance, only its latent variance
    /// `σ_f² − tr(K̃⁻¹ E[k kᵀ]) = σ_f²(1 − O(σ_f²/σ_x²))`, i.e. `NO_GP_SIGNAL_VAR` to within
    /// `1e-24` here: the process noise is raised by that (`compensate`) to compare like with
    /// like. Both add `KF_NOISE_FLOOR` to both noise variances.
    fn kalman_params(&self, compensate: bool) -> KalmanParams<f64> {
        let e = self.spec.dy;
        let extra = if compensate { NO_GP_SIGNAL_VAR } else { 0.0 };
        KalmanParams {
            a: self.a.clone(),
            log_process_noise: DVector::from_element(e, (self.q_std * self.q_std + extra).ln()),
            log_obs_noise: DVector::from_element(e, (self.r_std * self.r_std).ln()),
        }
    }
}

// ---------------------------------------------------------------------------------------------
// 1. GP off = Kalman filter

fn check_kalman(seed: u64, spec: NarxSpec, roots: &[(f64, f64)], n: usize) {
    let mut r = rng(seed);
    let plant = LinearPlant::new(&mut r, spec, roots, 0.02, 0.05);
    let traj = plant.simulate(&mut r, n);
    let (params, cfg) = plant.gp_off_model();
    let mut log = JitterLog::default();
    let gp = PreparedGp::new(&params, &cfg, &mut log).expect("prepare");
    let filt = filter_nll(&gp, &spec, &traj, &mut log).expect("filter");
    let (kf, kf_steps) = kalman_nll(
        &plant.kalman_params(true),
        &spec,
        &[&traj],
        &cfg.jitter,
        &mut log,
    )
    .expect("kalman");
    let (kf_raw, _) = kalman_nll(
        &plant.kalman_params(false),
        &spec,
        &[&traj],
        &cfg.jitter,
        &mut log,
    )
    .expect("kalman");
    let rel = (filt.nll - kf).abs() / kf.abs();
    println!(
        "seed {seed}, {spec:?}, {n} samples: filter {:.12e}, Kalman {kf:.12e}, rel {rel:.2e} \
         (without the σ_f² compensation {:.2e}); jitter {log:?}",
        filt.nll,
        (filt.nll - kf_raw).abs() / kf_raw.abs()
    );
    assert_eq!(filt.steps, kf_steps);
    assert_eq!(filt.steps, n - spec.warmup());
    assert!(
        rel <= 1e-10,
        "filter {} vs Kalman {kf}: rel {rel:e}",
        filt.nll
    );
    assert_eq!(log.events, 0, "no jitter expected");
}

#[test]
fn gp_off_filter_is_the_kalman_filter() {
    // an unstable and a stable second-order plant, one output, l_y = l_u = 2
    check_kalman(21, NarxSpec::siso(2, 2), &[(1.03, 0.9)], 80);
    check_kalman(22, NarxSpec::siso(2, 2), &[(0.95, 0.6)], 120);
    // two coupled outputs, one of them unstable, two inputs
    let spec = NarxSpec {
        ly: 2,
        lu: 2,
        dy: 2,
        du: 2,
    };
    check_kalman(23, spec, &[(1.02, 0.85), (0.9, 0.5)], 70);
    // more input than output lags: the start window covers l_u samples
    let spec = NarxSpec {
        ly: 2,
        lu: 3,
        dy: 1,
        du: 1,
    };
    check_kalman(24, spec, &[(0.98, 0.7)], 60);
}

// ---------------------------------------------------------------------------------------------
// 2. dual gradients vs finite differences

fn loss_at<T: MomentMatch>(
    shape: GpShape,
    flat: &[T],
    cfg: &GpConfig,
    spec: &NarxSpec,
    episodes: &[Episode],
) -> msgp_core::Result<T> {
    let params = GpParams::from_flat(shape, flat)?;
    let mut log = JitterLog::default();
    Ok(filter_loss(&params, cfg, spec, episodes, Complexity::None, &mut log)?.total())
}

/// Fourth-order central difference `(8[f(x+h) − f(x−h)] − [f(x+2h) − f(x−2h)]) / 12h`, as
/// `tests/gradients_fd.rs`.
fn fd(f: &dyn Fn(&[f64]) -> f64, x: &[f64], i: usize, h: f64) -> f64 {
    let at = |delta: f64| {
        let mut y = x.to_vec();
        y[i] += delta;
        f(&y)
    };
    (8.0 * (at(h) - at(-h)) - (at(2.0 * h) - at(-2.0 * h))) / (12.0 * h)
}

/// `real_tol`: how far the duals' real part may be from the f64 run. The duals run the generic
/// moment matching, f64 the vectorised kernel; both agree to rounding, but the latent variance
/// `S = σ_f² − tr(K̃⁻¹Q) + …` cancels when the filtered window is tight, and the two differ by up
/// to ~1e-13 of `S` (measured on the two-output case), which the innovation terms `e²/S`
/// carry into the sum.
fn check_gradients_with(
    params: &GpParams<f64>,
    cfg: &GpConfig,
    spec: &NarxSpec,
    eps: &[Episode],
    real_tol: f64,
) {
    let shape = params.shape().expect("shape");
    let x = params.to_flat();
    let active: Vec<usize> = (0..x.len()).collect();
    let (value, grad) =
        gradient(&x, &active, 0, |xd| loss_at(shape, xd, cfg, spec, eps)).expect("dual gradient");
    let f64_value = loss_at(shape, &x, cfg, spec, eps).expect("f64 loss");
    let real_err = (value - f64_value).abs() / f64_value.abs().max(1.0);
    println!("dual real part {value:.15e} vs f64 {f64_value:.15e}: rel {real_err:.1e}");
    assert!(
        real_err <= real_tol,
        "dual real part {value:e} vs f64 {f64_value:e}"
    );
    let f = |y: &[f64]| loss_at(shape, y, cfg, spec, eps).expect("loss");
    for group in ParamGroup::ALL {
        let range = shape.group_range(group);
        if group == ParamGroup::LinearMean && cfg.mean == MeanFunction::Zero {
            assert!(grad[range].iter().all(|g| *g == 0.0));
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
            "{:?} {group:?}: |g|∞ = {scale:.3e}, max |dual − fd| = {err:.3e}, rel {:.2e}",
            cfg.mean,
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

/// Under the zero prior mean and again with a linear prior mean (small random `A` near the
/// identity on the lag-0 outputs).
fn check_gradients(params: &GpParams<f64>, spec: &NarxSpec, eps: &[Episode], real_tol: f64) {
    check_gradients_with(params, &config(), spec, eps, real_tol);
    let mut with_mean = params.clone();
    let (e, d) = with_mean.linear_mean.shape();
    with_mean.linear_mean = DMatrix::from_fn(e, d, |a, k| {
        0.05 * ((3 * a + 7 * k) as f64).sin() + if a == k { 0.5 } else { 0.0 }
    });
    let cfg = GpConfig {
        mean: MeanFunction::Linear,
        ..config()
    };
    check_gradients_with(&with_mean, &cfg, spec, eps, real_tol);
}

#[test]
fn filter_gradients_match_finite_differences() {
    // one output, system 4 (nonlinear), 60 samples and a 50-sample slice
    let mut r = rng(31);
    let spec = NarxSpec::siso(2, 1);
    let (params, traj) = sys4_problem(&mut r, 3, 8, &spec, 60);
    let eps = vec![
        Episode::feed_forward(traj.clone()),
        Episode::feed_forward(traj.slice(10, 60)),
    ];
    check_gradients(&params, &spec, &eps, 1e-14);
    // two outputs with cross-covariances, 55 samples
    let mut r = rng(32);
    let spec = NarxSpec {
        ly: 1,
        lu: 1,
        dy: 2,
        du: 1,
    };
    let params = random_gp(&mut r, 8, spec.input_dim(), 2);
    let traj = two_output_trajectory(&mut r, 55);
    check_gradients(&params, &spec, &[Episode::feed_forward(traj)], 2e-13);
}

// ---------------------------------------------------------------------------------------------
// 3. Monte Carlo and conditioning

const MC_SAMPLES: usize = 200_000;

/// `B = U diag(√λ)` of `cov = U Λ Uᵀ`, so `x = μ + B z` samples a possibly singular Gaussian (the window's inputs have zero
/// variance).
fn sampler(cov: &DMatrix<f64>) -> DMatrix<f64> {
    let eig = cov.clone().symmetric_eigen();
    let sq = eig.eigenvalues.map(|l| l.max(0.0).sqrt());
    &eig.eigenvectors * DMatrix::from_diagonal(&sq)
}

/// Worst `|MC − exact| / (5 SE + 1e-9)` over the checks; each check asserts it is ≤ 1.
#[derive(Default)]
struct Check {
    worst: f64,
    count: usize,
}

impl Check {
    /// `values` are per-sample contributions whose mean estimates `exact`.
    fn mean_of(&mut self, what: &str, values: &[f64], exact: f64) -> (f64, f64) {
        let n = values.len() as f64;
        let mean = values.iter().sum::<f64>() / n;
        let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
        let se = (var / n).sqrt();
        let z = (mean - exact).abs() / (5.0 * se + 1e-9);
        self.worst = self.worst.max(z);
        self.count += 1;
        assert!(
            z <= 1.0,
            "{what}: filter {exact:.6e}, Monte Carlo {mean:.6e} ± {se:.2e}"
        );
        (mean, se)
    }
}

/// A short episode simulated from the GP model itself (f drawn from the GP's predictive at the
/// true window, plus process and observation noise).
fn simulate_gp(r: &mut StdRng, gp: &PreparedGp<f64>, spec: &NarxSpec, n: usize) -> Trajectory {
    let u = DMatrix::from_fn(n, spec.du, |t, i| 0.8 * (0.5 * t as f64 + i as f64).sin());
    let mut f = DMatrix::from_fn(n, spec.dy, |_, _| 0.3 * normal(r));
    for t in spec.warmup() - 1..n - 1 {
        let w = spec.window(&f, &u, t);
        for (j, (m, v)) in gp.predict(&w).into_iter().enumerate() {
            f[(t + 1, j)] = m + (v.max(0.0) + gp.outputs[j].sx2).sqrt() * normal(r);
        }
    }
    let y = DMatrix::from_fn(n, spec.dy, |t, j| {
        f[(t, j)] + gp.outputs[j].sy2.sqrt() * normal(r)
    });
    Trajectory::new(u, y).expect("trajectory")
}

/// Conditions `N(m, P)` on `y = H x + ε`, `ε ~ N(0, R)` (`H` the first `dy` coordinates) in
/// information form on the block `0..n` of positive variance (the rest is deterministic):
/// `P⁺ = (P⁻¹ + HᵀR⁻¹H)⁻¹`, `m⁺ = P⁺ (P⁻¹ m + HᵀR⁻¹ y)`. Also returns `−log N(y; Hm, HPHᵀ+R)`
/// from a dense inverse and determinant.
fn condition_information_form(
    m: &DVector<f64>,
    p: &DMatrix<f64>,
    y: &[f64],
    r: &[f64],
    n: usize,
) -> (DVector<f64>, DMatrix<f64>, f64) {
    let dy = y.len();
    let pl = p.view((0, 0), (n, n)).into_owned();
    let ml = m.rows(0, n).into_owned();
    let pinv = pl.clone().try_inverse().expect("P invertible");
    let mut lam = pinv.clone();
    let mut eta = &pinv * &ml;
    for j in 0..dy {
        lam[(j, j)] += 1.0 / r[j];
        eta[j] += y[j] / r[j];
    }
    let post = lam.try_inverse().expect("Λ invertible");
    let post_mean = &post * eta;
    let mut full_mean = m.clone();
    full_mean.rows_mut(0, n).copy_from(&post_mean);
    let mut full_cov = DMatrix::zeros(m.len(), m.len());
    full_cov.view_mut((0, 0), (n, n)).copy_from(&post);
    let s = DMatrix::from_fn(dy, dy, |i, j| p[(i, j)] + if i == j { r[i] } else { 0.0 });
    let e = DVector::from_fn(dy, |i, _| y[i] - m[i]);
    let quad = (e.transpose() * s.clone().try_inverse().expect("S invertible") * &e)[0];
    let nll = 0.5 * (quad + s.determinant().ln() + dy as f64 * (2.0 * std::f64::consts::PI).ln());
    (full_mean, full_cov, nll)
}

fn check_monte_carlo(seed: u64, spec: NarxSpec, m: usize, steps: usize) {
    let mut r = rng(seed);
    let (d, dy) = (spec.input_dim(), spec.dy);
    let mut params = random_gp(&mut r, m, d, dy);
    // a visibly nonlinear mean: large pseudo-targets, short length-scales, and windows
    // uncertain enough (sensor noise σ_y ≈ 0.2) that E[f] differs from f(E[x̃])
    params.pseudo_targets *= 1.5;
    params.log_lengthscales.fill(-0.5);
    params.log_obs_noise.fill((0.04f64).ln());
    params.log_process_noise.fill((0.01f64).ln());
    let cfg = config();
    let mut log = JitterLog::default();
    let gp = PreparedGp::new(&params, &cfg, &mut log).expect("prepare");
    let traj = simulate_gp(&mut r, &gp, &spec, spec.warmup() + steps);
    let mut check = Check::default();
    let mut worst_update = 0.0f64;
    let mut worst_step_nll = 0.0f64;
    let mut nonlinear = 0.0f64;
    let latent = spec.ly * dy;
    filter_steps(&gp, &spec, &traj, &mut log, |s| {
        // sample windows from the previous step's filtered Gaussian, propagate each through
        // the GP (f from its predictive at the sample, plus process noise)
        let b = sampler(s.window_cov);
        let mut xs = vec![vec![0.0; MC_SAMPLES]; dy];
        let mut ws = vec![vec![0.0; MC_SAMPLES]; d];
        let mut w = vec![0.0; d];
        for k in 0..MC_SAMPLES {
            let z = DVector::from_fn(d, |_, _| normal(&mut r));
            let wv = s.window_mean + &b * z;
            for i in 0..d {
                w[i] = wv[i];
                ws[i][k] = wv[i] - s.window_mean[i];
            }
            for (j, (mean, var)) in gp.predict(&w).into_iter().enumerate() {
                xs[j][k] = mean + (var.max(0.0) + gp.outputs[j].sx2).sqrt() * normal(&mut r);
            }
        }
        let at_mean = gp.predict(s.window_mean.as_slice());
        for a in 0..dy {
            let (mc, se) = check.mean_of(&format!("t={} E[x_{a}]", s.t), &xs[a], s.x_mean[a]);
            nonlinear = nonlinear.max((mc - at_mean[a].0).abs() / se);
            for b2 in a..dy {
                let v: Vec<f64> = (0..MC_SAMPLES)
                    .map(|k| (xs[a][k] - s.x_mean[a]) * (xs[b2][k] - s.x_mean[b2]))
                    .collect();
                check.mean_of(
                    &format!("t={} Cov[x_{a}, x_{b2}]", s.t),
                    &v,
                    s.x_cov[(a, b2)],
                );
            }
            for i in 0..d {
                let v: Vec<f64> = (0..MC_SAMPLES)
                    .map(|k| ws[i][k] * (xs[a][k] - s.x_mean[a]))
                    .collect();
                check.mean_of(
                    &format!("t={} Cov[x̃_{i}, x_{a}]", s.t),
                    &v,
                    s.cross_cov[(i, a)],
                );
            }
        }
        // the update against conditioning in information form
        let y: Vec<f64> = (0..dy).map(|j| traj.y[(s.t, j)]).collect();
        let rv: Vec<f64> = gp.outputs.iter().map(|o| o.sy2).collect();
        let (cm, cc, cnll) = condition_information_form(s.prior_mean, s.prior_cov, &y, &rv, latent);
        let scale = s.prior_cov.abs().max();
        let err_m = (s.filtered_mean - &cm).abs().max() / s.prior_mean.abs().max().max(1.0);
        let err_c = (s.filtered_cov - &cc).abs().max() / scale;
        worst_update = worst_update.max(err_m).max(err_c);
        worst_step_nll = worst_step_nll.max((s.nll - cnll).abs() / cnll.abs().max(1.0));
        Ok(())
    })
    .expect("filter");
    println!(
        "seed {seed}, {spec:?}, m={m}, {steps} steps: {} MC checks, worst |error|/(5 SE) = {:.3}; \
         update vs information form {worst_update:.1e}, step NLL {worst_step_nll:.1e}; \
         largest |E_MC[x] − f(E[x̃])| = {nonlinear:.0} SE",
        check.count, check.worst
    );
    assert!(
        worst_update <= 1e-10,
        "update vs conditioning: {worst_update:e}"
    );
    assert!(
        worst_step_nll <= 1e-12,
        "step NLL vs dense density: {worst_step_nll:e}"
    );
    assert!(
        nonlinear > 20.0,
        "the episode is too linear to test moment matching ({nonlinear:.1} SE)"
    );
}

#[test]
fn filter_predictions_match_monte_carlo() {
    check_monte_carlo(41, NarxSpec::siso(2, 1), 6, 8);
    let spec = NarxSpec {
        ly: 1,
        lu: 1,
        dy: 2,
        du: 1,
    };
    check_monte_carlo(42, spec, 5, 6);
}

// ---------------------------------------------------------------------------------------------
// 4. filter vs free run

#[test]
fn first_step_is_the_free_run_and_the_filter_beats_it_on_an_unstable_plant() {
    let mut r = rng(51);
    let spec = NarxSpec::siso(2, 2);
    let plant = LinearPlant::new(&mut r, spec, &[(1.04, 0.9)], 0.02, 0.05);
    let (params, cfg) = plant.gp_off_model();
    let trajs: Vec<Trajectory> = (0..20).map(|_| plant.simulate(&mut r, 100)).collect();
    let episodes: Vec<Episode> = trajs.iter().cloned().map(Episode::feed_forward).collect();

    // one scored step: the filter's prediction is the free run's, bit for bit
    let short: Vec<Episode> = trajs
        .iter()
        .map(|t| Episode::feed_forward(t.slice(0, spec.warmup() + 1)))
        .collect();
    let mut log = JitterLog::default();
    let free1 = msgp_loss(&params, &cfg, &spec, &short, Complexity::None, &mut log).expect("free");
    let filt1 = filter_loss(&params, &cfg, &spec, &short, Complexity::None, &mut log).expect("f");
    assert_eq!(free1.steps, filt1.steps);
    assert_eq!(free1.nll, filt1.nll, "one step: free run vs filter");

    // the whole episodes: the free run's variances grow with the unstable pole, the filter's
    // stay at the one-step level
    let free = msgp_loss(&params, &cfg, &spec, &episodes, Complexity::None, &mut log).expect("f");
    let filt = filter_loss(&params, &cfg, &spec, &episodes, Complexity::None, &mut log).expect("f");
    let per = |v: f64| v / filt.steps as f64;
    println!(
        "per step: filter {:.4}, free run {:.4} ({} steps)",
        per(filt.nll),
        per(free.nll),
        filt.steps
    );
    assert_eq!(free.steps, filt.steps);
    assert!(
        per(filt.nll) < per(free.nll) - 1.0,
        "filter {} vs free run {}",
        per(filt.nll),
        per(free.nll)
    );

    // under the true model the normalised innovations e²/S are independent χ²₁: mean 1 (SE
    // 0.032 over 1960 steps; 1.006 over 19600 steps of 200 episodes)
    let gp = PreparedGp::new(&params, &cfg, &mut log).expect("prepare");
    let mut nis = Vec::new();
    for t in &trajs {
        filter_steps(&gp, &spec, t, &mut log, |s| {
            nis.push(s.innovation[0].powi(2) / s.innovation_cov[(0, 0)]);
            Ok(())
        })
        .expect("filter");
    }
    let mean_nis = nis.iter().sum::<f64>() / nis.len() as f64;
    println!(
        "mean normalised innovation {mean_nis:.3} over {} steps",
        nis.len()
    );
    assert!((mean_nis - 1.0).abs() < 0.15, "NIS {mean_nis}");
    // the same check on a wrong model (process noise 10× too small) fails it
    let mut wrong = params.clone();
    wrong.log_process_noise[0] -= (10.0f64).ln();
    let gp = PreparedGp::new(&wrong, &cfg, &mut log).expect("prepare");
    let mut nis = Vec::new();
    for t in &trajs {
        filter_steps(&gp, &spec, t, &mut log, |s| {
            nis.push(s.innovation[0].powi(2) / s.innovation_cov[(0, 0)]);
            Ok(())
        })
        .expect("filter");
    }
    let wrong_nis = nis.iter().sum::<f64>() / nis.len() as f64;
    println!("mean normalised innovation, process noise /10: {wrong_nis:.3}");
    assert!(wrong_nis > 1.5, "a wrong model's NIS {wrong_nis}");
}

// ---------------------------------------------------------------------------------------------
// 5. the model's one-step-ahead filtered predictions (`msgp eval --filtered`)

/// `Model::filtered` in original units: its first prediction is the free simulation's first
/// step (nothing measured after the start window yet), and the Gaussian log density of the
/// measured outputs under its predictions is the filter likelihood in normalised units plus
/// the normalisation's Jacobian `ln σ_y` per step (a centred and scaled MSGP model, SISO).
#[test]
fn filtered_predictions_are_the_filter_in_original_units() {
    use msgp_core::fit::{FitSettings, MsgpSettings, fit};
    use msgp_core::loss::Likelihood;
    let mut r = rng(31);
    let spec = NarxSpec::siso(2, 2);
    let plant = LinearPlant::new(&mut r, spec, &[(1.02, 0.95)], 0.01, 0.05);
    let traj = plant.simulate(&mut r, 200);
    let settings = FitSettings {
        ly: 2,
        lu: 2,
        method: MsgpSettings {
            inducing: 10,
            iterations: 5,
            likelihood: Likelihood::Filter,
            validation_fraction: 0.0,
            alternative: None,
            ..MsgpSettings::default()
        }
        .into(),
        ..FitSettings::default()
    };
    let (model, _) = fit(std::slice::from_ref(&traj), &settings, &mut |_| {}).expect("fit");
    assert!(
        model.normalizer.y_mean[0] != 0.0,
        "centred, so the test sees the shift"
    );
    let filtered = model.filtered(&traj).expect("filtered");
    let free = model.simulate(&traj).expect("free run");
    assert_eq!(filtered.start, 2);
    assert_eq!(filtered.mean.nrows(), traj.len() - 2);
    let close = |a: f64, b: f64| (a - b).abs() <= 1e-10 * b.abs().max(1e-12);
    assert!(close(filtered.mean[(0, 0)], free.mean[(0, 0)]));
    assert!(close(filtered.var[(0, 0)], free.var[(0, 0)]));
    assert!(
        filtered.var[(5, 0)] < free.var[(5, 0)],
        "later steps have seen the outputs"
    );
    let by_hand: f64 = (0..filtered.mean.nrows())
        .map(|i| {
            let (m, v) = (filtered.mean[(i, 0)], filtered.var[(i, 0)]);
            let e = traj.y[(i + 2, 0)] - m;
            0.5 * (e * e / v + v.ln() + (2.0 * std::f64::consts::PI).ln())
        })
        .sum();
    let mut log = JitterLog::default();
    let gp = PreparedGp::new(&model.params, &model.config, &mut log).expect("gp");
    let norm = model.normalizer.apply(&traj);
    let f = filter_nll(&gp, &spec, &norm, &mut log).expect("filter");
    let reference = f.nll + f.steps as f64 * model.normalizer.y_std[0].ln();
    assert!(
        (by_hand - reference).abs() <= 1e-9 * reference.abs(),
        "{by_hand} vs {reference}"
    );
}
