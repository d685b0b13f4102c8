//! Reverse-mode (adjoint) gradient of the MSGP loss, derived by hand, for f64.
//!
//! Forward-mode duals cost about `P / LANES` loss evaluations; this sweep costs a small constant
//! number (a forward rollout that records the window state per step, then a backward pass that
//! recomputes each moment-matching step and pulls adjoints through it), whatever the number of
//! parameters. It is tested against the dual gradients (`tests/adjoint_vs_dual.rs`), which are
//! in turn tested against finite differences.
//!
//! Notation follows [`crate::moments`]: for output `a`, `s = Λ_a^{-½}` (as a vector),
//! `Ŝ = I + diag(s) Σ diag(s)`, `Ŵ = Ŝ⁻¹ diag(s) νᵀ`, `q_i = σ_f² |Ŝ|^{-½} exp(−½ ν̃_iᵀŴ_i)`;
//! for a pair `(a, b)`, `p = Λ_a⁻¹ + Λ_b⁻¹`, `S̃ = I + diag(√p) Σ diag(√p)`, `N = I − S̃⁻¹`,
//! `Ã = diag(Λ_a⁻¹/√p) νᵀ`, `B̃ = diag(Λ_b⁻¹/√p) νᵀ` and
//! `Q_ij = exp(lk^a_i + lk^b_j − ½ log|S̃| + ½ (Ã_i + B̃_j)ᵀ N (Ã_i + B̃_j))`.

use nalgebra::{DMatrix, DVector};

use crate::error::{MsgpError, Result};
use crate::gp::{GpConfig, GpParams, GpShape, ParamGroup, PreparedGp};
use crate::grad::dual::{Dual, gradient};
use crate::kernel::kernel_matrix;
use crate::linalg::{JitterLog, cholesky, symmetrize};
use crate::loss::{Complexity, LossValue, complexity_term, gaussian_nll};
use crate::mean_fn::{add_linear_mean, linear_mean_backward};
use crate::moments::Moments;
use crate::narx::NarxSpec;
use crate::policy::{FeedbackPolicy, PolicyMoments, PolicySpec};
use crate::rollout::{Layout, gather, initial_window, noisy_covariances};
use crate::trajectory::{Episode, Excitation, Trajectory};

/// Adjoint accumulators for the quantities the rollout reads from the prepared GP.
struct GpAdjoint {
    xbar: DMatrix<f64>,      // m × D (pseudo-inputs, direct)
    beta: Vec<DVector<f64>>, // per output
    kinv: Vec<DMatrix<f64>>, // per output
    inv_l2: DMatrix<f64>,    // E × D
    sf2: Vec<f64>,
    sx2: Vec<f64>,
    sy2: Vec<f64>,
    lin: DMatrix<f64>, // E × D (linear prior mean)
}

impl GpAdjoint {
    fn zeros(m: usize, d: usize, e: usize) -> Self {
        Self {
            xbar: DMatrix::zeros(m, d),
            beta: vec![DVector::zeros(m); e],
            kinv: vec![DMatrix::zeros(m, m); e],
            inv_l2: DMatrix::zeros(e, d),
            sf2: vec![0.0; e],
            sx2: vec![0.0; e],
            sy2: vec![0.0; e],
            lin: DMatrix::zeros(e, d),
        }
    }
}

struct OutCache {
    s: Vec<f64>,
    shat_inv: DMatrix<f64>,
    nut: DMatrix<f64>, // D × m
    w: DMatrix<f64>,   // D × m
    q: DVector<f64>,
    bq: DVector<f64>,
    acc: DVector<f64>,
    lk: DVector<f64>,
}

struct PairCache {
    a: usize,
    b: usize,
    sp: Vec<f64>,
    st_inv: DMatrix<f64>,
    n: DMatrix<f64>,
    at: DMatrix<f64>, // D × m
    bt: DMatrix<f64>, // D × m
    y: DMatrix<f64>,  // N B̃
    q: DMatrix<f64>,  // m × m
}

