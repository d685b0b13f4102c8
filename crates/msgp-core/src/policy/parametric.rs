//! The policy families a search can move, as data in original units: a saturated PID
//! ([`PidPolicy`]), a saturated linear feedback on a window ([`StateFeedback`]) and PILCO's RBF
//! network ([`RbfPolicy`]). Each has a flat parameter vector `θ`, acts at a point (on a plant),
//! and lifts to any scalar type for moment matching (f64 values, duals for gradients); the
//! PID and the RBF network also have closed-form vector–Jacobian products.

use nalgebra::{DMatrix, DVector};

use super::bounds::CommandBounds;
use super::{FeedbackPolicy, PidPolicy, RbfPolicy, StateFeedback};
use crate::error::{MsgpError, Result};
use crate::moments::MomentMatch;
use crate::numeric::scalar::{Scalar, c};

/// A policy family with its parameters (see the module docs).
#[derive(Clone, Debug, PartialEq)]
pub enum Policy {
    /// Saturated PID on the observation.
    Pid(PidPolicy<f64>),
    /// Saturated linear feedback on a window of observations and commands.
    StateFeedback(StateFeedback<f64>),
    /// PILCO's RBF network, saturated.
    Rbf(RbfPolicy<f64>),
}

/// A closed-form vector–Jacobian product of a policy's moment map: the adjoints of the input
/// moments and of `θ`.
pub(crate) type ThetaVjp = (DVector<f64>, DMatrix<f64>, Vec<f64>);

