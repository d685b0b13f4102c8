//! Tests of the fits (every method) through the public entry points.

use super::*;
use crate::gp::integrator::Structure;
use crate::gp::{MeanFunction, PreparedGp};
use crate::loss::{Complexity, Likelihood};
use crate::model::{Method, Rollout};
use crate::numeric::parallel::Threads;
use crate::policy::{LinearPolicy, PolicySpec};
use crate::rollout::{Control, rollout};
use nalgebra::DMatrix;

fn traj(n: usize) -> Trajectory {
    let u: Vec<f64> = (0..n).map(|i| (i as f64 * 0.3).sin()).collect();
    let y: Vec<f64> = (0..n).map(|i| (i as f64 * 0.2).cos()).collect();
    Trajectory::siso(&u, &y).expect("finite")
}

fn options(method: Method, inducing: Option<usize>, iterations: Option<usize>) -> FitOptions {
    FitOptions {
        method,
        ly: 2,
        lu: 3,
        seed: 7,
        integrators: Vec::new(),
        optimizer: FitOptimizer::Adam,
        start: None,
        threads: Threads::default(),
        segment_length: None,
        overrides: Overrides {
            inducing,
            iterations,
            // (only a GP has a prior mean to choose, only MSGP a likelihood)
            mean: (method != Method::LinearKf).then_some(MeanFunction::Zero),
            likelihood: (method == Method::Msgp).then_some(Likelihood::FreeRun),
            ..Overrides::default()
        },
    }
}

/// `options` with the mean `mean` (`None`: the protocol's choice between recipes).
fn with_mean(options: FitOptions, mean: Option<MeanFunction>) -> FitOptions {
    FitOptions {
        overrides: Overrides {
            mean,
            ..options.overrides
        },
        ..options
    }
}

/// The protocol's switches ([`Switches`]) turn the MSGP settings they name and nothing else,
/// reach a one-step fit's objective where there is one, and are refused, by name, by a method
/// without them.
#[test]
fn switches_turn_their_settings_and_other_methods_refuse_them() {
    let data = [traj(200)];
    let with = |method, switches| {
        let o = options(method, None, None);
        FitOptions {
            overrides: Overrides {
                switches,
                likelihood: None,
                ..o.overrides
            },
            ..o
        }
    };
    let all = Switches {
        one_step_objective: Some(OneStepObjective::Vfe),
        calibrate: Some(false),
        blow_up_fallback: Some(false),
    };
    let plain = with(Method::Msgp, Switches::default())
        .settings(&data)
        .expect("defaults");
    let turned = with(Method::Msgp, all).settings(&data).expect("switched");
    let (MethodSettings::Msgp(p), MethodSettings::Msgp(t)) = (&plain.method, &turned.method) else {
        panic!("msgp settings");
    };
    assert_eq!((p.calibrate, p.blow_up_fallback), (true, true));
    let expected = MsgpSettings {
        one_step_objective: OneStepObjective::Vfe,
        calibrate: false,
        blow_up_fallback: false,
        ..p.clone()
    };
    assert_eq!(t, &expected, "only the switched settings move");
    assert_ne!(p.one_step_objective, OneStepObjective::Vfe);
    let narx = with(
        Method::GpNarx,
        Switches {
            one_step_objective: Some(OneStepObjective::Exact),
            ..Switches::default()
        },
    )
    .settings(&data)
    .expect("a one-step objective");
    assert!(matches!(
        narx.method,
        MethodSettings::GpNarx(OneStepFitSettings {
            objective: OneStepObjective::Exact,
            ..
        })
    ));
    for (switch, name) in [
        (
            Switches {
                calibrate: Some(false),
                ..Switches::default()
            },
            "calibrate",
        ),
        (
            Switches {
                blow_up_fallback: Some(false),
                ..Switches::default()
            },
            "blow_up_fallback",
        ),
    ] {
        let e = with(Method::GpNarx, switch)
            .settings(&data)
            .expect_err("not gp-narx's");
        assert!(
            matches!(&e, MsgpError::InvalidSetting { name: n, reason } if *n == name && reason.contains("gp-narx")),
            "{e:?}"
        );
    }
    let e = with(
        Method::LinearKf,
        Switches {
            one_step_objective: Some(OneStepObjective::Vfe),
            ..Switches::default()
        },
    )
    .settings(&data)
    .expect_err("no one-step fit");
    assert!(
        matches!(
            &e,
            MsgpError::InvalidSetting {
                name: "one_step_objective",
                ..
            }
        ),
        "{e:?}"
    );
}

/// A warm start continues the previous model: zero iterations give it back unchanged (same
/// parameters and normaliser, although the new data would normalise differently), more
/// iterations lower the loss on the new data from there, settings with more pseudo-inputs grow
/// the model's (see the test's comments), and a model of another shape (more pseudo-inputs than asked, another history,
/// another method) is refused.
#[test]
fn a_warm_start_continues_the_previous_model() {
    let first: Vec<TrainingEpisode> = [traj(60), traj(50)]
        .into_iter()
        .map(|traj| TrainingEpisode { traj, policy: None })
        .collect();
    let settings = FitSettings {
        ly: 2,
        lu: 2,
        method: MsgpSettings {
            inducing: 12,
            iterations: 15,
            validation_fraction: 0.0,
            ..MsgpSettings::default()
        }
        .into(),
        ..FitSettings::default()
    };
    let (previous, _) = fit_episodes(&first, &settings, &mut |_| {}).expect("first fit");
    // more data, with another mean and scale
    let mut more = first.clone();
    let u: Vec<f64> = (0..70).map(|i| 2.0 + (i as f64 * 0.17).sin()).collect();
    let y: Vec<f64> = (0..70)
        .map(|i| 1.0 + 3.0 * (i as f64 * 0.11).cos())
        .collect();
    more.push(TrainingEpisode {
        traj: Trajectory::siso(&u, &y).expect("finite"),
        policy: None,
    });
    let zero = settings.clone().with_solver_iterations(0);
    let (same, _) = refit_episodes(&more, &zero, &previous, &mut |_| {}).expect("refit 0");
    assert_eq!(same.params, previous.params);
    assert_eq!(same.normalizer, previous.normalizer);
    let mut losses = Vec::new();
    let (cont, report) =
        refit_episodes(&more, &settings, &previous, &mut |p| losses.push(p.loss)).expect("refit");
    assert_eq!(report.iterations_run, 16);
    assert_eq!(cont.normalizer, previous.normalizer);
    assert_eq!(cont.params.pseudo_inputs, previous.params.pseudo_inputs);
    assert!(
        losses[losses.len() - 1] < losses[0] - 1e-3,
        "{} → {}",
        losses[0],
        losses[losses.len() - 1]
    );
    // from scratch on the same data, the start is the one-step fit: another first loss
    let mut scratch = Vec::new();
    fit_episodes(&more, &zero, &mut |p| scratch.push(p.loss)).expect("scratch");
    assert_ne!(scratch[0], losses[0]);
    // settings asking for more pseudo-inputs than the previous model has (its first data had
    // fewer windows, say) place that many afresh over the new data's windows, their targets
    // the previous function's: the grown model predicts what the previous one did
    let mut wider = zero.clone();
    wider.msgp_mut().expect("msgp").inducing = 50;
    let (grown, _) = refit_episodes(&more, &wider, &previous, &mut |_| {}).expect("refit wider");
    assert_eq!(grown.params.pseudo_inputs.nrows(), 50);
    assert_eq!(
        grown.params.log_lengthscales,
        previous.params.log_lengthscales
    );
    assert_eq!(grown.params.log_signal_var, previous.params.log_signal_var);
    let (gap, size) = residual_means_gap(&previous, &grown, &more);
    assert!(
        gap < 0.05 * size,
        "the grown model's mean moved by {gap} (GP part up to {size})"
    );
    // without targets (zero) the same placement would move it by the whole GP part
    let mut untargeted = grown.clone();
    untargeted.params.pseudo_targets.fill(0.0);
    let (gap0, _) = residual_means_gap(&previous, &untargeted, &more);
    assert!(gap0 > 0.5 * size, "{gap0} vs {size}");
    for (bad, needle) in [
        (
            {
                let mut s = settings.clone();
                s.msgp_mut().expect("msgp").inducing = 11;
                s
            },
            "at most 11",
        ),
        (settings.one_step_start().expect("msgp"), "only MSGP"),
        (
            FitSettings {
                lu: 3,
                ..settings.clone()
            },
            "(2, 3)",
        ),
    ] {
        let e = refit_episodes(&more, &bad, &previous, &mut |_| {}).expect_err("refused");
        assert!(e.to_string().contains(needle), "{e}");
    }
}

/// The largest difference between two models' latent means over the windows of `episodes`
/// (normalised by `a`'s normaliser), and the largest GP part (the mean over the linear mean)
/// of `a` there.
fn residual_means_gap(a: &Model, b: &Model, episodes: &[TrainingEpisode]) -> (f64, f64) {
    let norm: Vec<Trajectory> = episodes
        .iter()
        .map(|e| a.normalizer.apply(&e.traj))
        .collect();
    let refs: Vec<&Trajectory> = norm.iter().collect();
    let data = one_step_pairs(&a.spec, &refs).expect("pairs");
    let prepare = |m: &Model| {
        PreparedGp::new(&m.params, &m.config, &mut JitterLog::default()).expect("prepared")
    };
    let (ga, gb) = (prepare(a), prepare(b));
    let mut bare = ga.clone();
    bare.linear_mean = None;
    let (mut gap, mut size) = (0.0_f64, 0.0_f64);
    for i in 0..data.x.nrows() {
        let x: Vec<f64> = data.x.row(i).iter().copied().collect();
        for ((ma, _), (mb, _)) in ga.predict(&x).into_iter().zip(gb.predict(&x)) {
            gap = gap.max((ma - mb).abs());
        }
        for (m, _) in bare.predict(&x) {
            size = size.max(m.abs());
        }
    }
    (gap, size)
}

