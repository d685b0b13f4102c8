//! The sparse GP dynamics model, parametrised by pseudo-inputs and pseudo-targets.
//!
//! Vocabulary (paper section 3.2): the latent transition `x_{t+1} = f(x̃_t) + ε_x` is one GP per
//! output dimension `a`, conditioned on `m` *pseudo-inputs* `X̄` (rows are NARX windows, shared
//! by all outputs) and *pseudo-targets* `ȳ_a`. With `K̃_a = K_a(X̄, X̄) + σ_{x,a}² I` the
//! predictive distribution at a window `x̃` is eq. (13):
//! `μ_a(x̃) = k_a(x̃)ᵀ β_a`, `β_a = K̃_a⁻¹ ȳ_a`, and
//! `σ_a²(x̃) = σ_{f,a}² − k_a(x̃)ᵀ K̃_a⁻¹ k_a(x̃)`.
//! `σ_x²` is the *process noise* on the latent state and `σ_y²` the *observation noise* on
//! measurements `y_t = x_t + ε_y`.
//!
//! All positive quantities live in log space. Noise variances have a floor:
//! `σ² = floor + exp(θ)`, so a fit cannot collapse them to zero (see `docs/design.md`).
//!
//! Modules: [`kernel`] (SE-ARD, and the [`KernelScalar`] fast paths), [`params`] (`θ`, its
//! shape and flat layout), [`prepared`] (the factorised GP of one loss evaluation),
//! [`integrator`] (known integrating structure), [`kmeans`] (pseudo-input placement).

pub mod integrator;
pub mod kernel;
pub mod kmeans;
pub mod params;
pub mod prepared;

pub use kernel::KernelScalar;
pub use params::{GpConfig, GpParams, GpShape, MeanFunction, ParamGroup};
pub use prepared::{OutputGp, PreparedGp};
