//! Writes the test free simulation of one benchmark fit to CSV (t, y, mean, std) for plotting.
use msgp_core::data::{NoiseScale, SyntheticSystem};
use msgp_core::fit::{FitSettings, fit};
use msgp_core::model::Method;
use std::io::Write;
fn main() -> Result<(), Box<dyn std::error::Error>> {
    let args: Vec<String> = std::env::args().collect();
    let k: u8 = args[1].parse()?;
    let method = if args[2] == "msgp" {
        Method::Msgp
    } else {
        Method::GpNarx
    };
    let b = SyntheticSystem::new(k)?.generate(0, NoiseScale::StdDev)?;
    let s = FitSettings {
        method,
        ly: b.ly,
        lu: b.lu,
        ..FitSettings::default()
    };
    let (m, _) = fit(std::slice::from_ref(&b.train), &s, &mut |_| {})?;
    let sim = m.simulate(&b.test)?;
    let mut f = std::fs::File::create(&args[3])?;
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
