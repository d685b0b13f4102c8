//! The adjoint (reverse-mode) sweep of a rollout, derived by hand, for f64: the one loop behind
//! the MSGP loss gradient ([`crate::loss`]) and the policy-search gradient
//! ([`crate::policy_search`]).
//!
//! Forward-mode duals cost about `P / LANES` loss evaluations; this sweep costs a small constant
//! number (a forward rollout that records the window state per step, then a backward pass that
//! recomputes each moment-matching step and pulls adjoints through it,
//! [`crate::moments`]' VJP), whatever the number of parameters. What each step's predicted
//! observation is scored by is a [`StepScore`]: the likelihood of the measured output (the MSGP
//! loss) or the expected saturating cost (PILCO). It is tested against the dual gradients
//! (`tests/adjoint_vs_dual.rs`), which are in turn tested against finite differences.

use nalgebra::{DMatrix, DVector};

use super::window::{Layout, StartState, gather, noisy_covariances};
use crate::error::{MsgpError, Result};
use crate::gp::PreparedGp;
use crate::moments::Moments;
use crate::moments::fast::MmState;
use crate::moments::mean::{add_linear_mean, linear_mean_backward};
use crate::moments::vjp::{BackWork, Backward, GpAdjoint};
use crate::narx::NarxSpec;
use crate::numeric::dual::{Dual, gradient, weighted_sum};
use crate::numeric::linalg::{JitterLog, JitterPolicy, symmetrize};
use crate::policy::{FeedbackPolicy, PolicyMoments};

/// One step's predicted observation `y_t ~ N(mean, cov)`, as a [`StepScore`] sees it.
pub(crate) struct Predicted<'a> {
    /// The time step.
    pub t: usize,
    /// `E[y_t]`.
    pub mean: &'a DVector<f64>,
    /// `Cov[y_t]` (noise included).
    pub cov: &'a DMatrix<f64>,
    /// The jitter policy of any factorisation of `cov`.
    pub jitter: &'a JitterPolicy,
}