struct MmCache {
    nu: DMatrix<f64>, // m × D
    outs: Vec<OutCache>,
    pairs: Vec<PairCache>,
    mean: DVector<f64>,
    cov: DMatrix<f64>,
}

fn scaled_plus_identity(sigma: &DMatrix<f64>, p: &[f64]) -> DMatrix<f64> {
    let d = sigma.nrows();
    DMatrix::from_fn(d, d, |i, j| {
        p[i] * sigma[(i, j)] * p[j] + if i == j { 1.0 } else { 0.0 }
    })
}

fn mm_forward(
    gp: &PreparedGp<f64>,
    mu: &DVector<f64>,
    sigma: &DMatrix<f64>,
    log: &mut JitterLog,
) -> Result<MmCache> {
    let x = &gp.pseudo_inputs;
    let (m, d) = (x.nrows(), x.ncols());
    let e = gp.output_dim();
    let nu = DMatrix::from_fn(m, d, |i, k| x[(i, k)] - mu[k]);
    let mut outs = Vec::with_capacity(e);
    let mut mean = DVector::zeros(e);
    for (a, o) in gp.outputs.iter().enumerate() {
        let s: Vec<f64> = o.inv_l2.iter().map(|v| v.sqrt()).collect();
        let ch = cholesky(
            &scaled_plus_identity(sigma, &s),
            &gp.jitter,
            "I + Λ^{-½} Σ Λ^{-½}",
        )?;
        log.record(ch.jitter);
        let logdet = ch.log_det();
        let nut = DMatrix::from_fn(d, m, |k, i| nu[(i, k)] * s[k]);
        let w = ch.solve(&nut);
        let lsf2 = o.sf2.ln();
        let mut q = DVector::zeros(m);
        let mut lk = DVector::zeros(m);
        for i in 0..m {
            let mut quad = 0.0;
            let mut plain = 0.0;
            for k in 0..d {
                quad += nut[(k, i)] * w[(k, i)];
                plain += nut[(k, i)] * nut[(k, i)];
            }
            lk[i] = lsf2 - 0.5 * plain;
            q[i] = (lsf2 - 0.5 * (quad + logdet)).exp();
        }
        let bq = o.beta.component_mul(&q);
        let mut acc = &w * &bq;
        for k in 0..d {
            acc[k] *= s[k];
        }
        mean[a] = bq.sum();
        outs.push(OutCache {
            s,
            shat_inv: ch.inverse(),
            nut,
            w,
            q,
            bq,
            acc,
            lk,
        });
    }
    let mut cov = DMatrix::zeros(e, e);
    let mut pairs = Vec::new();
    for a in 0..e {
        for b in a..e {
            let (oa, ob) = (&gp.outputs[a], &gp.outputs[b]);
            let sp: Vec<f64> = (0..d)
                .map(|k| (oa.inv_l2[k] + ob.inv_l2[k]).sqrt())
                .collect();
            let ch = cholesky(
                &scaled_plus_identity(sigma, &sp),
                &gp.jitter,
                "I + P^{½} Σ P^{½}",
            )?;
            log.record(ch.jitter);
            let logdet_r = ch.log_det();
            let st_inv = ch.inverse();
            let n = DMatrix::identity(d, d) - &st_inv;
            let at = DMatrix::from_fn(d, m, |k, i| oa.inv_l2[k] * nu[(i, k)] / sp[k]);
            let bt = DMatrix::from_fn(d, m, |k, i| ob.inv_l2[k] * nu[(i, k)] / sp[k]);
            let y = &n * &bt;
            let na = &n * &at;
            let g = at.transpose() * &y;
            let ua = DVector::from_fn(m, |i, _| {
                outs[a].lk[i] + 0.5 * at.column(i).dot(&na.column(i))
            });
            let ub = DVector::from_fn(m, |j, _| {
                outs[b].lk[j] + 0.5 * bt.column(j).dot(&y.column(j)) - 0.5 * logdet_r
            });
            let q = DMatrix::from_fn(m, m, |i, j| (ua[i] + ub[j] + g[(i, j)]).exp());
            let mut v = oa.beta.dot(&(&q * &ob.beta)) - mean[a] * mean[b];
            if a == b {
                v += oa.sf2 - oa.kinv.component_mul(&q).sum();
            }
            cov[(a, b)] = v;
            cov[(b, a)] = v;
            pairs.push(PairCache {
                a,
                b,
                sp,
                st_inv,
                n,
                at,
                bt,
                y,
                q,
            });
        }
    }
    Ok(MmCache {
        nu,
        outs,
        pairs,
        mean,
        cov,
    })
}

