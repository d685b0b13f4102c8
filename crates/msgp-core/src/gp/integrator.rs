//! Integrating outputs: structure of the plant known before any data.
//!
//! An output is *integrating of order `k`* when the rest of the system drives its `k`-th
//! difference, not its level: a position under a commanded acceleration (`k = 2`), a tank level
//! under a flow (`k = 1`). Its next sample is then
//! `y_{t+1} = Σ_{i<k} (−1)^i C(k, i+1) y_{t−i} + (what drives the k-th difference)`,
//! i.e. `y_t + …` for `k = 1` and `2 y_t − y_{t−1} + …` for `k = 2`.
//!
//! The declaration is of a *pure* integrator: the output's lags drive nothing but its own
//! difference equation (the plant is invariant to shifts of the output's level and, for
//! `k = 2`, of its rate, like a robot's end-effector position under a commanded acceleration).
//! On a model with the linear prior mean ([`MeanFunction::Linear`]) this fixes:
//! - the output's row of `A`: the coefficients above on its own lags (zero beyond the `k`-th);
//! - every other row of `A`: zero on the output's lags;
//! - the GP: its length-scales on the output's lags are [`IGNORED_LENGTHSCALE`] (the kernel does
//!   not vary along them) and stay fixed; the pseudo-inputs sit at zero in those coordinates.
//!
//! The instrumental-variables start and the MSGP fit learn the rest. A few episodes of a slowly
//! drifting integrator do not identify it: fitted freely, the pendulum's end-effector row comes
//! out as a damped `1.78 x_t − 0.79 x_{t−1}`, the pole's row leans on the end-effector velocity
//! as a stand-in for its acceleration, and no policy search on such a model learns a position
//! loop (docs/design.md).

use serde::{Deserialize, Serialize};

use crate::error::{MsgpError, Result};
use crate::gp::MeanFunction;
use crate::narx::NarxSpec;

/// Output `output` (0-based column of `y`) is an `order`-fold discrete integral.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Integrator {
    /// Output column.
    pub output: usize,
    /// Number of integrations, `1 ≤ order ≤ l_y`.
    pub order: usize,
    /// *Kinematic*: the `order`-th difference is a linear function of the inputs alone (a robot's
    /// end effector, whose acceleration follows the command through a linear actuator whatever
    /// the load does). The output's row of `A` is zero on every output lag except its own
    /// integrator coefficients, and it gets no GP: only its input coefficients and its noise are
    /// fitted. In closed loop the inputs are a function of the outputs, and a free row explains
    /// the end effector's acceleration by the pole's velocity instead of the command.
    #[serde(default)]
    pub linear: bool,
}

/// One frozen coefficient of the linear prior mean: `A[row, col] = value`.
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct FixedCoefficient {
    /// Output (row of `A`).
    pub row: usize,
    /// Window index (column of `A`).
    pub col: usize,
    /// Its value.
    pub value: f64,
}

/// Length-scale (normalised units) on the lags of an integrating output: the kernel changes by
/// less than `5e-5` across ten standard deviations of the data.
pub const IGNORED_LENGTHSCALE: f64 = 1e3;

/// Signal variance (normalised units) of an output declared [`Integrator::linear`]: with zero
/// pseudo-targets its GP adds a variance of at most this per step.
pub const NO_GP_SIGNAL_VAR: f64 = 1e-12;

/// What a set of integrators fixes in a model: coefficients of `A` and GP inputs.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct Structure {
    /// Frozen coefficients of the linear prior mean.
    pub fixed: Vec<FixedCoefficient>,
    /// Window indices the GP ignores (length-scale [`IGNORED_LENGTHSCALE`], frozen).
    pub ignored: Vec<usize>,
    /// Outputs without a GP: pseudo-targets 0 and signal variance [`NO_GP_SIGNAL_VAR`], frozen.
    pub without_gp: Vec<usize>,
}

impl Structure {
    /// The structure `integrators` imply for `spec`.
    pub fn new(integrators: &[Integrator], spec: &NarxSpec) -> Self {
        let mut fixed = Vec::new();
        let mut ignored = Vec::new();
        let mut without_gp = Vec::new();
        for i in integrators {
            if i.linear {
                without_gp.push(i.output);
                // the kinematic row: zero on the other outputs' lags (its own follow)
                for lag in 0..spec.ly {
                    for j in (0..spec.dy).filter(|&j| j != i.output) {
                        fixed.push(FixedCoefficient {
                            row: i.output,
                            col: spec.y_index(lag, j),
                            value: 0.0,
                        });
                    }
                }
            }
            for lag in 0..spec.ly {
                let col = spec.y_index(lag, i.output);
                ignored.push(col);
                for row in 0..spec.dy {
                    let value = if row != i.output || lag >= i.order {
                        0.0
                    } else if lag % 2 == 0 {
                        binomial(i.order, lag + 1)
                    } else {
                        -binomial(i.order, lag + 1)
                    };
                    fixed.push(FixedCoefficient { row, col, value });
                }
            }
        }
        ignored.sort_unstable();
        without_gp.sort_unstable();
        Self {
            fixed,
            ignored,
            without_gp,
        }
    }
}

