//! The learning loop on small plants written here: a linear first-order lag and a nonlinear
//! (cubic) one, both seeded and fast. The trait's conventions (rows, early ends, bad
//! observations, commands out of bounds), the loop's determinism, that its policies improve
//! on the random episodes, and that a stopped loop keeps its episodes.

use std::ops::ControlFlow;

use msgp_core::MsgpError;
use msgp_core::fit::{FitSettings, LinearKfSettings, MethodSettings, OneStepFitSettings};
use msgp_core::gp::MeanFunction;
use msgp_core::learner::{
    Actor, ExcitationConfig, LearnEvent, Learner, LearnerSettings, Multisine, SearchModel,
    StartDistribution, Task, run_episode, target_cost,
};
use msgp_core::plant::{CommandSpec, OutputSpec, Plant, PlantSpec, PlantStep};
use msgp_core::policy::{CommandBounds, Policy, RbfPolicy, StateFeedback};
use msgp_core::policy_search::{PolicySearchSettings, SearchSpace};
use nalgebra::{DMatrix, DVector};
use rand::{SeedableRng, rngs::StdRng};
use rand_distr::{Distribution, Normal};

/// `y_{k+1} = y_k + T f(y_k, u_k) + ε`, `ε ~ N(0, noise²)`, `y_0 ~ N(0, 0.05²)`, observed
/// exactly; `f = −y + u` (linear) or `f = −y³ + u` (cubic). Ends early once `|y| > limit`.
struct Lag {
    spec: PlantSpec,
    cubic: bool,
    noise: f64,
    limit: f64,
    y: f64,
    rng: StdRng,
    /// Returns an observation of the wrong size at this step.
    bad_shape_at: Option<usize>,
    /// Returns NaN at this step.
    nan_at: Option<usize>,
    /// Fails (an error, as a robot's emergency stop) at this step of all it runs.
    fail_at: Option<usize>,
    total: usize,
    steps: usize,
}

impl Lag {
    fn new(cubic: bool) -> Self {
        Self {
            spec: PlantSpec {
                period: 0.1,
                commands: vec![CommandSpec {
                    name: "u".into(),
                    low: -3.0,
                    high: 3.0,
                }],
                outputs: vec![OutputSpec::named("y")],
            },
            cubic,
            noise: 0.01,
            limit: 10.0,
            y: 0.0,
            rng: StdRng::seed_from_u64(0),
            bad_shape_at: None,
            nan_at: None,
            fail_at: None,
            total: 0,
            steps: 0,
        }
    }
}

impl Plant for Lag {
    fn spec(&self) -> &PlantSpec {
        &self.spec
    }

    fn reset(&mut self, seed: u64) -> msgp_core::Result<Vec<f64>> {
        self.rng = StdRng::seed_from_u64(seed);
        self.y = Normal::new(0.0, 0.05).expect("valid").sample(&mut self.rng);
        self.steps = 0;
        Ok(vec![self.y])
    }

    fn step(&mut self, command: &[f64]) -> msgp_core::Result<PlantStep> {
        let drift = if self.cubic { -self.y.powi(3) } else { -self.y };
        let eps: f64 = Normal::new(0.0, self.noise)
            .expect("valid")
            .sample(&mut self.rng);
        self.y += self.spec.period * (drift + command[0]) + eps;
        self.steps += 1;
        self.total += 1;
        if self.fail_at == Some(self.total) {
            return Err(MsgpError::Plant("emergency stop".into()));
        }
        let observation = match (self.bad_shape_at, self.nan_at) {
            (Some(k), _) if k == self.steps => vec![self.y, 0.0],
            (_, Some(k)) if k == self.steps => vec![f64::NAN],
            _ => vec![self.y],
        };
        Ok(PlantStep {
            observation,
            done: self.y.abs() > self.limit,
            truncated: false,
        })
    }
}

fn bounds() -> CommandBounds {
    CommandBounds::new(vec![-3.0], vec![3.0]).expect("valid")
}