/// Adds `Σ̄` and `s̄`/`p̄` contributions of `Ŝ = I + diag(s) Σ diag(s)` given `Ŝ̄`.
fn pull_scaled(
    sbar_hat: &DMatrix<f64>,
    sigma: &DMatrix<f64>,
    s: &[f64],
    sigma_bar: &mut DMatrix<f64>,
    s_bar: &mut [f64],
) {
    let d = s.len();
    for i in 0..d {
        for j in 0..d {
            sigma_bar[(i, j)] += s[i] * sbar_hat[(i, j)] * s[j];
            s_bar[i] += (sbar_hat[(i, j)] + sbar_hat[(j, i)]) * sigma[(i, j)] * s[j];
        }
    }
}

/// Pulls adjoints of (mean, cov, io_cov) back to (μ, Σ) and the GP quantities.
fn mm_backward(
    gp: &PreparedGp<f64>,
    sigma: &DMatrix<f64>,
    c: &MmCache,
    mbar_in: &DVector<f64>,
    sbar: &DMatrix<f64>,
    vbar: &DMatrix<f64>,
    adj: &mut GpAdjoint,
) -> (DVector<f64>, DMatrix<f64>) {
    let (m, d) = c.nu.shape();
    let e = gp.output_dim();
    let mut mbar = mbar_in.clone();
    let mut nubar = DMatrix::<f64>::zeros(m, d);
    let mut sigma_bar = DMatrix::<f64>::zeros(d, d);
    let mut lkbar = vec![DVector::<f64>::zeros(m); e];

    for pc in &c.pairs {
        let (a, b) = (pc.a, pc.b);
        let vbar = if a == b {
            sbar[(a, a)]
        } else {
            sbar[(a, b)] + sbar[(b, a)]
        };
        if vbar == 0.0 {
            continue;
        }
        let (oa, ob) = (&gp.outputs[a], &gp.outputs[b]);
        // S_ab = β_aᵀ Q β_b − M_a M_b (+ σ_f² − tr(K̃⁻¹ Q))
        let qb = &pc.q * &ob.beta;
        let qta = pc.q.tr_mul(&oa.beta);
        adj.beta[a] += &qb * vbar;
        adj.beta[b] += &qta * vbar;
        mbar[a] -= vbar * c.mean[b];
        mbar[b] -= vbar * c.mean[a];
        let mut qbar = &oa.beta * ob.beta.transpose() * vbar;
        if a == b {
            adj.sf2[a] += vbar;
            qbar -= &oa.kinv * vbar;
            adj.kinv[a] -= &pc.q * vbar;
        }
        let ebar = qbar.component_mul(&pc.q);
        let uabar = DVector::from_fn(m, |i, _| ebar.row(i).sum());
        let ubbar = DVector::from_fn(m, |j, _| ebar.column(j).sum());
        // G = Ãᵀ Y, Y = N B̃
        let mut atbar = &pc.y * ebar.transpose();
        let ybar = &pc.at * &ebar;
        let mut nbar = &ybar * pc.bt.transpose();
        let mut btbar = &pc.n * &ybar;
        // ua_i = lk^a_i + ½ Ã_iᵀ N Ã_i ; ub_j = lk^b_j + ½ B̃_jᵀ N B̃_j − ½ log|S̃|
        let na = &pc.n * &pc.at;
        for i in 0..m {
            for k in 0..d {
                atbar[(k, i)] += uabar[i] * na[(k, i)];
                btbar[(k, i)] += ubbar[i] * pc.y[(k, i)];
            }
        }
        let at_s = DMatrix::from_fn(d, m, |k, i| pc.at[(k, i)] * uabar[i]);
        let bt_s = DMatrix::from_fn(d, m, |k, i| pc.bt[(k, i)] * ubbar[i]);
        nbar += (&at_s * pc.at.transpose() + &bt_s * pc.bt.transpose()) * 0.5;
        lkbar[a] += &uabar;
        lkbar[b] += &ubbar;
        let logdet_bar = -0.5 * ubbar.sum();
        // N = I − S̃⁻¹ ; log|S̃|
        let stbar = &pc.st_inv * &nbar * &pc.st_inv + &pc.st_inv * logdet_bar;
        let mut spbar = vec![0.0; d];
        pull_scaled(&stbar, sigma, &pc.sp, &mut sigma_bar, &mut spbar);
        for k in 0..d {
            let (ila, ilb, sp) = (oa.inv_l2[k], ob.inv_l2[k], pc.sp[k]);
            for i in 0..m {
                let nu = c.nu[(i, k)];
                nubar[(i, k)] += atbar[(k, i)] * ila / sp + btbar[(k, i)] * ilb / sp;
                adj.inv_l2[(a, k)] += atbar[(k, i)] * nu / sp;
                adj.inv_l2[(b, k)] += btbar[(k, i)] * nu / sp;
                spbar[k] -= (atbar[(k, i)] * pc.at[(k, i)] + btbar[(k, i)] * pc.bt[(k, i)]) / sp;
            }
            let pbar = spbar[k] / (2.0 * sp);
            adj.inv_l2[(a, k)] += pbar;
            adj.inv_l2[(b, k)] += pbar;
        }
    }

    for (a, oc) in c.outs.iter().enumerate() {
        let o = &gp.outputs[a];
        // V[:, a] = acc
        let accbar = vbar.column(a).into_owned();
        let mut sbar_v = vec![0.0; d];
        let mut bqbar = DVector::from_element(m, mbar[a]);
        let mut wbar = DMatrix::<f64>::zeros(d, m);
        for k in 0..d {
            let f = accbar[k] * oc.s[k];
            let mut sw = 0.0;
            for i in 0..m {
                bqbar[i] += f * oc.w[(k, i)];
                sw += oc.bq[i] * oc.w[(k, i)];
                wbar[(k, i)] += f * oc.bq[i];
            }
            sbar_v[k] += accbar[k] * sw;
        }
        adj.beta[a] += bqbar.component_mul(&oc.q);
        let qbar = bqbar.component_mul(&o.beta);
        let qq = qbar.component_mul(&oc.q);
        adj.sf2[a] += qq.sum() / o.sf2 + lkbar[a].sum() / o.sf2;
        let logdet_bar = -0.5 * qq.sum();
        let mut nutbar = DMatrix::<f64>::zeros(d, m);
        for i in 0..m {
            let quadbar = -0.5 * qq[i];
            for k in 0..d {
                nutbar[(k, i)] += quadbar * oc.w[(k, i)] - lkbar[a][i] * oc.nut[(k, i)];
                wbar[(k, i)] += quadbar * oc.nut[(k, i)];
            }
        }
        let z = &oc.shat_inv * &wbar;
        nutbar += &z;
        let shatbar = -(&z * oc.w.transpose()) + &oc.shat_inv * logdet_bar;
        pull_scaled(&shatbar, sigma, &oc.s, &mut sigma_bar, &mut sbar_v);
        for k in 0..d {
            for i in 0..m {
                nubar[(i, k)] += nutbar[(k, i)] * oc.s[k];
                sbar_v[k] += nutbar[(k, i)] * c.nu[(i, k)];
            }
            adj.inv_l2[(a, k)] += sbar_v[k] / (2.0 * oc.s[k]);
        }
    }
    adj.xbar += &nubar;
    let mubar = DVector::from_fn(d, |k, _| -nubar.column(k).sum());
    (mubar, sigma_bar)
}

