//! The vector–Jacobian product of one f64 moment-matching step ([`super::fast`]), derived by
//! hand: the backward pass of every adjoint sweep (`crate::rollout::adjoint`).
//!
//! It recomputes `Q` by the forward's own code (bit for bit what the forward used) and pulls the
//! adjoints of the step's mean, covariance and `V` back to the window's `(μ, Σ)` and to the
//! prepared GP's quantities ([`GpAdjoint`]). Tested through the sweeps against forward-mode duals
//! (`tests/adjoint_vs_dual.rs`), which are in turn tested against finite differences.
//!
//! Notation follows [`crate::moments`]: for output `a`, `s = Λ_a^{-½}` (as a vector),
//! `Ŝ = I + diag(s) Σ diag(s)`, `Ŵ = Ŝ⁻¹ diag(s) νᵀ`, `q_i = σ_f² |Ŝ|^{-½} exp(−½ ν̃_iᵀŴ_i)`;
//! for a pair `(a, b)`, `p = Λ_a⁻¹ + Λ_b⁻¹`, `S̃ = I + diag(√p) Σ diag(√p)`, `N = I − S̃⁻¹`,
//! `Ã = diag(Λ_a⁻¹/√p) νᵀ`, `B̃ = diag(Λ_b⁻¹/√p) νᵀ` and
//! `Q_ij = exp(lk^a_i + lk^b_j − ½ log|S̃| + ½ (Ã_i + B̃_j)ᵀ N (Ã_i + B̃_j))`.

use nalgebra::{DMatrix, DVector};

use super::fast::{MmState, q_matrix};
use crate::gp::PreparedGp;
use crate::numeric::simd::{
    Kernel, axpy, chol_inverse, dispatch, dot, gemm_rows, gram_add, solve_lower_rows,
    solve_upper_rows, sum,
};

/// Adjoint accumulators for the quantities the rollout reads from the prepared GP.
pub(crate) struct GpAdjoint {
    pub(crate) xbar: DMatrix<f64>,      // m × D (pseudo-inputs, direct)
    pub(crate) beta: Vec<DVector<f64>>, // per output
    pub(crate) kinv: Vec<DMatrix<f64>>, // per output
    pub(crate) inv_l2: DMatrix<f64>,    // E × D
    pub(crate) sf2: Vec<f64>,
    pub(crate) sx2: Vec<f64>,
    pub(crate) sy2: Vec<f64>,
    pub(crate) lin: DMatrix<f64>, // E × D (linear prior mean)
}

impl GpAdjoint {
    /// `self += o`, field by field (the destructuring is exhaustive: a new field must be added
    /// here, or the per-episode sums would drop it).
    pub(crate) fn add(&mut self, o: &GpAdjoint) {
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

    /// All-zero accumulators for `m` pseudo-inputs, input dimension `d` and `e` outputs.
    pub(crate) fn zeros(m: usize, d: usize, e: usize) -> Self {
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
pub(crate) struct BackWork {
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

/// One backward moment-matching step: the adjoints of its (mean, cov, V) to pull back to
/// (μ, Σ) and the GP quantities; [`Backward::pull`] returns (μ̄, Σ̄) and adds to `adj`.
pub(crate) struct Backward<'a> {
    pub gp: &'a PreparedGp<f64>,
    pub sigma: &'a DMatrix<f64>,
    pub c: &'a MmState,
    pub mbar_in: &'a DVector<f64>,
    pub sbar: &'a DMatrix<f64>,
    pub vbar: &'a DMatrix<f64>,
    pub adj: &'a mut GpAdjoint,
    pub w: &'a mut BackWork,
}

impl Backward<'_> {
    /// Runs the pass in the CPU's widest instruction set.
    pub fn pull(self) -> (DVector<f64>, DMatrix<f64>) {
        dispatch(self)
    }
}

impl Kernel for Backward<'_> {
    type Output = (DVector<f64>, DMatrix<f64>);
    #[inline(always)]
    fn run<const F: bool>(self) -> Self::Output {
        mm_backward_impl::<F>(self)
    }
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
