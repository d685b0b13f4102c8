//! Feedback policies `u = π(y; θ_π)` inside a moment-matching rollout (paper eq. 10).
//!
//! A policy may keep an internal state `p_t` (a previous observation for a finite-difference
//! derivative, a running integral, …) that the rollout carries inside its Gaussian. At each step
//! the policy receives the Gaussian of `q = [y_t; p_{t−1}]` (the current *observation* and its
//! previous state) and returns the moments of `o = [u_t; p_t]`: mean, covariance and the matrix
//! `C` with `Cov(q, o) = Cov(q) C`. The rollout then sets `Cov(z, o) = Cov(z, q) C` for every other
//! state entry `z`, which is exact for linear maps and PILCO's moment-matching approximation for
//! nonlinear ones (saturated policies implement this same trait). A stateless policy has
//! `state_dim() = 0` and sees just `y_t`.

use nalgebra::{DMatrix, DVector};

use crate::error::{MsgpError, Result};
use crate::numeric::scalar::Scalar;

/// Moments of a policy output `o = [u_t; p_t]`.
#[derive(Clone, Debug)]
pub struct PolicyMoments<T: Scalar> {
    /// `E[o]` (d_u + d_p).
    pub mean: DVector<T>,
    /// `Cov[o]`.
    pub cov: DMatrix<T>,
    /// `C` ((d_y + d_p) × (d_u + d_p)) with `Cov(q, o) = Cov(q) C`.
    pub c: DMatrix<T>,
}

/// A feedback policy usable in closed-loop rollouts.
pub trait FeedbackPolicy<T: Scalar>: Send + Sync {
    /// Number of inputs `d_u` it produces.
    fn input_dim(&self) -> usize;
    /// Dimension `d_p` of its internal state (0 for a stateless policy).
    fn state_dim(&self) -> usize {
        0
    }
    /// Its state after acting at time `t − 1`, computed from measured outputs `y` and inputs `u`
    /// (rows are time steps) — the starting point of a rollout at `t`.
    fn initial_state(&self, y: &DMatrix<f64>, u: &DMatrix<f64>, t: usize) -> DVector<f64> {
        let _ = (y, u, t);
        DVector::zeros(0)
    }
    /// What each entry of its state holds before a rollout that starts at rest (the policy
    /// search's start): an earlier observation, an earlier command, or zero.
    fn rest_state(&self) -> Vec<RestEntry> {
        vec![RestEntry::Zero; self.state_dim()]
    }
    /// Moments of `o = [u_t; p_t]` for `q = [y_t; p_{t−1}] ~ N(mean, cov)`.
    fn moments(&self, mean: &DVector<T>, cov: &DMatrix<T>) -> Result<PolicyMoments<T>>;
}

/// An entry of a policy's state at rest ([`FeedbackPolicy::rest_state`]).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum RestEntry {
    /// An earlier observation of output `j`: the latent rest value plus observation noise.
    Observation(usize),
    /// An earlier command `j`: the command at rest.
    Command(usize),
    /// Zero (an integral, …).
    Zero,
}

/// `u = K y + b`; moments are exact.
#[derive(Clone, Debug, PartialEq)]
pub struct LinearPolicy<T: Scalar> {
    /// `K` (d_u × d_y).
    pub gain: DMatrix<T>,
    /// `b` (d_u).
    pub offset: DVector<T>,
}

impl<T: Scalar> LinearPolicy<T> {
    /// Checks shapes.
    pub fn new(gain: DMatrix<T>, offset: DVector<T>) -> Result<Self> {
        if gain.nrows() != offset.len() {
            return Err(MsgpError::Shape(format!(
                "linear policy gain has {} rows but offset has {} entries",
                gain.nrows(),
                offset.len()
            )));
        }
        Ok(Self { gain, offset })
    }

    /// Converts the scalar type.
    pub fn map<U: Scalar>(&self, f: impl Fn(T) -> U + Copy) -> LinearPolicy<U> {
        LinearPolicy {
            gain: self.gain.map(f),
            offset: self.offset.map(f),
        }
    }
}

impl<T: Scalar> FeedbackPolicy<T> for LinearPolicy<T> {
    fn input_dim(&self) -> usize {
        self.gain.nrows()
    }

    fn moments(&self, mean: &DVector<T>, cov: &DMatrix<T>) -> Result<PolicyMoments<T>> {
        if mean.len() != self.gain.ncols() {
            return Err(MsgpError::Shape(format!(
                "linear policy expects {} observations, got {}",
                self.gain.ncols(),
                mean.len()
            )));
        }
        Ok(PolicyMoments {
            mean: &self.gain * mean + &self.offset,
            cov: &self.gain * cov * self.gain.transpose(),
            c: self.gain.transpose(),
        })
    }
}

/// A policy behind a reference or a box is a policy (the lifted [`Policy`]s inside
/// [`Normalized`]).
macro_rules! forward_policy {
    ($($ty:ty),*) => {$(
        impl<T: Scalar, P: FeedbackPolicy<T> + ?Sized> FeedbackPolicy<T> for $ty {
            fn input_dim(&self) -> usize {
                (**self).input_dim()
            }
            fn state_dim(&self) -> usize {
                (**self).state_dim()
            }
            fn initial_state(&self, y: &DMatrix<f64>, u: &DMatrix<f64>, t: usize) -> DVector<f64> {
                (**self).initial_state(y, u, t)
            }
            fn rest_state(&self) -> Vec<RestEntry> {
                (**self).rest_state()
            }
            fn moments(&self, mean: &DVector<T>, cov: &DMatrix<T>) -> Result<PolicyMoments<T>> {
                (**self).moments(mean, cov)
            }
        }
    )*};
}
forward_policy!(&P, Box<P>);