impl Policy {
    /// The family's name (`pid`, `linear`, `rbf`).
    pub fn kind(&self) -> &'static str {
        match self {
            Policy::Pid(_) => "pid",
            Policy::StateFeedback(_) => "linear",
            Policy::Rbf(_) => "rbf",
        }
    }

    /// The PID policy, if this is one.
    pub fn as_pid(&self) -> Option<&PidPolicy<f64>> {
        match self {
            Policy::Pid(p) => Some(p),
            _ => None,
        }
    }

    /// The parameters `θ`: PID `[K_p; K_i; K_d]`, state feedback `[K; b]`, RBF
    /// `[centres; weights; log widths]`, each matrix column-major.
    pub fn theta(&self) -> Vec<f64> {
        match self {
            Policy::Pid(p) => p.kp.iter().chain(&p.ki).chain(&p.kd).copied().collect(),
            Policy::StateFeedback(p) => p.theta(),
            Policy::Rbf(p) => p.theta(),
        }
    }

    /// Number of parameters.
    pub fn param_len(&self) -> usize {
        match self {
            Policy::Pid(p) => 3 * p.kp.len(),
            Policy::StateFeedback(p) => p.param_len(),
            Policy::Rbf(p) => p.param_len(),
        }
    }

    /// The same family with parameters `θ`.
    pub fn with_theta(&self, theta: &[f64]) -> Result<Policy> {
        Ok(match self {
            Policy::Pid(p) => Policy::Pid(pid_with(p, theta)?),
            Policy::StateFeedback(p) => Policy::StateFeedback(p.with_theta(theta)?),
            Policy::Rbf(p) => Policy::Rbf(p.with_theta(theta)?),
        })
    }

    /// The policy at parameters `θ` on scalar `T` (original units).
    pub fn lift_theta<T: MomentMatch>(&self, theta: &[T]) -> Result<Box<dyn FeedbackPolicy<T>>> {
        Ok(match self {
            Policy::Pid(p) => Box::new(pid_with(p, theta)?),
            Policy::StateFeedback(p) => Box::new(p.with_theta(theta)?),
            Policy::Rbf(p) => Box::new(p.with_theta(theta)?),
        })
    }

    /// The policy at its own parameters on scalar `T` (original units).
    pub fn lift<T: MomentMatch>(&self) -> Box<dyn FeedbackPolicy<T>> {
        match self {
            Policy::Pid(p) => Box::new(PidPolicy {
                kp: p.kp.map(c::<T>),
                ki: p.ki.map(c::<T>),
                kd: p.kd.map(c::<T>),
                period: p.period,
                u_max: p.u_max.clone(),
            }),
            Policy::StateFeedback(p) => Box::new(StateFeedback {
                gain: p.gain.map(c::<T>),
                offset: p.offset.map(c::<T>),
                output_lags: p.output_lags,
                input_lags: p.input_lags,
                bounds: p.bounds.clone(),
            }),
            Policy::Rbf(p) => Box::new(RbfPolicy {
                centres: p.centres.map(c::<T>),
                weights: p.weights.map(c::<T>),
                log_widths: p.log_widths.map(c::<T>),
                bounds: p.bounds.clone(),
            }),
        }
    }

    /// The command range.
    pub fn bounds(&self) -> CommandBounds {
        match self {
            // the PID's own limits (positive when made by `PidPolicy::new`)
            Policy::Pid(p) => CommandBounds {
                low: p.u_max.iter().map(|u| -u).collect(),
                high: p.u_max.clone(),
            },
            Policy::StateFeedback(p) => p.bounds.clone(),
            Policy::Rbf(p) => p.bounds.clone(),
        }
    }

    /// Size of the observation it acts on.
    pub fn observation_dim(&self) -> usize {
        match self {
            Policy::Pid(p) => p.kp.ncols(),
            Policy::StateFeedback(p) => p.dy(),
            Policy::Rbf(p) => p.centres.ncols(),
        }
    }

    /// Number of commands.
    pub fn command_dim(&self) -> usize {
        match self {
            Policy::Pid(p) => p.kp.nrows(),
            Policy::StateFeedback(p) => p.gain.nrows(),
            Policy::Rbf(p) => p.weights.ncols(),
        }
    }

    /// One step at a point: the command and the new state from the observation `y` and the
    /// previous state; an error when their sizes do not fit the policy.
    pub fn act(&self, y: &[f64], state: &[f64]) -> Result<(Vec<f64>, Vec<f64>)> {
        match self {
            Policy::Pid(p) => {
                let dy = p.kp.ncols();
                if y.len() != dy || state.len() != 2 * dy {
                    return Err(MsgpError::Shape(format!(
                        "PID policy expects an observation of size {dy} and a state of size {}, \
                         got {} and {}",
                        2 * dy,
                        y.len(),
                        state.len()
                    )));
                }
                Ok(p.act(y, state))
            }
            Policy::StateFeedback(p) => p.act(y, state),
            Policy::Rbf(p) => Ok((p.act(y)?, Vec::new())),
        }
    }

    /// The closed-form vector–Jacobian product of the moment map (original units) at
    /// `q ~ N(mean, cov)`, with `θ`'s adjoint in [`Policy::theta`]'s layout; `None` for a
    /// family without one (duals through [`FeedbackPolicy::moments`] then serve).
    pub(crate) fn moments_vjp(
        &self,
        mean: &DVector<f64>,
        cov: &DMatrix<f64>,
        mean_bar: &DVector<f64>,
        cov_bar: &DMatrix<f64>,
        c_bar: &DMatrix<f64>,
    ) -> Option<Result<ThetaVjp>> {
        match self {
            Policy::Pid(p) => Some(p.moments_vjp(mean, cov, mean_bar, cov_bar, c_bar).map(
                |(m, s, g)| {
                    let theta = g.kp.iter().chain(&g.ki).chain(&g.kd).copied().collect();
                    (m, s, theta)
                },
            )),
            Policy::Rbf(p) => Some(p.moments_vjp(mean, cov, mean_bar, cov_bar, c_bar)),
            Policy::StateFeedback(_) => None,
        }
    }

    /// Whether [`Policy::moments_vjp`] has a closed form.
    pub(crate) fn has_closed_form_vjp(&self) -> bool {
        !matches!(self, Policy::StateFeedback(_))
    }
}

