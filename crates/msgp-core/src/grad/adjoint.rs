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

use crate::cost::SaturatingCost;
use crate::error::{MsgpError, Result};
use crate::gp::{GpConfig, GpParams, GpShape, ParamGroup, PreparedGp};
use crate::grad::dual::{Dual, gradient, moments_gradient, weighted_sum};
use crate::kernel::kernel_matrix;
use crate::linalg::{JitterLog, JitterPolicy, cholesky, symmetrize};
use crate::loss::{Complexity, LossValue, complexity_term, gaussian_nll};
use crate::mean_fn::{add_linear_mean, linear_mean_backward};
use crate::mm_f64::{MmState, q_matrix};
use crate::moments::Moments;
use crate::narx::NarxSpec;
use crate::policy::{FeedbackPolicy, PolicyMoments, PolicySpec};
use crate::rollout::{Layout, StartState, gather, initial_window, noisy_covariances};
use crate::simd::{
    Kernel, axpy, chol_inverse, dispatch, dot, gemm_rows, gram_add, solve_lower_rows,
    solve_upper_rows, sum,
};
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
    /// `self += o`, field by field (the destructuring is exhaustive: a new field must be added
    /// here, or the per-episode sums would drop it).
    fn add(&mut self, o: &GpAdjoint) {
        let GpAdjoint {
            xbar,
            beta,
            kinv,
            inv_l2,
            sf2,
            sx2,
            sy2,
            lin,
        } = o;
        self.xbar += xbar;
        self.lin += lin;
        for (a, b) in self.beta.iter_mut().zip(beta) {
            *a += b;
        }
        for (a, b) in self.kinv.iter_mut().zip(kinv) {
            *a += b;
        }
        self.inv_l2 += inv_l2;
        for (a, b) in [
            (&mut self.sf2, sf2),
            (&mut self.sx2, sx2),
            (&mut self.sy2, sy2),
        ] {
            for (x, y) in a.iter_mut().zip(b) {
                *x += y;
            }
        }
    }

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

fn zero(v: &mut Vec<f64>, n: usize) {
    v.clear();
    v.resize(n, 0.0);
}

/// Reused buffers of the backward moment-matching pass.
#[derive(Default)]
struct BackWork {
    q: Vec<f64>,
    ebuf: Vec<f64>,
    ebar: Vec<f64>,
    ebar_t: Vec<f64>,
    qb: Vec<f64>,
    uabar: Vec<f64>,
    ubbar: Vec<f64>,
    atbar: Vec<f64>,
    btbar: Vec<f64>,
    ybar: Vec<f64>,
    tmp: Vec<f64>,
    nubar: Vec<f64>,
    lkbar: Vec<Vec<f64>>,
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

struct Backward<'a> {
    gp: &'a PreparedGp<f64>,
    sigma: &'a DMatrix<f64>,
    c: &'a MmState,
    mbar_in: &'a DVector<f64>,
    sbar: &'a DMatrix<f64>,
    vbar: &'a DMatrix<f64>,
    adj: &'a mut GpAdjoint,
    w: &'a mut BackWork,
}

impl Kernel for Backward<'_> {
    type Output = (DVector<f64>, DMatrix<f64>);
    #[inline(always)]
    fn run<const F: bool>(self) -> Self::Output {
        mm_backward_impl::<F>(self)
    }
}

/// Pulls adjoints of (mean, cov, V) back to (μ, Σ) and the GP quantities.
fn mm_backward(
    gp: &PreparedGp<f64>,
    sigma: &DMatrix<f64>,
    c: &MmState,
    mbar_in: &DVector<f64>,
    sbar: &DMatrix<f64>,
    vbar: &DMatrix<f64>,
    adj: &mut GpAdjoint,
    w: &mut BackWork,
) -> (DVector<f64>, DMatrix<f64>) {
    dispatch(Backward {
        gp,
        sigma,
        c,
        mbar_in,
        sbar,
        vbar,
        adj,
        w,
    })
}

