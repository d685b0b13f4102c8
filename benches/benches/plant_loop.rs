//! One iteration (model fit + policy search) of the learning loop on a plant of the Gymnasium
//! route, as `msgp.learn_policy(env=gym.make("Pendulum-v1"))` runs it: the preset's task and
//! settings (`msgp_sim::gym_pendulum::pendulum_v1_task`, `pendulum_v1_settings`: the filtered
//! MSGP with the prequential linear competitor, an RBF network of 50 basis functions searched
//! by L-BFGS from the latest 8 episodes' starts over 100-step rollouts) on the environment's
//! equations in Rust. The loop runs its first 7 iterations at seed 0 outside the timing; the
//! timed iteration is the eighth (8 policy episodes and the random one), the middle of the
//! preset's 14. The target: ≤ 10 s alone on the 2-core machine.
//!
//! Beside it, the search's unit of work on the same model: the adjoint gradient of every start's
//! closed-loop rollout at the task's first policy, one of the search's two starts (an L-BFGS
//! iteration is one of these, plus its line search's evaluations).
//!
//! The arm swing-up's iteration (`msgp_sim::swing_up`) is timed the same way at its eighth.

use std::hint::black_box;
use std::ops::ControlFlow;
use std::time::Duration;

use criterion::{Criterion, SamplingMode, criterion_group, criterion_main};
use msgp_core::learner::{Learner, LearnerSettings, TargetTask};
use msgp_core::plant::Plant;
use msgp_sim::gym_pendulum::{
    GymPendulum, GymPendulumParams, pendulum_v1_settings, pendulum_v1_task,
};
use msgp_sim::swing_up::{SwingUp, swing_up_params, swing_up_settings, swing_up_task};

/// The loop on `plant` after `iterations` iterations (no evaluation episodes).
fn learner_after(
    plant: &mut dyn Plant,
    task: &TargetTask,
    mut settings: LearnerSettings,
    iterations: usize,
) -> Learner {
    settings.iterations = iterations;
    settings.evaluation_episodes = 0;
    let task = task.task(plant.spec(), settings.seed).expect("task");
    let mut learner = Learner::new(task, settings).expect("learner");
    learner
        .run(plant, None, &mut |_| ControlFlow::Continue(()))
        .expect("the loop's first iterations");
    learner
}

fn bench_plant_loop(c: &mut Criterion) {
    let mut group = c.benchmark_group("plant_loop_iteration");
    group
        .sample_size(10)
        .sampling_mode(SamplingMode::Flat)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(120));
    let mut env = GymPendulum::new(GymPendulumParams::default());
    let settings = pendulum_v1_settings(env.spec(), 0);
    let learner = learner_after(&mut env, &pendulum_v1_task(), settings, 7);
    group.bench_function("pendulum_v1_eighth_iteration", |b| {
        b.iter(|| {
            let mut next = learner.clone();
            black_box(
                next.improve(&mut |_| ControlFlow::Continue(()))
                    .expect("iteration"),
            )
        })
    });
    // the search's unit of work: the adjoint gradient of the mean expected cost over the
    // problems (one 100-step closed-loop rollout from each of the latest episodes' starts), at
    // the task's first policy, on the model the eighth iteration searched
    let mut next = learner.clone();
    let step = next
        .improve(&mut |_| ControlFlow::Continue(()))
        .expect("iteration");
    let problems = next.task().problems(step.searched_model(), next.episodes());
    let space = &next.task().space;
    let x = space.start();
    group.bench_function(
        format!("pendulum_v1_search_gradient_{}_starts", problems.len()),
        |b| {
            b.iter(|| {
                for problem in &problems {
                    black_box(problem.gradient(space, &x).expect("gradient"));
                }
            })
        },
    );
    let mut arm = SwingUp::new(&swing_up_params()).expect("plant");
    let settings = swing_up_settings(arm.spec(), 0);
    let learner = learner_after(&mut arm, &swing_up_task(), settings, 7);
    group.bench_function("arm_swing_up_eighth_iteration", |b| {
        b.iter(|| {
            let mut next = learner.clone();
            black_box(
                next.improve(&mut |_| ControlFlow::Continue(()))
                    .expect("iteration"),
            )
        })
    });
    group.finish();
}

criterion_group!(benches, bench_plant_loop);
criterion_main!(benches);