/// 80 samples of `y_t = 0.9 y_{t−1} + 0.5 u_{t−1} + a sin(3 y_{t−1})` under a sine input.
fn first_order(a: f64) -> Trajectory {
    let u: Vec<f64> = (0..80).map(|i| (i as f64 * 0.37).sin()).collect();
    let mut y = vec![0.0; 80];
    for t in 1..80 {
        y[t] = 0.9 * y[t - 1] + 0.5 * u[t - 1] + a * (y[t - 1] * 3.0).sin();
    }
    Trajectory::siso(&u, &y).expect("finite")
}

/// Without a validation tail the fit returns the iterate of lowest training loss: a step
/// size large enough to throw the loss up near the end of the run (but not to fail
/// numerically) ends above its best, and the fit still returns the best iterate, bit for
/// bit the parameters of the same fit stopped at that iteration.
#[test]
fn without_validation_the_fit_returns_its_lowest_training_loss() {
    let traj = first_order(0.2);
    let iterations = 300;
    let settings = FitSettings {
        ly: 1,
        lu: 1,
        method: MsgpSettings {
            inducing: 10,
            iterations,
            learning_rate: 0.04,
            validation_fraction: 0.0,
            mean: MeanFunction::Linear,
            ..MsgpSettings::default()
        }
        .into(),
        ..FitSettings::default()
    };
    let mut losses = Vec::new();
    let (model, report) = fit(std::slice::from_ref(&traj), &settings, &mut |p| {
        losses.push(p.loss)
    })
    .expect("fit");
    assert!(
        report.numerical_stop.is_none(),
        "{:?}",
        report.numerical_stop
    );
    assert_eq!(losses.len(), iterations + 1);
    let (best, lowest) = losses
        .iter()
        .copied()
        .enumerate()
        .fold((0, f64::INFINITY), |a, b| if b.1 < a.1 { b } else { a });
    assert!(
        best < iterations && losses[iterations] > lowest + 1e-2,
        "the run must end above its best for the test to mean anything: {losses:?}"
    );
    assert_eq!(report.best_iteration, best);
    let stopped = settings.clone().with_solver_iterations(best);
    let (at_best, _) =
        fit(std::slice::from_ref(&traj), &stopped, &mut |_| {}).expect("fit to the best");
    assert_eq!(model.params, at_best.params);
}

