//! The building blocks of one loss evaluation, at the sizes of the two comparison problems
//! (`BENCHMARKS.md`): D = 4 (l_y = l_u = 2), m = 100, T = 500 and the actuator-like
//! D = 20 (l_y = l_u = 10), m = 100, T = 512. Sizes are in the benchmark ids.

use std::hint::black_box;
use std::time::Duration;

use criterion::{BenchmarkId, Criterion, SamplingMode, criterion_group, criterion_main};
use msgp_benches::{problem, window_state};
use msgp_core::gp::kernel::kernel_matrix;
use msgp_core::gp::{GpConfig, PreparedGp};
use msgp_core::moments::moment_match;
use msgp_core::numeric::linalg::JitterLog;
use msgp_core::rollout::{Control, simulate, simulate_correlated};

/// (D, m, T) of the two comparison problems.
const SIZES: [(usize, usize, usize); 2] = [(4, 100, 500), (20, 100, 512)];

fn bench_blocks(c: &mut Criterion) {
    let config = GpConfig::default();
    let mut kernel = c.benchmark_group("kernel_matrix");
    kernel
        .sample_size(10)
        .warm_up_time(Duration::from_millis(300))
        .measurement_time(Duration::from_secs(1));
    for (d, m, t) in SIZES {
        let (params, _, _) = problem(m, d, t, 0).expect("problem");
        let inv_l2: Vec<f64> = params
            .log_lengthscales
            .row(0)
            .iter()
            .map(|l| (-2.0 * l).exp())
            .collect();
        let x = params.pseudo_inputs.clone();
        kernel.bench_function(BenchmarkId::from_parameter(format!("m{m}_D{d}")), |b| {
            b.iter(|| black_box(kernel_matrix(&x, &x, &inv_l2, 1.0)))
        });
    }
    kernel.finish();

    let mut mm = c.benchmark_group("moment_match_step");
    mm.sample_size(10)
        .warm_up_time(Duration::from_millis(300))
        .measurement_time(Duration::from_secs(1));
    for (d, m, t) in SIZES {
        let (params, spec, episodes) = problem(m, d, t, 0).expect("problem");
        let mut log = JitterLog::default();
        let gp = PreparedGp::new(&params, &config, &mut log).expect("gp");
        let (mu, sigma) = window_state(&spec, &episodes[0]);
        mm.bench_function(BenchmarkId::from_parameter(format!("m{m}_D{d}")), |b| {
            b.iter(|| {
                let mut log = JitterLog::default();
                black_box(moment_match(&gp, &mu, &sigma, &mut log).expect("mm"))
            })
        });
    }
    mm.finish();

    let mut roll = c.benchmark_group("rollout_open_loop_f64");
    roll.sample_size(10)
        .sampling_mode(SamplingMode::Flat)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(3));
    for (d, m, t) in SIZES {
        let (params, spec, episodes) = problem(m, d, t, 0).expect("problem");
        let mut log = JitterLog::default();
        let gp = PreparedGp::new(&params, &config, &mut log).expect("gp");
        let traj = &episodes[0].traj;
        roll.bench_function(
            BenchmarkId::from_parameter(format!("D{d}_m{m}_T{t}")),
            |b| {
                b.iter(|| {
                    let mut log = JitterLog::default();
                    black_box(
                        simulate(
                            &gp,
                            &spec,
                            traj,
                            &Control::FeedForward,
                            traj.len(),
                            &mut log,
                        )
                        .expect("rollout"),
                    )
                })
            },
        );
        // what a free simulation reports: the same rollout with the correlated function
        // uncertainty's recursion beside it
        roll.bench_function(
            BenchmarkId::from_parameter(format!("correlated_D{d}_m{m}_T{t}")),
            |b| {
                b.iter(|| {
                    let mut log = JitterLog::default();
                    black_box(
                        simulate_correlated(&gp, &spec, traj, traj.len(), &mut log)
                            .expect("rollout"),
                    )
                })
            },
        );
    }
    roll.finish();
}

criterion_group!(benches, bench_blocks);
criterion_main!(benches);
