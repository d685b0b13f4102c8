//! The loop's settings: how many episodes and iterations, how each model is fitted and each
//! policy searched, and what the loop measures besides.

use serde::{Deserialize, Serialize};

use super::excitation::ExcitationConfig;
use crate::error::{MsgpError, Result};
use crate::fit::{FitOptimizer, FitSettings, MsgpSettings, MsgpStart};
use crate::gp::MeanFunction;
use crate::loss::Likelihood;
use crate::model::Method;
use crate::plant::PlantSpec;
use crate::policy_search::{PolicySearchSettings, PolicySolver};

/// Settings of the learning loop (any plant, any task).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
#[serde(deny_unknown_fields)]
pub struct LearnerSettings {
    /// Policy iterations after the random episodes.
    pub iterations: usize,
    /// Open-loop episodes of random excitation before the first policy.
    pub random_rollouts: usize,
    /// Their excitation.
    pub excitation: ExcitationConfig,
    /// Seed of everything random (episodes, excitation, fits, searches).
    pub seed: u64,
    /// The model's fit (method, history, inducing points, solver).
    pub fit: FitSettings,
    /// The policy search.
    pub search: PolicySearchSettings,
    /// After every iteration, this many evaluation episodes of the new policy (their own
    /// seeds, an episode's length each) estimate the expected cost the model predicted: one
    /// episode's cost is a single draw. Neither interaction nor training data. 0: none.
    pub evaluation_episodes: usize,
    /// The prequential choice (MSGP only, [`super::choice`]): every iteration also fits the
    /// linear model of the data and the search runs on the GP model only while its predictions
    /// of episodes it had not seen beat the linear model's.
    pub prequential_choice: bool,
    /// Open-loop episodes enter a free-run MSGP loss as overlapping segments of this many
    /// samples (stride half of it); `None` keeps them whole. An unstable plant's free run
    /// from an episode's first samples carries no information after a while.
    pub ff_segment: Option<usize>,
    /// From the second iteration on, each fit (MSGP, linear-kf) continues the previous model
    /// for this many solver iterations; `None` starts over every time.
    pub warm_start: Option<usize>,
    /// Every search also starts from the task's first policy, besides the running one (PILCO's
    /// fresh start: a running policy that saturates its commands has near-zero gradients, and
    /// one searched on the linear model before the GP model earned the search may sit far
    /// from any swing-up). The better of the two is kept.
    #[serde(default)]
    pub search_from_first: bool,
    /// Under the prequential choice, also fit the MSGP model's one-step start (GP-NARX on the
    /// same data) every iteration, and search on it instead of the MSGP model whenever the
    /// MSGP model's closed-loop free run of the latest episode, which neither had seen, was
    /// no better ([`super::choice`]): the trajectory training is kept only where it predicts
    /// better what the search predicts.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub one_step_guard: bool,
}

impl LearnerSettings {
    /// The settings as a run's record holds them: without the threads of the fit and the
    /// search, which are not recorded (results do not depend on them) and read back as the
    /// default. A finished run is recognised by `stored == settings.as_recorded()`, whatever
    /// `MSGP_THREADS` says.
    pub fn as_recorded(&self) -> Self {
        let mut recorded = self.clone();
        recorded.fit.threads = Default::default();
        recorded.search.threads = Default::default();
        recorded
    }

    /// The loop's defaults on a plant of `spec` (PILCO's loop with an MSGP model): MSGP on the
    /// filter likelihood (a linear prior mean under a GP of 30 pseudo-inputs, started from
    /// the one-step GP-NARX fit, 100 L-BFGS iterations, then each later fit continuing the
    /// previous one for 40; noise variances at least 1e-4 of the data's, PILCO's bound on the
    /// signal-to-noise ratio, which a noise-free simulator needs), history (2, 2), the
    /// prequential choice against the linear model, one random episode whose excitation
    /// reaches a fifth of the sampling rate; each search L-BFGS for up to 100 iterations from
    /// the running policy and from the task's first one; 10 evaluation episodes per iteration.
    ///
    /// Why not the built-in pendulum's start from the linear-kf model: on a plant whose data
    /// are far from linear (a swinging pendulum), the linear-kf fit explains them as
    /// observation noise, and a GP started at zero from there never grows (`docs/design.md`).
    pub fn for_plant(spec: &PlantSpec) -> Self {
        let max_hz = 0.2 / spec.period;
        Self {
            iterations: 10,
            random_rollouts: 1,
            excitation: ExcitationConfig {
                max_hz,
                min_hz: max_hz / 100.0,
                ..ExcitationConfig::default()
            },
            seed: 0,
            fit: FitSettings {
                ly: 2,
                lu: 2,
                method: MsgpSettings {
                    inducing: 30,
                    iterations: 100,
                    optimizer: FitOptimizer::Lbfgs,
                    likelihood: Likelihood::Filter,
                    validation_fraction: 0.0,
                    noise_floor: 1e-4,
                    mean: MeanFunction::Linear,
                    start: MsgpStart::OneStep,
                    alternative: None,
                    ..MsgpSettings::default()
                }
                .into(),
                ..FitSettings::default()
            },
            search: PolicySearchSettings {
                iterations: 100,
                restarts: 0,
                candidates: 0,
                trust_region: 0.0,
                solver: PolicySolver::Lbfgs,
                ..PolicySearchSettings::default()
            },
            evaluation_episodes: 10,
            prequential_choice: true,
            ff_segment: None,
            warm_start: Some(40),
            search_from_first: true,
            one_step_guard: false,
        }
    }

    /// The model's training method.
    pub fn method(&self) -> Method {
        self.fit.method()
    }

    /// Checks what the loop itself adds to its parts' settings.
    pub fn validate(&self) -> Result<()> {
        self.excitation.validate()?;
        if self.prequential_choice && self.method() != Method::Msgp {
            return Err(MsgpError::InvalidSetting {
                name: "prequential_choice",
                reason: "the choice between a GP model and its linear part needs an MSGP model"
                    .into(),
            });
        }
        if self.one_step_guard && !self.prequential_choice {
            return Err(MsgpError::InvalidSetting {
                name: "one_step_guard",
                reason: "the guard is part of the prequential choice; turn that on too".into(),
            });
        }
        if self.iterations > 0 && self.random_rollouts == 0 {
            return Err(MsgpError::InvalidSetting {
                name: "random_rollouts",
                reason: "the first model needs at least one random episode".into(),
            });
        }
        Ok(())
    }

    /// Whether open-loop episodes enter the loss in segments (a free-run MSGP fit only:
    /// one-step and linear-kf fits see every pair once, and a filter likelihood handles a
    /// whole unstable episode).
    pub fn segment_length(&self) -> Option<usize> {
        self.ff_segment.filter(|_| {
            self.fit
                .msgp()
                .is_some_and(|m| m.likelihood == Likelihood::FreeRun)
        })
    }
}
