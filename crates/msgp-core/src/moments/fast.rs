//! The f64 moment-matching kernel: the same mathematics as [`crate::moments::moment_match_generic`]
//! (which stays the reference and is what dual numbers run), organised for speed.
//!
//! - Every `D × m` quantity (`ν̃ᵀ`, `Ŝ⁻¹ν̃ᵀ`, `Ã`, `B̃`, `N Ã`, `N B̃`) is stored as `D` contiguous
//!   rows of `mp` entries (`m` padded to a multiple of 8, the padding kept at zero), so the
//!   triangular solves with `m` right-hand sides are axpys over whole rows instead of
//!   `m` column-by-column solves, and `N B̃ = B̃ − S̃⁻¹B̃` costs two such solves.
//! - The `m × m` block `Q_ij = exp(u^a_i + u^b_j + Ã_iᵀ N B̃_j)` is never formed for the loss:
//!   for blocks of four columns, the exponents are formed in tiles of eight rows with the
//!   product `Ãᵀ (N B̃)` accumulated in registers (a small GEMM micro-kernel, [`q_exponents`]),
//!   written to a buffer of `4·mp`, exponentiated there by the vectorised polynomial
//!   [`crate::numeric::simd::exp_q`] and reduced while in L1: `Σ (ββᵀ − K̃⁻¹) ∘ Q` over the lower
//!   triangle for a diagonal pair ([`q_reduce_sym`], weights prepared once per loss),
//!   `β_aᵀ Q β_b` for the others ([`q_reduce_pair`]). The adjoint recomputes `Q` with the same
//!   code ([`q_matrix`]) instead of storing it for every step.
//! - Buffers live in an [`MmState`] that is reused from step to step (thread-local for the
//!   rollout path), so a step allocates only its small outputs.
//!
//! [`crate::numeric::simd::dispatch`] runs the kernel with AVX2 + FMA when the CPU has them. Results
//! agree with the generic path to rounding (`tests/fast_path.rs`).

use std::cell::RefCell;

use nalgebra::{DMatrix, DVector};

use crate::error::Result;
use crate::gp::PreparedGp;
use crate::moments::Moments;
use crate::numeric::linalg::{JitterLog, cholesky};
use crate::numeric::simd::{
    Kernel, NJ, dispatch, dot, dot_into, exp_q, exp_slice, hsum, madd, padded, solve_lower_rows,
    solve_upper_rows, sum, sym_weights,
};

/// Per-output intermediates (output `a`), `D × mp` row blocks unless noted.
#[derive(Clone, Debug, Default)]
pub(crate) struct OutBufs {
    /// `s = Λ_a^{-½}` (D).
    pub s: Vec<f64>,
    /// Cholesky factor of `Ŝ = I + diag(s) Σ diag(s)`.
    pub l: DMatrix<f64>,
    /// `ν̃ᵀ = diag(s) νᵀ`.
    pub nut: Vec<f64>,
    /// `Ŵ = Ŝ⁻¹ ν̃ᵀ`.
    pub w: Vec<f64>,
    /// `q_i` (mp, zero padding).
    pub q: Vec<f64>,
    /// `β_i q_i` (mp, zero padding).
    pub bq: Vec<f64>,
    /// `V[:, a] = diag(s) Ŵ (β ∘ q)` (D).
    pub acc: Vec<f64>,
    /// `log k_a(x̄_i, μ)` (mp).
    pub lk: Vec<f64>,
    /// `β` padded with zeros to mp (only with two or more outputs).
    pub beta_p: Vec<f64>,
}

