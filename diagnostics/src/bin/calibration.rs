//! Would a variance calibration on the validation tail make MSGP's uncertainty honest on data it
//! was not trained on? For one benchmark and seed: the chosen recipe's head model (trained on
//! the first 80 %, as the protocol's first stage) simulates the tail; the additive output
//! variance `δ` (and, apart, the variance scale `s`) that minimises the tail's NLL is found on a
//! grid; then the protocol's model (trained on all the data) simulates the test part and the
//! alternate excitations, scored with `δ = 0`, with the tail's `δ` and `s`, and over the grid.
//!
//! `nested` judges by the head's own procedure, cross-validated: the chosen recipe's protocol
//! without the final training on the first 80 % (early-stopped on its own last fifth),
//! simulating the tail.
//!
//! `cargo run --release -p msgp-diagnostics --bin calibration -- [system] [seed] [proxy|head|nested]`

use std::path::Path;

use msgp_core::data::real::{RealSeries, data_dir};
use msgp_core::data::{NoiseScale, SyntheticSystem, Trajectory};
use msgp_core::fit::{FitSettings, MsgpSettings, fit};
use msgp_core::model::score;
use msgp_core::model::{Model, Simulation};
use msgp_diagnostics::{Switches, usage_error};

const USAGE: &str =
    "calibration [sys1..sys5|actuator|ballbeam|drives|furnace|dryer] [seed] [proxy|head|nested]";

/// Additive output variances (normalised units: times the training outputs' variance).
const GRID: [f64; 10] = [0.0, 1e-4, 3e-4, 1e-3, 3e-3, 1e-2, 3e-2, 0.1, 0.3, 1.0];
/// Variance scales.
const SCALES: [f64; 9] = [1.0, 1.5, 2.0, 3.0, 5.0, 10.0, 20.0, 50.0, 100.0];

fn adjusted(sim: &Simulation, add: f64, scale: f64) -> Simulation {
    let mut s = sim.clone();
    s.var.iter_mut().for_each(|v| *v = *v * scale + add);
    s
}

