//! The GP's uncertainty about its own function, kept correlated over a free simulation.
//!
//! Moment matching (paper section 3.3, [`super::forward`]) draws the latent function afresh at
//! every step: the GP's uncertainty about `f` at the window enters each step's variance as if
//! it were fresh process noise. A fitted model is *one* function, wrong in the same way every
//! time the window comes back to the same region. Under an input that dwells (a held level, a
//! slow sine) the same error repeats and the plant's dynamics sum it: with a static gain of 10
//! the mean's error is 10× the function's, while independent draws grow the standard deviation
//! by only `√(Σ_k g_k²)` (about 2.9× for the same plant). Coverage on such inputs collapses
//! although the model is as good as its data allow (synthetic system 4 in the generalisation
//! table: 2σ coverage 0.44–0.88 on held levels and slow sines).
//!
//! The fitted GP is the posterior given its pseudo-data `(X̄, ȳ)` with noise `σ_x²`. With the
//! linear prior mean its coefficients are uncertain too, under a vague prior (variance 100 per
//! coefficient, normalised units). The function's posterior covariance between two windows is
//! then (Rasmussen & Williams, eq. 2.41)
//! `C(x, x') = k(x, x') − k(x, X̄) K̃⁻¹ k(X̄, x') + R(x)ᵀ Σ_A R(x')`,
//! `R(x) = x − X̄ᵀ K̃⁻¹ k(X̄, x)`, `Σ_A = (X̄ᵀ K̃⁻¹ X̄ + 10⁻² I)⁻¹` — the same posterior whose
//! variance moment matching uses at each step (the last term, which it does not have, aside).
//!
//! Each step's function value, taken at the window's mean, is a perturbation `δf_s` of the
//! rollout's mean, and `Cov(δf_s, δf_{s'}) = C(x_s, x_{s'})`. Its effect on later means is
//! carried forward to first order with the window's covariance held at the moment-matching
//! values: `∂M/∂μ = V` (the moments' `Σ⁻¹ Cov[x̃, f]`, by Stein's lemma `E[∇f]`), so the window's
//! tangent `G` (D × past steps) shifts with the window and each new output adds its own step;
//! inputs, measured, have none. The variance of the mean's error is
//! `Var(δμ_t) = Σ_{s,s'} G_{t,s} G_{t,s'} C(x_s, x_{s'})`, kept by a recursion over the
//! window's covariance and its covariance with each new step's function value. Moment matching
//! has already counted each step's own function variance once, as independent noise: the same
//! recursion with the diagonal `C_GP(x_s, x_s)` only is subtracted, so what is added to
//! `Var[y_t]` is `max(0, ·)` of the cross terms `s ≠ s'` plus the linear mean's part — what
//! the correlation adds. On a white-noise input the cross terms nearly cancel; on a held input
//! they dominate, and far outside the data they approach `(Σ_s G_{t,s})² σ_f²`: the model does
//! not know its function there, and says so. Steps whose tangent has decayed below 10⁻⁸ of a
//! fresh one's are dropped from the sums (a stable plant forgets them), so the cost per step
//! is the number of steps still remembered times `m + D`.
//!
//! It widens the reported outputs of open-loop free simulations only and is never fed back: no
//! mean moves, so no RMSE does; the training loss, filtered predictions and closed-loop
//! rollouts (policy search) keep the paper's moment matching. [`crate::model::Rollout`]
//! `MomentMatchingIndependent` simulates without it.

use nalgebra::{DMatrix, DVector};

use super::forward::{Control, StepPrediction, Widen, rollout_started};
use super::window::initial_window;
use crate::data::Trajectory;
use crate::error::{MsgpError, Result};
use crate::gp::PreparedGp;
use crate::gp::kernel::{kernel_matrix, se_ard};
use crate::moments::Moments;
use crate::narx::NarxSpec;
use crate::narx::start_window::StartWindow;
use crate::numeric::linalg::JitterLog;

/// Prior precision of each linear-mean coefficient (normalised units): variance 100.
pub const LINEAR_PRIOR_PRECISION: f64 = 1e-2;

/// A step's tangent norm (against a fresh step's 1) below which it is dropped from the sums.
const FORGOTTEN: f64 = 1e-8;

