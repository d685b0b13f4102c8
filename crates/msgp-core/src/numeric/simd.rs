//! Small f64 building blocks for the fast moment-matching kernel ([`crate::moments::fast`]): a
//! polynomial `exp` over slices, dot products with independent partial sums, and triangular
//! solves whose right-hand sides are the contiguous rows of a `D × mp` block. All are written as
//! plain scalar loops that the compiler vectorises; [`dispatch`] runs a kernel inside pulp's
//! runtime-detected AVX-512 context (x86-64-v4: 8 lanes, which is [`CHUNK`]) or AVX2 + FMA
//! context (x86-64-v3), whichever the CPU has, and as portable code otherwise. No `unsafe`:
//! pulp's `Arch::dispatch` is the safe entry point. (AVX-512 made the D = 4 loss ≈ 20 % and its
//! gradient ≈ 10 % faster than AVX2 on the development machine's Xeon; BENCHMARKS.md.)
//!
//! Everything is `#[inline(always)]` so that it is compiled with the dispatching function's
//! target features. The const parameter `F` selects fused multiply-add (`true` only inside the
//! FMA context; elsewhere `mul_add` would be a libm call).

use nalgebra::{DMatrix, DVector};

/// Rows of the blocked kernels are padded to a multiple of this many entries.
pub(crate) const CHUNK: usize = 8;

/// `m` rounded up to a multiple of [`CHUNK`].
#[inline]
pub(crate) fn padded(m: usize) -> usize {
    m.div_ceil(CHUNK) * CHUNK
}

/// A kernel generic over the use of fused multiply-add. Implementations mark `run`
/// `#[inline(always)]`: otherwise it is compiled without the dispatched target features and
/// every `mul_add` becomes a libm call (measured 1.3× slower on the whole loss).
pub(crate) trait Kernel {
    type Output;
    fn run<const F: bool>(self) -> Self::Output;
}

struct Dispatch<K>(K);

impl<K: Kernel> pulp::WithSimd for Dispatch<K> {
    type Output = K::Output;
    #[inline(always)]
    fn with_simd<S: pulp::Simd>(self, _simd: S) -> K::Output {
        if S::IS_SCALAR {
            self.0.run::<false>()
        } else {
            self.0.run::<true>()
        }
    }
}

/// Runs `k` with the best instruction set the CPU offers (AVX-512, AVX2 + FMA or portable code).
#[inline]
pub(crate) fn dispatch<K: Kernel>(k: K) -> K::Output {
    pulp::Arch::new().dispatch(Dispatch(k))
}

/// `a·b + c`, fused when `F`.
#[inline(always)]
pub(crate) fn madd<const F: bool>(a: f64, b: f64, c: f64) -> f64 {
    if F { a.mul_add(b, c) } else { a * b + c }
}

const LOG2E: f64 = std::f64::consts::LOG2_E;
// fdlibm's split of ln 2: the high part has 21 trailing zero bits, so `n · LN2_HI` is exact
// for |n| < 2¹¹.
const LN2_HI: f64 = f64::from_bits(0x3FE6_2E42_FEE0_0000);
const LN2_LO: f64 = f64::from_bits(0x3DEA_39EF_3579_3C76);
// 1.5 · 2⁵²: adding it rounds to an integer held in the low mantissa bits.
const SHIFT: f64 = 6_755_399_441_055_744.0;
// The minimax polynomial `p` of degree 9 with `e^r ≈ 1 + r + r² p(r)` on `|r| ≤ ½ ln 2` (a
// degree-11 approximation of `e^r`): relative error 3.6·10⁻¹⁸, far below half an ulp. Computed
// by a Remez exchange in 60-digit arithmetic (`benches/reference/exp_minimax.py`); each literal
// is the coefficient rounded to f64 (the shortest decimal that reads back as that double).
const P: [f64; 10] = [
    0.500_000_000_000_001_1,
    0.166_666_666_666_664_13,
    0.041_666_666_666_530_267,
    0.008_333_333_333_494_333,
    0.001_388_888_894_359_806_5,
    0.000_198_412_695_067_800_84,
    2.480_149_313_577_340_5e-5,
    2.755_758_626_518_208e-6,
    2.763_023_407_657_713e-7,
    2.500_007_294_401_615_4e-8,
];

