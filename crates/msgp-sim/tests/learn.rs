//! The policy-learning loop end to end on the simulator (small settings): it runs, reports every
//! field, counts interaction time, and is reproducible for a seed.

use msgp_core::fit::{FitSettings, MsgpSettings};
use msgp_core::policy_search::PolicySearchSettings;
use std::ops::ControlFlow;

use msgp_sim::learn::{LearnEvent, LearnSettings, learn_policy, learn_policy_observed};
use msgp_sim::{PendulumParams, PlantTier, SimError};

/// `iterations` of a loop small enough for a test: two 1 s random rollouts, m = 20, 10 fit
/// and 3 search iterations.
fn small(iterations: usize) -> LearnSettings {
    LearnSettings {
        iterations,
        random_rollouts: 2,
        episode_seconds: 1.0,
        fit: FitSettings {
            ly: 2,
            lu: 2,
            method: MsgpSettings {
                inducing: 20,
                iterations: 10,
                validation_fraction: 0.0,
                ..MsgpSettings::default()
            }
            .into(),
            ..FitSettings::default()
        },
        search: PolicySearchSettings {
            iterations: 3,
            restarts: 0,
            ..PolicySearchSettings::default()
        },
        ..LearnSettings::default()
    }
}

/// `iterations` of the filtered MSGP loop's defaults, small ([`shortened`]).
fn small_filtered(iterations: usize) -> LearnSettings {
    shortened(LearnSettings::filtered_msgp(), iterations)
}

/// `iterations` of the loop `f`, small: two 1 s random rollouts, m = 10, 5 fit iterations,
/// 3 Adam steps from one start after 4 candidates.
fn shortened(f: LearnSettings, iterations: usize) -> LearnSettings {
    LearnSettings {
        iterations,
        random_rollouts: 2,
        episode_seconds: 1.0,
        fit: f.fit.clone().with_inducing(10).with_solver_iterations(5),
        search: PolicySearchSettings {
            iterations: 3,
            restarts: 0,
            candidates: 4,
            ..f.search
        },
        ..f
    }
}

#[test]
fn one_small_iteration_runs_and_is_reproducible() {
    let settings = small(1);
    let params = PendulumParams::tier(PlantTier::Noisy);
    let mut seen = 0;
    let a = learn_policy(&params, &settings, &mut |_| seen += 1).expect("learn");
    assert_eq!(seen, 1);
    assert_eq!(a.iterations.len(), 1);
    assert_eq!(
        a.episodes.len(),
        3,
        "two random rollouts and one policy episode"
    );
    let r = &a.iterations[0];
    assert!(
        r.predicted_cost.is_finite()
            && r.predicted_cost_std.is_finite()
            && r.actual_cost.is_finite()
    );
    let expected: f64 = a
        .episodes
        .iter()
        .map(|e| (e.samples.len() - 1) as f64 / params.control_rate_hz)
        .sum();
    assert!((r.interaction_seconds - expected).abs() < 1e-9);
    // the measured cost: the saturating cost of the policy episode's measured outputs after the
    // model's window, and nothing else (steps after an early stop would count 1 each)
    let ep = &a.episodes[2];
    let warm = settings.fit.ly.max(settings.fit.lu);
    let full = (settings.episode_seconds * params.control_rate_hz).round() as usize + 1;
    let [w_theta, w_x] = settings.cost_widths;
    let by_hand: f64 = ep.samples[warm..]
        .iter()
        .map(|s| {
            let z = (s.measurement.theta / w_theta).powi(2) + (s.measurement.x / w_x).powi(2);
            1.0 - (-0.5 * z).exp()
        })
        .sum::<f64>()
        + (full - ep.samples.len()) as f64;
    assert!(
        (r.actual_cost - by_hand).abs() < 1e-9,
        "{} vs {by_hand}",
        r.actual_cost
    );
    let b = learn_policy(&params, &settings, &mut |_| {}).expect("learn");
    // same seed, same numbers: everything but the wall-clock timings
    let untimed = |v: &[msgp_sim::learn::IterationReport]| {
        v.iter()
            .map(|r| msgp_sim::learn::IterationReport {
                fit_seconds: 0.0,
                search_seconds: 0.0,
                ..r.clone()
            })
            .collect::<Vec<_>>()
    };
    assert_eq!(
        untimed(&a.iterations),
        untimed(&b.iterations),
        "same seed, same numbers"
    );
    assert!(r.fit_seconds > 0.0 && r.search_seconds > 0.0);
}

