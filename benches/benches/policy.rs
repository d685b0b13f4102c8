//! The pieces of one policy-learning iteration on the simulated pendulum (`msgp learn-policy`
//! defaults: outputs θ and x, l_y = 2, l_u = 3, m = 50, linear prior mean, PID + PD gains, 5 s =
//! 250-step closed-loop rollouts): one expected-cost evaluation in f64, the gradient over the 5
//! gains by the adjoint sweep (the search's) and by duals (5 and 8 lanes), a reduced policy search
//! (on every core and on one), and 20 Adam iterations of the MSGP fit on four random rollouts
//! plus one feedback episode; the two parts of a later MSGP fit (four feedback episodes): its
//! one-step start and its Adam iterations on the trajectory likelihood; and the value and
//! adjoint gradient of the linear-kf loop's problem (its model, a 10 s = 500-step horizon).
//!
//! The model is fitted once, outside the timings, on four 3 s random-excitation episodes and one
//! 3 s episode of the hand-tuned gains (seeded).

use std::hint::black_box;
use std::ops::ControlFlow;
use std::time::Duration;

use criterion::measurement::WallTime;
use criterion::{BenchmarkGroup, Criterion, SamplingMode, criterion_group, criterion_main};
use msgp_core::fit::{TrainingEpisode, fit_episodes};
use msgp_core::learner::{self, fit_and_search};
use msgp_core::model::Method;
use msgp_core::numeric::dual;
use msgp_core::numeric::parallel::Threads;
use msgp_core::policy::{PidPolicy, Policy, PolicySpec};
use msgp_core::policy_search::cost::SaturatingCost;
use msgp_core::policy_search::{
    PidMask, PolicyProblem, PolicySearchSettings, SearchSpace, optimise_pid_scaled,
};
use msgp_sim::learn::{
    LearnSettings, ModelChoice, episode_trajectory, learner_settings, modelled_policy,
    pendulum_task, segments,
};
use msgp_sim::{
    EpisodeConfig, PendulumParams, PidPdGains, PidPdPolicy, PlantTier, RandomExcitation,
    Saturation, run_episode,
};
use nalgebra::{DMatrix, DVector};

/// Four random rollouts (in `segment`-sample segments, or whole) and `feedback` 3 s episodes of
/// the hand-tuned gains (seeds 500, 501, …).
fn training(
    params: &PendulumParams,
    settings: &LearnSettings,
    feedback: u64,
    segment: Option<usize>,
) -> Vec<TrainingEpisode> {
    let mut out = Vec::new();
    for seed in 0..4u64 {
        let mut ex = RandomExcitation::new(seed, &settings.excitation).expect("excitation");
        let config = EpisodeConfig {
            seconds: settings.episode_seconds,
            seed,
            initial_theta: None,
        };
        let ep = run_episode(params, &mut ex, &config).expect("episode");
        let traj = episode_trajectory(&ep).expect("trajectory");
        let parts = match segment {
            Some(n) => segments(&traj, n, 8).expect("segments"),
            None => vec![traj],
        };
        for traj in parts {
            out.push(TrainingEpisode { traj, policy: None });
        }
    }
    let mut gains = PidPdGains::hand_tuned();
    gains.saturation = Saturation::Sine;
    for seed in 500..500 + feedback {
        let mut controller = PidPdPolicy::new(gains, params).expect("policy");
        let config = EpisodeConfig {
            seconds: settings.episode_seconds,
            seed,
            initial_theta: None,
        };
        let ep = run_episode(params, &mut controller, &config).expect("episode");
        out.push(TrainingEpisode {
            traj: episode_trajectory(&ep).expect("trajectory"),
            policy: Some(PolicySpec::Direct(msgp_core::policy::Policy::Pid(
                modelled_policy(&gains, params).expect("policy"),
            ))),
        });
    }
    out
}

/// A benchmark group of 10 flat samples over `seconds` (each sample is long).
fn flat_group<'a>(c: &'a mut Criterion, name: &str, seconds: u64) -> BenchmarkGroup<'a, WallTime> {
    let mut group = c.benchmark_group(name);
    group
        .sample_size(10)
        .sampling_mode(SamplingMode::Flat)
        .warm_up_time(Duration::from_millis(500))
        .measurement_time(Duration::from_secs(seconds));
    group
}