/// `2^n` for an integer-valued `n` in `[-1022, 1023]`, built from the exponent bits.
#[inline(always)]
fn pow2(n: f64) -> f64 {
    f64::from_bits((n + (1023.0 + SHIFT)).to_bits() << 52)
}

/// The reduced exponential, the part [`exp1`] and [`exp_q`] share: `(e^r, n, t)` with
/// `e^x = e^r 2ⁿ`, `|r| ≤ ½ ln 2`, for `x` clamped above at 710 (`n ≤ 1024`), and `t` the
/// shifted value whose low mantissa bits hold `n` in two's complement. Cody–Waite reduction,
/// then `e^r = 1 + (r + r² p(r))` with the degree-9 polynomial [`P`] evaluated by Estrin's
/// scheme: its dependency chain is four multiply-adds deep instead of Horner's nine, which is
/// what bounds a vectorised loop of exponentials (measured 1.64 → 1.16 ns per exponential with
/// AVX2 on an AMD EPYC, together with [`exp_q`]'s integer scaling).
#[inline(always)]
fn exp_reduced<const F: bool>(x: f64) -> (f64, f64, f64) {
    // comparisons are false for NaN, which therefore passes through
    let x = if x > 710.0 { 710.0 } else { x };
    let t = madd::<F>(x, LOG2E, SHIFT);
    let n = t - SHIFT;
    let r = madd::<F>(n, -LN2_HI, x);
    let r = madd::<F>(n, -LN2_LO, r);
    let r2 = r * r;
    let r4 = r2 * r2;
    let r8 = r4 * r4;
    let a0 = madd::<F>(P[1], r, P[0]);
    let a1 = madd::<F>(P[3], r, P[2]);
    let a2 = madd::<F>(P[5], r, P[4]);
    let a3 = madd::<F>(P[7], r, P[6]);
    let a4 = madd::<F>(P[9], r, P[8]);
    let b0 = madd::<F>(a1, r2, a0);
    let b1 = madd::<F>(a3, r2, a2);
    let c0 = madd::<F>(b1, r4, b0);
    let p = madd::<F>(a4, r8, c0);
    // e^r = 1 + (r + r² p(r)): the small part first, one rounding into the final sum
    (1.0 + madd::<F>(r2, p, r), n, t)
}

/// `e^x` to within about one ulp of the correctly rounded value (tested against `f64::exp`),
/// branch-free so that loops over it vectorise. `x = n ln 2 + r` with `|r| ≤ ½ ln 2`
/// (Cody–Waite), a degree-11 minimax polynomial for `e^r` ([`P`]), and `2^n` applied as two
/// exact power-of-two factors so that subnormal results and overflow to `+∞` come out right.
/// NaN propagates; `x < −746` gives 0 and `x > 710` gives `+∞`.
#[inline(always)]
pub(crate) fn exp1<const F: bool>(x: f64) -> f64 {
    // comparisons are false for NaN, which therefore passes through
    let x = if x < -746.0 { -746.0 } else { x };
    let (y, n, _) = exp_reduced::<F>(x);
    // n ∈ [−1077, 1025]: split into two halves that are each a normal power of two
    let n1 = (n * 0.5 + SHIFT) - SHIFT;
    let n2 = n - n1;
    y * pow2(n1) * pow2(n2)
}

/// `e^x` for the `Q` blocks of moment matching: [`exp1`]'s result, bit for bit, for
/// `−708 ≤ x ≤ 709.4`. There the result is normal, so `2ⁿ` is applied exactly by adding `n`
/// to the exponent bits of `e^r` (an integer add instead of a multiplication and the
/// construction of `2ⁿ`). Results below `e^{−708}` (`x < −708`, a subnormal or zero `Q` entry)
/// are flushed to zero; `x > 709.43` (`n = 1024`) gives `+∞` (its last ulp-range of finite
/// values overflows early). NaN propagates. The `Q` block's exponentials are most of the
/// D = 4 loss.
#[inline(always)]
pub(crate) fn exp_q<const F: bool>(x: f64) -> f64 {
    let flush = x < -708.0;
    let (y, n, t) = exp_reduced::<F>(x);
    // n ∈ [−1021, 1023] unless flushed or overflowing: e^r ∈ [0.7, 1.5) times 2ⁿ is normal
    let v = f64::from_bits(y.to_bits().wrapping_add(t.to_bits() << 52));
    let v = if n > 1023.0 { f64::INFINITY } else { v };
    let v = if flush { 0.0 } else { v };
    // a NaN's payload bits would otherwise be shifted into the exponent
    if x.is_nan() { x } else { v }
}