/// Warm starts change nothing in the first iteration (there is no previous model) and continue
/// the first model in the second: its predictions then differ from a fit that starts over.
#[test]
fn a_warm_started_loop_continues_its_previous_model() {
    let settings = small(2);
    assert_eq!(settings.warm_start, None, "off by default");
    let params = PendulumParams::tier(PlantTier::Noisy);
    let cold = learn_policy(&params, &settings, &mut |_| {}).expect("cold");
    let warm_settings = LearnSettings {
        warm_start: Some(3),
        ..settings
    };
    let warm = learn_policy(&params, &warm_settings, &mut |_| {}).expect("warm");
    let (c, w) = (&cold.iterations, &warm.iterations);
    assert_eq!(c[0].predicted_cost, w[0].predicted_cost);
    assert_eq!(c[0].gains, w[0].gains);
    assert_ne!(c[1].predicted_cost, w[1].predicted_cost);
    assert!(w[1].predicted_cost.is_finite() && w[1].actual_cost.is_finite());
    // reproducible like a cold run
    let again = learn_policy(&params, &warm_settings, &mut |_| {}).expect("warm again");
    assert_eq!(again.iterations[1].predicted_cost, w[1].predicted_cost);
    assert_eq!(again.iterations[1].gains, w[1].gains);
}

/// The defaults per model: a linear-kf loop declares the end effector kinematic, the others
/// keep the default settings; a small linear-kf loop runs and is reproducible.
#[test]
fn linear_kf_defaults_declare_the_end_effector_kinematic_and_run() {
    use msgp_core::model::Method;
    use msgp_sim::learn::{
        END_EFFECTOR_INTEGRATOR, END_EFFECTOR_KINEMATIC, LINEAR_KF_POLICY_HORIZON_SECONDS,
        LINEAR_KF_WARM_START,
    };
    assert_eq!(
        LearnSettings::for_method(Method::Msgp),
        LearnSettings::default()
    );
    let kf = LearnSettings::for_method(Method::LinearKf);
    assert_eq!(kf.fit.integrators, vec![END_EFFECTOR_KINEMATIC]);
    assert_eq!(kf.warm_start, Some(LINEAR_KF_WARM_START));
    assert_eq!(kf.policy_horizon_seconds, LINEAR_KF_POLICY_HORIZON_SECONDS);
    assert_eq!(
        LearnSettings {
            fit: LearnSettings::default().fit,
            warm_start: None,
            policy_horizon_seconds: LearnSettings::default().policy_horizon_seconds,
            ..kf.clone()
        },
        LearnSettings::default(),
        "nothing else differs"
    );
    assert_eq!(
        LearnSettings::for_method(Method::GpNarx).fit.integrators,
        vec![END_EFFECTOR_INTEGRATOR]
    );
    // two iterations: the second warm-starts from the first's model
    let settings = LearnSettings {
        iterations: 2,
        random_rollouts: 2,
        episode_seconds: 1.0,
        search: PolicySearchSettings {
            iterations: 3,
            restarts: 0,
            candidates: 4,
            ..kf.search
        },
        ..kf
    };
    let params = PendulumParams::tier(PlantTier::Noisy);
    let a = learn_policy(&params, &settings, &mut |_| {}).expect("loop runs");
    let b = learn_policy(&params, &settings, &mut |_| {}).expect("loop runs");
    assert_eq!(a.iterations.len(), 2);
    assert!(a.iterations.iter().all(|r| r.predicted_cost.is_finite()));
    assert_eq!(a.final_gains, b.final_gains);
    assert_eq!(a.iterations[1].actual_cost, b.iterations[1].actual_cost);
}

