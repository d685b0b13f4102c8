//! Moment matching against Monte Carlo: mean, variance (with cross-covariances between outputs)
//! and input–output covariance, for random GPs and random Gaussian inputs.
//!
//! The Monte Carlo reference integrates the GP's conditional moments over `x ~ N(μ, Σ)`:
//! `E[f] = E[μ(x)]`, `Cov[f_a, f_b] = Cov[μ_a(x), μ_b(x)] + δ_ab E[σ_a²(x)]`,
//! `Cov[x, f_a] = Cov[x, μ_a(x)]`, with 2·10⁵ samples. Each check allows 5 Monte Carlo standard
//! errors (estimated from the same samples) plus 1e-9, so a wrong formula fails.

mod common;

use common::{config, normal, random_cov, random_gp, rng};
use msgp_core::gp::{MeanFunction, PreparedGp};
use msgp_core::moments::mean::add_linear_mean;
use msgp_core::moments::moment_match;
use msgp_core::numeric::linalg::{JitterLog, JitterPolicy, cholesky};
use nalgebra::{DMatrix, DVector};

const SAMPLES: usize = 200_000;

struct Check {
    worst: f64,
    count: usize,
}

impl Check {
    fn new() -> Self {
        Self {
            worst: 0.0,
            count: 0,
        }
    }
    /// `values` are per-sample contributions whose mean estimates `exact`.
    fn mean_of(&mut self, what: &str, values: &[f64], exact: f64) {
        let n = values.len() as f64;
        let mean = values.iter().sum::<f64>() / n;
        let var = values.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
        let se = (var / n).sqrt();
        let z = (mean - exact).abs() / (5.0 * se + 1e-9);
        self.worst = self.worst.max(z);
        self.count += 1;
        assert!(
            (mean - exact).abs() <= 5.0 * se + 1e-9,
            "{what}: moment matching {exact:.6e}, Monte Carlo {mean:.6e} ± {se:.2e}"
        );
    }
}

fn check_case(seed: u64, m: usize, d: usize, e: usize, input_scale: f64) {
    check_case_with(seed, m, d, e, input_scale, false);
}

/// With `linear`, the GP has a random linear prior mean `A x̃` and the moments are
/// `moment_match` followed by `add_linear_mean`; the reference samples `gp.predict`, which
/// includes `A x̃`.
fn check_case_with(seed: u64, m: usize, d: usize, e: usize, input_scale: f64, linear: bool) {
    let mut r = rng(seed);
    let mut params = random_gp(&mut r, m, d, e);
    let mut cfg = config();
    if linear {
        params.linear_mean = DMatrix::from_fn(e, d, |_, _| normal(&mut r));
        cfg.mean = MeanFunction::Linear;
    }
    let mut log = JitterLog::default();
    let gp = PreparedGp::new(&params, &cfg, &mut log).expect("prepare");
    let mu = DVector::from_fn(d, |_, _| 0.5 * normal(&mut r));
    let mut sigma = random_cov(&mut r, d, input_scale);
    // a deterministic input component, as in open-loop rollouts
    if d > 2 {
        for k in 0..d {
            sigma[(d - 1, k)] = 0.0;
            sigma[(k, d - 1)] = 0.0;
        }
    }
    let mut mm = moment_match(&gp, &mu, &sigma, &mut log).expect("moment match");
    if let Some(a) = &gp.linear_mean {
        add_linear_mean(a, &mu, &sigma, &mut mm);
        // V = Σ⁻¹ Cov[x̃, f] must stay consistent with the input–output covariance
        let err = (&sigma * &mm.v - &mm.io_cov).abs().max();
        assert!(
            err <= 1e-10 * mm.io_cov.abs().max().max(1.0),
            "Σ V ≠ Cov[x̃, f]: {err:e}"
        );
    }

    let chol = cholesky(
        &sigma,
        &JitterPolicy {
            initial_relative: 1e-14,
            growth: 10.0,
            max_relative: 1e-10,
        },
        "Σ",
    )
    .expect("Σ factor");
    let mut means = vec![vec![0.0; SAMPLES]; e];
    let mut vars = vec![vec![0.0; SAMPLES]; e];
    let mut xs = vec![vec![0.0; SAMPLES]; d];
    let mut x = vec![0.0; d];
    for s in 0..SAMPLES {
        let z = DVector::from_fn(d, |_, _| normal(&mut r));
        let xv = &mu + &chol.l * z;
        for k in 0..d {
            x[k] = xv[k];
            xs[k][s] = xv[k] - mu[k];
        }
        for (a, (mean, var)) in gp.predict(&x).into_iter().enumerate() {
            means[a][s] = mean;
            vars[a][s] = var;
        }
    }
    let mut check = Check::new();
    for a in 0..e {
        check.mean_of(&format!("mean[{a}]"), &means[a], mm.mean[a]);
    }
    for a in 0..e {
        for b in a..e {
            let v: Vec<f64> = (0..SAMPLES)
                .map(|s| {
                    (means[a][s] - mm.mean[a]) * (means[b][s] - mm.mean[b])
                        + if a == b { vars[a][s] } else { 0.0 }
                })
                .collect();
            check.mean_of(&format!("cov[{a},{b}]"), &v, mm.cov[(a, b)]);
        }
        for k in 0..d {
            let v: Vec<f64> = (0..SAMPLES)
                .map(|s| xs[k][s] * (means[a][s] - mm.mean[a]))
                .collect();
            check.mean_of(&format!("io_cov[{k},{a}]"), &v, mm.io_cov[(k, a)]);
        }
    }
    assert!(check.count >= e + e * (e + 1) / 2 + d * e);
    assert!(
        mm.cov
            .clone()
            .symmetric_eigenvalues()
            .iter()
            .all(|&l| l > 0.0),
        "output covariance not PD"
    );
    println!(
        "seed {seed}: m={m} D={d} E={e}: worst |error| / (5 SE) = {:.3}",
        check.worst
    );
}

#[test]
fn one_output_matches_monte_carlo() {
    check_case(1, 15, 3, 1, 0.3);
    check_case(2, 20, 4, 1, 1.0);
}

#[test]
fn several_outputs_with_cross_covariances_match_monte_carlo() {
    check_case(3, 12, 3, 2, 0.5);
    check_case(4, 10, 4, 3, 0.8);
}

#[test]
fn linear_prior_mean_matches_monte_carlo() {
    check_case_with(6, 12, 4, 1, 0.6, true);
    check_case_with(7, 10, 4, 2, 0.8, true);
}

#[test]
fn deterministic_input_reduces_to_gp_prediction() {
    let mut r = rng(5);
    let params = random_gp(&mut r, 10, 3, 2);
    let mut log = JitterLog::default();
    let gp = PreparedGp::new(&params, &config(), &mut log).expect("prepare");
    let mu = DVector::from_vec(vec![0.3, -0.2, 0.1]);
    let mm = moment_match(&gp, &mu, &DMatrix::zeros(3, 3), &mut log).expect("mm");
    let direct = gp.predict(mu.as_slice());
    for a in 0..2 {
        assert!((mm.mean[a] - direct[a].0).abs() < 1e-12);
        assert!((mm.cov[(a, a)] - direct[a].1).abs() < 1e-12);
        assert!(mm.io_cov.column(a).abs().max() < 1e-15);
    }
    assert!(
        mm.cov[(0, 1)].abs() < 1e-12,
        "independent GPs at a point are uncorrelated"
    );
}