/// `u = k y + b` on the observation, saturated into ±3.
fn linear_feedback() -> Policy {
    Policy::StateFeedback(
        StateFeedback::new(
            DMatrix::from_element(1, 1, 0.0),
            DVector::from_element(1, 0.0),
            1,
            (1, 0),
            bounds(),
        )
        .expect("valid"),
    )
}

/// Five Gaussian basis functions on `[-0.5, 1.5]`, zero weights.
fn rbf() -> Policy {
    let centres = DMatrix::from_fn(5, 1, |i, _| -0.5 + 0.5 * i as f64);
    Policy::Rbf(
        RbfPolicy::new(
            centres,
            DMatrix::zeros(5, 1),
            DVector::from_element(1, 0.5f64.ln()),
            bounds(),
        )
        .expect("valid"),
    )
}

/// Drive `y` to `target` from near 0 in 3 s; the search moves every parameter.
fn task(policy: Policy, target: f64) -> Task {
    let n = policy.param_len();
    Task {
        cost: target_cost(&[target], &[0.5], &[false]).expect("valid"),
        episode_steps: 30,
        policy_horizon: 30,
        start: StartDistribution::Observed { floor: 1e-4 },
        rest_command: vec![0.0],
        space: SearchSpace::all(policy),
        typical: vec![1.0; n],
    }
}

fn settings(method: MethodSettings, iterations: usize) -> LearnerSettings {
    LearnerSettings {
        iterations,
        random_rollouts: 2,
        excitation: ExcitationConfig {
            components: 10,
            min_hz: 0.1,
            max_hz: 2.0,
            rms_fraction: 0.5,
        },
        seed: 3,
        fit: FitSettings {
            ly: 1,
            lu: 1,
            method,
            ..FitSettings::default()
        },
        search: PolicySearchSettings {
            iterations: 30,
            learning_rate: 0.1,
            restarts: 1,
            ..PolicySearchSettings::default()
        },
        evaluation_episodes: 5,
        prequential_choice: false,
        ff_segment: None,
        warm_start: None,
        search_from_first: false,
        one_step_guard: false,
    }
}

fn linear_kf() -> MethodSettings {
    LinearKfSettings { iterations: 100 }.into()
}

fn gp_narx() -> MethodSettings {
    MethodSettings::GpNarx(OneStepFitSettings {
        inducing: 20,
        mean: MeanFunction::Linear,
        iterations: 100,
        ..OneStepFitSettings::default()
    })
}

/// The loop's default MSGP fit (the filter likelihood from the one-step start), smaller.
fn msgp() -> MethodSettings {
    let defaults = LearnerSettings::for_plant(&Lag::new(true).spec);
    let mut m = defaults.fit.msgp().expect("the loop fits MSGP").clone();
    m.inducing = 15;
    m.iterations = 40;
    m.into()
}

fn never(_: LearnEvent<'_>) -> ControlFlow<()> {
    ControlFlow::Continue(())
}

/// The mean measured cost of the random episodes, scored like the loop's.
fn random_cost(learner: &Learner) -> f64 {
    let t = learner.task();
    let random: Vec<_> = learner
        .episodes()
        .iter()
        .filter(|e| e.policy.is_none())
        .collect();
    random.iter().map(|e| e.cost(&t.cost, 1, 30)).sum::<f64>() / random.len() as f64
}