/// The posterior of a GP's function given its pseudo-data (and, with the linear mean, of its
/// coefficients): the covariance `C(x, x')` of the module docs, per output. The GP's own
/// factors (`K̃⁻¹`, length-scales, `σ_f²`) are read from it; only the linear mean's are added.
#[derive(Clone, Debug)]
pub struct FunctionPosterior<'a> {
    gp: &'a PreparedGp<f64>,
    /// Per output, with the linear mean: `K̃⁻¹ X̄` (m × D) and `L` (D × D) with `L Lᵀ = Σ_A`.
    linear: Vec<Option<(DMatrix<f64>, DMatrix<f64>)>>,
}

/// What the covariance needs of one window, for one output.
#[derive(Clone, Debug)]
struct Point {
    x: DVector<f64>,
    /// `k(X̄, x)`.
    k: DVector<f64>,
    /// `K̃⁻¹ k(X̄, x)`.
    kk: DVector<f64>,
    /// `Lᵀ R(x)` (empty without the linear mean).
    lr: DVector<f64>,
    /// `C_GP(x, x) = σ_f² − kᵀ K̃⁻¹ k`.
    gp_var: f64,
}

impl<'a> FunctionPosterior<'a> {
    /// The posterior of `gp`'s function.
    pub fn new(gp: &'a PreparedGp<f64>) -> Result<Self> {
        let z = &gp.pseudo_inputs;
        let d = z.ncols();
        let mut linear = Vec::with_capacity(gp.outputs.len());
        for (a, o) in gp.outputs.iter().enumerate() {
            if gp.linear_mean.is_none() {
                linear.push(None);
                continue;
            }
            let w = &o.kinv * z; // m × D
            let mut prec = z.transpose() * &w;
            for i in 0..d {
                prec[(i, i)] += LINEAR_PRIOR_PRECISION;
            }
            let prec = (&prec + prec.transpose()) * 0.5;
            let not_pd = |what: &str| {
                MsgpError::NonFinite(format!(
                    "the linear mean's {what} from the pseudo-data of output {a}"
                ))
            };
            let cov = prec
                .cholesky()
                .ok_or_else(|| not_pd("precision"))?
                .inverse();
            let cov = (&cov + cov.transpose()) * 0.5;
            let l = cov.cholesky().ok_or_else(|| not_pd("covariance"))?.l();
            linear.push(Some((w, l)));
        }
        Ok(Self { gp, linear })
    }

    fn point(&self, a: usize, x: &DVector<f64>) -> Point {
        let o = &self.gp.outputs[a];
        let xr = DMatrix::from_row_slice(1, x.len(), x.as_slice());
        let k = DVector::from_column_slice(
            kernel_matrix(&self.gp.pseudo_inputs, &xr, &o.inv_l2, o.sf2).as_slice(),
        );
        let kk = &o.kinv * &k;
        let lr = match &self.linear[a] {
            Some((w, l)) => l.tr_mul(&(x - w.tr_mul(&k))),
            None => DVector::zeros(0),
        };
        let gp_var = o.sf2 - k.dot(&kk);
        Point {
            x: x.clone(),
            k,
            kk,
            lr,
            gp_var,
        }
    }

    /// `C_GP(x, x')` of output `a` between two points: the SE kernel's posterior part.
    fn gp_cov(&self, a: usize, p: &Point, q: &Point) -> f64 {
        let o = &self.gp.outputs[a];
        se_ard(p.x.as_slice(), q.x.as_slice(), &o.inv_l2, o.sf2) - p.k.dot(&q.kk)
    }

    /// `C(x, x')` of output `a` between two points, the linear mean's part included.
    fn cov(&self, a: usize, p: &Point, q: &Point) -> f64 {
        self.gp_cov(a, p, q) + p.lr.dot(&q.lr)
    }

    /// `C(x, x')` of output `a`: the posterior covariance of its function at two windows
    /// (normalised units), the linear mean's uncertainty included.
    pub fn covariance(&self, a: usize, x: &DVector<f64>, x2: &DVector<f64>) -> f64 {
        self.cov(a, &self.point(a, x), &self.point(a, x2))
    }
}