/// `x ← e^x` element-wise.
#[inline(always)]
pub(crate) fn exp_slice<const F: bool>(x: &mut [f64]) {
    for v in x.iter_mut() {
        *v = exp1::<F>(*v);
    }
}

/// The SE-ARD kernel matrix `K_ij = σ_f² exp(−½ Σ_d (a_id − b_jd)² / ℓ_d²)` between the rows of
/// `a` (n × D) and `b` (m × D), column by column: the exponents over `a`'s contiguous columns,
/// then the vectorised [`exp_slice`]. Equal to [`crate::gp::kernel::kernel_matrix_generic`] to
/// rounding (its libm `exp` per entry was ≈ 10 % of a one-step GP fit).
pub(crate) fn kernel_matrix(
    a: &DMatrix<f64>,
    b: &DMatrix<f64>,
    inv_l2: &[f64],
    sf2: f64,
) -> DMatrix<f64> {
    let mut k = DMatrix::<f64>::zeros(a.nrows(), b.nrows());
    dispatch(KernelMatrix {
        a: a.as_slice(),
        b,
        inv_l2,
        sf2,
        out: k.as_mut_slice(),
    });
    k
}

struct KernelMatrix<'a> {
    /// `a` column-major (n × D).
    a: &'a [f64],
    b: &'a DMatrix<f64>,
    inv_l2: &'a [f64],
    sf2: f64,
    /// The n × m result, column-major, zeroed.
    out: &'a mut [f64],
}

impl Kernel for KernelMatrix<'_> {
    type Output = ();
    #[inline(always)]
    fn run<const F: bool>(self) {
        let KernelMatrix {
            a,
            b,
            inv_l2,
            sf2,
            out,
        } = self;
        kernel_columns::<F>(a, b, inv_l2, sf2, out);
    }
}

/// [`kernel_matrix`]'s loops, on plain slice arguments (so the compiler knows `out` aliases
/// none of the inputs).
#[inline(always)]
fn kernel_columns<const F: bool>(
    a: &[f64],
    b: &DMatrix<f64>,
    inv_l2: &[f64],
    sf2: f64,
    out: &mut [f64],
) {
    let (m, dim) = (b.nrows(), b.ncols());
    let n = out.len().checked_div(m).unwrap_or(0);
    for (j, col) in out.chunks_exact_mut(n.max(1)).take(m).enumerate() {
        for d in 0..dim {
            let (bj, w) = (b[(j, d)], -0.5 * inv_l2[d]);
            for (c, &x) in col.iter_mut().zip(&a[d * n..(d + 1) * n]) {
                let t = x - bj;
                *c = madd::<F>(w * t, t, *c);
            }
        }
        exp_slice::<F>(col);
        for c in col.iter_mut() {
            *c *= sf2;
        }
    }
}

/// `Σ a_i b_i` with [`CHUNK`] independent partial sums (vectorisable).
#[inline(always)]
pub(crate) fn dot<const F: bool>(a: &[f64], b: &[f64]) -> f64 {
    let n = a.len().min(b.len());
    let (a, b) = (&a[..n], &b[..n]);
    let mut acc = [0.0f64; CHUNK];
    let full = n / CHUNK * CHUNK;
    for (ca, cb) in a[..full]
        .chunks_exact(CHUNK)
        .zip(b[..full].chunks_exact(CHUNK))
    {
        for l in 0..CHUNK {
            acc[l] = madd::<F>(ca[l], cb[l], acc[l]);
        }
    }
    let mut s = hsum(&acc);
    for i in full..n {
        s = madd::<F>(a[i], b[i], s);
    }
    s
}

/// `acc_l += Σ_k a_{8k+l} b_{8k+l}`: [`dot`] without its horizontal sum and tail, for
/// reductions over many slices whose lengths are multiples of [`CHUNK`].
#[inline(always)]
pub(crate) fn dot_into<const F: bool>(a: &[f64], b: &[f64], acc: &mut [f64; CHUNK]) {
    debug_assert!(a.len().is_multiple_of(CHUNK) && a.len() == b.len());
    for (ca, cb) in a.chunks_exact(CHUNK).zip(b.chunks_exact(CHUNK)) {
        for l in 0..CHUNK {
            acc[l] = madd::<F>(ca[l], cb[l], acc[l]);
        }
    }
}