/// The filtered MSGP loop's defaults: linear-kf's loop (end effector kinematic, 10 s horizon)
/// with MSGP trained on the filter likelihood from the linear-kf start, warm-started; a small
/// loop of it runs and is reproducible, and an MSGP loop with the free-run likelihood keeps
/// the MSGP defaults.
#[test]
fn filtered_msgp_defaults_start_from_the_kalman_fit_and_run() {
    use msgp_core::fit::MsgpStart;
    use msgp_core::gp::MeanFunction;
    use msgp_core::loss::Likelihood;
    use msgp_core::model::Method;
    use msgp_sim::learn::{
        FILTERED_MSGP_INDUCING, FILTERED_MSGP_ITERATIONS, FILTERED_MSGP_SEARCH_ITERATIONS,
        FILTERED_MSGP_WARM_START, LINEAR_KF_POLICY_HORIZON_SECONDS,
    };
    let f = LearnSettings::for_model(Method::Msgp, Some(Likelihood::Filter));
    assert_eq!(f, LearnSettings::filtered_msgp());
    let m = f.fit.msgp().expect("an MSGP fit");
    assert_eq!(m.likelihood, Likelihood::Filter);
    assert_eq!(m.start, MsgpStart::LinearKf);
    assert_eq!(m.mean, MeanFunction::Linear);
    assert_eq!(
        f.fit.integrators,
        LearnSettings::for_method(Method::LinearKf).fit.integrators
    );
    assert_eq!(f.policy_horizon_seconds, LINEAR_KF_POLICY_HORIZON_SECONDS);
    assert_eq!(f.warm_start, Some(FILTERED_MSGP_WARM_START));
    assert_eq!(m.iterations, FILTERED_MSGP_ITERATIONS);
    assert_eq!(m.inducing, FILTERED_MSGP_INDUCING);
    assert_eq!(f.search.iterations, FILTERED_MSGP_SEARCH_ITERATIONS);
    let free = LearnSettings::for_model(Method::Msgp, Some(Likelihood::FreeRun));
    assert_eq!(free, LearnSettings::for_method(Method::Msgp));
    let settings = small_filtered(2);
    let params = PendulumParams::tier(PlantTier::Noisy);
    let a = learn_policy(&params, &settings, &mut |_| {}).expect("loop runs");
    let b = learn_policy(&params, &settings, &mut |_| {}).expect("loop runs");
    assert_eq!(a.iterations.len(), 2);
    assert!(a.iterations.iter().all(|r| r.predicted_cost.is_finite()));
    assert_eq!(a.final_gains, b.final_gains);
    assert_eq!(a.iterations[1].actual_cost, b.iterations[1].actual_cost);
    assert_eq!(
        a.iterations[1].predicted_cost,
        b.iterations[1].predicted_cost
    );
}

/// `fit 2`, `step 2.7`, `search 2`, `done 2`: what a [`LearnEvent`] is, for comparisons.
fn event_name(e: &LearnEvent<'_>) -> String {
    match e {
        LearnEvent::FitStarted { iteration } => format!("fit {iteration}"),
        LearnEvent::Fit {
            iteration,
            progress,
        } => format!("step {iteration}.{}", progress.iteration),
        LearnEvent::SearchStarted { iteration } => format!("search {iteration}"),
        LearnEvent::Iteration(r) => format!("done {}", r.iteration),
    }
}