/// The first-order spread of the rollout's mean under the function's posterior, carried along
/// an open-loop rollout.
pub(crate) struct Tangents<'a> {
    post: &'a FunctionPosterior<'a>,
    spec: &'a NarxSpec,
    /// The steps still remembered: output and window.
    steps: Vec<(usize, Point)>,
    /// `∂μ_window / ∂δf_s` for each remembered step (D × steps).
    g: DMatrix<f64>,
    /// `Var(δμ_window)` (D × D).
    var: DMatrix<f64>,
    /// The same with each step's own `C_GP` only (independent draws, D × D).
    indep: DMatrix<f64>,
}

impl<'a> Tangents<'a> {
    /// Zero tangents: the start window is measured, not predicted.
    pub(crate) fn new(post: &'a FunctionPosterior<'a>, spec: &'a NarxSpec) -> Self {
        let d = spec.input_dim();
        Self {
            post,
            spec,
            steps: Vec::new(),
            g: DMatrix::zeros(d, 0),
            var: DMatrix::zeros(d, d),
            indep: DMatrix::zeros(d, d),
        }
    }

    /// One step at the window whose mean is `mu` and moments `mm`: the variance the
    /// correlation adds to each output; the tangents move on to the next window.
    pub(crate) fn step(&mut self, mu: &DVector<f64>, mm: &Moments<f64>) -> DVector<f64> {
        let (d, dy) = (self.spec.input_dim(), self.spec.dy);
        let points: Vec<Point> = (0..dy).map(|a| self.post.point(a, mu)).collect();
        // p_a = Cov(δμ_window, δf_a at this window)
        let mut p = DMatrix::zeros(d, dy);
        for (j, (a, q)) in self.steps.iter().enumerate() {
            let c = self.post.cov(*a, q, &points[*a]);
            if c != 0.0 {
                let mut col = p.column_mut(*a);
                col.axpy(c, &self.g.column(j), 1.0);
            }
        }
        let v = &mm.v; // D × E
        let vv = &self.var * v;
        let cross = v.tr_mul(&p);
        let mut full = v.tr_mul(&vv) + &cross + cross.transpose();
        let iv = &self.indep * v;
        let mut ind = v.tr_mul(&iv);
        for (a, q) in points.iter().enumerate() {
            full[(a, a)] += q.gp_var + q.lr.norm_squared();
            ind[(a, a)] += q.gp_var;
        }
        let added = DVector::from_fn(dy, |a, _| (full[(a, a)] - ind[(a, a)]).max(0.0));
        // the new outputs' tangents: through the window, and their own step
        let mut out_g = v.tr_mul(&self.g).insert_columns(self.g.ncols(), dy, 0.0);
        for a in 0..dy {
            out_g[(a, self.g.ncols() + a)] = 1.0;
        }
        self.steps.extend(points.into_iter().enumerate());
        self.shift(&out_g, &(vv + p), &full, &iv, &ind);
        self.forget();
        added
    }

    /// Moves the window one step on: the new outputs enter at lag 0, the oldest drop out,
    /// inputs (measured) carry no tangent. `wf`/`wi`: the window's covariance with the new
    /// outputs, `full`/`ind`: theirs, with and without the correlation.
    fn shift(
        &mut self,
        out_g: &DMatrix<f64>,
        wf: &DMatrix<f64>,
        full: &DMatrix<f64>,
        wi: &DMatrix<f64>,
        ind: &DMatrix<f64>,
    ) {
        let spec = self.spec;
        let d = spec.input_dim();
        // source of each new window entry in [window (D), new outputs (d_y)], None for inputs
        let src: Vec<Option<usize>> = (0..d)
            .map(|i| {
                (i < spec.ly * spec.dy).then(|| {
                    let (k, j) = (i / spec.dy, i % spec.dy);
                    if k == 0 {
                        d + j
                    } else {
                        spec.y_index(k - 1, j)
                    }
                })
            })
            .collect();
        let aug = |win: &DMatrix<f64>, w_out: &DMatrix<f64>, out: &DMatrix<f64>| {
            let at = |s: usize, s2: usize| match (s >= d, s2 >= d) {
                (false, false) => win[(s, s2)],
                (false, true) => w_out[(s, s2 - d)],
                (true, false) => w_out[(s2, s - d)],
                (true, true) => out[(s - d, s2 - d)],
            };
            DMatrix::from_fn(d, d, |i, i2| match (src[i], src[i2]) {
                (Some(s), Some(s2)) => at(s, s2),
                _ => 0.0,
            })
        };
        let var = aug(&self.var, wf, full);
        let indep = aug(&self.indep, wi, ind);
        let n = out_g.ncols();
        let mut g = DMatrix::zeros(d, n);
        for i in 0..d {
            match src[i] {
                Some(s) if s >= d => g.row_mut(i).copy_from(&out_g.row(s - d)),
                Some(s) => g
                    .row_mut(i)
                    .columns_mut(0, self.g.ncols())
                    .copy_from(&self.g.row(s)),
                None => {}
            }
        }
        self.var = var;
        self.indep = indep;
        self.g = g;
    }

