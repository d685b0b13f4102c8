//! A saturated PID policy on the observations, with its derivative and integral carried exactly
//! in the rollout's Gaussian.
//!
//! With observations `y_t` (d_y), period `T` and gain matrices `K_p, K_i, K_d` (d_u × d_y):
//! `I_t = I_{t−1} + T y_t`, `ũ_t = K_p y_t + K_i I_t + K_d (y_t − y_{t−1}) / T`, and
//! `u_t = sat(ũ_t)` with PILCO's sine saturation scaled to unit slope at 0,
//! `sat(ũ) = u_max (9 sin(s) + sin(3s)) / 8`, `s = 2ũ / (3 u_max)`
//! (monotone for `|ũ| ≤ 3π u_max / 4`). The policy state is `p_t = [y_t; I_t]`; the
//! finite difference and the integral are linear maps of the Gaussian `[y_t; y_{t−1}; I_{t−1}]`,
//! so they are exact; only the saturation is moment-matched (exact moments of the sine).
//! The paper's policy — PID on the end-effector position, PD on the pole angle — is the case
//! `K_i = 0` on the angle.

use nalgebra::{DMatrix, DVector};

use super::bounds::saturation_vjp;
use super::{FeedbackPolicy, PolicyMoments, RestEntry};
use crate::error::{MsgpError, Result};
use crate::moments::saturation::saturate_moments;
use crate::numeric::scalar::{Scalar, c};

/// A saturated PID policy (see the module docs).
#[derive(Clone, Debug, PartialEq)]
pub struct PidPolicy<T: Scalar> {
    /// `K_p` (d_u × d_y).
    pub kp: DMatrix<T>,
    /// `K_i` (d_u × d_y).
    pub ki: DMatrix<T>,
    /// `K_d` (d_u × d_y).
    pub kd: DMatrix<T>,
    /// Control period `T` in seconds.
    pub period: f64,
    /// Saturation limits per input.
    pub u_max: Vec<f64>,
}

impl<T: Scalar> PidPolicy<T> {
    /// Checks shapes and limits.
    pub fn new(
        kp: DMatrix<T>,
        ki: DMatrix<T>,
        kd: DMatrix<T>,
        period: f64,
        u_max: Vec<f64>,
    ) -> Result<Self> {
        let shape = kp.shape();
        if ki.shape() != shape || kd.shape() != shape || u_max.len() != shape.0 {
            return Err(MsgpError::Shape(format!(
                "PID gains must all be {}x{} with {} limits",
                shape.0, shape.1, shape.0
            )));
        }
        if period.is_nan() || period <= 0.0 || u_max.iter().any(|u| u.is_nan() || *u <= 0.0) {
            return Err(MsgpError::InvalidSetting {
                name: "PID policy",
                reason: format!("period {period} and limits {u_max:?} must be positive"),
            });
        }
        Ok(Self {
            kp,
            ki,
            kd,
            period,
            u_max,
        })
    }

    /// `[ũ; y_t; I_t] = L [y_t; y_{t−1}; I_{t−1}]` as a matrix (all linear parts at once).
    fn linear_map(&self) -> DMatrix<T> {
        let (du, dy) = self.kp.shape();
        let tp = c::<T>(self.period);
        let inv_t = c::<T>(1.0 / self.period);
        let mut l = DMatrix::<T>::zeros(du + 2 * dy, 3 * dy);
        for i in 0..du {
            for j in 0..dy {
                // ũ = Kp y + Ki (I_{t−1} + T y) + Kd (y − y_{t−1}) / T
                l[(i, j)] = self.kp[(i, j)] + self.ki[(i, j)] * tp + self.kd[(i, j)] * inv_t;
                l[(i, dy + j)] = -self.kd[(i, j)] * inv_t;
                l[(i, 2 * dy + j)] = self.ki[(i, j)];
            }
        }
        for j in 0..dy {
            l[(du + j, j)] = T::one();
            l[(du + dy + j, j)] = tp;
            l[(du + dy + j, 2 * dy + j)] = T::one();
        }
        l
    }