/// `expected_cost_f64` (one closed-loop rollout with its cost) and `gradient_adjoint` (the
/// search's gradient over the free gains) of `problem`.
fn value_and_adjoint_gradient(
    group: &mut BenchmarkGroup<'_, WallTime>,
    problem: &PolicyProblem<'_>,
    mask: &PidMask,
    initial: &PidPolicy<f64>,
    x: &[f64],
) {
    group.bench_function("expected_cost_f64", |b| {
        b.iter(|| black_box(problem.evaluate(initial).expect("evaluate")))
    });
    group.bench_function("gradient_adjoint", |b| {
        let space = SearchSpace::pid(initial, mask);
        b.iter(|| black_box(problem.gradient(&space, x).expect("gradient")))
    });
}

fn bench_policy(c: &mut Criterion) {
    let params = PendulumParams::default();
    let settings = LearnSettings::default();
    let episodes = training(&params, &settings, 1, Some(30));
    let fit = LearnSettings::for_method(Method::GpNarx).fit;
    let (model, _) = fit_episodes(&episodes, &fit, &mut |_| {}).expect("fit");
    let cost = SaturatingCost::with_widths(DVector::from_element(2, 0.0), &settings.cost_widths)
        .expect("cost");
    let problem = PolicyProblem {
        model: &model,
        y0_mean: vec![0.0, 0.0],
        y0_var: vec![params.initial_theta_std.powi(2), 1e-8],
        u0: vec![0.0],
        cost,
        horizon: 250,
    };
    let mut gains = PidPdGains::hand_tuned();
    gains.saturation = Saturation::Sine;
    let initial = modelled_policy(&gains, &params).expect("policy");
    let mask = PidMask {
        kp: DMatrix::from_element(1, 2, true),
        ki: DMatrix::from_row_slice(1, 2, &[false, true]),
        kd: DMatrix::from_element(1, 2, true),
    };
    let x = mask.pack(&initial);
    let typical: Vec<f64> = x.iter().map(|g| g.abs().max(1.0)).collect();
    let all: Vec<usize> = (0..x.len()).collect();

    let mut group = flat_group(c, "policy_pendulum_m50_H250", 4);
    // the search's gradient: the rollout's adjoint sweep; and the duals it replaced (5 lanes for
    // 5 gains, and the generic 8) for comparison
    value_and_adjoint_gradient(&mut group, &problem, &mask, &initial, &x);
    group.bench_function("gradient_dual_5_lanes", |b| {
        b.iter(|| {
            black_box(
                dual::gradient_lanes::<5, _>(&x, &all, 1, |gd| {
                    Ok(problem.evaluate(&mask.unpack(&initial, gd))?.0)
                })
                .expect("gradient"),
            )
        })
    });
    group.bench_function("gradient_dual_8_lanes", |b| {
        b.iter(|| {
            black_box(
                dual::gradient(&x, &all, 1, |gd| {
                    Ok(problem.evaluate(&mask.unpack(&initial, gd))?.0)
                })
                .expect("gradient"),
            )
        })
    });
    // 20 screened candidates + 2 Adam starts × 5 steps: 20 + 2·(5 + 1) f64 rollouts and 10
    // gradients (the learn-policy default is 150 candidates and 4 starts × 20 steps)
    let search = PolicySearchSettings {
        iterations: 5,
        restarts: 0,
        candidates: 20,
        candidate_starts: 1,
        ..settings.search
    };
    for threads in [1, 2] {
        group.bench_function(
            format!("search_20_candidates_2x5_steps_threads{threads}"),
            |b| {
                let search = PolicySearchSettings {
                    threads: Threads::new(threads).expect("threads"),
                    ..search
                };
                b.iter(|| {
                    black_box(
                        optimise_pid_scaled(&problem, &initial, &mask, &typical, &search)
                            .expect("search"),
                    )
                })
            },
        );
    }
    group.finish();

    // the linear-kf loop's problem: its model (no GP) and its 10 s (500-step) horizon, where the
    // policy's per-step vector–Jacobian product is most of the adjoint sweep
    let kf_settings = LearnSettings::for_method(Method::LinearKf);
    let kf_fit = kf_settings.fit.clone();
    let (kf_model, _) = fit_episodes(&episodes, &kf_fit, &mut |_| {}).expect("linear-kf fit");
    let kf_problem = PolicyProblem {
        model: &kf_model,
        y0_mean: problem.y0_mean.clone(),
        y0_var: problem.y0_var.clone(),
        u0: problem.u0.clone(),
        cost: problem.cost.clone(),
        horizon: (kf_settings.policy_horizon_seconds * params.control_rate_hz).round() as usize,
    };
    let mut group = flat_group(c, "policy_pendulum_linear_kf_H500", 4);
    value_and_adjoint_gradient(&mut group, &kf_problem, &mask, &initial, &x);
    group.finish();

    let mut group = flat_group(c, "fit_pendulum_m50", 10);
    let msgp_with = |iterations, one_step_iterations| {
        let mut s = settings.fit.clone();
        let m = s.msgp_mut().expect("the loop's default model is MSGP");
        m.iterations = iterations;
        m.one_step_iterations = one_step_iterations;
        s
    };
    let msgp = msgp_with(20, 20);
    group.bench_function("msgp_20_one_step_plus_20_adam_iterations", |b| {
        b.iter(|| black_box(fit_episodes(&episodes, &msgp, &mut |_| {}).expect("fit")))
    });
    // the loop's later fits: four feedback episodes (about 900 one-step pairs, two outputs),
    // where the one-step start and the closed-loop episodes dominate
    let later = training(&params, &settings, 4, Some(30));
    let one_step = msgp_with(0, 20);
    group.bench_function("msgp_one_step_20_iterations_4_feedback_episodes", |b| {
        b.iter(|| black_box(fit_episodes(&later, &one_step, &mut |_| {}).expect("fit")))
    });
    let adam = msgp_with(10, 0);
    group.bench_function("msgp_10_adam_iterations_4_feedback_episodes", |b| {
        b.iter(|| black_box(fit_episodes(&later, &adam, &mut |_| {}).expect("fit")))
    });
    // the linear-kf model the loop fits with `--model linear-kf`, to convergence (two starts)
    let kf = LearnSettings::for_method(Method::LinearKf).fit;
    group.bench_function("linear_kf_full_fit", |b| {
        b.iter(|| black_box(fit_episodes(&episodes, &kf, &mut |_| {}).expect("fit")))
    });
    group.finish();
}

