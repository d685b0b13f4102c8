//! The learning loop on Gymnasium's `Pendulum-v1` (the Rust copy of its equations,
//! `msgp_sim::gym_pendulum`), with the Python preset's task and the loop's defaults, each
//! overridable: prints every iteration (model searched, fit and search seconds, predicted and
//! measured cost, the search's failure if any) and the final policy's mean return over
//! seeded 200-step episodes.
//!
//! `cargo run --release -p msgp-diagnostics --bin pendulum_v1 -- [seed] [settings.json]
//! [task.json] [starts=N] [research] [probe]`
//!
//! `settings.json` / `task.json`: JSON objects (or files holding them) merged into the
//! Python preset's settings and task (`msgp_sim::gym_pendulum::pendulum_v1_settings`,
//! `pendulum_v1_task`); `-` keeps them. `starts=N`: evaluation episodes of each policy (default 30).
//! `hanging`: every interaction episode starts hanging (θ = π ± 0.05; evaluation as
//! always from uniform starts). `research`: after the loop, the next model's closed-loop predictions of the latest
//! episodes against their measured cost, and searches with other settings on it. `probe`:
//! the next model's fit, free run of the first episode, and the cost of a rollout and its
//! gradient.
use std::ops::ControlFlow;

use msgp_core::learner::{Actor, LearnEvent, Learner, LearnerSettings, TargetTask, run_episode};
use msgp_core::plant::Plant;
use msgp_diagnostics::{overridden, seed_and_starts};
use msgp_sim::gym_pendulum::{
    GymPendulum, GymPendulumParams, pendulum_v1_settings, pendulum_v1_task,
};

/// The environment started hanging (θ = π ± 0.05, θ̇ = 0): PILCO's swing-up task, for
/// telling the difficulty of starts all around the circle from the model's.
struct Hanging(GymPendulum);

impl Plant for Hanging {
    fn spec(&self) -> &msgp_core::plant::PlantSpec {
        self.0.spec()
    }

    fn reset(&mut self, seed: u64) -> msgp_core::Result<Vec<f64>> {
        let y = self.0.reset(seed)?;
        // the uniform draw of θ moved to a small offset from hanging
        let theta = std::f64::consts::PI + 0.05 * y[1].atan2(y[0]) / std::f64::consts::PI;
        Ok(self.0.set_state(theta, 0.0))
    }

    fn step(&mut self, command: &[f64]) -> msgp_core::Result<msgp_core::plant::PlantStep> {
        self.0.step(command)
    }
}

/// Mean return of `policy` over `n` seeded 200-step episodes.
fn mean_return(policy: &msgp_core::policy::Policy, params: GymPendulumParams, n: usize) -> f64 {
    let mut env = GymPendulum::new(params);
    let mut total = 0.0;
    let actor = Actor::Policy {
        policy,
        rest: &[0.0],
    };
    let mut rets = Vec::new();
    let mut upright_end = 0;
    for k in 0..n {
        let ep = run_episode(&mut env, &actor, 1_000_000 + k as u64, 200).expect("episode");
        total += env.ret;
        rets.push(env.ret.round());
        upright_end += usize::from(ep.outputs[150..].iter().all(|y| y[0] > 0.995));
    }
    rets.sort_by(f64::total_cmp);
    println!("      returns {rets:?}; upright over the last 50 steps in {upright_end}/{n}");
    total / n as f64
}