/// Row `k` holds the observation at step `k` and the command issued then; an episode the plant
/// ends has the row of that observation (with the policy's command for it) and no more.
#[test]
fn episode_rows_and_early_end() {
    let mut plant = Lag::new(false);
    let signal = Multisine::for_bounds(1, &ExcitationConfig::default(), &bounds());
    let ep = run_episode(&mut plant, &Actor::Excitation(&signal), 4, 10).expect("runs");
    assert_eq!((ep.outputs.len(), ep.commands.len()), (11, 11));
    assert!(!ep.ended_early);
    // the plant's recursion holds between rows: y_{k+1} − y_k + 0.1 y_k − 0.1 u_k is noise
    for k in 0..10 {
        let (y, u) = (ep.outputs[k][0], ep.commands[k][0]);
        let eps = ep.outputs[k + 1][0] - y - 0.1 * (-y + u);
        assert!(eps.abs() < 0.05, "row {k}: {eps}");
        assert_eq!(u, signal.value(k as f64 * 0.1)[0].clamp(-3.0, 3.0));
    }
    // a plant that ends the episode at its fourth step
    plant.limit = 0.0;
    let policy = linear_feedback();
    let actor = Actor::Policy {
        policy: &policy,
        rest: &[0.0],
    };
    let ep = run_episode(&mut plant, &actor, 4, 10).expect("runs");
    assert_eq!(ep.outputs.len(), 2);
    assert!(ep.ended_early);
    // the cost counts every missing row as 1
    let cost = target_cost(&[0.0], &[1.0], &[false]).expect("valid");
    let c = ep.cost(&cost, 0, 11);
    assert!(c > 9.0 && c < 11.0, "{c}");
}

/// What a plant returns is checked at the step it returns it; a policy whose bounds exceed the
/// plant's is refused before anything runs.
#[test]
fn bad_observations_and_bounds() {
    let mut plant = Lag::new(false);
    plant.bad_shape_at = Some(3);
    let signal = Multisine::for_bounds(1, &ExcitationConfig::default(), &bounds());
    let err = run_episode(&mut plant, &Actor::Excitation(&signal), 0, 10).expect_err("must fail");
    let text = err.to_string();
    assert!(
        text.contains("step 3") && text.contains("2 values"),
        "{text}"
    );
    plant.bad_shape_at = None;
    plant.nan_at = Some(4);
    let err = run_episode(&mut plant, &Actor::Excitation(&signal), 0, 10).expect_err("must fail");
    let text = err.to_string();
    assert!(
        text.contains("step 4") && text.contains("`y`") && text.contains("NaN"),
        "{text}"
    );
    let wide = Policy::StateFeedback(
        StateFeedback::new(
            DMatrix::zeros(1, 1),
            DVector::zeros(1),
            1,
            (1, 0),
            CommandBounds::new(vec![-5.0], vec![5.0]).expect("valid"),
        )
        .expect("valid"),
    );
    // a policy on two outputs for a plant with one
    let two = Policy::StateFeedback(
        StateFeedback::new(DMatrix::zeros(1, 2), DVector::zeros(1), 2, (1, 0), bounds())
            .expect("valid"),
    );
    let mut learner = Learner::new(task(two, 1.0), settings(linear_kf(), 1)).expect("valid");
    let err = learner
        .run(&mut Lag::new(false), None, &mut never)
        .expect_err("must fail");
    assert!(err.to_string().contains("acts on 2 outputs"), "{err}");
    let mut learner = Learner::new(task(wide, 1.0), settings(linear_kf(), 1)).expect("valid");
    let err = learner
        .run(&mut Lag::new(false), None, &mut never)
        .expect_err("must fail");
    assert!(
        matches!(&err, MsgpError::InvalidSetting { name: "policy", .. }),
        "{err}"
    );
    assert!(learner.episodes().is_empty());
}

