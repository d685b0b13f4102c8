//! A policy written in original units, used inside a rollout that works in normalised units.
//!
//! Observations are de-normalised (`y = m_y + s_y ∘ y_n`, an affine map: exact) before the inner
//! policy sees them, and its inputs are normalised (`u_n = (u − m_u) / s_u`); the policy state
//! stays in original units. For `q_o = A q_n + b` and `o_n = B o_o + c` (A, B diagonal),
//! `Cov(q_n, o_n) = Cov(q_n) A C_o B`.

use nalgebra::{DMatrix, DVector};

use super::{FeedbackPolicy, Policy, PolicyMoments, RestEntry, ThetaVjp};
use crate::data::Normalizer;
use crate::error::{MsgpError, Result};
use crate::numeric::scalar::{Scalar, c};

/// Wraps a policy in original units for a rollout in normalised units.
#[derive(Clone, Debug, PartialEq)]
pub struct Normalized<P> {
    /// The policy in original units.
    pub inner: P,
    /// The model's normalisation.
    pub normalizer: Normalizer,
}

impl<P> Normalized<P> {
    /// The diagonal `A` of `q_o = A q_n + b` for a policy input of size `nq`: the outputs'
    /// standard deviations, then 1 for the policy state (kept in original units).
    fn input_scale(&self, nq: usize) -> Vec<f64> {
        let y_std = &self.normalizer.y_std;
        (0..nq)
            .map(|k| if k < y_std.len() { y_std[k] } else { 1.0 })
            .collect()
    }

    /// The diagonal `B` of `o_n = B o_o + c` for `du` inputs in a policy output of size `no`.
    fn output_scale(&self, du: usize, no: usize) -> Vec<f64> {
        (0..no)
            .map(|k| {
                if k < du {
                    1.0 / self.normalizer.u_std[k]
                } else {
                    1.0
                }
            })
            .collect()
    }

    /// The policy input's moments in original units, `q_o = A q_n + b` (`b`: the outputs'
    /// means on their entries, 0 on the policy state).
    fn input_to_original<T: Scalar>(
        &self,
        mean: &DVector<T>,
        cov: &DMatrix<T>,
    ) -> (DVector<T>, DMatrix<T>) {
        let y_mean = &self.normalizer.y_mean;
        let nq = mean.len();
        let a: Vec<T> = self.input_scale(nq).into_iter().map(c::<T>).collect();
        let qm = DVector::from_fn(nq, |k, _| {
            if k < y_mean.len() {
                mean[k] * a[k] + c::<T>(y_mean[k])
            } else {
                mean[k]
            }
        });
        let qc = DMatrix::from_fn(nq, nq, |i, j| cov[(i, j)] * a[i] * a[j]);
        (qm, qc)
    }
}

impl Normalized<Policy> {
    /// Vector–Jacobian product of [`FeedbackPolicy::moments`] in closed form
    /// ([`Policy`]'s, with `θ`'s adjoint): the affine changes of units are diagonal, so
    /// their adjoints scale the inner policy's. An error for a policy without one.
    pub(crate) fn moments_vjp(
        &self,
        mean: &DVector<f64>,
        cov: &DMatrix<f64>,
        mean_bar: &DVector<f64>,
        cov_bar: &DMatrix<f64>,
        c_bar: &DMatrix<f64>,
    ) -> Result<ThetaVjp> {
        let nq = mean.len();
        let (du, no) = (self.inner.command_dim(), mean_bar.len());
        let a = self.input_scale(nq);
        let b = self.output_scale(du, no);
        let (qm, qc) = self.input_to_original(mean, cov);
        let (qm_bar, qc_bar, theta) = self
            .inner
            .moments_vjp(
                &qm,
                &qc,
                &DVector::from_fn(no, |k, _| mean_bar[k] * b[k]),
                &DMatrix::from_fn(no, no, |i, j| cov_bar[(i, j)] * b[i] * b[j]),
                &DMatrix::from_fn(c_bar.nrows(), no, |i, j| a[i] * c_bar[(i, j)] * b[j]),
            )
            .unwrap_or_else(|| {
                Err(MsgpError::Shape(format!(
                    "the {} policy has no closed-form vector–Jacobian product",
                    self.inner.kind()
                )))
            })?;
        Ok((
            DVector::from_fn(nq, |k, _| qm_bar[k] * a[k]),
            DMatrix::from_fn(nq, nq, |i, j| qc_bar[(i, j)] * a[i] * a[j]),
            theta,
        ))
    }
}

impl<T: Scalar, P: FeedbackPolicy<T>> FeedbackPolicy<T> for Normalized<P> {
    fn input_dim(&self) -> usize {
        self.inner.input_dim()
    }

    fn state_dim(&self) -> usize {
        self.inner.state_dim()
    }

