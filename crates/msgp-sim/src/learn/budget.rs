//! A learning run's budget: the options `msgp learn-policy`, `msgp reproduce figure4` and the
//! Python sweep share (episodes, solver iterations, model size, search effort, cost widths and
//! the pendulum's cost widths), checked and turned into [`LearnSettings`] in one place
//! ([`Budget::settings`]). The experiment switches the loop once carried (`--experimental`:
//! start smoothing, feedback segments, a free end effector, the excitation band, random
//! policies, the trust region, the fit's solver, a hold margin, the prequential choice, the
//! one-step solver and objective) are gone; `docs/design.md` records what each showed.

use serde::{Deserialize, Serialize};

use msgp_core::MsgpError;
use msgp_core::fit::{FitSettings, Overrides};
use msgp_core::gp::MeanFunction;
use msgp_core::loss::Likelihood;
use msgp_core::model::Method;
use msgp_core::numeric::parallel::Threads;
use msgp_core::policy_search::PolicySearchSettings;

use super::settings::LearnSettings;
use crate::error::SimError;

/// What a learning run may spend, as its user states it; `None` fields take the model's own
/// default ([`LearnSettings::for_model`]). The defaults are the command line's.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(default, deny_unknown_fields)]
pub struct Budget {
    /// Likelihood of the MSGP fits (`None`: the loop's default, the filter likelihood).
    pub likelihood: Option<Likelihood>,
    /// Random episodes before the first policy.
    pub random_rollouts: usize,
    /// Length of every interaction episode \[s\].
    pub episode_seconds: f64,
    /// Solver iterations of each model fit (`None`: the model's default).
    pub fit_iters: Option<usize>,
    /// From the second iteration on, continue the previous model for this many solver
    /// iterations; 0: always from scratch (`None`: the model's default).
    pub warm_start: Option<usize>,
    /// Pseudo-inputs of a GP model (`None`: the model's default; linear-kf has no GP).
    pub inducing: Option<usize>,
    /// Adam steps of each policy optimisation start (`None`: the model's default).
    pub search_iters: Option<usize>,
    /// Random gain candidates screened on the model before each policy optimisation.
    pub candidates: usize,
    /// Prior mean of a GP model (a linear-kf model is its linear mean).
    pub mean: MeanFunction,
    /// Horizon of the predicted rollouts the gains are optimised on \[s\] (`None`: the
    /// model's default).
    pub policy_horizon: Option<f64>,
    /// Widths of the saturating cost on the pole angle \[rad\] and the end-effector position
    /// \[m\] (two values).
    pub cost_widths: Vec<f64>,
}

impl Default for Budget {
    fn default() -> Self {
        let d = LearnSettings::default();
        Budget {
            likelihood: None,
            random_rollouts: d.random_rollouts,
            episode_seconds: d.episode_seconds,
            fit_iters: None,
            warm_start: None,
            inducing: None,
            search_iters: None,
            candidates: d.search.candidates,
            mean: MeanFunction::Linear,
            policy_horizon: None,
            cost_widths: d.cost_widths.to_vec(),
        }
    }
}

/// A setting the fit's resolver refused, named as the budget's option.
fn flagged(e: MsgpError) -> SimError {
    match e {
        MsgpError::InvalidSetting { name, reason } => invalid(
            match name {
                "iterations" => "fit-iters",
                other => other,
            },
            reason,
        ),
        other => other.into(),
    }
}

/// A budget's option out of range.
fn invalid(option: &str, reason: impl Into<String>) -> SimError {
    SimError::Budget {
        option: option.to_string(),
        reason: reason.into(),
    }
}

