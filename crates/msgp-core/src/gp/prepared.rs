//! A GP ready for prediction: per-output factorisations of `K̃ = K(X̄, X̄) + σ_x² I` and the
//! vectors of eq. (13), computed once per loss evaluation from [`GpParams`].

use nalgebra::{DMatrix, DVector};

use super::kernel::{KernelScalar, kernel_matrix, se_ard};
use super::params::{GpConfig, GpParams, MeanFunction};
use crate::error::Result;
use crate::narx::start_window::StartWindow;
use crate::numeric::linalg::{Cholesky, JitterLog, JitterPolicy, cholesky};
use crate::numeric::scalar::{Scalar, c};

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
    /// its lower-triangle pass over `Q` (`numeric::simd::sym_weights`); empty for dual numbers.
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

impl<T: KernelScalar> PreparedGp<T> {
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
                        se_ard(x, &row, &o.inv_l2, o.sf2)
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
