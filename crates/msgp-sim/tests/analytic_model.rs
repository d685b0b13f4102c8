//! The rapier plant against an RK4 integration of the analytic pendulum-on-accelerating-base
//! ODE driven by the same commands (same delay and lag, integrated independently here).
//!
//! Reference model, θ from the upward vertical (positive toward +x), base acceleration `a`:
//!
//! ```text
//! I_p θ̈ = m l (g sin θ − a cos θ) − b θ̇,   ẋ = v,  v̇ = a,  ȧ = (u_delayed − a) / τ
//! ```
//!
//! The same test also integrates two *wrong* models (base-acceleration sign flipped; hinge
//! damping missing) and checks that they miss the rapier trajectory by far more than the
//! error bound, so the bound would catch such modelling mistakes.

use msgp_sim::{PendulumParams, Plant};

/// Error bound on the pole angle at the control steps \[rad\]. Measured on this setup:
/// 2.2e-4 (inverted, to |θ| ≈ 0.43) and 6.2e-5 (hanging, 10 s).
const THETA_BOUND: f64 = 1e-3;

/// Which variant of the analytic model to integrate.
#[derive(Clone, Copy, PartialEq)]
enum Model {
    Correct,
    FlippedBaseAcceleration,
    NoDamping,
}

/// RK4 reference state `[θ, θ̇, x, v, a]`.
fn derivative(p: &PendulumParams, model: Model, u: f64, s: [f64; 5]) -> [f64; 5] {
    let [theta, theta_dot, _x, v, a] = s;
    let ip = p.inertia_about_pivot();
    let ml = p.pole_mass * p.pole_com;
    let base = if model == Model::FlippedBaseAcceleration {
        -a
    } else {
        a
    };
    let b = if model == Model::NoDamping {
        0.0
    } else {
        p.hinge_damping
    };
    let theta_ddot = (ml * (p.gravity * theta.sin() - base * theta.cos()) - b * theta_dot) / ip;
    [theta_dot, theta_ddot, v, a, (u - a) / p.lag_time_constant]
}

fn rk4_step(p: &PendulumParams, model: Model, u: f64, s: [f64; 5], h: f64) -> [f64; 5] {
    let add = |s: [f64; 5], k: [f64; 5], f: f64| std::array::from_fn(|i| s[i] + f * k[i]);
    let k1 = derivative(p, model, u, s);
    let k2 = derivative(p, model, u, add(s, k1, h / 2.0));
    let k3 = derivative(p, model, u, add(s, k2, h / 2.0));
    let k4 = derivative(p, model, u, add(s, k3, h));
    std::array::from_fn(|i| s[i] + h / 6.0 * (k1[i] + 2.0 * k2[i] + 2.0 * k3[i] + k4[i]))
}

/// θ and x at every control step for the commands `u`, from the reference model.
fn reference(p: &PendulumParams, model: Model, theta0: f64, u: &[f64]) -> Vec<(f64, f64)> {
    let substeps = 200; // 0.1 ms RK4 steps at 50 Hz control
    let h = p.control_period() / f64::from(substeps);
    let mut s = [theta0, 0.0, 0.0, 0.0, 0.0];
    let mut out = vec![(s[0], s[2])];
    for k in 0..u.len() {
        // One control step of delay: period k applies the command issued at k - 1.
        let applied = if k == 0 { 0.0 } else { u[k - 1] };
        for _ in 0..substeps {
            s = rk4_step(p, model, applied, s, h);
        }
        out.push((s[0], s[2]));
    }
    out
}

/// θ and x at every control step for the commands `u`, from the rapier plant.
fn simulated(p: &PendulumParams, theta0: f64, u: &[f64]) -> Vec<(f64, f64)> {
    let mut plant = Plant::new(p, theta0).expect("valid plant");
    let mut out = Vec::with_capacity(u.len() + 1);
    let l = plant.latent(0.0);
    out.push((l.theta, l.x));
    for &command in u {
        plant.step(command).expect("finite state");
        let l = plant.latent(0.0);
        out.push((l.theta, l.x));
    }
    out
}

