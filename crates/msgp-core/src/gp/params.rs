//! The model's parameters `θ` (pseudo-inputs, pseudo-targets, log length-scales, log signal and
//! noise variances, the linear prior mean's coefficients), their shape and the one flat layout
//! the optimisers see ([`GpParams::to_flat`], [`ParamGroup::ALL`] order); the settings that are
//! not optimised ([`GpConfig`]).

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

use crate::error::{MsgpError, Result};
use crate::narx::start_window::StartWindow;
use crate::numeric::linalg::JitterPolicy;

/// Every differentiable parameter of the model (the paper's `θ`), or anything shaped like it:
/// `GpParams<f64>` also holds a gradient, `GpParams<bool>` which parameters an optimiser may
/// move; [`to_flat`](Self::to_flat) is the one flat layout the optimisers see.
#[derive(Clone, Debug, PartialEq)]
pub struct GpParams<T: nalgebra::Scalar> {
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

impl<T: nalgebra::Scalar + Copy> GpParams<T> {
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

    /// Every entry of `shape` set to `value` (e.g. a mask with every parameter free).
    pub fn filled(shape: GpShape, value: T) -> Self {
        let GpShape { m, d, e } = shape;
        Self {
            pseudo_inputs: DMatrix::from_element(m, d, value),
            pseudo_targets: DMatrix::from_element(m, e, value),
            log_lengthscales: DMatrix::from_element(e, d, value),
            log_signal_var: DVector::from_element(e, value),
            log_process_noise: DVector::from_element(e, value),
            log_obs_noise: DVector::from_element(e, value),
            linear_mean: DMatrix::from_element(e, d, value),
        }
    }

    /// Sets every entry of `group` to `value`.
    pub fn fill_group(&mut self, group: ParamGroup, value: T) {
        match group {
            ParamGroup::PseudoInputs => self.pseudo_inputs.fill(value),
            ParamGroup::PseudoTargets => self.pseudo_targets.fill(value),
            ParamGroup::Lengthscales => self.log_lengthscales.fill(value),
            ParamGroup::SignalVar => self.log_signal_var.fill(value),
            ParamGroup::ProcessNoise => self.log_process_noise.fill(value),
            ParamGroup::ObsNoise => self.log_obs_noise.fill(value),
            ParamGroup::LinearMean => self.linear_mean.fill(value),
        }
    }

    /// Converts the scalar type (e.g. f64 → dual with zero derivative).
    pub fn map<U: nalgebra::Scalar + Copy>(&self, f: impl Fn(T) -> U + Copy) -> GpParams<U> {
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

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_typed_mask_flattens_onto_its_groups() {
        let shape = GpShape { m: 3, d: 2, e: 2 };
        for group in ParamGroup::ALL {
            let mut mask = GpParams::filled(shape, false);
            mask.fill_group(group, true);
            let flat = mask.to_flat();
            assert_eq!(flat.len(), shape.len());
            let range = shape.group_range(group);
            for (i, free) in flat.iter().enumerate() {
                assert_eq!(*free, range.contains(&i), "{group:?} entry {i}");
            }
        }
        // matrices flatten by rows: A[(1, 0)] sits at the start of A's second row
        let mut mask = GpParams::filled(shape, false);
        mask.linear_mean[(1, 0)] = true;
        let at = shape.group_range(ParamGroup::LinearMean).start + shape.d;
        assert_eq!(mask.to_flat().iter().position(|&b| b), Some(at));
        let back = GpParams::from_flat(shape, &mask.to_flat()).expect("same shape");
        assert_eq!(back, mask);
    }
}
