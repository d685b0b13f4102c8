//! MSGP learns from feed-forward and feedback trajectories together (the paper's L_ff + L_fb):
//! a feedback trajectory of synthetic system 4 under a known linear policy enters the loss in
//! closed loop, and training lowers the loss.

use msgp_core::data::Trajectory;
use msgp_core::data::{NoiseScale, SyntheticSystem};
use msgp_core::fit::{FitSettings, MsgpSettings, TrainingEpisode, fit_episodes};
use msgp_core::policy::{LinearPolicy, PolicySpec};
use nalgebra::{DMatrix, DVector};

#[test]
fn feedback_and_feed_forward_episodes_train_together() {
    let sys = SyntheticSystem::new(4).expect("sys");
    let bench = sys.generate(0, NoiseScale::StdDev).expect("gen");
    // closed loop: u_t = −0.5 y_t + 0.3 on the measured (noisy) output, 200 samples
    let noise: Vec<f64> = bench
        .train
        .y
        .iter()
        .zip(sys.respond(&bench.train.u.iter().copied().collect::<Vec<_>>()))
        .map(|(y, c)| y - c)
        .collect();
    let (mut y, mut u) = (vec![0.0; 200], vec![0.0; 200]);
    let mut clean = vec![0.0; 200];
    for t in 0..200 {
        let y1 = if t >= 1 { clean[t - 1] } else { 0.0 };
        let y2 = if t >= 2 { clean[t - 2] } else { 0.0 };
        let u1 = if t >= 1 { u[t - 1] } else { 0.0 };
        clean[t] = sys.step(y1, y2, u1);
        y[t] = clean[t] + noise[t];
        u[t] = -0.5 * y[t] + 0.3;
    }
    let fb = Trajectory::siso(&u, &y).expect("traj");
    let policy = LinearPolicy::new(
        DMatrix::from_element(1, 1, -0.5),
        DVector::from_element(1, 0.3),
    )
    .expect("policy");
    let episodes = vec![
        TrainingEpisode {
            traj: bench.train.clone(),
            policy: None,
        },
        TrainingEpisode {
            traj: fb,
            policy: Some(PolicySpec::Linear(policy)),
        },
    ];
    let settings = FitSettings {
        ly: 2,
        lu: 1,
        method: MsgpSettings {
            inducing: 50,
            iterations: 60,
            patience: 100,
            ..MsgpSettings::default()
        }
        .into(),
        ..FitSettings::default()
    };
    let (model, report) = fit_episodes(&episodes, &settings, &mut |_| {}).expect("fit");
    let first = report.history.first().expect("history").1;
    let last = report.history.last().expect("history").1;
    assert!(last < first, "training loss did not fall: {first} → {last}");
    let m = model.evaluate(&bench.test).expect("evaluate");
    assert!(m.rmse.is_finite() && m.rmse < 1.0, "test RMSE {}", m.rmse);
}
