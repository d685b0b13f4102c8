use super::*;
use crate::gp::{GpConfig, GpParams, MeanFunction};
use crate::rollout::simulate;
use crate::rollout::window::{Layout, gather, initial_window, predict_step};
use num_dual::DualSVec64;
use rand::{RngExt, SeedableRng, rngs::StdRng};
use rand_distr::{Distribution, StandardNormal};

/// Directions carried by the dual reference (at least the draws' count).
const N: usize = 32;
type D = DualSVec64<N>;

fn normal(r: &mut StdRng) -> f64 {
    StandardNormal.sample(r)
}

/// Two outputs, one input, `l_y = l_u = 2`: a random GP near a random trajectory's windows.
fn problem(seed: u64, mean: MeanFunction) -> (NarxSpec, GpParams<f64>, GpConfig, Trajectory) {
    let mut r = StdRng::seed_from_u64(seed);
    let spec = NarxSpec {
        ly: 2,
        lu: 2,
        dy: 2,
        du: 1,
    };
    let (d, m, e, n) = (spec.input_dim(), 9, 2, 14);
    let y = DMatrix::from_fn(n, 2, |t, j| {
        0.6 * ((t as f64) * 0.3 + j as f64).sin() + 0.1 * normal(&mut r)
    });
    let u = DMatrix::from_fn(n, 1, |_, _| r.random_range(-1.0..1.0));
    let traj = Trajectory::new(u, y).expect("trajectory");
    let params = GpParams {
        pseudo_inputs: DMatrix::from_fn(m, d, |_, _| r.random_range(-1.2..1.2)),
        pseudo_targets: DMatrix::from_fn(m, e, |_, _| 0.5 * normal(&mut r)),
        log_lengthscales: DMatrix::from_fn(e, d, |_, _| r.random_range(0.0..0.8)),
        log_signal_var: DVector::from_fn(e, |_, _| r.random_range(-1.0..-0.2)),
        log_process_noise: DVector::from_fn(e, |_, _| r.random_range(-3.5..-2.5)),
        log_obs_noise: DVector::from_fn(e, |_, _| r.random_range(-5.0..-4.0)),
        linear_mean: DMatrix::from_fn(e, d, |_, _| 0.25 * normal(&mut r)),
    };
    let config = GpConfig {
        mean,
        ..GpConfig::default()
    };
    (spec, params, config, traj)
}

/// The draws' pseudo-targets and linear mean as dual numbers: derivative `k` is the move of
/// unit coordinate `k`.
fn dual_params(params: &GpParams<f64>, draws: &FunctionDraws, gp: &PreparedGp<f64>) -> GpParams<D> {
    let mut pd = params.map(D::from_re);
    for k in 0..draws.directions() {
        let mut x = vec![0.0; draws.directions()];
        x[k] = 1.0;
        let (dy, da) = draws.moves(gp, &x);
        let eps = D::from_re(0.0).derivative(k);
        for (i, v) in dy.iter().enumerate() {
            pd.pseudo_targets[i] += eps * *v;
        }
        for (i, v) in da.iter().enumerate() {
            pd.linear_mean[i] += eps * *v;
        }
    }
    pd
}

