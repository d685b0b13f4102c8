//! Tests of the learning loop.

use super::*;

fn report(iteration: usize, actual_cost: f64, stable: bool) -> IterationReport {
    IterationReport {
        iteration,
        predicted_cost: 1.0,
        predicted_cost_std: 0.1,
        actual_cost,
        expected_cost: None,
        held: false,
        search_model: None,
        held_out: None,
        interaction_seconds: 12.0 + 3.0 * iteration as f64,
        stable,
        fit_seconds: 1.0,
        search_seconds: 1.0,
        fit_numerical_stop: None,
        search_failure: None,
        gains: PidPdGains {
            kp_x: iteration as f64,
            ki_x: 0.0,
            kd_x: 0.0,
            kp_theta: 10.0,
            kd_theta: 2.0,
            saturation: Saturation::Sine,
        },
    }
}

fn outcome(iterations: Vec<IterationReport>) -> LearnOutcome {
    LearnOutcome {
        iterations,
        episodes: Vec::new(),
        final_gains: PidPdGains::hand_tuned(),
        random_policies: Vec::new(),
    }
}

#[test]
fn the_best_iteration_is_the_first_stable_else_the_cheapest() {
    let best = |o: &LearnOutcome| o.best_iteration().map(|r| r.iteration);
    // a stable iteration wins over a cheaper unstable one, and the first stable over later
    let o = outcome(vec![
        report(1, 2.0, false),
        report(2, 5.0, true),
        report(3, 1.0, true),
    ]);
    assert_eq!(best(&o), Some(2));
    assert_eq!(o.first_stable_iteration(), Some(2));
    // none stable: the lowest measured cost, the earliest on ties, NaN never
    let o = outcome(vec![
        report(1, f64::NAN, false),
        report(2, 4.0, false),
        report(3, 3.0, false),
        report(4, 3.0, false),
        report(5, 90.0, false),
    ]);
    assert_eq!(best(&o), Some(3));
    assert_eq!(o.best_iteration().map(|r| r.gains.kp_x), Some(3.0));
    assert_eq!(best(&outcome(vec![report(1, f64::NAN, false)])), None);
    assert_eq!(best(&outcome(Vec::new())), None);
}

/// The expected cost of the loop's reports is the mean of its evaluation episodes: seeded (the
/// same call, the same number; another iteration, other episodes), near the mean of many more
/// episodes (a single episode's cost is not: its spread is as large as its mean), and absent
/// without evaluation episodes.
#[test]
fn the_expected_cost_is_the_mean_of_seeded_evaluation_episodes() {
    let params = PendulumParams::default();
    let gains = PidPdGains::apollo_lqr();
    let settings = LearnSettings::default();
    let cost = SaturatingCost::with_widths(DVector::from_element(2, 0.0), &settings.cost_widths)
        .expect("cost");
    let scored = (3, 148);
    let at = |it: usize, s: &LearnSettings| {
        expected_cost(&params, &gains, s, it, &cost, scored).expect("episodes")
    };
    let fifty = at(1, &settings).expect("evaluated");
    assert_eq!(at(1, &settings), Some(fifty), "seeded");
    assert_ne!(
        at(2, &settings),
        Some(fifty),
        "each iteration its own episodes"
    );
    let many = LearnSettings {
        evaluation_episodes: 200,
        seed: 99,
        ..settings.clone()
    };
    let reference = at(1, &many).expect("evaluated");
    assert!(
        (fifty / reference - 1.0).abs() < 0.35,
        "mean of 50: {fifty}, of 200: {reference}"
    );
    // single episodes scatter over a factor far above 2 around that mean
    let singles: Vec<f64> = (0..20)
        .map(|k| {
            let one = LearnSettings {
                evaluation_episodes: 1,
                seed: 1000 + k,
                ..settings.clone()
            };
            at(1, &one).expect("one episode") / reference
        })
        .collect();
    let within = singles.iter().filter(|r| (0.5..=2.0).contains(*r)).count();
    assert!(
        within < 16,
        "single episodes within 2x of the mean: {within}/20 {singles:?}"
    );
    let none = LearnSettings {
        evaluation_episodes: 0,
        ..settings
    };
    assert_eq!(at(1, &none), None);
}
