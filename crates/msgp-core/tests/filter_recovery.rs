//! Recovery: the filter likelihood predicts feedback gains' costs as the plant has them; the
//! free-run likelihood, on the same data, predicts them an order of magnitude too high.
//!
//! The plant is an unstable pole with a nonlinearity, sampled at 50 Hz,
//! `θ_{t+1} = 2θ_t − θ_{t−1} + a sin θ_t − b u_{t−1} + w_t` (`a` = 0.006: an open-loop root of
//! 1.08 per step), measured with noise of 5 mrad (the pendulum's noisy tier), process noise
//! 0.1 mrad. Both MSGP models are fitted on the same 16 open-loop random-input episodes (each
//! stops once `|θ|` passes 0.5, as the pendulum's does); each then predicts the expected
//! saturating cost of three saturated PD controllers on the measured angle over 100 steps from
//! rest, as policy search does, and the plant's cost is the Monte Carlo mean of the same cost
//! under the same controller. The free-run likelihood fits a damped pole with process noise of
//! the sensor's size (`docs/experiments/2026-11-29-the-models-noise-split-and-the-filter-likelihood.md`, "The models' noise split and the filter likelihood")
//! and predicts the pole to fall under every controller; the filter likelihood, from the
//! linear-kf start, keeps the pole and the noise split. Measured (plant / filter / free-run):
//! 1.36 / 1.36 / 55.1, 0.41 / 0.40 / 10.6, 2.32 / 2.65 / 58.6. The free-run model still orders
//! these three as the plant does (its costs are all near "falls"); it is its calibration, what
//! a policy search's trade-offs rest on, that fails.

use msgp_core::data::Trajectory;
use msgp_core::fit::{FitOptimizer, FitSettings, MsgpSettings, MsgpStart, fit};
use msgp_core::gp::MeanFunction;
use msgp_core::loss::Likelihood;
use msgp_core::model::Model;
use msgp_core::policy::PidPolicy;
use msgp_core::policy_search::PolicyProblem;
use msgp_core::policy_search::cost::SaturatingCost;
use nalgebra::{DMatrix, DVector};
use rand::SeedableRng;
use rand::rngs::StdRng;
use rand_distr::{Distribution, StandardNormal};

const A: f64 = 0.006;
const B: f64 = 0.006;
const SENSOR: f64 = 0.005;
const PROCESS: f64 = 1e-4;
const PERIOD: f64 = 0.02;
const U_MAX: f64 = 3.0;
const START_STD: f64 = 0.02;
const HORIZON: usize = 100;
const WIDTH: f64 = 0.1;

fn normal(rng: &mut StdRng) -> f64 {
    StandardNormal.sample(rng)
}

/// `n` samples of a smooth random input: `count` sines of amplitude `amplitude` at the
/// frequencies `step, 2 step, …` (rad per sample), random phases.
fn random_sines(rng: &mut StdRng, n: usize, count: usize, amplitude: f64, step: f64) -> Vec<f64> {
    let phase: Vec<f64> = (0..count).map(|_| 3.0 * normal(rng)).collect();
    (0..n)
        .map(|t| {
            (0..count)
                .map(|k| amplitude * (step * (k as f64 + 1.0) * t as f64 + phase[k]).sin())
                .sum::<f64>()
        })
        .collect()
}

/// The filtered MSGP fit of the pendulum loop (filter likelihood, L-BFGS, from the linear-kf
/// start under a GP of `inducing` pseudo-inputs) on `base`'s history.
fn filter_fit(base: &FitSettings, inducing: usize) -> FitSettings {
    FitSettings {
        method: MsgpSettings {
            inducing,
            iterations: 100,
            optimizer: FitOptimizer::Lbfgs,
            likelihood: Likelihood::Filter,
            validation_fraction: 0.0,
            noise_floor: 1e-9,
            mean: MeanFunction::Linear,
            start: MsgpStart::LinearKf,
            alternative: None,
            ..MsgpSettings::default()
        }
        .into(),
        ..base.clone()
    }
}

