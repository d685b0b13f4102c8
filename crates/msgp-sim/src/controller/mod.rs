//! Controllers: the paper's PID + PD policy and smooth random excitation.

mod excitation;
mod pid_pd;

pub use excitation::{ExcitationConfig, RandomExcitation};
pub use pid_pd::{APOLLO_LQR_GAINS, PidPdGains, PidPdPolicy, Saturation};

use crate::plant::Measurement;

/// Anything that turns measurements into end-effector acceleration commands.
///
/// The episode runner calls [`reset`](Controller::reset) once, then
/// [`command`](Controller::command) once per control step with the newest noisy
/// measurement. The plant clips the returned command to its action limit.
pub trait Controller {
    /// Clears internal state (integrators, previous measurements) before an episode.
    fn reset(&mut self);
    /// Command \[m/s²\] for the control step at time `t` \[s\].
    fn command(&mut self, t: f64, measurement: &Measurement) -> f64;
    /// Short human-readable description, stored in run logs.
    fn describe(&self) -> String;
}