/// An observer that breaks stops the MSGP training at that iteration with
/// [`MsgpError::Stopped`]; one that never breaks gives what [`fit_episodes`] gives.
#[test]
fn an_observer_can_stop_a_fit() {
    let episodes = [TrainingEpisode {
        traj: first_order(0.2),
        policy: None,
    }];
    let settings = FitSettings {
        ly: 1,
        lu: 1,
        method: MsgpSettings {
            inducing: 10,
            iterations: 40,
            validation_fraction: 0.0,
            mean: MeanFunction::Linear,
            ..MsgpSettings::default()
        }
        .into(),
        ..FitSettings::default()
    };
    let mut seen = Vec::new();
    let err = fit_episodes_observed(&episodes, &settings, None, &mut |p| {
        seen.push(p.iteration);
        if p.iteration == 5 {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    })
    .expect_err("stopped");
    assert!(matches!(err, MsgpError::Stopped { iteration: 5 }), "{err}");
    assert_eq!(seen, (0..=5).collect::<Vec<_>>());
    let (observed, _) = fit_episodes_observed(&episodes, &settings, None, &mut |_| {
        ControlFlow::Continue(())
    })
    .expect("fit");
    let (plain, _) = fit_episodes(&episodes, &settings, &mut |_| {}).expect("fit");
    assert_eq!(observed.params, plain.params);
    // two recipes side by side on two threads: stopping the final training on all the data
    // (which may start before the second recipe's head ends) stops the whole fit
    let both = FitSettings {
        threads: Threads::new(2).expect("threads"),
        method: MsgpSettings {
            inducing: 10,
            iterations: 40,
            validation_fraction: 0.2,
            ..MsgpSettings::default()
        }
        .into(),
        ..settings
    };
    let err = fit_episodes_observed(&episodes, &both, None, &mut |p| {
        if (p.stage, p.iteration) == (2, 3) {
            ControlFlow::Break(())
        } else {
            ControlFlow::Continue(())
        }
    })
    .expect_err("stopped in the final training");
    assert!(matches!(err, MsgpError::Stopped { iteration: 3 }), "{err}");
}

#[test]
fn a_numerically_failing_step_keeps_parameters_that_evaluate() {
    // an absurd step size drives the rollout covariances to overflow within a few steps
    let traj = first_order(0.0);
    let settings = FitSettings {
        ly: 1,
        lu: 1,
        method: MsgpSettings {
            inducing: 10,
            iterations: 200,
            learning_rate: 30.0,
            validation_fraction: 0.0,
            mean: MeanFunction::Linear,
            ..MsgpSettings::default()
        }
        .into(),
        ..FitSettings::default()
    };
    let (model, report) =
        fit(std::slice::from_ref(&traj), &settings, &mut |_| {}).expect("fit survives");
    let stop = report
        .numerical_stop
        .expect("the step size is absurd enough to fail");
    assert!(stop.contains("kept iteration"), "{stop}");
    assert!(report.iterations_run < 201);
    // the kept parameters evaluate
    let mut log = JitterLog::default();
    let gp = PreparedGp::new(&model.params, &model.config, &mut log).expect("kept model");
    let norm = model.normalizer.apply(&traj);
    rollout(
        &gp,
        &model.spec,
        &norm,
        &Control::FeedForward,
        norm.len(),
        &mut log,
        |_| Ok(()),
    )
    .expect("kept model rolls out");
}

/// `y₀` a first-order lag `a y₀ + b u`, `y₁` a double integrator of `d u`, from rest, and
/// their measurements with a deterministic ripple of amplitude `ripple`; returns the clean
/// outputs too. `y₁` declared a kinematic double integrator: [`KINEMATIC_Y1`].
fn lag_and_double_integrator(
    u: DMatrix<f64>,
    (a, b, d): (f64, f64, f64),
    ripple: f64,
) -> (DMatrix<f64>, Trajectory) {
    let n = u.nrows();
    let mut y = DMatrix::<f64>::zeros(n, 2);
    for t in 1..n - 1 {
        y[(t + 1, 0)] = a * y[(t, 0)] + b * u[(t, 0)];
        y[(t + 1, 1)] = 2.0 * y[(t, 1)] - y[(t - 1, 1)] + d * u[(t, 0)];
    }
    let measured = y.map(|v| v + ripple * (10.0 * v / ripple).sin());
    (y, Trajectory::new(u, measured).expect("trajectory"))
}

const KINEMATIC_Y1: crate::gp::integrator::Integrator = crate::gp::integrator::Integrator {
    output: 1,
    order: 2,
    linear: true,
};

/// A linear-kf fit of a double integrator driven by a command with a non-zero mean: the
/// model is scaled, not centred (a centred linear model without intercept would lose the
/// mean command's constant acceleration, and its free simulation would drift away
/// quadratically), keeps the declared coefficients and has no GP.
#[test]
fn a_linear_kf_fit_simulates_an_integrator_under_a_mean_command() {
    let n = 200;
    let u = DMatrix::from_fn(n, 1, |t, _| 0.5 + 0.3 * (0.1 * t as f64).sin());
    let (clean, traj) = lag_and_double_integrator(u, (0.9, 0.1, 1e-3), 1e-4);
    let integrators = vec![KINEMATIC_Y1];
    let settings = FitSettings {
        ly: 2,
        lu: 1,
        integrators: integrators.clone(),
        method: LinearKfSettings { iterations: 200 }.into(),
        ..FitSettings::default()
    };
    let (model, report) = fit(std::slice::from_ref(&traj), &settings, &mut |_| {}).expect("fit");
    assert_eq!(model.method, Method::LinearKf);
    assert!(report.iterations_run > 0);
    assert!(model.normalizer.u_mean.iter().all(|&m| m == 0.0));
    assert!(model.normalizer.y_mean.iter().all(|&m| m == 0.0));
    for c in &Structure::new(&integrators, &model.spec).fixed {
        assert_eq!(model.params.linear_mean[(c.row, c.col)], c.value);
    }
    assert!(model.params.pseudo_targets.iter().all(|&v| v == 0.0));
    // free simulation over 200 steps: the mean command alone moves y₁ by ≈ 10 units
    let sim = model.simulate(&traj).expect("simulate");
    let last = sim.mean.nrows() - 1;
    let err = (sim.mean[(last, 1)] - clean[(n - 1, 1)]).abs();
    assert!(
        err < 0.05 * clean[(n - 1, 1)].abs(),
        "end effector off by {err}"
    );
    let err0 = (sim.mean[(last, 0)] - clean[(n - 1, 0)]).abs();
    assert!(err0 < 0.01, "first output off by {err0}");
}

/// A linear-kf warm start continues the previous model: zero iterations return its
/// parameters and units exactly, more iterations do not make the filter's likelihood of the
/// new data worse than there, and a model of another method is refused.
#[test]
fn a_linear_kf_fit_continues_the_previous_model() {
    let n = 200;
    let u = DMatrix::from_fn(n, 1, |t, _| 0.5 + 0.3 * (0.1 * t as f64).sin());
    let (_, traj) = lag_and_double_integrator(u, (0.9, 0.1, 1e-3), 1e-4);
    let episode = |t: Trajectory| TrainingEpisode {
        traj: t,
        policy: None,
    };
    let settings = FitSettings {
        ly: 2,
        lu: 1,
        integrators: vec![KINEMATIC_Y1],
        method: LinearKfSettings { iterations: 100 }.into(),
        ..FitSettings::default()
    };
    let (first, _) =
        fit_episodes(&[episode(traj.slice(0, 120))], &settings, &mut |_| {}).expect("fit");
    let all = [episode(traj.clone())];
    let again = |iterations| {
        refit_episodes(
            &all,
            &settings.clone().with_solver_iterations(iterations),
            &first,
            &mut |_| {},
        )
        .expect("warm start")
        .0
    };
    let same = again(0);
    assert_eq!(same.params, first.params);
    assert_eq!(same.normalizer, first.normalizer);
    let more = again(50);
    let nll = |m: &Model| {
        let t = m.normalizer.apply(&traj);
        let p = crate::fit::linear_kf::KalmanParams {
            a: m.params.linear_mean.clone(),
            log_process_noise: m.params.log_process_noise.clone(),
            log_obs_noise: m.params.log_obs_noise.clone(),
        };
        let mut log = JitterLog::default();
        crate::fit::linear_kf::kalman_nll(&p, &m.spec, &[&t], &m.config.jitter, &mut log)
            .expect("filter")
            .0
    };
    assert!(
        nll(&more) <= nll(&first),
        "{} > {}",
        nll(&more),
        nll(&first)
    );
    let (gp, _) = fit_episodes(
        &all,
        &FitSettings {
            method: MethodSettings::GpNarx(OneStepFitSettings {
                inducing: 10,
                iterations: 5,
                mean: MeanFunction::Linear,
                ..OneStepFitSettings::default()
            }),
            ..settings.clone()
        },
        &mut |_| {},
    )
    .expect("gp-narx fit");
    assert!(refit_episodes(&all, &settings, &gp, &mut |_| {}).is_err());
}

/// A driven double integrator `y₁` next to a damped output `y₀`: declared a linear
/// integrator, `y₁`'s coefficients, the GP's length-scales on its lags and `y₁`'s absent GP
/// come out of an MSGP fit exactly as the declaration set them, while the rest of the model
/// was trained.
#[test]
fn an_msgp_fit_keeps_what_an_integrating_output_fixes() {
    use crate::gp::integrator::{IGNORED_LENGTHSCALE, NO_GP_SIGNAL_VAR, Structure};
    let n = 120;
    let u = DMatrix::from_fn(n, 1, |t, _| {
        (0.3 * t as f64).sin() + (0.71 * t as f64).cos()
    });
    let (_, traj) = lag_and_double_integrator(u, (0.8, 0.3, 0.01), 1e-3);
    let integrators = vec![KINEMATIC_Y1];
    let settings = FitSettings {
        ly: 2,
        lu: 1,
        integrators: integrators.clone(),
        method: MsgpSettings {
            inducing: 15,
            iterations: 20,
            learning_rate: 0.01,
            validation_fraction: 0.0,
            mean: MeanFunction::Linear,
            ..MsgpSettings::default()
        }
        .into(),
        ..FitSettings::default()
    };
    let (model, _) = fit(std::slice::from_ref(&traj), &settings, &mut |_| {}).expect("fit");
    let structure = Structure::new(&integrators, &model.spec);
    let p = &model.params;
    for c in &structure.fixed {
        assert_eq!(p.linear_mean[(c.row, c.col)], c.value, "{}", p.linear_mean);
    }
    for &col in &structure.ignored {
        assert_eq!(p.log_lengthscales[(0, col)], IGNORED_LENGTHSCALE.ln());
        assert!(p.pseudo_inputs.column(col).iter().all(|&v| v == 0.0));
    }
    // `linear`: y₁ has no GP
    assert_eq!(structure.without_gp, vec![1]);
    assert!(p.pseudo_targets.column(1).iter().all(|&v| v == 0.0));
    assert_eq!(p.log_signal_var[1], NO_GP_SIGNAL_VAR.ln());
    // the free part was trained: the same fit without Adam steps differs
    let (start, _) = fit(
        std::slice::from_ref(&traj),
        &settings.clone().with_solver_iterations(0),
        &mut |_| {},
    )
    .expect("start");
    let u0 = model.spec.u_index(0, 0);
    assert_ne!(p.linear_mean[(1, u0)], start.params.linear_mean[(1, u0)]);
    // an integrator without the linear mean is refused
    let err = fit(
        std::slice::from_ref(&traj),
        &{
            let mut s = settings;
            s.msgp_mut().expect("msgp").mean = MeanFunction::Zero;
            s
        },
        &mut |_| {},
    )
    .expect_err("needs the linear mean");
    assert!(err.to_string().contains("integrators"), "{err}");
}

#[test]
fn options_default_inducing_and_iterations() {
    // 2 × (50 − 3) = 94 windows → 47 pseudo-inputs; 1000 − 3 windows → capped at 100
    let s = options(Method::Msgp, None, Some(30))
        .settings(&[traj(50), traj(50)])
        .expect("settings");
    let m = s.msgp().expect("msgp");
    assert_eq!(
        (m.inducing, m.iterations, m.one_step_iterations),
        (47, 30, 300)
    );
    let d = MsgpSettings::default();
    assert_eq!(
        (m.learning_rate, m.frozen.clone()),
        (d.learning_rate, d.frozen)
    );
    assert_eq!((s.ly, s.lu, s.seed), (2, 3, 7));
    let s = options(Method::GpNarx, None, Some(30))
        .settings(&[traj(1000)])
        .expect("settings");
    let one_step = |inducing, iterations| OneStepFitSettings {
        inducing,
        mean: MeanFunction::Zero,
        iterations,
        solver: OneStepSolver::Lbfgs,
        objective: OneStepObjective::Vfe,
    };
    assert_eq!(s.method, MethodSettings::GpNarx(one_step(100, 30)));
    let s = options(Method::PilcoNarx, Some(5), None)
        .settings(&[traj(4)])
        .expect("settings");
    // PILCO's variant keeps the exact GP's likelihood (`OneStepFitSettings::pilco`)
    assert_eq!(
        s.method,
        MethodSettings::PilcoNarx(OneStepFitSettings {
            objective: OneStepObjective::Exact,
            ..one_step(5, 300)
        })
    );
    let s = options(Method::LinearKf, None, Some(12))
        .settings(&[traj(40)])
        .expect("settings");
    assert_eq!(
        s.method,
        MethodSettings::LinearKf(LinearKfSettings { iterations: 12 })
    );
    assert_eq!(s.inducing(), None);
    // a linear-kf model has no GP: pseudo-inputs asked for are refused, not ignored
    let e = options(Method::LinearKf, Some(5), Some(12))
        .settings(&[traj(40)])
        .expect_err("no pseudo-inputs");
    assert!(
        matches!(
            e,
            MsgpError::InvalidSetting {
                name: "inducing",
                ..
            }
        ),
        "{e:?}"
    );
}

#[test]
fn options_refuse_bad_input_clearly() {
    let e = options(Method::Msgp, None, None)
        .settings(&[traj(10), traj(3)])
        .expect_err("short");
    assert!(
        e.to_string()
            .contains("training trajectory 1 has 3 samples"),
        "{e}"
    );
    let e = options(Method::Msgp, None, None)
        .settings(&[])
        .expect_err("empty");
    assert!(e.to_string().contains("no training trajectories"), "{e}");
    let e = options(Method::Msgp, Some(0), None)
        .settings(&[traj(10)])
        .expect_err("m = 0");
    assert!(e.to_string().contains("inducing"), "{e}");
    let e = FitOptions {
        ly: 0,
        ..options(Method::Msgp, None, None)
    }
    .settings(&[traj(10)])
    .expect_err("l_y = 0");
    assert!(e.to_string().contains("l_y"), "{e}");
}

/// MSGP's own choices of the options (its start, its segments) are refused by name by another
/// method before any data are read, and taken by MSGP.
#[test]
fn msgp_only_options_are_refused_by_name() {
    for method in [Method::GpNarx, Method::PilcoNarx, Method::LinearKf] {
        let start = FitOptions {
            start: Some(MsgpStart::Spread),
            ..options(method, None, None)
        };
        match start.check() {
            Err(MsgpError::InvalidSetting { name: "start", .. }) => {}
            other => panic!("{method:?} took a start: {other:?}"),
        }
        let segments = FitOptions {
            segment_length: Some(30),
            ..options(method, None, None)
        };
        match segments.settings(&[traj(200)]) {
            Err(MsgpError::InvalidSetting {
                name: "segment_length",
                ..
            }) => {}
            other => panic!("{method:?} took segments: {other:?}"),
        }
    }
    let msgp = FitOptions {
        start: Some(MsgpStart::Spread),
        segment_length: Some(30),
        ..options(Method::Msgp, None, None)
    };
    let s = msgp.settings(&[traj(200)]).expect("MSGP takes both");
    let m = s.msgp().expect("msgp");
    assert_eq!(
        (m.start, m.segments.map(|g| g.length)),
        (MsgpStart::Spread, Some(30))
    );
}

/// The settings serialise flat: the shared keys, `method` and the method's own keys only; an
/// MSGP record has the keys of format 1.1 (but `refit`) and later ones (but
/// `choose_final_budget`; both removed 2026-12-07), and every method's record reads back equal.
#[test]
fn settings_serialise_with_the_methods_own_keys() {
    let keys = |s: &FitSettings| {
        let v = serde_json::to_value(s).expect("json");
        let mut k: Vec<String> = v.as_object().expect("object").keys().cloned().collect();
        k.sort();
        k
    };
    let shared = ["integrators", "ly", "lu", "method", "seed"];
    let with = |own: &[&str]| {
        let mut k: Vec<String> = shared.iter().chain(own).map(|s| s.to_string()).collect();
        k.sort();
        k
    };
    let msgp_1_1 = [
        "complexity",
        "eval_every",
        "frozen",
        "inducing",
        "iterations",
        "learning_rate",
        "mean",
        "noise_floor",
        "one_step_iterations",
        "optimizer",
        "patience",
        "start_window",
        "validation_fraction",
    ];
    let mut msgp_1_2 = msgp_1_1.to_vec();
    msgp_1_2.push("likelihood");
    msgp_1_2.push("noise_start");
    msgp_1_2.push("one_step_solver");
    msgp_1_2.push("alternative");
    msgp_1_2.push("start");
    msgp_1_2.push("one_step_objective");
    msgp_1_2.push("full_data_iterations");
    msgp_1_2.push("calibrate");
    msgp_1_2.push("blow_up_fallback");
    msgp_1_2.push("full_data_blow_up");
    msgp_1_2.push("segments");
    assert_eq!(keys(&FitSettings::new(Method::Msgp)), with(&msgp_1_2));
    for m in [Method::GpNarx, Method::PilcoNarx] {
        assert_eq!(
            keys(&FitSettings::new(m)),
            with(&["inducing", "iterations", "mean", "objective", "solver"])
        );
    }
    assert_eq!(
        keys(&FitSettings::new(Method::LinearKf)),
        with(&["iterations"])
    );
    for m in [
        Method::Msgp,
        Method::GpNarx,
        Method::PilcoNarx,
        Method::LinearKf,
    ] {
        let s = FitSettings::new(m);
        let v = serde_json::to_value(&s).expect("json");
        assert_eq!(v["method"], serde_json::to_value(m).expect("method"));
        let back: FitSettings = serde_json::from_value(v).expect("reads back");
        assert_eq!(back, s);
        assert_eq!(back.method(), m);
    }
    // settings written before the start was a setting read back with the one-step start
    let mut v = serde_json::to_value(FitSettings::new(Method::Msgp)).expect("json");
    assert_eq!(v["start"], "one-step");
    v.as_object_mut().expect("object").remove("start");
    v.as_object_mut()
        .expect("object")
        .remove("one_step_objective");
    let back: FitSettings = serde_json::from_value(v).expect("reads back");
    assert_eq!(back.msgp().map(|s| s.start), Some(MsgpStart::OneStep));
    // and records from before the variational bound as exact fits
    assert_eq!(
        back.msgp().map(|s| s.one_step_objective),
        Some(OneStepObjective::Exact)
    );
    // the complexity term by its kebab-case name; records with its Rust name read back
    let mut v = serde_json::to_value(FitSettings::new(Method::Msgp)).expect("json");
    assert_eq!(v["complexity"], "pseudo-data-nll");
    for (old, term) in [
        ("None", Complexity::None),
        ("PseudoDataNll", Complexity::PseudoDataNll),
        ("NegHalfLogDet", Complexity::NegHalfLogDet),
        ("HalfLogDet", Complexity::HalfLogDet),
    ] {
        v["complexity"] = old.into();
        let back: FitSettings = serde_json::from_value(v.clone()).expect("reads back");
        assert_eq!(back.msgp().map(|s| s.complexity), Some(term));
    }
    assert_eq!(
        serde_json::to_value(Complexity::NegHalfLogDet).expect("json"),
        "neg-half-log-det"
    );
    let mut v = serde_json::to_value(FitSettings::new(Method::GpNarx)).expect("json");
    assert_eq!(v["objective"], "vfe");
    v.as_object_mut().expect("object").remove("objective");
    let back: FitSettings = serde_json::from_value(v).expect("reads back");
    assert!(matches!(
        back.method,
        MethodSettings::GpNarx(OneStepFitSettings {
            objective: OneStepObjective::Exact,
            ..
        })
    ));
}

/// An MSGP fit on the filter likelihood lowers the filter loss of its training data from the
/// one-step start, checks its validation tail by the filter too (the history's validation
/// column is the tail's filter NLL of the returned iterate), and refuses a smoothed start.
#[test]
fn an_msgp_fit_trains_on_the_filter_likelihood() {
    use crate::loss::filter_loss;
    use crate::rollout::Episode;
    let traj = first_order(0.3);
    let settings = |likelihood, iterations| FitSettings {
        ly: 1,
        lu: 1,
        method: MsgpSettings {
            inducing: 8,
            iterations,
            learning_rate: 0.01,
            likelihood,
            ..MsgpSettings::default()
        }
        .into(),
        ..FitSettings::default()
    };
    let filter_nll = |m: &Model| {
        let norm = m.normalizer.apply(&traj);
        let v = filter_loss(
            &m.params,
            &m.config,
            &m.spec,
            &[Episode::feed_forward(norm)],
            Complexity::None,
            &mut JitterLog::default(),
        )
        .expect("filter");
        v.nll / v.steps as f64
    };
    let fit_with = |s: &FitSettings| fit(std::slice::from_ref(&traj), s, &mut |_| {}).expect("fit");
    let (start, _) = fit_with(&settings(Likelihood::Filter, 0));
    let (trained, report) = fit_with(&settings(Likelihood::Filter, 60));
    assert!(
        filter_nll(&trained) < filter_nll(&start) - 0.05,
        "{} → {}",
        filter_nll(&start),
        filter_nll(&trained)
    );
    assert!(!report.history.is_empty(), "validation checks ran");
    // the same settings on the free-run likelihood train another model
    let (free, _) = fit_with(&settings(Likelihood::FreeRun, 60));
    assert_ne!(free.params, trained.params);
    let mut smoothed = settings(Likelihood::Filter, 10);
    smoothed.msgp_mut().expect("msgp").start_window =
        crate::narx::start_window::StartWindow::Smoothed {
            samples: 6,
            degree: 2,
        };
    let err = fit(std::slice::from_ref(&traj), &smoothed, &mut |_| {}).expect_err("refused");
    assert!(err.to_string().contains("measured window"), "{err}");
}

/// The divergence check: silent on a sound fit (and the fit reports nothing), firing on the
/// same model made unstable (a linear mean with a pole at 1.3 runs its free simulation far out
/// of the training outputs' range), and on a model whose predictive variance explodes.
#[test]
fn the_divergence_check_fires_on_an_unstable_model_only() {
    let traj = first_order(0.2);
    let settings = FitSettings {
        ly: 1,
        lu: 1,
        method: MsgpSettings {
            inducing: 10,
            iterations: 30,
            mean: MeanFunction::Linear,
            ..MsgpSettings::default()
        }
        .into(),
        ..FitSettings::default()
    };
    let (model, report) = fit(std::slice::from_ref(&traj), &settings, &mut |_| {}).expect("fit");
    assert_eq!(report.diverged, None);
    assert_eq!(check_divergence(&model, &[&traj]), None);
    let mut unstable = model.clone();
    unstable.params.linear_mean[(0, 0)] = 1.3;
    let why = check_divergence(&unstable, &[&traj]).expect("a pole at 1.3 diverges");
    assert!(
        why.contains("training trajectory 0") && why.contains("leaves the measured outputs' range"),
        "{why}"
    );
    // the same test against other data's outputs (what `msgp eval` runs): the stable model
    // stays inside them, the unstable one leaves them
    let range = OutputRange::of(&[&traj], 1);
    let sim = model.simulate(&traj).expect("simulates");
    assert_eq!(range.divergence(&sim, "the test part"), None);
    let sim = unstable.simulate(&traj).expect("simulates");
    let why = range
        .divergence(&sim, "the test part")
        .expect("the unstable model leaves the test outputs");
    assert!(
        why.starts_with("the free simulation of the test part leaves"),
        "{why}"
    );
    // an output that was not measured (no finite range) is not judged
    let unmeasured = OutputRange::of(&[], 1);
    assert_eq!(unmeasured.divergence(&sim, "x"), None);
    let mut noisy = model.clone();
    // a process noise far above the outputs' range: the mean stays, the variance does not
    noisy.params.log_process_noise[0] = (1e4f64).ln();
    let why = check_divergence(&noisy, &[&traj]).expect("exploding variance");
    assert!(why.contains("standard deviation"), "{why}");
    // nothing to check without feed-forward trajectories
    assert_eq!(check_divergence(&unstable, &[]), None);
}

/// The mean-feedback simulation of a fitted GP model: with (almost) no noise the moment-matching
/// rollout carries almost no variance, and the two simulations agree; the mean-feedback
/// variance is the one-step predictive variance, never more than the propagated one by much.
#[test]
fn mean_feedback_and_moment_matching_agree_without_noise() {
    use crate::model::Rollout;
    let traj = first_order(0.2);
    let settings = FitSettings {
        ly: 1,
        lu: 1,
        method: MsgpSettings {
            inducing: 15,
            iterations: 0,
            full_data_iterations: None,
            ..MsgpSettings::default()
        }
        .into(),
        ..FitSettings::default()
    };
    let (mut model, _) = fit(std::slice::from_ref(&traj), &settings, &mut |_| {}).expect("fit");
    model.config.noise_floor = 0.0;
    model.params.log_process_noise[0] = (1e-12f64).ln();
    model.params.log_obs_noise[0] = (1e-12f64).ln();
    let mm = model.simulate(&traj).expect("mm");
    let mf = model
        .simulate_as(&traj, Rollout::MeanFeedback)
        .expect("mean feedback");
    assert_eq!(mm.start, mf.start);
    assert_eq!(mm.mean.shape(), mf.mean.shape());
    let scale = traj.y.amax();
    for i in 0..mm.mean.nrows() {
        let d = (mm.mean[(i, 0)] - mf.mean[(i, 0)]).abs();
        assert!(
            d < 1e-3 * scale,
            "step {i}: MM {} vs mean feedback {}",
            mm.mean[(i, 0)],
            mf.mean[(i, 0)]
        );
    }
    // and with noise they differ (the rollout propagates it, mean feedback does not)
    let (noisy, _) = fit(std::slice::from_ref(&traj), &settings, &mut |_| {}).expect("fit");
    let mm = noisy.simulate(&traj).expect("mm");
    let mf = noisy.simulate_as(&traj, Rollout::MeanFeedback).expect("mf");
    let last = mm.var.nrows() - 1;
    assert!(
        mm.var[(last, 0)] > mf.var[(last, 0)],
        "propagated variance grows"
    );
}

/// 160 samples of a second-order plant with a long memory driven by two sines, linear but for
/// `nonlinear · tanh(y_{t−1})`.
/// The protocol's calibration is what its definition says: the chosen recipe trained on the
/// head alone for the final training's iterations (here: a fit of the head without a tail,
/// which starts and trains the same way) simulates the tail, and the added variance is the one
/// minimising that simulation's NLL. It widens every simulated variance by exactly that, moves
/// no mean, and is saved and reloaded with the model; `calibrate: false` leaves it out and the
/// model otherwise unchanged.
#[test]
fn the_calibration_is_the_tail_nll_of_the_final_trainings_proxy() {
    use crate::fit::calibration::{Judge, added_variance};
    use crate::model_file::{FitRecord, ModelFile};
    // a saturating plant whose output drifts in its last fifth (the tail): a model trained on
    // the head alone is overconfident there
    let n = 160;
    let u: Vec<f64> = (0..n).map(|i| ((i as f64) * 0.37).sin()).collect();
    let mut y = vec![0.0; n];
    for t in 1..n {
        let drift = if t < 128 { 0.0 } else { 0.5 };
        y[t] = 0.7 * y[t - 1] + (1.5 * u[t - 1]).tanh() + drift;
    }
    let traj = Trajectory::siso(&u, &y).expect("finite");
    let msgp = MsgpSettings {
        inducing: 12,
        iterations: 80,
        full_data_iterations: Some(40),
        ..MsgpSettings::default()
    };
    let settings = |msgp: MsgpSettings| ly2_lu1(Threads::new(1).expect("threads"), msgp);
    let (model, report) = fit(
        std::slice::from_ref(&traj),
        &settings(msgp.clone()),
        &mut |_| {},
    )
    .expect("fit");
    let c = report.calibration.clone().expect("calibrated");
    let Judge::Proxy { iteration } = c.judge else {
        panic!("the final training ran, so its proxy judges: {c:?}")
    };
    // the proxy, independently: the chosen recipe on the head, no tail, 40 iterations
    let chosen = match report.chosen_recipe {
        0 => msgp.clone(),
        _ => msgp.with_recipe(msgp.alternative.expect("alternative")),
    };
    let n = traj.len();
    let n_val = (n as f64 * msgp.validation_fraction).round() as usize;
    let head = traj.slice(0, n - n_val);
    let proxy_settings = settings(MsgpSettings {
        validation_fraction: 0.0,
        iterations: 40,
        ..chosen
    });
    let (proxy, proxy_report) =
        fit(std::slice::from_ref(&head), &proxy_settings, &mut |_| {}).expect("proxy");
    // (the reference normalises by the head's statistics, the fit by all the data's: the two
    // proxies agree to an iteration or two and their calibrations to the grid's step)
    assert!(
        proxy_report.best_iteration.abs_diff(iteration) <= 3,
        "{} vs {iteration}",
        proxy_report.best_iteration
    );
    let tail = traj.slice(n - n_val - model.spec.warmup(), n);
    let sim = proxy.simulate(&tail).expect("tail");
    let (std, w) = (model.normalizer.y_std[0], model.spec.warmup());
    let pairs: Vec<(f64, f64)> = (0..sim.mean.nrows())
        .map(|i| {
            let r = (tail.y[(w + i, 0)] - sim.mean[(i, 0)]) / std;
            (r * r, sim.var[(i, 0)] / (std * std))
        })
        .collect();
    let delta = added_variance(&pairs);
    assert!(
        delta > 0.1,
        "the proxy is overconfident on the tail: {delta}"
    );
    assert_eq!(model.calibration.len(), 1);
    let step = 10f64.ln() / crate::fit::calibration::GRID_PER_DECADE as f64;
    assert!(
        (model.calibration[0] / delta).ln().abs() <= 1.01 * step,
        "{} vs {delta}",
        model.calibration[0]
    );
    // … which the final model's own simulation of the tail (it trained on it) would not give
    let gp = PreparedGp::new(&model.params, &model.config, &mut Default::default()).expect("gp");
    let ep = crate::rollout::Episode::feed_forward(model.normalizer.apply(&tail));
    let own = calibration::tail_calibration(&gp, &model.spec, &[ep]).expect("own");
    assert!(
        (own[0] / delta).ln().abs() > 2.0 * step,
        "{own:?} vs {delta}"
    );
    assert!((c.added_std[0] - model.calibration[0].sqrt() * std).abs() < 1e-12 * std);
    // every simulated variance widened by δ, no mean moved
    let bare = Model {
        calibration: Vec::new(),
        ..model.clone()
    };
    let (a, b) = (
        model.simulate(&traj).expect("sim"),
        bare.simulate(&traj).expect("sim"),
    );
    assert_eq!(a.mean, b.mean);
    for (va, vb) in a.var.iter().zip(b.var.iter()) {
        assert!((va - vb - model.calibration[0] * std * std).abs() < 1e-12 * va);
    }
    // saved and reloaded with the model
    let record = FitRecord {
        train: std::slice::from_ref(&traj),
        settings: &settings(msgp.clone()),
        report: &report,
        inputs: &["u".to_string()],
        outputs: &["y".to_string()],
    };
    let reloaded = ModelFile::from_fit(&model, &record)
        .expect("file")
        .to_model()
        .expect("model");
    assert_eq!(reloaded.calibration, model.calibration);
    // switched off: no calibration, the same parameters
    let (off, off_report) = fit(
        std::slice::from_ref(&traj),
        &settings(MsgpSettings {
            calibrate: false,
            ..msgp
        }),
        &mut |_| {},
    )
    .expect("fit");
    assert!(off.calibration.is_empty() && off_report.calibration.is_none());
    assert_eq!(off.params, model.params);
}

/// MSGP fit settings for the small single-input plants of these tests: `l_y = 2`, `l_u = 1`.
fn ly2_lu1(threads: Threads, msgp: MsgpSettings) -> FitSettings {
    FitSettings {
        ly: 2,
        lu: 1,
        threads,
        method: msgp.into(),
        ..FitSettings::default()
    }
}

fn long_memory_plant(nonlinear: f64) -> Trajectory {
    let n = 160;
    let u: Vec<f64> = (0..n)
        .map(|i| ((i as f64) * 0.37).sin() + 0.5 * ((i as f64) * 0.05).cos())
        .collect();
    let mut y = vec![0.0; n];
    for t in 2..n {
        y[t] = 1.5 * y[t - 1] - 0.6 * y[t - 2] + 0.3 * u[t - 1] + nonlinear * y[t - 1].tanh();
    }
    Trajectory::siso(&u, &y).expect("finite")
}

/// The default protocol trains both recipes where a validation tail can judge them and keeps
/// the one of lower validation NLL; the two recipes run side by side on two threads with the
/// same result, bit for bit, as one after the other; without a validation tail, or with a mean
/// the user chose, only the settings' own recipe trains.
#[test]
fn the_protocol_keeps_the_recipe_with_the_better_validation_nll() {
    // a linear plant with a long memory: the linear-mean recipe explains it
    let traj = long_memory_plant(0.0);
    let settings = |threads: usize, validation_fraction: f64| FitSettings {
        ly: 2,
        lu: 1,
        threads: Threads::new(threads).expect("threads"),
        method: MsgpSettings {
            inducing: 12,
            iterations: 60,
            validation_fraction,
            ..MsgpSettings::default()
        }
        .into(),
        ..FitSettings::default()
    };
    let (one, r1) = fit(std::slice::from_ref(&traj), &settings(1, 0.2), &mut |_| {}).expect("fit");
    assert_eq!(r1.recipes.len(), 2, "{:?}", r1.recipes);
    assert_eq!(r1.recipes[1].recipe, LINEAR_RECIPE);
    let v: Vec<f64> = r1
        .recipes
        .iter()
        .map(|r| r.validation.expect("validated"))
        .collect();
    let chosen = if v[1] < v[0] { 1 } else { 0 };
    assert_eq!(r1.chosen_recipe, chosen);
    assert_eq!(chosen, 1, "the linear recipe wins on a linear plant: {v:?}");
    assert_eq!(one.config.mean, MeanFunction::Linear);
    // on two threads the final training may start before the second head ends (for the
    // recipe leading then): the same model and the same report either way
    let (two, r2) = fit(std::slice::from_ref(&traj), &settings(2, 0.2), &mut |_| {}).expect("fit");
    assert_eq!(one.params, two.params, "two threads give the same model");
    assert_eq!(r1.chosen_recipe, r2.chosen_recipe);
    assert_eq!(r1.iterations_run, r2.iterations_run);
    assert_eq!(r1.best_iteration, r2.best_iteration);
    assert_eq!(r1.history, r2.history);
    assert_eq!(r1.recipes, r2.recipes);
    assert_eq!(r1.full_data_iteration, r2.full_data_iteration);
    assert!(r1.full_data_iteration.is_some(), "the final training ran");
    assert_eq!(r1.full_data_failed, r2.full_data_failed);
    assert_eq!(r1.numerical_stop, r2.numerical_stop);
    assert_eq!(r1.jitter.events, r2.jitter.events);
    assert!(r1.calibration.is_some(), "the model was calibrated");
    assert_eq!(r1.calibration, r2.calibration);
    assert_eq!(one.calibration, two.calibration);
    // no tail: one recipe, the settings' own
    let (alone, r) = fit(std::slice::from_ref(&traj), &settings(2, 0.0), &mut |_| {}).expect("fit");
    assert!(
        r.recipes.len() == 1 && r.chosen_recipe == 0,
        "{:?}",
        r.recipes
    );
    assert_eq!(alone.config.mean, MeanFunction::Zero);
    // a mean chosen in the options: no alternative
    let chosen = with_mean(
        FitOptions {
            ly: 2,
            lu: 1,
            ..options(Method::Msgp, Some(12), Some(10))
        },
        Some(MeanFunction::Zero),
    )
    .settings(std::slice::from_ref(&traj))
    .expect("settings");
    assert_eq!(chosen.msgp().expect("msgp").alternative, None);
    let auto = with_mean(
        FitOptions {
            ly: 2,
            lu: 1,
            ..options(Method::Msgp, Some(12), Some(10))
        },
        None,
    )
    .settings(std::slice::from_ref(&traj))
    .expect("settings");
    assert_eq!(auto.msgp().expect("msgp").alternative, Some(LINEAR_RECIPE));
    let linear = with_mean(
        FitOptions {
            ly: 2,
            lu: 1,
            ..options(Method::Msgp, Some(12), Some(10))
        },
        Some(MeanFunction::Linear),
    )
    .settings(std::slice::from_ref(&traj))
    .expect("settings");
    let linear = linear.msgp().expect("msgp");
    assert_eq!((linear.recipe(), linear.alternative), (LINEAR_RECIPE, None));
    // the linear-kf start: the linear recipe alone, without being asked for the mean; a zero
    // mean is refused by name
    let from_kalman = with_mean(
        FitOptions {
            ly: 2,
            lu: 1,
            start: Some(MsgpStart::LinearKf),
            ..options(Method::Msgp, Some(12), Some(10))
        },
        None,
    );
    let s = from_kalman
        .settings(std::slice::from_ref(&traj))
        .expect("settings");
    let s = s.msgp().expect("msgp");
    assert_eq!(
        (s.recipe(), s.alternative, s.start),
        (LINEAR_RECIPE, None, MsgpStart::LinearKf)
    );
    let zero = with_mean(from_kalman, Some(MeanFunction::Zero))
        .settings(std::slice::from_ref(&traj))
        .expect_err("a zero mean");
    assert!(zero.to_string().contains("linear-kf start"), "{zero}");
}

/// The progress events of the last final training among `(stage, iteration)` events: on two
/// threads a final training started for the recipe leading at the time restarts at iteration 0
/// if the other recipe overtakes it.
fn last_final_run(stages: &[(u8, usize)]) -> usize {
    let start = stages
        .iter()
        .rposition(|&event| event == (2, 0))
        .expect("a final training");
    stages[start..].iter().filter(|&&(s, _)| s == 2).count()
}

/// After the validation tail has chosen the recipe, the chosen recipe trains again from its
/// start on all the training data: the model returned is bit for bit the one a fit of that
/// recipe alone, without a tail, for the final stage's iterations gives, and not the head's.
#[test]
fn the_chosen_recipe_trains_again_on_all_the_data() {
    const FINAL: usize = 80;
    let traj = long_memory_plant(0.1);
    let msgp = |validation_fraction: f64, full: Option<usize>| MsgpSettings {
        inducing: 12,
        iterations: FINAL,
        validation_fraction,
        full_data_iterations: full,
        ..MsgpSettings::default()
    };
    let settings = |m: MsgpSettings| ly2_lu1(Threads::default(), m);
    let mut stages = Vec::new();
    let (model, report) = fit(
        std::slice::from_ref(&traj),
        &settings(msgp(0.2, Some(FINAL))),
        &mut |p| stages.push((p.stage, p.iteration)),
    )
    .expect("fit");
    assert!(report.full_data_failed.is_none(), "{report:?}");
    let last = report.full_data_iteration.expect("the final stage ran");
    assert!(last <= FINAL, "{last}");
    assert_eq!(
        last_final_run(&stages),
        FINAL + 1,
        "the final stage runs its iterations on the observed thread"
    );
    // the same recipe alone, on all the data, without a tail
    let chosen = report.recipes[report.chosen_recipe].recipe;
    let alone = MsgpSettings {
        iterations: FINAL,
        alternative: None,
        ..msgp(0.0, None).with_recipe(chosen)
    };
    let (reference, r) =
        fit(std::slice::from_ref(&traj), &settings(alone), &mut |_| {}).expect("fit alone");
    assert_eq!(model.params, reference.params);
    assert_eq!(model.config, reference.config);
    assert_eq!(r.best_iteration, last);
    // without the stage: the head's model, another one
    let (head, r) = fit(
        std::slice::from_ref(&traj),
        &settings(msgp(0.2, None)),
        &mut |_| {},
    )
    .expect("fit without the final stage");
    assert!(r.full_data_iteration.is_none());
    assert_eq!(r.chosen_recipe, report.chosen_recipe);
    assert_ne!(head.params, model.params);
    // the final stage takes at most the settings' iterations (the linear recipe's first Adam
    // step throws its loss up by ≈ 20 nats per step, which is not a blow-up)
    let mut stages = Vec::new();
    let few = settings(MsgpSettings {
        iterations: 10,
        ..msgp(0.2, Some(FINAL))
    });
    let (_, r) = fit(std::slice::from_ref(&traj), &few, &mut |p| {
        stages.push((p.stage, p.iteration))
    })
    .expect("fit with few iterations");
    assert_eq!(last_final_run(&stages), 11);
    assert!(r.full_data_failed.is_none(), "{:?}", r.full_data_failed);
    assert!(r.full_data_iteration.expect("ran") <= 10);
    // L-BFGS fits have no final stage: the early-stopped head's model is theirs
    let (_, r) = fit(
        std::slice::from_ref(&traj),
        &settings(MsgpSettings {
            iterations: 10,
            optimizer: FitOptimizer::Lbfgs,
            ..msgp(0.2, Some(FINAL))
        }),
        &mut |_| {},
    )
    .expect("L-BFGS fit");
    assert_eq!((r.full_data_iteration, r.full_data_failed), (None, None));
}

/// The final training is the chosen recipe trained alone on all the data for its whole
/// length, bit for bit, its proxy's iterate judging the calibration.
#[test]
fn the_final_training_is_the_recipe_trained_alone_on_all_the_data() {
    const FINAL: usize = 200;
    let traj = long_memory_plant(0.1);
    let msgp = MsgpSettings {
        inducing: 12,
        iterations: FINAL,
        validation_fraction: 0.2,
        full_data_iterations: Some(FINAL),
        ..MsgpSettings::default()
    };
    let settings = |m: MsgpSettings| ly2_lu1(Threads::default(), m);
    let (model, r) = fit(
        std::slice::from_ref(&traj),
        &settings(msgp.clone()),
        &mut |_| {},
    )
    .expect("fit");
    let recipe = r.recipes[r.chosen_recipe].recipe;
    let alone = MsgpSettings {
        iterations: FINAL,
        validation_fraction: 0.0,
        full_data_iterations: None,
        alternative: None,
        ..msgp.with_recipe(recipe)
    };
    let (whole, _) =
        fit(std::slice::from_ref(&traj), &settings(alone), &mut |_| {}).expect("fit alone");
    assert!(r.full_data_iteration.is_some_and(|k| k <= FINAL), "{r:?}");
    assert_eq!(model.params, whole.params);
    match r.calibration.as_ref().map(|c| c.judge) {
        Some(calibration::Judge::Proxy { iteration }) => assert!(iteration <= FINAL),
        other => panic!("the proxy judges the calibration: {other:?}"),
    }
}

/// A small MSGP model (8 pseudo-inputs, 20 iterations, history (2, 1)) of `first_order(0.3)`
/// on `likelihood`, for the tests of its scores in original units.
fn small_model(likelihood: Likelihood) -> Model {
    let settings = FitSettings {
        ly: 2,
        lu: 1,
        method: MsgpSettings {
            inducing: 8,
            iterations: 20,
            validation_fraction: 0.0,
            likelihood,
            ..MsgpSettings::default()
        }
        .into(),
        ..FitSettings::default()
    };
    let train = first_order(0.3);
    fit(std::slice::from_ref(&train), &settings, &mut |_| {})
        .expect("fit")
        .0
}

/// `Σ_t −log N(y_t; μ_t, σ²_t)` of one output's predictions `p` of `traj`, summed by hand,
/// and the number of steps.
fn gaussian_nll_by_hand(traj: &Trajectory, p: &crate::model::Simulation) -> (f64, usize) {
    let n = p.mean.nrows();
    let sum = (0..n)
        .map(|i| {
            let (r, v) = (traj.y[(p.start + i, 0)] - p.mean[(i, 0)], p.var[(i, 0)]);
            0.5 * ((2.0 * std::f64::consts::PI * v).ln() + r * r / v)
        })
        .sum();
    (sum, n)
}

/// `model` and `traj` with the output in other units (× 1024, offset by 5): a score in
/// original units moves by the Jacobian `steps · ln 1024` and nothing else.
fn in_other_units(model: &Model, traj: &Trajectory) -> (Model, Trajectory) {
    let mut scaled = model.clone();
    scaled.normalizer.y_std[0] *= 1024.0;
    scaled.normalizer.y_mean[0] = scaled.normalizer.y_mean[0] * 1024.0 + 5.0;
    let y = traj.y.map(|v| v * 1024.0 + 5.0);
    (scaled, Trajectory::new(traj.u.clone(), y).expect("finite"))
}

fn close(a: f64, b: f64, tol: f64) -> bool {
    (a - b).abs() <= tol * b.abs().max(1.0)
}

/// `Model::filter_nll` in original units: for one output the joint density factors into the
/// one-step predictive densities that `Model::filtered` returns (summed here by hand), and the
/// same model and data in other units score the same up to the Jacobian, so models with
/// different normalisers compare on one scale.
#[test]
fn the_filter_nll_in_original_units_sums_the_filtered_predictive_densities() {
    let model = small_model(Likelihood::Filter);
    let test = first_order(0.25);
    let (nll, steps) = model.filter_nll(&test).expect("filter");
    let (by_hand, n) = gaussian_nll_by_hand(&test, &model.filtered(&test).expect("filtered"));
    assert_eq!(steps, n);
    assert!(close(nll, by_hand, 1e-10), "{nll} against {by_hand}");
    let (scaled, other_units) = in_other_units(&model, &test);
    let (nll_other, _) = scaled.filter_nll(&other_units).expect("filter");
    let expected = nll + steps as f64 * 1024f64.ln();
    // the offset's rounding (1e-16) passes through a filter with a near-singular window
    // covariance; a wrong Jacobian would be off by `steps · ln 1024` ≈ 530
    assert!(
        close(nll_other, expected, 1e-6),
        "{nll_other} against {expected}"
    );
}

/// `Model::rollout_nll` in original units: on measured inputs it sums the Gaussian densities
/// of the paper's moment-matching simulation (`Rollout::MomentMatchingIndependent`, the
/// rollout the loss trains on); in closed loop under a constant policy `u = b` (given in
/// original units) it scores the same as on a trajectory whose later inputs are `b`; outputs
/// in other units score the same up to the Jacobian.
#[test]
fn the_rollout_nll_in_original_units_sums_the_simulations_densities() {
    let model = small_model(Likelihood::FreeRun);
    let by_hand = |t: &Trajectory| {
        let p = model.simulate_as(t, Rollout::MomentMatchingIndependent);
        gaussian_nll_by_hand(t, &p.expect("simulates"))
    };
    let test = first_order(0.3);
    let (nll, steps) = model.rollout_nll(&test, None).expect("rolls out");
    let (expected, n) = by_hand(&test);
    assert_eq!(steps, n);
    assert!(close(nll, expected, 1e-10), "{nll} against {expected}");

    // u = 0.4 in closed loop against the same inputs given; the first window keeps its
    // measured inputs, the policy chooses every later one
    let b = 0.4;
    let offset = nalgebra::DVector::from_element(1, b);
    let constant =
        PolicySpec::Linear(LinearPolicy::new(DMatrix::zeros(1, 1), offset).expect("shapes"));
    let mut held = test.clone();
    let w = model.spec.warmup();
    held.u.rows_mut(w, test.len() - w).fill(b);
    let (closed, _) = model.rollout_nll(&test, Some(&constant)).expect("closed");
    let (given, _) = by_hand(&held);
    assert!(close(closed, given, 1e-10), "{closed} against {given}");
    assert!((closed - nll).abs() > 1.0, "the policy's inputs matter");

    let (scaled, other_units) = in_other_units(&model, &test);
    let (nll_other, _) = scaled.rollout_nll(&other_units, None).expect("rolls out");
    let expected = nll + steps as f64 * 1024f64.ln();
    assert!(
        close(nll_other, expected, 1e-6),
        "{nll_other} against {expected}"
    );
}

/// The spread start ([`MsgpStart::Spread`]) is the one-step fit's own starting point: the
/// one-step start without one-step iterations, not the default one-step start. Where the
/// zero-mean recipe's final training completes, no spread head trains.
#[test]
fn the_spread_start_is_the_one_step_fits_starting_point() {
    let traj = long_memory_plant(0.4);
    let base = MsgpSettings {
        inducing: 12,
        iterations: 60,
        full_data_iterations: Some(40),
        alternative: None,
        ..MsgpSettings::default()
    };
    let settings = |msgp: MsgpSettings| ly2_lu1(Threads::new(1).expect("threads"), msgp);
    // no tail and no training return the start
    let start = |start: MsgpStart, one_step_iterations: usize| {
        let s = settings(MsgpSettings {
            start,
            one_step_iterations,
            iterations: 0,
            validation_fraction: 0.0,
            ..base.clone()
        });
        fit(std::slice::from_ref(&traj), &s, &mut |_| {})
            .expect("start")
            .0
            .params
    };
    let spread = start(MsgpStart::Spread, DEFAULT_ONE_STEP_ITERATIONS);
    assert_eq!(spread, start(MsgpStart::OneStep, 0));
    let one_step = start(MsgpStart::OneStep, DEFAULT_ONE_STEP_ITERATIONS);
    assert!(
        (&spread.log_lengthscales - &one_step.log_lengthscales).amax() > 0.1,
        "the one-step fit moved the length-scales: {} against {}",
        spread.log_lengthscales,
        one_step.log_lengthscales
    );
    let (_, r) = fit(std::slice::from_ref(&traj), &settings(base), &mut |_| {}).expect("fit");
    assert!(r.full_data_iteration.is_some(), "{:?}", r.full_data_failed);
    assert_eq!(r.recipes.len(), 1, "{:?}", r.recipes);
}

/// `FitReport::fallback` names the returned model's head only where it is a fallback head:
/// another head's final training failed and this one's completed.
#[test]
fn the_report_names_a_kept_fallback_head() {
    let outcome = |mean, start, final_failed: Option<&str>, fallback_head| RecipeOutcome {
        recipe: Recipe {
            mean,
            ..MsgpSettings::default().recipe()
        },
        start,
        final_failed: final_failed.map(String::from),
        diverged: None,
        fallback_head,
        validation: Some(0.5),
        failed: None,
    };
    let mut report = FitReport {
        recipes: vec![
            outcome(
                MeanFunction::Zero,
                MsgpStart::OneStep,
                Some("blew up"),
                false,
            ),
            outcome(MeanFunction::Linear, MsgpStart::OneStep, None, false),
            outcome(MeanFunction::Zero, MsgpStart::Spread, None, true),
            outcome(MeanFunction::Linear, MsgpStart::OneStep, None, true),
        ],
        chosen_recipe: 3,
        full_data_iteration: Some(400),
        ..FitReport::default()
    };
    let label = |r: &FitReport| r.fallback().map(RecipeOutcome::fallback_label);
    assert_eq!(label(&report), Some("linear"));
    report.chosen_recipe = 2;
    assert_eq!(label(&report), Some("spread"));
    // the head's model stands: no final training completed
    report.full_data_iteration = None;
    assert_eq!(label(&report), None);
    // a racing recipe's model, returned after another's final training failed (the first
    // set aside for diverging, the next one's final training blew up): no fallback head
    report.full_data_iteration = Some(400);
    report.chosen_recipe = 1;
    assert_eq!(label(&report), None);
    report.chosen_recipe = 0;
    assert_eq!(label(&report), None);
}

/// Where the chosen zero-mean recipe's final training blows up (forced here by a negative
/// limit, [`MsgpSettings::full_data_blow_up`]), the same recipe trains its two fallback heads
/// (from the spread start; with a linear mean at its own step and complexity) and tries their
/// final trainings; when those blow up too, the one-step head's model stands and the
/// calibration judges the head's own training. The two recipes race on two threads first (the
/// first thread starting the winner's final training early): one and two threads give the same
/// model and report; `blow_up_fallback: false` trains no fallback head. (A fallback head's final
/// training completing, and their order, is `tests/benchmarks.rs`' ballbeam.)
#[test]
fn a_blown_up_final_training_tries_the_fallback_heads() {
    // a saturating plant on which the zero-mean recipe beats the linear one on the tail
    let n = 160;
    let u: Vec<f64> = (0..n)
        .map(|i| ((i as f64) * 0.37).sin() + 0.5 * ((i as f64) * 0.05).cos())
        .collect();
    let mut y = vec![0.0f64; n];
    for t in 1..n {
        y[t] = 0.9 * (2.0 * y[t - 1]).sin() + (2.0 * u[t - 1]).tanh();
    }
    let traj = Trajectory::siso(&u, &y).expect("finite");
    let settings = |threads: usize, blow_up_fallback: bool| {
        ly2_lu1(
            Threads::new(threads).expect("threads"),
            MsgpSettings {
                inducing: 12,
                iterations: 60,
                full_data_iterations: Some(40),
                full_data_blow_up: -1.0,
                blow_up_fallback,
                ..MsgpSettings::default()
            },
        )
    };
    let (one, r1) = fit(std::slice::from_ref(&traj), &settings(1, true), &mut |_| {}).expect("fit");
    let starts: Vec<(MeanFunction, MsgpStart, bool, bool)> = r1
        .recipes
        .iter()
        .map(|r| {
            let failed = r.final_failed.is_some();
            (r.recipe.mean, r.start, failed, r.fallback_head)
        })
        .collect();
    assert_eq!(
        starts,
        [
            (MeanFunction::Zero, MsgpStart::OneStep, true, false),
            (MeanFunction::Linear, MsgpStart::OneStep, false, false),
            (MeanFunction::Zero, MsgpStart::Spread, true, true),
            (MeanFunction::Linear, MsgpStart::OneStep, true, true)
        ]
    );
    // the linear fallback is the zero-mean recipe with a linear mean, not the racing linear one
    let own = MsgpSettings::default().recipe();
    assert_eq!(
        r1.recipes[3].recipe,
        Recipe {
            mean: MeanFunction::Linear,
            ..own
        }
    );
    assert_ne!(r1.recipes[3].recipe, r1.recipes[1].recipe);
    assert!(
        r1.recipes.iter().all(|r| r.validation.is_some()),
        "{:?}",
        r1.recipes
    );
    assert_eq!(r1.chosen_recipe, 0);
    assert!(r1.fallback().is_none(), "no fallback head completed");
    assert_eq!(r1.full_data_iteration, None);
    assert!(r1.full_data_failed.is_some());
    assert!(matches!(
        r1.calibration.as_ref().map(|c| c.judge),
        Some(calibration::Judge::HeadProxy { .. })
    ));
    let (two, r2) = fit(std::slice::from_ref(&traj), &settings(2, true), &mut |_| {}).expect("fit");
    assert_eq!(one.params, two.params, "two threads give the same model");
    assert_eq!(one.calibration, two.calibration);
    assert_eq!(r1.recipes, r2.recipes);
    assert_eq!(r1.iterations_run, r2.iterations_run);
    assert_eq!(r1.best_iteration, r2.best_iteration);
    assert_eq!(r1.history, r2.history);
    assert_eq!(r1.full_data_failed, r2.full_data_failed);
    assert_eq!(r1.calibration, r2.calibration);
    // without the fallback: the same model, no fallback head
    let (alone, r) = fit(
        std::slice::from_ref(&traj),
        &settings(2, false),
        &mut |_| {},
    )
    .expect("fit");
    assert_eq!(r.recipes.len(), 2, "{:?}", r.recipes);
    assert_eq!(alone.params, one.params);
}

/// The fit of `traj` with `judge` deciding which models the protocol's choice counts as
/// diverging (in place of [`check_divergence`]).
fn fit_judged(
    traj: &Trajectory,
    settings: &FitSettings,
    judge: &dyn Fn(&Model) -> Option<String>,
) -> (Model, FitReport) {
    let episodes = [TrainingEpisode {
        traj: traj.clone(),
        policy: None,
    }];
    let mut go_on = |_: &FitProgress| ControlFlow::Continue(());
    fit_unchecked(&episodes, settings, None, &mut go_on, Some(judge)).expect("fit")
}

/// A judge by the model's prior mean: `mean`'s models diverge.
fn diverging(mean: MeanFunction) -> impl Fn(&Model) -> Option<String> {
    move |m: &Model| (m.config.mean == mean).then(|| "it runs away".to_string())
}

/// Where the recipe the validation tail chose ends in a model that diverges over the training
/// inputs, the other racing recipe's final training runs and its model is returned (bit for bit
/// that recipe's fit alone on all the data), with the first set aside and why; where every
/// model diverges, the tail's choice stands as without the check; without a final training
/// (L-BFGS), the other head's model is returned.
#[test]
fn a_model_that_diverges_gives_way_to_the_next_recipe() {
    const FINAL: usize = 60;
    let traj = long_memory_plant(0.1);
    let msgp = |optimizer: FitOptimizer| MsgpSettings {
        inducing: 12,
        iterations: FINAL,
        validation_fraction: 0.2,
        full_data_iterations: Some(FINAL),
        optimizer,
        ..MsgpSettings::default()
    };
    let settings = |m: MsgpSettings| ly2_lu1(Threads::default(), m);
    let adam = settings(msgp(FitOptimizer::Adam));
    let (first, r0) = fit(std::slice::from_ref(&traj), &adam, &mut |_| {}).expect("fit");
    assert_eq!(r0.recipes.len(), 2, "{:?}", r0.recipes);
    assert!(r0.set_aside().is_none());
    let preferred = r0.chosen_recipe;
    let other = 1 - preferred;
    let preferred_mean = r0.recipes[preferred].recipe.mean;

    let (model, r) = fit_judged(&traj, &adam, &diverging(preferred_mean));
    assert_eq!(r.chosen_recipe, other, "{:?}", r.recipes);
    let aside = r.set_aside().expect("the preferred recipe was set aside");
    assert_eq!(aside.recipe, r0.recipes[preferred].recipe);
    assert_eq!(aside.diverged.as_deref(), Some("it runs away"));
    assert_eq!(r.recipes[other].diverged, None);
    assert!(r.full_data_iteration.is_some(), "{r:?}");
    assert_ne!(model.config.mean, preferred_mean);
    assert!(r.calibration.is_some(), "the kept model is calibrated");
    assert_eq!(
        r.recipes[preferred].validation,
        r0.recipes[preferred].validation
    );
    // the other recipe alone, on all the data, without a tail
    let alone = MsgpSettings {
        validation_fraction: 0.0,
        full_data_iterations: None,
        alternative: None,
        ..msgp(FitOptimizer::Adam).with_recipe(r.recipes[other].recipe)
    };
    let (reference, _) =
        fit(std::slice::from_ref(&traj), &settings(alone), &mut |_| {}).expect("fit alone");
    assert_eq!(model.params, reference.params);

    // every model diverges: the tail's choice, as without the check
    let (same, r) = fit_judged(&traj, &adam, &|_| Some("always".into()));
    assert_eq!(same.params, first.params);
    assert_eq!(same.calibration, first.calibration);
    assert_eq!(r.chosen_recipe, preferred);
    assert!(r.set_aside().is_none());
    assert!(r.recipes.iter().all(|o| o.diverged.is_none()), "{r:?}");

    // no final training: the other head
    let lbfgs = settings(msgp(FitOptimizer::Lbfgs));
    let (_, h0) = fit(std::slice::from_ref(&traj), &lbfgs, &mut |_| {}).expect("fit");
    let head_mean = h0.recipes[h0.chosen_recipe].recipe.mean;
    let (head, h) = fit_judged(&traj, &lbfgs, &diverging(head_mean));
    assert_eq!(h.full_data_iteration, None);
    assert_eq!(h.chosen_recipe, 1 - h0.chosen_recipe);
    assert_ne!(head.config.mean, head_mean);
    assert_eq!(
        h.set_aside().map(|o| o.recipe),
        Some(h0.recipes[h0.chosen_recipe].recipe)
    );
}

/// `Model::sample_free_runs`: the same seed gives the same paths, another seed others; the
/// paths are in original units (their first step is the moment-matching simulation's, in a
/// plant's units far from the normalised ones); a linear-kf model is refused.
#[test]
fn sampled_free_runs_are_seeded_and_in_original_units() {
    let plant = long_memory_plant(0.1);
    let y = plant.y.map(|v| 50.0 + 20.0 * v);
    let traj = Trajectory::new(plant.u.clone(), y).expect("finite");
    let settings = ly2_lu1(
        Threads::default(),
        MsgpSettings {
            inducing: 12,
            iterations: 30,
            validation_fraction: 0.0,
            ..MsgpSettings::default()
        },
    );
    let (model, _) = fit(std::slice::from_ref(&traj), &settings, &mut |_| {}).expect("fit");
    const PATHS: usize = 400;
    let a = model.sample_free_runs(&traj, PATHS, 5).expect("paths");
    assert_eq!(a, model.sample_free_runs(&traj, PATHS, 5).expect("again"));
    assert_ne!(
        a,
        model
            .sample_free_runs(&traj, PATHS, 6)
            .expect("another seed")
    );
    let sim = model.simulate(&traj).expect("simulate");
    assert_eq!(a[0].nrows(), sim.mean.nrows());
    // the first step, from the measured window, is moment matching's distribution (later
    // ones drift apart on this briefly trained model: whole functions are not its Gaussian)
    let first = a.iter().map(|p| p[(0, 0)]).sum::<f64>() / PATHS as f64;
    let sd = sim.var[(0, 0)].sqrt();
    assert!(
        (first - sim.mean[(0, 0)]).abs() < 0.1 * sd + 4.0 * sd / (PATHS as f64).sqrt(),
        "the paths' first step {first}, the simulation's {} ± {sd}",
        sim.mean[(0, 0)]
    );
    let kf = FitSettings {
        method: MethodSettings::LinearKf(LinearKfSettings::default()),
        ..settings
    };
    let (linear, _) = fit(std::slice::from_ref(&traj), &kf, &mut |_| {}).expect("linear-kf");
    let refused = linear.sample_free_runs(&traj, 10, 0).expect_err("refused");
    assert!(refused.to_string().contains("linear-kf"), "{refused}");
}

/// A history long for the data is named before the fit starts: more GP inputs than training
/// windows (the dryer's 500 samples with `--history 400,400`), or more than
/// [`MANY_GP_INPUTS`] inputs; the paper's histories and linear-kf get no warning.
#[test]
fn a_long_history_is_warned_about_before_the_fit() {
    let data = [traj(500)];
    let with = |ly, lu, method| {
        FitOptions {
            ly,
            lu,
            ..options(method, None, None)
        }
        .history_warning(&data)
    };
    let many = with(400, 400, Method::Msgp).expect("a warning");
    assert!(
        many.starts_with(
            "the history l_y=400, l_u=400 makes 800 GP inputs but the training part has only \
             100 windows"
        ),
        "{many}"
    );
    let slow = with(40, 40, Method::GpNarx).expect("a warning");
    assert!(
        slow.starts_with("the history l_y=40, l_u=40 makes 80 GP inputs (more than 64)"),
        "{slow}"
    );
    assert_eq!(with(32, 32, Method::Msgp), None, "64 inputs: no warning");
    assert_eq!(with(10, 10, Method::Msgp), None);
    assert_eq!(with(400, 400, Method::LinearKf), None);
    assert_eq!(
        with(600, 600, Method::Msgp),
        None,
        "no windows: the fit's error says it"
    );
}

/// A fit by segments whose one segment is the whole trajectory is the whole fit bit for bit;
/// shorter segments make another fit and say so in the report; the default trains by
/// segments exactly when the training part has more than `LONG_LOG_WINDOWS` windows, and
/// `segment_length: Some(0)` never does.
#[test]
fn segments_fit_long_logs_and_one_segment_is_the_whole_fit() {
    let train = vec![traj(80)];
    let fit_with = |segment_length: Option<usize>| {
        let options = FitOptions {
            segment_length,
            ..options(Method::Msgp, Some(12), Some(10))
        };
        fit(
            &train,
            &options.settings(&train).expect("settings"),
            &mut |_| {},
        )
        .expect("fit")
    };
    let (whole, whole_report) = fit_with(Some(0));
    let (one, one_report) = fit_with(Some(200));
    assert_eq!(whole.params, one.params);
    assert_eq!(whole_report.segments, None);
    assert_eq!(one_report.segments.map(|(_, k)| k), Some(1));
    let (cut, cut_report) = fit_with(Some(20));
    assert_eq!(cut_report.segments.map(|(_, k)| k), Some(4));
    assert_ne!(cut.params, whole.params);
    let defaults = FitOptions::new(Method::Msgp, 2, 2);
    let long = |windows: usize| vec![traj(windows + 2)];
    assert_eq!(defaults.segments(&long(LONG_LOG_WINDOWS)), None);
    assert_eq!(
        defaults.segments(&long(LONG_LOG_WINDOWS + 1)),
        Some(Segments::DEFAULT)
    );
    let off = FitOptions {
        segment_length: Some(0),
        ..defaults
    };
    assert_eq!(off.segments(&long(LONG_LOG_WINDOWS + 1)), None);
}