fn binomial(n: usize, k: usize) -> f64 {
    (0..k).fold(1.0, |acc, i| acc * (n - i) as f64 / (i + 1) as f64)
}

/// Checks `integrators` against the model: a linear prior mean, existing outputs, each declared
/// once, `1 ≤ order ≤ l_y`.
pub fn validate(integrators: &[Integrator], spec: &NarxSpec, mean: MeanFunction) -> Result<()> {
    let invalid = |reason: String| MsgpError::InvalidSetting {
        name: "integrators",
        reason,
    };
    if !integrators.is_empty() && mean != MeanFunction::Linear {
        return Err(invalid(
            "an integrating output fixes coefficients of the linear prior mean; use the linear mean"
                .into(),
        ));
    }
    for (k, i) in integrators.iter().enumerate() {
        if i.output >= spec.dy {
            return Err(invalid(format!(
                "output {} does not exist (the data have {} outputs)",
                i.output, spec.dy
            )));
        }
        if i.order == 0 || i.order > spec.ly {
            return Err(invalid(format!(
                "output {}: order {} must be between 1 and l_y = {}",
                i.output, i.order, spec.ly
            )));
        }
        if integrators[..k].iter().any(|j| j.output == i.output) {
            return Err(invalid(format!("output {} is declared twice", i.output)));
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    fn spec(ly: usize) -> NarxSpec {
        NarxSpec {
            ly,
            lu: 2,
            dy: 2,
            du: 1,
        }
    }

    #[test]
    fn coefficients_are_the_differences_of_the_order() {
        let s = spec(3);
        let own = |order| -> Vec<f64> {
            Structure::new(
                &[Integrator {
                    output: 1,
                    order,
                    linear: false,
                }],
                &s,
            )
            .fixed
            .iter()
            .filter(|c| c.row == 1)
            .map(|c| c.value)
            .collect()
        };
        assert_eq!(own(1), vec![1.0, 0.0, 0.0]);
        assert_eq!(own(2), vec![2.0, -1.0, 0.0]);
        assert_eq!(own(3), vec![3.0, -3.0, 1.0]);
        // the other output's row is zero on the integrator's lags, and the GP ignores them
        let st = Structure::new(
            &[Integrator {
                output: 1,
                order: 2,
                linear: false,
            }],
            &s,
        );
        let lags: Vec<usize> = (0..3).map(|k| s.y_index(k, 1)).collect();
        assert_eq!(st.ignored, lags);
        let other: Vec<(usize, f64)> = st
            .fixed
            .iter()
            .filter(|c| c.row == 0)
            .map(|c| (c.col, c.value))
            .collect();
        assert_eq!(other, lags.iter().map(|&c| (c, 0.0)).collect::<Vec<_>>());
        assert_eq!(st.fixed.len(), 6);
        assert!(st.without_gp.is_empty());
        // kinematic: also zero on the other output's lags in its own row, and no GP
        let k = Structure::new(
            &[Integrator {
                output: 1,
                order: 2,
                linear: true,
            }],
            &s,
        );
        assert_eq!(k.without_gp, vec![1]);
        for lag in 0..3 {
            let c = s.y_index(lag, 0);
            assert!(
                k.fixed
                    .iter()
                    .any(|f| f.row == 1 && f.col == c && f.value == 0.0)
            );
        }
        assert_eq!(k.fixed.len(), 9);
        // the order-k recursion continues every polynomial of degree k − 1 exactly
        let poly = |order: usize, t: f64| {
            (0..order)
                .map(|p| (p as f64 + 0.7) * t.powi(p as i32))
                .sum::<f64>()
        };
        for order in 1..=3usize {
            let next: f64 = (0..3)
                .map(|lag| own(order)[lag] * poly(order, -(lag as f64)))
                .sum();
            assert!(
                (next - poly(order, 1.0)).abs() < 1e-12,
                "order {order}: {next}"
            );
        }
    }

    #[test]
    fn bad_declarations_are_rejected() {
        let s = spec(2);
        let one = |output, order| {
            vec![Integrator {
                output,
                order,
                linear: false,
            }]
        };
        assert!(validate(&one(1, 2), &s, MeanFunction::Linear).is_ok());
        assert!(validate(&one(1, 2), &s, MeanFunction::Zero).is_err());
        assert!(validate(&one(2, 1), &s, MeanFunction::Linear).is_err());
        assert!(validate(&one(0, 3), &s, MeanFunction::Linear).is_err());
        assert!(validate(&one(0, 0), &s, MeanFunction::Linear).is_err());
        let twice = vec![
            Integrator {
                output: 0,
                order: 1,
                linear: false,
            },
            Integrator {
                output: 0,
                order: 2,
                linear: true,
            },
        ];
        assert!(validate(&twice, &s, MeanFunction::Linear).is_err());
    }
}
