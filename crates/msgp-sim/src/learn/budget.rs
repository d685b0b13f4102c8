//! A learning run's budget: the options `msgp learn-policy`, `msgp reproduce figure4` and the
//! Python sweep share (episodes, solver iterations, model size, search effort, cost widths and
//! the experiment switches of `docs/design.md`), checked and turned into [`LearnSettings`] in
//! one place ([`Budget::settings`]).

use serde::{Deserialize, Serialize};

use msgp_core::fit::{FitOptimizer, FitSettings, MethodSettings, OneStepObjective, OneStepSolver};
use msgp_core::gp::MeanFunction;
use msgp_core::loss::Likelihood;
use msgp_core::model::Method;
use msgp_core::narx::start_window::StartWindow;
use msgp_core::numeric::parallel::Threads;
use msgp_core::policy_search::PolicySearchSettings;

use super::settings::LearnSettings;
use crate::error::SimError;

/// One experiment switch of the learning loop (`--experimental KEY=VALUE`): a setting that the
/// experiments of `docs/design.md` varied, not an option the loop needs. Serialised as
/// `{"key": value}` with the command line's keys.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Experiment {
    /// `start-smoothing=N` (MSGP): start each training rollout from a quadratic fitted to its
    /// first N samples; 0: the measured window.
    StartSmoothing(usize),
    /// `fb-segment=N` (MSGP): feedback episodes enter the loss as overlapping segments of N
    /// samples; 0: whole.
    FbSegment(usize),
    /// `free-position=true|false`: do not declare the end effector a double integrator of the
    /// command.
    FreePosition(bool),
    /// `excitation-max-hz=HZ`: highest frequency of the random excitation.
    ExcitationMaxHz(f64),
    /// `random-policies=K`: K of the random rollouts run random PID + PD gains.
    RandomPolicies(usize),
    /// `trust-region=R`: no gain moves further than R typical magnitudes per search; 0: off.
    TrustRegion(f64),
    /// `fit-optimizer=adam|lbfgs` (MSGP): the solver of each fit.
    FitOptimizer(FitOptimizer),
    /// `hold-margin=K`: the search's gains replace the running ones only when predicted to
    /// pay by K standard deviations of their predicted cost; 0: always.
    HoldMargin(f64),
    /// `prequential=true|false` (MSGP): the search runs on the GP model only while its
    /// predictions of the episodes it had not seen beat the linear model's
    /// ([`LearnSettings::prequential_choice`]).
    Prequential(bool),
    /// `one-step-solver=adam|lbfgs` (GP models): how the one-step marginal likelihood is
    /// minimised — GP-NARX's whole fit, the free-run MSGP's start ([`OneStepSolver`]); the
    /// filtered MSGP starts from the linear-kf model and has no one-step fit to change.
    OneStepSolver(OneStepSolver),
    /// `one-step-objective=exact|vfe` (GP models): the one-step fit's likelihood — the exact
    /// GP's marginal likelihood on at most 1000 pairs, or Titsias' bound with the pseudo-inputs
    /// ([`OneStepObjective`]).
    OneStepObjective(OneStepObjective),
}

/// The keys of [`Experiment`], as written on the command line.
pub const EXPERIMENT_KEYS: [&str; 11] = [
    "start-smoothing",
    "fb-segment",
    "free-position",
    "excitation-max-hz",
    "random-policies",
    "trust-region",
    "fit-optimizer",
    "hold-margin",
    "prequential",
    "one-step-solver",
    "one-step-objective",
];