/// `Σ a_i` with [`CHUNK`] independent partial sums.
#[inline(always)]
pub(crate) fn sum(a: &[f64]) -> f64 {
    let mut acc = [0.0f64; CHUNK];
    let full = a.len() / CHUNK * CHUNK;
    for c in a[..full].chunks_exact(CHUNK) {
        for l in 0..CHUNK {
            acc[l] += c[l];
        }
    }
    let mut s = hsum(&acc);
    for v in &a[full..] {
        s += *v;
    }
    s
}

#[inline(always)]
pub(crate) fn hsum(acc: &[f64; CHUNK]) -> f64 {
    ((acc[0] + acc[4]) + (acc[1] + acc[5])) + ((acc[2] + acc[6]) + (acc[3] + acc[7]))
}

/// `y ← y + α x`.
#[inline(always)]
pub(crate) fn axpy<const F: bool>(alpha: f64, x: &[f64], y: &mut [f64]) {
    for (yi, xi) in y.iter_mut().zip(x) {
        *yi = madd::<F>(alpha, *xi, *yi);
    }
}

/// Solves `L X = B` in place, where `X` (and `B`) are `d` rows of stride `mp` in `x` and `L` is
/// lower triangular (`d × d`): every step is an axpy over a contiguous row.
#[inline(always)]
pub(crate) fn solve_lower_rows<const F: bool>(
    l: &DMatrix<f64>,
    x: &mut [f64],
    d: usize,
    mp: usize,
) {
    for i in 0..d {
        let (done, rest) = x.split_at_mut(i * mp);
        let xi = &mut rest[..mp];
        for k in 0..i {
            axpy::<F>(-l[(i, k)], &done[k * mp..(k + 1) * mp], xi);
        }
        // one division per row, not per entry (a vector division costs ≈ 16 multiplications)
        let inv = 1.0 / l[(i, i)];
        for v in xi.iter_mut() {
            *v *= inv;
        }
    }
}

/// Solves `Lᵀ X = B` in place (same layout as [`solve_lower_rows`]).
#[inline(always)]
pub(crate) fn solve_upper_rows<const F: bool>(
    l: &DMatrix<f64>,
    x: &mut [f64],
    d: usize,
    mp: usize,
) {
    for i in (0..d).rev() {
        let (head, tail) = x.split_at_mut((i + 1) * mp);
        let xi = &mut head[i * mp..];
        for k in (i + 1)..d {
            axpy::<F>(-l[(k, i)], &tail[(k - i - 1) * mp..(k - i) * mp], xi);
        }
        // one division per row, not per entry (a vector division costs ≈ 16 multiplications)
        let inv = 1.0 / l[(i, i)];
        for v in xi.iter_mut() {
            *v *= inv;
        }
    }
}

/// `(L Lᵀ)⁻¹` (symmetrised) from a lower Cholesky factor, as a dense `d × d` matrix.
#[inline(always)]
pub(crate) fn chol_inverse<const F: bool>(l: &DMatrix<f64>) -> DMatrix<f64> {
    let d = l.nrows();
    let mut x = vec![0.0; d * d];
    for i in 0..d {
        x[i * d + i] = 1.0;
    }
    solve_lower_rows::<F>(l, &mut x, d, d);
    solve_upper_rows::<F>(l, &mut x, d, d);
    // x holds rows of A⁻¹ (row i at x[i d..]); A⁻¹ is symmetric up to rounding
    DMatrix::from_fn(d, d, |i, j| 0.5 * (x[i * d + j] + x[j * d + i]))
}

/// [`chol_inverse`] with the best instruction set the CPU offers.
pub(crate) fn spd_inverse(l: &DMatrix<f64>) -> DMatrix<f64> {
    struct Inverse<'a>(&'a DMatrix<f64>);
    impl Kernel for Inverse<'_> {
        type Output = DMatrix<f64>;
        #[inline(always)]
        fn run<const F: bool>(self) -> DMatrix<f64> {
            chol_inverse::<F>(self.0)
        }
    }
    dispatch(Inverse(l))
}