/// Per output-pair intermediates.
#[derive(Clone, Debug, Default)]
pub(crate) struct PairBufs {
    pub a: usize,
    pub b: usize,
    /// `√p`, `p = Λ_a⁻¹ + Λ_b⁻¹` (D).
    pub sp: Vec<f64>,
    /// Cholesky factor of `S̃ = I + diag(√p) Σ diag(√p)`.
    pub l: DMatrix<f64>,
    /// `Ã`, `B̃` (`B̃` is `Ã` when `a == b` and then left empty).
    pub at: Vec<f64>,
    pub bt: Vec<f64>,
    /// `N Ã`, `N B̃` (`N Ã` left empty when `a == b`).
    pub na: Vec<f64>,
    pub nb: Vec<f64>,
    /// `u^a_i`, `u^b_j` (mp).
    pub ua: Vec<f64>,
    pub ub: Vec<f64>,
}

/// Workspace and, after [`MmState::forward`], the intermediates of one moment-matching step.
#[derive(Clone, Debug, Default)]
pub(crate) struct MmState {
    pub m: usize,
    pub d: usize,
    pub mp: usize,
    /// `νᵀ = (X̄ − μ)ᵀ` as `D × mp` rows.
    pub nu_t: Vec<f64>,
    pub outs: Vec<OutBufs>,
    pub pairs: Vec<PairBufs>,
    /// `4 · mp` buffer of `Q`'s exponents.
    ebuf: Vec<f64>,
    /// `D × mp` scratch.
    tmp: Vec<f64>,
    /// Outputs: mean (E), cov (E × E), `V` (D × E).
    pub mean: DVector<f64>,
    pub cov: DMatrix<f64>,
}

fn resize(v: &mut Vec<f64>, n: usize) {
    v.clear();
    v.resize(n, 0.0);
}

/// `I + diag(p) Σ diag(p)`.
pub(crate) fn scaled_plus_identity(sigma: &DMatrix<f64>, p: &[f64]) -> DMatrix<f64> {
    let d = sigma.nrows();
    DMatrix::from_fn(d, d, |i, j| {
        p[i] * sigma[(i, j)] * p[j] + if i == j { 1.0 } else { 0.0 }
    })
}

struct Forward<'a> {
    st: &'a mut MmState,
    gp: &'a PreparedGp<f64>,
    mu: &'a DVector<f64>,
    sigma: &'a DMatrix<f64>,
    log: &'a mut JitterLog,
}

impl Kernel for Forward<'_> {
    type Output = Result<()>;
    #[inline(always)]
    fn run<const F: bool>(self) -> Result<()> {
        self.st
            .forward_impl::<F>(self.gp, self.mu, self.sigma, self.log)
    }
}

impl MmState {
    /// Moment matching of `N(mu, sigma)` through `gp`; the intermediates stay in `self`.
    pub fn forward(
        &mut self,
        gp: &PreparedGp<f64>,
        mu: &DVector<f64>,
        sigma: &DMatrix<f64>,
        log: &mut JitterLog,
    ) -> Result<()> {
        dispatch(Forward {
            st: self,
            gp,
            mu,
            sigma,
            log,
        })
    }

    /// The moments of the last [`forward`](Self::forward).
    pub fn moments(&self, sigma: &DMatrix<f64>) -> Moments<f64> {
        let (d, e) = (self.d, self.outs.len());
        let v = DMatrix::from_fn(d, e, |k, a| self.outs[a].acc[k]);
        Moments {
            mean: self.mean.clone(),
            cov: self.cov.clone(),
            io_cov: sigma * &v,
            v,
        }
    }

