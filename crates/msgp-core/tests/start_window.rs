//! The smoothed start window of the training loss against a hand computation: a linear model
//! alone (`x_{t+1} = 2 x_t − x_{t−1}`, the GP switched off) on outputs that are exactly linear
//! in time, where every prediction is exact and the NLL is the log of the predicted variances,
//! propagated by hand from `σ_y² H Hᵀ`.

use msgp_core::data::Trajectory;
use msgp_core::gp::{GpConfig, GpParams, MeanFunction};
use msgp_core::loss::{Complexity, msgp_loss};
use msgp_core::narx::NarxSpec;
use msgp_core::narx::start_window::StartWindow;
use msgp_core::numeric::linalg::JitterLog;
use msgp_core::rollout::Episode;
use nalgebra::{DMatrix, DVector, Matrix2, Vector2};

#[test]
fn smoothed_start_matches_a_hand_propagated_linear_model() {
    let spec = NarxSpec::siso(2, 1);
    let d = spec.input_dim();
    let (sx2, sy2): (f64, f64) = (1e-4, 4e-4);
    let mut a = DMatrix::zeros(1, d);
    a[(0, spec.y_index(0, 0))] = 2.0;
    a[(0, spec.y_index(1, 0))] = -1.0;
    let params = GpParams {
        pseudo_inputs: DMatrix::zeros(1, d),
        pseudo_targets: DMatrix::zeros(1, 1),
        log_lengthscales: DMatrix::zeros(1, d),
        log_signal_var: DVector::from_element(1, -60.0),
        log_process_noise: DVector::from_element(1, sx2.ln()),
        log_obs_noise: DVector::from_element(1, sy2.ln()),
        linear_mean: a,
    };
    let n = 25;
    let y: Vec<f64> = (0..n).map(|t| 0.1 + 0.05 * t as f64).collect();
    let traj = Trajectory::siso(&vec![0.3; n], &y).expect("trajectory");
    let episodes = [Episode::feed_forward(traj)];
    let how = StartWindow::Smoothed {
        samples: 10,
        degree: 2,
    };
    let config = GpConfig {
        mean: MeanFunction::Linear,
        noise_floor: 0.0,
        start: how,
        ..GpConfig::default()
    };
    let mut log = JitterLog::default();
    let v = msgp_loss(
        &params,
        &config,
        &spec,
        &episodes,
        Complexity::None,
        &mut log,
    )
    .expect("loss");
    assert_eq!(
        v.steps,
        n - 10,
        "the rollout starts after the smoother's samples"
    );

    // by hand: window [x_t, x_{t−1}] ~ N(exact, σ_y² H Hᵀ); x_{t+1} = 2x_t − x_{t−1} + ε_x
    let sm = how.smoother(spec.warmup(), spec.ly, n).expect("smoother");
    let p = &sm.pattern;
    let mut cov = Matrix2::new(p[(0, 0)], p[(0, 1)], p[(1, 0)], p[(1, 1)]) * sy2;
    let f = Vector2::new(2.0, -1.0);
    let mut nll = 0.0;
    for _ in 10..n {
        let var_x = f.dot(&(cov * f)) + sx2;
        let cross = cov * f; // Cov(window, x_{t+1})
        nll += 0.5 * (std::f64::consts::TAU * (var_x + sy2)).ln();
        cov = Matrix2::new(var_x, cross[0], cross[0], cov[(0, 0)]);
    }
    assert!(
        (v.nll - nll).abs() < 1e-10 * nll.abs(),
        "loss {} vs hand {nll}",
        v.nll
    );

    // the measured window starts two steps in, with σ_y² I: a different loss
    let measured = GpConfig {
        start: StartWindow::Measured,
        ..config
    };
    let m = msgp_loss(
        &params,
        &measured,
        &spec,
        &episodes,
        Complexity::None,
        &mut log,
    )
    .expect("loss");
    assert_eq!(m.steps, n - spec.warmup());
}