/// `out[k, :] = Σ_j c[k, j] · mat[:, j]` for `k < d`, `j < n`: `c` and `out` are `d` rows of
/// stride `mp`, `mat` holds `n` columns of `mp` entries (column `j` at `j·mp`). Four rows of
/// `out` and eight entries of a row are accumulated in registers over `j` (a GEMM micro-kernel
/// for the `D × m · m × m` products of the adjoint).
#[inline(always)]
pub(crate) fn gemm_rows<const F: bool>(
    c: &[f64],
    mat: &[f64],
    out: &mut [f64],
    d: usize,
    n: usize,
    mp: usize,
) {
    let mut k0 = 0;
    while k0 < d {
        match d - k0 {
            1 => gemm_block::<F, 1>(c, mat, out, k0, n, mp),
            2 => gemm_block::<F, 2>(c, mat, out, k0, n, mp),
            3 => gemm_block::<F, 3>(c, mat, out, k0, n, mp),
            _ => gemm_block::<F, 4>(c, mat, out, k0, n, mp),
        }
        k0 += 4;
    }
}

#[inline(always)]
fn gemm_block<const F: bool, const KB: usize>(
    c: &[f64],
    mat: &[f64],
    out: &mut [f64],
    k0: usize,
    n: usize,
    mp: usize,
) {
    let mut i0 = 0;
    while i0 < mp {
        let mut acc = [[0.0f64; CHUNK]; KB];
        for j in 0..n {
            let col = &mat[j * mp + i0..j * mp + i0 + CHUNK];
            for kk in 0..KB {
                let cv = c[(k0 + kk) * mp + j];
                for l in 0..CHUNK {
                    acc[kk][l] = madd::<F>(col[l], cv, acc[kk][l]);
                }
            }
        }
        for kk in 0..KB {
            out[(k0 + kk) * mp + i0..(k0 + kk) * mp + i0 + CHUNK].copy_from_slice(&acc[kk]);
        }
        i0 += CHUNK;
    }
}

/// `out[(r, s)] += α Σ_i x[r, i] y[s, i]` for `d` rows of stride `mp` (a multiple of
/// [`CHUNK`]; `out` is `d × d`). The sum runs over all `mp` entries, so the padding of `x` or of
/// `y` must be zero. Two rows of `x` against four of `y` at a time, four lanes each.
#[inline(always)]
pub(crate) fn gram_add<const F: bool>(
    x: &[f64],
    y: &[f64],
    alpha: f64,
    out: &mut DMatrix<f64>,
    d: usize,
    mp: usize,
) {
    let mut r0 = 0;
    while r0 + 2 <= d {
        let mut s0 = 0;
        while s0 + 4 <= d {
            gram_block::<F, 2, 4>(x, y, alpha, out, r0, s0, mp);
            s0 += 4;
        }
        while s0 < d {
            gram_block::<F, 2, 1>(x, y, alpha, out, r0, s0, mp);
            s0 += 1;
        }
        r0 += 2;
    }
    if r0 < d {
        let mut s0 = 0;
        while s0 + 4 <= d {
            gram_block::<F, 1, 4>(x, y, alpha, out, r0, s0, mp);
            s0 += 4;
        }
        while s0 < d {
            gram_block::<F, 1, 1>(x, y, alpha, out, r0, s0, mp);
            s0 += 1;
        }
    }
}

#[inline(always)]
fn gram_block<const F: bool, const RB: usize, const SB: usize>(
    x: &[f64],
    y: &[f64],
    alpha: f64,
    out: &mut DMatrix<f64>,
    r0: usize,
    s0: usize,
    mp: usize,
) {
    const W: usize = 4;
    let mut acc = [[[0.0f64; W]; SB]; RB];
    let mut i0 = 0;
    while i0 < mp {
        for rr in 0..RB {
            let xv = &x[(r0 + rr) * mp + i0..(r0 + rr) * mp + i0 + W];
            for ss in 0..SB {
                let yv = &y[(s0 + ss) * mp + i0..(s0 + ss) * mp + i0 + W];
                for l in 0..W {
                    acc[rr][ss][l] = madd::<F>(xv[l], yv[l], acc[rr][ss][l]);
                }
            }
        }
        i0 += W;
    }
    for rr in 0..RB {
        for ss in 0..SB {
            let a = &acc[rr][ss];
            out[(r0 + rr, s0 + ss)] += alpha * ((a[0] + a[2]) + (a[1] + a[3]));
        }
    }
}

