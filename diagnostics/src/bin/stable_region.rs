//! How much of a box of PID + PD gains balances the default plant: draws `samples` gain sets
//! uniformly in `[0, hi]` per gain ([`random_gains`] with seeds `0..samples`),
//! runs the stability test (seed 0) on each and prints the ones that pass. A diagnostic for
//! docs/design.md: the default `hi` is the box the loop's first policy search can reach.
//!
//! `cargo run --release -p msgp-diagnostics --bin stable_region -- [samples]
//! [hi_kp_x,hi_ki_x,hi_kd_x,hi_kp_theta,hi_kd_theta]` (default: 200 samples in
//! `[0, 2 × typical]` = `2,0.6,2,20,4`; no switches)
use msgp_diagnostics::{Switches, numbers, usage_error};
use msgp_sim::seed::{Stream, rng_for};
use msgp_sim::{PendulumParams, PidPdGains, Saturation, StabilityCriteria, stability_test};
use rand::{RngExt, SeedableRng};

/// A random gain set: each gain drawn uniformly in `[0, 2 scale]` from `seed`'s random-gains
/// stream, sine saturation.
fn random_gains(seed: u64, scale: &[f64; 5]) -> PidPdGains {
    let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(rng_for(seed, Stream::RandomGains));
    let mut g = [0.0; 5];
    for (gk, s) in g.iter_mut().zip(scale) {
        *gk = rng.random_range(0.0..=2.0 * s.abs());
    }
    PidPdGains {
        saturation: Saturation::Sine,
        ..PidPdGains::from_array(g)
    }
}

const USAGE: &str = "stable_region [samples] [hi_kp_x,hi_ki_x,hi_kd_x,hi_kp_theta,hi_kd_theta]";

/// The number of draws and the box's upper corner.
fn options() -> Result<(u64, [f64; 5]), String> {
    let sw = Switches::from_args(2, &[])?;
    let n = sw.arg(0, "samples")?.unwrap_or(200);
    let hi = match sw.positional().get(1) {
        None => [2.0, 0.6, 2.0, 20.0, 4.0],
        Some(s) => <[f64; 5]>::try_from(numbers(s)?)
            .map_err(|_| format!("the box needs five numbers separated by commas, got {s:?}"))?,
    };
    Ok((n, hi))
}

fn main() -> Result<(), msgp_sim::SimError> {
    let (n, hi) = options().unwrap_or_else(|e| usage_error(USAGE, &e));
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
