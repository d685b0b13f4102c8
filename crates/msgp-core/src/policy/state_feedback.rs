//! A linear state feedback on a NARX window, squashed into the command bounds:
//! `u_t = mid + sat(K w_t + b)` ([`super::bounds`]) with the window
//! `w_t = [y_t, y_{t−1}, …, y_{t−k_y+1}, u_{t−1}, …, u_{t−k_u}]` of the last `k_y` observations
//! and `k_u` commands (`k_y = 1, k_u = 0`: PILCO's linear policy on the observation).
//!
//! The policy carries what the window needs beyond `y_t` as its state
//! `p_t = [y_t, …, y_{t−k_y+2}, u_t, …, u_{t−k_u+1}]`, so the policy input
//! `q = [y_t; p_{t−1}]` is the window itself. `ũ = K q + b` and the state's shifted entries are
//! linear in `q` (exact); only the saturation is moment-matched, and the new command enters the
//! state as the same random variable as the output `u_t`.

use nalgebra::{DMatrix, DVector};

use super::bounds::CommandBounds;
use super::{FeedbackPolicy, PolicyMoments, RestEntry};
use crate::error::{MsgpError, Result};
use crate::numeric::scalar::Scalar;

/// A saturated linear feedback on the window (see the module docs), in original units.
#[derive(Clone, Debug, PartialEq)]
pub struct StateFeedback<T: nalgebra::Scalar> {
    /// `K` (d_u × (k_y d_y + k_u d_u)), columns in the window's order.
    pub gain: DMatrix<T>,
    /// `b` (d_u).
    pub offset: DVector<T>,
    /// `k_y ≥ 1`: observations in the window.
    pub output_lags: usize,
    /// `k_u`: past commands in the window.
    pub input_lags: usize,
    /// The command bounds.
    pub bounds: CommandBounds,
}

impl<T: Scalar> StateFeedback<T> {
    /// Checks shapes; `dy` is the observation's size.
    pub fn new(
        gain: DMatrix<T>,
        offset: DVector<T>,
        dy: usize,
        (output_lags, input_lags): (usize, usize),
        bounds: CommandBounds,
    ) -> Result<Self> {
        let du = bounds.len();
        let nq = output_lags * dy + input_lags * du;
        if output_lags == 0 || dy == 0 || gain.shape() != (du, nq) || offset.len() != du {
            return Err(MsgpError::Shape(format!(
                "state feedback on {output_lags} observations of size {dy} and {input_lags} \
                 commands of size {du} needs a {du}x{nq} gain (at least one observation) and \
                 {du} offsets, got {}x{} and {}",
                gain.nrows(),
                gain.ncols(),
                offset.len()
            )));
        }
        Ok(Self {
            gain,
            offset,
            output_lags,
            input_lags,
            bounds,
        })
    }

    /// Observation size `d_y`.
    pub fn dy(&self) -> usize {
        self.gain
            .ncols()
            .saturating_sub(self.input_lags * self.du())
            / self.output_lags.max(1)
    }

    fn du(&self) -> usize {
        self.gain.nrows()
    }

    /// Number of parameters: the gain, then the offset.
    pub fn param_len(&self) -> usize {
        self.gain.len() + self.offset.len()
    }

    /// `θ = [K (column-major); b]`.
    pub fn theta(&self) -> Vec<T> {
        self.gain
            .iter()
            .chain(self.offset.iter())
            .copied()
            .collect()
    }

    /// The same feedback with parameters `θ` ([`StateFeedback::theta`]'s layout) on scalar `U`.
    pub fn with_theta<U: Scalar>(&self, theta: &[U]) -> Result<StateFeedback<U>> {
        if theta.len() != self.param_len() {
            return Err(MsgpError::Shape(format!(
                "state feedback has {} parameters, {} given",
                self.param_len(),
                theta.len()
            )));
        }
        let (du, nq) = self.gain.shape();
        Ok(StateFeedback {
            gain: DMatrix::from_column_slice(du, nq, &theta[..du * nq]),
            offset: DVector::from_column_slice(&theta[du * nq..]),
            output_lags: self.output_lags,
            input_lags: self.input_lags,
            bounds: self.bounds.clone(),
        })
    }

