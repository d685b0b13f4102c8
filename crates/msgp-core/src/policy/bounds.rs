//! Command bounds and PILCO's sine saturation into them: `u = mid + sat(ũ)`, with
//! `sat(ũ) = h (9 sin s + sin 3s) / 8`, `s = 2ũ / (3h)`, `mid = (low + high)/2` and
//! `h = (high − low)/2` per command. The saturation has unit slope at `ũ = 0` and keeps every
//! command inside `[low, high]`; its moments under a Gaussian `ũ` are exact
//! ([`crate::moments::saturation`]), its input–output covariance by Stein's lemma. The
//! linear-state-feedback and RBF policies end in it; the PID policy is its symmetric case.

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use crate::error::{MsgpError, Result};
use crate::moments::saturation::saturate_moments;
use crate::numeric::scalar::{Scalar, c};

/// The range `[low, high]` of each command: finite, `low < high`, as many of each (checked
/// when made, read back through [`CommandBounds::low`] and [`CommandBounds::high`]).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(try_from = "RawBounds")]
pub struct CommandBounds {
    pub(crate) low: Vec<f64>,
    pub(crate) high: Vec<f64>,
}

/// Bounds as read, before [`CommandBounds::new`] checks them.
#[derive(Deserialize)]
struct RawBounds {
    low: Vec<f64>,
    high: Vec<f64>,
}

impl TryFrom<RawBounds> for CommandBounds {
    type Error = MsgpError;
    fn try_from(raw: RawBounds) -> Result<Self> {
        Self::new(raw.low, raw.high)
    }
}

impl CommandBounds {
    /// Lower bound per command.
    pub fn low(&self) -> &[f64] {
        &self.low
    }

    /// Upper bound per command.
    pub fn high(&self) -> &[f64] {
        &self.high
    }

    /// Checks that both bounds are finite, as many, and `low < high` for every command.
    pub fn new(low: Vec<f64>, high: Vec<f64>) -> Result<Self> {
        if low.len() != high.len() || low.is_empty() {
            return Err(MsgpError::InvalidSetting {
                name: "command bounds",
                reason: format!(
                    "need as many lower as upper bounds (at least one), got {} and {}",
                    low.len(),
                    high.len()
                ),
            });
        }
        for (k, (l, h)) in low.iter().zip(&high).enumerate() {
            if !(l.is_finite() && h.is_finite() && l < h) {
                return Err(MsgpError::InvalidSetting {
                    name: "command bounds",
                    reason: format!("command {k}: need finite low < high, got [{l}, {h}]"),
                });
            }
        }
        Ok(Self { low, high })
    }

    /// `[−u_max, u_max]` per command.
    pub fn symmetric(u_max: &[f64]) -> Result<Self> {
        Self::new(u_max.iter().map(|u| -u).collect(), u_max.to_vec())
    }

    /// Number of commands.
    pub fn len(&self) -> usize {
        self.low.len()
    }

    /// True when there are no commands (never, for validated bounds).
    pub fn is_empty(&self) -> bool {
        self.low.is_empty()
    }

    /// The middle of each range.
    pub fn mid(&self) -> Vec<f64> {
        self.low
            .iter()
            .zip(&self.high)
            .map(|(l, h)| 0.5 * (l + h))
            .collect()
    }

    /// Half the width of each range.
    pub fn half_range(&self) -> Vec<f64> {
        self.low
            .iter()
            .zip(&self.high)
            .map(|(l, h)| 0.5 * (h - l))
            .collect()
    }

    /// The command for the unsaturated value `ũ` (one per command).
    pub fn saturate(&self, u_tilde: &[f64]) -> Vec<f64> {
        let (mid, h) = (self.mid(), self.half_range());
        u_tilde
            .iter()
            .enumerate()
            .map(|(k, u)| {
                mid[k] + crate::moments::saturation::saturate(2.0 * u / (3.0 * h[k]), h[k])
            })
            .collect()
    }

    /// The argument scale `2 / (3h)` of each command's sine.
    fn scale(&self) -> Vec<f64> {
        self.half_range().iter().map(|h| 2.0 / (3.0 * h)).collect()
    }