fn best<F: Fn(f64) -> f64>(grid: &[f64], nll: F) -> (f64, f64) {
    grid.iter().map(|&g| (g, nll(g))).fold(
        (f64::NAN, f64::INFINITY),
        |b, c| if c.1 < b.1 { c } else { b },
    )
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let sw = Switches::from_args(3, &[]).unwrap_or_else(|e| usage_error(USAGE, &e));
    let name = sw
        .arg::<String>(0, "system")
        .unwrap_or_else(|e| usage_error(USAGE, &e))
        .unwrap_or("sys4".into());
    let seed: u64 = sw
        .arg(1, "seed")
        .unwrap_or_else(|e| usage_error(USAGE, &e))
        .unwrap_or(0);
    let judge_name = sw
        .arg::<String>(2, "judge")
        .unwrap_or_else(|e| usage_error(USAGE, &e))
        .unwrap_or("proxy".into());
    let proxy = judge_name == "proxy";
    // the head's own procedure cross-validated: trained on the head with early stopping on
    // the head's own last fifth, judged on the tail
    let nested = judge_name == "nested";
    let (bench, alternates): (_, Vec<(String, Trajectory)>) =
        if let Some(k) = name.strip_prefix("sys") {
            let s = SyntheticSystem::new(k.parse()?)?;
            let b = s.generate(seed, NoiseScale::StdDev)?;
            let alt = s
                .alternate_tests(seed)?
                .into_iter()
                .map(|(e, t)| (e.name().to_string(), t))
                .collect();
            (b, alt)
        } else {
            let s = RealSeries::ALL
                .into_iter()
                .find(|s| s.name() == name)
                .ok_or("unknown series")?;
            (s.load(&data_dir(Path::new(".")))?, Vec::new())
        };
    let settings = FitSettings {
        ly: bench.ly,
        lu: bench.lu,
        seed,
        ..FitSettings::default()
    };
    let msgp = settings.msgp().ok_or("msgp")?.clone();
    let (model, fitted) = fit(std::slice::from_ref(&bench.train), &settings, &mut |_| {
        // quiet
    })?;
    // the model as it simulates without the fit's own calibration
    let model = Model {
        calibration: Vec::new(),
        ..model
    };
    let n = bench.train.len();
    let n_val = (n as f64 * msgp.validation_fraction).round() as usize;
    let w = model.spec.warmup();
    let tail = bench.train.slice(n - n_val - w, n);
    let head_data = bench.train.slice(0, n - n_val);
    // the head model (early-stopped on the tail) or the proxy: the chosen recipe trained on the
    // head for the final stage's iterations, without a tail
    let chosen = if fitted.chosen_recipe == 0 {
        msgp.clone()
    } else {
        msgp.with_recipe(msgp.alternative.ok_or("alternative")?)
    };
    let judge_settings = FitSettings {
        method: if proxy {
            MsgpSettings {
                validation_fraction: 0.0,
                alternative: None,
                iterations: msgp.full_data_iterations.unwrap_or(400),
                ..chosen
            }
        } else if nested {
            MsgpSettings {
                full_data_iterations: None,
                alternative: None,
                ..chosen
            }
        } else {
            MsgpSettings {
                full_data_iterations: None,
                ..msgp.clone()
            }
        }
        .into(),
        ..settings.clone()
    };
    let train = if proxy || nested {
        &head_data
    } else {
        &bench.train
    };
    let (judge, _) = fit(std::slice::from_ref(train), &judge_settings, &mut |_| {
        // quiet
    })?;
    let tail_sim = judge.simulate(&tail)?;
    let yvar = judge.normalizer.y_var_to_original(0, 1.0);
    let (d_star, d_nll) = best(&GRID, |d| {
        score(&adjusted(&tail_sim, d * yvar, 1.0), &tail).map_or(f64::INFINITY, |m| m.nll)
    });
    let (s_star, s_nll) = best(&SCALES, |s| {
        score(&adjusted(&tail_sim, 0.0, s), &tail).map_or(f64::INFINITY, |m| m.nll)
    });
    let m0 = score(&tail_sim, &tail)?;
    println!(
        "{name} seed {seed} ({}): judge on tail rmse {:.4} nll {:.3} cov {:.2}; best add \
         {d_star:e} (nll {d_nll:.3}), best scale {s_star} (nll {s_nll:.3})",
        judge_name, m0.rmse, m0.nll, m0.coverage_2sigma
    );
    let mut tests = vec![("test".to_string(), bench.test.clone())];
    tests.extend(alternates);
    for (label, t) in &tests {
        report(&model, label, t, yvar, d_star, s_star)?;
    }
    Ok(())
}

fn report(
    model: &Model,
    label: &str,
    t: &Trajectory,
    yvar: f64,
    d_star: f64,
    s_star: f64,
) -> Result<(), Box<dyn std::error::Error>> {
    let sim = model.simulate(t)?;
    let m = |add: f64, scale: f64| score(&adjusted(&sim, add * yvar, scale), t);
    let (a, b, c) = (m(0.0, 1.0)?, m(d_star, 1.0)?, m(0.0, s_star)?);
    let grid: Vec<String> = GRID
        .iter()
        .map(|&d| {
            m(d, 1.0).map_or("err".into(), |x| {
                format!("{d:e}:{:.2}/{:.2}", x.nll, x.coverage_2sigma)
            })
        })
        .collect();
    println!(
        "  {label:<18} rmse {:.4} | nll/cov raw {:.3}/{:.2} add {:.3}/{:.2} scale {:.3}/{:.2} | {}",
        a.rmse,
        a.nll,
        a.coverage_2sigma,
        b.nll,
        b.coverage_2sigma,
        c.nll,
        c.coverage_2sigma,
        grid.join(" ")
    );
    Ok(())
}