    /// Where each entry of the output `o = [u_t; p_t]` comes from in `[u_t; r]`, with
    /// `r = [y_t, …, y_{t−k_y+2}, u_{t−1}, …, u_{t−k_u+1}]` the entries of `q` that shift into
    /// the state: index `< d_u` is `u_t`, else `d_u + ` the entry of `r`.
    fn output_sources(&self) -> (Vec<usize>, Vec<usize>) {
        let (du, dy) = (self.du(), self.dy());
        let ny = (self.output_lags - 1) * dy;
        let nu_old = self.input_lags.saturating_sub(1) * du;
        // r's entries in q: the newest observations, then the newest past commands
        let r_in_q: Vec<usize> = (0..ny)
            .chain((0..nu_old).map(|k| self.output_lags * dy + k))
            .collect();
        let mut src: Vec<usize> = (0..du).collect();
        src.extend((0..ny).map(|k| du + k));
        if self.input_lags > 0 {
            src.extend(0..du);
            src.extend((0..nu_old).map(|k| du + ny + k));
        }
        (src, r_in_q)
    }
}

impl StateFeedback<f64> {
    /// One step at a point: `(u_t, p_t)` from `y_t` and `p_{t−1}`; an error when their sizes
    /// do not fit the window.
    pub fn act(&self, y: &[f64], state: &[f64]) -> Result<(Vec<f64>, Vec<f64>)> {
        let q: Vec<f64> = y.iter().chain(state).copied().collect();
        if y.len() != self.dy() || q.len() != self.gain.ncols() {
            return Err(MsgpError::Shape(format!(
                "state feedback expects an observation of size {} and a state of size {}, got \
                 {} and {}",
                self.dy(),
                self.gain.ncols() - self.dy(),
                y.len(),
                state.len()
            )));
        }
        let ut: Vec<f64> = (0..self.du())
            .map(|i| self.offset[i] + (0..q.len()).map(|k| self.gain[(i, k)] * q[k]).sum::<f64>())
            .collect();
        let u = self.bounds.saturate(&ut);
        let (src, r_in_q) = self.output_sources();
        let ur: Vec<f64> = u
            .iter()
            .copied()
            .chain(r_in_q.iter().map(|&k| q[k]))
            .collect();
        let state = src[self.du()..].iter().map(|&k| ur[k]).collect();
        Ok((u, state))
    }
}

impl<T: Scalar> FeedbackPolicy<T> for StateFeedback<T> {
    fn input_dim(&self) -> usize {
        self.du()
    }

    fn state_dim(&self) -> usize {
        self.gain.ncols() - self.dy()
    }

    /// `[y_{t−1}, …, y_{t−k_y+1}, u_{t−1}, …, u_{t−k_u}]` from the measured rows, samples before
    /// the first repeating it.
    fn initial_state(&self, y: &DMatrix<f64>, u: &DMatrix<f64>, t: usize) -> DVector<f64> {
        let (du, dy) = (self.du(), self.dy());
        let row = |k: usize| t.saturating_sub(k);
        let mut p = Vec::with_capacity(self.gain.ncols() - dy);
        for k in 1..self.output_lags {
            p.extend((0..dy).map(|j| y[(row(k), j)]));
        }
        for k in 1..=self.input_lags {
            p.extend((0..du).map(|j| u[(row(k), j)]));
        }
        DVector::from_vec(p)
    }

    /// The earlier observations, then the earlier commands.
    fn rest_state(&self) -> Vec<RestEntry> {
        let (du, dy) = (self.du(), self.dy());
        let observations = (1..self.output_lags).flat_map(|_| (0..dy).map(RestEntry::Observation));
        let commands = (0..self.input_lags).flat_map(|_| (0..du).map(RestEntry::Command));
        observations.chain(commands).collect()
    }