/// Columns of `Q` per block of the moment-matching kernel's fused passes (and of the layout of
/// [`sym_weights`]).
pub(crate) const NJ: usize = 4;

/// The reduction weights of a diagonal output pair, for `moments::fast::q_reduce_sym`: the variance of a
/// moment-matched output is `σ_f² − μ² + Σ_ij (β_i β_j − K̃⁻¹_ij) Q_ij`, a sum over the
/// symmetric `Q` that the pass takes over its lower triangle. Column `j` (at `j·mp`, `m`
/// rounded up to [`NJ`] columns) holds `2 (β_i β_j − K̃⁻¹_ij)` below the diagonal, the plain
/// weight on it and zero above it and in the padding. Built once per loss with the GP's
/// factorisations ([`crate::gp::OutputGp::q_weights`]).
pub(crate) fn sym_weights(beta: &DVector<f64>, kinv: &DMatrix<f64>) -> Vec<f64> {
    let m = beta.len();
    let mp = padded(m);
    let mut w = vec![0.0; m.div_ceil(NJ) * NJ * mp];
    for j in 0..m {
        let col = &mut w[j * mp..j * mp + m];
        col[j] = beta[j] * beta[j] - kinv[(j, j)];
        for i in (j + 1)..m {
            col[i] = 2.0 * (beta[i] * beta[j] - kinv[(i, j)]);
        }
    }
    w
}

#[cfg(test)]
mod tests {
    use super::*;

    struct ExpAll(Vec<f64>);
    impl Kernel for ExpAll {
        type Output = Vec<f64>;
        #[inline(always)]
        fn run<const F: bool>(mut self) -> Vec<f64> {
            exp_slice::<F>(&mut self.0);
            self.0
        }
    }

    /// A deterministic sweep: a fine grid plus pseudo-random points (xorshift) on `[lo, hi]`.
    fn points(lo: f64, hi: f64, n: usize) -> Vec<f64> {
        let mut s = 0x9E37_79B9_7F4A_7C15u64;
        let mut v: Vec<f64> = (0..n)
            .map(|i| lo + (hi - lo) * i as f64 / (n - 1) as f64)
            .collect();
        for _ in 0..n {
            s ^= s << 13;
            s ^= s >> 7;
            s ^= s << 17;
            v.push(lo + (hi - lo) * ((s >> 11) as f64 / (1u64 << 53) as f64));
        }
        v
    }

    fn max_rel(xs: &[f64], ys: &[f64]) -> f64 {
        xs.iter()
            .zip(ys)
            .map(|(&x, &y)| {
                let r = x.exp();
                if r == 0.0 || !r.is_normal() {
                    0.0
                } else {
                    ((y - r) / r).abs()
                }
            })
            .fold(0.0, f64::max)
    }

    #[test]
    fn exp_matches_libm_to_about_one_ulp() {
        // the exponents the kernel sees: Q entries and q_i lie well inside [−700, 50]
        for (lo, hi) in [(-1.0, 1.0), (-40.0, 10.0), (-708.0, 709.0)] {
            let xs = points(lo, hi, 200_000);
            let dispatched = dispatch(ExpAll(xs.clone()));
            let fused: Vec<f64> = xs.iter().map(|&x| exp1::<true>(x)).collect();
            let plain: Vec<f64> = xs.iter().map(|&x| exp1::<false>(x)).collect();
            for (name, ys) in [
                ("dispatched", &dispatched),
                ("fma", &fused),
                ("no fma", &plain),
            ] {
                let e = max_rel(&xs, ys);
                println!("[{lo}, {hi}] {name}: max relative error {e:.3e}");
                assert!(e <= 2.3e-16, "{name} exp on [{lo}, {hi}]: {e:e}");
            }
        }
    }

    struct ExpQAll(Vec<f64>);
    impl Kernel for ExpQAll {
        type Output = Vec<f64>;
        #[inline(always)]
        fn run<const F: bool>(mut self) -> Vec<f64> {
            for v in self.0.iter_mut() {
                *v = exp_q::<F>(*v);
            }
            self.0
        }
    }

