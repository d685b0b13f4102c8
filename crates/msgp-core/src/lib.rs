//! # msgp-core
//!
//! Multi-step Gaussian processes (MSGP; Doerr et al., CoRL 2017): sparse GP-NARX dynamics models
//! whose parameters are fitted to the likelihood of whole observed trajectories under
//! free-running moment-matching predictions, and PILCO policy search on them.
//!
//! One module per concept of the paper, each depending only on the ones above it in this list
//! (`scripts/check-modules` checks that the graph has no cycle):
//! - [`error`]: the crate's one error type;
//! - [`numeric`]: the [`Scalar`](numeric::Scalar) (f64 or forward-mode duals), robust Cholesky
//!   with a recorded jitter policy, dual-number gradients, SIMD kernels, threads;
//! - [`optim`]: objectives and solvers (Adam, L-BFGS) under an observer;
//! - [`narx`]: the autoregressive window and how a rollout starts it;
//! - [`data`]: trajectories, normalisation, CSV/MCAP readers, the paper's benchmarks;
//! - [`gp`]: the SE-ARD kernel, the pseudo-input sparse GP's parameters and their flat layout,
//!   the prepared (factorised) GP, integrating structure, k-means;
//! - [`moments`]: exact moment matching under Gaussian inputs (generic, the f64 fast path behind
//!   [`MomentMatch`](moments::MomentMatch), its VJP), the linear mean, the sine saturation;
//! - [`policy`]: the policy families (saturated PID, linear state feedback on a window, PILCO's
//!   RBF network) with exact output moments, in original and normalised units;
//! - [`rollout`]: open- and closed-loop rollouts of the window's joint Gaussian, and their
//!   adjoint sweep;
//! - [`loss`]: the trajectory likelihood (eq. 4) with its complexity term, and its gradient;
//!   the free-run likelihood (the paper's) and the filter likelihood ([`loss::filter`]);
//! - [`model`]: the fitted model, its free simulation and scores;
//! - [`fit`]: MSGP, the one-step baselines and linear-kf, from trajectories to a model;
//! - [`model_file`]: the versioned model file (a model and its training record);
//! - [`policy_search`]: PILCO's inner loop: expected saturating cost, its gradient, the search;
//! - [`plant`]: a system the learning loop runs episodes on (the trait the simulator, a
//!   Gymnasium environment or a user's model implements);
//! - [`learner`]: PILCO's outer loop on a plant: episodes, fits, searches, the prequential
//!   choice, one iteration's step on logged episodes;
//! - [`policy_file`]: the versioned policy file (a policy, its plant's signals, its task and
//!   what the model predicted of it).

#![warn(missing_docs)]

pub mod data;
pub mod error;
pub mod fit;
pub mod gp;
pub mod learner;
pub mod loss;
pub mod model;
pub mod model_file;
pub mod moments;
pub mod narx;
pub mod numeric;
pub mod optim;
pub mod overlay;
pub mod plant;
pub mod policy;
pub mod policy_file;
pub mod policy_search;
pub mod rollout;

pub use error::{MsgpError, Result};
