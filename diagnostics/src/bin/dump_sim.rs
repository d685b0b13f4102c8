//! Writes the test free simulation of one benchmark fit to CSV (t, y, mean, std) for plotting:
//! synthetic system `k` (seed 0, noise read as a standard deviation), the `FitSettings`
//! defaults of the method.
//!
//! `cargo run --release -p msgp-diagnostics --bin dump_sim -- <k: 1..5> <msgp|gp-narx> <out.csv>
//! [threads=N]` (`threads`: the fit's threads, default every core; results do not depend on it)
use msgp_core::data::{NoiseScale, SyntheticSystem};
use msgp_core::fit::{FitSettings, fit};
use msgp_core::model::Method;
use msgp_core::numeric::parallel::Threads;
use msgp_diagnostics::{Switches, usage_error};
use std::io::Write;

const USAGE: &str = "dump_sim <k: 1..5> <msgp|gp-narx> <out.csv> [threads=N]";

/// The system number, the method, the output file and the threads.
fn options() -> Result<(u8, Method, String, Threads), String> {
    let sw = Switches::from_args(3, &["threads"])?;
    let k = sw.arg(0, "k")?.ok_or("the system number k is missing")?;
    let method = match sw.arg::<String>(1, "method")?.as_deref() {
        Some("msgp") => Method::Msgp,
        Some("gp-narx") => Method::GpNarx,
        Some(other) => return Err(format!("unknown method `{other}`")),
        None => return Err("the method is missing".into()),
    };
    let out = sw.arg(2, "out.csv")?.ok_or("the output file is missing")?;
    Ok((k, method, out, sw.threads()?))
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let (k, method, out, threads) = options().unwrap_or_else(|e| usage_error(USAGE, &e));
    let b = SyntheticSystem::new(k)?.generate(0, NoiseScale::StdDev)?;
    let s = FitSettings {
        ly: b.ly,
        lu: b.lu,
        threads,
        ..FitSettings::new(method)
    };
    let (m, _) = fit(std::slice::from_ref(&b.train), &s, &mut |_| {})?;
    let sim = m.simulate(&b.test)?;
    let mut f = std::fs::File::create(&out)?;
    writeln!(f, "t,y,mean,std")?;
    for i in 0..sim.mean.nrows() {
        writeln!(
            f,
            "{},{},{},{}",
            sim.start + i,
            b.test.y[(sim.start + i, 0)],
            sim.mean[(i, 0)],
            sim.var[(i, 0)].sqrt()
        )?;
    }
    Ok(())
}