    #[test]
    fn the_q_block_exp_is_exp1_bit_for_bit_where_normal() {
        let xs = points(-708.0, 709.4, 400_000);
        let fast = dispatch(ExpQAll(xs.clone()));
        let reference = dispatch(ExpAll(xs.clone()));
        let differ = fast
            .iter()
            .zip(&reference)
            .filter(|(a, b)| a.to_bits() != b.to_bits())
            .count();
        assert_eq!(differ, 0, "{differ} of {} results differ", xs.len());
        let plain: Vec<f64> = xs.iter().map(|&x| exp_q::<false>(x)).collect();
        assert!(max_rel(&xs, &plain) <= 2.3e-16);
        // the edges: flushed below e^−708, +∞ above, NaN through
        let edges = vec![
            -708.0,
            -708.01,
            -745.0,
            -1e300,
            f64::NEG_INFINITY,
            709.8,
            1e300,
            f64::INFINITY,
            f64::NAN,
            // a NaN whose payload sits in the bits that the integer scaling shifts
            f64::from_bits(0x7FF8_0000_0000_0FFF),
        ];
        let ys = dispatch(ExpQAll(edges));
        assert!(ys[0] > 2.2e-308 && ((ys[0] - (-708.0f64).exp()) / ys[0]).abs() < 3e-16);
        assert_eq!(&ys[1..5], &[0.0; 4]);
        assert_eq!(&ys[5..8], &[f64::INFINITY; 3]);
        assert!(ys[8].is_nan() && ys[9].is_nan());
        assert!(exp_q::<false>(f64::from_bits(0x7FF8_0000_0000_0FFF)).is_nan());
    }

    #[test]
    fn exp_edge_cases() {
        let xs = vec![
            0.0,
            -0.0,
            1.0,
            -745.0,
            -745.2,
            -750.0,
            -1e300,
            709.7,
            709.8,
            1e300,
            f64::INFINITY,
            f64::NEG_INFINITY,
            -720.0,
            -730.5,
        ];
        let ys = dispatch(ExpAll(xs.clone()));
        assert_eq!(ys[0], 1.0);
        assert_eq!(ys[1], 1.0);
        assert!((ys[2] - std::f64::consts::E).abs() <= 2.3e-16 * std::f64::consts::E);
        assert!(ys[3] > 0.0 && ys[3] < 1e-323);
        assert_eq!(ys[5], 0.0);
        assert_eq!(ys[6], 0.0);
        assert!(ys[7].is_finite() && ((ys[7] - 709.7f64.exp()) / ys[7]).abs() < 3e-16);
        assert_eq!(ys[8], f64::INFINITY);
        assert_eq!(ys[9], f64::INFINITY);
        assert_eq!(ys[10], f64::INFINITY);
        assert_eq!(ys[11], 0.0);
        // subnormal results: absolute error below the smallest normal's ulp
        for &k in &[12usize, 13] {
            assert!(
                (ys[k] - xs[k].exp()).abs() <= 1e-320,
                "{} {}",
                ys[k],
                xs[k].exp()
            );
        }
        let nan = dispatch(ExpAll(vec![f64::NAN]));
        assert!(nan[0].is_nan());
    }

    #[test]
    fn dispatched_kernel_matrix_matches_the_generic_one() {
        // 37 × 3 against 11 × 3 points (lengths that are not multiples of the lanes), and the
        // empty cases
        let a = DMatrix::from_fn(37, 3, |i, d| ((i * 7 + d * 3) % 17) as f64 * 0.21 - 1.4);
        let b = DMatrix::from_fn(11, 3, |j, d| ((j * 5 + d * 11) % 13) as f64 * 0.3 - 1.9);
        let il2 = [0.7, 2.3, 0.05];
        let fast = kernel_matrix(&a, &b, &il2, 1.7);
        let slow = crate::gp::kernel::kernel_matrix_generic(&a, &b, &il2, 1.7);
        assert_eq!(fast.shape(), (37, 11));
        let rel = fast
            .iter()
            .zip(slow.iter())
            .map(|(f, s)| ((f - s) / s).abs())
            .fold(0.0, f64::max);
        assert!(rel <= 1e-14, "relative difference {rel}");
        // entries span several orders of magnitude, so a wrong exponent term would show
        let (lo, hi) = slow
            .iter()
            .fold((f64::MAX, 0.0f64), |(l, h), v| (l.min(*v), h.max(*v)));
        assert!(hi / lo > 1e3, "{lo} .. {hi}");
        let none = DMatrix::<f64>::zeros(0, 3);
        assert_eq!(kernel_matrix(&none, &b, &il2, 1.0).shape(), (0, 11));
        assert_eq!(kernel_matrix(&a, &none, &il2, 1.0).shape(), (37, 0));
    }