    /// The saturation at a point (unit slope at 0).
    pub fn saturate(u_tilde: f64, u_max: f64) -> f64 {
        crate::moments::saturation::saturate(2.0 * u_tilde / (3.0 * u_max), u_max)
    }

    /// One step at a point: returns `(u_t, p_t)` from `y_t` and `p_{t−1} = [y_{t−1}; I_{t−1}]`:
    /// `I_t = I_{t−1} + T y_t`, `ũ = Σ_j Kp y_j + Ki I_{t,j} + Kd (y_j − y_{t−1,j}) / T`, summed
    /// from the last output to the first (the order of the simulator's PID + PD controller on
    /// `[θ, x]`, whose episodes a plant run of this policy then reproduces bit for bit).
    pub fn act(&self, y: &[f64], state: &[f64]) -> (Vec<f64>, Vec<f64>) {
        let (du, dy) = self.kp.shape();
        let (previous, integral) = state.split_at(dy);
        let integral: Vec<f64> = (0..dy).map(|j| integral[j] + y[j] * self.period).collect();
        let u = (0..du)
            .map(|i| {
                let mut u = 0.0;
                for j in (0..dy).rev() {
                    let derivative = (y[j] - previous[j]) / self.period;
                    u += self.kp[(i, j)].re() * y[j];
                    u += self.ki[(i, j)].re() * integral[j];
                    u += self.kd[(i, j)].re() * derivative;
                }
                Self::saturate(u, self.u_max[i])
            })
            .collect();
        (u, y.iter().copied().chain(integral).collect())
    }
}

/// Adjoints of a PID policy's gain matrices (each d_u × d_y), from
/// [`PidPolicy::moments_vjp`].
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct PidAdjoint {
    /// Adjoint of `K_p`.
    pub kp: DMatrix<f64>,
    /// Adjoint of `K_i`.
    pub ki: DMatrix<f64>,
    /// Adjoint of `K_d`.
    pub kd: DMatrix<f64>,
}

/// Adjoints of a policy map's input moments `(mean, cov)` and of the PID gains.
pub(crate) type PidVjp = (DVector<f64>, DMatrix<f64>, PidAdjoint);