/// On the linear lag a linear-kf model and a linear feedback with offset reach the target
/// (`u = y*` holds `y` there): after three iterations the policy's expected cost is a tenth of
/// the random episodes' and half the first policy's; the same seed gives the same numbers.
#[test]
fn linear_plant_learns_and_repeats() {
    let run = || {
        let mut learner =
            Learner::new(task(linear_feedback(), 1.0), settings(linear_kf(), 3)).expect("valid");
        learner
            .run(&mut Lag::new(false), None, &mut never)
            .expect("runs");
        learner
    };
    let a = run();
    let last = a.reports().last().expect("three iterations");
    let expected = last.expected_cost.expect("evaluated");
    let random = random_cost(&a);
    eprintln!(
        "linear: random {random:.3}, iterations {:?}",
        a.reports()
            .iter()
            .map(|r| (r.predicted_cost, r.actual_cost, r.expected_cost))
            .collect::<Vec<_>>()
    );
    // random 26.3, the first policy 4.44, the third 1.53 (the rise from 0 alone costs ~1)
    assert!(expected < 0.1 * random, "{expected} vs {random}");
    let first = a.reports()[0].expected_cost.expect("evaluated");
    assert!(expected < 0.5 * first, "{expected} vs {first}");
    // the model predicted it within one step's full cost
    assert!(
        (last.predicted_cost - expected).abs() < 1.0,
        "{} vs {expected}",
        last.predicted_cost
    );
    let b = run();
    let untimed = |l: &Learner| -> Vec<_> {
        l.reports()
            .iter()
            .map(|r| {
                (
                    r.predicted_cost,
                    r.actual_cost,
                    r.expected_cost,
                    r.policy.clone(),
                )
            })
            .collect()
    };
    assert_eq!(untimed(&a), untimed(&b));
    assert_eq!(a.episodes(), b.episodes());
}

/// On the cubic lag, a one-step GP-NARX model and an RBF network: holding `y` at 1.2 needs
/// `u = 1.728`, far from where the random episodes spend their time; the policy's expected
/// cost falls below a tenth of the random episodes' (27.7 against 1.78 measured) and below
/// the first policy's.
#[test]
fn nonlinear_plant_learns_with_an_rbf_policy() {
    let mut learner = Learner::new(task(rbf(), 1.2), settings(gp_narx(), 3)).expect("valid");
    learner
        .run(&mut Lag::new(true), None, &mut never)
        .expect("runs");
    let random = random_cost(&learner);
    let costs: Vec<_> = learner
        .reports()
        .iter()
        .map(|r| (r.predicted_cost, r.actual_cost, r.expected_cost))
        .collect();
    eprintln!("cubic: random {random:.3}, iterations {costs:?}");
    let expected = learner.reports().last().and_then(|r| r.expected_cost);
    let expected = expected.expect("evaluated");
    assert!(expected < 0.1 * random, "{expected} vs {random}");
    let first = learner.reports()[0].expected_cost.expect("evaluated");
    assert!(expected < first, "{expected} vs {first}");
}

/// An observer's stop ends the loop with `Stopped` — also when it answers a policy episode,
/// which then keeps its iteration's report — and a plant's failure during a policy episode
/// leaves the loop's state as it was before the iteration; every episode run to its end stays,
/// and the loop continues from there to the episodes an uninterrupted loop runs.
#[test]
fn a_stopped_loop_keeps_its_episodes_and_resumes() {
    let fresh =
        || Learner::new(task(linear_feedback(), 1.0), settings(linear_kf(), 2)).expect("valid");
    let mut whole = fresh();
    whole
        .run(&mut Lag::new(false), None, &mut never)
        .expect("runs");
    // stopped at the first policy episode
    let mut learner = fresh();
    let mut plant = Lag::new(false);
    let err = learner
        .run(&mut plant, None, &mut |e| match e {
            LearnEvent::Episode {
                episode,
                evaluation: false,
            } if episode.policy.is_some() => ControlFlow::Break(()),
            _ => ControlFlow::Continue(()),
        })
        .expect_err("must stop");
    assert!(matches!(err, MsgpError::Stopped { iteration: 1 }), "{err}");
    assert_eq!((learner.episodes().len(), learner.reports().len()), (3, 1));
    learner.run(&mut plant, None, &mut never).expect("resumes");
    assert_eq!(whole.episodes(), learner.episodes());
    // the plant fails in the first policy episode (the random ones take 2 × 30 steps)
    let mut learner = fresh();
    let mut failing = Lag::new(false);
    failing.fail_at = Some(65);
    let err = learner
        .run(&mut failing, None, &mut never)
        .expect_err("must fail");
    assert!(err.to_string().contains("emergency stop"), "{err}");
    assert_eq!((learner.episodes().len(), learner.reports().len()), (2, 0));
    assert_eq!(learner.policy(), &linear_feedback());
    learner
        .run(&mut Lag::new(false), None, &mut never)
        .expect("resumes");
    assert_eq!(whole.episodes(), learner.episodes());
    let policies =
        |l: &Learner| -> Vec<_> { l.reports().iter().map(|r| r.policy.clone()).collect() };
    assert_eq!(policies(&whole), policies(&learner));
}