mod bounds;
mod normalized;
mod parametric;
mod pid;
mod rbf;
mod state_feedback;

pub use bounds::CommandBounds;
pub use normalized::Normalized;
pub use parametric::Policy;
pub(crate) use parametric::ThetaVjp;
pub use pid::PidPolicy;
pub use rbf::RbfPolicy;
pub use state_feedback::StateFeedback;

/// The policy that produced a feedback trajectory, as data (f64 parameters), so the loss can
/// rebuild it on any scalar type: f64 for values, duals for gradients and for the adjoint
/// sweep's policy Jacobians.
#[derive(Clone, Debug, PartialEq)]
pub enum PolicySpec {
    /// `u = K y + b` in the model's units.
    Linear(LinearPolicy<f64>),
    /// A policy in the model's units.
    Direct(Policy),
    /// A policy in original units inside a normalised model.
    Normalized(Normalized<Policy>),
}

impl PolicySpec {
    /// The same policy (given in original units) for a rollout in the normalised units of
    /// `normalizer`: a linear policy is converted exactly (`K_n = diag(1/s_u) K diag(s_y)`,
    /// `b_n = (K m_y + b − m_u)/s_u`), a policy is wrapped in [`Normalized`].
    pub fn normalized(&self, normalizer: &crate::data::Normalizer) -> Result<PolicySpec> {
        let n = normalizer;
        Ok(match self {
            PolicySpec::Linear(p) => {
                let (du, dy) = p.gain.shape();
                if n.y_std.len() != dy || n.u_std.len() != du {
                    return Err(MsgpError::Shape(
                        "linear policy does not fit the data's dimensions".into(),
                    ));
                }
                let gain =
                    DMatrix::from_fn(du, dy, |i, j| p.gain[(i, j)] * n.y_std[j] / n.u_std[i]);
                let ym = DVector::from_column_slice(&n.y_mean);
                let k_ym = &p.gain * ym;
                let offset = DVector::from_fn(du, |i, _| {
                    (k_ym[i] + p.offset[i] - n.u_mean[i]) / n.u_std[i]
                });
                PolicySpec::Linear(LinearPolicy::new(gain, offset)?)
            }
            PolicySpec::Direct(p) => PolicySpec::Normalized(Normalized {
                inner: p.clone(),
                normalizer: n.clone(),
            }),
            PolicySpec::Normalized(w) => PolicySpec::Normalized(Normalized {
                inner: w.inner.clone(),
                normalizer: n.clone(),
            }),
        })
    }

    /// Whether [`PolicySpec::moments_vjp`] has a closed form (the PID and the RBF network; a
    /// linear policy's map is cheap enough for duals).
    pub(crate) fn has_closed_form_vjp(&self) -> bool {
        match self {
            PolicySpec::Linear(_) => false,
            PolicySpec::Direct(p) => p.has_closed_form_vjp(),
            PolicySpec::Normalized(w) => w.inner.has_closed_form_vjp(),
        }
    }

    /// Vector–Jacobian product of the policy's moment map in closed form (the input moments'
    /// adjoints and the parameters'); an error for a policy without one
    /// ([`PolicySpec::has_closed_form_vjp`]).
    pub(crate) fn moments_vjp(
        &self,
        mean: &DVector<f64>,
        cov: &DMatrix<f64>,
        mean_bar: &DVector<f64>,
        cov_bar: &DMatrix<f64>,
        c_bar: &DMatrix<f64>,
    ) -> Result<ThetaVjp> {
        let none =
            || MsgpError::Shape("this policy has no closed-form vector–Jacobian product".into());
        match self {
            PolicySpec::Direct(p) => p
                .moments_vjp(mean, cov, mean_bar, cov_bar, c_bar)
                .unwrap_or_else(|| Err(none())),
            PolicySpec::Normalized(p) => p.moments_vjp(mean, cov, mean_bar, cov_bar, c_bar),
            PolicySpec::Linear(_) => Err(none()),
        }
    }

    /// The policy on scalar type `T`.
    pub fn lift<T: crate::moments::MomentMatch>(&self) -> Box<dyn FeedbackPolicy<T>> {
        let c = crate::numeric::scalar::c::<T>;
        match self {
            PolicySpec::Linear(p) => Box::new(p.map(c)),
            PolicySpec::Direct(p) => p.lift::<T>(),
            PolicySpec::Normalized(n) => Box::new(Normalized {
                inner: n.inner.lift::<T>(),
                normalizer: n.normalizer.clone(),
            }),
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::Normalizer;

    #[test]
    fn normalised_linear_policy_acts_like_the_original() {
        let p = LinearPolicy::new(
            DMatrix::from_row_slice(1, 2, &[-0.7, 0.4]),
            DVector::from_vec(vec![0.3]),
        )
        .expect("policy");
        let n = Normalizer {
            u_mean: vec![0.2],
            u_std: vec![1.5],
            y_mean: vec![1.0, -2.0],
            y_std: vec![0.5, 3.0],
        };
        let PolicySpec::Linear(pn) = PolicySpec::Linear(p.clone())
            .normalized(&n)
            .expect("normalise")
        else {
            panic!("a linear policy stays linear");
        };
        let yo = DVector::from_vec(vec![1.3, -4.0]);
        let yn = DVector::from_vec(vec![(1.3 - 1.0) / 0.5, (-4.0 + 2.0) / 3.0]);
        let uo = &p.gain * &yo + &p.offset;
        let un = &pn.gain * &yn + &pn.offset;
        assert!(((uo[0] - 0.2) / 1.5 - un[0]).abs() < 1e-14);
    }
}
