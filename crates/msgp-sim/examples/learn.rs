//! Runs the policy-learning loop on the default plant and prints each iteration.
//! `cargo run --release -p msgp-sim --example learn -- [msgp|gp-narx] [seed] [iterations]`
use msgp_core::model::Method;
use msgp_sim::PendulumParams;
use msgp_sim::learn::{LearnSettings, learn_policy};

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let method = if args.get(1).map(String::as_str) == Some("gp-narx") {
        Method::GpNarx
    } else {
        Method::Msgp
    };
    let seed: u64 = args.get(2).map_or(Ok(0), |s| s.parse())?;
    let iterations: usize = args.get(3).map_or(Ok(8), |s| s.parse())?;
    let settings = LearnSettings {
        seed,
        iterations,
        ..LearnSettings::for_method(method)
    };
    let start = std::time::Instant::now();
    let out = learn_policy(&PendulumParams::default(), &settings, &mut |r| {
        eprintln!(
            "it {} predicted {:.2} ± {:.2} actual {:.2} interaction {:.1}s stable {} gains {:?} ({:.0}s)",
            r.iteration,
            r.predicted_cost,
            2.0 * r.predicted_cost_std,
            r.actual_cost,
            r.interaction_seconds,
            r.stable,
            [
                r.gains.kp_x,
                r.gains.ki_x,
                r.gains.kd_x,
                r.gains.kp_theta,
                r.gains.kd_theta
            ]
            .map(|g| (g * 100.0).round() / 100.0),
            start.elapsed().as_secs_f64()
        );
    })?;
    println!("first stable iteration: {:?}", out.first_stable_iteration());
    Ok(())
}
