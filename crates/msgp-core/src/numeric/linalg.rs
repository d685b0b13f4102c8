//! Robust Cholesky factorisation with a recorded jitter policy, generic over [`Scalar`].
//!
//! `K + σ²I` can lose positive definiteness numerically (pseudo-inputs that nearly coincide,
//! long length-scales). [`cholesky`] first tries the matrix as it is; on failure it adds
//! `jitter · mean(diag)` to the diagonal, growing the jitter geometrically up to
//! [`JitterPolicy::max_relative`], and records what it used in a [`JitterLog`]. Past the limit it
//! returns [`MsgpError::NotPositiveDefinite`]; it never panics. The decision is taken on the real
//! part, so a dual run factorises exactly like the f64 run.

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use crate::error::{MsgpError, Result};
use crate::numeric::scalar::{Scalar, c};

/// How much diagonal jitter may be added, relative to the mean diagonal.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct JitterPolicy {
    /// First jitter tried after a failed factorisation (relative to the mean diagonal).
    pub initial_relative: f64,
    /// Growth factor between attempts.
    pub growth: f64,
    /// Largest relative jitter before giving up with an error.
    pub max_relative: f64,
}

impl Default for JitterPolicy {
    fn default() -> Self {
        Self {
            initial_relative: 1e-10,
            growth: 10.0,
            max_relative: 1e-4,
        }
    }
}

/// A visible record of every jitter added during a computation.
#[derive(Clone, Copy, Debug, Default, PartialEq, Serialize, Deserialize)]
pub struct JitterLog {
    /// Number of factorisations that needed jitter.
    pub events: usize,
    /// Largest absolute jitter added.
    pub max_jitter: f64,
}

impl JitterLog {
    /// Records a factorisation that used `jitter` (0 means none was needed).
    pub fn record(&mut self, jitter: f64) {
        if jitter > 0.0 {
            self.events += 1;
            self.max_jitter = self.max_jitter.max(jitter);
        }
    }
    /// Merges another log into this one.
    pub fn merge(&mut self, other: &JitterLog) {
        self.events += other.events;
        self.max_jitter = self.max_jitter.max(other.max_jitter);
    }
}

/// Lower-triangular Cholesky factor `L` with `A + jitter·I = L Lᵀ`.
#[derive(Clone, Debug)]
pub struct Cholesky<T: Scalar> {
    /// The factor (upper triangle is zero).
    pub l: DMatrix<T>,
    /// Absolute jitter that was added to the diagonal (0 if none).
    pub jitter: f64,
}

/// Attempts `L Lᵀ = A` without jitter; on failure returns the failing pivot and its value.
fn try_factor<T: Scalar>(
    a: &DMatrix<T>,
    jitter: T,
) -> std::result::Result<DMatrix<T>, (usize, f64)> {
    let n = a.nrows();
    let mut l = DMatrix::<T>::zeros(n, n);
    for j in 0..n {
        let mut d = a[(j, j)] + jitter;
        for k in 0..j {
            d -= l[(j, k)] * l[(j, k)];
        }
        let dv = d.re();
        if dv <= 0.0 || !dv.is_finite() {
            return Err((j, dv));
        }
        let ljj = d.sqrt();
        l[(j, j)] = ljj;
        let inv = T::one() / ljj;
        for i in (j + 1)..n {
            let mut s = a[(i, j)];
            for k in 0..j {
                s -= l[(i, k)] * l[(j, k)];
            }
            l[(i, j)] = s * inv;
        }
    }
    Ok(l)
}

/// Factorises the symmetric matrix `a` under `policy`; `what` names it in errors.
pub fn cholesky<T: Scalar>(
    a: &DMatrix<T>,
    policy: &JitterPolicy,
    what: &str,
) -> Result<Cholesky<T>> {
    if a.nrows() != a.ncols() {
        return Err(MsgpError::Shape(format!(
            "{what} is {}x{}, not square",
            a.nrows(),
            a.ncols()
        )));
    }
    let n = a.nrows();
    let mut last = match try_factor(a, T::zero()) {
        Ok(l) => return Ok(Cholesky { l, jitter: 0.0 }),
        Err(e) => e,
    };
    let mean_diag = if n == 0 {
        1.0
    } else {
        (0..n).map(|i| a[(i, i)].re().abs()).sum::<f64>() / n as f64
    };
    let scale = if mean_diag > 0.0 && mean_diag.is_finite() {
        mean_diag
    } else {
        1.0
    };
    let mut rel = policy.initial_relative;
    let mut jitter = rel * scale;
    while rel <= policy.max_relative * (1.0 + 1e-12) {
        jitter = rel * scale;
        match try_factor(a, c::<T>(jitter)) {
            Ok(l) => return Ok(Cholesky { l, jitter }),
            Err(e) => last = e,
        }
        rel *= policy.growth.max(1.0 + 1e-3);
    }
    Err(MsgpError::NotPositiveDefinite {
        what: what.to_string(),
        pivot: last.0,
        value: last.1,
        jitter,
    })
}