/// Open-loop episodes under smooth random inputs (sums of six sines, random phases).
fn episodes(seed: u64, count: usize) -> Vec<Trajectory> {
    let mut rng = StdRng::seed_from_u64(seed);
    (0..count)
        .map(|_| {
            let n = 150;
            let u = random_sines(&mut rng, n, 6, 0.5, 0.05);
            let mut th = vec![START_STD * normal(&mut rng); n];
            let mut len = n;
            for t in 1..n - 1 {
                th[t + 1] = 2.0 * th[t] - th[t - 1] + A * th[t].sin() - B * u[t - 1]
                    + PROCESS * normal(&mut rng);
                if th[t + 1].abs() > 0.5 {
                    len = t + 2;
                    break;
                }
            }
            let y: Vec<f64> = th[..len]
                .iter()
                .map(|v| v + SENSOR * normal(&mut rng))
                .collect();
            Trajectory::siso(&u[..len], &y).expect("trajectory")
        })
        .collect()
}

/// The policy's saturation (`PidPolicy`'s sine saturation).
fn saturate(v: f64) -> f64 {
    let s = 2.0 * v / (3.0 * U_MAX);
    let s = s.clamp(-std::f64::consts::FRAC_PI_2, std::f64::consts::FRAC_PI_2);
    U_MAX * (9.0 * s.sin() + (3.0 * s).sin()) / 8.0
}

/// The plant's expected cost of PD gains `(kp, kd)` over [`HORIZON`] steps from rest, by Monte
/// Carlo (4000 runs, common random numbers across gain sets).
fn plant_cost(kp: f64, kd: f64) -> f64 {
    let mut rng = StdRng::seed_from_u64(77);
    let runs = 4000;
    let mut total = 0.0;
    for _ in 0..runs {
        let start = START_STD * normal(&mut rng);
        let (mut th_prev, mut th) = (start, start);
        let mut y_prev = start + SENSOR * normal(&mut rng);
        let (mut u_prev, mut u_prev2) = (0.0, 0.0);
        let mut cost = 0.0;
        for _ in 0..HORIZON {
            // θ_{t+1} from θ_t, θ_{t−1} and u_{t−1}
            let next = 2.0 * th - th_prev + A * th.sin() - B * u_prev2 + PROCESS * normal(&mut rng);
            th_prev = th;
            th = next;
            let y = th + SENSOR * normal(&mut rng);
            cost += 1.0 - (-0.5 * (y / WIDTH).powi(2)).exp();
            let u = saturate(kp * y + kd * (y - y_prev) / PERIOD);
            y_prev = y;
            u_prev2 = u_prev;
            u_prev = u;
        }
        total += cost;
    }
    total / runs as f64
}

fn predicted_cost(model: &Model, kp: f64, kd: f64) -> f64 {
    let problem = PolicyProblem {
        model,
        y0_mean: vec![0.0],
        y0_var: vec![START_STD * START_STD],
        u0: vec![0.0],
        cost: SaturatingCost::with_widths(DVector::from_element(1, 0.0), &[WIDTH]).expect("cost"),
        horizon: HORIZON,
    };
    let policy = PidPolicy::new(
        DMatrix::from_element(1, 1, kp),
        DMatrix::zeros(1, 1),
        DMatrix::from_element(1, 1, kd),
        PERIOD,
        vec![U_MAX],
    )
    .expect("policy");
    problem.evaluate(&policy).expect("rollout").0
}

/// Indices of `costs` from the lowest to the highest.
fn order(costs: &[f64]) -> Vec<usize> {
    let mut idx: Vec<usize> = (0..costs.len()).collect();
    idx.sort_by(|&i, &j| costs[i].total_cmp(&costs[j]));
    idx
}

