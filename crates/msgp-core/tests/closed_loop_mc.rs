//! The moment-matched expected cost of a closed-loop rollout (saturated PID policy, two outputs)
//! against Monte Carlo rollouts of the same GP model and policy.
//!
//! The Monte Carlo reference samples the same generative process the moment matching
//! approximates: at each step every particle draws `x_{t+1} ~ N(μ(x̃), σ²(x̃) + σ_x²)` from the GP
//! predictive at its own window, observes `y = x + ε_y`, and the policy acts on `y`. With a
//! smooth model (long length-scales) the Gaussian approximation is accurate, so the summed
//! expected cost and each step's expected cost must agree within Monte Carlo error.

mod common;

use common::{config, normal, rng};
use msgp_core::gp::{GpParams, PreparedGp};
use msgp_core::narx::NarxSpec;
use msgp_core::numeric::linalg::JitterLog;
use msgp_core::policy::{FeedbackPolicy, PidPolicy};
use msgp_core::policy_search::closed_loop_cost;
use msgp_core::policy_search::cost::SaturatingCost;
use msgp_core::rollout::StartState;
use nalgebra::{DMatrix, DVector};
use rand::RngExt;

const PARTICLES: usize = 40_000;

#[test]
fn closed_loop_expected_cost_matches_monte_carlo() {
    let mut r = rng(51);
    let spec = NarxSpec {
        ly: 2,
        lu: 1,
        dy: 2,
        du: 1,
    };
    let d = spec.input_dim();
    let m = 20;
    // a smooth, mildly nonlinear, stable model around 0
    let x = DMatrix::from_fn(m, d, |_, _| r.random_range(-1.0..1.0));
    let targets = DMatrix::from_fn(m, 2, |i, a| {
        let w = x.row(i);
        if a == 0 {
            0.6 * w[0] - 0.2 * w[1] + 0.3 * w[4]
        } else {
            0.5 * w[1] + 0.4 * w[0] - 0.2 * w[4]
        }
    });
    let params = GpParams {
        pseudo_inputs: x,
        pseudo_targets: targets,
        log_lengthscales: DMatrix::from_element(2, d, 1.2),
        log_signal_var: DVector::from_element(2, 0.0),
        log_process_noise: DVector::from_element(2, (2e-3f64).ln()),
        log_obs_noise: DVector::from_element(2, (1e-3f64).ln()),
        linear_mean: DMatrix::zeros(2, d),
    };
    let mut log = JitterLog::default();
    let gp = PreparedGp::new(&params, &config(), &mut log).expect("gp");
    let policy = PidPolicy::new(
        DMatrix::from_row_slice(1, 2, &[-0.4, -0.2]),
        DMatrix::from_row_slice(1, 2, &[0.0, -0.1]),
        DMatrix::from_row_slice(1, 2, &[-0.01, 0.0]),
        0.1,
        vec![1.0],
    )
    .expect("policy");
    let cost =
        SaturatingCost::with_widths(DVector::from_vec(vec![0.0, 0.0]), &[0.4, 0.6]).expect("cost");

    // start: window [x_t, x_{t-1}, u_t] and policy state [y_{t-1}; I_{t-1}]
    let n = d + policy.state_dim();
    let mut mean = DVector::zeros(n);
    mean[0] = 0.5;
    mean[1] = -0.3;
    mean[2] = 0.45;
    mean[3] = -0.25;
    mean[d] = 0.45;
    mean[d + 1] = -0.25;
    let mut cov = DMatrix::zeros(n, n);
    for i in 0..4 {
        cov[(i, i)] = 0.01;
    }
    let start = StartState {
        mean: mean.clone(),
        cov: cov.clone(),
    };
    let (t0, horizon) = (2, 22);
    let mm = closed_loop_cost(&gp, &spec, &start, &policy, (t0, horizon), &cost, &mut log)
        .expect("cost");

    // Monte Carlo over the same process
    let steps = horizon - t0;
    let mut per_step = vec![vec![0.0; PARTICLES]; steps];
    let sx: Vec<f64> = gp.outputs.iter().map(|o| o.sx2.sqrt()).collect();
    let sy: Vec<f64> = gp.outputs.iter().map(|o| o.sy2.sqrt()).collect();
    for p in 0..PARTICLES {
        let mut w: Vec<f64> = (0..d)
            .map(|i| mean[i] + if i < 4 { 0.1 * normal(&mut r) } else { 0.0 })
            .collect();
        let mut state: Vec<f64> = (0..4).map(|k| mean[d + k]).collect();
        for s in 0..steps {
            let pred = gp.predict(&w);
            let xn: Vec<f64> = (0..2)
                .map(|a| pred[a].0 + (pred[a].1 + sx[a] * sx[a]).sqrt() * normal(&mut r))
                .collect();
            let y: Vec<f64> = (0..2).map(|a| xn[a] + sy[a] * normal(&mut r)).collect();
            per_step[s][p] = cost.at(&y);
            let (u, next) = policy.act(&y, &state);
            state = next;
            w = vec![xn[0], xn[1], w[0], w[1], u[0]];
        }
    }
    let mut total_mc = 0.0;
    let mut total_var = 0.0;
    for s in 0..steps {
        let c = &per_step[s];
        let mean_c = c.iter().sum::<f64>() / PARTICLES as f64;
        let var_c = c.iter().map(|v| (v - mean_c).powi(2)).sum::<f64>() / (PARTICLES as f64 - 1.0);
        let se = (var_c / PARTICLES as f64).sqrt();
        assert!(
            (mean_c - mm.steps[s].mean).abs() <= 5.0 * se + 2e-3,
            "step {s}: moment matching {:.5}, Monte Carlo {mean_c:.5} ± {se:.5}",
            mm.steps[s].mean
        );
        assert!(
            (var_c - mm.steps[s].var).abs() <= 0.1 * var_c + 1e-3,
            "step {s}: variance {} vs {var_c}",
            mm.steps[s].var
        );
        total_mc += mean_c;
        total_var += var_c;
    }
    println!(
        "total expected cost: moment matching {:.4}, Monte Carlo {total_mc:.4}",
        mm.total
    );
    assert!(
        (mm.total - total_mc).abs()
            <= 0.02 * total_mc
                + 5.0 * (total_var / PARTICLES as f64).sqrt() * (steps as f64).sqrt()
    );
}
