//! The one-step baselines: GP-NARX trained by the marginal likelihood (eq. 5) on one-step pairs,
//! and PILCO's variant with penalties on the signal-to-noise ratio and extreme length-scales
//! (appendix A.1.1; `fit::hyper`).
//!
//! Two objectives ([`OneStepObjective`]). `Exact` (MSGP's start, PILCO's variant): the full GP's
//! marginal likelihood, then the fitted GP is made sparse for moment-matching rollouts: `m`
//! pseudo-inputs from seeded k-means over the training windows. `Vfe` (the GP-NARX baseline): the
//! hyperparameters and the pseudo-inputs (from the same k-means start) by the variational
//! sparse GP's bound (`fit::vfe`). Either way the pseudo-targets are chosen so that the sparse mean
//! `k(x)ᵀ K̃_m⁻¹ ȳ` equals the DTC/projected-process mean
//! `k(x)ᵀ (σ_n² K_mm + K_mn K_nm)⁻¹ K_mn y`, i.e. `ȳ = K̃_m (σ_n² K_mm + K_mn K_nm)⁻¹ K_mn y`.
//! The exact objective's sparse GP-NARX is MSGP's initialisation, as in the paper.
//!
//! With a linear prior mean ([`MeanFunction::Linear`]) the map `A` is an instrumental-variables
//! ARX fit of the targets on the windows (see [`OneStepData`]), and the GP is fitted to what it
//! leaves over.

use nalgebra::{DMatrix, DVector};

use crate::data::Trajectory;
use crate::error::{MsgpError, Result};
use crate::gp::integrator::{FixedCoefficient, IGNORED_LENGTHSCALE, NO_GP_SIGNAL_VAR, Structure};
use crate::gp::kernel::kernel_matrix;
use crate::gp::kmeans::{gp_inputs, place_pseudo_inputs};
use crate::gp::{GpConfig, GpParams, MeanFunction};
use crate::narx::NarxSpec;
use crate::numeric::dense::DenseChol;
use crate::numeric::linalg::JitterLog;
use crate::numeric::parallel::Threads;
use crate::optim::{Adam, Flow, Lbfgs, Objective, Solver, minimize};

use super::vfe::Vfe;

pub use super::hyper::Hyper;
use super::hyper::pilco_penalty;

pub use super::settings::{OneStepObjective, OneStepSolver};

const LN_2PI: f64 = 1.837_877_066_409_345_3;

/// Extra lags of the instrument window beyond the regressor's (`l_y + 2` outputs and
/// `l_u + 2` inputs): an over-identified instrumental-variables estimate.
const INSTRUMENT_EXTRA_LAGS: usize = 2;

/// One-step training pairs: windows `x̃_t` (N × D) and next outputs `y_{t+1}` (N × E), and for
/// the pairs with enough history, *instruments* for the linear prior mean.
///
/// The measured outputs in `x̃_t` carry the observation noise that also enters the target
/// (errors in variables), so least squares of `y_{t+1}` on `x̃_t` is biased: on a fast-sampled
/// mechanical system it can turn `θ_{t+1} ≈ 2θ_t − θ_{t−1}` into a random walk. The instruments
/// are the signals at times `≤ t − l_y` (`l_y + 2` output and `l_u + 2` input lags of the window
/// at `t − l_y`): correlated with `x̃_t` through the dynamics, but not with the observation noise
/// of `y_{t−l_y+1}, …, y_{t+1}` (white noise), nor — under feedback — with inputs computed from
/// those noisy outputs.
#[derive(Clone, Debug)]
pub struct OneStepData {
    /// Inputs.
    pub x: DMatrix<f64>,
    /// Targets.
    pub y: DMatrix<f64>,
    /// Rows of `x`/`y` that have instruments.
    pub instrumented: Vec<usize>,
    /// Their instruments (one row per entry of `instrumented`).
    pub z: DMatrix<f64>,
    /// `l_y`: the first `l_y · d_y` columns of `x` are the output lags (newest first), which
    /// the linear prior mean's start is kept stable on ([`stabilize_linear_mean`]).
    pub output_lags: usize,
}

/// Builds one-step pairs from every trajectory.
pub fn one_step_pairs(spec: &NarxSpec, trajs: &[&Trajectory]) -> Result<OneStepData> {
    let d = spec.input_dim();
    let zspec = NarxSpec {
        ly: spec.ly + INSTRUMENT_EXTRA_LAGS,
        lu: spec.lu + INSTRUMENT_EXTRA_LAGS,
        ..*spec
    };
    let mut rows_x: Vec<Vec<f64>> = Vec::new();
    let mut rows_y: Vec<Vec<f64>> = Vec::new();
    let mut rows_z: Vec<Vec<f64>> = Vec::new();
    let mut instrumented = Vec::new();
    for traj in trajs {
        traj.check(spec)?;
        for t in (spec.warmup() - 1)..(traj.len() - 1) {
            if t >= spec.ly + zspec.warmup() - 1 {
                instrumented.push(rows_x.len());
                rows_z.push(zspec.window(&traj.y, &traj.u, t - spec.ly));
            }
            rows_x.push(spec.window(&traj.y, &traj.u, t));
            rows_y.push((0..spec.dy).map(|j| traj.y[(t + 1, j)]).collect());
        }
    }
    let n = rows_x.len();
    Ok(OneStepData {
        x: DMatrix::from_fn(n, d, |i, k| rows_x[i][k]),
        y: DMatrix::from_fn(n, spec.dy, |i, j| rows_y[i][j]),
        z: DMatrix::from_fn(rows_z.len(), zspec.input_dim(), |i, k| rows_z[i][k]),
        instrumented,
        output_lags: spec.ly,
    })
}

