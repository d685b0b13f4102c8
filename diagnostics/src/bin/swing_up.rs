//! The learning loop on the arm-mounted pendulum's swing-up (`msgp_sim::swing_up`): prints
//! every iteration (model searched, fit and search seconds, predicted and measured cost,
//! whether the iteration's own episode ended held upright, the success test over seeded
//! starts near hanging) and the interaction seconds up to the first success.
//!
//! `cargo run --release -p msgp-diagnostics --bin swing_up -- [seed] [settings.json]
//! [task.json] [params.json] [starts=N] [model=NAME]`
//!
//! `settings.json` / `task.json` / `params.json`: JSON objects (or files holding them) merged
//! into the defaults (`LearnerSettings::for_plant`, the swing-up's `TargetTask`, its
//! `PendulumParams`); `-` keeps them.
//! `starts=N`: the success test's starts (default 5). `model=NAME`: the loop's model
//! (`msgp-filter`, `msgp`, `gp-narx`, `linear-kf`; `with_model` on the settings), default the
//! preset's.
use std::ops::ControlFlow;

use msgp_core::learner::{LearnEvent, Learner, LearnerSettings, LoopModel, TargetTask, with_model};
use msgp_core::plant::Plant;
use msgp_diagnostics::{overridden, seed_and_starts};
use msgp_sim::swing_up::{
    SwingUp, SwingUpSuccess, held_upright, swing_up_params, swing_up_settings, swing_up_task,
};

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let (seed, starts) = seed_and_starts(&args, 5);
    let params: msgp_sim::PendulumParams = overridden(&swing_up_params(), args.get(3));
    let mut plant = SwingUp::new(&params).expect("plant");
    let target: TargetTask = overridden(&swing_up_task(), args.get(2));
    let settings = swing_up_settings(plant.spec(), seed);
    let mut settings: LearnerSettings = overridden(&settings, args.get(1));
    if let Some(name) = args.iter().find_map(|a| a.strip_prefix("model=")) {
        let model: LoopModel = name.parse().expect("model");
        settings = with_model(settings, model).expect("model settings");
    }
    let task = target.task(plant.spec(), seed).expect("task");
    let mut learner = Learner::new(task, settings).expect("learner");
    let mut success = SwingUpSuccess {
        plant: SwingUp::new(&params).expect("plant"),
        starts,
        steps: target.episode_steps,
    };
    let period = plant.spec().period;
    let clock = std::time::Instant::now();
    let mut held = false;
    let mut first: Option<(usize, f64)> = None;
    let result = learner.run(&mut plant, Some(&mut success), &mut |e| {
        match e {
            LearnEvent::Episode {
                episode,
                evaluation: false,
            } => {
                let thetas: Vec<f64> = episode.outputs.iter().map(|y| y[0]).collect();
                held = !episode.ended_early && held_upright(&thetas, period);
                let top = thetas.iter().map(|t| t.cos()).fold(-1.0, f64::max);
                // the largest distance from upright over the hold's last seconds
                let hold = (msgp_sim::swing_up::HOLD_SECONDS / period).round() as usize;
                let tau = std::f64::consts::TAU;
                let off = thetas[thetas.len().saturating_sub(hold)..]
                    .iter()
                    .map(|t| (t - tau * (t / tau).round()).abs())
                    .fold(0.0, f64::max);
                let reach = episode
                    .outputs
                    .iter()
                    .map(|y| y[2].abs())
                    .fold(0.0, f64::max);
                println!(
                    "      episode: {} steps{}, highest cos θ {top:.2}, max |x| {reach:.2}, \
                     farthest from upright over the last {hold} steps {off:.2} rad",
                    episode.outputs.len(),
                    if episode.ended_early {
                        " (rail end)"
                    } else {
                        ""
                    }
                );
            }
            LearnEvent::Iteration(r) => {
                println!(
                    "it {:2} model {:?} fit {:.1}s search {:.1}s predicted {:.1} actual {:.1} \
                     held {held} success {:?} interaction {:.0}s failure {:?} \
                     linear search failure {:?} held-out nll gp/linear {:?} free run gp/one-step {:?}",
                    r.iteration,
                    r.search_model,
                    r.fit_seconds,
                    r.search_seconds,
                    r.predicted_cost,
                    r.actual_cost,
                    r.success,
                    r.interaction_seconds,
                    r.search_failure,
                    r.linear_search_failure,
                    r.held_out
                        .as_ref()
                        .map(|h| (h.gp_nll.round(), h.linear_nll.round())),
                    r.held_out
                        .and_then(|h| h.rollout)
                        .map(|f| (f.gp.round(), f.one_step.round())),
                );
                if r.success == Some(true) && first.is_none() {
                    first = Some((r.iteration, r.interaction_seconds));
                }
            }
            _ => {}
        }
        ControlFlow::Continue(())
    });
    println!(
        "total {:.0}s: {result:?}; first success {first:?}",
        clock.elapsed().as_secs_f64()
    );
}
