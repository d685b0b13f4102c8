//! A learning run's budget: the options `msgp learn-policy`, `msgp reproduce figure4` and the
//! Python sweep share (episodes, solver iterations, model size, search effort, cost widths and
//! the pendulum's cost widths), checked and turned into [`LearnSettings`] in one place
//! ([`Budget::settings`]). The experiment switches the loop once carried (`--experimental`:
//! start smoothing, feedback segments, a free end effector, the excitation band, random
//! policies, the trust region, the fit's solver, a hold margin, the prequential choice, the
//! one-step solver and objective) are gone; `docs/design.md` records what each showed.

use serde::{Deserialize, Serialize};

use msgp_core::fit::{FitSettings, MethodSettings};
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
    /// Pseudo-inputs of the model (`None`: the model's default).
    pub inducing: Option<usize>,
    /// Adam steps of each policy optimisation start (`None`: the model's default).
    pub search_iters: Option<usize>,
    /// Random gain candidates screened on the model before each policy optimisation.
    pub candidates: usize,
    /// Prior mean of the GP model.
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
        if self.inducing == Some(0) {
            return Err(invalid("inducing", "must be at least 1"));
        }
        if let (Some(l), false) = (self.likelihood, method == Method::Msgp) {
            return Err(invalid(
                "likelihood",
                format!(
                    "{}: the likelihood of an MSGP fit; the {} model has its own",
                    l.name(),
                    method.name()
                ),
            ));
        }
        let d = LearnSettings::for_model(method, self.likelihood);
        let threads = Threads::from_env()?;
        let fit = FitSettings {
            // a linear-kf model has the linear mean whatever `mean` says
            integrators: match (method, self.mean) {
                (Method::LinearKf, _) | (_, MeanFunction::Linear) => d.fit.integrators.clone(),
                _ => Vec::new(),
            },
            threads,
            ..d.fit.clone()
        };
        let mut fit = match self.inducing {
            Some(m) => fit.with_inducing(m),
            None => fit,
        };
        match &mut fit.method {
            MethodSettings::Msgp(s) => {
                s.mean = self.mean;
                if let Some(l) = self.likelihood {
                    s.likelihood = l;
                }
            }
            MethodSettings::GpNarx(s) | MethodSettings::PilcoNarx(s) => s.mean = self.mean,
            MethodSettings::LinearKf(_) => {}
        }
        let fit = match self.fit_iters {
            Some(n) => fit.with_solver_iterations(n),
            None => fit,
        };
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
        let cases: [(Budget, Method, &str); 4] = [
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
        ];
        for (budget, method, expected) in cases {
            let e = budget
                .settings(method, 0, 1)
                .expect_err("out of range")
                .to_string();
            assert!(e.contains(expected), "{e:?} lacks {expected:?}");
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