/// The tangents of every step against forward-mode duals of the same rollout whose window
/// covariances are held at moment matching's: the mean of step `t` with the pseudo-targets and
/// the linear mean moved along each draw direction, differentiated by the duals. Returns the
/// largest absolute difference and the largest tangent.
fn compare_with_duals(seed: u64, mean: MeanFunction) -> (f64, f64, Vec<f64>) {
    let (spec, params, config, traj) = problem(seed, mean);
    let mut log = JitterLog::default();
    let gp = PreparedGp::new(&params, &config, &mut log).expect("gp");
    let draws = FunctionDraws::new(&gp).expect("draws");
    assert!(draws.directions() <= N, "{} directions", draws.directions());
    let gpd = PreparedGp::new(&dual_params(&params, &draws, &gp), &config, &mut log).expect("gp");
    let mut tangents = Tangents::new(&draws, &spec, &gp.pseudo_inputs);

    let first = initial_window(&gp, &spec, &traj, StartWindow::Measured).expect("window");
    let start = first.state(None, &traj).expect("state");
    let (d, dy) = (spec.input_dim(), spec.dy);
    let layout = Layout {
        d,
        ds: 0,
        dy,
        du: spec.du,
    };
    let sel = layout.gather_map(&spec);
    let (mut mu, mut sigma) = (start.mean.clone(), start.cov.clone());
    let mut mud: DVector<D> = mu.map(D::from_re);
    let (mut worst, mut largest) = (0.0f64, 0.0f64);
    let mut added = Vec::new();
    for t in first.t0..traj.len() {
        let sm = predict_step(&gp, &mu, &sigma, "test", t, &mut log).expect("step");
        added.extend(tangents.step(&mu, &sigma, &sm.mm).expect("tangents").iter());
        let smd = predict_step(&gpd, &mud, &sigma.map(D::from_re), "dual", t, &mut log)
            .expect("dual step");
        for j in 0..dy {
            assert!((smd.mm.mean[j].re - sm.mm.mean[j]).abs() < 1e-12);
            let eps = smd.mm.mean[j].eps.0.expect("derivatives");
            for k in 0..draws.directions() {
                let tk = tangents.last[(j, k)];
                worst = worst.max((eps[k] - tk).abs());
                largest = largest.max(tk.abs());
            }
        }
        // the f64 state moves on as the rollout's; the dual window's outputs shift with it
        let (mut amu, acov) = layout.augmented(&mu, &sigma, &sm.mm.mean, &sm.mm.v, &sm.xcov);
        if t + 1 < traj.len() {
            layout.set_measured_input(&mut amu, &traj.u, t);
        }
        (mu, sigma) = gather(&amu, &acov, &sel);
        let mut next = mu.map(D::from_re);
        for j in 0..dy {
            next[spec.y_index(0, j)] = smd.mm.mean[j];
            for k in 1..spec.ly {
                next[spec.y_index(k, j)] = mud[spec.y_index(k - 1, j)];
            }
        }
        mud = next;
    }
    (worst, largest, added)
}

#[test]
fn tangents_equal_forward_mode_duals_of_the_drawn_functions_means() {
    for mean in [MeanFunction::Zero, MeanFunction::Linear] {
        for seed in 0..3 {
            let (worst, largest, _) = compare_with_duals(seed, mean);
            assert!(largest > 1e-2, "{mean:?} seed {seed}: tangents {largest}");
            assert!(
                worst < 1e-10 * largest.max(1.0),
                "{mean:?} seed {seed}: tangent off by {worst} (largest {largest})"
            );
        }
    }
}

#[test]
fn the_first_step_adds_only_the_linear_means_uncertainty() {
    // at the first step nothing is correlated yet: the pseudo-targets' part is moment
    // matching's own function variance, already counted, and exactly subtracted
    let (_, _, zero) = compare_with_duals(4, MeanFunction::Zero);
    assert!(zero[0].abs() < 1e-14 && zero[1].abs() < 1e-14, "{zero:?}");
    let (_, _, linear) = compare_with_duals(4, MeanFunction::Linear);
    assert!(linear[0] > 1e-6 && linear[1] > 1e-6, "{linear:?}");
    // later steps add the correlation's share
    assert!(zero.iter().skip(2).any(|v| *v > 1e-6), "{zero:?}");
}

