//! Seeded k-means (k-means++ initialisation, Lloyd iterations) to place pseudo-inputs, and the
//! one placement every fit uses ([`place_pseudo_inputs`]).

use nalgebra::DMatrix;
use rand::{RngExt, SeedableRng, rngs::StdRng};

use crate::error::{MsgpError, Result};

/// Lloyd iterations of every pseudo-input placement.
const PLACEMENT_ITERATIONS: usize = 30;

/// The GP's inputs: the windows `x` (one per row) with the columns in `ignored` (coordinates
/// the kernel leaves out, [`super::integrator::Structure`]) at zero.
pub fn gp_inputs(x: &DMatrix<f64>, ignored: &[usize]) -> DMatrix<f64> {
    let mut gx = x.clone();
    for &k in ignored {
        gx.column_mut(k).fill(0.0);
    }
    gx
}

/// `m` pseudo-inputs over the rows of `gx`: every row when there are no more than `m`, else
/// the seeded k-means centres.
pub fn place_pseudo_inputs(gx: &DMatrix<f64>, m: usize, seed: u64) -> Result<DMatrix<f64>> {
    match m >= gx.nrows() {
        true => Ok(gx.clone()),
        false => kmeans(gx, m, PLACEMENT_ITERATIONS, seed),
    }
}

fn dist2(x: &DMatrix<f64>, i: usize, c: &DMatrix<f64>, j: usize) -> f64 {
    (0..x.ncols())
        .map(|d| (x[(i, d)] - c[(j, d)]).powi(2))
        .sum()
}

/// `k` centres of the rows of `x`; the same seed gives the same centres.
pub fn kmeans(x: &DMatrix<f64>, k: usize, iterations: usize, seed: u64) -> Result<DMatrix<f64>> {
    let (n, d) = x.shape();
    if k == 0 || k > n {
        return Err(MsgpError::InvalidSetting {
            name: "inducing points",
            reason: format!(
                "{k} pseudo-inputs need between 1 and {n} (the number of training windows)"
            ),
        });
    }
    let mut rng = StdRng::seed_from_u64(seed);
    let mut centres = DMatrix::zeros(k, d);
    let first = rng.random_range(0..n);
    centres.row_mut(0).copy_from(&x.row(first));
    let mut best = vec![f64::INFINITY; n];
    for c in 1..k {
        for i in 0..n {
            best[i] = best[i].min(dist2(x, i, &centres, c - 1));
        }
        let total: f64 = best.iter().sum();
        let pick = if total > 0.0 {
            let mut r = rng.random_range(0.0..total);
            let mut chosen = n - 1;
            for (i, b) in best.iter().enumerate() {
                if r < *b {
                    chosen = i;
                    break;
                }
                r -= b;
            }
            chosen
        } else {
            rng.random_range(0..n)
        };
        centres.row_mut(c).copy_from(&x.row(pick));
    }
    let mut assign = vec![0usize; n];
    for _ in 0..iterations {
        let mut changed = false;
        for i in 0..n {
            let (mut bj, mut bd) = (0, f64::INFINITY);
            for j in 0..k {
                let dd = dist2(x, i, &centres, j);
                if dd < bd {
                    bd = dd;
                    bj = j;
                }
            }
            if assign[i] != bj {
                assign[i] = bj;
                changed = true;
            }
        }
        let mut sums = DMatrix::<f64>::zeros(k, d);
        let mut counts = vec![0usize; k];
        for i in 0..n {
            counts[assign[i]] += 1;
            for dd in 0..d {
                sums[(assign[i], dd)] += x[(i, dd)];
            }
        }
        for j in 0..k {
            if counts[j] > 0 {
                for dd in 0..d {
                    centres[(j, dd)] = sums[(j, dd)] / counts[j] as f64;
                }
            }
        }
        if !changed {
            break;
        }
    }
    Ok(centres)
}