    /// Drops the steps whose tangent has decayed below [`FORGOTTEN`].
    fn forget(&mut self) {
        let keep: Vec<bool> = (0..self.steps.len())
            .map(|j| self.g.column(j).norm() >= FORGOTTEN)
            .collect();
        if keep.iter().all(|k| *k) {
            return;
        }
        let mut flags = keep.iter();
        self.steps
            .retain(|_| flags.next().copied().unwrap_or(false));
        let columns: Vec<usize> = (0..keep.len()).filter(|&j| keep[j]).collect();
        self.g = self.g.select_columns(columns.iter());
    }
}

impl Widen<f64> for Tangents<'_> {
    fn widen(
        &mut self,
        mu: &DVector<f64>,
        mm: &Moments<f64>,
        ycov: &mut DMatrix<f64>,
    ) -> Result<()> {
        let added = self.step(mu, mm);
        for (j, v) in added.iter().enumerate() {
            if !v.is_finite() {
                return Err(MsgpError::NonFinite(
                    "the correlated function uncertainty of a free simulation".into(),
                ));
            }
            ycov[(j, j)] += v;
        }
        Ok(())
    }
}

/// Open-loop free simulation of `traj` (normalised units) to `horizon` whose reported output
/// variances include the correlated function uncertainty (see the module docs); the means are
/// moment matching's.
pub fn simulate_correlated(
    gp: &PreparedGp<f64>,
    spec: &NarxSpec,
    traj: &Trajectory,
    horizon: usize,
    log: &mut JitterLog,
) -> Result<Vec<StepPrediction<f64>>> {
    let post = FunctionPosterior::new(gp)?;
    let mut tangents = Tangents::new(&post, spec);
    let mut out = Vec::with_capacity(horizon.saturating_sub(spec.warmup()));
    rollout_started(
        gp,
        spec,
        traj,
        &Control::FeedForward,
        horizon,
        StartWindow::Measured,
        log,
        Some(&mut tangents),
        |p| {
            out.push(p);
            Ok(())
        },
    )?;
    Ok(out)
}

/// The jitter (per unit of the larger of `σ_f²` and the value's own variance) on the
/// covariance of a sampled path's function values.
const SAMPLE_JITTER: f64 = 1e-6;

/// How a sampled free run draws the GP's function ([`sample_free_runs`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum FunctionDraws {
    /// One whole function per path: each value conditioned on the values the path drew before
    /// (what the model believes; [`simulate_correlated`] approximates its spread).
    Whole,
    /// A fresh, independent value at every step (the paper's moment matching's picture).
    PerStep,
}

