//! Where an iteration of the filtered MSGP loop (with the prequential choice) spends its time:
//! on the state of the loop's `k+1`-th iteration (four random-excitation episodes and `k`
//! feedback episodes of the hand-tuned gains, 3 s each, whole), the previous GP and linear
//! models fitted on all but the last episode, it times the GP model's warm fit (the loop's 100
//! L-BFGS iterations, and 40), the linear competitor's warm fit (linear-kf's 300), each with the
//! iterations it ran, and the policy search on each model. A diagnostic for BENCHMARKS.md.
//!
//! `cargo run --release -p msgp-diagnostics --bin choice_timing -- [apollo|noisy] [k]`
//! (defaults: noisy, 4)
use std::ops::ControlFlow;
use std::time::Instant;

use msgp_core::fit::{FitSettings, TrainingEpisode, fit_episodes_observed};
use msgp_core::model::{Method, Model};
use msgp_core::policy::PolicySpec;
use msgp_core::policy_search::PolicySearchSettings;
use msgp_diagnostics::{Switches, usage_error};
use msgp_sim::learn::{LearnSettings, ModelChoice, episode_trajectory, modelled_policy};
use msgp_sim::{
    EpisodeConfig, PendulumParams, PidPdGains, PidPdPolicy, PlantTier, RandomExcitation,
    Saturation, run_episode,
};

const USAGE: &str = "choice_timing [apollo|noisy] [k]";

fn data(
    params: &PendulumParams,
    settings: &LearnSettings,
    k: u64,
) -> Result<Vec<TrainingEpisode>, Box<dyn std::error::Error>> {
    let mut out = Vec::new();
    let config = |seed| EpisodeConfig {
        seconds: settings.episode_seconds,
        seed,
        initial_theta: None,
    };
    for seed in 0..4u64 {
        let mut ex = RandomExcitation::new(seed, &settings.excitation)?;
        let ep = run_episode(params, &mut ex, &config(seed))?;
        out.push(TrainingEpisode {
            traj: episode_trajectory(&ep)?,
            policy: None,
        });
    }
    let mut gains = PidPdGains::hand_tuned();
    gains.saturation = Saturation::Sine;
    for seed in 500..500 + k {
        let mut controller = PidPdPolicy::new(gains, params)?;
        let ep = run_episode(params, &mut controller, &config(seed))?;
        out.push(TrainingEpisode {
            traj: episode_trajectory(&ep)?,
            policy: Some(PolicySpec::Direct(msgp_core::policy::Policy::Pid(
                modelled_policy(&gains, params)?,
            ))),
        });
    }
    Ok(out)
}

fn timed_fit(
    what: &str,
    training: &[TrainingEpisode],
    settings: &FitSettings,
    previous: Option<&Model>,
) -> Result<Model, Box<dyn std::error::Error>> {
    let clock = Instant::now();
    let (model, report) = fit_episodes_observed(training, settings, previous, &mut |_| {
        ControlFlow::Continue(())
    })?;
    println!(
        "{what}: {:.2} s, {} solver iterations",
        clock.elapsed().as_secs_f64(),
        report.iterations_run
    );
    Ok(model)
}

fn main() -> Result<(), Box<dyn std::error::Error>> {
    let sw = Switches::from_args(2, &[]).unwrap_or_else(|e| usage_error(USAGE, &e));
    let tier = match sw.positional().first().map(String::as_str) {
        None | Some("noisy") => PlantTier::Noisy,
        Some("apollo") => PlantTier::Apollo,
        Some(other) => usage_error(USAGE, &format!("unknown tier {other:?}")),
    };
    let k: u64 = sw
        .arg(1, "k")
        .unwrap_or_else(|e| usage_error(USAGE, &e))
        .unwrap_or(4);
    let params = PendulumParams::tier(tier);
    let settings = LearnSettings::for_model(Method::Msgp, None);
    let training = data(&params, &settings, k)?;
    let n = training.len();
    let gp_cold = timed_fit(
        "GP cold fit on all but the last episode",
        &training[..n - 1],
        &settings.fit,
        None,
    )?;
    let mut choice = ModelChoice::new(&msgp_sim::learn::learner_settings(&params, &settings)?)?;
    let linear_cold = choice.fit(&training[..n - 1], 1)?;
    for warm in [100, 40] {
        timed_fit(
            &format!("GP warm fit, {warm} iterations"),
            &training,
            &settings.fit.clone().with_solver_iterations(warm),
            Some(&gp_cold),
        )?;
    }
    let linear_settings = LearnSettings::for_model(Method::LinearKf, None);
    let linear = timed_fit(
        "linear warm fit (linear-kf's warm start)",
        &training,
        &FitSettings {
            ly: settings.fit.ly,
            lu: settings.fit.lu,
            ..linear_settings.fit.clone()
        }
        .with_solver_iterations(linear_settings.warm_start.unwrap_or(300)),
        Some(&linear_cold),
    )?;
    let gp = gp_cold;
    let (cost, horizon) = (
        msgp_core::policy_search::cost::SaturatingCost::with_widths(
            nalgebra::DVector::from_element(2, 0.0),
            &settings.cost_widths,
        )?,
        (settings.policy_horizon_seconds * params.control_rate_hz).round() as usize,
    );
    let mut gains = PidPdGains::hand_tuned();
    gains.saturation = Saturation::Sine;
    for (what, model) in [("GP", &gp), ("linear", &linear)] {
        let problem = msgp_sim::learn::pendulum_problem(model, &params, cost.clone(), horizon);
        let policy = modelled_policy(&gains, &params)?;
        let mask = msgp_core::policy_search::PidMask {
            kp: nalgebra::DMatrix::from_element(1, 2, true),
            ki: nalgebra::DMatrix::from_row_slice(1, 2, &[false, true]),
            kd: nalgebra::DMatrix::from_element(1, 2, true),
        };
        let typical: Vec<f64> = mask.pack(&policy).into_iter().map(f64::abs).collect();
        let search = PolicySearchSettings {
            seed: 4,
            ..settings.search
        };
        let clock = Instant::now();
        msgp_core::policy_search::optimise_pid_scaled(&problem, &policy, &mask, &typical, &search)?;
        println!(
            "search on the {what} model: {:.2} s",
            clock.elapsed().as_secs_f64()
        );
    }
    Ok(())
}