    #[inline(always)]
    fn forward_impl<const F: bool>(
        &mut self,
        gp: &PreparedGp<f64>,
        mu: &DVector<f64>,
        sigma: &DMatrix<f64>,
        log: &mut JitterLog,
    ) -> Result<()> {
        let x = &gp.pseudo_inputs;
        let (m, d) = (x.nrows(), x.ncols());
        let e = gp.output_dim();
        let mp = padded(m);
        self.m = m;
        self.d = d;
        self.mp = mp;
        resize(&mut self.nu_t, d * mp);
        for k in 0..d {
            let row = &mut self.nu_t[k * mp..k * mp + m];
            let (xk, muk) = (x.column(k), mu[k]);
            for i in 0..m {
                row[i] = xk[i] - muk;
            }
        }
        resize(&mut self.ebuf, NJ * mp);
        resize(&mut self.tmp, d * mp);
        self.outs.resize_with(e, OutBufs::default);
        self.mean = DVector::zeros(e);
        self.cov = DMatrix::zeros(e, e);

        for (a, o) in gp.outputs.iter().enumerate() {
            let ob = &mut self.outs[a];
            ob.s.clear();
            ob.s.extend(o.inv_l2.iter().map(|v| v.sqrt()));
            let ch = cholesky(
                &scaled_plus_identity(sigma, &ob.s),
                &gp.jitter,
                "I + Λ^{-½} Σ Λ^{-½}",
            )?;
            log.record(ch.jitter);
            let logdet = ch.log_det();
            ob.l = ch.l;
            resize(&mut ob.nut, d * mp);
            for k in 0..d {
                let sk = ob.s[k];
                let (src, dst) = (
                    &self.nu_t[k * mp..(k + 1) * mp],
                    &mut ob.nut[k * mp..(k + 1) * mp],
                );
                for (t, v) in dst.iter_mut().zip(src) {
                    *t = v * sk;
                }
            }
            ob.w.clear();
            ob.w.extend_from_slice(&ob.nut);
            solve_lower_rows::<F>(&ob.l, &mut ob.w, d, mp);
            solve_upper_rows::<F>(&ob.l, &mut ob.w, d, mp);
            // quad_i = ν̃_iᵀŴ_i, plain_i = ‖ν̃_i‖², accumulated row by row
            let lsf2 = o.sf2.ln();
            resize(&mut ob.lk, mp);
            resize(&mut ob.q, mp);
            {
                let (quad, plain) = (&mut ob.q, &mut ob.lk);
                for k in 0..d {
                    let (nr, wr) = (&ob.nut[k * mp..(k + 1) * mp], &ob.w[k * mp..(k + 1) * mp]);
                    for i in 0..mp {
                        quad[i] = madd::<F>(nr[i], wr[i], quad[i]);
                        plain[i] = madd::<F>(nr[i], nr[i], plain[i]);
                    }
                }
                for i in 0..mp {
                    plain[i] = lsf2 - plain[i] * 0.5;
                    quad[i] = lsf2 - (quad[i] + logdet) * 0.5;
                }
            }
            exp_slice::<F>(&mut ob.q);
            resize(&mut ob.bq, mp);
            let beta = o.beta.as_slice();
            // only the off-diagonal pairs' reduction reads β padded
            if e > 1 {
                resize(&mut ob.beta_p, mp);
                ob.beta_p[..m].copy_from_slice(beta);
            }
            for i in 0..m {
                ob.bq[i] = beta[i] * ob.q[i];
            }
            for i in m..mp {
                ob.q[i] = 0.0;
            }
            self.mean[a] = sum(&ob.bq);
            ob.acc.clear();
            for k in 0..d {
                ob.acc
                    .push(ob.s[k] * dot::<F>(&ob.w[k * mp..(k + 1) * mp], &ob.bq));
            }
        }

        let npairs = e * (e + 1) / 2;
        self.pairs.resize_with(npairs, PairBufs::default);
        let mut pi = 0;
        for a in 0..e {
            for b in a..e {
                let (oa, obp) = (&gp.outputs[a], &gp.outputs[b]);
                let pb = &mut self.pairs[pi];
                pi += 1;
                pb.a = a;
                pb.b = b;
                pb.sp.clear();
                pb.sp
                    .extend((0..d).map(|k| (oa.inv_l2[k] + obp.inv_l2[k]).sqrt()));
                let ch = cholesky(
                    &scaled_plus_identity(sigma, &pb.sp),
                    &gp.jitter,
                    "I + P^{½} Σ P^{½}",
                )?;
                log.record(ch.jitter);
                let logdet_r = ch.log_det();
                pb.l = ch.l;
                let diag = a == b;
                // Ã, B̃
                scaled_rows(&mut pb.at, &oa.inv_l2, &self.nu_t, &pb.sp, d, mp);
                if diag {
                    pb.bt.clear();
                    pb.na.clear();
                } else {
                    scaled_rows(&mut pb.bt, &obp.inv_l2, &self.nu_t, &pb.sp, d, mp);
                }
                {
                    let bt: &[f64] = if diag { &pb.at } else { &pb.bt };
                    apply_n::<F>(&mut pb.nb, bt, &mut self.tmp, &pb.l, d, mp);
                }
                if !diag {
                    apply_n::<F>(&mut pb.na, &pb.at, &mut self.tmp, &pb.l, d, mp);
                }
                resize(&mut pb.ua, mp);
                resize(&mut pb.ub, mp);
                {
                    let (at, bt) = (&pb.at[..], if diag { &pb.at[..] } else { &pb.bt[..] });
                    let (na, nb) = (if diag { &pb.nb[..] } else { &pb.na[..] }, &pb.nb[..]);
                    for k in 0..d {
                        let r = k * mp..(k + 1) * mp;
                        let (ar, nar, br, nbr) =
                            (&at[r.clone()], &na[r.clone()], &bt[r.clone()], &nb[r]);
                        for i in 0..mp {
                            pb.ua[i] = madd::<F>(ar[i], nar[i], pb.ua[i]);
                            pb.ub[i] = madd::<F>(br[i], nbr[i], pb.ub[i]);
                        }
                    }
                    let (lka, lkb) = (&self.outs[a].lk, &self.outs[b].lk);
                    for i in 0..mp {
                        pb.ua[i] = lka[i] + pb.ua[i] * 0.5;
                        pb.ub[i] = lkb[i] + pb.ub[i] * 0.5 - logdet_r * 0.5;
                    }
                }
                let v = if diag {
                    // a GP prepared without the weights (not built by PreparedGp::new) gets
                    // them made here
                    let made;
                    let weights: &[f64] = if oa.q_weights.len() == m.div_ceil(NJ) * NJ * mp {
                        &oa.q_weights
                    } else {
                        made = sym_weights(&oa.beta, &oa.kinv);
                        &made
                    };
                    let red = q_reduce_sym::<F>(
                        m,
                        mp,
                        d,
                        &pb.at,
                        &pb.nb,
                        &pb.ua,
                        &pb.ub,
                        weights,
                        &mut self.ebuf,
                    );
                    red - self.mean[a] * self.mean[b] + oa.sf2
                } else {
                    let ebb = q_reduce_pair::<F>(
                        m,
                        mp,
                        d,
                        &pb.at,
                        &pb.nb,
                        &pb.ua,
                        &pb.ub,
                        &self.outs[a].beta_p,
                        &self.outs[b].beta_p,
                        &mut self.ebuf,
                    );
                    ebb - self.mean[a] * self.mean[b]
                };
                self.cov[(a, b)] = v;
                self.cov[(b, a)] = v;
            }
        }
        Ok(())
    }
}

