//! The correlated function uncertainty against Monte Carlo over whole drawn functions, at the
//! scale of a real fit.
//!
//! Fits MSGP (the default protocol) on synthetic system `k`'s Table-2 training data, then draws
//! whole functions from the GP's posterior given its pseudo-data
//! (`msgp_core::rollout::FunctionDraws`), simulates every test (the training input, Table 2's
//! test input, the three unseen excitations) by the paper's moment matching with each drawn
//! function, and prints per test: the RMSE; 2σ coverage and NLL of the paper's moment
//! matching (`mm-independent`); of the paper's variance plus the drawn functions' spread of
//! means (Monte Carlo, no subtraction: an upper reference); and of the default rollout
//! (`mm`, first-order and with moment matching's own share subtracted).
//!
//! `cargo run --release -p msgp-diagnostics --bin epistemic -- <k: 1..5> <seed> [draws=N]
//! [threads=N]`
use msgp_core::data::{NoiseScale, SyntheticSystem, Trajectory};
use msgp_core::fit::{FitSettings, fit};
use msgp_core::gp::PreparedGp;
use msgp_core::model::{Method, Model, Rollout, score};
use msgp_core::numeric::linalg::JitterLog;
use msgp_core::rollout::FunctionDraws;
use msgp_diagnostics::{Switches, usage_error};
use rand::SeedableRng;
use rand_distr::{Distribution, StandardNormal};

const USAGE: &str = "epistemic <k: 1..5> <seed> [draws=N] [threads=N]";

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let sw =
        Switches::from_args(2, &["draws", "threads"]).unwrap_or_else(|e| usage_error(USAGE, &e));
    let k: u8 = sw
        .arg(0, "k")
        .unwrap_or_else(|e| usage_error(USAGE, &e))
        .unwrap_or_else(|| usage_error(USAGE, "k is missing"));
    let seed: u64 = sw
        .arg(1, "seed")
        .unwrap_or_else(|e| usage_error(USAGE, &e))
        .unwrap_or(0);
    let draws: usize = sw
        .get("draws")
        .unwrap_or_else(|e| usage_error(USAGE, &e))
        .unwrap_or(64);
    if draws < 2 {
        usage_error(USAGE, "draws must be at least 2");
    }
    let threads = sw.threads().unwrap_or_else(|e| usage_error(USAGE, &e));
    let sys = SyntheticSystem::new(k)?;
    let b = sys.generate(seed, NoiseScale::StdDev)?;
    let s = FitSettings {
        ly: b.ly,
        lu: b.lu,
        seed,
        threads,
        ..FitSettings::new(Method::Msgp)
    };
    let (model, _) = fit(std::slice::from_ref(&b.train), &s, &mut |_| {})?;
    eprintln!(
        "mean {:?}, calibration {:?}",
        model.config.mean, model.calibration
    );
    let mut tests: Vec<(String, Trajectory)> = vec![
        ("train".into(), b.train.clone()),
        ("table2".into(), b.test.clone()),
    ];
    for (e, t) in sys.alternate_tests(seed)? {
        tests.push((e.name().to_string(), t));
    }
    let mut log = JitterLog::default();
    let gp = PreparedGp::new(&model.params, &model.config, &mut log)?;
    let fd = FunctionDraws::new(&gp)?;
    let mut rng = rand::rngs::StdRng::seed_from_u64(1000 + seed);
    let drawn: Vec<Model> = (0..draws)
        .map(|_| {
            let x: Vec<f64> = (0..fd.directions())
                .map(|_| StandardNormal.sample(&mut rng))
                .collect();
            let (dy, da) = fd.moves(&gp, &x);
            let mut md = model.clone();
            md.params.pseudo_targets += dy;
            md.params.linear_mean += da;
            md
        })
        .collect();
    println!(
        "test,rmse,cov_paper,nll_paper,cov_mc,nll_mc,cov_mm,nll_mm,std_paper,std_mc_spread,std_mm"
    );
    for (name, traj) in &tests {
        let paper = model.simulate_as(traj, Rollout::MomentMatchingIndependent)?;
        let default = model.simulate(traj)?;
        let sims: Vec<_> = drawn
            .iter()
            .map(|md| md.simulate_as(traj, Rollout::MomentMatchingIndependent))
            .collect::<Result<_, _>>()?;
        let n = paper.mean.nrows();
        let mut mc = paper.clone();
        let (mut sp, mut ss, mut sd) = (0.0, 0.0, 0.0);
        for i in 0..n {
            let mean: f64 = sims.iter().map(|s| s.mean[(i, 0)]).sum::<f64>() / draws as f64;
            let spread: f64 = sims
                .iter()
                .map(|s| (s.mean[(i, 0)] - mean).powi(2))
                .sum::<f64>()
                / (draws - 1) as f64;
            mc.var[(i, 0)] += spread;
            sp += paper.var[(i, 0)];
            ss += spread;
            sd += default.var[(i, 0)];
        }
        let (a, w, d) = (
            score(&paper, traj)?,
            score(&mc, traj)?,
            score(&default, traj)?,
        );
        let rms = |v: f64| (v / n as f64).sqrt();
        println!(
            "{name},{:.4},{:.3},{:.3},{:.3},{:.3},{:.3},{:.3},{:.4},{:.4},{:.4}",
            a.rmse,
            a.coverage_2sigma,
            a.nll,
            w.coverage_2sigma,
            w.nll,
            d.coverage_2sigma,
            d.nll,
            rms(sp),
            rms(ss),
            rms(sd)
        );
    }
    Ok(())
}
