//! Policy search on a learned model: an unstable first-order plant, a P(ID) policy, the expected
//! saturating cost of a 30-step closed-loop rollout. The optimiser must find a stabilising gain
//! and cut the expected cost; policy search is seeded and reproducible.

use msgp_core::data::Trajectory;
use msgp_core::fit::{FitSettings, MethodSettings, OneStepFitSettings, fit};
use msgp_core::model::Model;
use msgp_core::numeric::parallel::Threads;
use msgp_core::policy::PidPolicy;
use msgp_core::policy_search::cost::SaturatingCost;
use msgp_core::policy_search::{
    PidMask, PolicyProblem, PolicySearchSettings, PolicySolver, SearchSpace, optimise_over,
    optimise_pid, optimise_pid_scaled,
};
use nalgebra::{DMatrix, DVector};
use rand::{RngExt, SeedableRng, rngs::StdRng};

/// A GP-NARX model of `x_{t+1} = 1.1 x_t + 0.5 u_t` from 300 noisy random-input samples.
fn unstable_plant_model() -> Model {
    // x_{t+1} = 1.1 x_t + 0.5 u_t, measured with small noise, random inputs
    let mut rng = StdRng::seed_from_u64(3);
    let n = 300;
    let u: Vec<f64> = (0..n).map(|_| rng.random_range(-1.0..1.0)).collect();
    let mut x = vec![0.0; n];
    for t in 1..n {
        x[t] = (1.1 * x[t - 1] + 0.5 * u[t - 1]).clamp(-3.0, 3.0);
        if x[t].abs() >= 3.0 {
            x[t] *= 0.5;
        }
    }
    let y: Vec<f64> = x
        .iter()
        .map(|v| v + 0.01 * rng.random_range(-1.0..1.0))
        .collect();
    let traj = Trajectory::siso(&u, &y).expect("traj");
    let settings = FitSettings {
        ly: 1,
        lu: 1,
        method: MethodSettings::GpNarx(OneStepFitSettings {
            inducing: 60,
            ..OneStepFitSettings::default()
        }),
        ..FitSettings::default()
    };
    fit(&[traj], &settings, &mut |_| {}).expect("fit").0
}

/// Regulating the plant from `x = 1 ± 0.1` to 0 over 30 steps with a P gain from 0 (the only
/// free gain), `|u| ≤ 2`.
fn p_control_problem(model: &Model) -> (PolicyProblem<'_>, PidPolicy<f64>, PidMask) {
    let problem = PolicyProblem {
        model,
        y0_mean: vec![1.0],
        y0_var: vec![0.01],
        u0: vec![0.0],
        cost: SaturatingCost::with_widths(DVector::from_element(1, 0.0), &[0.5]).expect("cost"),
        horizon: 30,
    };
    let zero = DMatrix::zeros(1, 1);
    let initial =
        PidPolicy::new(zero.clone(), zero.clone(), zero.clone(), 1.0, vec![2.0]).expect("pid");
    let mask = PidMask {
        kp: DMatrix::from_element(1, 1, true),
        ki: DMatrix::from_element(1, 1, false),
        kd: DMatrix::from_element(1, 1, false),
    };
    (problem, initial, mask)
}

#[test]
fn finds_a_stabilising_gain_on_a_learned_unstable_plant() {
    let model = unstable_plant_model();
    let (problem, initial, mask) = p_control_problem(&model);
    let (before, _) = problem.evaluate(&initial).expect("evaluate");
    let s = PolicySearchSettings {
        iterations: 40,
        learning_rate: 0.1,
        restarts: 1,
        ..PolicySearchSettings::default()
    };
    let result = optimise_pid(&problem, &initial, &mask, &s).expect("search");
    let k = result.policy.as_pid().expect("a PID policy").kp[(0, 0)];
    println!(
        "expected cost {before:.3} → {:.3}, gain {k:.3}",
        result.expected_cost
    );
    assert!(
        result.expected_cost < 0.5 * before,
        "{} vs {before}",
        result.expected_cost
    );
    assert!(
        (1.1 + 0.5 * k).abs() < 0.9,
        "closed-loop pole {}",
        1.1 + 0.5 * k
    );
    let again = optimise_pid(&problem, &initial, &mask, &s).expect("search");
    assert_eq!(again.policy, result.policy, "seeded search is reproducible");
}

/// With three Adam steps from a zero gain, the default scale (1) cannot move the gain far
/// enough to stabilise the plant; a typical magnitude of 10 can. Malformed scales are errors.
#[test]
fn typical_gain_magnitudes_set_the_search_scale() {
    let model = unstable_plant_model();
    let (problem, initial, mask) = p_control_problem(&model);
    let s = PolicySearchSettings {
        iterations: 3,
        learning_rate: 0.1,
        restarts: 0,
        candidates: 0,
        ..PolicySearchSettings::default()
    };
    let pole = |typical: f64| {
        let r = optimise_pid_scaled(&problem, &initial, &mask, &[typical], &s).expect("search");
        1.1 + 0.5 * r.policy.as_pid().expect("a PID policy").kp[(0, 0)]
    };
    let (small, large) = (pole(1.0), pole(10.0));
    println!("closed-loop pole: scale 1 → {small:.3}, scale 10 → {large:.3}");
    assert!(small.abs() > 0.9, "{small}");
    assert!(large.abs() < 0.9, "{large}");
    for bad in [vec![0.0], vec![f64::NAN], vec![1.0, 1.0], vec![-1.0]] {
        assert!(optimise_pid_scaled(&problem, &initial, &mask, &bad, &s).is_err());
    }
}

