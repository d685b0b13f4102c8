//! Gradients by forward-mode vector dual numbers.
//!
//! The generic function is evaluated on [`DualSVec64<N>`](num_dual::DualSVec64) scalars, each
//! carrying `N = LANES` directional derivatives; the parameters are split into chunks of `LANES`
//! directions, and chunks are spread over threads. Costs about `P / LANES` dual evaluations,
//! so it is the reference mechanism every fast path is tested against, not the fit's workhorse.

use num_dual::DualSVec64;

use crate::error::Result;

/// Number of directions carried by one dual evaluation.
pub const LANES: usize = 8;

/// The dual scalar used for gradients.
pub type Dual = DualSVec64<LANES>;

/// `Σ_k ⟨a_k, w_k⟩` over pairs of equally long slices, summed in order: the scalar whose dual
/// gradient is a vector–Jacobian product, the weights `w_k` being the adjoints of the outputs
/// `a_k` (a policy's or a saturation's moments, flattened column-major).
pub(crate) fn weighted_sum(pairs: &[(&[Dual], &[f64])]) -> Dual {
    let mut acc = Dual::from_re(0.0);
    for (a, w) in pairs {
        for (o, b) in a.iter().zip(w.iter()) {
            acc += *o * *b;
        }
    }
    acc
}

/// Gradient of a scalar `f(mean, cov)` of Gaussian moments with respect to `mean` and every
/// entry of `cov` (not symmetrised), by duals over the `d + d²` packed inputs on one thread:
/// the shared step of the small VJPs inside the adjoint sweep (a saturation's, a cost's).
pub(crate) fn moments_gradient<F>(
    mean: &nalgebra::DVector<f64>,
    cov: &nalgebra::DMatrix<f64>,
    f: F,
) -> Result<(nalgebra::DVector<f64>, nalgebra::DMatrix<f64>)>
where
    F: Fn(&nalgebra::DVector<Dual>, &nalgebra::DMatrix<Dual>) -> Result<Dual> + Sync,
{
    use nalgebra::{DMatrix, DVector};
    let d = mean.len();
    let mut x: Vec<f64> = mean.iter().copied().collect();
    x.extend(cov.iter().copied());
    let active: Vec<usize> = (0..x.len()).collect();
    let (_, g) = gradient(&x, &active, 1, |xd: &[Dual]| {
        let m = DVector::from_column_slice(&xd[..d]);
        let s = DMatrix::from_column_slice(d, d, &xd[d..]);
        f(&m, &s)
    })?;
    Ok((
        DVector::from_column_slice(&g[..d]),
        DMatrix::from_column_slice(d, d, &g[d..]),
    ))
}

/// Value and `(index, derivative)` pairs from one chunk of directions.
type ChunkResult = Result<(f64, Vec<(usize, f64)>)>;

/// Value and gradient of `f` at `x` with respect to the coordinates listed in `active`
/// (entries of the gradient outside `active` are 0). `threads = 0` uses all cores.
pub fn gradient<F>(x: &[f64], active: &[usize], threads: usize, f: F) -> Result<(f64, Vec<f64>)>
where
    F: Fn(&[Dual]) -> Result<Dual> + Sync,
{
    gradient_lanes::<LANES, F>(x, active, threads, f)
}

/// [`gradient`] with `N` directions per dual evaluation. With few parameters (a policy's
/// handful of gains) `N` = their number does one evaluation without idle lanes: the cost of a
/// dual operation grows with `N`.
pub fn gradient_lanes<const N: usize, F>(
    x: &[f64],
    active: &[usize],
    threads: usize,
    f: F,
) -> Result<(f64, Vec<f64>)>
where
    F: Fn(&[DualSVec64<N>]) -> Result<DualSVec64<N>> + Sync,
{
    let chunks: Vec<&[usize]> = active.chunks(N).collect();
    let threads = if threads == 0 {
        std::thread::available_parallelism()
            .map(|n| n.get())
            .unwrap_or(1)
    } else {
        threads
    }
    .clamp(1, chunks.len().max(1));

    let eval_chunk = |chunk: &[usize]| -> ChunkResult {
        let mut xd: Vec<DualSVec64<N>> = x.iter().map(|&v| DualSVec64::from_re(v)).collect();
        for (lane, &i) in chunk.iter().enumerate() {
            xd[i] = DualSVec64::from_re(x[i]).derivative(lane);
        }
        let y = f(&xd)?;
        let mut out = Vec::with_capacity(chunk.len());
        for (lane, &i) in chunk.iter().enumerate() {
            let d = y.eps.0.as_ref().map_or(0.0, |e| e[lane]);
            out.push((i, d));
        }
        Ok((y.re, out))
    };

    if chunks.is_empty() {
        let y = f(&x
            .iter()
            .map(|&v| DualSVec64::from_re(v))
            .collect::<Vec<_>>())?;
        return Ok((y.re, vec![0.0; x.len()]));
    }

    let results: Vec<ChunkResult> = if threads == 1 {
        chunks.iter().map(|ch| eval_chunk(ch)).collect()
    } else {
        let per = chunks.len().div_ceil(threads);
        std::thread::scope(|s| {
            let handles: Vec<_> = chunks
                .chunks(per)
                .map(|group| s.spawn(|| group.iter().map(|ch| eval_chunk(ch)).collect::<Vec<_>>()))
                .collect();
            handles
                .into_iter()
                .flat_map(|h| match h.join() {
                    Ok(v) => v,
                    Err(_) => vec![Err(crate::error::MsgpError::NonFinite(
                        "a gradient worker thread panicked".into(),
                    ))],
                })
                .collect()
        })
    };

    let mut grad = vec![0.0; x.len()];
    let mut value = f64::NAN;
    for r in results {
        let (v, parts) = r?;
        value = v;
        for (i, d) in parts {
            grad[i] = d;
        }
    }
    Ok((value, grad))
}