/// The independent-injection covariance against its definition: every step's pseudo-target
/// draw a fresh set of coordinates, carried by the same tangent recursion (the window's
/// tangent grows by `d_y` columns a step).
#[test]
fn the_subtracted_part_is_independent_draws_carried_forward() {
    let (spec, params, config, traj) = problem(7, MeanFunction::Zero);
    let mut log = JitterLog::default();
    let gp = PreparedGp::new(&params, &config, &mut log).expect("gp");
    let draws = FunctionDraws::new(&gp).expect("draws");
    let mut tangents = Tangents::new(&draws, &spec, &gp.pseudo_inputs);
    let first = initial_window(&gp, &spec, &traj, StartWindow::Measured).expect("window");
    let start = first.state(None, &traj).expect("state");
    let (d, dy) = (spec.input_dim(), spec.dy);
    let layout = Layout {
        d,
        ds: 0,
        dy,
        du: spec.du,
    };
    let sel = layout.gather_map(&spec);
    let (mut mu, mut sigma) = (start.mean.clone(), start.cov.clone());
    // fresh columns: one per output per step
    let mut fresh = DMatrix::<f64>::zeros(d, 0);
    let mut checked = 0;
    for t in first.t0..traj.len() {
        let sm = predict_step(&gp, &mu, &sigma, "test", t, &mut log).expect("step");
        let added = tangents.step(&mu, &sigma, &sm.mm).expect("tangents");
        // the correlated total and this step's own injection, from the tangents
        let total: Vec<f64> = (0..dy)
            .map(|a| tangents.last.row(a).norm_squared())
            .collect();
        let mut out = sm.mm.v.tr_mul(&fresh); // E × (steps·E)
        let cols = out.ncols();
        out = out.insert_columns(cols, dy, 0.0);
        // this step's own injection: the pseudo-target block of a zero-tangent step here
        let mut own = Tangents::new(&draws, &spec, &gp.pseudo_inputs);
        own.step(&mu, &sigma, &sm.mm).expect("own");
        for a in 0..dy {
            let off = draws.offsets[a];
            let r = draws.outputs[a].targets.ncols();
            out[(a, cols + a)] = own.last.view((a, off), (1, r)).norm();
        }
        for a in 0..dy {
            let indep = out.row(a).norm_squared();
            let expect = (total[a] - indep).max(0.0);
            assert!(
                (added[a] - expect).abs() < 1e-10 * total[a].max(1e-3),
                "step {t} output {a}: added {} against {expect}",
                added[a]
            );
            checked += 1;
        }
        // shift the fresh tangents as the window shifts: new outputs at lag 0
        let mut next = DMatrix::zeros(d, out.ncols());
        for j in 0..dy {
            next.row_mut(spec.y_index(0, j)).copy_from(&out.row(j));
            for k in 1..spec.ly {
                let prev = fresh.row(spec.y_index(k - 1, j)).into_owned();
                let mut row = next.row_mut(spec.y_index(k, j));
                row.columns_mut(0, prev.len()).copy_from(&prev);
            }
        }
        fresh = next;
        let (mut amu, acov) = layout.augmented(&mu, &sigma, &sm.mm.mean, &sm.mm.v, &sm.xcov);
        if t + 1 < traj.len() {
            layout.set_measured_input(&mut amu, &traj.u, t);
        }
        (mu, sigma) = gather(&amu, &acov, &sel);
    }
    assert!(checked >= 20);
}

#[test]
fn widening_moves_no_mean_and_only_adds_variance() {
    for mean in [MeanFunction::Zero, MeanFunction::Linear] {
        let (spec, params, config, traj) = problem(11, mean);
        let mut log = JitterLog::default();
        let gp = PreparedGp::new(&params, &config, &mut log).expect("gp");
        let plain = simulate(
            &gp,
            &spec,
            &traj,
            &Control::FeedForward,
            traj.len(),
            &mut log,
        )
        .expect("plain");
        let wide = simulate_correlated(&gp, &spec, &traj, traj.len(), &mut log).expect("wide");
        assert_eq!(plain.len(), wide.len());
        let mut grew = false;
        for (p, w) in plain.iter().zip(&wide) {
            assert_eq!(p.mean, w.mean, "means are moment matching's, bit for bit");
            for j in 0..spec.dy {
                assert!(w.cov[(j, j)] >= p.cov[(j, j)]);
                grew |= w.cov[(j, j)] > p.cov[(j, j)] * (1.0 + 1e-6);
                for k in 0..spec.dy {
                    if k != j {
                        assert_eq!(w.cov[(j, k)], p.cov[(j, k)]);
                    }
                }
            }
        }
        assert!(grew, "{mean:?}: nothing added");
    }
}

/// The draws' Monte Carlo spread of moment matching's means (window covariances free to move
/// with the draw) agrees with the first-order spread (covariances held) for small draws, on a
/// held input, where the same function error repeats.
#[test]
fn monte_carlo_over_small_draws_agrees_with_the_first_order_spread() {
    let (spec, params, config, mut traj) = problem(3, MeanFunction::Linear);
    let n = traj.len();
    for t in 0..n {
        traj.u[(t, 0)] = 0.4;
    }
    let mut log = JitterLog::default();
    let gp = PreparedGp::new(&params, &config, &mut log).expect("gp");
    let draws = FunctionDraws::new(&gp).expect("draws");
    let mean_of = |p: &GpParams<f64>| -> Vec<DVector<f64>> {
        let mut log = JitterLog::default();
        let g = PreparedGp::new(p, &config, &mut log).expect("gp");
        simulate(&g, &spec, &traj, &Control::FeedForward, n, &mut log)
            .expect("sim")
            .into_iter()
            .map(|s| s.mean)
            .collect()
    };
    let base = mean_of(&params);
    // first-order spread ‖T‖² along the rollout
    let mut tangents = Tangents::new(&draws, &spec, &gp.pseudo_inputs);
    let mut spread = Vec::new();
    let mut log2 = JitterLog::default();
    rollout_widened(
        &gp,
        &spec,
        &traj,
        &Control::FeedForward,
        n,
        StartWindow::Measured,
        &mut log2,
        Some(&mut RecordSpread {
            inner: &mut tangents,
            out: &mut spread,
        }),
        |_| Ok(()),
    )
    .expect("rollout");
    // Monte Carlo over small draws (scale h), variance / h²
    let h = 1e-3;
    let mut r = StdRng::seed_from_u64(5);
    let draws_n = 400;
    let mut acc = vec![0.0; base.len()];
    for _ in 0..draws_n {
        let x: Vec<f64> = (0..draws.directions())
            .map(|_| h * normal(&mut r))
            .collect();
        let (dy, da) = draws.moves(&gp, &x);
        let mut p = params.clone();
        p.pseudo_targets += dy;
        p.linear_mean += da;
        for (i, m) in mean_of(&p).iter().enumerate() {
            acc[i] += (m[0] - base[i][0]).powi(2);
        }
    }
    for (i, s) in spread.iter().enumerate() {
        let mc = acc[i] / draws_n as f64 / (h * h);
        // 400 draws: the Monte Carlo variance is within ±20 % (≈ 3 standard errors)
        assert!(
            (mc - s).abs() < 0.2 * s + 1e-9,
            "step {i}: Monte Carlo {mc} against first order {s}"
        );
    }
}