    /// Moments of `u = mid + sat(ũ)` for `ũ ~ N(m, s)` whose covariance with the policy input
    /// `q` is `Cov(q) v`: returns `(E[u], Cov[u], C)` with `Cov(q, u) = Cov(q) C`.
    pub fn moments<T: Scalar>(
        &self,
        m: &DVector<T>,
        s: &DMatrix<T>,
        v: &DMatrix<T>,
    ) -> (DVector<T>, DMatrix<T>, DMatrix<T>) {
        let du = m.len();
        let scale: Vec<T> = self.scale().into_iter().map(c::<T>).collect();
        let sm = DVector::from_fn(du, |i, _| m[i] * scale[i]);
        let sc = DMatrix::from_fn(du, du, |i, j| s[(i, j)] * scale[i] * scale[j]);
        let sat = saturate_moments(&sm, &sc, &self.half_range());
        let mid = self.mid();
        let mean = DVector::from_fn(du, |i, _| sat.mean[i] + c::<T>(mid[i]));
        let vs = DMatrix::from_fn(v.nrows(), du, |r, i| v[(r, i)] * scale[i]);
        (mean, sat.cov, vs * sat.c)
    }

    /// Vector–Jacobian product of [`CommandBounds::moments`] (f64): for the adjoints of its
    /// outputs, the adjoints of `(m, s, v)`. The affine parts in closed form, the sine's
    /// moments by forward-mode duals over its `d_u + d_u²` inputs.
    pub(crate) fn moments_vjp(
        &self,
        m: &DVector<f64>,
        s: &DMatrix<f64>,
        v: &DMatrix<f64>,
        mean_bar: &DVector<f64>,
        cov_bar: &DMatrix<f64>,
        c_bar: &DMatrix<f64>,
    ) -> Result<(DVector<f64>, DMatrix<f64>, DMatrix<f64>)> {
        let du = m.len();
        let scale = self.scale();
        let sm = DVector::from_fn(du, |i, _| m[i] * scale[i]);
        let sc = DMatrix::from_fn(du, du, |i, j| s[(i, j)] * scale[i] * scale[j]);
        let h = self.half_range();
        let sat = saturate_moments(&sm, &sc, &h);
        let vs = DMatrix::from_fn(v.nrows(), du, |r, i| v[(r, i)] * scale[i]);
        // C = (v S) C_sat
        let vs_bar = c_bar * sat.c.transpose();
        let csat_bar = vs.transpose() * c_bar;
        let v_bar = DMatrix::from_fn(v.nrows(), du, |r, i| vs_bar[(r, i)] * scale[i]);
        let (sm_bar, sc_bar) = saturation_vjp(&sm, &sc, &h, mean_bar, cov_bar, &csat_bar)?;
        let m_bar = DVector::from_fn(du, |i, _| sm_bar[i] * scale[i]);
        let s_bar = DMatrix::from_fn(du, du, |i, j| sc_bar[(i, j)] * scale[i] * scale[j]);
        Ok((m_bar, s_bar, v_bar))
    }
}

/// The sine saturation's vector–Jacobian product: the adjoints of its input moments `(m, s)`
/// for the adjoints of its outputs (mean, covariance and `C`), by forward-mode duals over the
/// `d_u + d_u²` inputs.
pub(crate) fn saturation_vjp(
    m: &DVector<f64>,
    s: &DMatrix<f64>,
    u_max: &[f64],
    mean_bar: &DVector<f64>,
    cov_bar: &DMatrix<f64>,
    c_bar: &DMatrix<f64>,
) -> Result<(DVector<f64>, DMatrix<f64>)> {
    use crate::numeric::dual::{moments_gradient, weighted_sum};
    moments_gradient(m, s, |md, sd| {
        let sat = saturate_moments(md, sd, u_max);
        Ok(weighted_sum(&[
            (sat.mean.as_slice(), mean_bar.as_slice()),
            (sat.cov.as_slice(), cov_bar.as_slice()),
            (sat.c.as_slice(), c_bar.as_slice()),
        ]))
    })
}