fn max_theta_error(a: &[(f64, f64)], b: &[(f64, f64)]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x.0 - y.0).abs())
        .fold(0.0, f64::max)
}

fn max_x_error(a: &[(f64, f64)], b: &[(f64, f64)]) -> f64 {
    a.iter()
        .zip(b)
        .map(|(x, y)| (x.1 - y.1).abs())
        .fold(0.0, f64::max)
}

/// A smooth, sign-changing command sequence within the action limit.
fn commands(p: &PendulumParams, seconds: f64, amplitude: f64) -> Vec<f64> {
    let n = (seconds * p.control_rate_hz).round() as usize;
    (0..n)
        .map(|k| {
            let t = k as f64 * p.control_period();
            amplitude
                * (0.7 * (std::f64::consts::TAU * 1.3 * t).sin()
                    + 0.3 * (std::f64::consts::TAU * 0.45 * t + 1.0).cos())
        })
        .collect()
}

fn report(name: &str, sim: &[(f64, f64)], p: &PendulumParams, theta0: f64, u: &[f64]) -> [f64; 3] {
    let good = reference(p, Model::Correct, theta0, u);
    let flipped = reference(p, Model::FlippedBaseAcceleration, theta0, u);
    let undamped = reference(p, Model::NoDamping, theta0, u);
    let e = [
        max_theta_error(sim, &good),
        max_theta_error(sim, &flipped),
        max_theta_error(sim, &undamped),
    ];
    let peak = good.iter().map(|s| s.0.abs()).fold(0.0, f64::max);
    println!(
        "{name}: max |θ_rapier − θ_rk4| = {:.3e} rad (peak |θ| {peak:.3}); flipped-sign model {:.3e}, undamped model {:.3e}; max x error {:.3e} m",
        e[0],
        e[1],
        e[2],
        max_x_error(sim, &good)
    );
    e
}

/// Inverted pole (the real configuration), falling from 0.05 rad under a smooth base
/// motion, until the reference reaches about |θ| = 0.45 rad.
#[test]
fn inverted_pole_matches_rk4() {
    let p = PendulumParams::default().noiseless();
    let theta0 = 0.05;
    let all = commands(&p, 3.0, 1.5);
    let full = reference(&p, Model::Correct, theta0, &all);
    let n = full
        .iter()
        .position(|s| s.0.abs() > 0.45)
        .expect("the pole falls within 3 s");
    let u = &all[..n - 1];
    let sim = simulated(&p, theta0, u);
    let [good, flipped, undamped] = report("inverted", &sim, &p, theta0, u);
    assert!(
        good < THETA_BOUND,
        "rapier vs RK4 θ error {good:.3e} exceeds the bound"
    );
    assert!(
        flipped > 100.0 * THETA_BOUND,
        "a sign flip would go unnoticed ({flipped:.3e})"
    );
    assert!(
        undamped > 3.0 * THETA_BOUND,
        "missing damping would go unnoticed ({undamped:.3e})"
    );
    let x_err = max_x_error(&sim, &reference(&p, Model::Correct, theta0, u));
    assert!(
        x_err < 1e-9,
        "end-effector motion differs from the reference: {x_err:.3e} m"
    );
}

/// Hanging pole (gravity reversed makes θ = 0 stable) swinging for 10 s: long enough for
/// the hinge damping to matter, so a missing or wrong damping model is caught.
#[test]
fn hanging_pole_with_damping_matches_rk4() {
    let p = PendulumParams {
        gravity: -9.81,
        ..PendulumParams::default().noiseless()
    };
    let theta0 = 0.3;
    let u = commands(&p, 10.0, 1.0);
    let sim = simulated(&p, theta0, &u);
    let [good, flipped, undamped] = report("hanging", &sim, &p, theta0, &u);
    assert!(
        good < THETA_BOUND,
        "rapier vs RK4 θ error {good:.3e} exceeds the bound"
    );
    assert!(
        flipped > 100.0 * THETA_BOUND,
        "a sign flip would go unnoticed ({flipped:.3e})"
    );
    assert!(
        undamped > 50.0 * THETA_BOUND,
        "missing damping would go unnoticed ({undamped:.3e})"
    );
}