/// A PID policy with gains `θ = [K_p; K_i; K_d]` (column-major) and `p`'s period and limits.
fn pid_with<T: Scalar>(p: &PidPolicy<f64>, theta: &[T]) -> Result<PidPolicy<T>> {
    let (du, dy) = p.kp.shape();
    let n = du * dy;
    if theta.len() != 3 * n {
        return Err(MsgpError::Shape(format!(
            "PID policy has {} gains, {} given",
            3 * n,
            theta.len()
        )));
    }
    Ok(PidPolicy {
        kp: DMatrix::from_column_slice(du, dy, &theta[..n]),
        ki: DMatrix::from_column_slice(du, dy, &theta[n..2 * n]),
        kd: DMatrix::from_column_slice(du, dy, &theta[2 * n..]),
        period: p.period,
        u_max: p.u_max.clone(),
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    fn families() -> Vec<Policy> {
        let pid = PidPolicy::new(
            DMatrix::from_row_slice(1, 2, &[1.0, 2.0]),
            DMatrix::from_row_slice(1, 2, &[0.0, 0.5]),
            DMatrix::from_row_slice(1, 2, &[0.1, 0.2]),
            0.05,
            vec![3.0],
        )
        .expect("pid");
        let bounds = CommandBounds::new(vec![-1.0, 0.0], vec![2.0, 5.0]).expect("bounds");
        let sf = StateFeedback::new(
            DMatrix::from_fn(2, 4, |i, j| 0.1 * (i + 2 * j) as f64 - 0.3),
            DVector::from_vec(vec![0.2, -0.1]),
            1,
            (2, 1),
            bounds.clone(),
        )
        .expect("state feedback");
        let rbf = RbfPolicy::new(
            DMatrix::from_fn(3, 1, |i, _| i as f64 - 1.0),
            DMatrix::from_fn(3, 2, |i, j| 0.5 * (i as f64) - j as f64),
            DVector::from_vec(vec![-0.2]),
            bounds,
        )
        .expect("rbf");
        vec![
            Policy::Pid(pid),
            Policy::StateFeedback(sf),
            Policy::Rbf(rbf),
        ]
    }

    /// `θ` round-trips, a wrong length is refused, commands stay in bounds, and the lifted
    /// policy's moments at a point (zero covariance) are the point action.
    #[test]
    fn every_family_round_trips_its_parameters_and_acts_as_its_moments_say() {
        for p in families() {
            let theta = p.theta();
            assert_eq!(theta.len(), p.param_len(), "{}", p.kind());
            assert_eq!(p.with_theta(&theta).expect("same θ"), p);
            assert!(p.with_theta(&theta[1..]).is_err(), "{}", p.kind());
            let lifted = p.lift::<f64>();
            let dy = match &p {
                Policy::Rbf(_) => 1,
                Policy::StateFeedback(_) => 1,
                Policy::Pid(_) => 2,
            };
            let nq = dy + lifted.state_dim();
            let q: Vec<f64> = (0..nq).map(|k| 0.7 * k as f64 - 0.4).collect();
            let (u, state) = p.act(&q[..dy], &q[dy..]).expect("act");
            let longer: Vec<f64> = q[..dy].iter().chain(&[0.5]).copied().collect();
            assert!(
                p.act(&longer, &q[dy..]).is_err(),
                "{}: a wrong size",
                p.kind()
            );
            let pm = lifted
                .moments(&DVector::from_vec(q.clone()), &DMatrix::zeros(nq, nq))
                .expect("moments");
            let point: Vec<f64> = u.iter().chain(&state).copied().collect();
            assert_eq!(point.len(), pm.mean.len(), "{}", p.kind());
            for (a, b) in point.iter().zip(pm.mean.iter()) {
                assert!(
                    (a - b).abs() < 1e-12,
                    "{}: {point:?} vs {}",
                    p.kind(),
                    pm.mean
                );
            }
            let b = p.bounds();
            for (k, uk) in u.iter().enumerate() {
                assert!(*uk >= b.low[k] && *uk <= b.high[k], "{}: {u:?}", p.kind());
            }
        }
    }
}
