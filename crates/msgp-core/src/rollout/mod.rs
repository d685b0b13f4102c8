//! Free-running moment-matching rollouts over the NARX window (paper section 3.3), open loop
//! (given inputs) or closed loop (a known feedback policy), and their adjoint sweep.
//!
//! Modules: [`forward`] (the rollout: one loop, any scalar), `window` (the Gaussian state and
//! its one-step layout), `adjoint` (the hand-derived reverse sweep, f64), [`episode`] (a
//! trajectory and how its inputs were produced), [`mean_feedback`] (the baselines' simulation
//! that feeds back predicted means only), [`function_uncertainty`] (the GP's uncertainty about
//! its function kept correlated over a free simulation: what a free simulation reports).

pub(crate) mod adjoint;
pub mod episode;
pub mod forward;
pub mod function_uncertainty;
pub mod mean_feedback;
pub(crate) mod window;

pub use episode::{Episode, Excitation};
pub(crate) use forward::rollout_started;
pub use forward::{Control, StepPrediction, rollout, rollout_from, simulate};
pub use function_uncertainty::{
    FunctionDraws, FunctionPosterior, sample_free_runs, simulate_correlated,
};
pub use mean_feedback::simulate_mean_feedback;
pub use window::StartState;
