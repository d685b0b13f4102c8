//! Tests of the learning loop.

use super::*;

fn report(iteration: usize, actual_cost: f64, stable: bool) -> IterationReport {
    IterationReport {
        iteration,
        predicted_cost: 1.0,
        predicted_cost_std: 0.1,
        actual_cost,
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