#[inline(always)]
fn mm_backward_impl<const F: bool>(bw: Backward<'_>) -> (DVector<f64>, DMatrix<f64>) {
    let Backward {
        gp,
        sigma,
        c,
        mbar_in,
        sbar,
        vbar,
        adj,
        w,
    } = bw;
    let (m, d, mp) = (c.m, c.d, c.mp);
    let e = gp.output_dim();
    let mut mbar = mbar_in.clone();
    let mut sigma_bar = DMatrix::<f64>::zeros(d, d);
    zero(&mut w.nubar, d * mp);
    w.lkbar.resize_with(e, Vec::new);
    for lk in w.lkbar.iter_mut() {
        zero(lk, mp);
    }

    for pc in &c.pairs {
        let (a, b) = (pc.a, pc.b);
        let diag = a == b;
        let vb = if diag {
            sbar[(a, a)]
        } else {
            sbar[(a, b)] + sbar[(b, a)]
        };
        if vb == 0.0 {
            continue;
        }
        let (oa, ob) = (&gp.outputs[a], &gp.outputs[b]);
        let (beta_a, beta_b) = (oa.beta.as_slice(), ob.beta.as_slice());
        // S_ab = β_aᵀ Q β_b − M_a M_b (+ σ_f² − tr(K̃⁻¹ Q)): one pass over Q's columns gives
        // Qβ_b, Qᵀβ_a, K̃⁻¹'s adjoint, Ē = Q̄ ∘ Q and its row and column sums
        mbar[a] -= vb * c.mean[b];
        mbar[b] -= vb * c.mean[a];
        if diag {
            adj.sf2[a] += vb;
        }
        // Q again, by the forward's own code (bit-identical to what the forward used): cheaper
        // than keeping 8·m² bytes per step and pair
        // (q_matrix overwrites every entry: no zero fill)
        w.q.resize(m * m, 0.0);
        w.ebuf.resize(4 * mp, 0.0);
        q_matrix::<F>(
            m,
            mp,
            d,
            &pc.at,
            &pc.nb,
            &pc.ua,
            &pc.ub,
            diag,
            &mut w.ebuf,
            &mut w.q,
        );
        // Ē as m columns of stride mp: rows < m are written below, the padding is zeroed here
        w.ebar.resize(m * mp, 0.0);
        for j in 0..m {
            w.ebar[j * mp + m..(j + 1) * mp].fill(0.0);
        }
        zero(&mut w.qb, m);
        zero(&mut w.uabar, mp);
        zero(&mut w.ubbar, mp);
        {
            let kinv = oa.kinv.as_slice();
            let adj_kinv = adj.kinv[a].as_mut_slice();
            let adj_beta_b = adj.beta[b].as_mut_slice();
            // a diagonal pair's Q and Ē are symmetric: Qᵀβ_a = Qβ_b and Ē's row sums are its
            // column sums, so two of the column pass's streams are skipped (taken after it)
            for j in 0..m {
                let qcol = &w.q[j * m..(j + 1) * m];
                if !diag {
                    adj_beta_b[j] += vb * dot::<F>(beta_a, qcol);
                }
                axpy::<F>(beta_b[j], qcol, &mut w.qb);
                let ecol = &mut w.ebar[j * mp..j * mp + m];
                let f = vb * beta_b[j];
                if diag {
                    let kcol = &kinv[j * m..(j + 1) * m];
                    let acol = &mut adj_kinv[j * m..(j + 1) * m];
                    for ((((ac, ec), &q), &k), &ba) in acol
                        .iter_mut()
                        .zip(ecol.iter_mut())
                        .zip(qcol)
                        .zip(kcol)
                        .zip(beta_a)
                    {
                        *ac -= vb * q;
                        *ec = (f * ba - vb * k) * q;
                    }
                } else {
                    for ((ec, &q), &ba) in ecol.iter_mut().zip(qcol).zip(beta_a) {
                        *ec = f * ba * q;
                    }
                }
                w.ubbar[j] = sum(ecol);
                if !diag {
                    for (u, e) in w.uabar.iter_mut().zip(ecol.iter()) {
                        *u += e;
                    }
                }
            }
            let adj_beta_a = adj.beta[a].as_mut_slice();
            if diag {
                axpy::<F>(2.0 * vb, &w.qb, adj_beta_a);
                w.uabar[..m].copy_from_slice(&w.ubbar[..m]);
            } else {
                axpy::<F>(vb, &w.qb, adj_beta_a);
            }
        }
        // G = Ãᵀ Y, Y = N B̃: Ã̄ = Y Ēᵀ, Ȳ = Ã Ē. For a diagonal pair Ē is symmetric and
        // Y = N Ã, so Ã̄ = N Ȳ (formed below with B̃̄ = N Ȳ): one m × m product instead of two.
        let bt: &[f64] = if diag { &pc.at } else { &pc.bt };
        let na: &[f64] = if diag { &pc.nb } else { &pc.na };
        zero(&mut w.atbar, d * mp);
        zero(&mut w.ybar, d * mp);
        zero(&mut w.btbar, d * mp);
        if diag {
            gemm_rows::<F>(&pc.at, &w.ebar, &mut w.ybar, d, m, mp);
        } else {
            gemm_rows::<F>(&pc.nb, &w.ebar, &mut w.atbar, d, m, mp);
            zero(&mut w.ebar_t, m * mp);
            for j in 0..m {
                for i in 0..m {
                    w.ebar_t[i * mp + j] = w.ebar[j * mp + i];
                }
            }
            gemm_rows::<F>(&pc.at, &w.ebar_t, &mut w.ybar, d, m, mp);
        }
        // N̄ = Ȳ B̃ᵀ + ½ (Ã diag(ū_a) Ãᵀ + B̃ diag(ū_b) B̃ᵀ); for a diagonal pair (Ã = B̃) one
        // product: (Ȳ + ½ Ã diag(ū_a + ū_b)) Ãᵀ
        let mut nbar = DMatrix::<f64>::zeros(d, d);
        zero(&mut w.tmp, d * mp);
        if diag {
            for k in 0..d {
                let r = k * mp..k * mp + m;
                for ((((t, &y), &x), &ua), &ub) in w.tmp[r.clone()]
                    .iter_mut()
                    .zip(&w.ybar[r.clone()])
                    .zip(&pc.at[r])
                    .zip(&w.uabar)
                    .zip(&w.ubbar)
                {
                    *t = y + 0.5 * (ua + ub) * x;
                }
            }
            gram_add::<F>(&w.tmp, &pc.at, 1.0, &mut nbar, d, mp);
        } else {
            gram_add::<F>(&w.ybar, bt, 1.0, &mut nbar, d, mp);
            for k in 0..d {
                let r = k * mp..k * mp + m;
                for ((t, &x), &u) in w.tmp[r.clone()].iter_mut().zip(&pc.at[r]).zip(&w.uabar) {
                    *t = x * u;
                }
            }
            gram_add::<F>(&w.tmp, &pc.at, 0.5, &mut nbar, d, mp);
            for k in 0..d {
                let r = k * mp..k * mp + m;
                for ((t, &x), &u) in w.tmp[r.clone()].iter_mut().zip(&bt[r]).zip(&w.ubbar) {
                    *t = x * u;
                }
            }
            gram_add::<F>(&w.tmp, bt, 0.5, &mut nbar, d, mp);
        }
        // B̃̄ = N Ȳ = Ȳ − S̃⁻¹ Ȳ ; ua_i = lk^a_i + ½ Ã_iᵀ N Ã_i ; ub_j = lk^b_j + ½ B̃_jᵀ N B̃_j − ½ log|S̃|
        w.tmp.clear();
        w.tmp.extend_from_slice(&w.ybar);
        solve_lower_rows::<F>(&pc.l, &mut w.tmp, d, mp);
        solve_upper_rows::<F>(&pc.l, &mut w.tmp, d, mp);
        for k in 0..d {
            let r = k * mp..k * mp + m;
            for ((((bb, &y), &t), &ub), &nb) in w.btbar[r.clone()]
                .iter_mut()
                .zip(&w.ybar[r.clone()])
                .zip(&w.tmp[r.clone()])
                .zip(&w.ubbar)
                .zip(&pc.nb[r.clone()])
            {
                *bb = y - t + ub * nb;
            }
            if diag {
                for ((((ab, &y), &t), &ua), &x) in w.atbar[r.clone()]
                    .iter_mut()
                    .zip(&w.ybar[r.clone()])
                    .zip(&w.tmp[r.clone()])
                    .zip(&w.uabar)
                    .zip(&na[r])
                {
                    *ab = y - t + ua * x;
                }
            } else {
                for ((ab, &ua), &x) in w.atbar[r.clone()].iter_mut().zip(&w.uabar).zip(&na[r]) {
                    *ab += ua * x;
                }
            }
        }
        for i in 0..m {
            w.lkbar[a][i] += w.uabar[i];
            w.lkbar[b][i] += w.ubbar[i];
        }
        let logdet_bar = -0.5 * sum(&w.ubbar[..m]);
        // N = I − S̃⁻¹ ; log|S̃|
        let st_inv = chol_inverse::<F>(&pc.l);
        let stbar = &st_inv * &nbar * &st_inv + &st_inv * logdet_bar;
        let mut spbar = vec![0.0; d];
        pull_scaled(&stbar, sigma, &pc.sp, &mut sigma_bar, &mut spbar);
        for k in 0..d {
            let (ila, ilb, sp) = (oa.inv_l2[k], ob.inv_l2[k], pc.sp[k]);
            let r = k * mp..k * mp + m;
            let (atb, btb, atk, btk, nuk) = (
                &w.atbar[r.clone()],
                &w.btbar[r.clone()],
                &pc.at[r.clone()],
                &bt[r.clone()],
                &c.nu_t[r.clone()],
            );
            let nubar = &mut w.nubar[r];
            let (mut la, mut lb, mut sq) = (0.0, 0.0, 0.0);
            for i in 0..m {
                nubar[i] += atb[i] * ila / sp + btb[i] * ilb / sp;
            }
            la += dot::<F>(atb, nuk) / sp;
            lb += dot::<F>(btb, nuk) / sp;
            sq += (dot::<F>(atb, atk) + dot::<F>(btb, btk)) / sp;
            spbar[k] -= sq;
            let pbar = spbar[k] / (2.0 * sp);
            adj.inv_l2[(a, k)] += la + pbar;
            adj.inv_l2[(b, k)] += lb + pbar;
        }
    }

    for (a, oc) in c.outs.iter().enumerate() {
        let o = &gp.outputs[a];
        let beta = o.beta.as_slice();
        // V[:, a] = acc = diag(s) Ŵ (β ∘ q)
        let mut sbar_v = vec![0.0; d];
        // bq̄_i = M̄_a + Σ_k V̄_ka s_k Ŵ_ki ; Ŵ̄ = (V̄ ∘ s) bqᵀ
        zero(&mut w.qb, mp);
        w.qb[..m].iter_mut().for_each(|v| *v = mbar[a]);
        zero(&mut w.ybar, d * mp); // Ŵ̄
        for k in 0..d {
            let f = vbar[(k, a)] * oc.s[k];
            let r = k * mp..(k + 1) * mp;
            axpy::<F>(f, &oc.w[r.clone()], &mut w.qb);
            sbar_v[k] += vbar[(k, a)] * dot::<F>(&oc.bq, &oc.w[r.clone()]);
            axpy::<F>(f, &oc.bq, &mut w.ybar[r]);
        }
        // q̄ = bq̄ ∘ β ; qq = q̄ ∘ q
        let adj_beta = adj.beta[a].as_mut_slice();
        zero(&mut w.uabar, mp); // qq
        for i in 0..m {
            adj_beta[i] += w.qb[i] * oc.q[i];
            w.uabar[i] = w.qb[i] * beta[i] * oc.q[i];
        }
        let sqq = sum(&w.uabar[..m]);
        adj.sf2[a] += sqq / o.sf2 + sum(&w.lkbar[a][..m]) / o.sf2;
        let logdet_bar = -0.5 * sqq;
        // ν̃̄ = −½ qq ∘ Ŵ − lk̄ ∘ ν̃ ; Ŵ̄ += −½ qq ∘ ν̃
        zero(&mut w.atbar, d * mp); // ν̃̄
        let lkbar = &w.lkbar[a];
        for k in 0..d {
            let r = k * mp..k * mp + m;
            for (((((nb, wb), &qq), &lb), &wv), &nv) in w.atbar[r.clone()]
                .iter_mut()
                .zip(w.ybar[r.clone()].iter_mut())
                .zip(&w.uabar)
                .zip(lkbar)
                .zip(&oc.w[r.clone()])
                .zip(&oc.nut[r])
            {
                let quadbar = -0.5 * qq;
                *nb = quadbar * wv - lb * nv;
                *wb += quadbar * nv;
            }
        }
        // Ŵ = Ŝ⁻¹ ν̃ᵀ: z = Ŝ⁻¹ Ŵ̄, ν̃̄ += z, Ŝ̄ = −z Ŵᵀ + log|Ŝ|̄ Ŝ⁻¹
        w.tmp.clear();
        w.tmp.extend_from_slice(&w.ybar);
        solve_lower_rows::<F>(&oc.l, &mut w.tmp, d, mp);
        solve_upper_rows::<F>(&oc.l, &mut w.tmp, d, mp);
        for (t, z) in w.atbar.iter_mut().zip(&w.tmp) {
            *t += z;
        }
        let shat_inv = chol_inverse::<F>(&oc.l);
        let mut shatbar = &shat_inv * logdet_bar;
        gram_add::<F>(&w.tmp, &oc.w, -1.0, &mut shatbar, d, mp);
        pull_scaled(&shatbar, sigma, &oc.s, &mut sigma_bar, &mut sbar_v);
        for k in 0..d {
            let r = k * mp..k * mp + m;
            let sk = oc.s[k];
            let nutb = &w.atbar[r.clone()];
            sbar_v[k] += dot::<F>(nutb, &c.nu_t[r.clone()]);
            axpy::<F>(sk, nutb, &mut w.nubar[r]);
            adj.inv_l2[(a, k)] += sbar_v[k] / (2.0 * sk);
        }
    }
    let xbar = adj.xbar.as_mut_slice();
    let mut mubar = DVector::zeros(d);
    for k in 0..d {
        let nb = &w.nubar[k * mp..k * mp + m];
        for (x, v) in xbar[k * m..(k + 1) * m].iter_mut().zip(nb) {
            *x += v;
        }
        mubar[k] = -sum(nb);
    }
    (mubar, sigma_bar)
}