impl PidPolicy<f64> {
    /// Vector–Jacobian product of [`FeedbackPolicy::moments`] at `q ~ N(mean, cov)`: for the
    /// adjoints `(ō_mean, ō_cov, C̄)` of its outputs, the adjoints of `mean`, `cov` and the
    /// gains. In closed form through the linear map `L` and the blocks built from it; by
    /// forward-mode duals through the saturation's `d_u + d_u²` inputs only. Duals through the
    /// whole map are the reference it is tested against.
    pub(crate) fn moments_vjp(
        &self,
        mean: &DVector<f64>,
        cov: &DMatrix<f64>,
        mean_bar: &DVector<f64>,
        cov_bar: &DMatrix<f64>,
        c_bar: &DMatrix<f64>,
    ) -> Result<PidVjp> {
        let (du, dy) = self.kp.shape();
        let (nq, no) = (3 * dy, du + 2 * dy);
        if mean.len() != nq
            || cov.shape() != (nq, nq)
            || mean_bar.len() != no
            || cov_bar.shape() != (no, no)
            || c_bar.shape() != (nq, no)
        {
            return Err(MsgpError::Shape(format!(
                "PID policy VJP: input moments of size {nq} and output adjoints of size {no} \
                 expected, got {} and {}",
                mean.len(),
                mean_bar.len()
            )));
        }
        // the forward pass (as `moments`)
        let l = self.linear_map();
        let lm = &l * mean;
        let lc = &l * cov * l.transpose();
        let scale: Vec<f64> = self.u_max.iter().map(|u| 2.0 / (3.0 * u)).collect();
        let sm = DVector::from_fn(du, |i, _| lm[i] * scale[i]);
        let sc = DMatrix::from_fn(du, du, |i, j| lc[(i, j)] * scale[i] * scale[j]);
        let sat = saturate_moments(&sm, &sc, &self.u_max);
        // `S C_sat`, the factor of the (p, u) covariance block and of C's u columns
        let ssc = DMatrix::from_fn(du, du, |i, j| scale[i] * sat.c[(i, j)]);

        // adjoints of L·mean and L·cov·Lᵀ, and of S C_sat
        let mut lm_bar = DVector::<f64>::zeros(no);
        lm_bar
            .rows_mut(du, 2 * dy)
            .copy_from(&mean_bar.rows(du, 2 * dy));
        let mut lc_bar = DMatrix::<f64>::zeros(no, no);
        lc_bar
            .view_mut((du, du), (2 * dy, 2 * dy))
            .copy_from(&cov_bar.view((du, du), (2 * dy, 2 * dy)));
        // Cov(p, u) = lc_pu (S C_sat) sits in the (p, u) block and, transposed, in (u, p)
        let pu_bar =
            cov_bar.view((du, 0), (2 * dy, du)) + cov_bar.view((0, du), (du, 2 * dy)).transpose();
        let mut lc_pu_bar = lc_bar.view_mut((du, 0), (2 * dy, du));
        lc_pu_bar += &pu_bar * ssc.transpose();
        let mut ssc_bar = lc.view((du, 0), (2 * dy, du)).transpose() * &pu_bar;
        // C = [Lᵤᵀ (S C_sat), L_pᵀ]
        let mut l_bar = DMatrix::<f64>::zeros(no, nq);
        let cu_bar = c_bar.columns(0, du);
        let mut l_bar_u = l_bar.rows_mut(0, du);
        l_bar_u += &ssc * cu_bar.transpose();
        ssc_bar += l.rows(0, du) * cu_bar;
        let mut l_bar_p = l_bar.rows_mut(du, 2 * dy);
        l_bar_p += c_bar.columns(du, 2 * dy).transpose();
        // through the saturation: its inputs (s_m, s_c) from its outputs' adjoints
        let csat_bar = DMatrix::from_fn(du, du, |i, j| scale[i] * ssc_bar[(i, j)]);
        let (sm_bar, sc_bar) = saturation_vjp(
            &sm,
            &sc,
            &self.u_max,
            &mean_bar.rows(0, du).into_owned(),
            &cov_bar.view((0, 0), (du, du)).into_owned(),
            &csat_bar,
        )?;
        for i in 0..du {
            lm_bar[i] += scale[i] * sm_bar[i];
            for j in 0..du {
                lc_bar[(i, j)] += scale[i] * scale[j] * sc_bar[(i, j)];
            }
        }
        // lm = L mean, lc = L cov Lᵀ
        let mean_adj = l.transpose() * &lm_bar;
        let lc_bar_l = &lc_bar * &l;
        let cov_adj = l.transpose() * &lc_bar_l;
        l_bar += &lm_bar * mean.transpose();
        l_bar += &lc_bar_l * cov.transpose() + lc_bar.transpose() * &l * cov;
        // L's u rows hold the gains (see `linear_map`)
        let (tp, inv_t) = (self.period, 1.0 / self.period);
        let gains = PidAdjoint {
            kp: DMatrix::from_fn(du, dy, |i, j| l_bar[(i, j)]),
            ki: DMatrix::from_fn(du, dy, |i, j| l_bar[(i, j)] * tp + l_bar[(i, 2 * dy + j)]),
            kd: DMatrix::from_fn(du, dy, |i, j| (l_bar[(i, j)] - l_bar[(i, dy + j)]) * inv_t),
        };
        Ok((mean_adj, cov_adj, gains))
    }
}