/// An episode ended by a limit is not costed as a failure: its missing steps count the
/// measured steps' mean, where a failed episode's count 1 each.
#[test]
fn a_truncated_episode_is_not_costed_as_a_failure() {
    use msgp_core::learner::Episode;
    let cost = target_cost(&[0.0], &[1.0], &[false]).expect("valid");
    let mut ep = Episode {
        seed: 0,
        outputs: vec![vec![0.0], vec![1.0]],
        commands: vec![vec![0.0], vec![0.0]],
        ended_early: true,
        truncated: false,
        policy: None,
    };
    let measured = cost.at(&[0.0]) + cost.at(&[1.0]);
    assert!((ep.cost(&cost, 0, 4) - (measured + 2.0)).abs() < 1e-15);
    ep.truncated = true;
    assert!((ep.cost(&cost, 0, 4) - 2.0 * measured).abs() < 1e-15);
}

/// The one-step guard: every iteration scores the MSGP model against the linear model (their
/// filters) and against the MSGP fit's one-step start (their closed-loop free runs) on the
/// episode it ran, and each search runs on the model those scores name (the linear model
/// until the MSGP model has beaten it in total; then the MSGP model only where it also beat
/// its one-step start on the latest episode). A learner rebuilt from the
/// episodes replays the same scores and continues to the same policy.
#[test]
fn the_one_step_guard_searches_on_the_model_its_scores_name() {
    let mut guarded = settings(msgp(), 4);
    guarded.prequential_choice = true;
    guarded.one_step_guard = true;
    let without_choice = LearnerSettings {
        prequential_choice: false,
        ..guarded.clone()
    };
    let err = Learner::new(task(rbf(), 1.2), without_choice).expect_err("refused");
    assert!(err.to_string().contains("one_step_guard"), "{err}");

    let mut learner = Learner::new(task(rbf(), 1.2), guarded.clone()).expect("valid");
    learner
        .run(&mut Lag::new(true), None, &mut never)
        .expect("runs");
    let (mut linear, mut one_step, mut scored) = (0.0, None, 0);
    for r in learner.reports() {
        let expected = if !(scored > 0 && linear < 0.0) {
            SearchModel::Linear
        } else if one_step.is_some_and(|d: f64| d >= 0.0) {
            SearchModel::OneStep
        } else {
            SearchModel::Gp
        };
        assert_eq!(r.search_model, Some(expected), "iteration {}", r.iteration);
        let h = r.held_out.expect("scored");
        let free = h.rollout.expect("the one-step model scored");
        let finite = [h.gp_nll, h.linear_nll, free.gp, free.one_step];
        assert!(finite.iter().all(|v| v.is_finite()), "{h:?}");
        eprintln!(
            "iteration {}: {:?}, held out {h:?}",
            r.iteration, r.search_model
        );
        linear += h.gp_nll - h.linear_nll;
        one_step = Some(free.gp - free.one_step);
        scored += 1;
    }

    let mut rebuilt = Learner::from_episodes(
        task(rbf(), 1.2),
        guarded,
        learner.episodes().to_vec(),
        &mut never,
    )
    .expect("replays");
    let next = |l: &mut Learner| {
        let step = l.improve(&mut never).expect("improves");
        (step.search_model, step.searched.expect("searched").policy)
    };
    assert_eq!(next(&mut rebuilt), next(&mut learner));
}