/// Largest eigenvalue modulus the start of a linear prior mean may have
/// ([`stabilize_linear_mean`]).
pub const STABLE_RADIUS: f64 = 0.99;

/// The spectral radius of the autoregressive part of `A` (E × D, windows with `ly` output lags of
/// `E` outputs first): the largest eigenvalue modulus of its block companion matrix.
pub fn autoregressive_radius(a: &DMatrix<f64>, ly: usize) -> f64 {
    let e = a.nrows();
    let n = ly * e;
    if n == 0 || a.ncols() < n {
        return 0.0;
    }
    let mut c = DMatrix::zeros(n, n);
    for r in 0..e {
        for col in 0..n {
            c[(r, col)] = a[(r, col)];
        }
    }
    for i in e..n {
        c[(i, i - e)] = 1.0;
    }
    c.complex_eigenvalues()
        .iter()
        .map(|z| z.norm())
        .fold(0.0, f64::max)
}

/// Keeps the start of a linear prior mean stable: where the instrumental-variables estimate of
/// `A` has an autoregressive part with an eigenvalue of modulus above [`STABLE_RADIUS`] (an
/// over-parametrised ARX fit on a few hundred samples can, e.g. drives with `l_y = 10`, and its
/// free simulation then runs away before training starts), the lag-`k` blocks are scaled by
/// `c^(k+1)`, `c = STABLE_RADIUS / ρ`, which scales every eigenvalue by `c` and keeps their
/// pattern. Returns the radius before, when it scaled. Not for maps with fixed coefficients
/// (declared integrators have their unit roots by design).
pub fn stabilize_linear_mean(a: &mut DMatrix<f64>, ly: usize) -> Option<f64> {
    let rho = autoregressive_radius(a, ly);
    if rho.is_nan() || rho <= STABLE_RADIUS {
        return None;
    }
    let c = STABLE_RADIUS / rho;
    let e = a.nrows();
    for k in 0..ly {
        let f = c.powi(k as i32 + 1);
        for r in 0..e {
            for j in 0..e {
                a[(r, k * e + j)] *= f;
            }
        }
    }
    Some(rho)
}

/// Negative log marginal likelihood (eq. 5) of one output, optionally with PILCO's penalties.
pub(crate) struct Marginal {
    /// The inputs, each column centred (the SE kernel sees only differences).
    xc: DMatrix<f64>,
    y: DVector<f64>,
    config: GpConfig,
    /// `Some(std of each input dimension)` adds PILCO's penalties.
    pilco_std: Option<Vec<f64>>,
    log: JitterLog,
}

impl Marginal {
    pub(crate) fn new(
        x: &DMatrix<f64>,
        y: DVector<f64>,
        config: GpConfig,
        pilco_std: Option<Vec<f64>>,
    ) -> Self {
        let mut xc = x.clone();
        for mut col in xc.column_iter_mut() {
            let mean = col.mean();
            col.add_scalar_mut(-mean);
        }
        Self {
            xc,
            y,
            config,
            pilco_std,
            log: JitterLog::default(),
        }
    }
}

impl Objective for Marginal {
    fn value_and_gradient(&mut self, p: &[f64]) -> Result<(f64, Vec<f64>)> {
        let (n, d) = self.xc.shape();
        let h = Hyper::from_vec(p);
        let inv_l2 = h.inv_l2();
        let sf2 = h.log_signal_var.exp();
        let sn2 = self.config.noise_floor + h.log_noise.exp();
        let kf = kernel_matrix(&self.xc, &self.xc, &inv_l2, sf2);
        let mut k = kf.clone();
        for i in 0..n {
            k[(i, i)] += sn2;
        }
        let ch = DenseChol::new(
            &k,
            &self.config.jitter,
            "one-step GP kernel matrix",
            &mut self.log,
        )?;
        let kinv = ch.inverse();
        let alpha = &kinv * &self.y;
        let kdiag = kinv.diagonal();
        let mut value = 0.5 * self.y.dot(&alpha) + 0.5 * ch.log_det() + 0.5 * n as f64 * LN_2PI;
        // dNLL/dθ = −½ tr((ααᵀ − K⁻¹) ∂K/∂θ) = −½ Σᵢⱼ Gᵢⱼ ∂log kᵢⱼ/∂θ, G = (ααᵀ − K⁻¹) ∘ K_f;
        // ∂log kᵢⱼ/∂log ℓ_d = (xᵢ_d − xⱼ_d)² / ℓ_d², and Σᵢⱼ Gᵢⱼ (xᵢ − xⱼ)² =
        // Σᵢ xᵢ² (rᵢ + cᵢ) − 2 xᵀ G x with r, c the row and column sums of G: one n × n × d
        // product instead of a scalar loop over the pairs (the inputs are centred, which leaves
        // the differences as they are and keeps the expanded terms small)
        let mut g = kinv;
        for j in 0..n {
            for i in 0..n {
                g[(i, j)] = (alpha[i] * alpha[j] - g[(i, j)]) * kf[(i, j)];
            }
        }
        let tr_sf: f64 = g.iter().sum();
        let rows = g.column_sum();
        let cols = g.row_sum();
        let gx = &g * &self.xc;
        let mut grad = vec![0.0; d + 2];
        for (dd, gr) in grad.iter_mut().take(d).enumerate() {
            let mut q = 0.0;
            for i in 0..n {
                let xi = self.xc[(i, dd)];
                q += xi * (xi * (rows[i] + cols[i]) - 2.0 * gx[(i, dd)]);
            }
            *gr = -0.5 * q * inv_l2[dd];
        }
        grad[d] = -0.5 * tr_sf;
        let tr_w: f64 = (0..n).map(|i| alpha[i] * alpha[i] - kdiag[i]).sum();
        grad[d + 1] = -0.5 * tr_w * h.log_noise.exp();
        if let Some(std) = &self.pilco_std {
            value += pilco_penalty(&h, std, sn2, &mut grad);
        }
        Ok((value, grad))
    }
}

