//! The models the loop can learn with, and a loop's settings switched to one of them: MSGP on
//! the free-run likelihood (the paper's) or on the filter likelihood, each under the
//! prequential choice; one-step GP-NARX with the MSGP fit's own start settings (standard PILCO:
//! the same pseudo-inputs, linear prior mean and solver), without the choice; linear-kf, the
//! linear-Gaussian window model alone. Figure 4 and the plant tasks compare these four.

use std::str::FromStr;

use serde::{Deserialize, Serialize};

use super::LearnerSettings;
use crate::error::{MsgpError, Result};
use crate::fit::{LinearKfSettings, Overrides};
use crate::loss::Likelihood;
use crate::model::Method;

/// A model the loop can learn with: MSGP with either likelihood, one-step GP-NARX, linear-kf.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum LoopModel {
    /// MSGP trained on the free-run likelihood (the paper's).
    Msgp,
    /// MSGP trained on the filter likelihood.
    MsgpFilter,
    /// One-step GP-NARX (standard PILCO).
    GpNarx,
    /// The linear-Gaussian window model by the Kalman-filter likelihood.
    LinearKf,
}

impl LoopModel {
    /// Every model, in the order of the tables that compare them (Figure 4, the plant tasks).
    pub const ALL: [LoopModel; 4] = [
        LoopModel::Msgp,
        LoopModel::MsgpFilter,
        LoopModel::GpNarx,
        LoopModel::LinearKf,
    ];

    /// The loop's model and MSGP likelihood.
    pub fn model(self) -> (Method, Option<Likelihood>) {
        match self {
            LoopModel::Msgp => (Method::Msgp, Some(Likelihood::FreeRun)),
            LoopModel::MsgpFilter => (Method::Msgp, Some(Likelihood::Filter)),
            LoopModel::GpNarx => (Method::GpNarx, None),
            LoopModel::LinearKf => (Method::LinearKf, None),
        }
    }

    /// Name in tables, folders and on the command line.
    pub fn name(self) -> &'static str {
        match self {
            LoopModel::Msgp => "msgp",
            LoopModel::MsgpFilter => "msgp-filter",
            LoopModel::GpNarx => "gp-narx",
            LoopModel::LinearKf => "linear-kf",
        }
    }
}

impl FromStr for LoopModel {
    type Err = String;

    fn from_str(s: &str) -> std::result::Result<Self, String> {
        LoopModel::ALL
            .into_iter()
            .find(|m| m.name() == s)
            .ok_or_else(|| {
                let names: Vec<&str> = LoopModel::ALL.iter().map(|m| m.name()).collect();
                format!("unknown model `{s}` (known: {})", names.join(", "))
            })
    }
}

/// `settings` with its model replaced by `model` (see the module docs); the settings must fit
/// MSGP, from which the other models are derived.
pub fn with_model(mut settings: LearnerSettings, model: LoopModel) -> Result<LearnerSettings> {
    let msgp_only = |name: &str| MsgpError::InvalidSetting {
        name: "fit.method",
        reason: format!("the task's preset must fit MSGP to derive the {name} model"),
    };
    match model {
        LoopModel::MsgpFilter | LoopModel::Msgp => {
            let likelihood = match model {
                LoopModel::Msgp => Likelihood::FreeRun,
                _ => Likelihood::Filter,
            };
            if settings.fit.msgp().is_none() {
                return Err(msgp_only(model.name()));
            }
            let likelihood = Overrides {
                likelihood: Some(likelihood),
                ..Overrides::default()
            };
            settings.fit = likelihood.apply(settings.fit)?;
        }
        LoopModel::GpNarx => {
            settings.fit = settings
                .fit
                .one_step_start()
                .ok_or_else(|| msgp_only(model.name()))?;
            settings.prequential_choice = false;
            settings.one_step_guard = false;
        }
        LoopModel::LinearKf => {
            settings.fit.method = LinearKfSettings::default().into();
            settings.prequential_choice = false;
            settings.one_step_guard = false;
        }
    }
    settings.validate()?;
    Ok(settings)
}
