//! The saturating cost and the sine saturation against Monte Carlo (2·10⁵ samples, 5 standard
//! errors).

mod common;

use common::{normal, random_cov, rng};
use msgp_core::moments::saturation::{saturate, saturate_moments};
use msgp_core::numeric::linalg::{JitterLog, JitterPolicy, cholesky};
use msgp_core::policy_search::cost::SaturatingCost;
use nalgebra::{DMatrix, DVector};

const N: usize = 200_000;

fn within(what: &str, samples: &[f64], exact: f64) {
    let n = samples.len() as f64;
    let mean = samples.iter().sum::<f64>() / n;
    let var = samples.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0);
    let se = (var / n).sqrt();
    assert!(
        (mean - exact).abs() <= 5.0 * se + 1e-12,
        "{what}: exact {exact:.6e}, MC {mean:.6e} ± {se:.1e}"
    );
}

/// Each entry's mean and each pair's covariance over `values` (one row per sample) against
/// `mean` and `cov`.
fn moments_within(what: &str, values: &[Vec<f64>], mean: &DVector<f64>, cov: &DMatrix<f64>) {
    for a in 0..mean.len() {
        let col: Vec<f64> = values.iter().map(|v| v[a]).collect();
        within(&format!("E[{what}]"), &col, mean[a]);
        for b in 0..mean.len() {
            let v: Vec<f64> = values
                .iter()
                .map(|f| (f[a] - mean[a]) * (f[b] - mean[b]))
                .collect();
            within(&format!("Cov[{what}]"), &v, cov[(a, b)]);
        }
    }
}

fn sample(r: &mut rand::rngs::StdRng, m: &DVector<f64>, s: &DMatrix<f64>) -> Vec<DVector<f64>> {
    let l = cholesky(s, &JitterPolicy::default(), "S").expect("chol").l;
    (0..N)
        .map(|_| m + &l * DVector::from_fn(m.len(), |_, _| normal(r)))
        .collect()
}

#[test]
fn saturating_cost_mean_and_variance_match_monte_carlo() {
    let mut r = rng(31);
    for case in 0..3 {
        let m = DVector::from_fn(2, |_, _| 0.4 * normal(&mut r));
        let s = random_cov(&mut r, 2, 0.2 + 0.3 * case as f64);
        let cost = SaturatingCost::with_widths(DVector::from_vec(vec![0.1, -0.2]), &[0.5, 0.8])
            .expect("cost");
        let mut log = JitterLog::default();
        let mom = cost
            .moments(&m, &s, &JitterPolicy::default(), &mut log)
            .expect("moments");
        let xs = sample(&mut r, &m, &s);
        let c: Vec<f64> = xs.iter().map(|x| cost.at(x.as_slice())).collect();
        within("E[c]", &c, mom.mean);
        let sq: Vec<f64> = c.iter().map(|v| (v - mom.mean).powi(2)).collect();
        within("Var[c]", &sq, mom.var);
    }
}

#[test]
fn sine_saturation_moments_match_monte_carlo() {
    let mut r = rng(32);
    let u_max = [3.0, 1.5];
    for case in 0..3 {
        let m = DVector::from_fn(2, |_, _| 0.8 * normal(&mut r));
        let s = random_cov(&mut r, 2, 0.3 + 0.7 * case as f64);
        let mom = saturate_moments(&m, &s, &u_max);
        let xs = sample(&mut r, &m, &s);
        let us: Vec<Vec<f64>> = xs
            .iter()
            .map(|x| (0..2).map(|i| saturate(x[i], u_max[i])).collect())
            .collect();
        moments_within("u", &us, &mom.mean, &mom.cov);
        let io = &s * &mom.c;
        for i in 0..2 {
            for j in 0..2 {
                let w: Vec<f64> = xs
                    .iter()
                    .zip(&us)
                    .map(|(x, u)| (x[i] - m[i]) * (u[j] - mom.mean[j]))
                    .collect();
                within("Cov[x, u]", &w, io[(i, j)]);
            }
        }
    }
    assert!(
        (saturate(std::f64::consts::FRAC_PI_2, 3.0) - 3.0).abs() < 1e-12,
        "saturates at u_max"
    );
}

/// A cost on three outputs, the first and last angles (costed on their unit tips), the middle
/// one plain.
fn tip_cost() -> SaturatingCost {
    SaturatingCost::with_angles(
        DVector::from_vec(vec![0.3, -0.2, 2.9]),
        &[0.5, 0.8, 0.4],
        &[true, false, true],
    )
    .expect("cost")
}

/// The features `[sin θ₀, cos θ₀, y₁, sin θ₂, cos θ₂]` of a correlated Gaussian, one angle
/// near ±π: their exact mean, covariance and cross-covariance with the outputs against Monte
/// Carlo. A missing `e^{−σ²/2}` or a sign in the sum-and-difference identities is off by
/// many standard errors at these spreads.
#[test]
fn trigonometric_feature_moments_match_monte_carlo() {
    let mut r = rng(33);
    let cost = tip_cost();
    for case in 0..3 {
        let m = DVector::from_vec(vec![0.5 * normal(&mut r), 0.3, 3.0 + 0.2 * normal(&mut r)]);
        let s = random_cov(&mut r, 3, 0.2 + 0.6 * case as f64);
        let fm = cost.feature_moments(&m, &s);
        let xs = sample(&mut r, &m, &s);
        let fs: Vec<Vec<f64>> = xs
            .iter()
            .map(|x| vec![x[0].sin(), x[0].cos(), x[1], x[2].sin(), x[2].cos()])
            .collect();
        moments_within("φ", &fs, &fm.mean, &fm.cov);
    }
}

/// The expected tip cost against Monte Carlo of the cost itself: the features' moments are
/// exact and the expectation takes them as Gaussian (PILCO's approximation), exact as the
/// spread goes to zero. Allowed: 5 standard errors plus an approximation bound per spread
/// (measured at seed 34: 1.6e-4, 5.7e-4 and 1.4e-2 from MC at output variances of about
/// 0.005, 0.05 and 0.2).
#[test]
fn tip_cost_expectation_matches_monte_carlo() {
    let mut r = rng(34);
    let cost = tip_cost();
    for (spread, bias) in [(0.005, 0.0), (0.05, 1e-3), (0.2, 2e-2)] {
        let m = DVector::from_vec(vec![0.2, -0.1, -3.0]);
        let s = random_cov(&mut r, 3, spread);
        let mut log = JitterLog::default();
        let mom = cost
            .moments(&m, &s, &JitterPolicy::default(), &mut log)
            .expect("moments");
        let xs = sample(&mut r, &m, &s);
        let c: Vec<f64> = xs.iter().map(|x| cost.at(x.as_slice())).collect();
        let n = c.len() as f64;
        let mc = c.iter().sum::<f64>() / n;
        let se = (c.iter().map(|v| (v - mc).powi(2)).sum::<f64>() / (n - 1.0) / n).sqrt();
        assert!(
            (mom.mean - mc).abs() <= 5.0 * se + bias,
            "spread {spread}: closed form {:.6} vs MC {mc:.6} ± {se:.1e}",
            mom.mean
        );
    }
}