    fn initial_state(&self, y: &DMatrix<f64>, u: &DMatrix<f64>, t: usize) -> DVector<f64> {
        let n = &self.normalizer;
        let yo = DMatrix::from_fn(y.nrows(), y.ncols(), |r, j| n.y_to_original(j, y[(r, j)]));
        let uo = DMatrix::from_fn(u.nrows(), u.ncols(), |r, j| {
            u[(r, j)] * n.u_std[j] + n.u_mean[j]
        });
        self.inner.initial_state(&yo, &uo, t)
    }

    /// The inner policy's: its state stays in original units.
    fn rest_state(&self) -> Vec<RestEntry> {
        self.inner.rest_state()
    }

    fn moments(&self, mean: &DVector<T>, cov: &DMatrix<T>) -> Result<PolicyMoments<T>> {
        let n = &self.normalizer;
        let du = self.input_dim();
        let nq = mean.len();
        let a: Vec<T> = self.input_scale(nq).into_iter().map(c::<T>).collect();
        let (qm, qc) = self.input_to_original(mean, cov);
        let inner = self.inner.moments(&qm, &qc)?;
        let no = inner.mean.len();
        let b: Vec<T> = self.output_scale(du, no).into_iter().map(c::<T>).collect();
        let om = DVector::from_fn(no, |k, _| {
            if k < du {
                (inner.mean[k] - c::<T>(n.u_mean[k])) * b[k]
            } else {
                inner.mean[k]
            }
        });
        let oc = DMatrix::from_fn(no, no, |i, j| inner.cov[(i, j)] * b[i] * b[j]);
        let cm = DMatrix::from_fn(nq, no, |i, j| a[i] * inner.c[(i, j)] * b[j]);
        Ok(PolicyMoments {
            mean: om,
            cov: oc,
            c: cm,
        })
    }
}

#[cfg(test)]
mod tests {
    use nalgebra::{DMatrix, DVector};
    use rand::SeedableRng;
    use rand::rngs::StdRng;
    use rand_distr::{Distribution, StandardNormal};

    use super::*;
    use crate::numeric::dual::{Dual, gradient, weighted_sum};
    use crate::policy::{CommandBounds, PidPolicy, RbfPolicy};

    /// A random normaliser for `du` commands and `dy` outputs.
    fn normalizer(r: &mut dyn FnMut(f64) -> f64, du: usize, dy: usize) -> Normalizer {
        Normalizer {
            u_mean: (0..du).map(|_| r(0.3)).collect(),
            u_std: (0..du).map(|_| 1.0 + r(0.5).abs()).collect(),
            y_mean: (0..dy).map(|_| r(0.1)).collect(),
            y_std: (0..dy).map(|_| 0.2 + r(0.1).abs()).collect(),
        }
    }

