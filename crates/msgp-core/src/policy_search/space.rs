//! What a policy search moves: a [`Policy`] and which entries of its parameter vector `θ`
//! are free. The search works on the packed free entries `x`; everything else stays at the
//! policy's values.

use nalgebra::DMatrix;

use crate::error::{MsgpError, Result};
use crate::moments::MomentMatch;
use crate::numeric::scalar::{Scalar, c};
use crate::policy::{FeedbackPolicy, PidPolicy, Policy};

/// A policy and its free parameters.
#[derive(Clone, Debug, PartialEq)]
pub struct SearchSpace {
    /// The policy whose fixed parameters stay.
    pub base: Policy,
    /// One flag per entry of `base.theta()`: free or fixed.
    pub free: Vec<bool>,
}

impl SearchSpace {
    /// Every parameter of `base` free.
    pub fn all(base: Policy) -> Self {
        let free = vec![true; base.param_len()];
        Self { base, free }
    }

    /// A PID policy with the gains `mask` frees.
    pub fn pid(initial: &PidPolicy<f64>, mask: &PidMask) -> Self {
        let free = [&mask.kp, &mask.ki, &mask.kd]
            .iter()
            .flat_map(|m| m.iter().copied())
            .collect();
        Self {
            base: Policy::Pid(initial.clone()),
            free,
        }
    }

    /// Checks that the flags fit the policy and free at least one parameter.
    pub fn validate(&self) -> Result<()> {
        if self.free.len() != self.base.param_len() {
            return Err(MsgpError::Shape(format!(
                "{} free flags for a {} policy of {} parameters",
                self.free.len(),
                self.base.kind(),
                self.base.param_len()
            )));
        }
        if self.is_empty() {
            return Err(MsgpError::InvalidSetting {
                name: "policy search",
                reason: "no free parameters".into(),
            });
        }
        Ok(())
    }

    /// Number of free parameters.
    pub fn len(&self) -> usize {
        self.free.iter().filter(|f| **f).count()
    }

    /// True when nothing is free.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The free entries of a full parameter vector (or of its adjoint), in order.
    pub fn pack(&self, full: &[f64]) -> Vec<f64> {
        full.iter()
            .zip(&self.free)
            .filter(|(_, f)| **f)
            .map(|(v, _)| *v)
            .collect()
    }

    /// The base's free parameters.
    pub fn start(&self) -> Vec<f64> {
        self.pack(&self.base.theta())
    }

    /// The full parameter vector on scalar `T` with the free entries from `x`.
    fn full<T: Scalar>(&self, x: &[T]) -> Result<Vec<T>> {
        if x.len() != self.len() {
            return Err(MsgpError::Shape(format!(
                "{} parameters given, the search frees {}",
                x.len(),
                self.len()
            )));
        }
        let mut k = 0;
        Ok(self
            .base
            .theta()
            .into_iter()
            .zip(&self.free)
            .map(|(v, f)| {
                if *f {
                    k += 1;
                    x[k - 1]
                } else {
                    c::<T>(v)
                }
            })
            .collect())
    }

    /// The policy (as data) with free parameters `x`.
    pub fn controller(&self, x: &[f64]) -> Result<Policy> {
        self.base.with_theta(&self.full(x)?)
    }

    /// The policy with free parameters `x` on scalar `T` (original units).
    pub fn policy<T: MomentMatch>(&self, x: &[T]) -> Result<Box<dyn FeedbackPolicy<T>>> {
        self.base.lift_theta(&self.full(x)?)
    }
}

/// Which PID gains are optimised: `true` entries of the three d_u × d_y masks are free.
#[derive(Clone, Debug, PartialEq)]
pub struct PidMask {
    /// Free entries of `K_p`.
    pub kp: DMatrix<bool>,
    /// Free entries of `K_i`.
    pub ki: DMatrix<bool>,
    /// Free entries of `K_d`.
    pub kd: DMatrix<bool>,
}

impl PidMask {
    /// Number of free gains.
    pub fn len(&self) -> usize {
        [&self.kp, &self.ki, &self.kd]
            .iter()
            .map(|m| m.iter().filter(|b| **b).count())
            .sum()
    }

    /// True when nothing is free.
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }

    /// The free gains of `p` as a vector (K_p, then K_i, then K_d; column-major).
    pub fn pack(&self, p: &PidPolicy<f64>) -> Vec<f64> {
        self.pack_matrices(&p.kp, &p.ki, &p.kd)
    }

    /// The free entries of three d_u × d_y matrices (gains or their adjoints), in
    /// [`PidMask::pack`]'s order.
    fn pack_matrices(&self, kp: &DMatrix<f64>, ki: &DMatrix<f64>, kd: &DMatrix<f64>) -> Vec<f64> {
        let mut v = Vec::new();
        for (m, g) in [(&self.kp, kp), (&self.ki, ki), (&self.kd, kd)] {
            v.extend(m.iter().zip(g.iter()).filter(|(b, _)| **b).map(|(_, x)| *x));
        }
        v
    }

    /// `base` with its free gains replaced by `x`.
    pub fn unpack<T: Scalar>(&self, base: &PidPolicy<f64>, x: &[T]) -> PidPolicy<T> {
        let mut k = 0;
        let mut fill = |m: &DMatrix<bool>, g: &DMatrix<f64>| {
            DMatrix::from_fn(g.nrows(), g.ncols(), |i, j| {
                if m[(i, j)] {
                    k += 1;
                    x[k - 1]
                } else {
                    c::<T>(g[(i, j)])
                }
            })
        };
        let kp = fill(&self.kp, &base.kp);
        let ki = fill(&self.ki, &base.ki);
        let kd = fill(&self.kd, &base.kd);
        PidPolicy {
            kp,
            ki,
            kd,
            period: base.period,
            u_max: base.u_max.clone(),
        }
    }
}