/// What an adjoint rollout scores each predicted observation by, and that score's adjoint:
/// where a new per-step loss plugs into the sweep.
pub(crate) trait StepScore {
    /// The score of one step's prediction.
    fn value(&self, y: &Predicted<'_>, log: &mut JitterLog) -> Result<f64>;

    /// The gradient of [`value`](Self::value) with respect to `mean` and (symmetric) `cov`.
    fn vjp(&self, y: &Predicted<'_>) -> Result<(DVector<f64>, DMatrix<f64>)>;
}

/// One prediction step as the adjoint sweeps record it (the free run's here, the filter's in
/// [`crate::loss::filter`]'s gradient): the window predicted from, the moment-matching
/// intermediates and the moments of the new latent output. [`PredictRecord::forward`] computes
/// what [`super::window::predict_step`] does, bit for bit (the same kernel, in the same order).
pub(crate) struct PredictRecord {
    /// The window's mean (D).
    pub wmu: DVector<f64>,
    /// The window's covariance (D × D).
    pub wsig: DMatrix<f64>,
    /// The moment-matching intermediates (O(m·D) per step; `Q` is recomputed in the backward
    /// pass).
    pub cache: MmState,
    /// The GP's own `V` (without the linear mean).
    pub v_gp: DMatrix<f64>,
    /// `E[x_{t+1}]` (with the linear mean).
    pub mean: DVector<f64>,
    /// `V = Σ⁻¹ Cov(x̃_t, x_{t+1})` (with the linear mean).
    pub v: DMatrix<f64>,
    /// `Cov[x_{t+1}] = S + Σ_x`.
    pub xcov: DMatrix<f64>,
    /// `Cov[y_{t+1}] = S + Σ_x + Σ_y`.
    pub ycov: DMatrix<f64>,
}

impl PredictRecord {
    /// Moment-matches the GP (plus the linear prior mean) at the window `N(wmu, wsig)` and
    /// adds the noises, keeping what the backward pass needs.
    pub(crate) fn forward(
        gp: &PreparedGp<f64>,
        wmu: DVector<f64>,
        wsig: DMatrix<f64>,
        log: &mut JitterLog,
    ) -> Result<Self> {
        let (d, dy) = (wmu.len(), gp.output_dim());
        let mut mm = MmState::default();
        mm.forward(gp, &wmu, &wsig, log)?;
        let v_gp = DMatrix::from_fn(d, dy, |k, a| mm.outs[a].acc[k]);
        // the moments of f = A x̃ + g (the GP's own stay in the cache for the backward pass)
        let (mut fmean, mut fcov, mut v) = (mm.mean.clone(), mm.cov.clone(), v_gp.clone());
        if let Some(a) = &gp.linear_mean {
            let mut mom = Moments {
                mean: mm.mean.clone(),
                cov: mm.cov.clone(),
                io_cov: DMatrix::zeros(d, dy),
                v: v_gp.clone(),
            };
            add_linear_mean(a, &wmu, &wsig, &mut mom);
            (fmean, fcov, v) = (mom.mean, mom.cov, mom.v);
        }
        let (xcov, ycov) = noisy_covariances(gp, &fcov);
        Ok(Self {
            wmu,
            wsig,
            cache: mm,
            v_gp,
            mean: fmean,
            v,
            xcov,
            ycov,
        })
    }
}

/// The adjoints of one step's quantities, as a backward sweep accumulates them: the current
/// state `[x̃_t, p_t]` (n), the new latent output's mean, its covariance with and without
/// observation noise, and `V`.
pub(crate) struct StepBar {
    /// `μ̄` of the state (n).
    pub mubar: DVector<f64>,
    /// `Σ̄` of the state (n × n).
    pub sigmabar: DMatrix<f64>,
    /// `M̄` (d_y).
    pub mbar: DVector<f64>,
    /// Adjoint of `Cov[x_{t+1}]` (d_y × d_y).
    pub xcovbar: DMatrix<f64>,
    /// Adjoint of `Cov[y_{t+1}]` (d_y × d_y).
    pub ycovbar: DMatrix<f64>,
    /// `V̄` (D × d_y).
    pub vbar: DMatrix<f64>,
}

impl StepBar {
    /// All zero, for a state of `n` entries, a window of `d` and `dy` outputs.
    pub(crate) fn zeros(n: usize, d: usize, dy: usize) -> Self {
        Self {
            mubar: DVector::zeros(n),
            sigmabar: DMatrix::zeros(n, n),
            mbar: DVector::zeros(dy),
            xcovbar: DMatrix::zeros(dy, dy),
            ycovbar: DMatrix::zeros(dy, dy),
            vbar: DMatrix::zeros(d, dy),
        }
    }
}

/// The adjoint of [`gather`]: scatters the next state's `μ̄`, `Σ̄` (`sigmabar` symmetric) back
/// to the augmented vector of `len` entries.
pub(crate) fn gather_backward(
    sel: &[usize],
    len: usize,
    mubar: &DVector<f64>,
    sigmabar: &DMatrix<f64>,
) -> (DVector<f64>, DMatrix<f64>) {
    let n = sel.len();
    let mut amubar = DVector::<f64>::zeros(len);
    let mut acovbar = DMatrix::<f64>::zeros(len, len);
    for i in 0..n {
        amubar[sel[i]] += mubar[i];
        for j in 0..n {
            acovbar[(sel[i], sel[j])] += sigmabar[(i, j)];
        }
    }
    (amubar, acovbar)
}

/// The adjoint of [`Layout::augmented`] (`[z; x_{t+1}]`, `Cov(z, x) = Σ[:, :d] V`; `sigma`
/// the state's covariance): adds to `bar`'s state, mean, `Cov[x]` and `V` adjoints. The policy
/// slots' adjoints are the caller's.
pub(crate) fn augmented_backward(
    layout: &Layout,
    sigma: &DMatrix<f64>,
    v: &DMatrix<f64>,
    amubar: &DVector<f64>,
    acovbar: &DMatrix<f64>,
    bar: &mut StepBar,
) {
    let (n, x, d, dy) = (layout.n(), layout.x_slot(), layout.d, layout.dy);
    bar.mubar += amubar.rows(0, n);
    bar.mbar += amubar.rows(x, dy);
    bar.sigmabar += acovbar.view((0, 0), (n, n));
    let zxbar =
        acovbar.view((0, x), (n, dy)).into_owned() + acovbar.view((x, 0), (dy, n)).transpose();
    add_block(&mut bar.sigmabar, (0, 0), &(&zxbar * v.transpose()));
    bar.vbar += sigma.columns(0, d).transpose() * &zxbar;
    bar.xcovbar += acovbar.view((x, x), (dy, dy));
}

/// The adjoint of [`PredictRecord::forward`]: pulls `bar`'s `M̄`, `Cov[x]`, `Cov[y]` and `V̄`
/// back through the noises (to `adj.sx2`, `adj.sy2`), the linear mean and the moment matching
/// ([`Backward::pull`]), adding the window's `μ̄`, `Σ̄` to `bar`'s state adjoints.
pub(crate) fn predict_backward(
    gp: &PreparedGp<f64>,
    rec: &PredictRecord,
    bar: &mut StepBar,
    adj: &mut GpAdjoint,
    work: &mut BackWork,
) {
    let d = rec.wmu.len();
    bar.xcovbar += &bar.ycovbar;
    for j in 0..bar.mbar.len() {
        adj.sy2[j] += bar.ycovbar[(j, j)];
        adj.sx2[j] += bar.xcovbar[(j, j)];
    }
    let wsig = &rec.wsig;
    if let Some(a) = &gp.linear_mean {
        let lb = linear_mean_backward(
            a,
            &rec.wmu,
            wsig,
            &rec.v_gp,
            &bar.mbar,
            &bar.xcovbar,
            &bar.vbar,
        );
        adj.lin += &lb.a;
        for k in 0..d {
            bar.mubar[k] += lb.mu[k];
        }
        add_block(&mut bar.sigmabar, (0, 0), &lb.sigma);
        bar.vbar = lb.v;
    }
    let (mub, sigb) = Backward {
        gp,
        sigma: wsig,
        c: &rec.cache,
        mbar_in: &bar.mbar,
        sbar: &bar.xcovbar,
        vbar: &bar.vbar,
        adj,
        w: work,
    }
    .pull();
    for k in 0..d {
        bar.mubar[k] += mub[k];
    }
    add_block(&mut bar.sigmabar, (0, 0), &sigb);
}

/// What the forward rollout records per step.
struct StepRecord {
    /// The state's covariance `Cov[x̃_t, p_t]`.
    sigma: DMatrix<f64>,
    /// The prediction.
    pred: PredictRecord,
    /// Closed loop: policy input moments, the policy's output, and `Cov(z, q)`.
    policy: Option<PolicyRecord>,
}

struct PolicyRecord {
    qm: DVector<f64>,
    qc: DMatrix<f64>,
    pm: PolicyMoments<f64>,
    zq: DMatrix<f64>,
}

/// A policy's moment map in dual numbers, as a function of its parameters `θ` and of the
/// moments `(mean, cov)` of its input: `(θ, mean, cov) ↦ policy(θ).moments(mean, cov)`.
pub type DualPolicyMap<'a> =
    dyn Fn(&[Dual], &DVector<Dual>, &DMatrix<Dual>) -> Result<PolicyMoments<Dual>> + Sync + 'a;

/// A policy's vector–Jacobian product in closed form, `(q_m, q_c, ō_mean, ō_cov, C̄) ↦ (q̄_m,
/// q̄_c, θ̄)`: what `policy_vjp` computes by duals through a [`DualPolicyMap`].
pub type PolicyVjp<'a> = dyn Fn(
        &DVector<f64>,
        &DMatrix<f64>,
        &DVector<f64>,
        &DMatrix<f64>,
        &DMatrix<f64>,
    ) -> Result<(DVector<f64>, DMatrix<f64>, Vec<f64>)>
    + Sync
    + 'a;

/// The policy of a closed-loop adjoint rollout, and what the sweep differentiates it by.
pub(crate) struct AdjointPolicy<'a> {
    /// The policy at its current parameters.
    pub policy: &'a dyn FeedbackPolicy<f64>,
    /// The same policy's moment map in dual numbers (for the vector–Jacobian product of each
    /// step); `θ` may be empty (a fixed policy: the feedback episodes of a model fit).
    pub moments: &'a DualPolicyMap<'a>,
    /// The vector–Jacobian product in closed form, used instead of duals through `moments`
    /// when given.
    pub vjp: Option<&'a PolicyVjp<'a>>,
    /// The parameter values `θ`.
    pub theta: &'a [f64],
}

