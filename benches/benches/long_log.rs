//! Long logs (`msgp_core::fit::segments`): the default MSGP fit of a 60,000-sample log of the
//! paper's synthetic system 4 (uniform input on [−1, 1], output noise σ = 0.18, seed 0; the
//! first half trains, as `msgp fit`'s default split), which trains by segments of 1,000 steps,
//! 2 per Adam step (issue target: ≤ 2 min, ≤ 1 GB); and what one Adam step of that training
//! costs against one step on the whole training part (the free-run loss and its adjoint
//! gradient, D = 3, m = 100): the segmented step stays at two segments whatever the log's
//! length, the whole one grows with it. Memory is not measured here: `/usr/bin/time -v msgp
//! fit` on the same log (`BENCHMARKS.md`).

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, SamplingMode, criterion_group, criterion_main};
use msgp_core::data::Trajectory;
use msgp_core::data::synthetic::SyntheticSystem;
use msgp_core::fit::{FitOptions, Overrides, fit};
use msgp_core::loss::{Complexity, loss_and_gradient};
use msgp_core::model::Method;
use msgp_core::numeric::linalg::JitterLog;
use msgp_core::numeric::parallel::Threads;
use msgp_core::rollout::Episode;
use rand::{RngExt, SeedableRng, rngs::StdRng};
use rand_distr::{Distribution, Normal};

/// `n` samples of system 4 under a uniform input, with output noise.
fn system4_log(n: usize, seed: u64) -> Trajectory {
    let mut rng = StdRng::seed_from_u64(seed);
    let u: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
    let noise = Normal::new(0.0, 0.18).expect("normal");
    let system = SyntheticSystem::new(4).expect("system 4");
    let y: Vec<f64> = system
        .respond(&u)
        .into_iter()
        .map(|y| y + noise.sample(&mut rng))
        .collect();
    Trajectory::siso(&u, &y).expect("finite")
}

fn bench_long_fit(c: &mut Criterion) {
    let log = system4_log(60_000, 0);
    let train = vec![log.slice(0, 30_000)];
    let options = FitOptions {
        threads: Threads::available(),
        ..FitOptions::new(Method::Msgp, 2, 1)
    };
    let settings = options.settings(&train).expect("settings");
    let mut group = c.benchmark_group("long_log_60000");
    group
        .sample_size(10)
        .sampling_mode(SamplingMode::Flat)
        .warm_up_time(Duration::from_millis(1))
        .measurement_time(Duration::from_secs(600));
    group.bench_function("msgp_default_fit", |b| {
        b.iter(|| black_box(fit(&train, &settings, &mut |_| {}).expect("fit")))
    });
    group.finish();
}

fn bench_step(c: &mut Criterion) {
    let log = system4_log(30_000, 1);
    let (model, _) = {
        let head = vec![log.slice(0, 600)];
        let options = FitOptions {
            segment_length: Some(0),
            overrides: Overrides {
                inducing: Some(100),
                iterations: Some(20),
                ..Overrides::default()
            },
            ..FitOptions::new(Method::Msgp, 2, 1)
        };
        fit(
            &head,
            &options.settings(&head).expect("settings"),
            &mut |_| {},
        )
        .expect("fit")
    };
    let norm = model.normalizer.apply(&log);
    let piece = |start: usize, len: usize| Episode::feed_forward(norm.slice(start, start + len));
    let mut group = c.benchmark_group("long_log_adam_step");
    group
        .sample_size(10)
        .sampling_mode(SamplingMode::Flat)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(5));
    let threads = Threads::available();
    let mut cases: Vec<(String, Vec<Episode>)> = [2_000, 10_000, 30_000]
        .into_iter()
        .map(|n| (format!("whole_T{n}"), vec![piece(0, n)]))
        .collect();
    cases.push((
        "segments_2x1000".into(),
        vec![piece(0, 1_002), piece(15_000, 1_002)],
    ));
    for (name, episodes) in cases {
        group.bench_function(name, |b| {
            b.iter(|| {
                let mut log = JitterLog::default();
                black_box(
                    loss_and_gradient(
                        &model.params,
                        &model.config,
                        &model.spec,
                        &episodes,
                        Complexity::HalfLogDet,
                        threads,
                        &mut log,
                    )
                    .expect("gradient"),
                )
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench_step, bench_long_fit);
criterion_main!(benches);