impl Experiment {
    /// The switch's key, as written on the command line.
    pub fn key(&self) -> &'static str {
        EXPERIMENT_KEYS[match self {
            Experiment::StartSmoothing(_) => 0,
            Experiment::FbSegment(_) => 1,
            Experiment::FreePosition(_) => 2,
            Experiment::ExcitationMaxHz(_) => 3,
            Experiment::RandomPolicies(_) => 4,
            Experiment::TrustRegion(_) => 5,
            Experiment::FitOptimizer(_) => 6,
            Experiment::HoldMargin(_) => 7,
            Experiment::Prequential(_) => 8,
            Experiment::OneStepSolver(_) => 9,
            Experiment::OneStepObjective(_) => 10,
        }]
    }

    /// `KEY=VALUE` as a switch; the value's syntax is checked here, its range by
    /// [`Budget::settings`].
    pub fn parse(s: &str) -> Result<Experiment, String> {
        let (key, value) = s
            .split_once('=')
            .ok_or_else(|| format!("expected KEY=VALUE, got `{s}`"))?;
        let (key, value) = (key.trim(), value.trim());
        let count = || {
            value
                .parse::<usize>()
                .map_err(|_| format!("{key} needs a count, got `{value}`"))
        };
        let number = || {
            value
                .parse::<f64>()
                .map_err(|_| format!("{key} needs a number, got `{value}`"))
        };
        let flag = || {
            value
                .parse::<bool>()
                .map_err(|_| format!("{key} is true or false, got `{value}`"))
        };
        // the two solver switches' values; true: adam
        let adam_or_lbfgs = || match value.to_ascii_lowercase().as_str() {
            "adam" => Ok(true),
            "lbfgs" => Ok(false),
            _ => Err(format!("{key} is adam or lbfgs, got `{value}`")),
        };
        Ok(match key {
            "start-smoothing" => Experiment::StartSmoothing(count()?),
            "fb-segment" => Experiment::FbSegment(count()?),
            "free-position" => Experiment::FreePosition(flag()?),
            "prequential" => Experiment::Prequential(flag()?),
            "excitation-max-hz" => Experiment::ExcitationMaxHz(number()?),
            "random-policies" => Experiment::RandomPolicies(count()?),
            "trust-region" => Experiment::TrustRegion(number()?),
            "hold-margin" => Experiment::HoldMargin(number()?),
            "fit-optimizer" => Experiment::FitOptimizer(match adam_or_lbfgs()? {
                true => FitOptimizer::Adam,
                false => FitOptimizer::Lbfgs,
            }),
            "one-step-solver" => Experiment::OneStepSolver(match adam_or_lbfgs()? {
                true => OneStepSolver::Adam,
                false => OneStepSolver::Lbfgs,
            }),
            "one-step-objective" => {
                Experiment::OneStepObjective(match value.to_ascii_lowercase().as_str() {
                    "exact" => OneStepObjective::Exact,
                    "vfe" => OneStepObjective::Vfe,
                    _ => return Err(format!("{key} is exact or vfe, got `{value}`")),
                })
            }
            other => {
                return Err(format!(
                    "unknown experiment `{other}` (known: {})",
                    EXPERIMENT_KEYS.join(", ")
                ));
            }
        })
    }
}

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
    /// Experiment switches, applied in order.
    pub experimental: Vec<Experiment>,
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
            experimental: Vec::new(),
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
        // the experiment switches, each at the loop's default unless set
        let msgp_defaults = d.fit.msgp().cloned().unwrap_or_default();
        let mut start_smoothing = match msgp_defaults.start_window {
            StartWindow::Smoothed { samples, .. } => samples,
            StartWindow::Measured => 0,
        };
        let mut fb_segment = d.fb_segment.unwrap_or(0);
        let mut free_position = false;
        let mut excitation = d.excitation;
        let mut random_policies = d.random_policies;
        let mut trust_region = d.search.trust_region;
        let mut optimizer = msgp_defaults.optimizer;
        let mut hold_margin = d.hold_margin;
        let mut prequential_choice = d.prequential_choice;
        let mut one_step_solver = None;
        let mut one_step_objective = None;
        for e in &self.experimental {
            if matches!(
                e,
                Experiment::StartSmoothing(_)
                    | Experiment::FitOptimizer(_)
                    | Experiment::Prequential(true)
            ) && method != Method::Msgp
                || matches!(
                    e,
                    Experiment::OneStepSolver(_) | Experiment::OneStepObjective(_)
                ) && method == Method::LinearKf
            {
                let fit = match e {
                    Experiment::OneStepSolver(_) | Experiment::OneStepObjective(_) => "a GP fit",
                    _ => "the MSGP fit",
                };
                return Err(invalid(
                    &format!("experimental {}", e.key()),
                    format!(
                        "a setting of {fit}; the {} model does not have it",
                        method.name()
                    ),
                ));
            }
            match *e {
                Experiment::StartSmoothing(n) => start_smoothing = n,
                Experiment::FbSegment(n) => fb_segment = n,
                Experiment::FreePosition(b) => free_position = b,
                Experiment::ExcitationMaxHz(hz) => excitation.max_hz = hz,
                Experiment::RandomPolicies(k) => random_policies = k,
                Experiment::TrustRegion(r) => trust_region = r,
                Experiment::FitOptimizer(o) => optimizer = o,
                Experiment::HoldMargin(k) => hold_margin = k,
                Experiment::Prequential(b) => prequential_choice = b,
                Experiment::OneStepSolver(o) => one_step_solver = Some(o),
                Experiment::OneStepObjective(o) => one_step_objective = Some(o),
            }
        }
        if !(trust_region.is_finite() && trust_region >= 0.0) {
            return Err(invalid(
                "experimental trust-region",
                format!("must be finite and at least 0, got {trust_region}"),
            ));
        }
        if !(hold_margin.is_finite() && hold_margin >= 0.0) {
            return Err(invalid(
                "experimental hold-margin",
                format!("must be finite and at least 0, got {hold_margin}"),
            ));
        }
        if random_policies > self.random_rollouts {
            return Err(invalid(
                "experimental random-policies",
                format!(
                    "({random_policies}) cannot exceed random-rollouts ({})",
                    self.random_rollouts
                ),
            ));
        }
        let start_window = match start_smoothing {
            0 => StartWindow::Measured,
            samples => StartWindow::Smoothed { samples, degree: 2 },
        };
        start_window
            .validate(d.fit.ly.max(d.fit.lu))
            .map_err(|e| invalid("experimental start-smoothing", e.to_string()))?;
        excitation
            .validate()
            .map_err(|e| invalid("experimental excitation-max-hz", e.to_string()))?;
        let fit = FitSettings {
            // a linear-kf model has the linear mean whatever `mean` says
            integrators: match (method, self.mean, free_position) {
                (_, _, true) => Vec::new(),
                (Method::LinearKf, _, false) | (_, MeanFunction::Linear, false) => {
                    d.fit.integrators.clone()
                }
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
                s.optimizer = optimizer;
                s.start_window = start_window;
                if let Some(l) = self.likelihood {
                    s.likelihood = l;
                }
                if let Some(o) = one_step_solver {
                    s.one_step_solver = o;
                }
                if let Some(o) = one_step_objective {
                    s.one_step_objective = o;
                }
            }
            MethodSettings::GpNarx(s) | MethodSettings::PilcoNarx(s) => {
                s.mean = self.mean;
                if let Some(o) = one_step_solver {
                    s.solver = o;
                }
                if let Some(o) = one_step_objective {
                    s.objective = o;
                }
            }
            MethodSettings::LinearKf(_) => {}
        }
        let fit = match self.fit_iters {
            Some(n) => fit.with_solver_iterations(n),
            None => fit,
        };
        Ok(LearnSettings {
            iterations,
            random_rollouts: self.random_rollouts,
            random_policies,
            fb_segment: (fb_segment > 0).then_some(fb_segment),
            episode_seconds: self.episode_seconds,
            policy_horizon_seconds: self.policy_horizon.unwrap_or(d.policy_horizon_seconds),
            excitation,
            cost_widths,
            hold_margin,
            prequential_choice,
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
                trust_region,
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
                    experimental: vec![Experiment::OneStepSolver(OneStepSolver::Lbfgs)],
                    ..Budget::default()
                },
                Method::LinearKf,
                "experimental one-step-solver: a setting of a GP fit",
            ),
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
                    experimental: vec![Experiment::StartSmoothing(5)],
                    ..Budget::default()
                },
                Method::LinearKf,
                "experimental start-smoothing: a setting of the MSGP fit",
            ),
            (
                Budget {
                    random_rollouts: 2,
                    experimental: vec![Experiment::RandomPolicies(3)],
                    ..Budget::default()
                },
                Method::Msgp,
                "experimental random-policies: (3) cannot exceed random-rollouts (2)",
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
    fn the_one_step_switches_reach_gp_narx_and_the_msgp_start() {
        // GP-NARX's default is L-BFGS, MSGP's start Adam: each switched to the other
        let budget = Budget {
            experimental: vec![Experiment::OneStepSolver(OneStepSolver::Adam)],
            ..Budget::default()
        };
        let s = budget.settings(Method::GpNarx, 0, 1).expect("valid");
        let mut fit = s.fit.clone();
        match &mut fit.method {
            MethodSettings::GpNarx(o) => {
                assert_eq!(o.solver, OneStepSolver::Adam);
                o.solver = OneStepSolver::Lbfgs;
            }
            other => panic!("{other:?}"),
        }
        let mut default = LearnSettings::for_model(Method::GpNarx, None).fit;
        default.threads = fit.threads;
        assert_eq!(
            fit, default,
            "the switch changes the solver and nothing else"
        );
        let budget = Budget {
            likelihood: Some(Likelihood::FreeRun),
            experimental: vec![Experiment::OneStepSolver(OneStepSolver::Lbfgs)],
            ..Budget::default()
        };
        let d = LearnSettings::for_model(Method::Msgp, Some(Likelihood::FreeRun));
        assert_eq!(
            d.fit.msgp().map(|m| m.one_step_solver),
            Some(OneStepSolver::Adam)
        );
        let s = budget.settings(Method::Msgp, 0, 1).expect("valid");
        assert_eq!(
            s.fit.msgp().map(|m| m.one_step_solver),
            Some(OneStepSolver::Lbfgs)
        );
        // the one-step objective: the free-run MSGP's start and GP-NARX's whole fit
        let vfe = |likelihood| Budget {
            likelihood,
            experimental: vec![Experiment::OneStepObjective(OneStepObjective::Vfe)],
            ..Budget::default()
        };
        assert_eq!(
            d.fit.msgp().map(|m| m.one_step_objective),
            Some(OneStepObjective::Exact)
        );
        let s = vfe(Some(Likelihood::FreeRun))
            .settings(Method::Msgp, 0, 1)
            .expect("valid");
        assert_eq!(
            s.fit.msgp().map(|m| m.one_step_objective),
            Some(OneStepObjective::Vfe)
        );
        let s = vfe(None).settings(Method::GpNarx, 0, 1).expect("valid");
        match &s.fit.method {
            MethodSettings::GpNarx(o) => assert_eq!(o.objective, OneStepObjective::Vfe),
            other => panic!("{other:?}"),
        }
        let err = vfe(None)
            .settings(Method::LinearKf, 0, 1)
            .expect_err("linear-kf has no one-step fit");
        assert!(err.to_string().contains("one-step-objective"), "{err}");
    }

    #[test]
    fn experiments_parse_and_serialise_with_the_command_lines_keys() {
        let e = Experiment::parse("fit-optimizer=LBFGS").expect("parses");
        assert_eq!(e, Experiment::FitOptimizer(FitOptimizer::Lbfgs));
        assert_eq!(
            serde_json::to_string(&e).expect("json"),
            r#"{"fit-optimizer":"lbfgs"}"#
        );
        for (k, key) in EXPERIMENT_KEYS.iter().enumerate() {
            let value = [
                "4", "4", "true", "5", "1", "0.5", "adam", "1", "false", "lbfgs", "vfe",
            ][k];
            let e = Experiment::parse(&format!("{key}={value}")).expect("parses");
            assert_eq!(e.key(), *key);
            let back: Experiment =
                serde_json::from_str(&serde_json::to_string(&e).expect("json")).expect("reads");
            assert_eq!(back, e);
        }
        assert_eq!(
            Experiment::parse(" trust-region = 2.5 "),
            Ok(Experiment::TrustRegion(2.5))
        );
        for bad in [
            "fb-segment",
            "fb-segment=x",
            "free-position=1",
            "trust-region",
            "one-step-solver=newton",
            "one-step-objective=sparse",
        ] {
            assert!(Experiment::parse(bad).is_err(), "{bad}");
        }
        let unknown = Experiment::parse("wobble=3").expect_err("unknown key");
        assert!(unknown.contains("start-smoothing"), "{unknown}");
        let budget: Budget = serde_json::from_str(
            r#"{"episode_seconds": 2.0, "experimental": [{"trust-region": 0.5}]}"#,
        )
        .expect("a partial budget reads");
        assert_eq!(budget.episode_seconds, 2.0);
        assert_eq!(budget.inducing, None);
        assert!(serde_json::from_str::<Budget>(r#"{"episodes": 2}"#).is_err());
    }
}