/// Vector–Jacobian product of a policy's moment map at `(qm, qc, θ)`: the gradient of
/// `⟨ō_mean, mean⟩ + ⟨ō_cov, cov⟩ + ⟨C̄, C⟩` with respect to every entry of `qm`, `qc` and `θ`,
/// in closed form when the policy has one ([`AdjointPolicy::vjp`]), else by forward-mode duals
/// (`n_q + n_q² + |θ|` directions).
fn policy_vjp(
    policy: &AdjointPolicy<'_>,
    rec: &PolicyRecord,
    mean_bar: &DVector<f64>,
    cov_bar: &DMatrix<f64>,
    c_bar: &DMatrix<f64>,
) -> Result<(DVector<f64>, DMatrix<f64>, Vec<f64>)> {
    if let Some(vjp) = policy.vjp {
        return vjp(&rec.qm, &rec.qc, mean_bar, cov_bar, c_bar);
    }
    let nq = rec.qm.len();
    let mut x: Vec<f64> = rec.qm.iter().copied().collect();
    x.extend(rec.qc.iter().copied());
    x.extend_from_slice(policy.theta);
    let active: Vec<usize> = (0..x.len()).collect();
    let (_, g) = gradient(&x, &active, 1, |xd: &[Dual]| {
        let qm = DVector::from_column_slice(&xd[..nq]);
        let qc = DMatrix::from_column_slice(nq, nq, &xd[nq..nq + nq * nq]);
        let pm = (policy.moments)(&xd[nq + nq * nq..], &qm, &qc)?;
        Ok(weighted_sum(&[
            (pm.mean.as_slice(), mean_bar.as_slice()),
            (pm.cov.as_slice(), cov_bar.as_slice()),
            (pm.c.as_slice(), c_bar.as_slice()),
        ]))
    })?;
    Ok((
        DVector::from_column_slice(&g[..nq]),
        DMatrix::from_column_slice(nq, nq, &g[nq..nq + nq * nq]),
        g[nq + nq * nq..].to_vec(),
    ))
}