/// One iteration of the default loop (`msgp learn-policy --sim pendulum`: the filtered MSGP,
/// m = 30, warm-started fit, the linear competitor's warm fit and the prequential choice, 10 s
/// policy horizon, 12 Adam steps per search start), as the loop
/// runs it ([`msgp_core::learner::fit_and_search`] with the pendulum's task), at the state of its fifth iteration on each plant tier:
/// four random-excitation episodes and four feedback episodes of the hand-tuned gains (3 s
/// each, whole, seeded), the previous model fitted (outside the timing) on all but the last
/// episode. The target: fit + search ≤ 5 s alone on the 2-core machine.
fn bench_loop_iteration(c: &mut Criterion) {
    let settings = LearnSettings::for_model(Method::Msgp, None);
    let mut group = flat_group(c, "loop_iteration_filtered_msgp_m30", 60);
    for tier in [PlantTier::Apollo, PlantTier::Noisy] {
        let params = PendulumParams::tier(tier);
        let data = training(&params, &settings, 4, None);
        let mut gains = PidPdGains::hand_tuned();
        gains.saturation = Saturation::Sine;
        let policy = Policy::Pid(modelled_policy(&gains, &params).expect("valid"));
        let task = pendulum_task(&params, &settings).expect("valid");
        let learner = learner_settings(&params, &settings).expect("valid");
        let quiet = &mut |_: learner::LearnEvent<'_>| ControlFlow::Continue(());
        // the previous iteration, whose models then predict the last episode (the
        // prequential choice's score)
        let mut choice = ModelChoice::new(&learner).expect("an MSGP loop");
        let step = fit_and_search(
            &task,
            &learner,
            (&[], &data[..7]),
            None,
            &policy,
            4,
            Some(&mut choice),
            quiet,
        )
        .expect("previous iteration");
        let linear = step.linear.expect("the linear competitor");
        choice
            .score(&step.model, &linear, None, &data[7..])
            .expect("held-out scores");
        let previous = step.model;
        group.bench_function(format!("fit_and_search_{}_8_episodes", tier.name()), |b| {
            b.iter(|| {
                let quiet = &mut |_: learner::LearnEvent<'_>| ControlFlow::Continue(());
                let mut choice = choice.clone();
                black_box(
                    fit_and_search(
                        &task,
                        &learner,
                        (&[], &data),
                        Some(&previous),
                        &policy,
                        5,
                        Some(&mut choice),
                        quiet,
                    )
                    .expect("iteration"),
                )
            })
        });
    }
    group.finish();
}

criterion_group!(benches, bench_policy, bench_loop_iteration);
criterion_main!(benches);
