//! Why MSGP loses the swing-up to one-step GP-NARX: the loop of `settings.json` (default the
//! swing-up's, MSGP on the filter likelihood) runs `iterations` iterations; then both models
//! — the loop's MSGP and GP-NARX with its start settings — are fitted to the same episodes
//! (each iteration's fit replayed, `Learner::from_episodes`) and each takes the next search.
//! Printed per model: its noise and signal variances, its search's predicted cost, the
//! predicted per-step cost (mean ± sd) of both searched policies and of the last episode's on
//! both models, and what each searched policy costs on the plant from the success test's
//! starts.
//!
//! `cargo run --release -p msgp-diagnostics --bin swing_up_models -- [seed] [settings.json]
//! iterations=N`
use std::ops::ControlFlow;

use msgp_core::learner::LoopModel;
use msgp_core::learner::with_model;
use msgp_core::learner::{Actor, Episode, Learner, LearnerSettings, run_episode};
use msgp_core::model::Model;
use msgp_core::plant::Plant;
use msgp_core::policy::Policy;
use msgp_core::policy_search::PolicyProblem;
use msgp_diagnostics::{Switches, overridden};
use msgp_sim::swing_up::{
    SwingUp, held_upright, success_seed, swing_up_params, swing_up_settings, swing_up_task,
};

fn main() {
    let switches = Switches::from_args(2, &["iterations"]).unwrap_or_else(|e| panic!("{e}"));
    let seed: u64 = switches.arg(0, "seed").expect("seed").unwrap_or(0);
    let iterations: usize = switches.get("iterations").expect("iterations").unwrap_or(6);
    let params = swing_up_params();
    let mut plant = SwingUp::new(&params).expect("plant");
    let target = swing_up_task();
    let base = swing_up_settings(plant.spec(), seed);
    let mut settings: LearnerSettings = overridden(&base, switches.positional().get(1));
    settings.iterations = iterations;
    let task = target.task(plant.spec(), seed).expect("task");
    let mut learner = Learner::new(task.clone(), settings.clone()).expect("learner");
    learner
        .run(&mut plant, None, &mut |_| ControlFlow::Continue(()))
        .expect("loop");
    for r in learner.reports() {
        println!(
            "it {:2} {:?} predicted {:.1} actual {:.1}",
            r.iteration, r.search_model, r.predicted_cost, r.actual_cost
        );
    }
    let episodes: Vec<Episode> = learner.episodes().to_vec();
    let last = episodes.last().expect("episodes").clone();
    let narx = with_model(settings.clone(), LoopModel::GpNarx).expect("gp-narx");
    let mut searched: Vec<(&str, Model, Policy)> = Vec::new();
    for (name, s) in [("msgp", settings.clone()), ("gp-narx", narx)] {
        let mut l = Learner::from_episodes(task.clone(), s, episodes.clone(), &mut |_| {
            ControlFlow::Continue(())
        })
        .expect("replay");
        let step = l
            .improve(&mut |_| ControlFlow::Continue(()))
            .expect("improve");
        let model = step.model.clone();
        let p = &model.params;
        let exp = |v: &nalgebra::DVector<f64>| -> Vec<String> {
            v.iter().map(|x| format!("{:.2e}", x.exp())).collect()
        };
        println!(
            "{name}: search on {:?} predicted {:?}; process noise {:?}, obs noise {:?}, signal {:?}, calibration {:?}, lengthscales {:?}",
            step.search_model,
            step.searched.as_ref().map(|r| r.expected_cost),
            exp(&p.log_process_noise),
            exp(&p.log_obs_noise),
            exp(&p.log_signal_var),
            model.calibration,
            p.log_lengthscales
                .map(f64::exp)
                .row_iter()
                .map(|r| r
                    .iter()
                    .map(|x| format!("{x:.2}"))
                    .collect::<Vec<_>>()
                    .join(" "))
                .collect::<Vec<_>>(),
        );
        let policy = match &step.searched {
            Ok(r) => r.policy.clone(),
            Err(_) => l.policy().clone(),
        };
        searched.push((name, model, policy));
    }
    let last_policy = last.policy.clone().expect("policy episode");
    let policies: Vec<(String, &Policy)> = searched
        .iter()
        .map(|(n, _, p)| (format!("{n}'s search"), p))
        .chain(std::iter::once((
            "last episode's".to_string(),
            &last_policy,
        )))
        .collect();
    for (model_name, model, _) in &searched {
        for (policy_name, policy) in &policies {
            let problem = PolicyProblem {
                model,
                y0_mean: last.outputs[0].clone(),
                y0_var: vec![1e-4; last.outputs[0].len()],
                u0: vec![0.0],
                cost: task.cost.clone(),
                horizon: target.policy_horizon,
            };
            match problem.evaluate(policy.lift::<f64>().as_ref()) {
                Ok((total, steps)) => {
                    let line: Vec<String> = steps
                        .iter()
                        .step_by(5)
                        .map(|(m, v)| format!("{m:.2}±{:.2}", v.max(0.0).sqrt()))
                        .collect();
                    println!(
                        "on {model_name}, {policy_name} policy: total {total:.1}; {}",
                        line.join(" ")
                    );
                }
                Err(e) => println!("on {model_name}, {policy_name} policy: {e}"),
            }
        }
    }
    let actual: Vec<String> = last
        .outputs
        .iter()
        .step_by(5)
        .map(|y| format!("{:.2}", task.cost.at(y)))
        .collect();
    println!("last episode measured: {}", actual.join(" "));
    for (name, _, policy) in &searched {
        let rest = plant.spec().bounds().expect("bounds").mid();
        let actor = Actor::Policy {
            policy,
            rest: &rest,
        };
        let costs: Vec<String> = (0..5)
            .map(|k| {
                let ep = run_episode(&mut plant, &actor, success_seed(k), target.episode_steps)
                    .expect("episode");
                let thetas: Vec<f64> = ep.outputs.iter().map(|y| y[0]).collect();
                format!(
                    "{:.1}{}",
                    ep.cost(&task.cost, 1, target.episode_steps),
                    if held_upright(&thetas, plant.spec().period) {
                        " held"
                    } else {
                        ""
                    }
                )
            })
            .collect();
        println!(
            "{name}'s searched policy on the plant: {}",
            costs.join(", ")
        );
    }
}