/// The L-BFGS of [`OneStepSolver::Lbfgs`]: it reaches the marginal likelihood's optimum in a
/// few dozen iterations, where Adam (step 0.05) had not converged after 300 (system 4, seed 0:
/// free-simulation RMSE 0.700 against 0.656 at the optimum) and took 20 times as long
/// (`docs/design.md`).
pub const ONE_STEP_LBFGS: Lbfgs = Lbfgs {
    memory: 10,
    max_step: 1.0,
    first_step: 0.1,
    c1: 1e-4,
    max_backtracks: 30,
    tolerance: 1e-9,
    patience: 5,
};

/// Step size of [`OneStepSolver::Adam`].
pub const ONE_STEP_ADAM_STEP: f64 = 0.05;

/// Settings of the one-step fit.
#[derive(Clone, Copy, Debug)]
pub struct OneStepSettings {
    /// Solver of the marginal likelihood.
    pub solver: OneStepSolver,
    /// Most solver iterations on the marginal likelihood ([`ONE_STEP_LBFGS`] stops by itself
    /// when converged, typically after 30–100; Adam runs them all).
    pub iterations: usize,
    /// The hyperparameters' objective and the pseudo-inputs' source.
    pub objective: OneStepObjective,
    /// Add PILCO's penalties.
    pub pilco_penalty: bool,
    /// Most one-step pairs used for hyperparameters (an evenly spaced subset beyond that).
    pub max_pairs: usize,
    /// Threads the outputs' fits run on (the result does not depend on it).
    pub threads: Threads,
}

impl Default for OneStepSettings {
    fn default() -> Self {
        Self {
            solver: OneStepSolver::Lbfgs,
            objective: OneStepObjective::Exact,
            iterations: 300,
            pilco_penalty: false,
            max_pairs: 1000,
            threads: Threads::default(),
        }
    }
}

pub(crate) fn column_std(x: &DMatrix<f64>, d: usize) -> f64 {
    let n = x.nrows() as f64;
    let mean = x.column(d).sum() / n;
    let var = x.column(d).iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (n - 1.0).max(1.0);
    var.sqrt().max(1e-6)
}

/// The linear prior mean `A` (E × D) on the normalised pairs: two-stage least squares with the
/// instruments of [`OneStepData`] when at least `4 · dim(z)` pairs have them, else ridge least
/// squares `argmin ‖Y − X Aᵀ‖² + λ‖A‖²`. Both use the ridge `λ = 1e-6 N` on their Gram
/// matrices. The `fixed` coefficients (of integrating outputs, [`crate::gp::integrator`]) are set,
/// and each row's other coefficients are fitted to what they leave over.
///
/// 2SLS: `Aᵀ = (Bᵀ G⁻¹ B)⁻¹ Bᵀ G⁻¹ C` with `G = ZᵀZ`, `B = ZᵀX`, `C = ZᵀY`, i.e. least squares of
/// `Y` on the projection of `X` onto the instruments.
pub(crate) fn arx_linear_mean(
    data: &OneStepData,
    config: &GpConfig,
    fixed: &[FixedCoefficient],
    log: &mut JitterLog,
) -> Result<DMatrix<f64>> {
    let (d, e) = (data.x.ncols(), data.y.ncols());
    let mut a = DMatrix::zeros(e, d);
    let mut is_fixed = vec![vec![false; d]; e];
    for c in fixed {
        a[(c.row, c.col)] = c.value;
        is_fixed[c.row][c.col] = true;
    }
    // rows with the same free columns are solved together (all rows, when nothing is fixed)
    let mut groups: Vec<(Vec<usize>, Vec<usize>)> = Vec::new();
    for (row, flags) in is_fixed.iter().enumerate() {
        let free: Vec<usize> = (0..d).filter(|&k| !flags[k]).collect();
        match groups.iter_mut().find(|(cols, _)| *cols == free) {
            Some((_, rows)) => rows.push(row),
            None => groups.push((free, vec![row])),
        }
    }
    // the targets less the fixed part
    let y = &data.y - &data.x * a.transpose();
    for (cols, rows) in groups {
        if cols.is_empty() {
            continue;
        }
        let x = data.x.select_columns(&cols);
        let y = y.select_columns(&rows);
        let at = arx_solve(data, &x, &y, config, log)?; // free × rows
        for (i, &row) in rows.iter().enumerate() {
            for (k, &col) in cols.iter().enumerate() {
                a[(row, col)] = at[(k, i)];
            }
        }
    }
    Ok(a)
}

