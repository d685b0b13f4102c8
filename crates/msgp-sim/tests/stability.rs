//! The stability test on the default (noisy, delayed, lagged) plant.

use msgp_sim::{PendulumParams, PidPdGains, StabilityCriteria, StabilityReport, stability_test};

fn print(name: &str, report: &StabilityReport) {
    println!("{name}: passed = {}", report.passed);
    for s in &report.starts {
        println!(
            "  θ0 = {:+.3}: {} max|θ| = {:.4} max|x| = {:.4} rms θ (last 5 s) = {:.4} duration = {:.2} s {}",
            s.initial_theta,
            if s.passed { "PASS" } else { "FAIL" },
            s.max_abs_theta,
            s.max_abs_x,
            s.rms_theta_final,
            s.duration,
            s.failure.as_deref().unwrap_or("")
        );
    }
}

/// Hand-tuned gains (Apollo LQR with the position loop halved) balance the default plant,
/// measurement noise, delay and lag included, for several noise seeds.
#[test]
fn hand_tuned_gains_pass_on_default_plant() {
    let params = PendulumParams::default();
    let criteria = StabilityCriteria::default();
    for seed in [0, 1, 2] {
        let report = stability_test(&params, &PidPdGains::hand_tuned(), seed, &criteria)
            .expect("valid inputs");
        print(&format!("hand-tuned, seed {seed}"), &report);
        assert!(report.passed, "hand-tuned gains failed with seed {seed}");
        assert_eq!(report.starts.len(), 5);
        for s in &report.starts {
            assert!(
                s.max_abs_theta < 0.06,
                "start {} swung to {}",
                s.initial_theta,
                s.max_abs_theta
            );
        }
    }
}

/// The Apollo LQR gains, mapped to the PID + PD convention, balance the default plant with
/// the angle noise reduced to 3 mrad (at the default 5 mrad the finite-difference D term
/// saturates the command and some starts fail; see `PidPdGains::apollo_lqr`).
#[test]
fn apollo_lqr_gains_pass() {
    let params = PendulumParams {
        sigma_theta: 3e-3,
        ..PendulumParams::default()
    };
    let criteria = StabilityCriteria::default();
    for seed in [0, 1, 2] {
        let report = stability_test(&params, &PidPdGains::apollo_lqr(), seed, &criteria)
            .expect("valid inputs");
        print(
            &format!("Apollo LQR (sigma_theta 3e-3), seed {seed}"),
            &report,
        );
        assert!(report.passed, "Apollo LQR gains failed with seed {seed}");
        assert_eq!(report.starts.len(), 5);
        // The pole really is balanced, not just inside the limits by luck of the window.
        for s in &report.starts {
            assert!(
                s.max_abs_theta < 0.06,
                "start {} swung to {}",
                s.initial_theta,
                s.max_abs_theta
            );
        }
    }
}

#[test]
fn zero_gains_fail() {
    let report = stability_test(
        &PendulumParams::default(),
        &PidPdGains::default(),
        0,
        &StabilityCriteria::default(),
    )
    .expect("valid inputs");
    print("zero gains", &report);
    // Also on the noiseless plant, where nothing but the physics can make the pole fall.
    let noiseless = stability_test(
        &PendulumParams::default().noiseless(),
        &PidPdGains::default(),
        0,
        &StabilityCriteria::default(),
    )
    .expect("valid inputs");
    assert!(!noiseless.passed);
    assert!(!report.passed);
    // Every start away from upright falls.
    for s in report.starts.iter().filter(|s| s.initial_theta != 0.0) {
        assert!(
            !s.passed,
            "start {} passed with zero gains",
            s.initial_theta
        );
        assert!(s.max_abs_theta >= 0.1);
    }
}

#[test]
fn wrong_sign_angle_gains_fail() {
    // Moving away from the pole (kp_theta, kd_theta < 0) must not be reported as stable.
    let mut gains = PidPdGains::hand_tuned();
    gains.kp_theta = -gains.kp_theta;
    gains.kd_theta = -gains.kd_theta;
    let report = stability_test(
        &PendulumParams::default(),
        &gains,
        0,
        &StabilityCriteria::default(),
    )
    .expect("valid inputs");
    print("flipped angle gains", &report);
    assert!(!report.passed);
}

#[test]
fn invalid_inputs_are_errors() {
    let bad_gains = PidPdGains {
        kp_x: f64::NAN,
        ..PidPdGains::default()
    };
    assert!(
        stability_test(
            &PendulumParams::default(),
            &bad_gains,
            0,
            &StabilityCriteria::default()
        )
        .is_err()
    );
    let no_starts = StabilityCriteria {
        initial_thetas: vec![],
        ..StabilityCriteria::default()
    };
    assert!(
        stability_test(
            &PendulumParams::default(),
            &PidPdGains::apollo_lqr(),
            0,
            &no_starts
        )
        .is_err()
    );
}