/// `dst[k, :] = src[k, :] · il2_k / sp_k` (`Ã` or `B̃` from `νᵀ`).
#[inline(always)]
fn scaled_rows(dst: &mut Vec<f64>, il2: &[f64], nu_t: &[f64], sp: &[f64], d: usize, mp: usize) {
    resize(dst, d * mp);
    for k in 0..d {
        let f = il2[k] / sp[k];
        let (src, out) = (&nu_t[k * mp..(k + 1) * mp], &mut dst[k * mp..(k + 1) * mp]);
        for (t, v) in out.iter_mut().zip(src) {
            *t = v * f;
        }
    }
}

/// `dst = N src = src − S̃⁻¹ src` for `D × mp` rows, `S̃ = L Lᵀ`.
#[inline(always)]
fn apply_n<const F: bool>(
    dst: &mut Vec<f64>,
    src: &[f64],
    tmp: &mut Vec<f64>,
    l: &DMatrix<f64>,
    d: usize,
    mp: usize,
) {
    tmp.clear();
    tmp.extend_from_slice(src);
    solve_lower_rows::<F>(l, tmp, d, mp);
    solve_upper_rows::<F>(l, tmp, d, mp);
    resize(dst, d * mp);
    for ((o, s), t) in dst.iter_mut().zip(src).zip(tmp.iter()) {
        *o = s - t;
    }
}

