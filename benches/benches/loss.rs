//! One MSGP loss evaluation and one full gradient (adjoint and forward-mode duals; and the
//! filter likelihood's adjoint gradient on the same episodes) at
//! D = 4 (l_y = l_u = 2), m = 100, T = 500 (the dryer / synthetic-4 configuration) and value +
//! adjoint gradient at the actuator-like D = 20 (l_y = l_u = 10), m = 100, T = 512.

use std::hint::black_box;
use std::time::Duration;

use criterion::{Criterion, SamplingMode, criterion_group, criterion_main};
use msgp_benches::problem;
use msgp_core::gp::{GpConfig, GpParams};
use msgp_core::loss::{self, Complexity, msgp_loss};
use msgp_core::numeric::dual;
use msgp_core::numeric::linalg::JitterLog;
use msgp_core::numeric::parallel::Threads;

fn bench_loss(c: &mut Criterion) {
    let config = GpConfig::default();
    let complexity = Complexity::default();
    for (d, m, t) in [(4, 100, 500), (20, 100, 512)] {
        let (params, spec, episodes) = problem(m, d, t, 0).expect("problem");
        let mut group = c.benchmark_group(format!("msgp_loss_D{d}_m{m}_T{t}"));
        group
            .sample_size(10)
            .sampling_mode(SamplingMode::Flat)
            .warm_up_time(Duration::from_millis(500))
            .measurement_time(Duration::from_secs(3));
        group.bench_function("loss_f64", |b| {
            b.iter(|| {
                let mut log = JitterLog::default();
                black_box(
                    msgp_loss(&params, &config, &spec, &episodes, complexity, &mut log)
                        .expect("loss"),
                )
            })
        });
        group.bench_function("gradient_adjoint", |b| {
            b.iter(|| {
                let mut log = JitterLog::default();
                black_box(
                    loss::loss_and_gradient(
                        &params,
                        &config,
                        &spec,
                        &episodes,
                        complexity,
                        Threads::available(),
                        &mut log,
                    )
                    .expect("grad"),
                )
            })
        });
        // the filter likelihood's adjoint gradient on the same episodes (the fit's other loss)
        group.bench_function("filter_loss_and_gradient", |b| {
            b.iter(|| {
                let mut log = JitterLog::default();
                black_box(
                    loss::filter_loss_and_gradient(
                        &params,
                        &config,
                        &spec,
                        &episodes,
                        complexity,
                        Threads::available(),
                        &mut log,
                    )
                    .expect("filter grad"),
                )
            })
        });
        if d == 4 {
            // forward-mode duals: one chunk of LANES directions (the full gradient costs
            // P / LANES chunks)
            let x = params.to_flat();
            let shape = params.shape().expect("shape");
            let chunk: Vec<usize> = (0..dual::LANES).collect();
            group.bench_function("dual_one_chunk_of_8_directions", |b| {
                b.iter(|| {
                    black_box(
                        dual::gradient(&x, &chunk, 1, |xd| {
                            let p = GpParams::from_flat(shape, xd)?;
                            let mut log = JitterLog::default();
                            Ok(
                                msgp_loss(&p, &config, &spec, &episodes, complexity, &mut log)?
                                    .total(),
                            )
                        })
                        .expect("dual"),
                    )
                })
            });
        }
        group.finish();
    }
}

criterion_group!(benches, bench_loss);
criterion_main!(benches);
