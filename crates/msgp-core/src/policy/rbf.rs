//! PILCO's radial-basis-function network policy: `ũ_a(y) = Σ_i w_ia exp(−½ (y − c_i)ᵀ Λ⁻¹
//! (y − c_i))`, `Λ = diag(ℓ²)`, squashed into the command bounds by the sine saturation
//! ([`super::bounds`]). It acts on the current observation and keeps no state.
//!
//! The network is the mean of a GP whose pseudo-inputs are the centres and whose weights are
//! given (no `K̃⁻¹`), so its moments under a Gaussian observation are exactly the GP moment
//! matching's ([`crate::moments`]) with unit signal variance and without the GP's own variance
//! term (`σ_f² − tr(K̃⁻¹ Q)`): mean `wᵀ q`, covariance `wᵀ Q w − M Mᵀ`, input–output
//! covariance as the GP's. The closed-form vector–Jacobian product reuses the moment
//! matching's hand-derived backward pass; duals through [`FeedbackPolicy::moments`] are its
//! reference.

use nalgebra::{DMatrix, DVector};

use super::bounds::CommandBounds;
use super::{FeedbackPolicy, PolicyMoments};
use crate::error::{MsgpError, Result};
use crate::gp::{KernelScalar, OutputGp, PreparedGp};
use crate::moments::fast::MmState;
use crate::moments::vjp::{BackWork, Backward, GpAdjoint};
use crate::moments::{MomentMatch, moment_match};
use crate::narx::start_window::StartWindow;
use crate::numeric::linalg::{Cholesky, JitterLog, JitterPolicy};
use crate::numeric::scalar::{Scalar, c};

/// A radial-basis-function network policy (see the module docs), in the observation's units.
#[derive(Clone, Debug, PartialEq)]
pub struct RbfPolicy<T: nalgebra::Scalar> {
    /// Centres `c_i` (n × d_y).
    pub centres: DMatrix<T>,
    /// Weights `w_ia` (n × d_u).
    pub weights: DMatrix<T>,
    /// `log ℓ_d` of the basis functions' widths (d_y), shared by every centre.
    pub log_widths: DVector<T>,
    /// The command bounds.
    pub bounds: CommandBounds,
}

impl<T: Scalar> RbfPolicy<T> {
    /// Checks shapes: `n ≥ 1` centres of the observation's size, a weight per centre and
    /// command, a width per observation entry.
    pub fn new(
        centres: DMatrix<T>,
        weights: DMatrix<T>,
        log_widths: DVector<T>,
        bounds: CommandBounds,
    ) -> Result<Self> {
        let (n, dy) = centres.shape();
        if n == 0 || dy == 0 || weights.shape() != (n, bounds.len()) || log_widths.len() != dy {
            return Err(MsgpError::Shape(format!(
                "RBF policy: {n} centres of size {dy} need {n}x{} weights and {dy} widths, got \
                 {}x{} and {}",
                bounds.len(),
                weights.nrows(),
                weights.ncols(),
                log_widths.len()
            )));
        }
        Ok(Self {
            centres,
            weights,
            log_widths,
            bounds,
        })
    }

    /// Number of parameters: centres, weights, widths.
    pub fn param_len(&self) -> usize {
        self.centres.len() + self.weights.len() + self.log_widths.len()
    }

    /// The parameters `θ = [centres; weights; log widths]`, each column-major.
    pub fn theta(&self) -> Vec<T> {
        let mut v: Vec<T> = self.centres.iter().copied().collect();
        v.extend(self.weights.iter().copied());
        v.extend(self.log_widths.iter().copied());
        v
    }

    /// The same network with parameters `θ` ([`RbfPolicy::theta`]'s layout) on scalar `U`.
    pub fn with_theta<U: Scalar>(&self, theta: &[U]) -> Result<RbfPolicy<U>> {
        let (n, dy) = self.centres.shape();
        let du = self.weights.ncols();
        if theta.len() != self.param_len() {
            return Err(MsgpError::Shape(format!(
                "RBF policy has {} parameters, {} given",
                self.param_len(),
                theta.len()
            )));
        }
        let (a, b) = (n * dy, n * dy + n * du);
        Ok(RbfPolicy {
            centres: DMatrix::from_column_slice(n, dy, &theta[..a]),
            weights: DMatrix::from_column_slice(n, du, &theta[a..b]),
            log_widths: DVector::from_column_slice(&theta[b..]),
            bounds: self.bounds.clone(),
        })
    }

    /// The network before the saturation at a point (entries of `y` beyond the centres' size
    /// are ignored).
    pub fn network(&self, y: &[T]) -> Vec<T> {
        let inv_l2: Vec<T> = self.inv_l2();
        let half = c::<T>(0.5);
        (0..self.weights.ncols())
            .map(|a| {
                let mut u = T::zero();
                for i in 0..self.centres.nrows() {
                    let mut s = T::zero();
                    for ((yd, cd), w) in y.iter().zip(self.centres.row(i).iter()).zip(&inv_l2) {
                        let r = *yd - *cd;
                        s += r * r * *w;
                    }
                    u += self.weights[(i, a)] * (-(s * half)).exp();
                }
                u
            })
            .collect()
    }

    fn inv_l2(&self) -> Vec<T> {
        self.log_widths
            .iter()
            .map(|l| (-(*l * c::<T>(2.0))).exp())
            .collect()
    }
}

