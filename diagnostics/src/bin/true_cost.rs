//! What the loop's objective asks for on the plant itself: the expected saturating cost of
//! PID + PD gains over a horizon, estimated by simulated episodes (the plant as a perfect
//! model), minimised by a cross-entropy search; the minimiser then gets the stability test.
//! A diagnostic for docs/design.md: if the true cost's minimiser fails the test, no model can
//! make the loop pass it except by luck.
//!
//! `cargo run --release -p msgp-diagnostics --bin true_cost -- [horizon_s] [w_theta,w_x] [seed]`
//! (default: 5 s, widths `0.1,0.3`, seed 0; no switches)
use msgp_core::policy_search::SaturatingCost;
use msgp_diagnostics::{Switches, numbers, usage_error};
use msgp_sim::learn::episode_cost;
use msgp_sim::{
    EpisodeConfig, PendulumParams, PidPdGains, PidPdPolicy, Saturation, StabilityCriteria,
    run_episode, stability_test,
};
use nalgebra::DVector;
use rand::SeedableRng;
use rand_distr::{Distribution, Normal};

fn cost_of(
    params: &PendulumParams,
    g: &PidPdGains,
    cost: &SaturatingCost,
    horizon: f64,
    episodes: u64,
) -> f64 {
    let steps = (horizon * params.control_rate_hz).round() as usize;
    let mut total = 0.0;
    for s in 0..episodes {
        let Ok(mut c) = PidPdPolicy::new(*g, params) else {
            return f64::INFINITY;
        };
        let Ok(ep) = run_episode(
            params,
            &mut c,
            &EpisodeConfig {
                seconds: horizon,
                seed: 10_000 + s,
                initial_theta: None,
            },
        ) else {
            return f64::INFINITY;
        };
        total += episode_cost(&ep, cost, 0, steps);
    }
    total / episodes as f64
}

fn gains(v: &[f64]) -> PidPdGains {
    PidPdGains {
        saturation: Saturation::Sine,
        ..PidPdGains::from_array([v[0], v[1], v[2], v[3], v[4]])
    }
}

const USAGE: &str = "true_cost [horizon_s] [w_theta,w_x] [seed]";

/// The horizon, the cost widths and the search's seed.
fn options() -> Result<(f64, Vec<f64>, u64), String> {
    let sw = Switches::from_args(3, &[])?;
    let horizon = sw.arg(0, "horizon_s")?.unwrap_or(5.0);
    let widths = match sw.positional().get(1) {
        None => vec![0.1, 0.3],
        Some(s) => numbers(s)?,
    };
    Ok((horizon, widths, sw.arg(2, "seed")?.unwrap_or(0)))
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (horizon, widths, seed) = options().unwrap_or_else(|e| usage_error(USAGE, &e));
    let params = PendulumParams::default();
    let cost = SaturatingCost::with_widths(DVector::zeros(2), &widths)?;
    let episodes = 6;
    let hand = PidPdGains {
        saturation: Saturation::Sine,
        ..PidPdGains::hand_tuned()
    };
    println!(
        "horizon {horizon} s, widths {widths:?}: hand-tuned cost {:.2}",
        cost_of(&params, &hand, &cost, horizon, episodes)
    );
    // cross-entropy search from the loop's start, spread two typical magnitudes
    let mut mean = vec![1.0, 0.3, 1.0, 10.0, 2.0];
    let mut std = vec![2.0, 0.6, 2.0, 20.0, 4.0];
    let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(seed);
    let (pop, elite) = (40, 8);
    for generation in 0..12 {
        let mut scored: Vec<(f64, Vec<f64>)> = (0..pop)
            .map(|_| {
                let v: Vec<f64> = mean
                    .iter()
                    .zip(&std)
                    .map(|(m, s)| Normal::new(*m, *s).map_or(*m, |n| n.sample(&mut rng)))
                    .collect();
                (cost_of(&params, &gains(&v), &cost, horizon, episodes), v)
            })
            .collect();
        scored.sort_by(|a, b| a.0.total_cmp(&b.0));
        for j in 0..5 {
            let vals: Vec<f64> = scored[..elite].iter().map(|(_, v)| v[j]).collect();
            let m = vals.iter().sum::<f64>() / elite as f64;
            let var = vals.iter().map(|x| (x - m).powi(2)).sum::<f64>() / elite as f64;
            mean[j] = m;
            std[j] = var.sqrt().max(1e-3);
        }
        let best = &scored[0];
        println!(
            "generation {generation:2}: best {:.2} at [{:.2}, {:.2}, {:.2}, {:.1}, {:.2}], elite mean cost {:.2}",
            best.0,
            best.1[0],
            best.1[1],
            best.1[2],
            best.1[3],
            best.1[4],
            scored[..elite].iter().map(|s| s.0).sum::<f64>() / elite as f64
        );
    }
    let g = gains(&mean);
    let c = cost_of(&params, &g, &cost, horizon, episodes);
    let stable = stability_test(&params, &g, 0, &StabilityCriteria::default())?.passed;
    println!(
        "CEM mean [{:.2}, {:.2}, {:.2}, {:.1}, {:.2}]: cost {c:.2}, stability test {}",
        mean[0],
        mean[1],
        mean[2],
        mean[3],
        mean[4],
        if stable { "passed" } else { "failed" }
    );
    Ok(())
}
