//! # msgp-core
//!
//! Multi-step Gaussian processes (MSGP; Doerr et al., CoRL 2017): sparse GP-NARX dynamics models
//! whose parameters are fitted to the likelihood of whole observed trajectories under
//! free-running moment-matching predictions.
//!
//! Module map:
//! - [`scalar`]: the one scalar abstraction (f64 or forward-mode duals);
//! - [`linalg`]: robust Cholesky with a recorded jitter policy;
//! - [`kernel`], [`gp`]: SE-ARD kernel and the pseudo-input sparse GP;
//! - [`moments`]: exact moment matching under Gaussian inputs;
//! - [`narx`], [`rollout`], [`policy`]: the autoregressive window and open/closed-loop rollouts;
//! - [`loss`]: the trajectory likelihood and complexity term;
//! - [`kalman`]: the linear-Gaussian window model by the exact Kalman-filter likelihood;
//! - [`grad`]: exact gradients.

pub mod baseline;
pub mod cost;
pub mod data;
pub mod dense;
pub mod error;
pub mod fit;
pub mod gp;
pub mod grad;
pub mod integrator;
pub mod kalman;
pub mod kernel;
pub mod kmeans;
pub mod linalg;
pub mod loss;
pub mod mean_fn;
pub(crate) mod mm_f64;
pub mod model;
pub mod model_file;
pub mod moments;
pub mod narx;
pub mod optim;
mod parallel;
pub mod policy;
pub mod policy_cost;
pub mod policy_search;
pub mod rollout;
pub mod saturation;
pub mod scalar;
mod simd;
pub mod start_window;
pub mod trajectory;

pub use error::{MsgpError, Result};