/// The observed loop reports, per iteration and in order: the fit's start, every solver
/// iteration of the MSGP fit (10 here, plus the evaluation at the end), the search's start and
/// the finished iteration; and it learns exactly what `learn_policy` does.
#[test]
fn the_observed_loop_reports_fits_searches_and_iterations_in_order() {
    let settings = small(2);
    let params = PendulumParams::tier(PlantTier::Noisy);
    let mut events = Vec::new();
    let observed = learn_policy_observed(&params, &settings, &mut |e| {
        events.push(event_name(&e));
        ControlFlow::Continue(())
    })
    .expect("learn");
    let mut expected = Vec::new();
    for it in 1..=2 {
        expected.push(format!("fit {it}"));
        expected.extend((0..=10).map(|k| format!("step {it}.{k}")));
        expected.push(format!("search {it}"));
        expected.push(format!("done {it}"));
    }
    assert_eq!(events, expected);
    let plain = learn_policy(&params, &settings, &mut |_| {}).expect("learn");
    let gains = |o: &msgp_sim::learn::LearnOutcome| -> Vec<_> {
        o.iterations.iter().map(|r| r.gains).collect()
    };
    assert_eq!(gains(&observed), gains(&plain));
    // a break ends the loop there, also in the middle of a fit
    for (at, iteration) in [("fit 1", 1), ("step 2.3", 2), ("done 1", 1)] {
        let mut seen = Vec::new();
        let err = learn_policy_observed(&params, &settings, &mut |e| {
            let name = event_name(&e);
            let flow = if name == at {
                ControlFlow::Break(())
            } else {
                ControlFlow::Continue(())
            };
            seen.push(name);
            flow
        })
        .expect_err("stopped");
        assert!(
            matches!(err, SimError::Stopped { iteration: i } if i == iteration),
            "{err}"
        );
        assert_eq!(seen.last().map(String::as_str), Some(at), "{seen:?}");
    }
}

/// The prequential choice of the filtered MSGP loop: every iteration reports which model its
/// search ran on and both models' filter likelihoods of the episode it then ran; the first
/// search runs on the linear model (nothing predicted yet), each later one on the GP model
/// exactly when the GP's held-out scores so far sum below the linear model's. The scores are
/// of data neither model saw: the first iteration's, recomputed here from models fitted on the
/// random episodes alone, are the reported ones bit for bit. Reproducible; off, nothing is
/// reported.
#[test]
fn the_prequential_choice_searches_on_the_model_that_predicted_unseen_episodes_better() {
    use msgp_core::fit::{TrainingEpisode, fit_episodes};
    use msgp_core::model::Method;
    use msgp_sim::learn::{ModelChoice, SearchModel, episode_trajectory};
    assert!(
        LearnSettings::filtered_msgp().prequential_choice,
        "the filtered loop's default"
    );
    let settings = LearnSettings {
        evaluation_episodes: 0,
        ..small_filtered(3)
    };
    let params = PendulumParams::tier(PlantTier::Noisy);
    let a = learn_policy(&params, &settings, &mut |_| {}).expect("loop runs");
    let mut advantage = 0.0;
    for (k, r) in a.iterations.iter().enumerate() {
        let expected = if k > 0 && advantage < 0.0 {
            SearchModel::Gp
        } else {
            SearchModel::Linear
        };
        assert_eq!(r.search_model, Some(expected), "iteration {}", r.iteration);
        let h = r.held_out.expect("scored");
        assert!(h.gp_nll.is_finite() && h.linear_nll.is_finite() && h.steps > 0);
        advantage += h.gp_nll - h.linear_nll;
    }
    // iteration 1: both models fitted on the random episodes, scored on the first feedback one
    let training: Vec<TrainingEpisode> = a.episodes[..2]
        .iter()
        .map(|ep| TrainingEpisode {
            traj: episode_trajectory(ep).expect("trajectory"),
            policy: None,
        })
        .collect();
    let newest = episode_trajectory(&a.episodes[2]).expect("trajectory");
    let learner = msgp_sim::learn::learner_settings(&params, &settings).expect("valid");
    let mut choice = ModelChoice::new(&learner).expect("an MSGP loop");
    let linear = choice.fit(&training, 1).expect("linear fit");
    let gp_settings = FitSettings {
        seed: settings.seed + 1,
        ..settings.fit.clone()
    };
    let (gp, _) = fit_episodes(&training, &gp_settings, &mut |_| {}).expect("GP fit");
    let h = a.iterations[0].held_out.expect("scored");
    assert_eq!(linear.filter_nll(&newest).expect("filter").0, h.linear_nll);
    assert_eq!(gp.filter_nll(&newest).expect("filter").0, h.gp_nll);
    assert_eq!(linear.method, Method::LinearKf);
    let b = learn_policy(&params, &settings, &mut |_| {}).expect("loop runs");
    assert_eq!(a.final_gains, b.final_gains);
    for (x, y) in a.iterations.iter().zip(&b.iterations) {
        assert_eq!((x.search_model, x.held_out), (y.search_model, y.held_out));
    }
    let off = LearnSettings {
        prequential_choice: false,
        iterations: 1,
        ..settings
    };
    let c = learn_policy(&params, &off, &mut |_| {}).expect("loop runs");
    assert_eq!(
        (c.iterations[0].search_model, c.iterations[0].held_out),
        (None, None)
    );
}