/// What the forward rollout records per step.
struct StepRecord {
    sigma: DMatrix<f64>,
    /// The moment-matching intermediates (kept, not recomputed: ≈ 8·m²·pairs bytes per step).
    cache: MmCache,
    ycov: DMatrix<f64>,
    resid: DVector<f64>,
    v: DMatrix<f64>,
    /// The GP's own `V` (without the linear mean) and the window mean.
    v_gp: DMatrix<f64>,
    wmu: DVector<f64>,
    /// Closed loop: policy input moments, the policy's output, and `Cov(z, q)`.
    policy: Option<PolicyRecord>,
}

struct PolicyRecord {
    qm: DVector<f64>,
    qc: DMatrix<f64>,
    pm: PolicyMoments<f64>,
    zq: DMatrix<f64>,
}

/// Vector–Jacobian product of a policy's moment map at `(qm, qc)`: the gradient of
/// `⟨ō_mean, mean⟩ + ⟨ō_cov, cov⟩ + ⟨C̄, C⟩` with respect to every entry of `qm` and `qc`,
/// by forward-mode duals (the policy block is small: `n_q + n_q²` directions).
fn policy_vjp(
    policy: &dyn FeedbackPolicy<Dual>,
    rec: &PolicyRecord,
    mean_bar: &DVector<f64>,
    cov_bar: &DMatrix<f64>,
    c_bar: &DMatrix<f64>,
) -> Result<(DVector<f64>, DMatrix<f64>)> {
    let nq = rec.qm.len();
    let mut x: Vec<f64> = rec.qm.iter().copied().collect();
    x.extend(rec.qc.iter().copied());
    let active: Vec<usize> = (0..x.len()).collect();
    let (_, g) = gradient(&x, &active, 1, |xd: &[Dual]| {
        let qm = DVector::from_column_slice(&xd[..nq]);
        let qc = DMatrix::from_column_slice(nq, nq, &xd[nq..]);
        let pm = policy.moments(&qm, &qc)?;
        let mut acc = Dual::from_re(0.0);
        for (o, b) in pm.mean.iter().zip(mean_bar.iter()) {
            acc += *o * *b;
        }
        for (o, b) in pm.cov.iter().zip(cov_bar.iter()) {
            acc += *o * *b;
        }
        for (o, b) in pm.c.iter().zip(c_bar.iter()) {
            acc += *o * *b;
        }
        Ok(acc)
    })?;
    Ok((
        DVector::from_column_slice(&g[..nq]),
        DMatrix::from_column_slice(nq, nq, &g[nq..]),
    ))
}

