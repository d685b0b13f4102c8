//! Continuing a model fitted earlier (a *warm start*, [`super::refit_episodes`]): which
//! settings may continue which model, and the pseudo-inputs a continuation adds when the data
//! have grown past the windows that capped the first fit's count.
//!
//! A policy-search loop fits its first model on one short random episode (17 windows on the
//! swing-up), which caps the pseudo-inputs below the count asked; the warm starts that follow
//! keep the hyperparameters and, with the pseudo-inputs frozen, would keep those 17 positions
//! for every later iteration, however much of the state space the new episodes cover. A
//! continuation on more windows than the previous model has pseudo-inputs therefore places
//! `min(asked, windows)` pseudo-inputs afresh by k-means over every window (in the previous
//! model's normalised units), and sets their targets to the previous GP's residual mean there,
//! so the continued model starts from (nearly) the previous function.

use nalgebra::DMatrix;

use super::FitSettings;
use super::one_step::one_step_pairs;
use crate::data::Trajectory;
use crate::error::{MsgpError, Result};
use crate::gp::GpParams;
use crate::gp::integrator::Structure;
use crate::gp::kmeans::{gp_inputs, place_pseudo_inputs};
use crate::gp::prepared::PreparedGp;
use crate::model::{Method, Model};
use crate::narx::NarxSpec;
use crate::numeric::linalg::JitterLog;

/// Whether `settings` describe a model that can continue `previous` ([`refit_episodes`]).
pub(super) fn check(settings: &FitSettings, previous: &Model) -> Result<()> {
    let refuse = |what: String| {
        Err(MsgpError::InvalidSetting {
            name: "warm start",
            reason: what,
        })
    };
    let method = settings.method();
    if method != previous.method || !matches!(method, Method::Msgp | Method::LinearKf) {
        return refuse(format!(
            "only MSGP and linear-kf fits continue from a previous model of their own method \
             (settings: {}, model: {})",
            method.name(),
            previous.method.name()
        ));
    }
    let history = (settings.ly, settings.lu) == (previous.spec.ly, previous.spec.lu);
    let Some(msgp) = settings.msgp() else {
        if !history {
            return refuse(format!(
                "the previous model has history ({}, {}); the settings ask for ({}, {})",
                previous.spec.ly, previous.spec.lu, settings.ly, settings.lu
            ));
        }
        return Ok(());
    };
    if !history
        // fewer pseudo-inputs than asked: the first fit's data had fewer windows, which capped
        // them; the continuation adds the missing ones (`grown_pseudo_inputs`)
        || previous.params.pseudo_inputs.nrows() > msgp.inducing
        || msgp.mean != previous.config.mean
    {
        return refuse(format!(
            "the previous model has history ({}, {}), {} pseudo-inputs and a {:?} mean; the \
             settings ask for ({}, {}), at most {} and {:?}",
            previous.spec.ly,
            previous.spec.lu,
            previous.params.pseudo_inputs.nrows(),
            previous.config.mean,
            settings.ly,
            settings.lu,
            msgp.inducing,
            msgp.mean
        ));
    }
    Ok(())
}

/// `previous`'s parameters with `min(inducing, windows)` pseudo-inputs placed afresh over the
/// windows of `norm` (normalised trajectories), when that is more than `previous` has; `None`
/// when the previous pseudo-inputs stay. Each new pseudo-target is the previous GP's residual
/// mean (the linear mean left out) at its pseudo-input; every other parameter is kept.
pub(super) fn grown_pseudo_inputs(
    previous: &Model,
    norm: &[Trajectory],
    spec: NarxSpec,
    structure: &Structure,
    inducing: usize,
    seed: u64,
) -> Result<Option<GpParams<f64>>> {
    let had = previous.params.pseudo_inputs.nrows();
    if inducing <= had {
        return Ok(None);
    }
    let refs: Vec<&Trajectory> = norm.iter().collect();
    let data = one_step_pairs(&spec, &refs)?;
    let m = inducing.min(data.x.nrows());
    if m <= had {
        return Ok(None);
    }
    let pseudo = place_pseudo_inputs(&gp_inputs(&data.x, &structure.ignored), m, seed)?;
    let mut gp = PreparedGp::new(
        &previous.params,
        &previous.config,
        &mut JitterLog::default(),
    )?;
    gp.linear_mean = None;
    let e = previous.params.pseudo_targets.ncols();
    let mut targets = DMatrix::zeros(m, e);
    for i in 0..m {
        let z: Vec<f64> = pseudo.row(i).iter().copied().collect();
        for (a, (mean, _)) in gp.predict(&z).into_iter().enumerate() {
            targets[(i, a)] = mean;
        }
    }
    Ok(Some(GpParams {
        pseudo_inputs: pseudo,
        pseudo_targets: targets,
        ..previous.params.clone()
    }))
}