#[test]
fn the_filter_likelihood_predicts_feedback_gains_as_the_plant_has_them() {
    let data = episodes(5, 16);
    let base = FitSettings {
        ly: 2,
        lu: 2,
        ..FitSettings::default()
    };
    let free_run = FitSettings {
        method: MsgpSettings {
            inducing: 30,
            mean: MeanFunction::Linear,
            ..MsgpSettings::default()
        }
        .into(),
        ..base.clone()
    };
    let filter = filter_fit(&base, 30);
    let (free_model, _) = fit(&data, &free_run, &mut |_| {}).expect("free-run fit");
    let (filter_model, _) = fit(&data, &filter, &mut |_| {}).expect("filter fit");
    // weakly damped, well damped, barely stabilising
    let gains = [(2.0, 0.05), (3.0, 0.3), (1.3, 0.02)];
    let plant: Vec<f64> = gains.iter().map(|&(p, d)| plant_cost(p, d)).collect();
    let by_filter: Vec<f64> = gains
        .iter()
        .map(|&(p, d)| predicted_cost(&filter_model, p, d))
        .collect();
    let by_free: Vec<f64> = gains
        .iter()
        .map(|&(p, d)| predicted_cost(&free_model, p, d))
        .collect();
    let report = format!("plant {plant:?}\nfilter {by_filter:?}\nfree-run {by_free:?}");
    eprintln!("{report}");
    assert_eq!(order(&by_filter), order(&plant), "{report}");
    for k in 0..gains.len() {
        let ratio = by_filter[k] / plant[k];
        assert!((1.0 / 1.3..1.3).contains(&ratio), "gains {k}: {report}");
        assert!(by_free[k] > 5.0 * plant[k], "gains {k}: {report}");
    }
}

/// What the filtered MSGP loop's prequential choice rests on (`msgp_sim::learn::ModelChoice`):
/// on episodes neither model was trained on, the filter likelihood (`Model::filter_nll`) of the
/// GP model (linear mean + GP, from the linear-kf start) beats the linear-kf model's where the
/// plant has a nonlinearity a linear model cannot carry (a saturating input,
/// `y_{t+1} = 0.7 y_t + 0.8 tanh(2 u_t)`), and does not where the plant is linear
/// (`y_{t+1} = 0.7 y_t + 0.5 u_t`): there the GP can only fit the noise.
#[test]
fn held_out_filter_likelihood_prefers_the_gp_only_where_the_plant_is_nonlinear() {
    use msgp_core::fit::LinearKfSettings;
    let plant = |nonlinear: bool, seed: u64, count: usize| -> Vec<Trajectory> {
        let mut rng = StdRng::seed_from_u64(seed);
        (0..count)
            .map(|_| {
                let n = 120;
                let u = random_sines(&mut rng, n, 4, 0.6, 0.07);
                let mut x = vec![0.0; n];
                for t in 0..n - 1 {
                    let drive = if nonlinear {
                        0.8 * (2.0 * u[t]).tanh()
                    } else {
                        0.5 * u[t]
                    };
                    x[t + 1] = 0.7 * x[t] + drive + 0.01 * normal(&mut rng);
                }
                let y: Vec<f64> = x.iter().map(|v| v + 0.05 * normal(&mut rng)).collect();
                Trajectory::siso(&u, &y).expect("trajectory")
            })
            .collect()
    };
    let base = FitSettings {
        ly: 1,
        lu: 1,
        ..FitSettings::default()
    };
    let gp_settings = filter_fit(&base, 20);
    let linear_settings = FitSettings {
        method: LinearKfSettings { iterations: 300 }.into(),
        ..base
    };
    let mut report = String::new();
    for nonlinear in [true, false] {
        let train = plant(nonlinear, 11, 6);
        let test = plant(nonlinear, 12, 4);
        let (gp, _) = fit(&train, &gp_settings, &mut |_| {}).expect("GP fit");
        let (linear, _) = fit(&train, &linear_settings, &mut |_| {}).expect("linear fit");
        let score = |m: &Model| -> f64 {
            test.iter()
                .map(|t| m.filter_nll(t).expect("filter").0)
                .sum()
        };
        let (g, l) = (score(&gp), score(&linear));
        report.push_str(&format!(
            "nonlinear {nonlinear}: GP {g:.1}, linear {l:.1}\n"
        ));
        if nonlinear {
            assert!(g < l - 50.0, "{report}");
        } else {
            assert!(g > l, "{report}");
        }
    }
    eprintln!("{report}");
}