fn episode_adjoint(
    gp: &PreparedGp<f64>,
    spec: &NarxSpec,
    traj: &Trajectory,
    policy: Option<&PolicySpec>,
    adj: &mut GpAdjoint,
    log: &mut JitterLog,
) -> Result<(f64, usize)> {
    let d = spec.input_dim();
    let (dy, du) = (spec.dy, spec.du);
    let t0 = spec.warmup();
    let horizon = traj.len();
    let pol: Option<Box<dyn FeedbackPolicy<f64>>> = policy.map(|p| p.lift::<f64>());
    let pol_dual: Option<Box<dyn FeedbackPolicy<Dual>>> = policy.map(|p| p.lift::<Dual>());
    let ds = pol.as_ref().map_or(0, |p| p.state_dim());
    let layout = Layout { d, ds, dy, du };
    let (n, x, u) = (layout.n(), layout.x_slot(), layout.u_slot());
    let len = layout.len();
    let sel = layout.gather_map(spec);
    let (wmu, wsigma) = initial_window(gp, spec, traj);
    let mut mu = DVector::<f64>::zeros(n);
    let mut sigma = DMatrix::<f64>::zeros(n, n);
    mu.rows_mut(0, d).copy_from(&wmu);
    sigma.view_mut((0, 0), (d, d)).copy_from(&wsigma);
    if let Some(p) = &pol {
        let p0 = p.initial_state(&traj.y, &traj.u, t0);
        mu.rows_mut(d, ds).copy_from(&p0);
    }

    // forward
    let mut recs: Vec<StepRecord> = Vec::with_capacity(horizon - t0);
    let mut nll = 0.0;
    let mut nll_log = JitterLog::default();
    for t in t0..horizon {
        let wsig = sigma.view((0, 0), (d, d)).into_owned();
        let wmu = mu.rows(0, d).into_owned();
        let mm = mm_forward(gp, &wmu, &wsig, log)?;
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
        let yrow: Vec<f64> = (0..dy).map(|j| traj.y[(t, j)]).collect();
        nll += gaussian_nll(&yrow, &fmean, &ycov, &gp.jitter, &mut nll_log)?;
        if !nll.is_finite() {
            return Err(MsgpError::NonFinite(format!(
                "trajectory likelihood at step {t}"
            )));
        }
        let resid = DVector::from_fn(dy, |j, _| yrow[j] - fmean[j]);
        let mean = fmean;
        let mut rec = StepRecord {
            sigma: sigma.clone(),
            cache: mm,
            ycov: ycov.clone(),
            resid,
            v: v.clone(),
            v_gp,
            wmu,
            policy: None,
        };
        if t + 1 < horizon {
            let (mut amu, mut acov) = layout.augmented(&mu, &sigma, &mean, &v, &xcov);
            match &pol {
                None => {
                    for j in 0..du {
                        amu[u + j] = traj.u[(t, j)];
                    }
                }
                Some(p) => {
                    let (qm, qc) = layout.policy_input(&amu, &acov, &ycov);
                    let pm = p.moments(&qm, &qc)?;
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
    let mut mubar_next = DVector::<f64>::zeros(n);
    let mut sigmabar_next = DMatrix::<f64>::zeros(n, n);
    let last = recs.len() - 1;
    for (s, rec) in recs.iter().enumerate().rev() {
        let mut mbar = DVector::<f64>::zeros(dy);
        let mut xcovbar = DMatrix::<f64>::zeros(dy, dy);
        let mut ycovbar = DMatrix::<f64>::zeros(dy, dy);
        let mut mubar = DVector::<f64>::zeros(n);
        let mut sigmabar = DMatrix::<f64>::zeros(n, n);
        let mut vbar = DMatrix::<f64>::zeros(d, dy);
        if s < last {
            symmetrize(&mut sigmabar_next);
            let mut amubar = DVector::<f64>::zeros(len);
            let mut acovbar = DMatrix::<f64>::zeros(len, len);
            for i in 0..n {
                amubar[sel[i]] += mubar_next[i];
                for j in 0..n {
                    acovbar[(sel[i], sel[j])] += sigmabar_next[(i, j)];
                }
            }
            if let (Some(pr), Some(pd)) = (&rec.policy, &pol_dual) {
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
                let (qm_bar, qc_bar) = policy_vjp(pd.as_ref(), pr, &mean_bar, &cov_bar, &c_bar)?;
                // policy_input: q = [y_{t+1}; p_t]
                for k in 0..dy {
                    amubar[x + k] += qm_bar[k];
                }
                for k in 0..ds {
                    amubar[d + k] += qm_bar[dy + k];
                }
                ycovbar += qc_bar.view((0, 0), (dy, dy));
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
            // augmented: [z; x_{t+1}] with Cov(z, x) = Σ[:, :d] V
            mubar += amubar.rows(0, n);
            mbar += amubar.rows(x, dy);
            sigmabar += acovbar.view((0, 0), (n, n));
            let zxbar = acovbar.view((0, x), (n, dy)).into_owned()
                + acovbar.view((x, 0), (dy, n)).transpose();
            add_block(&mut sigmabar, (0, 0), &(&zxbar * rec.v.transpose()));
            vbar += rec.sigma.columns(0, d).transpose() * &zxbar;
            xcovbar += acovbar.view((x, x), (dy, dy));
        }
        // NLL = ½[rᵀV⁻¹r + log|V|]
        let vch = cholesky(&rec.ycov, &gp.jitter, "predictive covariance")?;
        let vinv = vch.inverse();
        let alpha = &vinv * &rec.resid;
        mbar -= &alpha;
        ycovbar += (&vinv - &alpha * alpha.transpose()) * 0.5;
        xcovbar += &ycovbar;
        for j in 0..dy {
            adj.sy2[j] += ycovbar[(j, j)];
            adj.sx2[j] += xcovbar[(j, j)];
        }
        let wsig = rec.sigma.view((0, 0), (d, d)).into_owned();
        if let Some(a) = &gp.linear_mean {
            let lb = linear_mean_backward(a, &rec.wmu, &wsig, &rec.v_gp, &mbar, &xcovbar, &vbar);
            adj.lin += &lb.a;
            for k in 0..d {
                mubar[k] += lb.mu[k];
            }
            add_block(&mut sigmabar, (0, 0), &lb.sigma);
            vbar = lb.v;
        }
        let (mub, sigb) = mm_backward(gp, &wsig, &rec.cache, &mbar, &xcovbar, &vbar, adj);
        for k in 0..d {
            mubar[k] += mub[k];
        }
        add_block(&mut sigmabar, (0, 0), &sigb);
        mubar_next = mubar;
        sigmabar_next = sigmabar;
    }
    for k in 0..spec.ly {
        for j in 0..dy {
            let i = spec.y_index(k, j);
            adj.sy2[j] += sigmabar_next[(i, i)];
        }
    }
    Ok((nll, recs.len()))
}

/// `m[at..] += b` for a block.
fn add_block(m: &mut DMatrix<f64>, at: (usize, usize), b: &DMatrix<f64>) {
    for i in 0..b.nrows() {
        for j in 0..b.ncols() {
            m[(at.0 + i, at.1 + j)] += b[(i, j)];
        }
    }
}

/// Value and gradient (in [`GpParams::to_flat`] layout) of the MSGP loss, by the adjoint sweep.
pub fn loss_and_gradient(
    params: &GpParams<f64>,
    config: &GpConfig,
    spec: &NarxSpec,
    episodes: &[Episode],
    complexity: Complexity,
    log: &mut JitterLog,
) -> Result<(LossValue<f64>, Vec<f64>)> {
    let shape: GpShape = params.shape()?;
    let GpShape { m, d, e } = shape;
    let gp = PreparedGp::new(params, config, log)?;
    let mut adj = GpAdjoint::zeros(m, d, e);
    let mut nll = 0.0;
    let mut steps = 0;
    for (k, ep) in episodes.iter().enumerate() {
        ep.traj
            .check(spec)
            .map_err(|err| MsgpError::Data(format!("episode {k}: {err}")))?;
        let policy = match &ep.excitation {
            Excitation::FeedForward => None,
            Excitation::Feedback(p) => Some(p.as_ref()),
        };
        let (v, n) = episode_adjoint(&gp, spec, &ep.traj, policy, &mut adj, log)?;
        nll += v;
        steps += n;
    }
    let comp = complexity_term(params, &gp, complexity);
    let mut ybar = DMatrix::<f64>::zeros(m, e);
    let mut logdet_bar = vec![0.0; e];
    for a in 0..e {
        match complexity {
            Complexity::None => {}
            Complexity::HalfLogDet => logdet_bar[a] = 0.5,
            Complexity::NegHalfLogDet => logdet_bar[a] = -0.5,
            Complexity::PseudoDataNll => {
                logdet_bar[a] = 0.5;
                // ½ ȳᵀβ with β = K̃⁻¹ȳ: d/dȳ = β (symmetric K̃), routed as ȳ̄ += ½β, β̄ += ½ȳ
                for i in 0..m {
                    ybar[(i, a)] += 0.5 * gp.outputs[a].beta[i];
                }
                let ycol = params.pseudo_targets.column(a).into_owned();
                adj.beta[a] += ycol * 0.5;
            }
        }
    }

    // pull through the preparation: β = K̃⁻¹ȳ, K̃⁻¹, log|K̃|, K̃ = K + σx² I
    let mut grad = vec![0.0; shape.len()];
    let mut inv_l2_bar = adj.inv_l2.clone();
    let mut sf2_bar = adj.sf2.clone();
    let mut sx2_bar = adj.sx2.clone();
    for (a, o) in gp.outputs.iter().enumerate() {
        let w = &o.kinv * &adj.beta[a];
        for i in 0..m {
            ybar[(i, a)] += w[i];
        }
        let ktbar =
            -(&o.kinv * &adj.kinv[a] * &o.kinv) - &w * o.beta.transpose() + &o.kinv * logdet_bar[a];
        sx2_bar[a] += ktbar.trace();
        let k = kernel_matrix(
            &params.pseudo_inputs,
            &params.pseudo_inputs,
            &o.inv_l2,
            o.sf2,
        );
        for i in 0..m {
            for j in 0..m {
                let g = ktbar[(i, j)] * k[(i, j)];
                if g == 0.0 {
                    continue;
                }
                sf2_bar[a] += g / o.sf2;
                for dd in 0..d {
                    let diff = params.pseudo_inputs[(i, dd)] - params.pseudo_inputs[(j, dd)];
                    inv_l2_bar[(a, dd)] -= 0.5 * g * diff * diff;
                    adj.xbar[(i, dd)] -= g * o.inv_l2[dd] * diff;
                    adj.xbar[(j, dd)] += g * o.inv_l2[dd] * diff;
                }
            }
        }
    }
    let r = shape.group_range(ParamGroup::PseudoInputs);
    for i in 0..m {
        for dd in 0..d {
            grad[r.start + i * d + dd] = adj.xbar[(i, dd)];
        }
    }
    let r = shape.group_range(ParamGroup::PseudoTargets);
    for i in 0..m {
        for a in 0..e {
            grad[r.start + i * e + a] = ybar[(i, a)];
        }
    }
    let r = shape.group_range(ParamGroup::Lengthscales);
    for (a, o) in gp.outputs.iter().enumerate() {
        for dd in 0..d {
            grad[r.start + a * d + dd] = -2.0 * o.inv_l2[dd] * inv_l2_bar[(a, dd)];
        }
    }
    for (a, o) in gp.outputs.iter().enumerate() {
        grad[shape.group_range(ParamGroup::SignalVar).start + a] = sf2_bar[a] * o.sf2;
        grad[shape.group_range(ParamGroup::ProcessNoise).start + a] =
            sx2_bar[a] * (o.sx2 - config.noise_floor);
        grad[shape.group_range(ParamGroup::ObsNoise).start + a] =
            adj.sy2[a] * (o.sy2 - config.noise_floor);
    }
    if gp.linear_mean.is_some() {
        let r = shape.group_range(ParamGroup::LinearMean);
        for a in 0..e {
            for dd in 0..d {
                grad[r.start + a * d + dd] = adj.lin[(a, dd)];
            }
        }
    }
    Ok((
        LossValue {
            nll,
            complexity: comp,
            steps,
        },
        grad,
    ))
}
