//! The loop's settings: how many episodes and iterations, how each model is fitted and each
//! policy searched, and what the loop measures besides.

use serde::{Deserialize, Serialize};

use super::excitation::ExcitationConfig;
use crate::error::{MsgpError, Result};
use crate::fit::FitSettings;
use crate::loss::Likelihood;
use crate::model::Method;
use crate::policy_search::PolicySearchSettings;

/// Settings of the learning loop (any plant, any task).
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
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
}

impl LearnerSettings {
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