/// `Aᵀ` of `y ≈ x Aᵀ` by two-stage least squares with `data`'s instruments, or ridge least
/// squares (see [`arx_linear_mean`]).
fn arx_solve(
    data: &OneStepData,
    x: &DMatrix<f64>,
    y: &DMatrix<f64>,
    config: &GpConfig,
    log: &mut JitterLog,
) -> Result<DMatrix<f64>> {
    let ridge = |mut g: DMatrix<f64>, n: usize| {
        for k in 0..g.nrows() {
            g[(k, k)] += 1e-6 * n as f64;
        }
        g
    };
    let ni = data.instrumented.len();
    if ni >= 4 * data.z.ncols() {
        let x = x.select_rows(&data.instrumented);
        let y = y.select_rows(&data.instrumented);
        let zt = data.z.transpose();
        let g = DenseChol::new(
            &ridge(&zt * &data.z, ni),
            &config.jitter,
            "ZᵀZ + λI (instruments of the linear prior mean)",
            log,
        )?;
        let b = &zt * &x;
        let gb = g.solve(&b);
        let gc = g.solve(&(&zt * &y));
        let normal = DenseChol::new(
            &ridge(b.transpose() * &gb, ni),
            &config.jitter,
            "Bᵀ G⁻¹ B + λI (two-stage least squares)",
            log,
        )?;
        return Ok(normal.solve(&(b.transpose() * gc)));
    }
    let n = x.nrows();
    let ch = DenseChol::new(
        &ridge(x.transpose() * x, n),
        &config.jitter,
        "XᵀX + λI (linear prior mean)",
        log,
    )?;
    Ok(ch.solve(&(x.transpose() * y)))
}

/// Minimises `objective` from `x0` and returns the final iterate, or the lowest one seen when
/// the last is not finite or not the lowest (Adam does not descend monotonically).
fn minimize_to_best(
    objective: &mut dyn Objective,
    solver: &Solver,
    x0: Vec<f64>,
    active: &[bool],
    iterations: usize,
) -> Result<Vec<f64>> {
    let mut best = (f64::INFINITY, x0.clone());
    let (x, v) = minimize(objective, solver, x0, active, iterations, |_, v, x| {
        if v < best.0 {
            best = (v, x.to_vec());
        }
        Ok(Flow::Continue)
    })?;
    Ok(if v.is_finite() && v < best.0 {
        x
    } else {
        best.1
    })
}

/// Fits one-step GP-NARX hyperparameters per output and projects onto `m` pseudo-inputs.
/// Returns the sparse model (process noise = one-step noise, observation noise at the floor).
/// The outputs' fits run on up to [`OneStepSettings::threads`] threads; the result does not
/// depend on it.
pub fn fit_one_step(
    data: &OneStepData,
    m: usize,
    settings: &OneStepSettings,
    config: &GpConfig,
    structure: &Structure,
    seed: u64,
    log: &mut JitterLog,
) -> Result<GpParams<f64>> {
    let (n, d) = data.x.shape();
    let e = data.y.ncols();
    if n < 2 {
        return Err(MsgpError::Data(format!(
            "{n} one-step pairs are too few to fit a GP"
        )));
    }
    let linear_mean = prior_mean(data, config, structure, log)?;
    let problem = OneStep::new(data, &linear_mean, settings, config, structure);
    let start = place_pseudo_inputs(&problem.gx, m, seed)?;
    let mm = start.nrows();
    let solver = match settings.solver {
        OneStepSolver::Lbfgs => Solver::Lbfgs(ONE_STEP_LBFGS),
        OneStepSolver::Adam => Solver::Adam(Adam {
            learning_rate: ONE_STEP_ADAM_STEP,
            ..Adam::default()
        }),
    };
    let vfe_fit = match settings.objective {
        OneStepObjective::Vfe if mm < problem.idx.len() => Some(problem.vfe(&start, &solver, log)?),
        _ => None,
    };
    let pseudo = match &vfe_fit {
        Some((_, z)) => z.clone(),
        None => start,
    };
    let mut params = GpParams {
        pseudo_inputs: pseudo.clone(),
        pseudo_targets: DMatrix::zeros(mm, e),
        log_lengthscales: DMatrix::zeros(e, d),
        log_signal_var: DVector::zeros(e),
        log_process_noise: DVector::zeros(e),
        log_obs_noise: DVector::from_element(e, (1e-3 * config.noise_floor).ln()),
        linear_mean,
    };
    // the outputs are independent fits: one per thread (faer runs sequentially), their
    // results and jitter records taken in output order, so any thread count gives the same bits
    let outputs: Vec<usize> = (0..e).collect();
    let fit_output = |_: usize, &a: &usize| {
        let vfe_hyper = vfe_fit.as_ref().map(|(hypers, _)| hypers[a].clone());
        problem.fit_output(a, vfe_hyper, &pseudo, m, &solver)
    };
    let fits = crate::numeric::parallel::map_indexed(&outputs, settings.threads.get(), fit_output);
    for (a, fit) in fits.into_iter().enumerate() {
        let (h, ybar, olog) = fit?;
        log.merge(&olog);
        params.pseudo_targets.set_column(a, &ybar);
        for k in 0..d {
            params.log_lengthscales[(a, k)] = h.log_lengthscales[k];
        }
        params.log_signal_var[a] = h.log_signal_var;
        params.log_process_noise[a] = h.log_noise;
    }
    Ok(params)
}

/// The GP's prior mean `A` (outputs × window): zero, or the linear ARX map by least squares
/// (kept stable where no integrating output fixes part of it).
fn prior_mean(
    data: &OneStepData,
    config: &GpConfig,
    structure: &Structure,
    log: &mut JitterLog,
) -> Result<DMatrix<f64>> {
    let (e, d) = (data.y.ncols(), data.x.ncols());
    Ok(match config.mean {
        MeanFunction::Zero => DMatrix::zeros(e, d),
        MeanFunction::Linear => {
            let mut a = arx_linear_mean(data, config, &structure.fixed, log)?;
            if structure.fixed.is_empty() {
                stabilize_linear_mean(&mut a, data.output_lags);
            }
            a
        }
    })
}

