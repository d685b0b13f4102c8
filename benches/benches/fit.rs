//! A whole MSGP fit of the dryer series (m = 100, T = 500 training samples, `l_y = l_u = 2`)
//! to its stopping criterion (early stopping on the held-out last 20 %), by each solver: Adam
//! (the paper's, 400 iterations) and L-BFGS (`msgp_core::fit::FIT_LBFGS`). Issue 7's target is
//! ≤ 10 s on two cores. Needs the real series (`MSGP_DATA_DIR`, default `../shared/data/real`);
//! skipped with a message when they are absent.

use std::hint::black_box;
use std::path::Path;
use std::time::Duration;

use criterion::{Criterion, SamplingMode, criterion_group, criterion_main};
use msgp_core::data::real::{RealSeries, data_dir};
use msgp_core::fit::{FitOptimizer, FitSettings, MsgpSettings, fit};

fn bench_fit(c: &mut Criterion) {
    let dir = data_dir(&Path::new(env!("CARGO_MANIFEST_DIR")).join(".."));
    let bench = match RealSeries::Dryer.load(&dir) {
        Ok(b) => b,
        Err(e) => {
            eprintln!("skipped: the dryer series is not available ({e})");
            return;
        }
    };
    let mut group = c.benchmark_group("fit_dryer_m100_T500");
    group
        .sample_size(10)
        .sampling_mode(SamplingMode::Flat)
        .warm_up_time(Duration::from_millis(1))
        .measurement_time(Duration::from_secs(20));
    for (name, optimizer) in [
        ("msgp_lbfgs", FitOptimizer::Lbfgs),
        ("msgp_adam_400", FitOptimizer::Adam),
    ] {
        let settings = FitSettings {
            ly: bench.ly,
            lu: bench.lu,
            method: MsgpSettings {
                optimizer,
                ..MsgpSettings::default()
            }
            .into(),
            ..FitSettings::default()
        };
        group.bench_function(name, |b| {
            b.iter(|| {
                black_box(
                    fit(std::slice::from_ref(&bench.train), &settings, &mut |_| {}).expect("fit"),
                )
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench_fit);
criterion_main!(benches);
