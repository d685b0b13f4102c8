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

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use crate::error::{MsgpError, Result};
use crate::kernel::kernel_matrix;
use crate::linalg::{Cholesky, JitterLog, JitterPolicy, cholesky};
use crate::scalar::{Scalar, c};
use crate::start_window::StartWindow;

/// Every differentiable parameter of the model (the paper's `θ`).
#[derive(Clone, Debug, PartialEq)]
pub struct GpParams<T: Scalar> {
    /// `X̄`: m × D pseudo-inputs.
    pub pseudo_inputs: DMatrix<T>,
    /// `ȳ`: m × E pseudo-targets (column `a` for output `a`).
    pub pseudo_targets: DMatrix<T>,
    /// `log ℓ`: E × D log length-scales.
    pub log_lengthscales: DMatrix<T>,
    /// `log σ_f²` per output.
    pub log_signal_var: DVector<T>,
    /// `log(σ_x² − floor)` per output (process noise).
    pub log_process_noise: DVector<T>,
    /// `log(σ_y² − floor)` per output (observation noise).
    pub log_obs_noise: DVector<T>,
    /// `A`: E × D coefficients of the linear prior mean `m(x̃) = A x̃` (zero, and frozen, under
    /// [`MeanFunction::Zero`]).
    pub linear_mean: DMatrix<T>,
}

/// The GP's prior mean over the NARX window.
///
/// `Zero` is the paper's model: far from the pseudo-inputs every prediction reverts to the
/// (normalised) data mean with the full signal variance. `Linear` adds a trained linear map
/// `m(x̃) = A x̃` (an ARX model) and lets the GP model what it leaves over, the usual choice for
/// mechanical systems: an unstable plant (a pendulum) stays nearly linear near its operating
/// point, and predictions outside the data follow the linear model instead of collapsing to the
/// mean. Moment matching stays exact (`A x̃` is linear in the Gaussian window).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum MeanFunction {
    /// `m(x̃) = 0`.
    #[default]
    Zero,
    /// `m(x̃) = A x̃`, `A` trained with the other parameters.
    Linear,
}

/// Settings that are not optimised.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct GpConfig {
    /// Lower bound added to both noise variances (normalised units).
    pub noise_floor: f64,
    /// Jitter policy for every Cholesky factorisation.
    pub jitter: JitterPolicy,
    /// Prior mean function.
    #[serde(default)]
    pub mean: MeanFunction,
    /// How the MSGP training loss starts the rollout of a measured trajectory (predictions from
    /// data always start from the measured window). A training setting: not in model files.
    #[serde(default)]
    pub start: StartWindow,
}

impl Default for GpConfig {
    fn default() -> Self {
        Self {
            noise_floor: 1e-6,
            jitter: JitterPolicy::default(),
            mean: MeanFunction::Zero,
            start: StartWindow::Measured,
        }
    }
}

/// One parameter group, for flattening and freezing.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, Serialize, Deserialize)]
pub enum ParamGroup {
    /// `X̄`
    PseudoInputs,
    /// `ȳ`
    PseudoTargets,
    /// `log ℓ`
    Lengthscales,
    /// `log σ_f²`
    SignalVar,
    /// process noise
    ProcessNoise,
    /// observation noise
    ObsNoise,
    /// `A` of the linear prior mean
    LinearMean,
}

impl ParamGroup {
    /// All groups in flattening order.
    pub const ALL: [ParamGroup; 7] = [
        ParamGroup::PseudoInputs,
        ParamGroup::PseudoTargets,
        ParamGroup::Lengthscales,
        ParamGroup::SignalVar,
        ParamGroup::ProcessNoise,
        ParamGroup::ObsNoise,
        ParamGroup::LinearMean,
    ];
}

/// Sizes of the model: `m` pseudo-inputs, input dimension `D`, `E` outputs.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct GpShape {
    /// Number of pseudo-inputs.
    pub m: usize,
    /// GP input dimension.
    pub d: usize,
    /// Number of outputs.
    pub e: usize,
}

impl GpShape {
    /// Number of scalars in `group`.
    pub fn group_len(&self, group: ParamGroup) -> usize {
        match group {
            ParamGroup::PseudoInputs => self.m * self.d,
            ParamGroup::PseudoTargets => self.m * self.e,
            ParamGroup::Lengthscales | ParamGroup::LinearMean => self.e * self.d,
            ParamGroup::SignalVar | ParamGroup::ProcessNoise | ParamGroup::ObsNoise => self.e,
        }
    }

