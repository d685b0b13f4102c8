//! PILCO's smooth action saturation `u = u_max (9 sin x + sin 3x) / 8` with exact moments
//! under a Gaussian `x ~ N(m, S)` (any dimension, full covariance).
//!
//! Uses `E[cos(v)] = e^{−Var v/2} cos E[v]` for Gaussian `v`:
//! `E[sin(a x_i)] = e^{−a² S_ii/2} sin(a m_i)`,
//! `E[sin(a x_i) sin(b x_j)] = ½(E cos(a x_i − b x_j) − E cos(a x_i + b x_j))`, and Stein's lemma
//! for the input–output covariance: `Cov(x, sin(a x_j)) = S_{:,j} a e^{−a² S_jj/2} cos(a m_j)`.
//! The returned `C` satisfies `Cov(x, u) = S C` (diagonal here).

use nalgebra::{DMatrix, DVector};

use crate::numeric::scalar::{Scalar, c};

/// Moments of the saturated output.
#[derive(Clone, Debug)]
pub struct SaturatedMoments<T: Scalar> {
    /// `E[u]`.
    pub mean: DVector<T>,
    /// `Cov[u]`.
    pub cov: DMatrix<T>,
    /// `C` with `Cov(x, u) = S C`.
    pub c: DMatrix<T>,
}

const FREQ: [(f64, f64); 2] = [(1.0, 9.0 / 8.0), (3.0, 1.0 / 8.0)];

/// The saturation at a point.
pub fn saturate(x: f64, u_max: f64) -> f64 {
    u_max * (9.0 * x.sin() + (3.0 * x).sin()) / 8.0
}

/// Moments of `u_max (9 sin x + sin 3x)/8` for `x ~ N(m, s)`, elementwise limits `u_max`.
pub fn saturate_moments<T: Scalar>(
    m: &DVector<T>,
    s: &DMatrix<T>,
    u_max: &[f64],
) -> SaturatedMoments<T> {
    let n = m.len();
    let half = c::<T>(0.5);
    let ecos = |mean: T, var: T| (-(var * half)).exp() * mean.cos();
    let mut mean = DVector::<T>::zeros(n);
    let mut cmat = DMatrix::<T>::zeros(n, n);
    for i in 0..n {
        let um = c::<T>(u_max[i]);
        for (a, w) in FREQ {
            let (a, w) = (c::<T>(a), c::<T>(w));
            let damp = (-(a * a * s[(i, i)] * half)).exp();
            mean[i] += um * w * damp * (a * m[i]).sin();
            cmat[(i, i)] += um * w * a * damp * (a * m[i]).cos();
        }
    }
    let mut cov = DMatrix::<T>::zeros(n, n);
    for i in 0..n {
        for j in i..n {
            let mut e = T::zero();
            for (a, wa) in FREQ {
                for (b, wb) in FREQ {
                    let (a, b) = (c::<T>(a), c::<T>(b));
                    let minus = ecos(
                        a * m[i] - b * m[j],
                        a * a * s[(i, i)] + b * b * s[(j, j)] - c::<T>(2.0) * a * b * s[(i, j)],
                    );
                    let plus = ecos(
                        a * m[i] + b * m[j],
                        a * a * s[(i, i)] + b * b * s[(j, j)] + c::<T>(2.0) * a * b * s[(i, j)],
                    );
                    e += c::<T>(wa * wb) * (minus - plus) * half;
                }
            }
            let v = e * c::<T>(u_max[i] * u_max[j]) - mean[i] * mean[j];
            cov[(i, j)] = v;
            cov[(j, i)] = v;
        }
    }
    SaturatedMoments { mean, cov, c: cmat }
}