    #[test]
    fn dispatched_inverse_matches_the_generic_one() {
        // an SE kernel matrix of 100 points plus noise (condition number ≈ 1e4)
        let n = 100;
        let a = DMatrix::from_fn(n, n, |i, j| {
            let (x, y) = (i as f64 * 0.37 % 7.0, j as f64 * 0.37 % 7.0);
            (-0.5 * (x - y).powi(2)).exp() + if i == j { 1e-2 } else { 0.0 }
        });
        let chol = crate::numeric::linalg::cholesky(
            &a,
            &crate::numeric::linalg::JitterPolicy::default(),
            "test",
        )
        .expect("spd");
        let fast = spd_inverse(&chol.l);
        let generic = chol.inverse();
        let scale = generic.abs().max();
        assert!((&fast - &generic).abs().max() < 1e-10 * scale);
        assert!((&a * &fast - DMatrix::identity(n, n)).abs().max() < 1e-9);
        assert_eq!(fast, fast.transpose());
    }

    #[test]
    fn row_solves_and_sums() {
        let a = DMatrix::from_row_slice(3, 3, &[4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 2.0]);
        let l = a.clone().cholesky().expect("spd").l();
        let inv = chol_inverse::<false>(&l);
        assert!((&a * &inv - DMatrix::identity(3, 3)).abs().max() < 1e-14);
        // two right-hand sides stored as rows of stride 8
        let b = DMatrix::from_row_slice(3, 2, &[1.0, -2.0, 0.5, 3.0, -1.0, 0.25]);
        let mut x = vec![0.0; 3 * 8];
        for i in 0..3 {
            for j in 0..2 {
                x[i * 8 + j] = b[(i, j)];
            }
        }
        solve_lower_rows::<true>(&l, &mut x, 3, 8);
        solve_upper_rows::<true>(&l, &mut x, 3, 8);
        let want = a.clone().cholesky().expect("spd").solve(&b);
        for i in 0..3 {
            for j in 0..2 {
                assert!((x[i * 8 + j] - want[(i, j)]).abs() < 1e-14);
            }
        }
        // gemm_rows: out = C Mᵀ-style products against a naive loop (d = 6, n = 5, mp = 8)
        let (d, n, mp) = (6, 5, 8);
        let cm: Vec<f64> = (0..d * mp).map(|i| ((i * 7) % 11) as f64 - 5.0).collect();
        let mat: Vec<f64> = (0..n * mp).map(|i| ((i * 5) % 13) as f64 * 0.25).collect();
        let mut out = vec![0.0; d * mp];
        gemm_rows::<true>(&cm, &mat, &mut out, d, n, mp);
        for k in 0..d {
            for i in 0..mp {
                let want: f64 = (0..n).map(|j| cm[k * mp + j] * mat[j * mp + i]).sum();
                assert!((out[k * mp + i] - want).abs() < 1e-12);
            }
        }
        // gram_add against naive dots (d = 5 rows of stride 8, the last 2 entries zero)
        let (d, mp) = (5, 8);
        let xs: Vec<f64> = (0..d * mp)
            .map(|i| {
                if i % mp < 6 {
                    ((i * 3) % 7) as f64 - 3.0
                } else {
                    0.0
                }
            })
            .collect();
        let ys: Vec<f64> = (0..d * mp).map(|i| ((i * 5) % 9) as f64 * 0.5).collect();
        let mut g = DMatrix::zeros(d, d);
        gram_add::<true>(&xs, &ys, 2.0, &mut g, d, mp);
        for r in 0..d {
            for c in 0..d {
                let want: f64 = (0..mp).map(|i| 2.0 * xs[r * mp + i] * ys[c * mp + i]).sum();
                assert!((g[(r, c)] - want).abs() < 1e-12);
            }
        }
        let v: Vec<f64> = (0..21).map(|i| i as f64 * 0.5).collect();
        let w: Vec<f64> = (0..21).map(|i| 1.0 - i as f64 * 0.1).collect();
        let naive: f64 = v.iter().zip(&w).map(|(a, b)| a * b).sum();
        assert!((dot::<true>(&v, &w) - naive).abs() < 1e-12);
        assert!((sum(&v) - v.iter().sum::<f64>()).abs() < 1e-12);
    }
}