    /// Index range of `group` in the flat parameter vector.
    pub fn group_range(&self, group: ParamGroup) -> std::ops::Range<usize> {
        let mut start = 0;
        for g in ParamGroup::ALL {
            let len = self.group_len(g);
            if g == group {
                return start..start + len;
            }
            start += len;
        }
        start..start
    }

    /// Total number of parameters.
    pub fn len(&self) -> usize {
        ParamGroup::ALL.iter().map(|g| self.group_len(*g)).sum()
    }

    /// True when the model has no parameters (never for a valid model).
    pub fn is_empty(&self) -> bool {
        self.len() == 0
    }
}

impl<T: Scalar> GpParams<T> {
    /// The shape, checked for consistency.
    pub fn shape(&self) -> Result<GpShape> {
        let m = self.pseudo_inputs.nrows();
        let d = self.pseudo_inputs.ncols();
        let e = self.pseudo_targets.ncols();
        let ok = self.pseudo_targets.nrows() == m
            && self.log_lengthscales.shape() == (e, d)
            && self.log_signal_var.len() == e
            && self.log_process_noise.len() == e
            && self.log_obs_noise.len() == e
            && self.linear_mean.shape() == (e, d)
            && m > 0
            && e > 0;
        if !ok {
            return Err(MsgpError::Shape(format!(
                "inconsistent GP parameters: X̄ {}x{}, ȳ {}x{}, log ℓ {}x{}, noise lengths {}/{}/{}, A {}x{}",
                m,
                d,
                self.pseudo_targets.nrows(),
                e,
                self.log_lengthscales.nrows(),
                self.log_lengthscales.ncols(),
                self.log_signal_var.len(),
                self.log_process_noise.len(),
                self.log_obs_noise.len(),
                self.linear_mean.nrows(),
                self.linear_mean.ncols()
            )));
        }
        Ok(GpShape { m, d, e })
    }

    /// Flattens in [`ParamGroup::ALL`] order (matrices row-major).
    pub fn to_flat(&self) -> Vec<T> {
        let mut v = Vec::new();
        for i in 0..self.pseudo_inputs.nrows() {
            v.extend(self.pseudo_inputs.row(i).iter().copied());
        }
        for i in 0..self.pseudo_targets.nrows() {
            v.extend(self.pseudo_targets.row(i).iter().copied());
        }
        for i in 0..self.log_lengthscales.nrows() {
            v.extend(self.log_lengthscales.row(i).iter().copied());
        }
        v.extend(self.log_signal_var.iter().copied());
        v.extend(self.log_process_noise.iter().copied());
        v.extend(self.log_obs_noise.iter().copied());
        for i in 0..self.linear_mean.nrows() {
            v.extend(self.linear_mean.row(i).iter().copied());
        }
        v
    }

    /// Inverse of [`to_flat`](Self::to_flat).
    pub fn from_flat(shape: GpShape, flat: &[T]) -> Result<Self> {
        if flat.len() != shape.len() {
            return Err(MsgpError::Shape(format!(
                "flat parameter vector has {} entries, the model needs {}",
                flat.len(),
                shape.len()
            )));
        }
        let GpShape { m, d, e } = shape;
        let take = |g: ParamGroup| &flat[shape.group_range(g)];
        Ok(Self {
            pseudo_inputs: DMatrix::from_row_slice(m, d, take(ParamGroup::PseudoInputs)),
            pseudo_targets: DMatrix::from_row_slice(m, e, take(ParamGroup::PseudoTargets)),
            log_lengthscales: DMatrix::from_row_slice(e, d, take(ParamGroup::Lengthscales)),
            log_signal_var: DVector::from_column_slice(take(ParamGroup::SignalVar)),
            log_process_noise: DVector::from_column_slice(take(ParamGroup::ProcessNoise)),
            log_obs_noise: DVector::from_column_slice(take(ParamGroup::ObsNoise)),
            linear_mean: DMatrix::from_row_slice(e, d, take(ParamGroup::LinearMean)),
        })
    }

    /// Converts the scalar type (e.g. f64 → dual with zero derivative).
    pub fn map<U: Scalar>(&self, f: impl Fn(T) -> U + Copy) -> GpParams<U> {
        GpParams {
            pseudo_inputs: self.pseudo_inputs.map(f),
            pseudo_targets: self.pseudo_targets.map(f),
            log_lengthscales: self.log_lengthscales.map(f),
            log_signal_var: self.log_signal_var.map(f),
            log_process_noise: self.log_process_noise.map(f),
            log_obs_noise: self.log_obs_noise.map(f),
            linear_mean: self.linear_mean.map(f),
        }
    }
}