/// Figures of short runs of every model's loop (predicted and measured cost, the gains on the
/// pole), stored from the loop before it moved onto the generic policy search: what the loop
/// computes stays the same through refactors. Relative 1e-9: a change of formula, order of
/// work or seed moves them by far more.
#[test]
fn short_runs_keep_their_stored_figures() {
    use msgp_core::model::Method;
    let params = PendulumParams::default();
    let cases = [
        ("msgp filter", small_filtered(2), STORED_FILTER),
        ("msgp free-run", small(2), STORED_FREE),
        (
            "gp-narx",
            shortened(LearnSettings::for_method(Method::GpNarx), 2),
            STORED_GP_NARX,
        ),
        (
            "linear-kf",
            shortened(LearnSettings::for_method(Method::LinearKf), 2),
            STORED_LINEAR_KF,
        ),
    ];
    let runs: Vec<(&str, Vec<Figures>, &[Figures])> = cases
        .into_iter()
        .map(|(name, settings, stored)| {
            let out = learn_policy(&params, &settings, &mut |_| {}).expect("learn");
            let got = out
                .iterations
                .iter()
                .map(|r| {
                    [
                        r.predicted_cost,
                        r.actual_cost,
                        r.gains.kp_theta,
                        r.gains.kd_theta,
                    ]
                })
                .collect();
            (name, got, stored)
        })
        .collect();
    for (name, got, _) in &runs {
        println!("{name}: {got:?}");
    }
    for (name, got, stored) in runs {
        assert_eq!(got.len(), stored.len(), "{name}");
        for (g, s) in got.iter().zip(stored) {
            for (a, b) in g.iter().zip(s) {
                assert!(
                    (a - b).abs() <= 1e-9 * b.abs().max(1e-3),
                    "{name}: {got:?} vs stored {stored:?}"
                );
            }
        }
    }
}

/// An iteration's predicted and measured cost, `kp_θ` and `kd_θ`.
type Figures = [f64; 4];

const STORED_FILTER: &[[f64; 4]] = &[
    [
        1.1501792381972327,
        0.17397774983011016,
        19.000000001285585,
        2.408319511326732,
    ],
    [
        1.1398214529740176,
        3.3415179689312575,
        19.14483992235543,
        2.4842776335882526,
    ],
];
const STORED_FREE: &[[f64; 4]] = &[
    [
        24.415860742845275,
        0.25599488106968504,
        8.498504337036191,
        1.6998686280901294,
    ],
    [
        3.733531296442371,
        6.30953463014866,
        6.999876345345779,
        1.9997839861184596,
    ],
];
const STORED_GP_NARX: &[[f64; 4]] = &[
    [
        4.308267399045464,
        0.1446840985983482,
        19.08104212463047,
        2.803338346165367,
    ],
    [
        0.9452367695159009,
        2.2747665948962967,
        20.76209532178013,
        5.051519384617118,
    ],
];
const STORED_LINEAR_KF: &[[f64; 4]] = &[
    [
        0.7839673615826025,
        0.15799279670033495,
        18.005484278779875,
        2.6063366666211296,
    ],
    [
        1.2402078056083856,
        3.647698372669343,
        21.524207314688383,
        2.277982966864927,
    ],
];

