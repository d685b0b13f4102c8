//! A measured trajectory and how its inputs were produced: one term of the MSGP loss, `L_ff`
//! (open loop, the measured inputs) or `L_fb` (closed loop, the known feedback policy),
//! paper eq. (4).

use crate::data::Trajectory;
use crate::policy::PolicySpec;

/// How a trajectory's inputs were produced: given (feed-forward) or by a known feedback policy.
#[derive(Clone, Debug, PartialEq)]
pub enum Excitation {
    /// Inputs were applied open loop; the rollout uses the measured `u`.
    FeedForward,
    /// Inputs came from this policy acting on the observations; the rollout closes the loop
    /// (the paper's `L_fb`).
    Feedback(Box<PolicySpec>),
}

/// A trajectory plus how it was excited: one term of `L_ff` or `L_fb` (paper eq. 4).
#[derive(Clone, Debug, PartialEq)]
pub struct Episode {
    /// The data (normalised units).
    pub traj: Trajectory,
    /// Open or closed loop.
    pub excitation: Excitation,
}

impl Episode {
    /// A feed-forward episode.
    pub fn feed_forward(traj: Trajectory) -> Self {
        Self {
            traj,
            excitation: Excitation::FeedForward,
        }
    }
}