/// Per-output quantities that depend only on the parameters, computed once per loss evaluation.
#[derive(Clone, Debug)]
pub struct OutputGp<T: Scalar> {
    /// `1/ℓ_d²`.
    pub inv_l2: Vec<T>,
    /// `σ_f²`.
    pub sf2: T,
    /// Process noise `σ_x²` (floor included).
    pub sx2: T,
    /// Observation noise `σ_y²` (floor included).
    pub sy2: T,
    /// `β = K̃⁻¹ ȳ`.
    pub beta: DVector<T>,
    /// `K̃⁻¹`.
    pub kinv: DMatrix<T>,
    /// Cholesky factor of `K̃`.
    pub chol: Cholesky<T>,
    /// For f64: the weights `ββᵀ − K̃⁻¹` of the f64 kernel's variance reduction, laid out for
    /// its lower-triangle pass over `Q` (`mm_f64::sym_weights`); empty for dual numbers.
    pub q_weights: Vec<T>,
}

/// A GP ready for prediction: the parameters plus per-output factorisations.
#[derive(Clone, Debug)]
pub struct PreparedGp<T: Scalar> {
    /// Pseudo-inputs `X̄` (m × D).
    pub pseudo_inputs: DMatrix<T>,
    /// One entry per output.
    pub outputs: Vec<OutputGp<T>>,
    /// Jitter policy used for later factorisations (moment matching).
    pub jitter: JitterPolicy,
    /// `A` (E × D) of the linear prior mean; `None` for [`MeanFunction::Zero`].
    pub linear_mean: Option<DMatrix<T>>,
    /// How the training loss starts rollouts of measured trajectories.
    pub start: StartWindow,
}

impl<T: Scalar> PreparedGp<T> {
    /// Factorises `K̃_a` for every output; jitter is recorded in `log`.
    pub fn new(params: &GpParams<T>, config: &GpConfig, log: &mut JitterLog) -> Result<Self> {
        let shape = params.shape()?;
        let mut outputs = Vec::with_capacity(shape.e);
        for a in 0..shape.e {
            let inv_l2: Vec<T> = (0..shape.d)
                .map(|d| (-(params.log_lengthscales[(a, d)] * c::<T>(2.0))).exp())
                .collect();
            let sf2 = params.log_signal_var[a].exp();
            let sx2 = params.log_process_noise[a].exp() + c::<T>(config.noise_floor);
            let sy2 = params.log_obs_noise[a].exp() + c::<T>(config.noise_floor);
            let mut k = kernel_matrix(&params.pseudo_inputs, &params.pseudo_inputs, &inv_l2, sf2);
            for i in 0..shape.m {
                k[(i, i)] += sx2;
            }
            let chol = cholesky(&k, &config.jitter, &format!("K + σx² I of output {a}"))?;
            log.record(chol.jitter);
            let target = DVector::from_column_slice(params.pseudo_targets.column(a).as_slice());
            let beta = chol.solve_vec(&target);
            let kinv = T::spd_inverse(&chol);
            let q_weights = T::q_weights(&beta, &kinv);
            outputs.push(OutputGp {
                inv_l2,
                sf2,
                sx2,
                sy2,
                beta,
                kinv,
                chol,
                q_weights,
            });
        }
        Ok(Self {
            pseudo_inputs: params.pseudo_inputs.clone(),
            outputs,
            jitter: config.jitter,
            linear_mean: (config.mean == MeanFunction::Linear).then(|| params.linear_mean.clone()),
            start: config.start,
        })
    }

    /// Input dimension D.
    pub fn input_dim(&self) -> usize {
        self.pseudo_inputs.ncols()
    }

    /// Number of outputs E.
    pub fn output_dim(&self) -> usize {
        self.outputs.len()
    }

    /// Predictive mean and variance of the latent `f_a` at a deterministic input (eq. 13), the
    /// linear prior mean included.
    pub fn predict(&self, x: &[T]) -> Vec<(T, T)> {
        let m = self.pseudo_inputs.nrows();
        let mut row = vec![T::zero(); x.len()];
        self.outputs
            .iter()
            .enumerate()
            .map(|(a, o)| {
                let k = DVector::from_iterator(
                    m,
                    (0..m).map(|i| {
                        for d in 0..x.len() {
                            row[d] = self.pseudo_inputs[(i, d)];
                        }
                        crate::kernel::se_ard(x, &row, &o.inv_l2, o.sf2)
                    }),
                );
                let mut mean = k.dot(&o.beta);
                if let Some(lm) = &self.linear_mean {
                    for (d, xd) in x.iter().enumerate() {
                        mean += lm[(a, d)] * *xd;
                    }
                }
                let var = o.sf2 - (&o.kinv * &k).dot(&k);
                (mean, var)
            })
            .collect()
    }
}