/// The one-step fit's problem: the targets the GP models (what the prior mean leaves over),
/// its inputs, and the subset of pairs the hyperparameters are fitted on.
struct OneStep<'a> {
    targets: DMatrix<f64>,
    /// The GP's inputs (ignored coordinates neutralised).
    gx: DMatrix<f64>,
    /// The pairs the hyperparameters see (every `stride`-th, at most `max_pairs`).
    idx: Vec<usize>,
    xs: DMatrix<f64>,
    /// Each input's spread: the length-scales' start.
    std: Vec<f64>,
    settings: &'a OneStepSettings,
    config: &'a GpConfig,
    structure: &'a Structure,
}

impl<'a> OneStep<'a> {
    fn new(
        data: &OneStepData,
        linear_mean: &DMatrix<f64>,
        settings: &'a OneStepSettings,
        config: &'a GpConfig,
        structure: &'a Structure,
    ) -> Self {
        let (n, d) = data.x.shape();
        let targets = &data.y - &data.x * linear_mean.transpose();
        let gx = gp_inputs(&data.x, &structure.ignored);
        let stride = n.div_ceil(settings.max_pairs.max(1));
        let idx: Vec<usize> = (0..n).step_by(stride).collect();
        let xs = DMatrix::from_fn(idx.len(), d, |i, k| gx[(idx[i], k)]);
        let std: Vec<f64> = (0..d)
            .map(|k| match structure.ignored.contains(&k) {
                true => IGNORED_LENGTHSCALE,
                false => column_std(&gx, k),
            })
            .collect();
        Self {
            targets,
            gx,
            idx,
            xs,
            std,
            settings,
            config,
            structure,
        }
    }

    /// Output `a`'s targets on the hyperparameters' subset.
    fn subset(&self, a: usize) -> DVector<f64> {
        DVector::from_fn(self.idx.len(), |i, _| self.targets[(self.idx[i], a)])
    }

    /// The start of output `a`'s fit: length-scales at the inputs' spread, the signal at the
    /// targets' variance and the noise at 5 % of it (without a GP: all of it noise).
    fn start_hyper(&self, a: usize) -> Hyper {
        let ys = self.subset(a);
        let var_y = {
            let mean = ys.mean();
            ys.iter().map(|v| (v - mean).powi(2)).sum::<f64>() / (ys.len() as f64 - 1.0).max(1.0)
        }
        .max(1e-6);
        let log_lengthscales = self.std.iter().map(|s| s.ln()).collect();
        let floor = self.config.noise_floor;
        if self.structure.without_gp.contains(&a) {
            // no GP: what the linear mean leaves over is noise (pseudo-targets stay zero)
            Hyper {
                log_lengthscales,
                log_signal_var: NO_GP_SIGNAL_VAR.ln(),
                log_noise: (var_y - floor).max(1e-3 * floor).ln(),
            }
        } else {
            Hyper {
                log_lengthscales,
                log_signal_var: var_y.ln(),
                log_noise: (0.05 * var_y).ln(),
            }
        }
    }

    /// The variational sparse GP from the pseudo-inputs `start`: hyperparameters of every
    /// output and the shared pseudo-inputs in one bound (with every window a pseudo-input it
    /// is the exact GP's likelihood).
    fn vfe(
        &self,
        start: &DMatrix<f64>,
        solver: &Solver,
        log: &mut JitterLog,
    ) -> Result<(Vec<Hyper>, DMatrix<f64>)> {
        let (structure, e, d, mm) = (
            self.structure,
            self.targets.ncols(),
            self.xs.ncols(),
            start.nrows(),
        );
        let ys = (0..e)
            .map(|a| (!structure.without_gp.contains(&a)).then(|| self.subset(a)))
            .collect();
        let penalty = self.settings.pilco_penalty.then(|| self.std.clone());
        let mut objective = Vfe::new(&self.xs, ys, mm, *self.config, penalty);
        let hypers: Vec<Hyper> = (0..e).map(|a| self.start_hyper(a)).collect();
        let x0 = objective.pack(&hypers, start);
        let mut active = Vec::with_capacity(x0.len());
        for a in 0..e {
            let gp = !structure.without_gp.contains(&a);
            active.extend((0..d + 2).map(|k| gp && !structure.ignored.contains(&k)));
        }
        for k in 0..d {
            active.extend(std::iter::repeat_n(!structure.ignored.contains(&k), mm));
        }
        let x = minimize_to_best(
            &mut objective,
            solver,
            x0,
            &active,
            self.settings.iterations,
        )?;
        log.merge(&objective.log);
        let hypers: Vec<Hyper> = (0..e).map(|a| objective.hyper(&x, a)).collect();
        Ok((hypers, objective.pseudo_inputs(&x)))
    }