/// Free simulations of `traj`'s inputs (normalised units) up to `horizon`, each drawing the
/// function from the posterior of the module docs as `draws` says, with its own process noise:
/// the Monte Carlo reference of [`simulate_correlated`] (whole functions) and of the paper's
/// moment matching (per-step draws). A path draws its function where it goes: at each window,
/// conditioned on the values it drew at the windows it visited before (a Cholesky factor of
/// their covariance, grown by a row per step), plus `σ_x²` noise fed back as the rollout's
/// latent state is; its start window is drawn from the rollout's (the measured outputs with
/// their observation noise `σ_y²`, or the smoothed start's). Returns each path's latent
/// outputs, without observation noise (steps × d_y, the first row at the rollout's first
/// step); their spread plus `σ_y²` is what a rollout's reported variance approximates. The cost
/// per path grows with the cube of the steps.
pub fn sample_free_runs<R: rand::Rng + ?Sized>(
    gp: &PreparedGp<f64>,
    spec: &NarxSpec,
    traj: &Trajectory,
    horizon: usize,
    paths: usize,
    draws: FunctionDraws,
    rng: &mut R,
) -> Result<Vec<DMatrix<f64>>> {
    use rand_distr::{Distribution, StandardNormal};
    let post = FunctionPosterior::new(gp)?;
    let horizon = horizon.min(traj.len());
    // the rollout's Gaussian start window: its output lags drawn with it
    let first = initial_window(gp, spec, traj, gp.start)?;
    let t0 = first.t0;
    if horizon <= t0 {
        return Err(MsgpError::Data(format!(
            "a simulation needs more than {t0} samples, got {horizon}"
        )));
    }
    let lags = first
        .pattern
        .clone()
        .cholesky()
        .or_else(|| (&first.pattern + DMatrix::identity(spec.ly, spec.ly) * 1e-12).cholesky())
        .ok_or_else(|| MsgpError::NonFinite("the start window's covariance".into()))?
        .l();
    let mut out = Vec::with_capacity(paths);
    for _ in 0..paths {
        let mut y = traj.y.rows(0, horizon).into_owned();
        for j in 0..spec.dy {
            let z = DVector::from_fn(spec.ly, |_, _| StandardNormal.sample(rng));
            let e = &lags * z * gp.outputs[j].sy2.sqrt();
            for k in 0..spec.ly {
                y[(t0 - 1 - k, j)] = first.mean[spec.y_index(k, j)] + e[k];
            }
        }
        // per output: the windows visited, the rows of the Cholesky factor of their
        // covariance, and the standard normal draws that made the function's values there
        let mut visited: Vec<Vec<Point>> = vec![Vec::new(); spec.dy];
        let mut chol: Vec<Vec<Vec<f64>>> = vec![Vec::new(); spec.dy];
        let mut normals: Vec<Vec<f64>> = vec![Vec::new(); spec.dy];
        for t in t0..horizon {
            let x = DVector::from_vec(spec.window(&y, &traj.u, t - 1));
            for a in 0..spec.dy {
                let p = post.point(a, &x);
                // the posterior mean (eq. 13) from the point's own kernel vector
                let mean = p.k.dot(&gp.outputs[a].beta)
                    + gp.linear_mean
                        .as_ref()
                        .map_or(0.0, |lm| lm.row(a).dot(&x.transpose()));
                // (a path that settles visits nearly the same window again and again: the
                // covariance of its values is nearly singular, and a jitter of 10⁻⁶ of the
                // larger of σ_f² and the value's own variance keeps the factor's pivots away from
                // rounding noise; at 10⁻⁸ and below, rounding blows a few paths up)
                let own = post.cov(a, &p, &p).max(0.0);
                let jitter = SAMPLE_JITTER * gp.outputs[a].sf2.max(own);
                let scale = own + jitter;
                // the new row `l` of the factor: `L l = C(X_visited, x)`
                let mut row = Vec::with_capacity(visited[a].len() + 1);
                for (i, q) in visited[a].iter().enumerate() {
                    let r = &chol[a][i];
                    let s = post.cov(a, q, &p)
                        - r[..i].iter().zip(&row).map(|(u, v)| u * v).sum::<f64>();
                    row.push(s / r[i]);
                }
                let rest = scale - row.iter().map(|v| v * v).sum::<f64>();
                row.push(rest.max(jitter).sqrt());
                let z: f64 = StandardNormal.sample(rng);
                normals[a].push(z);
                let f = mean + row.iter().zip(&normals[a]).map(|(l, z)| l * z).sum::<f64>();
                match draws {
                    FunctionDraws::Whole => {
                        chol[a].push(row);
                        visited[a].push(p);
                    }
                    FunctionDraws::PerStep => normals[a].clear(),
                }
                let e: f64 = StandardNormal.sample(rng);
                let value = f + gp.outputs[a].sx2.sqrt() * e;
                if !value.is_finite() {
                    return Err(MsgpError::NonFinite(format!(
                        "a sampled free simulation: output {a} at step {t}"
                    )));
                }
                y[(t, a)] = value;
            }
        }
        out.push(y.rows(t0, horizon - t0).into_owned());
    }
    Ok(out)
}

#[cfg(test)]
mod tests;