/// Searches on the next iteration's model with other search settings: how much lower the
/// model's cost goes than the loop's search found.
fn research(learner: &Learner, params: GymPendulumParams, n: usize) {
    use msgp_core::policy_search::{PolicySearchSettings, optimise_over};
    let mut copy = learner.clone();
    let step = copy
        .improve(&mut |_| ControlFlow::Continue(()))
        .expect("improve");
    let task = learner.task();
    let problems = task.problems(step.searched_model(), learner.episodes());
    println!(
        "model searched: {:?}; loop's search: {:?}",
        step.search_model,
        step.searched.as_ref().map(|r| r.expected_cost)
    );
    // the model's closed-loop prediction of the latest episodes (their start, their policy)
    // against what they measured, cost per step
    let model = step.searched_model();
    for ep in learner.episodes().iter().rev().take(3) {
        let Some(policy) = &ep.policy else { continue };
        let problem = msgp_core::policy_search::PolicyProblem {
            model,
            y0_mean: ep.outputs[0].clone(),
            y0_var: vec![1e-6; 3],
            u0: vec![0.0],
            cost: task.cost.clone(),
            horizon: 100,
        };
        let lifted = policy.lift::<f64>();
        match problem.evaluate(lifted.as_ref()) {
            Ok((_, steps)) => {
                let line: Vec<String> = (0..steps.len())
                    .step_by(10)
                    .map(|t| {
                        let y = &ep.outputs[(t + 1).min(ep.outputs.len() - 1)];
                        let actual = task.cost.at(y);
                        format!("{:.2}±{:.2}/{:.2}", steps[t].0, steps[t].1.sqrt(), actual)
                    })
                    .collect();
                println!(
                    "episode {}: predicted±sd/actual: {}",
                    ep.seed,
                    line.join(" ")
                );
            }
            Err(e) => println!("episode {}: {e}", ep.seed),
        }
    }
    // the loop's own search settings, varied; (name, settings, from the task's first policy
    // instead of the running one)
    let base = learner.settings().search;
    let variants: Vec<(&str, PolicySearchSettings, bool)> = vec![
        ("running only", base, false),
        ("first only", base, true),
        (
            "running, 300 its",
            PolicySearchSettings {
                iterations: 300,
                ..base
            },
            false,
        ),
        (
            "running + 4 restarts 0.5",
            PolicySearchSettings {
                restarts: 4,
                restart_spread: 0.5,
                ..base
            },
            false,
        ),
        (
            "first + 4 restarts 1.0",
            PolicySearchSettings {
                restarts: 4,
                restart_spread: 1.0,
                ..base
            },
            true,
        ),
    ];
    for (name, s, from_first) in variants {
        let space = if from_first {
            task.space.clone()
        } else {
            task.space_at(learner.policy())
        };
        let clock = std::time::Instant::now();
        match optimise_over(&problems, &space, &task.typical, &s, &[]) {
            Ok(r) => println!(
                "{name}: predicted {:.1} in {:.1}s; return over {n} starts {:.1}",
                r.expected_cost,
                clock.elapsed().as_secs_f64(),
                mean_return(&r.policy, params, n)
            ),
            Err(e) => println!("{name}: {e}"),
        }
    }
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (seed, starts) = seed_and_starts(&args, 30);
    let params = GymPendulumParams::default();
    let mut env = GymPendulum::new(params);
    let target: TargetTask = overridden(&pendulum_v1_task(), args.get(2));
    let settings = pendulum_v1_settings(env.spec(), seed);
    let settings: LearnerSettings = overridden(&settings, args.get(1));
    let task = target.task(env.spec(), seed).expect("task");
    let mut learner = Learner::new(task, settings).expect("learner");
    let clock = std::time::Instant::now();
    let mut hanging = Hanging(env.clone());
    let plant: &mut dyn Plant = if args.iter().any(|a| a == "hanging") {
        &mut hanging
    } else {
        &mut env
    };
    let result = learner.run(plant, None, &mut |e| {
        if let LearnEvent::Iteration(r) = e {
            println!(
                "it {:2} model {:?} fit {:.1}s search {:.1}s predicted {:.1} actual {:.1} \
                 expected {:?} failure {:?} fit_stop {:?}",
                r.iteration,
                r.search_model,
                r.fit_seconds,
                r.search_seconds,
                r.predicted_cost,
                r.actual_cost,
                r.expected_cost.map(|c| (c * 10.0).round() / 10.0),
                r.search_failure,
                r.fit_numerical_stop
            );
            if let Some(p) = &r.policy {
                println!(
                    "      return over {starts} starts: {:.1}",
                    mean_return(p, params, starts)
                );
            }
        }
        ControlFlow::Continue(())
    });
    println!("total {:.0}s: {result:?}", clock.elapsed().as_secs_f64());
    if args.iter().any(|a| a == "research") {
        research(&learner, params, starts);
    }
    if args.iter().any(|a| a == "probe") {
        let step = learner
            .improve(&mut |_| ControlFlow::Continue(()))
            .expect("improve");
        let problems = learner
            .task()
            .problems(step.searched_model(), learner.episodes());
        let problem = &problems[problems.len() - 1];
        let model = step.searched_model();
        let pr = &model.params;
        println!(
            "fit: its {} best {} history tail {:?} stop {:?} diverged {:?}",
            step.fit_report.iterations_run,
            step.fit_report.best_iteration,
            step.fit_report
                .history
                .iter()
                .rev()
                .take(3)
                .collect::<Vec<_>>(),
            step.fit_report.numerical_stop,
            step.fit_report.diverged
        );
        println!(
            "log ell {:.2}\nlog sf2 {:.2} log proc {:.2} log obs {:.2}\nlinear mean {:.3}",
            pr.log_lengthscales,
            pr.log_signal_var.transpose(),
            pr.log_process_noise.transpose(),
            pr.log_obs_noise.transpose(),
            pr.linear_mean
        );
        let traj = learner.episodes()[0].trajectory().expect("traj");
        match model.simulate(&traj) {
            Ok(sim) => {
                for t in (0..sim.mean.nrows()).step_by(10) {
                    println!(
                        "sim {t}: mean {:?} var {:?} true {:?}",
                        sim.mean.row(t).iter().collect::<Vec<_>>(),
                        sim.var.row(t).iter().collect::<Vec<_>>(),
                        learner.episodes()[0].outputs[t + sim.start]
                    );
                }
            }
            Err(e) => println!("simulate: {e}"),
        }
        println!("filter nll {:?}", model.filter_nll(&traj));
        println!("start {:?} {:?}", problem.y0_mean, problem.y0_var);
        let policy = learner.policy().lift::<f64>();
        println!(
            "evaluate: {:?}",
            problem.evaluate(policy.as_ref()).map(|(c, s)| (c, s.len()))
        );
        let clock = std::time::Instant::now();
        for _ in 0..20 {
            problem
                .gradient(&learner.task().space, &learner.task().space.start())
                .ok();
        }
        println!(
            "gradient: {:.1} ms each",
            clock.elapsed().as_secs_f64() * 50.0
        );
        let clock = std::time::Instant::now();
        for _ in 0..20 {
            problem.evaluate(policy.as_ref()).ok();
        }
        println!(
            "evaluate: {:.1} ms each",
            clock.elapsed().as_secs_f64() * 50.0
        );
        println!(
            "gradient: {:?}",
            problem
                .gradient(&learner.task().space, &learner.task().space.start())
                .map(|(v, _)| v)
        );
    }
}