/// What [`rollout_adjoint`] returns.
pub(crate) struct RolloutAdjoint {
    /// Σ of the step scores.
    pub total: f64,
    /// Number of scored steps.
    pub steps: usize,
    /// Gradient with respect to the policy's parameters `θ`.
    pub theta: Vec<f64>,
    /// Adjoint of the start state's covariance.
    pub start_cov: DMatrix<f64>,
}

/// The adjoint sweep of one rollout from `start` over `t0..horizon`: a forward pass that records
/// every step, then a backward pass that pulls the step losses' adjoints back through the
/// moment matching, the window shift and (closed loop) the policy. Open loop (no `policy`) it
/// follows `inputs` (rows are absolute time steps). Each step's predicted observation is scored
/// by `score`. Adds the GP adjoints to `adj`.
#[allow(clippy::too_many_arguments)]
pub(crate) fn rollout_adjoint(
    gp: &PreparedGp<f64>,
    spec: &NarxSpec,
    start: &StartState<f64>,
    score: &dyn StepScore,
    inputs: Option<&DMatrix<f64>>,
    policy: Option<&AdjointPolicy<'_>>,
    t0: usize,
    horizon: usize,
    adj: &mut GpAdjoint,
    log: &mut JitterLog,
) -> Result<RolloutAdjoint> {
    let d = spec.input_dim();
    let (dy, du) = (spec.dy, spec.du);
    let ds = policy.map_or(0, |p| p.policy.state_dim());
    let layout = Layout { d, ds, dy, du };
    let (n, x, u) = (layout.n(), layout.x_slot(), layout.u_slot());
    let len = layout.len();
    let sel = layout.gather_map(spec);
    if start.mean.len() != n || start.cov.shape() != (n, n) {
        return Err(MsgpError::Shape(format!(
            "start state has {} entries; window and policy state need {n}",
            start.mean.len()
        )));
    }
    if horizon <= t0 {
        return Err(MsgpError::Shape(format!(
            "an adjoint rollout over {t0}..{horizon} has no step"
        )));
    }
    // open loop the inputs come from the measured trajectory
    if policy.is_none() && inputs.is_none() {
        return Err(MsgpError::Shape(
            "an expected-cost rollout needs a policy to produce its inputs".into(),
        ));
    }
    let mut mu = start.mean.clone();
    let mut sigma = start.cov.clone();
    let mut theta_bar = vec![0.0; policy.map_or(0, |p| p.theta.len())];
    // forward
    let mut recs: Vec<StepRecord> = Vec::with_capacity(horizon - t0);
    let mut total = 0.0;
    let mut nll_log = JitterLog::default();
    for t in t0..horizon {
        let wsig = sigma.view((0, 0), (d, d)).into_owned();
        let wmu = mu.rows(0, d).into_owned();
        let pred = PredictRecord::forward(gp, wmu, wsig, log)?;
        let predicted = Predicted {
            t,
            mean: &pred.mean,
            cov: &pred.ycov,
            jitter: &gp.jitter,
        };
        total += score.value(&predicted, &mut nll_log)?;
        if !total.is_finite() {
            return Err(MsgpError::NonFinite(format!("rollout loss at step {t}")));
        }
        let mut rec = StepRecord {
            sigma: sigma.clone(),
            pred,
            policy: None,
        };
        if t + 1 < horizon {
            let PredictRecord {
                mean,
                v,
                xcov,
                ycov,
                ..
            } = &rec.pred;
            let (mut amu, mut acov) = layout.augmented(&mu, &sigma, mean, v, xcov);
            match policy {
                None => {
                    if let Some(inputs) = inputs {
                        layout.set_measured_input(&mut amu, inputs, t);
                    }
                }
                Some(p) => {
                    let (qm, qc) = layout.policy_input(&amu, &acov, ycov);
                    let pm = p.policy.moments(&qm, &qc)?;
                    let mut zq = DMatrix::<f64>::zeros(u, dy + ds);
                    zq.view_mut((0, 0), (u, dy))
                        .copy_from(&acov.view((0, x), (u, dy)));
                    zq.view_mut((0, dy), (u, ds))
                        .copy_from(&acov.view((0, d), (u, ds)));
                    layout.set_policy_output(&mut amu, &mut acov, &pm);
                    rec.policy = Some(PolicyRecord { qm, qc, pm, zq });
                }
            }
            (mu, sigma) = gather(&amu, &acov, &sel);
        }
        recs.push(rec);
    }
    log.merge(&nll_log);

    // backward
    let mut work = BackWork::default();
    let mut mubar_next = DVector::<f64>::zeros(n);
    let mut sigmabar_next = DMatrix::<f64>::zeros(n, n);
    let last = recs.len() - 1;
    for (s, rec) in recs.iter().enumerate().rev() {
        let mut bar = StepBar::zeros(n, d, dy);
        if s < last {
            symmetrize(&mut sigmabar_next);
            let (mut amubar, mut acovbar) = gather_backward(&sel, len, &mubar_next, &sigmabar_next);
            if let (Some(pr), Some(pa)) = (&rec.policy, policy) {
                let no = du + ds;
                // set_policy_output: mean, cov, and cross = Z_q C
                let mean_bar = amubar.rows(u, no).into_owned();
                let cov_bar = acovbar.view((u, u), (no, no)).into_owned();
                let cross_bar = acovbar.view((0, u), (u, no)).into_owned()
                    + acovbar.view((u, 0), (no, u)).transpose();
                let zq_bar = &cross_bar * pr.pm.c.transpose();
                let c_bar = pr.zq.transpose() * &cross_bar;
                add_block(&mut acovbar, (0, x), &zq_bar.columns(0, dy).into_owned());
                add_block(&mut acovbar, (0, d), &zq_bar.columns(dy, ds).into_owned());
                // the policy's own moment map
                let (qm_bar, qc_bar, th_bar) = policy_vjp(pa, pr, &mean_bar, &cov_bar, &c_bar)?;
                for (acc, g) in theta_bar.iter_mut().zip(&th_bar) {
                    *acc += g;
                }
                // policy_input: q = [y_{t+1}; p_t]
                for k in 0..dy {
                    amubar[x + k] += qm_bar[k];
                }
                for k in 0..ds {
                    amubar[d + k] += qm_bar[dy + k];
                }
                bar.ycovbar += qc_bar.view((0, 0), (dy, dy));
                add_block(
                    &mut acovbar,
                    (x, d),
                    &qc_bar.view((0, dy), (dy, ds)).into_owned(),
                );
                add_block(
                    &mut acovbar,
                    (d, x),
                    &qc_bar.view((dy, 0), (ds, dy)).into_owned(),
                );
                add_block(
                    &mut acovbar,
                    (d, d),
                    &qc_bar.view((dy, dy), (ds, ds)).into_owned(),
                );
            }
            augmented_backward(
                &layout,
                &rec.sigma,
                &rec.pred.v,
                &amubar,
                &acovbar,
                &mut bar,
            );
        }
        let (gm, gc) = score.vjp(&Predicted {
            t: t0 + s,
            mean: &rec.pred.mean,
            cov: &rec.pred.ycov,
            jitter: &gp.jitter,
        })?;
        bar.mbar += gm;
        bar.ycovbar += gc;
        predict_backward(gp, &rec.pred, &mut bar, adj, &mut work);
        mubar_next = bar.mubar;
        sigmabar_next = bar.sigmabar;
    }
    Ok(RolloutAdjoint {
        total,
        steps: recs.len(),
        theta: theta_bar,
        start_cov: sigmabar_next,
    })
}

/// `m[at..] += b` for a block.
pub(crate) fn add_block(m: &mut DMatrix<f64>, at: (usize, usize), b: &DMatrix<f64>) {
    for i in 0..b.nrows() {
        for j in 0..b.ncols() {
            m[(at.0 + i, at.1 + j)] += b[(i, j)];
        }
    }
}