impl<T: Scalar> FeedbackPolicy<T> for PidPolicy<T> {
    fn input_dim(&self) -> usize {
        self.kp.nrows()
    }

    fn state_dim(&self) -> usize {
        2 * self.kp.ncols()
    }

    /// `[y_{t−1}; I_{t−1}]` with the integral summed over the measured samples `0..t`.
    fn initial_state(&self, y: &DMatrix<f64>, _u: &DMatrix<f64>, t: usize) -> DVector<f64> {
        let dy = self.kp.ncols();
        let mut p = DVector::zeros(2 * dy);
        if t == 0 {
            return p;
        }
        for j in 0..dy {
            p[j] = y[(t - 1, j)];
            p[dy + j] = (0..t).map(|k| y[(k, j)]).sum::<f64>() * self.period;
        }
        p
    }

    /// The previous observation, then a zero integral.
    fn rest_state(&self) -> Vec<RestEntry> {
        let dy = self.kp.ncols();
        (0..dy)
            .map(RestEntry::Observation)
            .chain(std::iter::repeat_n(RestEntry::Zero, dy))
            .collect()
    }

    fn moments(&self, mean: &DVector<T>, cov: &DMatrix<T>) -> Result<PolicyMoments<T>> {
        let (du, dy) = self.kp.shape();
        if mean.len() != 3 * dy {
            return Err(MsgpError::Shape(format!(
                "PID policy expects [y; y_prev; integral] of length {}, got {}",
                3 * dy,
                mean.len()
            )));
        }
        let l = self.linear_map();
        let lm = &l * mean;
        let lc = &l * cov * l.transpose();
        // scale ũ to the sine's argument s = 2ũ / (3 u_max)
        let scale: Vec<T> = self.u_max.iter().map(|u| c::<T>(2.0 / (3.0 * u))).collect();
        let sm = DVector::from_fn(du, |i, _| lm[i] * scale[i]);
        let sc = DMatrix::from_fn(du, du, |i, j| lc[(i, j)] * scale[i] * scale[j]);
        let sat = saturate_moments(&sm, &sc, &self.u_max);
        // o = [u; p]: u's C w.r.t. s is sat.c; chain through s = diag(scale) ũ, ũ = L_u q
        let no = du + 2 * dy;
        let mut omean = DVector::<T>::zeros(no);
        let mut ocov = DMatrix::<T>::zeros(no, no);
        omean.rows_mut(0, du).copy_from(&sat.mean);
        omean.rows_mut(du, 2 * dy).copy_from(&lm.rows(du, 2 * dy));
        ocov.view_mut((0, 0), (du, du)).copy_from(&sat.cov);
        ocov.view_mut((du, du), (2 * dy, 2 * dy))
            .copy_from(&lc.view((du, du), (2 * dy, 2 * dy)));
        // Cov(p, u) = Cov(p, s) C_sat, Cov(p, s) = Cov(p, ũ) diag(scale)
        let pu = DMatrix::from_fn(2 * dy, du, |r, i| lc[(du + r, i)] * scale[i]) * &sat.c;
        ocov.view_mut((du, 0), (2 * dy, du)).copy_from(&pu);
        ocov.view_mut((0, du), (du, 2 * dy))
            .copy_from(&pu.transpose());
        // C: Cov(q, o) = Cov(q) C with C = [Lᵤᵀ diag(scale) C_sat, L_pᵀ]
        let mut cm = DMatrix::<T>::zeros(3 * dy, no);
        let lu_s = DMatrix::from_fn(du, 3 * dy, |i, k| l[(i, k)] * scale[i]);
        cm.view_mut((0, 0), (3 * dy, du))
            .copy_from(&(lu_s.transpose() * &sat.c));
        cm.view_mut((0, du), (3 * dy, 2 * dy))
            .copy_from(&l.rows(du, 2 * dy).transpose());
        Ok(PolicyMoments {
            mean: omean,
            cov: ocov,
            c: cm,
        })
    }
}