    /// Output `a`'s hyperparameters (the variational fit's `vfe_hyper`, else its own marginal
    /// likelihood's) and pseudo-targets on `pseudo`.
    fn fit_output(
        &self,
        a: usize,
        vfe_hyper: Option<Hyper>,
        pseudo: &DMatrix<f64>,
        m: usize,
        solver: &Solver,
    ) -> Result<(Hyper, DVector<f64>, JitterLog)> {
        let mut log = JitterLog::default();
        let mm = pseudo.nrows();
        let without_gp = self.structure.without_gp.contains(&a);
        let h = match vfe_hyper {
            Some(h) => h,
            None if without_gp => return Ok((self.start_hyper(a), DVector::zeros(mm), log)),
            None => {
                let penalty = self.settings.pilco_penalty.then(|| self.std.clone());
                let mut objective = Marginal::new(&self.xs, self.subset(a), *self.config, penalty);
                let mut active = vec![true; self.xs.ncols() + 2];
                for &k in &self.structure.ignored {
                    active[k] = false;
                }
                let x0 = self.start_hyper(a).to_vec();
                let iterations = self.settings.iterations;
                let x = minimize_to_best(&mut objective, solver, x0, &active, iterations)?;
                log.merge(&objective.log);
                Hyper::from_vec(&x)
            }
        };
        if without_gp {
            return Ok((h, DVector::zeros(mm), log));
        }
        let ybar = self.project(&h, a, pseudo, m, &mut log)?;
        Ok((h, ybar, log))
    }

    /// Output `a`'s pseudo-targets on `pseudo` under `h`: the DTC mean of all its targets
    /// (the targets themselves where every window is a pseudo-input).
    fn project(
        &self,
        h: &Hyper,
        a: usize,
        pseudo: &DMatrix<f64>,
        m: usize,
        log: &mut JitterLog,
    ) -> Result<DVector<f64>> {
        let n = self.targets.nrows();
        let mm = pseudo.nrows();
        let inv_l2 = h.inv_l2();
        let sf2 = h.log_signal_var.exp();
        let sn2 = self.config.noise_floor + h.log_noise.exp();
        let yfull = DVector::from_fn(n, |i, _| self.targets[(i, a)]);
        if m >= n {
            return Ok(yfull);
        }
        let kmm = kernel_matrix(pseudo, pseudo, &inv_l2, sf2);
        let kmn = kernel_matrix(pseudo, &self.gx, &inv_l2, sf2);
        let a_mat = &kmm * sn2 + &kmn * kmn.transpose();
        let ch = DenseChol::new(&a_mat, &self.config.jitter, "σ² K_mm + K_mn K_nm", log)?;
        let rhs = &kmn * &yfull;
        let sol = ch.solve(&DMatrix::from_column_slice(mm, 1, rhs.as_slice()));
        let mut kt = kmm;
        for i in 0..mm {
            kt[(i, i)] += sn2;
        }
        Ok(DVector::from_column_slice((&kt * sol).as_slice()))
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// The variational bound against the exact marginal likelihood it generalises.
    mod bound {
        use super::super::*;
        use crate::fit::vfe::tests as vfe_tests;

        /// With every input a pseudo-input (and no jitter on `K_mm`) the bound is the exact negative
        /// log marginal likelihood (`Q = K_nn`, no trace term). Short length-scales keep `K_nn`
        /// well conditioned.
        #[test]
        fn with_every_input_as_pseudo_input_the_bound_is_the_marginal_likelihood() {
            let (x, y) = vfe_tests::problem(30);
            let config = GpConfig::default();
            let short = Hyper {
                log_lengthscales: vec![-1.8, -1.5, -1.6],
                ..vfe_tests::hyper()
            };
            let mut vfe = Vfe::new(&x, vec![Some(y.clone())], 30, config, None);
            vfe.kmm_jitter = 0.0;
            let p = vfe.pack(std::slice::from_ref(&short), &x);
            let (v, g) = vfe.value_and_gradient(&p).expect("bound");
            let mut exact = Marginal::new(&x, y, config, None);
            let (e, ge) = exact.value_and_gradient(&short.to_vec()).expect("exact");
            assert!(
                (v - e).abs() <= 1e-8 * e.abs().max(1.0),
                "bound {v} vs exact {e}"
            );
            // at Z = X the bound is the marginal likelihood for every hyperparameter: so are
            // their derivatives
            for (i, (a, b)) in g.iter().zip(&ge).enumerate() {
                assert!(
                    (a - b).abs() <= 1e-6 * b.abs().max(1.0),
                    "hyper {i}: {a} vs {b}"
                );
            }
            // fewer pseudo-inputs: a bound, strictly above the exact value
            let z = x.rows(0, 8).into_owned();
            let mut sparse = Vfe::new(&x, vec![Some(vfe_tests::problem(30).1)], 8, config, None);
            let p = sparse.pack(&[short], &z);
            let (vs, _) = sparse.value_and_gradient(&p).expect("bound");
            assert!(vs > e + 1e-3, "sparse bound {vs} not above exact {e}");
        }
    }

    /// The stabilisation scales every eigenvalue of the autoregressive part by the same factor:
    /// an unstable second-order map (roots 1.2 and 0.5) becomes roots 0.99 and 0.4125, the input
    /// coefficients untouched; a stable one is left alone.
    #[test]
    fn an_unstable_linear_start_is_scaled_inside_the_unit_circle() {
        // y' = 1.7 y − 0.6 y₋₁ + 0.3 u: z² − 1.7 z + 0.6 = (z − 1.2)(z − 0.5)
        let mut a = DMatrix::from_row_slice(1, 3, &[1.7, -0.6, 0.3]);
        assert!((autoregressive_radius(&a, 2) - 1.2).abs() < 1e-12);
        let before = stabilize_linear_mean(&mut a, 2).expect("unstable");
        assert!((before - 1.2).abs() < 1e-12);
        let c = STABLE_RADIUS / 1.2;
        // (z − 1.2c)(z − 0.5c) = z² − 1.7c z + 0.6c²
        assert!((a[(0, 0)] - 1.7 * c).abs() < 1e-12 && (a[(0, 1)] + 0.6 * c * c).abs() < 1e-12);
        assert_eq!(a[(0, 2)], 0.3);
        assert!((autoregressive_radius(&a, 2) - STABLE_RADIUS).abs() < 1e-9);
        let mut stable = DMatrix::from_row_slice(1, 3, &[1.2, -0.35, 0.3]);
        let copy = stable.clone();
        assert_eq!(stabilize_linear_mean(&mut stable, 2), None);
        assert_eq!(stable, copy);
        // two outputs: a block companion; the coupling makes it unstable, the scaling fixes it
        let mut b = DMatrix::from_row_slice(2, 3, &[0.9, 0.5, 0.1, 0.4, 0.9, -0.2]);
        assert!(autoregressive_radius(&b, 1) > 1.0);
        stabilize_linear_mean(&mut b, 1).expect("unstable");
        assert!((autoregressive_radius(&b, 1) - STABLE_RADIUS).abs() < 1e-9);
    }

    /// A smooth multisine (`n` × 1): the inputs of a window are predictable from older ones, so
    /// older signals are strong instruments.
    fn multisine(n: usize) -> DMatrix<f64> {
        DMatrix::from_fn(n, 1, |t, _| {
            [(0.07, 0.3), (0.19, 1.1), (0.31, 2.0), (0.53, 0.7)]
                .iter()
                .map(|(w, phase)| (w * t as f64 + phase).sin())
                .sum::<f64>()
        })
    }

    /// A lightly damped resonance sampled fast, `y_{t+1} = 1.9 y_t − 0.95 y_{t−1} + 0.1 u_t`,
    /// measured with 20% noise: least squares turns the lag coefficients towards a random walk,
    /// the instruments recover them.
    #[test]
    fn instruments_remove_the_errors_in_variables_bias_of_the_linear_mean() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let mut rng = rand::rngs::StdRng::seed_from_u64(3);
        let n = 4000;
        let mut latent = vec![0.0; n];
        let u = multisine(n);
        for t in 1..n - 1 {
            latent[t + 1] = 1.9 * latent[t] - 0.95 * latent[t - 1] + 0.1 * u[(t, 0)];
        }
        let std = {
            let m = latent.iter().sum::<f64>() / n as f64;
            (latent.iter().map(|v| (v - m).powi(2)).sum::<f64>() / n as f64).sqrt()
        };
        let y = DMatrix::from_fn(n, 1, |t, _| {
            let z: f64 = StandardNormal.sample(&mut rng);
            latent[t] + 0.2 * std * z
        });
        let traj = Trajectory::new(u, y).expect("trajectory");
        let spec = NarxSpec::siso(2, 1);
        let data = one_step_pairs(&spec, &[&traj]).expect("pairs");
        assert_eq!(data.instrumented.len(), data.x.nrows() - 4);
        let mut log = JitterLog::default();
        let config = GpConfig::default();
        let iv = arx_linear_mean(&data, &config, &[], &mut log).expect("iv");
        let ls = {
            let plain = OneStepData {
                instrumented: Vec::new(),
                z: DMatrix::zeros(0, data.z.ncols()),
                ..data.clone()
            };
            arx_linear_mean(&plain, &config, &[], &mut log).expect("ls")
        };
        // 20% noise is enough to bias least squares by more than 0.1 on each lag
        assert!((ls[(0, 0)] - 1.9).abs() > 0.1, "{ls}");
        assert!((ls[(0, 1)] + 0.95).abs() > 0.1, "{ls}");
        assert!((iv[(0, 0)] - 1.9).abs() < 0.02, "{iv}");
        assert!((iv[(0, 1)] + 0.95).abs() < 0.02, "{iv}");
        assert!((iv[(0, 2)] - 0.1).abs() < 0.01, "{iv}");
    }

