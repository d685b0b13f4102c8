//! The arm swing-up learned by the loop (`msgp_sim::swing_up`): a short seeded run with the
//! task's defaults lowers the measured cost well below the hanging pole's, with its searches
//! on the GP model (the prequential choice deciding).

use std::ops::ControlFlow;

use msgp_core::learner::{Learner, SearchModel};
use msgp_core::plant::Plant;
use msgp_sim::swing_up::{
    EPISODE_STEPS, SwingUp, swing_up_params, swing_up_settings, swing_up_task,
};

/// The measured cost of an episode with the command held at zero (the pole hangs).
fn hanging_cost(plant: &mut SwingUp, cost: &msgp_core::policy_search::SaturatingCost) -> f64 {
    plant.reset(1).expect("reset");
    (0..EPISODE_STEPS)
        .map(|_| cost.at(&plant.step(&[0.0]).expect("step").observation))
        .sum()
}

/// Eight iterations at seed 0 (measured: the episodes' cost goes 38.9, 33.4, 34.9, 28.5, 34.1,
/// 31.1, 31.6, 30.3 against the hanging pole's 39.7 under the task's two widths; iterations 2–8
/// search on the GP model). Required: an episode at least 15 % cheaper than hanging, and at
/// least six of the seven searches after the first on the GP model by the prequential choice
/// (not by the fallback from a failed linear search). A loop whose search does not leave
/// hanging stays at 38.9–39.7 (with one width of 0.5 the search on a confident model never
/// moved: `docs/experiments/2026-12-07-the-swing-ups-cost-was-flat-several-widths.md`).
#[test]
fn eight_iterations_swing_the_pole_and_search_on_the_gp() {
    let mut plant = SwingUp::new(&swing_up_params()).expect("plant");
    let task = swing_up_task().task(plant.spec(), 0).expect("task");
    let hanging = hanging_cost(&mut plant, &task.cost);
    // per step 1 − ½ (e^{−8} + e^{−8/9}): the tip 2 from upright at widths 0.5 and 1.5
    let per_step = 1.0 - 0.5 * ((-8.0f64).exp() + (-8.0f64 / 9.0).exp());
    assert!(
        (hanging - 50.0 * per_step).abs() < 0.3,
        "the hanging pole costs {per_step:.3} per step: {hanging}"
    );
    let mut settings = swing_up_settings(plant.spec(), 0);
    settings.iterations = 8;
    settings.evaluation_episodes = 0;
    let mut learner = Learner::new(task, settings).expect("learner");
    learner
        .run(&mut plant, None, &mut |_| ControlFlow::Continue(()))
        .expect("run");
    let reports = learner.reports();
    let best = reports
        .iter()
        .map(|r| r.actual_cost)
        .fold(f64::INFINITY, f64::min);
    let costs: Vec<f64> = reports.iter().map(|r| r.actual_cost).collect();
    assert!(best <= 0.85 * hanging, "{costs:?} vs hanging {hanging}");
    let on_gp = reports[1..]
        .iter()
        .filter(|r| r.search_model == Some(SearchModel::Gp) && r.linear_search_failure.is_none())
        .count();
    assert!(
        on_gp >= 6,
        "{:?}",
        reports.iter().map(|r| r.search_model).collect::<Vec<_>>()
    );
}
