//! How much of a box of PID + PD gains balances the default plant: draws `samples` gain sets
//! uniformly in `[0, hi]` per gain (the draws of [`random_gains`] with seeds `0..samples`),
//! runs the stability test (seed 0) on each and prints the ones that pass. A diagnostic for
//! docs/design.md: the default `hi` is the box the loop's first policy search can reach.
//!
//! `cargo run --release -p msgp-sim --example stable_region -- [samples] [hi_kp_x,hi_ki_x,hi_kd_x,hi_kp_theta,hi_kd_theta]`
use msgp_sim::learn::random_gains;
use msgp_sim::{PendulumParams, StabilityCriteria, stability_test};

fn main() -> Result<(), msgp_sim::SimError> {
    let args: Vec<String> = std::env::args().collect();
    let n: u64 = args.get(1).and_then(|s| s.parse().ok()).unwrap_or(200);
    let hi: [f64; 5] = match args.get(2) {
        None => [2.0, 0.6, 2.0, 20.0, 4.0],
        Some(s) => {
            let v: Vec<f64> = s.split(',').filter_map(|v| v.trim().parse().ok()).collect();
            match <[f64; 5]>::try_from(v) {
                Ok(hi) => hi,
                Err(_) => {
                    eprintln!("the box needs five numbers separated by commas, got {s:?}");
                    std::process::exit(2);
                }
            }
        }
    };
    let scale = hi.map(|h| h / 2.0);
    let params = PendulumParams::default();
    let mut stable = 0;
    for k in 0..n {
        let g = random_gains(k, &scale);
        let r = stability_test(&params, &g, 0, &StabilityCriteria::default())?;
        if r.passed {
            stable += 1;
            println!(
                "stable: kp_x {:.2} ki_x {:.2} kd_x {:.2} kp_th {:.1} kd_th {:.2}",
                g.kp_x, g.ki_x, g.kd_x, g.kp_theta, g.kd_theta
            );
        }
    }
    println!("{stable} of {n} stable in the box [0, {hi:?}]");
    Ok(())
}