impl Budget {
    /// The loop's settings for `method` under this budget: seed `seed`, `iterations` policy
    /// iterations, threads from `MSGP_THREADS` (results do not depend on them). Every option
    /// is checked here.
    pub fn settings(
        &self,
        method: Method,
        seed: u64,
        iterations: usize,
    ) -> Result<LearnSettings, SimError> {
        if !(self.episode_seconds.is_finite() && self.episode_seconds > 0.0) {
            return Err(invalid(
                "episode-seconds",
                format!("must be positive, got {}", self.episode_seconds),
            ));
        }
        if let Some(h) = self.policy_horizon
            && !(h.is_finite() && h > 0.0 && h <= 600.0)
        {
            return Err(invalid(
                "policy-horizon",
                format!("must be in (0, 600] seconds, got {h}"),
            ));
        }
        let cost_widths: [f64; 2] = match self.cost_widths.as_slice() {
            [w_theta, w_x] if [w_theta, w_x].iter().all(|w| w.is_finite() && **w > 0.0) => {
                [*w_theta, *w_x]
            }
            other => {
                return Err(invalid(
                    "cost-widths",
                    format!(
                        "needs two positive widths (angle in rad, position in m), got {other:?}"
                    ),
                ));
            }
        };
        if self.random_rollouts == 0 {
            return Err(invalid(
                "random-rollouts",
                "must be at least 1 (the first model needs data)",
            ));
        }
        let d = LearnSettings::for_model(method, self.likelihood);
        let threads = Threads::from_env()?;
        let base = FitSettings {
            // the end effector integrates the command only under a linear mean (a linear-kf
            // model is one)
            integrators: match (method, self.mean) {
                (Method::LinearKf, _) | (_, MeanFunction::Linear) => d.fit.integrators.clone(),
                (_, MeanFunction::Zero) => Vec::new(),
            },
            threads,
            ..d.fit.clone()
        };
        // one budget serves every model of a table: its GP's size and mean are the GP models'
        // (a linear-kf model has no GP and is its linear mean)
        let gp = method != Method::LinearKf;
        let fit = Overrides {
            iterations: self.fit_iters,
            inducing: self.inducing.filter(|_| gp),
            mean: Some(self.mean).filter(|_| gp),
            likelihood: self.likelihood,
            ..Overrides::default()
        }
        .apply(base)
        .map_err(flagged)?;
        Ok(LearnSettings {
            iterations,
            random_rollouts: self.random_rollouts,
            episode_seconds: self.episode_seconds,
            policy_horizon_seconds: self.policy_horizon.unwrap_or(d.policy_horizon_seconds),
            cost_widths,
            seed,
            fit,
            warm_start: match self.warm_start {
                None => d.warm_start,
                Some(0) => None,
                Some(n) => Some(n),
            },
            search: PolicySearchSettings {
                iterations: self.search_iters.unwrap_or(d.search.iterations),
                candidates: self.candidates,
                threads,
                ..d.search
            },
            ..d
        })
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn the_default_budget_gives_the_loops_defaults() {
        for (method, likelihood) in [
            (Method::Msgp, None),
            (Method::Msgp, Some(Likelihood::FreeRun)),
            (Method::GpNarx, None),
            (Method::LinearKf, None),
        ] {
            let budget = Budget {
                likelihood,
                ..Budget::default()
            };
            let s = budget.settings(method, 3, 8).expect("valid budget");
            let d = LearnSettings::for_model(method, likelihood);
            assert_eq!(s.seed, 3);
            assert_eq!(s.iterations, 8);
            assert_eq!(s.fit, d.fit, "{method:?}");
            assert_eq!(s.warm_start, d.warm_start);
            assert_eq!(s.policy_horizon_seconds, d.policy_horizon_seconds);
            assert_eq!(s.search, d.search);
        }
    }

    #[test]
    fn options_out_of_range_name_the_option() {
        let cases: [(Budget, Method, &str); 6] = [
            (
                Budget {
                    episode_seconds: -1.0,
                    ..Budget::default()
                },
                Method::Msgp,
                "episode-seconds: must be positive",
            ),
            (
                Budget {
                    cost_widths: vec![0.1],
                    ..Budget::default()
                },
                Method::Msgp,
                "cost-widths: needs two positive widths",
            ),
            (
                Budget {
                    likelihood: Some(Likelihood::Filter),
                    ..Budget::default()
                },
                Method::GpNarx,
                "likelihood: filter: the likelihood of an MSGP fit",
            ),
            (
                Budget {
                    random_rollouts: 0,
                    ..Budget::default()
                },
                Method::Msgp,
                "random-rollouts: must be at least 1",
            ),
            // the fit's own options, refused by the fit's resolver and named as the budget's
            (
                Budget {
                    inducing: Some(0),
                    ..Budget::default()
                },
                Method::Msgp,
                "inducing: need at least one pseudo-input",
            ),
            (
                Budget {
                    likelihood: Some(Likelihood::FreeRun),
                    ..Budget::default()
                },
                Method::LinearKf,
                "likelihood: free-run: the likelihood of an MSGP fit",
            ),
        ];
        for (budget, method, expected) in cases {
            let e = budget
                .settings(method, 0, 1)
                .expect_err("out of range")
                .to_string();
            assert!(e.contains(expected), "{e:?} lacks {expected:?}");
        }
    }

    /// One budget serves every model of a table: its pseudo-inputs and mean reach the GP
    /// models and pass over linear-kf, which has no GP.
    #[test]
    fn a_budgets_gp_options_are_the_gp_models() {
        let budget = Budget {
            inducing: Some(12),
            mean: MeanFunction::Zero,
            ..Budget::default()
        };
        let kf = budget.settings(Method::LinearKf, 0, 1).expect("linear-kf");
        assert_eq!(kf.fit, LearnSettings::for_model(Method::LinearKf, None).fit);
        for method in [Method::Msgp, Method::GpNarx] {
            let s = budget.settings(method, 0, 1).expect("a GP model");
            assert_eq!(s.fit.inducing(), Some(12));
            assert_eq!(s.fit.mean(), MeanFunction::Zero);
            assert!(s.fit.integrators.is_empty(), "{method:?}");
        }
    }

    #[test]
    fn a_budget_reads_from_partial_json_and_refuses_unknown_options() {
        let budget: Budget =
            serde_json::from_str(r#"{"episode_seconds": 2.0}"#).expect("a partial budget reads");
        assert_eq!(budget.episode_seconds, 2.0);
        assert_eq!(budget.inducing, None);
        assert!(serde_json::from_str::<Budget>(r#"{"episodes": 2}"#).is_err());
        // the switches are gone: a budget that names one is refused
        assert!(
            serde_json::from_str::<Budget>(r#"{"experimental": [{"trust-region": 0.5}]}"#).is_err()
        );
    }
}