    /// Two outputs measured with noise: a resonance `y₀` and a double integrator `y₁` of the
    /// same input. With `y₁` declared integrating, its own-lag coefficients are exactly
    /// `[2, −1]`, `y₀`'s row ignores `y₁`, and the other coefficients are estimated around
    /// them.
    #[test]
    fn an_integrating_output_fixes_its_lags_and_fits_the_rest() {
        use crate::gp::integrator::Integrator;
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let mut rng = rand::rngs::StdRng::seed_from_u64(5);
        let n = 3000;
        let u = multisine(n);
        let mut latent = DMatrix::<f64>::zeros(n, 2);
        for t in 1..n - 1 {
            latent[(t + 1, 0)] = 1.9 * latent[(t, 0)] - 0.95 * latent[(t - 1, 0)] + 0.1 * u[(t, 0)];
            latent[(t + 1, 1)] = 2.0 * latent[(t, 1)] - latent[(t - 1, 1)] + 0.002 * u[(t, 0)];
        }
        let y = DMatrix::from_fn(n, 2, |t, j| {
            let z: f64 = StandardNormal.sample(&mut rng);
            latent[(t, j)] + [0.05, 0.01][j] * z
        });
        let traj = Trajectory::new(u, y).expect("trajectory");
        let spec = NarxSpec {
            ly: 2,
            lu: 1,
            dy: 2,
            du: 1,
        };
        let data = one_step_pairs(&spec, &[&traj]).expect("pairs");
        let fixed = Structure::new(
            &[Integrator {
                output: 1,
                order: 2,
                linear: false,
            }],
            &spec,
        )
        .fixed;
        let mut log = JitterLog::default();
        let config = GpConfig::default();
        let free = arx_linear_mean(&data, &config, &[], &mut log).expect("free");
        let a = arx_linear_mean(&data, &config, &fixed, &mut log).expect("fixed");
        let (y1, y1_lag1, u0) = (spec.y_index(0, 1), spec.y_index(1, 1), spec.u_index(0, 0));
        assert_eq!(a[(1, y1)], 2.0);
        assert_eq!(a[(1, y1_lag1)], -1.0);
        assert!((a[(1, u0)] - 0.002).abs() < 2e-4, "{a}");
        for k in [spec.y_index(0, 0), spec.y_index(1, 0)] {
            assert!(a[(1, k)].abs() < 0.02, "{a}");
        }
        // y₀'s row: zero on y₁'s lags, its own estimated as without the declaration
        assert_eq!(a[(0, y1)], 0.0);
        assert_eq!(a[(0, y1_lag1)], 0.0);
        for (k, truth) in [
            (spec.y_index(0, 0), 1.9),
            (spec.y_index(1, 0), -0.95),
            (u0, 0.1),
        ] {
            assert!((a[(0, k)] - truth).abs() < 0.02, "{a}");
            assert!((a[(0, k)] - free[(0, k)]).abs() < 0.01, "{a} vs {free}");
        }
    }