impl<T: KernelScalar> RbfPolicy<T> {
    /// The network as a prepared GP: pseudo-inputs at the centres, `β` the weights, unit signal
    /// variance, `K̃⁻¹ = 0` (no variance term of its own), no noise.
    fn as_gp(&self) -> PreparedGp<T> {
        let n = self.centres.nrows();
        let inv_l2 = self.inv_l2();
        let outputs = (0..self.weights.ncols())
            .map(|a| {
                let beta = DVector::from_column_slice(self.weights.column(a).as_slice());
                let kinv = DMatrix::<T>::zeros(n, n);
                let q_weights = T::q_weights(&beta, &kinv);
                OutputGp {
                    inv_l2: inv_l2.clone(),
                    sf2: T::one(),
                    sx2: T::zero(),
                    sy2: T::zero(),
                    beta,
                    kinv,
                    chol: Cholesky {
                        l: DMatrix::identity(n, n),
                        jitter: 0.0,
                    },
                    q_weights,
                }
            })
            .collect();
        PreparedGp {
            pseudo_inputs: self.centres.clone(),
            outputs,
            jitter: JitterPolicy::default(),
            linear_mean: None,
            start: StartWindow::default(),
        }
    }
}

impl RbfPolicy<f64> {
    /// The command at observation `y`; an error for an observation of the wrong size.
    pub fn act(&self, y: &[f64]) -> Result<Vec<f64>> {
        let dy = self.centres.ncols();
        if y.len() != dy {
            return Err(MsgpError::Shape(format!(
                "RBF policy expects an observation of size {dy}, got {}",
                y.len()
            )));
        }
        Ok(self.bounds.saturate(&self.network(y)))
    }

    /// Vector–Jacobian product of [`FeedbackPolicy::moments`] at `q ~ N(mean, cov)`: for the
    /// adjoints of its outputs, the adjoints of `mean`, `cov` and `θ` ([`RbfPolicy::theta`]'s
    /// layout). The network's part by the moment matching's backward pass, the saturation's by
    /// [`CommandBounds::moments_vjp`].
    pub(crate) fn moments_vjp(
        &self,
        mean: &DVector<f64>,
        cov: &DMatrix<f64>,
        mean_bar: &DVector<f64>,
        cov_bar: &DMatrix<f64>,
        c_bar: &DMatrix<f64>,
    ) -> Result<(DVector<f64>, DMatrix<f64>, Vec<f64>)> {
        let (n, dy) = self.centres.shape();
        let du = self.weights.ncols();
        if mean.len() != dy || cov.shape() != (dy, dy) {
            return Err(MsgpError::Shape(format!(
                "RBF policy expects an observation of size {dy}, got {}",
                mean.len()
            )));
        }
        let gp = self.as_gp();
        let mut st = MmState::default();
        st.forward(&gp, mean, cov, &mut JitterLog::default())?;
        let mm = st.moments(cov);
        let s = deterministic(&mm.cov);
        let (m_bar, s_bar, v_bar) = self
            .bounds
            .moments_vjp(&mm.mean, &s, &mm.v, mean_bar, cov_bar, c_bar)?;
        let mut adj = GpAdjoint::zeros(n, dy, du);
        let (q_mean_bar, q_cov_bar) = Backward {
            gp: &gp,
            sigma: cov,
            c: &st,
            mbar_in: &m_bar,
            sbar: &s_bar,
            vbar: &v_bar,
            adj: &mut adj,
            w: &mut BackWork::default(),
        }
        .pull();
        let mut theta: Vec<f64> = adj.xbar.iter().copied().collect();
        for a in 0..du {
            theta.extend(adj.beta[a].iter());
        }
        let inv_l2 = self.inv_l2();
        // ∂(1/ℓ²)/∂log ℓ = −2/ℓ²
        theta.extend(
            (0..dy).map(|d| (0..du).map(|a| adj.inv_l2[(a, d)]).sum::<f64>() * (-2.0 * inv_l2[d])),
        );
        Ok((q_mean_bar, q_cov_bar, theta))
    }
}

/// The network's covariance from the GP moment matching's: without the unit signal variance
/// the GP adds on each output's diagonal (a variance that rounding takes below zero, for a
/// near-deterministic input, is zero).
fn deterministic<T: Scalar>(cov: &DMatrix<T>) -> DMatrix<T> {
    let mut s = cov.clone();
    for a in 0..s.nrows() {
        s[(a, a)] -= T::one();
        if s[(a, a)].re() < 0.0 {
            s[(a, a)] = T::zero();
        }
    }
    s
}

impl<T: MomentMatch> FeedbackPolicy<T> for RbfPolicy<T> {
    fn input_dim(&self) -> usize {
        self.weights.ncols()
    }

    fn moments(&self, mean: &DVector<T>, cov: &DMatrix<T>) -> Result<PolicyMoments<T>> {
        let dy = self.centres.ncols();
        if mean.len() != dy || cov.shape() != (dy, dy) {
            return Err(MsgpError::Shape(format!(
                "RBF policy expects an observation of size {dy}, got {}",
                mean.len()
            )));
        }
        let mm = moment_match(&self.as_gp(), mean, cov, &mut JitterLog::default())?;
        let (mean, cov, c) = self
            .bounds
            .moments(&mm.mean, &deterministic(&mm.cov), &mm.v);
        Ok(PolicyMoments { mean, cov, c })
    }
}
