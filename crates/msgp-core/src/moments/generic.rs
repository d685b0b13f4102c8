//! The generic moment matching, for every [`Scalar`]: the reference the f64 kernel
//! (`super::fast`) is tested against, and what forward-mode duals run.

use nalgebra::{DMatrix, DVector};

use super::Moments;
use crate::error::Result;
use crate::gp::{KernelScalar, PreparedGp};
use crate::numeric::linalg::{JitterLog, cholesky};
use crate::numeric::scalar::{Scalar, c};

/// `I + diag(p) Σ diag(p)`.
fn scaled_plus_identity<T: Scalar>(sigma: &DMatrix<T>, p: &[T]) -> DMatrix<T> {
    let d = sigma.nrows();
    let mut s = DMatrix::<T>::identity(d, d);
    for i in 0..d {
        for j in 0..d {
            s[(i, j)] += p[i] * sigma[(i, j)] * p[j];
        }
    }
    s
}

/// The generic implementation of [`super::moment_match`], for every [`Scalar`]: the reference
/// the f64 kernel is tested against, and what forward-mode duals run.
pub fn moment_match_generic<T: KernelScalar>(
    gp: &PreparedGp<T>,
    mu: &DVector<T>,
    sigma: &DMatrix<T>,
    log: &mut JitterLog,
) -> Result<Moments<T>> {
    let x = &gp.pseudo_inputs;
    let (m, d) = (x.nrows(), x.ncols());
    let e = gp.output_dim();
    let half = c::<T>(0.5);

    // ν = X̄ − μ (m × D)
    let mut nu = x.clone();
    for i in 0..m {
        for k in 0..d {
            nu[(i, k)] -= mu[k];
        }
    }

    let mut mean = DVector::<T>::zeros(e);
    let mut io_cov = DMatrix::<T>::zeros(d, e);
    let mut v = DMatrix::<T>::zeros(d, e);
    // log k_a(x̄_i, μ) per output (m)
    let mut logk: Vec<Vec<T>> = Vec::with_capacity(e);
    for (a, o) in gp.outputs.iter().enumerate() {
        let s: Vec<T> = o.inv_l2.iter().map(|v| v.sqrt()).collect();
        let shat = scaled_plus_identity(sigma, &s);
        let ch = cholesky(&shat, &gp.jitter, "I + Λ^{-½} Σ Λ^{-½}")?;
        log.record(ch.jitter);
        let logdet = ch.log_det();
        // ν̃ᵀ (D × m), scaled by s
        let mut nut = DMatrix::<T>::zeros(d, m);
        for i in 0..m {
            for k in 0..d {
                nut[(k, i)] = nu[(i, k)] * s[k];
            }
        }
        let w = ch.solve(&nut); // Ŝ⁻¹ ν̃ᵀ
        let lsf2 = o.sf2.ln();
        let mut lk = vec![T::zero(); m];
        // Σ_i β_i q_i (Σ+Λ)⁻¹ ν_i, accumulated in D
        let mut acc = DVector::<T>::zeros(d);
        let mut ma = T::zero();
        for i in 0..m {
            let mut quad = T::zero();
            let mut plain = T::zero();
            for k in 0..d {
                quad += nut[(k, i)] * w[(k, i)];
                plain += nut[(k, i)] * nut[(k, i)];
            }
            lk[i] = lsf2 - plain * half;
            let q = (lsf2 - (quad + logdet) * half).exp();
            let bq = o.beta[i] * q;
            ma += bq;
            for k in 0..d {
                acc[k] += bq * s[k] * w[(k, i)];
            }
        }
        mean[a] = ma;
        let col = sigma * &acc;
        io_cov.set_column(a, &col);
        v.set_column(a, &acc);
        logk.push(lk);
    }

    let mut cov = DMatrix::<T>::zeros(e, e);
    for a in 0..e {
        for b in a..e {
            let (oa, ob) = (&gp.outputs[a], &gp.outputs[b]);
            let p: Vec<T> = (0..d).map(|k| oa.inv_l2[k] + ob.inv_l2[k]).collect();
            let sp: Vec<T> = p.iter().map(|v| v.sqrt()).collect();
            let st = scaled_plus_identity(sigma, &sp);
            let ch = cholesky(&st, &gp.jitter, "I + P^{½} Σ P^{½}")?;
            log.record(ch.jitter);
            let logdet_r = ch.log_det();
            // ã_i = Λ_a⁻¹ ν_i / √P, b̃_j = Λ_b⁻¹ ν_j / √P (as D × m)
            let mut at = DMatrix::<T>::zeros(d, m);
            let mut bt = DMatrix::<T>::zeros(d, m);
            for i in 0..m {
                for k in 0..d {
                    at[(k, i)] = oa.inv_l2[k] * nu[(i, k)] / sp[k];
                    bt[(k, i)] = ob.inv_l2[k] * nu[(i, k)] / sp[k];
                }
            }
            // (I − S̃⁻¹) b̃
            let mb = &bt - ch.solve(&bt);
            let g = at.transpose() * &mb; // m × m: ã_iᵀ (I − S̃⁻¹) b̃_j
            let ma = &at - ch.solve(&at);
            let mut ua = vec![T::zero(); m];
            let mut ub = vec![T::zero(); m];
            for i in 0..m {
                let mut qa = T::zero();
                let mut qb = T::zero();
                for k in 0..d {
                    qa += at[(k, i)] * ma[(k, i)];
                    qb += bt[(k, i)] * mb[(k, i)];
                }
                ua[i] = logk[a][i] + qa * half;
                ub[i] = logk[b][i] + qb * half - logdet_r * half;
            }
            let mut ebb = T::zero();
            let mut tr = T::zero();
            for j in 0..m {
                let mut colsum = T::zero();
                let mut trcol = T::zero();
                for i in 0..m {
                    let qij = (ua[i] + ub[j] + g[(i, j)]).exp();
                    colsum += oa.beta[i] * qij;
                    if a == b {
                        trcol += oa.kinv[(i, j)] * qij;
                    }
                }
                ebb += colsum * ob.beta[j];
                tr += trcol;
            }
            let mut v = ebb - mean[a] * mean[b];
            if a == b {
                v += oa.sf2 - tr;
            }
            cov[(a, b)] = v;
            cov[(b, a)] = v;
        }
    }
    Ok(Moments {
        mean,
        cov,
        io_cov,
        v,
    })
}