    fn moments(&self, mean: &DVector<T>, cov: &DMatrix<T>) -> Result<PolicyMoments<T>> {
        let nq = self.gain.ncols();
        if mean.len() != nq {
            return Err(MsgpError::Shape(format!(
                "state feedback expects a window of size {nq}, got {}",
                mean.len()
            )));
        }
        let du = self.du();
        // ũ = K q + b, Cov(q, ũ) = Σ Kᵀ
        let kt = self.gain.transpose();
        let um = &self.gain * mean + &self.offset;
        let uc = &self.gain * cov * &kt;
        let (u_mean, u_cov, u_c) = self.bounds.moments(&um, &uc, &kt);
        let (src, r_in_q) = self.output_sources();
        let nr = r_in_q.len();
        // [u; r]: r = R q exactly, Cov(r, u) = Cov(r, q) C_u = R Σ C_u
        let n = du + nr;
        let mut m = DVector::<T>::zeros(n);
        let mut s = DMatrix::<T>::zeros(n, n);
        let mut cm = DMatrix::<T>::zeros(nq, n);
        m.rows_mut(0, du).copy_from(&u_mean);
        s.view_mut((0, 0), (du, du)).copy_from(&u_cov);
        cm.columns_mut(0, du).copy_from(&u_c);
        let sig_cu = cov * &u_c;
        for (a, &qa) in r_in_q.iter().enumerate() {
            m[du + a] = mean[qa];
            cm[(qa, du + a)] = T::one();
            for (b, &qb) in r_in_q.iter().enumerate() {
                s[(du + a, du + b)] = cov[(qa, qb)];
            }
            for i in 0..du {
                s[(du + a, i)] = sig_cu[(qa, i)];
                s[(i, du + a)] = sig_cu[(qa, i)];
            }
        }
        let no = src.len();
        Ok(PolicyMoments {
            mean: DVector::from_fn(no, |i, _| m[src[i]]),
            cov: DMatrix::from_fn(no, no, |i, j| s[(src[i], src[j])]),
            c: DMatrix::from_fn(nq, no, |k, i| cm[(k, src[i])]),
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Running the policy along a trajectory, its state after step `t` is the window's rest as
    /// `initial_state` reads it from the same samples at `t + 1`: the two agree on the layout.
    #[test]
    fn the_state_after_acting_is_the_window_initial_state_reads() {
        let bounds = CommandBounds::new(vec![-2.0, -1.0], vec![2.0, 3.0]).expect("bounds");
        let (dy, lags) = (2, (3, 2));
        let nq = lags.0 * dy + lags.1 * 2;
        let policy = StateFeedback::new(
            DMatrix::from_fn(2, nq, |i, k| 0.05 * (k as f64 - 3.0) + 0.1 * i as f64),
            DVector::from_vec(vec![0.1, 0.4]),
            dy,
            lags,
            bounds,
        )
        .expect("policy");
        let n = 8;
        let y = DMatrix::from_fn(n, dy, |t, j| (0.4 * t as f64 + j as f64).sin());
        let mut u = DMatrix::zeros(n, 2);
        let mut state: Vec<f64> = policy.initial_state(&y, &u, 0).iter().copied().collect();
        for t in 0..n - 1 {
            let yt: Vec<f64> = y.row(t).iter().copied().collect();
            let (ut, next) = policy.act(&yt, &state).expect("act");
            u.set_row(t, &nalgebra::RowDVector::from_vec(ut));
            let read: Vec<f64> = policy
                .initial_state(&y, &u, t + 1)
                .iter()
                .copied()
                .collect();
            if t + 1 >= lags.0.max(lags.1) {
                assert_eq!(next, read, "step {t}");
            }
            state = next;
        }
    }
}