/// Records output 0's first-order spread `‖T_0‖²` of every step.
struct RecordSpread<'a, 'b> {
    inner: &'a mut Tangents<'b>,
    out: &'a mut Vec<f64>,
}

impl Widen<f64> for RecordSpread<'_, '_> {
    fn widen(
        &mut self,
        mu: &DVector<f64>,
        sigma: &DMatrix<f64>,
        mm: &Moments<f64>,
        _ycov: &mut DMatrix<f64>,
    ) -> Result<()> {
        self.inner.step(mu, sigma, mm)?;
        self.out.push(self.inner.last.row(0).norm_squared());
        Ok(())
    }
}

/// The draws' covariance of the function at the pseudo-inputs is the posterior covariance of
/// a GP given the pseudo-data `(X̄, ȳ)` with noise `σ_x²`, whose kernel is the SE kernel plus
/// the linear mean's prior `100 x xᵀ` (Rasmussen & Williams §2.7): `K_a − K_a (K_a + σ_x² I)⁻¹
/// K_a`, `K_a = K + 100 X̄ X̄ᵀ`; without the linear mean, `K − K K̃⁻¹ K`. At a pseudo-input this
/// is also the variance the GP itself predicts there.
#[test]
fn the_draws_are_the_posterior_given_the_pseudo_data() {
    for mean in [MeanFunction::Zero, MeanFunction::Linear] {
        let (_, params, config, _) = problem(2, mean);
        let mut log = JitterLog::default();
        let gp = PreparedGp::new(&params, &config, &mut log).expect("gp");
        let draws = FunctionDraws::new(&gp).expect("draws");
        let z = &gp.pseudo_inputs;
        let m = z.nrows();
        for (a, o) in gp.outputs.iter().enumerate() {
            let k = kernel_matrix(z, z, &o.inv_l2, o.sf2);
            // δf(x̄_i) = k_iᵀ K̃⁻¹ δȳ + δA x̄_i, one column per draw coordinate
            let mut cov = DMatrix::<f64>::zeros(m, m);
            for c in 0..draws.directions() {
                let mut x = vec![0.0; draws.directions()];
                x[c] = 1.0;
                let (dy, da) = draws.moves(&gp, &x);
                let col = &k * (&o.kinv * dy.column(a)) + z * da.row(a).transpose();
                cov += &col * col.transpose();
            }
            let prior = match mean {
                MeanFunction::Zero => k.clone(),
                MeanFunction::Linear => &k + z * z.transpose() * 100.0,
            };
            let noisy = &prior + DMatrix::identity(m, m) * o.sx2;
            let reference = &prior - &prior * noisy.try_inverse().expect("inverse") * &prior;
            let scale = reference.diagonal().max();
            assert!(scale > 1e-4, "{mean:?}: posterior variance {scale}");
            let worst = (&cov - &reference).abs().max();
            assert!(
                worst < 1e-7 * scale.max(1.0),
                "{mean:?} output {a}: draws' covariance off by {worst} (scale {scale})"
            );
            if mean == MeanFunction::Zero {
                for i in 0..m {
                    let (_, var) = gp.predict(z.row(i).transpose().as_slice())[a];
                    assert!(
                        (cov[(i, i)] - var).abs() < 1e-7,
                        "{} against {var}",
                        cov[(i, i)]
                    );
                }
            }
        }
    }
}
