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

/// Eight iterations at seed 0 (measured: the episodes' cost goes 49.0, 47.3, 44.5, 45.2, 40.8,
/// 44.3, 43.7, 40.0 against the hanging pole's 50.0; iterations 2–8 search on the GP model;
/// before the warm starts grew their pseudo-inputs, 49.0, 47.5, 48.7, 47.6, 45.5, 46.5, 37.7,
/// 34.7). Required: an episode at least 15 % cheaper than hanging, and at least six of the
/// seven searches after the first on the GP model by the prequential choice (not by the
/// fallback from a failed linear search). A loop that does not learn to swing stays above 45.
#[test]
fn eight_iterations_swing_the_pole_and_search_on_the_gp() {
    let mut plant = SwingUp::new(&swing_up_params()).expect("plant");
    let task = swing_up_task().task(plant.spec(), 0).expect("task");
    let hanging = hanging_cost(&mut plant, &task.cost);
    assert!(
        hanging > 49.5,
        "the hanging pole costs about 1 per step: {hanging}"
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