/// Rows of `Q` per tile: one vector of the dispatched instruction set.
const LANES: usize = crate::numeric::simd::CHUNK;

/// The exponents of `Q` for columns `j0..j0 + NJ`, rows `first..mp` in tiles of [`LANES`]:
/// `u^a_i + u^b_j + (Ãᵀ Y)_ij` with `Y = N B̃`, the product accumulated in registers, written
/// to `ebuf[jj·(mp − first) + i − first]`: the block's `NJ` columns lie end to end, so that one
/// loop exponentiates all of them (a loop of exponentials is latency-bound, and longer loops
/// overlap more of them). Every pass over `Q` (the loss's reductions and the adjoint's
/// recomputation) exponentiates what this function writes with [`exp_q`], so they all see the
/// same bits.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
fn q_exponents<const F: bool>(
    d: usize,
    mp: usize,
    at: &[f64],
    y: &[f64],
    ua: &[f64],
    ub: &[f64],
    first: usize,
    j0: usize,
    ebuf: &mut [f64],
) {
    let ld = mp - first;
    let mut i0 = first;
    while i0 < mp {
        let mut acc = [[0.0f64; LANES]; NJ];
        for k in 0..d {
            let a = &at[k * mp + i0..k * mp + i0 + LANES];
            let yk = &y[k * mp + j0..k * mp + j0 + NJ];
            for jj in 0..NJ {
                let yv = yk[jj];
                for l in 0..LANES {
                    acc[jj][l] = madd::<F>(a[l], yv, acc[jj][l]);
                }
            }
        }
        let uai = &ua[i0..i0 + LANES];
        for jj in 0..NJ {
            let ubj = ub[j0 + jj];
            let o = jj * ld + i0 - first;
            let out = &mut ebuf[o..o + LANES];
            for l in 0..LANES {
                out[l] = uai[l] + ubj + acc[jj][l];
            }
        }
        i0 += LANES;
    }
}

/// The first row of the tiles of column block `j0` in a symmetric pass: the start of the
/// row chunk that holds the diagonal (rows above it are not needed, `Q` being symmetric).
#[inline(always)]
fn sym_start(j0: usize) -> usize {
    j0 / LANES * LANES
}

/// `x ← e^x` by [`exp_q`] (a plain loop over the slice, which the compiler vectorises).
#[inline(always)]
fn exp_q_slice<const F: bool>(x: &mut [f64]) {
    for v in x.iter_mut() {
        *v = exp_q::<F>(*v);
    }
}

/// `Σ_ij W_ij Q_ij` for a diagonal output pair (`Q` symmetric), with `W` from
/// [`sym_weights`]: only the tiles on or below the diagonal are computed, and each column is
/// exponentiated and reduced while in L1 (`Q` is never stored). `ebuf` holds `NJ · mp`.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(crate) fn q_reduce_sym<const F: bool>(
    m: usize,
    mp: usize,
    d: usize,
    at: &[f64],
    y: &[f64],
    ua: &[f64],
    ub: &[f64],
    w: &[f64],
    ebuf: &mut [f64],
) -> f64 {
    let mut total = [0.0f64; crate::numeric::simd::CHUNK];
    let mut j0 = 0;
    while j0 < m {
        let start = sym_start(j0);
        let ld = mp - start;
        q_exponents::<F>(d, mp, at, y, ua, ub, start, j0, ebuf);
        exp_q_slice::<F>(&mut ebuf[..NJ * ld]);
        for jj in 0..NJ {
            let c = (j0 + jj) * mp;
            dot_into::<F>(
                &ebuf[jj * ld..(jj + 1) * ld],
                &w[c + start..c + mp],
                &mut total,
            );
        }
        j0 += NJ;
    }
    hsum(&total)
}