/// Candidates and Adam starts run on threads; the answer is the same for any thread count
/// (bit for bit), so a seed reproduces a search on any machine.
#[test]
fn threads_do_not_change_the_search_result() {
    let model = unstable_plant_model();
    let (problem, initial, mask) = p_control_problem(&model);
    let s = PolicySearchSettings {
        iterations: 8,
        learning_rate: 0.1,
        restarts: 2,
        candidates: 12,
        candidate_starts: 2,
        ..PolicySearchSettings::default()
    };
    let on = |threads: usize| PolicySearchSettings {
        threads: Threads::new(threads).expect("threads"),
        ..s
    };
    let one = optimise_pid_scaled(&problem, &initial, &mask, &[1.0], &on(1)).expect("search");
    for threads in [2, 3] {
        let many =
            optimise_pid_scaled(&problem, &initial, &mask, &[1.0], &on(threads)).expect("search");
        assert_eq!(many.policy, one.policy, "threads {threads}");
        assert_eq!(
            many.expected_cost.to_bits(),
            one.expected_cost.to_bits(),
            "threads {threads}"
        );
    }
    // the search did something: five starts from a zero gain find a stabilising one
    assert!(
        (1.1 + 0.5 * one.policy.as_pid().expect("a PID policy").kp[(0, 0)]).abs() < 1.0,
        "{:?}",
        one.policy.as_pid().expect("a PID policy").kp
    );
}

/// The same regulation problem from `x0 = y0` (variance 0.01).
fn from_start(model: &Model, y0: f64) -> PolicyProblem<'_> {
    let (mut problem, _, _) = p_control_problem(model);
    problem.y0_mean = vec![y0];
    problem
}

/// Several starts, searched by L-BFGS: the objective is the mean of each start's expected
/// cost (checked against the problems evaluated one by one), and the gain found stabilises
/// the plant from both.
#[test]
fn a_search_over_several_starts_minimises_their_mean_cost() {
    let model = unstable_plant_model();
    let (_, initial, mask) = p_control_problem(&model);
    let problems = [from_start(&model, 1.0), from_start(&model, -0.5)];
    let space = SearchSpace::pid(&initial, &mask);
    let s = PolicySearchSettings {
        iterations: 30,
        restarts: 0,
        candidates: 0,
        solver: PolicySolver::Lbfgs,
        ..PolicySearchSettings::default()
    };
    let both = optimise_over(&problems, &space, &[1.0], &s, &[]).expect("search");
    let policy = both.policy.lift::<f64>();
    let each: Vec<f64> = problems
        .iter()
        .map(|p| p.evaluate(policy.as_ref()).expect("evaluate").0)
        .collect();
    let mean = 0.5 * (each[0] + each[1]);
    assert!(
        (both.expected_cost - mean).abs() <= 1e-12 * mean,
        "{} vs {mean}",
        both.expected_cost
    );
    let k = both.policy.as_pid().expect("a PID policy").kp[(0, 0)];
    assert!(
        (1.1 + 0.5 * k).abs() < 0.9,
        "closed-loop pole {}",
        1.1 + 0.5 * k
    );
    let (zero, _) = problems[0].evaluate(&initial).expect("evaluate");
    assert!(each[0] < 0.5 * zero, "{} vs {zero}", each[0]);
    // a trust region has no meaning for L-BFGS: refused, not ignored
    let bad = PolicySearchSettings {
        trust_region: 1.0,
        ..s
    };
    assert!(optimise_over(&problems, &space, &[1.0], &bad, &[]).is_err());
    assert!(optimise_over(&[], &space, &[1.0], &s, &[]).is_err());
}

/// A further start (the learner's first policy) is searched like the running one: from a
/// running gain that destabilises the plant and no iterations, the search returns the
/// further start when it is cheaper; a start of the wrong length is refused.
#[test]
fn further_starts_are_searched_and_kept_when_cheaper() {
    let model = unstable_plant_model();
    let (problem, initial, mask) = p_control_problem(&model);
    let mut bad = initial.clone();
    bad.kp[(0, 0)] = 2.0;
    let space = SearchSpace::pid(&bad, &mask);
    let s = PolicySearchSettings {
        iterations: 0,
        restarts: 0,
        candidates: 0,
        ..PolicySearchSettings::default()
    };
    let alone =
        optimise_over(std::slice::from_ref(&problem), &space, &[1.0], &s, &[]).expect("search");
    let good = vec![-1.6];
    let with = optimise_over(
        std::slice::from_ref(&problem),
        &space,
        &[1.0],
        &s,
        std::slice::from_ref(&good),
    )
    .expect("search");
    assert_eq!(alone.policy.as_pid().expect("pid").kp[(0, 0)], 2.0);
    assert_eq!(with.policy.as_pid().expect("pid").kp[(0, 0)], -1.6);
    assert!(with.expected_cost < alone.expected_cost);
    assert!(
        optimise_over(
            std::slice::from_ref(&problem),
            &space,
            &[1.0],
            &s,
            &[vec![1.0, 2.0]]
        )
        .is_err()
    );
}
