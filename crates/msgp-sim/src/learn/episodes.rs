//! The loop's interaction episodes and how each enters the model loss: its `[θ, x]`
//! trajectory, whole or in overlapping segments, feed-forward or under the gains that ran it.

use nalgebra::DMatrix;

use msgp_core::data::Trajectory;
use msgp_core::fit::TrainingEpisode;
use msgp_core::loss::Likelihood;
use msgp_core::policy::{Policy, PolicySpec};
use msgp_core::policy_search::cost::SaturatingCost;

use crate::controller::{Controller, PidPdGains, PidPdPolicy};
use crate::episode::{Episode, EpisodeConfig, run_episode};
use crate::error::SimError;
use crate::params::PendulumParams;
use crate::seed::{Stream, rng_for};

use super::problem::{episode_cost, modelled_policy};
use super::settings::LearnSettings;

/// `[θ, x]` and the commands of an episode.
pub fn episode_trajectory(ep: &Episode) -> Result<Trajectory, SimError> {
    let n = ep.samples.len();
    let u = DMatrix::from_fn(n, 1, |k, _| ep.samples[k].command);
    let y = DMatrix::from_fn(n, 2, |k, j| {
        let m = ep.samples[k].measurement;
        if j == 0 { m.theta } else { m.x }
    });
    Ok(Trajectory::new(u, y)?)
}

/// `traj` as overlapping segments of `len` samples with stride `len / 2` (the last one ends
/// at the end); segments shorter than `min_len` are dropped.
pub fn segments(
    traj: &Trajectory,
    len: usize,
    min_len: usize,
) -> Result<Vec<Trajectory>, SimError> {
    let n = traj.len();
    let len = len.max(min_len).max(2);
    let stride = (len / 2).max(1);
    let mut out = Vec::new();
    let mut start = 0;
    while start + min_len <= n {
        let end = (start + len).min(n);
        out.push(Trajectory::new(
            traj.u.rows(start, end - start).into_owned(),
            traj.y.rows(start, end - start).into_owned(),
        )?);
        if end == n {
            break;
        }
        start += stride;
    }
    Ok(out)
}

/// `traj` cut into segments of `segment` samples for free-run MSGP fits; whole otherwise:
/// one-step and linear-kf fits see every pair once (segments would duplicate the overlaps),
/// and a filter likelihood (MSGP's or linear-kf's) handles a whole unstable episode.
pub(super) fn msgp_segments(
    traj: Trajectory,
    segment: Option<usize>,
    settings: &LearnSettings,
) -> Result<Vec<Trajectory>, SimError> {
    match segment {
        Some(len)
            if settings
                .fit
                .msgp()
                .is_some_and(|m| m.likelihood == Likelihood::FreeRun) =>
        {
            segments(&traj, len, settings.fit.ly.max(settings.fit.lu) + 5)
        }
        _ => Ok(vec![traj]),
    }
}

/// One episode of `gains` and its training entries: the trajectory under those gains
/// (`L_fb`), whole or in [`LearnSettings::fb_segment`] segments.
pub(super) fn feedback_episode(
    params: &PendulumParams,
    gains: &PidPdGains,
    settings: &LearnSettings,
    seed: u64,
    seconds: &mut f64,
) -> Result<(Episode, Vec<TrainingEpisode>), SimError> {
    let mut controller = PidPdPolicy::new(*gains, params)?;
    let ep = interact(
        params,
        &mut controller,
        settings.episode_seconds,
        seed,
        seconds,
    )?;
    let parts = msgp_segments(episode_trajectory(&ep)?, settings.fb_segment, settings)?;
    let policy = PolicySpec::Direct(Policy::Pid(modelled_policy(gains, params)?));
    let entries = parts
        .into_iter()
        .map(|traj| TrainingEpisode {
            traj,
            policy: Some(policy.clone()),
        })
        .collect();
    Ok((ep, entries))
}

/// The expected cost of `gains` on the system after `iteration`: the mean measured cost
/// ([`episode_cost`] over the scored steps `from..from + steps`) of
/// [`LearnSettings::evaluation_episodes`] episodes of the loop's length from random initial
/// angles, each with its own seed; `None` when there are none.
pub(super) fn expected_cost(
    params: &PendulumParams,
    gains: &PidPdGains,
    settings: &LearnSettings,
    iteration: usize,
    cost: &SaturatingCost,
    (from, steps): (usize, usize),
) -> Result<Option<f64>, SimError> {
    let n = settings.evaluation_episodes;
    if n == 0 {
        return Ok(None);
    }
    let mut total = 0.0;
    for k in 0..n {
        let mut controller = PidPdPolicy::new(*gains, params)?;
        let stream = Stream::Evaluation {
            iteration: u32::try_from(iteration).unwrap_or(u32::MAX),
            episode: u32::try_from(k).unwrap_or(u32::MAX),
        };
        let ep = run_episode(
            params,
            &mut controller,
            &EpisodeConfig {
                seconds: settings.episode_seconds,
                seed: rng_for(settings.seed, stream),
                initial_theta: None,
            },
        )?;
        total += episode_cost(&ep, cost, from, steps);
    }
    Ok(Some(total / n as f64))
}

/// One interaction episode from a random initial angle; adds its duration to `seconds`.
pub(super) fn interact(
    params: &PendulumParams,
    controller: &mut dyn Controller,
    length: f64,
    seed: u64,
    seconds: &mut f64,
) -> Result<Episode, SimError> {
    let ep = run_episode(
        params,
        controller,
        &EpisodeConfig {
            seconds: length,
            seed,
            initial_theta: None,
        },
    )?;
    *seconds += ep.samples.len().saturating_sub(1) as f64 * params.control_period();
    Ok(ep)
}