/// `β_aᵀ Q β_b` for an off-diagonal output pair; `beta_a` and `beta_b` are padded with zeros
/// to `mp` entries. `ebuf` holds `NJ · mp`.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(crate) fn q_reduce_pair<const F: bool>(
    m: usize,
    mp: usize,
    d: usize,
    at: &[f64],
    y: &[f64],
    ua: &[f64],
    ub: &[f64],
    beta_a: &[f64],
    beta_b: &[f64],
    ebuf: &mut [f64],
) -> f64 {
    let mut ebb = 0.0;
    let mut j0 = 0;
    while j0 < m {
        q_exponents::<F>(d, mp, at, y, ua, ub, 0, j0, ebuf);
        exp_q_slice::<F>(&mut ebuf[..NJ * mp]);
        for jj in 0..NJ {
            ebb += dot::<F>(&ebuf[jj * mp..(jj + 1) * mp], beta_a) * beta_b[j0 + jj];
        }
        j0 += NJ;
    }
    ebb
}

/// `Q` itself (m × m, column-major, into `q`), for the adjoint's backward pass: the same
/// exponents and exponential as the forward's reductions, bit for bit. A symmetric pass
/// computes the lower triangle and mirrors it. `ebuf` holds `NJ · mp`.
#[inline(always)]
#[allow(clippy::too_many_arguments)]
pub(crate) fn q_matrix<const F: bool>(
    m: usize,
    mp: usize,
    d: usize,
    at: &[f64],
    y: &[f64],
    ua: &[f64],
    ub: &[f64],
    sym: bool,
    ebuf: &mut [f64],
    q: &mut [f64],
) {
    let mut j0 = 0;
    while j0 < m {
        let start = if sym { sym_start(j0) } else { 0 };
        let ld = mp - start;
        q_exponents::<F>(d, mp, at, y, ua, ub, start, j0, ebuf);
        for jj in 0..NJ.min(m - j0) {
            let j = j0 + jj;
            let (col, e) = (
                &mut q[j * m + start..(j + 1) * m],
                &ebuf[jj * ld..jj * ld + m - start],
            );
            for (qv, ev) in col.iter_mut().zip(e) {
                *qv = exp_q::<F>(*ev);
            }
        }
        j0 += NJ;
    }
    if sym {
        for j in 0..m {
            for i in (j + 1)..m {
                q[i * m + j] = q[j * m + i];
            }
        }
    }
}

thread_local! {
    static STATE: RefCell<MmState> = RefCell::new(MmState::default());
}

/// [`crate::moments::moment_match_generic`] for f64, through the fast kernel (the workspace is
/// per thread and reused).
pub(crate) fn moment_match_f64(
    gp: &PreparedGp<f64>,
    mu: &DVector<f64>,
    sigma: &DMatrix<f64>,
    log: &mut JitterLog,
) -> Result<Moments<f64>> {
    STATE.with(|cell| match cell.try_borrow_mut() {
        Ok(mut st) => {
            st.forward(gp, mu, sigma, log)?;
            Ok(st.moments(sigma))
        }
        // re-entrant use (not expected): a fresh workspace
        Err(_) => {
            let mut st = MmState::default();
            st.forward(gp, mu, sigma, log)?;
            Ok(st.moments(sigma))
        }
    })
}