    /// The closed-form VJP of a normalised policy's moment map equals the gradient of
    /// `⟨ō_mean, mean⟩ + ⟨ō_cov, cov⟩ + ⟨C̄, C⟩` by duals through the whole map, with respect
    /// to the input moments and every parameter, block by block (`blocks`: the parameter
    /// groups' lengths; each entry to 1e-10 of its block's largest), at a point where the
    /// saturation is active. `symmetric`: compare the covariance adjoint's symmetric part only.
    fn check_vjp(
        policy: &Normalized<Policy>,
        size: &[f64],
        r: &mut dyn FnMut(f64) -> f64,
        blocks: &[(&str, usize)],
        symmetric: bool,
    ) {
        let nq = size.len();
        let mean = DVector::from_fn(nq, |i, _| r(size[i]));
        let f = DMatrix::from_fn(nq, nq, |i, _| r(0.5 * size[i]));
        let cov = &f * f.transpose()
            + DMatrix::from_fn(nq, nq, |i, j| {
                if i == j {
                    0.01 * size[i] * size[i]
                } else {
                    0.0
                }
            });
        let lifted = Normalized {
            inner: policy.inner.lift::<f64>(),
            normalizer: policy.normalizer.clone(),
        };
        let pm = lifted.moments(&mean, &cov).expect("moments");
        let (u_var, u_lin) = (pm.cov[(0, 0)], pm.c.column(0).amax());
        assert!(u_var > 1e-3 && u_lin > 1e-3, "Var u {u_var}, |C_u| {u_lin}");
        let no = pm.mean.len();
        let mean_bar = DVector::from_fn(no, |_, _| r(1.0));
        let cov_bar = DMatrix::from_fn(no, no, |_, _| r(1.0));
        let c_bar = DMatrix::from_fn(nq, no, |_, _| r(1.0));
        let (qm_bar, qc_bar, theta_bar) = policy
            .moments_vjp(&mean, &cov, &mean_bar, &cov_bar, &c_bar)
            .expect("vjp");
        let mut x: Vec<f64> = mean.iter().chain(cov.iter()).copied().collect();
        x.extend(policy.inner.theta());
        let active: Vec<usize> = (0..x.len()).collect();
        let k = nq + nq * nq;
        let (_, g) = gradient(&x, &active, 1, |xd: &[Dual]| {
            let p = Normalized {
                inner: policy.inner.lift_theta::<Dual>(&xd[k..])?,
                normalizer: policy.normalizer.clone(),
            };
            let pm = p.moments(
                &DVector::from_column_slice(&xd[..nq]),
                &DMatrix::from_column_slice(nq, nq, &xd[nq..k]),
            )?;
            Ok(weighted_sum(&[
                (pm.mean.as_slice(), mean_bar.as_slice()),
                (pm.cov.as_slice(), cov_bar.as_slice()),
                (pm.c.as_slice(), c_bar.as_slice()),
            ]))
        })
        .expect("duals");
        // the covariance is symmetric: only the adjoint's symmetric part is defined (the duals
        // through a Cholesky factor see one triangle, the backward pass both)
        let sym = |v: &[f64]| {
            let a = DMatrix::from_column_slice(nq, nq, v);
            (&a + a.transpose()) * 0.5
        };
        let mut g = g;
        let mut qc_bar = qc_bar;
        if symmetric {
            let g_cov = sym(&g[nq..k]);
            g[nq..k].copy_from_slice(g_cov.as_slice());
            qc_bar = sym(qc_bar.as_slice());
        }
        let closed: Vec<f64> = qm_bar
            .iter()
            .chain(qc_bar.iter())
            .chain(theta_bar.iter())
            .copied()
            .collect();
        assert_eq!(closed.len(), g.len());
        let mut ranges = vec![("mean", 0..nq), ("cov", nq..k)];
        let mut at = k;
        for (name, len) in blocks {
            ranges.push((name, at..at + len));
            at += len;
        }
        assert_eq!(at, g.len(), "the blocks cover θ");
        for (name, range) in ranges {
            let scale = g[range.clone()].iter().fold(0.0f64, |m, v| m.max(v.abs()));
            assert!(scale > 0.0, "{name} has no gradient");
            for i in range {
                assert!(
                    (closed[i] - g[i]).abs() <= 1e-10 * scale,
                    "{} {name} entry {i}: closed form {} vs duals {} (scale {scale})",
                    policy.inner.kind(),
                    closed[i],
                    g[i]
                );
            }
        }
    }

    #[test]
    fn the_pid_vjp_matches_duals_through_the_whole_map() {
        let mut rng = StdRng::seed_from_u64(7);
        let mut r = |s: f64| {
            let z: f64 = StandardNormal.sample(&mut rng);
            s * z
        };
        let (du, dy) = (1, 2);
        for _ in 0..5 {
            let mut gains = |s: f64| DMatrix::from_fn(du, dy, |_, _| r(s));
            let (kp, ki, kd) = (gains(5.0), gains(1.0), gains(0.3));
            let pid = PidPolicy::new(kp, ki, kd, 0.02, vec![5.0]).expect("pid");
            let normalizer = Normalizer {
                u_mean: vec![r(0.3)],
                u_std: vec![1.0 + r(0.5).abs()],
                y_mean: vec![r(0.1), r(0.1)],
                y_std: vec![0.05 + r(0.02).abs(), 0.2 + r(0.1).abs()],
            };
            let policy = Normalized {
                inner: Policy::Pid(pid),
                normalizer,
            };
            // q = [y (normalised); y_prev, integral (original units, the outputs' sizes)]
            let size = [1.0, 1.0, 0.05, 0.2, 0.05, 0.2];
            let blocks = [("kp", du * dy), ("ki", du * dy), ("kd", du * dy)];
            check_vjp(&policy, &size, &mut r, &blocks, false);
        }
    }

    #[test]
    fn the_rbf_vjp_matches_duals_through_the_whole_map() {
        let mut rng = StdRng::seed_from_u64(11);
        let mut r = |s: f64| {
            let z: f64 = StandardNormal.sample(&mut rng);
            s * z
        };
        let (n, du, dy) = (6, 2, 3);
        for _ in 0..3 {
            let bounds = CommandBounds::new(vec![-1.5, 0.0], vec![2.0, 4.0]).expect("bounds");
            let rbf = RbfPolicy::new(
                DMatrix::from_fn(n, dy, |_, _| r(0.5)),
                DMatrix::from_fn(n, du, |_, _| r(2.0)),
                DVector::from_fn(dy, |_, _| r(0.3) - 0.5),
                bounds,
            )
            .expect("rbf");
            let policy = Normalized {
                inner: Policy::Rbf(rbf),
                normalizer: normalizer(&mut r, du, dy),
            };
            let blocks = [("centres", n * dy), ("weights", n * du), ("widths", dy)];
            check_vjp(&policy, &[1.0, 1.0, 1.0], &mut r, &blocks, true);
        }
    }
}
