//! What 2σ coverage a model exactly right about its own uncertainty would score on the
//! generalisation table's synthetic tests (a posterior predictive check of the target
//! "coverage ≥ 0.9 on every alternate excitation").
//!
//! Each synthetic system is fitted as `msgp reproduce generalisation` fits it (the default
//! MSGP protocol, the seed's Table-2 data) and simulated on each of its tests. Beside the
//! coverage of the true outputs, `PATHS` free runs are drawn from the model itself, each with
//! one whole function from its posterior and its own process noise
//! (`Model::sample_free_runs`), and each path's coverage by the same reported band is scored as
//! if it were the truth. Where the errors are strongly correlated over time (held levels, slow
//! sines) a single test's coverage is a few effective samples, and even a model whose belief is
//! the truth's distribution falls below 0.9 on some tests: printed is the spread of the paths'
//! coverage and the fraction of them below 0.9.
//!
//! Usage: `coverage_check SYSTEMS SEEDS PATHS`, e.g. `coverage_check 1,2,3,4,5 0,1,2 200`.

use msgp_core::data::{NoiseScale, SyntheticSystem};
use msgp_core::fit::{FitSettings, fit};
use msgp_core::gp::PreparedGp;
use msgp_core::model::{Method, Simulation};
use msgp_core::numeric::linalg::JitterLog;
use nalgebra::DMatrix;

/// The fraction of `y`'s rows (the simulated steps, from the simulation's start) inside the
/// band mean ± 2σ.
fn coverage(sim: &Simulation, y: &DMatrix<f64>, offset: usize) -> f64 {
    let n = sim.mean.nrows();
    let inside = (0..n)
        .filter(|&i| (y[(offset + i, 0)] - sim.mean[(i, 0)]).abs() <= 2.0 * sim.var[(i, 0)].sqrt())
        .count();
    inside as f64 / n as f64
}

fn list<T: std::str::FromStr>(arg: Option<&String>, default: &str) -> Vec<T> {
    arg.map_or(default, String::as_str)
        .split(',')
        .filter_map(|s| s.trim().parse().ok())
        .collect()
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let systems: Vec<u8> = list(args.get(1), "1,2,3,4,5");
    let seeds: Vec<u64> = list(args.get(2), "0,1,2");
    let paths: usize = args.get(3).and_then(|s| s.parse().ok()).unwrap_or(200);
    println!(
        "| system | test | seed | coverage (truth) | paths: mean | 10th percentile | P(< 0.9) | \
         truth by the paths' band + σ_y² | its width / the reported band's | paths by their own \
         band: P(< 0.9) |"
    );
    println!("|---|---|---:|---:|---:|---:|---:|---:|---:|---:|");
    let mut expected_misses = 0.0;
    let mut inherent_misses = 0.0;
    let mut cells = 0usize;
    let mut misses = 0usize;
    for &k in &systems {
        let system = SyntheticSystem::new(k)?;
        for &seed in &seeds {
            let bench = system.generate(seed, NoiseScale::StdDev)?;
            let settings = FitSettings {
                ly: bench.ly,
                lu: bench.lu,
                seed,
                ..FitSettings::new(Method::Msgp)
            };
            let (model, _) = fit(std::slice::from_ref(&bench.train), &settings, &mut |_| {})?;
            let mut tests = vec![("Table 2 test input".to_string(), bench.test.clone(), false)];
            for (e, t) in system.alternate_tests(seed)? {
                tests.push((e.name().to_string(), t, true));
            }
            for (name, traj, alternate) in tests {
                let sim = model.simulate(&traj)?;
                let truth = coverage(&sim, &traj.y, sim.start);
                let drawn = model.sample_free_runs(&traj, paths, seed)?;
                let mut own: Vec<f64> = drawn.iter().map(|y| coverage(&sim, y, 0)).collect();
                own.sort_by(f64::total_cmp);
                let mean = own.iter().sum::<f64>() / own.len() as f64;
                let p10 = own[own.len() / 10];
                let below = own.iter().filter(|&&c| c < 0.9).count() as f64 / own.len() as f64;
                // the paths' own Gaussian band (their mean and spread, latent like them): how
                // often one path falls below 0.9 of a band that is exactly its distribution's
                // moments
                let k = drawn.len() as f64;
                let n = sim.mean.nrows();
                let mc_mean = DMatrix::from_fn(n, 1, |i, _| {
                    drawn.iter().map(|y| y[(i, 0)]).sum::<f64>() / k
                });
                let mc_var = DMatrix::from_fn(n, 1, |i, _| {
                    drawn
                        .iter()
                        .map(|y| (y[(i, 0)] - mc_mean[(i, 0)]).powi(2))
                        .sum::<f64>()
                        / (k - 1.0)
                });
                let band = Simulation {
                    start: sim.start,
                    mean: mc_mean,
                    var: mc_var,
                };
                let own_band =
                    drawn.iter().filter(|y| coverage(&band, y, 0) < 0.9).count() as f64 / k;
                // the truth by the paths' band widened by the observation noise, as the
                // reported band is
                let gp = PreparedGp::new(&model.params, &model.config, &mut JitterLog::default())?;
                let sy2 = model.normalizer.y_var_to_original(0, gp.outputs[0].sy2);
                let observed = Simulation {
                    var: band.var.map(|v| v + sy2),
                    ..band.clone()
                };
                let truth_mc = coverage(&observed, &traj.y, sim.start);
                // how wide that band is against the reported one (mean standard deviations)
                let width = observed.var.map(f64::sqrt).sum() / sim.var.map(f64::sqrt).sum();
                if alternate {
                    expected_misses += below;
                    inherent_misses += own_band;
                    cells += 1;
                    misses += usize::from(truth < 0.9);
                }
                println!(
                    "| {} | {name} | {seed} | {truth:.3} | {mean:.3} | {p10:.3} | {below:.3} | \
                     {truth_mc:.3} | {width:.2} | {own_band:.3} |",
                    system.number()
                );
            }
        }
    }
    println!(
        "\nalternate excitations: {cells} tests, {misses} below 0.9 by the truth; a model whose \
         belief were the truth's distribution would miss {expected_misses:.1} of them on average \
         with the reported band, {inherent_misses:.1} with a band of that distribution's own moments"
    );
    Ok(())
}