    fn problem() -> (DMatrix<f64>, DVector<f64>) {
        let x = DMatrix::from_fn(40, 3, |i, k| ((i * 7 + k * 3) as f64 * 0.37).sin());
        let y = DVector::from_fn(40, |i, _| {
            (x[(i, 0)] * 2.0).sin() + 0.3 * x[(i, 2)] + 0.05 * ((i as f64) * 1.3).cos()
        });
        (x, y)
    }

    fn check(pilco: bool) {
        let (x, y) = problem();
        let std: Vec<f64> = (0..3).map(|k| column_std(&x, k)).collect();
        let mut obj = Marginal::new(&x, y, GpConfig::default(), pilco.then_some(std));
        // near the penalties' active region for the PILCO case
        let p = vec![-0.3, 0.4, 4.0, 0.2, -3.0];
        let (_, g) = obj.value_and_gradient(&p).expect("value");
        for i in 0..p.len() {
            let h = 1e-4;
            let mut f = |d: f64| {
                let mut q = p.clone();
                q[i] += d;
                obj.value_and_gradient(&q).expect("value").0
            };
            let fd = (8.0 * (f(h) - f(-h)) - (f(2.0 * h) - f(-2.0 * h))) / (12.0 * h);
            assert!(
                (fd - g[i]).abs() <= 1e-6 * fd.abs().max(1.0),
                "param {i}: analytic {} vs fd {fd}",
                g[i]
            );
        }
    }

    #[test]
    fn outputs_fitted_on_two_threads_give_the_same_bits() {
        let (x, y0) = problem();
        let y = DMatrix::from_fn(x.nrows(), 3, |i, a| match a {
            0 => y0[i],
            1 => (x[(i, 1)] * 1.5).cos() - 0.2 * x[(i, 0)],
            _ => x[(i, 2)] * x[(i, 0)],
        });
        let data = OneStepData {
            x,
            y,
            instrumented: Vec::new(),
            z: DMatrix::zeros(0, 3),
            output_lags: 1,
        };
        let settings = OneStepSettings {
            iterations: 30,
            ..OneStepSettings::default()
        };
        let run_on = |data: &OneStepData, threads: usize| {
            let mut log = JitterLog::default();
            let settings = OneStepSettings {
                threads: Threads::new(threads).expect("threads"),
                ..settings
            };
            fit_one_step(
                data,
                12,
                &settings,
                &GpConfig::default(),
                &Structure::default(),
                4,
                &mut log,
            )
            .expect("fit")
        };
        let one = run_on(&data, 1).to_flat();
        for threads in [2, 3] {
            let p = run_on(&data, threads).to_flat();
            assert!(
                one.iter().zip(&p).all(|(a, b)| a.to_bits() == b.to_bits()),
                "{threads} threads"
            );
        }
        // each output's fit is its own: output 1 alone gives the same hyperparameters and
        // pseudo-targets as in the three-output fit on three threads
        let alone = OneStepData {
            y: data.y.columns(1, 1).into_owned(),
            ..data.clone()
        };
        let (p1, p3) = (run_on(&alone, 1), run_on(&data, 3));
        assert_eq!(p1.log_lengthscales.row(0), p3.log_lengthscales.row(1));
        assert_eq!(p1.log_signal_var[0], p3.log_signal_var[1]);
        assert_eq!(p1.log_process_noise[0], p3.log_process_noise[1]);
        assert_eq!(p1.pseudo_targets.column(0), p3.pseudo_targets.column(1));
        assert_ne!(p3.log_signal_var[0], p3.log_signal_var[1]);
    }

    #[test]
    fn marginal_likelihood_gradient_matches_finite_differences() {
        check(false);
        check(true);
    }

    #[test]
    fn one_step_pairs_follow_the_window_layout() {
        let t = Trajectory::siso(&[1.0, 2.0, 3.0, 4.0], &[10.0, 20.0, 30.0, 40.0]).expect("traj");
        let spec = NarxSpec::siso(2, 1);
        let d = one_step_pairs(&spec, &[&t]).expect("pairs");
        assert_eq!(d.x.nrows(), 2);
        assert_eq!(
            d.x.row(0).iter().copied().collect::<Vec<_>>(),
            vec![20.0, 10.0, 2.0]
        );
        assert_eq!(d.y[(0, 0)], 30.0);
    }
}