/// The real-robot route: the loop's episodes logged to CSV (as the simulator writes them) and
/// read back as `msgp fit` reads data, the loop's state replayed from them
/// ([`msgp_core::learner::Learner::from_episodes`]), then one improvement step: for every
/// iteration of a filtered MSGP loop (its warm starts and prequential choice carried across
/// iterations) it gives the gains the loop ran next, to the bit.
#[test]
fn improving_from_logged_episodes_gives_the_loops_policies() {
    use std::path::PathBuf;

    use msgp_core::data::dataset::{Dataset, Selection};
    use msgp_core::learner::{Episode, Learner};
    use msgp_core::policy::Policy;
    use msgp_sim::learn::{gains_from, learner_settings, modelled_policy, pendulum_task};

    let settings = LearnSettings {
        evaluation_episodes: 0,
        ..small_filtered(3)
    };
    let params = PendulumParams::default();
    let out = learn_policy(&params, &settings, &mut |_| {}).expect("loop runs");
    let dir = std::env::temp_dir().join(format!("msgp-improve-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("scratch dir");
    let r = settings.random_rollouts;
    let (inputs, outputs) = (
        vec!["command".to_string()],
        vec!["meas_theta".to_string(), "meas_x".to_string()],
    );
    let selection = Selection {
        inputs: &inputs,
        outputs: &outputs,
        topic: None,
        time: Default::default(),
        sort_time: false,
    };
    let episodes: Vec<Episode> = out
        .episodes
        .iter()
        .enumerate()
        .map(|(k, ep)| {
            let path: PathBuf = dir.join(format!("{k:02}.csv"));
            msgp_sim::write_run(&path, ep).expect("log written");
            let data = Dataset::load(&[path], &selection).expect("log read");
            let traj = &data.parts[0].traj;
            let rows = |m: &nalgebra::DMatrix<f64>| -> Vec<Vec<f64>> {
                (0..m.nrows())
                    .map(|i| m.row(i).iter().copied().collect())
                    .collect()
            };
            let policy = (k >= r).then(|| {
                Policy::Pid(modelled_policy(&out.iterations[k - r].gains, &params).expect("gains"))
            });
            Episode {
                seed: ep.info.seed,
                outputs: rows(&traj.y),
                commands: rows(&traj.u),
                ended_early: false,
                truncated: false,
                policy,
            }
        })
        .collect();
    let _ = std::fs::remove_dir_all(&dir);
    let task = pendulum_task(&params, &settings).expect("task");
    let loop_settings = learner_settings(&params, &settings).expect("settings");
    let quiet = &mut |_: msgp_core::learner::LearnEvent<'_>| ControlFlow::Continue(());
    for n in 0..settings.iterations {
        let logged = episodes[..r + n].to_vec();
        let mut learner =
            Learner::from_episodes(task.clone(), loop_settings.clone(), logged, quiet)
                .expect("replays");
        let step = learner.improve(quiet).expect("improves");
        let found = step.searched.expect("the search found a policy");
        assert_eq!(
            gains_from(&found.policy).expect("PID"),
            out.iterations[n].gains,
            "iteration {}",
            n + 1
        );
        assert_eq!(step.search_model, out.iterations[n].search_model);
    }
    // the episodes must come in the loop's order: a policy episode among the random ones is
    // refused with the place named
    let mut shuffled = episodes[..r + 1].to_vec();
    shuffled.swap(0, r);
    let err =
        Learner::from_episodes(task, loop_settings, shuffled, quiet).expect_err("out of order");
    assert!(err.to_string().contains("episode 0 out of place"), "{err}");
}
