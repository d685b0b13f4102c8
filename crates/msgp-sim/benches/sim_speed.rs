//! Simulation speed: simulated seconds per wall-clock second.
//!
//! Each iteration runs one 10 s episode (500 control steps, 10 000 rapier steps at 1 kHz)
//! of the hand-tuned policy on the default plant. Criterion's throughput is reported in
//! control steps ("elements") per second; divide by 50 for simulated seconds per second,
//! or read the `sim_seconds_per_wall_second` line this bench prints.

use std::hint::black_box;
use std::time::Instant;

use criterion::{Criterion, Throughput, criterion_group, criterion_main};
use msgp_sim::{EpisodeConfig, PendulumParams, PidPdGains, PidPdPolicy, run_episode};

const SECONDS: f64 = 10.0;

fn episode(params: &PendulumParams, seed: u64) -> usize {
    let mut policy = PidPdPolicy::new(PidPdGains::hand_tuned(), params).expect("valid gains");
    let config = EpisodeConfig {
        seconds: SECONDS,
        seed,
        initial_theta: Some(0.02),
    };
    run_episode(params, &mut policy, &config)
        .expect("episode runs")
        .samples
        .len()
}

fn bench(c: &mut Criterion) {
    let params = PendulumParams::default();
    let steps = (SECONDS * params.control_rate_hz).round() as u64;
    let mut group = c.benchmark_group("pendulum");
    group.sample_size(20);
    group.throughput(Throughput::Elements(steps));
    group.bench_function("episode_10s_1kHz", |b| {
        b.iter(|| black_box(episode(black_box(&params), 0)))
    });
    group.finish();

    // A plain summary line in the unit the issue asks for.
    let runs = 20;
    let start = Instant::now();
    for seed in 0..runs {
        black_box(episode(&params, seed));
    }
    let wall = start.elapsed().as_secs_f64();
    println!(
        "sim_seconds_per_wall_second: {:.0} ({} × {SECONDS} s episodes in {wall:.3} s wall)",
        runs as f64 * SECONDS / wall,
        runs
    );
}

criterion_group!(benches, bench);
criterion_main!(benches);
