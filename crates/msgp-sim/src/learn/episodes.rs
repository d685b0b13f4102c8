//! A recorded pendulum episode as the model sees it: its `[θ, x]` trajectory and commands.

use nalgebra::DMatrix;

use msgp_core::data::Trajectory;

use crate::episode::Episode;
use crate::error::SimError;

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