impl<T: Scalar> Cholesky<T> {
    /// Solves `L X = B` (forward substitution).
    pub fn solve_lower(&self, b: &DMatrix<T>) -> DMatrix<T> {
        let n = self.l.nrows();
        let mut x = b.clone();
        for col in 0..x.ncols() {
            for i in 0..n {
                let mut s = x[(i, col)];
                for k in 0..i {
                    s -= self.l[(i, k)] * x[(k, col)];
                }
                x[(i, col)] = s / self.l[(i, i)];
            }
        }
        x
    }

    /// Solves `Lᵀ X = B` (back substitution).
    pub fn solve_upper(&self, b: &DMatrix<T>) -> DMatrix<T> {
        let n = self.l.nrows();
        let mut x = b.clone();
        for col in 0..x.ncols() {
            for i in (0..n).rev() {
                let mut s = x[(i, col)];
                for k in (i + 1)..n {
                    s -= self.l[(k, i)] * x[(k, col)];
                }
                x[(i, col)] = s / self.l[(i, i)];
            }
        }
        x
    }

    /// Solves `A X = B`.
    pub fn solve(&self, b: &DMatrix<T>) -> DMatrix<T> {
        self.solve_upper(&self.solve_lower(b))
    }

    /// Solves `A x = b` for a vector.
    pub fn solve_vec(&self, b: &DVector<T>) -> DVector<T> {
        let m = DMatrix::from_column_slice(b.len(), 1, b.as_slice());
        DVector::from_column_slice(self.solve(&m).as_slice())
    }

    /// `A⁻¹` (symmetric).
    pub fn inverse(&self) -> DMatrix<T> {
        let n = self.l.nrows();
        let inv = self.solve(&DMatrix::identity(n, n));
        (&inv + inv.transpose()) * c::<T>(0.5)
    }

    /// `log |A|`.
    pub fn log_det(&self) -> T {
        let mut s = T::zero();
        for i in 0..self.l.nrows() {
            s += self.l[(i, i)].ln();
        }
        s * c::<T>(2.0)
    }
}

/// Symmetrises a square matrix in place: `(A + Aᵀ)/2`.
pub fn symmetrize<T: Scalar>(a: &mut DMatrix<T>) {
    let n = a.nrows();
    let half = c::<T>(0.5);
    for i in 0..n {
        for j in (i + 1)..n {
            let v = (a[(i, j)] + a[(j, i)]) * half;
            a[(i, j)] = v;
            a[(j, i)] = v;
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn factor_solve_logdet_match_direct() {
        let a = DMatrix::from_row_slice(3, 3, &[4.0, 1.0, 0.5, 1.0, 3.0, 0.2, 0.5, 0.2, 2.0]);
        let ch = cholesky(&a, &JitterPolicy::default(), "A").expect("spd");
        assert_eq!(ch.jitter, 0.0);
        let rebuilt = &ch.l * ch.l.transpose();
        assert!((rebuilt - &a).abs().max() < 1e-14);
        let inv = ch.inverse();
        assert!((&a * inv - DMatrix::identity(3, 3)).abs().max() < 1e-14);
        let det: f64 = a.clone().determinant();
        assert!((ch.log_det() - det.ln()).abs() < 1e-13);
    }

    #[test]
    fn singular_matrix_gets_recorded_jitter() {
        let v = DMatrix::from_row_slice(3, 1, &[1.0, 2.0, 3.0]);
        let a = &v * v.transpose();
        let ch = cholesky(&a, &JitterPolicy::default(), "rank one").expect("jitter helps");
        assert!(ch.jitter > 0.0);
        let mut log = JitterLog::default();
        log.record(ch.jitter);
        assert_eq!(log.events, 1);
    }

    #[test]
    fn indefinite_matrix_is_an_error_not_a_panic() {
        let a = DMatrix::from_row_slice(2, 2, &[1.0, 0.0, 0.0, -1.0]);
        let err = cholesky(&a, &JitterPolicy::default(), "bad").expect_err("indefinite");
        assert!(err.to_string().contains("bad is not positive definite"));
    }
}