/// What the forward rollout records per step.
struct StepRecord {
    sigma: DMatrix<f64>,
    /// The moment-matching intermediates (O(m·D) per step; `Q` is recomputed in the backward
    /// pass).
    cache: MmState,
    ycov: DMatrix<f64>,
    /// `E[y_t]`.
    mean: DVector<f64>,
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

/// A policy's moment map in dual numbers, as a function of its parameters `θ` and of the
/// moments `(mean, cov)` of its input: `(θ, mean, cov) ↦ policy(θ).moments(mean, cov)`.
pub type DualPolicyMap<'a> =
    dyn Fn(&[Dual], &DVector<Dual>, &DMatrix<Dual>) -> Result<PolicyMoments<Dual>> + Sync + 'a;

/// A policy's vector–Jacobian product in closed form, `(q_m, q_c, ō_mean, ō_cov, C̄) ↦ (q̄_m,
/// q̄_c, θ̄)`: what [`policy_vjp`] computes by duals through a [`DualPolicyMap`].
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

/// Gradient of the expected cost `E[c(y)]`, `y ~ N(mean, cov)`, with respect to `mean` and
/// (symmetrised) `cov`, by forward-mode duals (`d_y + d_y²` directions).
fn cost_vjp(
    cost: &SaturatingCost,
    mean: &DVector<f64>,
    cov: &DMatrix<f64>,
    jitter: &JitterPolicy,
) -> Result<(DVector<f64>, DMatrix<f64>)> {
    let (gm, gc) = moments_gradient(mean, cov, |m, s| {
        let mut log = JitterLog::default();
        Ok(cost.moments(m, s, jitter, &mut log)?.mean)
    })?;
    Ok((gm, (&gc + gc.transpose()) * 0.5))
}

/// Value and gradient, with respect to the policy parameters `θ`, of the expected cost
/// `Σ_t E[c(y_t)]` of a closed-loop rollout of `policy` from `start` over `t0..horizon`
/// ([`crate::policy_cost::closed_loop_cost`]), by the adjoint sweep: reverse mode over the
/// rollout, forward-mode duals only inside each step's small policy and cost maps. It costs a
/// few rollouts whatever `|θ|`; duals over `θ` through the whole rollout are the reference it
/// is tested against. `moments` is the same policy's moment map in dual numbers; `vjp`, when
/// given, its vector–Jacobian product in closed form (used instead of duals through `moments`).
#[allow(clippy::too_many_arguments)]
pub fn closed_loop_cost_gradient(
    gp: &PreparedGp<f64>,
    spec: &NarxSpec,
    start: &StartState<f64>,
    policy: &dyn FeedbackPolicy<f64>,
    moments: &DualPolicyMap<'_>,
    vjp: Option<&PolicyVjp<'_>>,
    theta: &[f64],
    t0: usize,
    horizon: usize,
    cost: &SaturatingCost,
    log: &mut JitterLog,
) -> Result<(f64, Vec<f64>)> {
    let (m, d, e) = (gp.pseudo_inputs.nrows(), gp.input_dim(), gp.output_dim());
    if d != spec.input_dim() || e != spec.dy || policy.input_dim() != spec.du {
        return Err(MsgpError::Shape(format!(
            "GP ({d} inputs, {e} outputs), NARX spec ({} inputs, {} outputs) and policy ({} \
             inputs) do not fit together",
            spec.input_dim(),
            spec.dy,
            policy.input_dim()
        )));
    }
    // the GP's own adjoints are not needed here; they accumulate in a scratch record
    let mut scratch = GpAdjoint::zeros(m, d, e);
    let adjoint_policy = AdjointPolicy {
        policy,
        moments,
        vjp,
        theta,
    };
    let out = rollout_adjoint(
        gp,
        spec,
        start,
        StepLoss::Cost(cost),
        Some(&adjoint_policy),
        t0,
        horizon,
        &mut scratch,
        log,
    )?;
    Ok((out.total, out.theta))
}

/// What a rollout adjoint scores each predicted observation by.
enum StepLoss<'a> {
    /// Negative log likelihood of the measured outputs (the MSGP loss).
    Nll(&'a Trajectory),
    /// Expected saturating cost (policy search).
    Cost(&'a SaturatingCost),
}

/// What [`rollout_adjoint`] returns.
struct RolloutAdjoint {
    /// Σ of the step losses.
    total: f64,
    steps: usize,
    /// Gradient with respect to the policy's parameters `θ`.
    theta: Vec<f64>,
    /// Adjoint of the start state's covariance.
    start_cov: DMatrix<f64>,
}

/// The MSGP loss of one episode: its free-running prediction from the measured window (open
/// loop on its inputs, or closed loop under its policy), scored by the likelihood of the
/// measured outputs. Adds the GP adjoints to `adj`; returns the NLL and the number of steps.
fn episode_adjoint(
    gp: &PreparedGp<f64>,
    spec: &NarxSpec,
    traj: &Trajectory,
    policy: Option<&PolicySpec>,
    adj: &mut GpAdjoint,
    log: &mut JitterLog,
) -> Result<(f64, usize)> {
    let d = spec.input_dim();
    let pol: Option<Box<dyn FeedbackPolicy<f64>>> = policy.map(|p| p.lift::<f64>());
    // the episode's policy is fixed (no parameters): lifted to duals once
    let pol_dual: Option<Box<dyn FeedbackPolicy<Dual>>> = policy.map(|p| p.lift::<Dual>());
    let moments;
    // the policy's vector–Jacobian product in closed form where it has one (the duals through
    // `moments` are its reference)
    let vjp = policy.filter(|p| p.has_closed_form_vjp()).map(|p| {
        move |qm: &DVector<f64>,
              qc: &DMatrix<f64>,
              mean_bar: &DVector<f64>,
              cov_bar: &DMatrix<f64>,
              c_bar: &DMatrix<f64>| {
            let (qm_bar, qc_bar, _) = p.moments_vjp(qm, qc, mean_bar, cov_bar, c_bar)?;
            Ok((qm_bar, qc_bar, Vec::new()))
        }
    });
    let adjoint_policy = match (pol.as_deref(), pol_dual.as_deref()) {
        (Some(p), Some(pd)) => {
            moments = move |_: &[Dual], qm: &DVector<Dual>, qc: &DMatrix<Dual>| pd.moments(qm, qc);
            Some(AdjointPolicy {
                policy: p,
                moments: &moments,
                vjp: vjp.as_ref().map(|f| f as &PolicyVjp<'_>),
                theta: &[],
            })
        }
        _ => None,
    };
    let ds = pol.as_ref().map_or(0, |p| p.state_dim());
    let first = initial_window(gp, spec, traj, gp.start)?;
    let t0 = first.t0;
    let (wmu, wsigma) = (&first.mean, &first.cov);
    let mut mu = DVector::<f64>::zeros(d + ds);
    let mut sigma = DMatrix::<f64>::zeros(d + ds, d + ds);
    mu.rows_mut(0, d).copy_from(wmu);
    sigma.view_mut((0, 0), (d, d)).copy_from(wsigma);
    if let Some(p) = &pol {
        let p0 = p.initial_state(&traj.y, &traj.u, t0);
        mu.rows_mut(d, ds).copy_from(&p0);
    }
    let start = StartState {
        mean: mu,
        cov: sigma,
    };
    let out = rollout_adjoint(
        gp,
        spec,
        &start,
        StepLoss::Nll(traj),
        adjoint_policy.as_ref(),
        t0,
        traj.len(),
        adj,
        log,
    )?;
    // the start window's output covariance is the observation noise times its pattern
    for j in 0..spec.dy {
        for k in 0..spec.ly {
            for k2 in 0..spec.ly {
                adj.sy2[j] += first.pattern[(k, k2)]
                    * out.start_cov[(spec.y_index(k, j), spec.y_index(k2, j))];
            }
        }
    }
    Ok((out.total, out.steps))
}

/// The adjoint sweep of one rollout from `start` over `t0..horizon`: a forward pass that records
/// every step, then a backward pass that pulls the step losses' adjoints back through the
/// moment matching, the window shift and (closed loop) the policy. Open loop (no `policy`) it
/// follows the inputs of the [`StepLoss::Nll`] trajectory. Adds the GP adjoints to `adj`.
#[allow(clippy::too_many_arguments)]
fn rollout_adjoint(
    gp: &PreparedGp<f64>,
    spec: &NarxSpec,
    start: &StartState<f64>,
    loss: StepLoss<'_>,
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
    // open loop the inputs come from the measured trajectory, which only the NLL has
    if policy.is_none() && matches!(loss, StepLoss::Cost(_)) {
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
        match &loss {
            StepLoss::Nll(traj) => {
                let yrow: Vec<f64> = (0..dy).map(|j| traj.y[(t, j)]).collect();
                total += gaussian_nll(&yrow, &fmean, &ycov, &gp.jitter, &mut nll_log)?;
            }
            StepLoss::Cost(cost) => {
                total += cost.moments(&fmean, &ycov, &gp.jitter, &mut nll_log)?.mean;
            }
        }
        if !total.is_finite() {
            return Err(MsgpError::NonFinite(format!("rollout loss at step {t}")));
        }
        let mean = fmean;
        let mut rec = StepRecord {
            sigma: sigma.clone(),
            cache: mm,
            ycov: ycov.clone(),
            mean: mean.clone(),
            v: v.clone(),
            v_gp,
            wmu,
            policy: None,
        };
        if t + 1 < horizon {
            let (mut amu, mut acov) = layout.augmented(&mu, &sigma, &mean, &v, &xcov);
            match policy {
                None => {
                    if let StepLoss::Nll(traj) = &loss {
                        for j in 0..du {
                            amu[u + j] = traj.u[(t, j)];
                        }
                    }
                }
                Some(p) => {
                    let (qm, qc) = layout.policy_input(&amu, &acov, &ycov);
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
        match &loss {
            StepLoss::Nll(traj) => {
                // NLL = ½[rᵀV⁻¹r + log|V|]
                let t = t0 + s;
                let resid = DVector::from_fn(dy, |j, _| traj.y[(t, j)] - rec.mean[j]);
                let vch = cholesky(&rec.ycov, &gp.jitter, "predictive covariance")?;
                let vinv = vch.inverse();
                let alpha = &vinv * &resid;
                mbar -= &alpha;
                ycovbar += (&vinv - &alpha * alpha.transpose()) * 0.5;
            }
            StepLoss::Cost(cost) => {
                let (gm, gc) = cost_vjp(cost, &rec.mean, &rec.ycov, &gp.jitter)?;
                mbar += gm;
                ycovbar += gc;
            }
        }
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
        let (mub, sigb) = mm_backward(
            gp, &wsig, &rec.cache, &mbar, &xcovbar, &vbar, adj, &mut work,
        );
        for k in 0..d {
            mubar[k] += mub[k];
        }
        add_block(&mut sigmabar, (0, 0), &sigb);
        mubar_next = mubar;
        sigmabar_next = sigmabar;
    }
    Ok(RolloutAdjoint {
        total,
        steps: recs.len(),
        theta: theta_bar,
        start_cov: sigmabar_next,
    })
}

/// `m[at..] += b` for a block.
fn add_block(m: &mut DMatrix<f64>, at: (usize, usize), b: &DMatrix<f64>) {
    for i in 0..b.nrows() {
        for j in 0..b.ncols() {
            m[(at.0 + i, at.1 + j)] += b[(i, j)];
        }
    }
}

/// What one episode contributes to the loss and its adjoints.
struct EpisodeOut {
    adj: GpAdjoint,
    nll: f64,
    steps: usize,
    log: JitterLog,
}

/// Environment variable with the number of threads the loss gradient runs its episodes on
/// (default: every available core).
pub const THREADS_VAR: &str = "MSGP_THREADS";

/// Threads for the episodes of one loss gradient: [`THREADS_VAR`] if set to a positive integer,
/// else the available parallelism.
pub fn thread_count() -> usize {
    std::env::var(THREADS_VAR)
        .ok()
        .and_then(|v| v.trim().parse::<usize>().ok())
        .filter(|&n| n > 0)
        .unwrap_or_else(|| std::thread::available_parallelism().map_or(1, |n| n.get()))
}

/// Value and gradient (in [`GpParams::to_flat`] layout) of the MSGP loss, by the adjoint sweep.
/// Episodes run on [`thread_count`] threads; the result is bit-identical for any thread count.
pub fn loss_and_gradient(
    params: &GpParams<f64>,
    config: &GpConfig,
    spec: &NarxSpec,
    episodes: &[Episode],
    complexity: Complexity,
    log: &mut JitterLog,
) -> Result<(LossValue<f64>, Vec<f64>)> {
    loss_and_gradient_with_threads(
        params,
        config,
        spec,
        episodes,
        complexity,
        thread_count(),
        log,
    )
}

/// [`loss_and_gradient`] with the episodes on up to `threads` threads (1: the calling thread
/// only). Every episode accumulates its own adjoints and the episodes are summed in order, so
/// the result does not depend on `threads`.
pub fn loss_and_gradient_with_threads(
    params: &GpParams<f64>,
    config: &GpConfig,
    spec: &NarxSpec,
    episodes: &[Episode],
    complexity: Complexity,
    threads: usize,
    log: &mut JitterLog,
) -> Result<(LossValue<f64>, Vec<f64>)> {
    let shape: GpShape = params.shape()?;
    let GpShape { m, d, e } = shape;
    let gp = PreparedGp::new(params, config, log)?;
    // one adjoint accumulator per episode, summed in episode order: the result does not depend
    // on how many threads ran the episodes
    let run = |k: usize, ep: &Episode| -> Result<EpisodeOut> {
        ep.traj
            .check(spec)
            .map_err(|err| MsgpError::Data(format!("episode {k}: {err}")))?;
        let policy = match &ep.excitation {
            Excitation::FeedForward => None,
            Excitation::Feedback(p) => Some(p.as_ref()),
        };
        let mut adj = GpAdjoint::zeros(m, d, e);
        let mut elog = JitterLog::default();
        let (nll, steps) = episode_adjoint(&gp, spec, &ep.traj, policy, &mut adj, &mut elog)?;
        Ok(EpisodeOut {
            adj,
            nll,
            steps,
            log: elog,
        })
    };
    let outs = crate::parallel::map_indexed(episodes, threads, run);
    let mut adj = GpAdjoint::zeros(m, d, e);
    let mut nll = 0.0;
    let mut steps = 0;
    for out in outs {
        let out = out?;
        adj.add(&out.adj);
        log.merge(&out.log);
        nll += out.nll;
        steps += out.steps;
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
