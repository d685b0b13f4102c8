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
        let io = &s * &mom.c;
        for i in 0..2 {
            within(
                "E[u]",
                &us.iter().map(|u| u[i]).collect::<Vec<_>>(),
                mom.mean[i],
            );
            for j in 0..2 {
                let v: Vec<f64> = us
                    .iter()
                    .map(|u| (u[i] - mom.mean[i]) * (u[j] - mom.mean[j]))
                    .collect();
                within("Cov[u]", &v, mom.cov[(i, j)]);
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
