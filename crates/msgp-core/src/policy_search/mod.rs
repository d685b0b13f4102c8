//! Policy search on a learned model (PILCO's inner loop): minimise the expected saturating cost
//! of a closed-loop moment-matching rollout over the free parameters of a policy (the gains of
//! a saturated PID, a linear state feedback, an RBF network: [`crate::policy::Policy`]), with
//! exact gradients and Adam with seeded restarts around the current parameters. The gradients
//! come from the rollout's adjoint sweep ([`PolicyProblem::gradient`]; ≈ 3× faster than
//! forward-mode duals over the PID's five gains, BENCHMARKS.md); the duals
//! ([`policy_gradient_duals`]) stay the reference it is tested against.
//!
//! Everything the user specifies (parameters, cost target and widths, start state) is in
//! original units; the model's normalisation is applied exactly inside.
//!
//! Modules: [`cost`] (the saturating cost and its Gaussian moments), [`objective`] (the
//! closed-loop expected cost, the problem and its start, the gradient over the free parameters
//! and its dual reference), [`gradient`] (the expected-cost rollout's adjoint), [`space`] (which
//! parameters move: a policy and its free flags, the PID's gain mask), [`search`] (the
//! optimiser).

pub mod cost;
pub mod gradient;
pub mod objective;
pub mod search;
pub mod space;

pub use cost::SaturatingCost;
pub use gradient::{DualPolicyMap, PolicyVjp, closed_loop_cost_gradient};
pub use objective::{PolicyProblem, RolloutCost, closed_loop_cost, policy_gradient_duals};
pub use search::{
    PolicySearchResult, PolicySearchSettings, PolicySolver, optimise, optimise_over, optimise_pid,
    optimise_pid_scaled,
};
pub use space::{PidMask, SearchSpace};
