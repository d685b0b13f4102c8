//! What msgp-sim writes, msgp-core reads back exactly, and a model fitted on one episode's log
//! predicts another excitation of the same plant.

use std::path::PathBuf;

use msgp_core::data::Trajectory;
use msgp_core::data::dataset::{Dataset, Selection};
use msgp_core::data::table::TimeSource;
use msgp_core::fit::{FitOptimizer, FitOptions, Overrides, fit};
use msgp_core::model::Method;
use msgp_core::numeric::parallel::Threads;
use msgp_sim::learn::episode_trajectory;
use msgp_sim::{
    Episode, EpisodeConfig, ExcitationConfig, PendulumParams, PlantTier, RandomExcitation,
    run_episode, write_run,
};

/// A hanging pole (gravity reversed: stable) under seeded smooth random excitation, with the
/// pole free to swing and the end effector to drift (no early stop), so that an open-loop episode
/// runs its full length.
fn episode(seed: u64, seconds: f64) -> Episode {
    let params = PendulumParams {
        gravity: -9.81,
        stop_theta: 3.0,
        stop_x: 1e3,
        ..PendulumParams::tier(PlantTier::Noisy)
    };
    // small swings: the pole stays near its linear regime
    let small = ExcitationConfig {
        rms: 0.3,
        ..ExcitationConfig::default()
    };
    let mut excitation = RandomExcitation::new(seed, &small).expect("excitation");
    let config = EpisodeConfig {
        seconds,
        seed,
        initial_theta: Some(0.0),
    };
    run_episode(&params, &mut excitation, &config).expect("episode")
}

fn scratch(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("msgp-tests-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("scratch folder");
    dir
}

fn defaults() -> Selection<'static> {
    Selection {
        inputs: &[],
        outputs: &[],
        topic: None,
        time: TimeSource::Log,
        sort_time: false,
    }
}

#[test]
fn simulator_logs_load_as_the_episode_in_csv_and_mcap() {
    let ep = episode(3, 4.0);
    let expected = episode_trajectory(&ep).expect("trajectory");
    assert_eq!(expected.len(), 201, "4 s at 50 Hz, both ends");
    let dir = scratch("logs");
    for (ext, inputs, outputs) in [
        ("csv", vec!["command"], vec!["meas_theta", "meas_x"]),
        (
            "mcap",
            vec!["/pendulum/command:acceleration"],
            vec!["/pendulum/measurement:theta", "/pendulum/measurement:x"],
        ),
    ] {
        let path = dir.join(format!("run.{ext}"));
        write_run(&path, &ep).expect("write log");
        let data = Dataset::load(std::slice::from_ref(&path), &defaults()).expect("load log");
        assert_eq!(data.inputs, inputs, "{ext}: default input");
        assert_eq!(data.outputs, outputs, "{ext}: default outputs");
        assert_eq!(data.parts.len(), 1, "{ext}: one trajectory");
        let part = &data.parts[0];
        assert_eq!(part.traj, expected, "{ext}: every value read back exactly");
        assert_eq!(part.times.len(), expected.len());
        assert!(
            part.times
                .windows(2)
                .all(|w| (w[1] - w[0] - 0.02).abs() < 1e-9),
            "{ext}: 50 Hz time stamps"
        );
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// RMSE of always predicting `mean` (the training outputs' mean) over `traj`'s outputs.
fn mean_predictor_rmse(traj: &Trajectory, mean: &[f64], from: usize) -> f64 {
    let (n, dy) = (traj.len() - from, traj.y.ncols());
    let se: f64 = (from..traj.len())
        .flat_map(|t| (0..dy).map(move |j| (t, j)))
        .map(|(t, j)| (traj.y[(t, j)] - mean[j]).powi(2))
        .sum();
    (se / (n * dy) as f64).sqrt()
}

/// The pole's angle answers the command like a lightly damped oscillator, whatever the end
/// effector's drift (a double integral of the command): modelled alone, from the command, by
/// the linear window model fitted on the filter likelihood (a one-step GP-NARX fit of the same
/// log free-simulates it at 0.6× the training mean's RMSE: its phase drifts over 8 s).
#[test]
fn a_model_fitted_on_a_simulator_log_predicts_another_excitation() {
    let dir = scratch("model");
    let path = dir.join("train.mcap");
    write_run(&path, &episode(3, 8.0)).expect("write log");
    let (inputs, outputs) = (
        ["/pendulum/command:acceleration".to_string()],
        ["/pendulum/measurement:theta".to_string()],
    );
    let angle = Selection {
        inputs: &inputs,
        outputs: &outputs,
        topic: None,
        time: TimeSource::Log,
        sort_time: false,
    };
    let data = Dataset::load(std::slice::from_ref(&path), &angle).expect("load log");
    let train: Vec<Trajectory> = data.parts.iter().map(|p| p.traj.clone()).collect();
    let settings = FitOptions {
        method: Method::LinearKf,
        ly: 3,
        lu: 3,
        seed: 0,
        integrators: Vec::new(),
        optimizer: FitOptimizer::Adam,
        start: Default::default(),
        threads: Threads::available(),
        segment_length: None,
        overrides: Overrides {
            iterations: Some(100),
            ..Overrides::default()
        },
    }
    .settings(&train)
    .expect("settings");
    let (model, _) = fit(&train, &settings, &mut |_| {}).expect("fit");
    // another seed: another excitation signal and other sensor noise
    let full = episode_trajectory(&episode(4, 8.0)).expect("test trajectory");
    let test = Trajectory::new(full.u.clone(), full.y.columns(0, 1).into_owned()).expect("angle");
    let metrics = model.evaluate(&test).expect("evaluate");
    let mean = [train[0].y.column(0).mean()];
    let baseline = mean_predictor_rmse(&test, &mean, model.spec.warmup());
    eprintln!(
        "angle: free-simulation RMSE {:.4} rad (training mean: {baseline:.4}), 2σ coverage {:.3}",
        metrics.rmse, metrics.coverage_2sigma
    );
    assert!(
        metrics.rmse < 0.3 * baseline,
        "free-simulation RMSE {} against the training mean's {baseline}",
        metrics.rmse
    );
    assert!(
        metrics.coverage_2sigma > 0.8,
        "2σ coverage {}",
        metrics.coverage_2sigma
    );
    let _ = std::fs::remove_dir_all(&dir);
}
