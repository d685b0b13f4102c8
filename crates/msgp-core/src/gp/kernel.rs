//! The squared-exponential kernel with automatic relevance determination (SE-ARD):
//! `k(x, x') = σ_f² exp(-½ Σ_d (x_d - x'_d)² / ℓ_d²)`, eq. (11) of the paper with
//! `Λ = diag(1/ℓ_1², …, 1/ℓ_D²)`.

use nalgebra::{DMatrix, DVector};
use num_dual::DualSVec64;

use crate::numeric::linalg::Cholesky;
use crate::numeric::scalar::{Scalar, c};
use crate::numeric::simd;

/// A [`Scalar`] with the GP layer's f64 fast paths: the generic code calls these, `f64`
/// overrides them with vectorised kernels that compute the same quantities (equal to rounding;
/// `tests/fast_path.rs`), dual numbers keep the generic defaults.
pub trait KernelScalar: Scalar {
    /// The SE-ARD kernel matrix ([`kernel_matrix`]).
    fn kernel_matrix(
        a: &DMatrix<Self>,
        b: &DMatrix<Self>,
        inv_l2: &[Self],
        sf2: Self,
    ) -> DMatrix<Self> {
        kernel_matrix_generic(a, b, inv_l2, sf2)
    }

    /// `A⁻¹` from `A`'s Cholesky factor ([`Cholesky::inverse`]); f64 overrides it with the
    /// vectorised row solves of the fast kernels.
    fn spd_inverse(chol: &Cholesky<Self>) -> DMatrix<Self> {
        chol.inverse()
    }

    /// What the f64 moment-matching kernel needs of a diagonal output pair, prepared once per
    /// loss ([`crate::gp::OutputGp::q_weights`]); nothing for other scalars.
    fn q_weights(_beta: &DVector<Self>, _kinv: &DMatrix<Self>) -> Vec<Self> {
        Vec::new()
    }
}

impl KernelScalar for f64 {
    fn kernel_matrix(a: &DMatrix<f64>, b: &DMatrix<f64>, inv_l2: &[f64], sf2: f64) -> DMatrix<f64> {
        simd::kernel_matrix(a, b, inv_l2, sf2)
    }

    fn spd_inverse(chol: &Cholesky<f64>) -> DMatrix<f64> {
        simd::spd_inverse(&chol.l)
    }

    fn q_weights(beta: &DVector<f64>, kinv: &DMatrix<f64>) -> Vec<f64> {
        simd::sym_weights(beta, kinv)
    }
}

impl<const N: usize> KernelScalar for DualSVec64<N> {}

/// `k(a, b)` for one pair of points, with `inv_l2[d] = 1/ℓ_d²`.
pub fn se_ard<T: Scalar>(a: &[T], b: &[T], inv_l2: &[T], sf2: T) -> T {
    let mut s = T::zero();
    for d in 0..a.len() {
        let diff = a[d] - b[d];
        s += diff * diff * inv_l2[d];
    }
    sf2 * (-(s * c::<T>(0.5))).exp()
}

/// Kernel matrix between the rows of `a` (n×D) and the rows of `b` (m×D). f64 takes a
/// vectorised path (`simd::kernel_matrix`; equal to [`kernel_matrix_generic`] to
/// rounding), other scalars the generic one.
pub fn kernel_matrix<T: KernelScalar>(
    a: &DMatrix<T>,
    b: &DMatrix<T>,
    inv_l2: &[T],
    sf2: T,
) -> DMatrix<T> {
    T::kernel_matrix(a, b, inv_l2, sf2)
}

/// [`kernel_matrix`] entry by entry with [`se_ard`] (the reference; what dual numbers run).
pub fn kernel_matrix_generic<T: Scalar>(
    a: &DMatrix<T>,
    b: &DMatrix<T>,
    inv_l2: &[T],
    sf2: T,
) -> DMatrix<T> {
    let (n, m, dim) = (a.nrows(), b.nrows(), a.ncols());
    let mut k = DMatrix::<T>::zeros(n, m);
    let mut ra = vec![T::zero(); dim];
    let mut rb = vec![T::zero(); dim];
    for i in 0..n {
        for d in 0..dim {
            ra[d] = a[(i, d)];
        }
        for j in 0..m {
            for d in 0..dim {
                rb[d] = b[(j, d)];
            }
            k[(i, j)] = se_ard(&ra, &rb, inv_l2, sf2);
        }
    }
    k
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn se_ard_known_value() {
        // ℓ = (1, 2), σ_f² = 3, points (0,0) and (1,2): exp(-½ (1 + 1)) = e^{-1}.
        let v = se_ard(&[0.0, 0.0], &[1.0, 2.0], &[1.0, 0.25], 3.0);
        assert!((v - 3.0 * (-1.0f64).exp()).abs() < 1e-15);
    }
}
