//! Tests of the learning loop.

use super::*;
use crate::controller::{PidPdGains, Saturation};

fn report(iteration: usize, actual_cost: f64, stable: bool) -> IterationReport {
    IterationReport {
        iteration,
        predicted_cost: 1.0,
        predicted_cost_std: 0.1,
        actual_cost,
        expected_cost: None,
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

/// The pendulum as the loop's plant runs the simulator's own episodes: the excitation and the
/// PID + PD gains through [`msgp_core::learner::run_episode`] give the samples
/// [`crate::episode::run_episode`] gives with the simulator's controllers (the same initial
/// angle, noise and commands), and the recorded episodes are those samples.
#[test]
fn the_pendulum_plant_runs_the_simulators_episodes() {
    use msgp_core::learner::{Actor, Multisine, run_episode};
    use msgp_core::policy::Policy;

    use crate::controller::{PidPdPolicy, RandomExcitation};
    use crate::episode::{EpisodeConfig, run_episode as sim_episode};

    let params = PendulumParams::default();
    let settings = LearnSettings::default();
    let config = |seed| EpisodeConfig {
        seconds: 3.0,
        seed,
        initial_theta: None,
    };
    let mut plant = PendulumPlant::new(&params, 3.0).expect("valid");
    let learner = learner_settings(&params, &settings).expect("valid");
    let bounds = msgp_core::policy::CommandBounds::symmetric(&[params.action_limit]).expect("ok");
    let signal = Multisine::for_bounds(7, &learner.excitation, &bounds);
    let ep = run_episode(&mut plant, &Actor::Excitation(&signal), 7, 150).expect("runs");
    let excited_last = (7, ep.commands[ep.len() - 1][0]);
    let mut excitation = RandomExcitation::new(7, &settings.excitation).expect("valid");
    let reference = sim_episode(&params, &mut excitation, &config(7)).expect("runs");
    assert_eq!(ep.len(), reference.samples.len());
    for (k, s) in reference.samples.iter().enumerate() {
        assert_eq!(ep.commands[k][0], s.command, "excitation, row {k}");
        assert_eq!(ep.outputs[k], vec![s.measurement.theta, s.measurement.x]);
    }
    // a stabilising and a falling gain set: the falling one ends early on both sides
    let lqr = PidPdGains {
        saturation: Saturation::Sine,
        ..PidPdGains::apollo_lqr()
    };
    let falling = PidPdGains {
        kp_theta: 5.0,
        ..lqr
    };
    for gains in [lqr, falling] {
        let policy = Policy::Pid(modelled_policy(&gains, &params).expect("valid"));
        let actor = Actor::Policy {
            policy: &policy,
            rest: &[0.0],
        };
        let ep = run_episode(&mut plant, &actor, 11, 150).expect("runs");
        let mut controller = PidPdPolicy::new(gains, &params).expect("valid");
        let reference = sim_episode(&params, &mut controller, &config(11)).expect("runs");
        assert_eq!(ep.len(), reference.samples.len(), "{gains:?}");
        assert_eq!(
            ep.ended_early,
            reference.info.termination != crate::episode::Termination::Completed
        );
        for (k, s) in reference.samples.iter().enumerate() {
            assert_eq!(ep.commands[k][0], s.command, "{gains:?}, row {k}");
            assert_eq!(ep.outputs[k], vec![s.measurement.theta, s.measurement.x]);
        }
    }
    let recorded = plant.take_episodes(&[excited_last]);
    assert_eq!(recorded.len(), 3);
    let reference = reference_episode(&params, &settings);
    assert_eq!(recorded[0].samples, reference.samples);
    assert_eq!(recorded[0].info.termination, reference.info.termination);
}

/// The simulator's own episode of seed 7 under the excitation.
fn reference_episode(params: &PendulumParams, settings: &LearnSettings) -> crate::episode::Episode {
    let mut excitation =
        crate::controller::RandomExcitation::new(7, &settings.excitation).expect("valid");
    let config = crate::episode::EpisodeConfig {
        seconds: 3.0,
        seed: 7,
        initial_theta: None,
    };
    crate::episode::run_episode(params, &mut excitation, &config).expect("runs")
}
