//! The variational sparse GP's one-step objective (Titsias 2009, "Variational learning of
//! inducing variables in sparse Gaussian processes"): the negative collapsed bound
//!
//! `F = −log N(y; 0, Q + σ²I) + tr(K_nn − Q) / (2σ²)`, `Q = K_nm K_mm⁻¹ K_mn`,
//!
//! minimised jointly in the kernel hyperparameters, the noise and the `m` pseudo-inputs `Z`
//! (shared by the outputs; the bound of several outputs is the sum of theirs). It is the
//! marginal likelihood of a GP with 100 inducing inputs as the sparse-GP packages compute it
//! (GPy's `SparseGPRegression`, GPflow's `SGPR`), the reading of the paper's GP-NARX baseline
//! ("each method utilizes 100 inducing inputs", hyperparameters "by the maximum likelihood
//! objective", appendix A.1.1). Unlike the exact marginal likelihood it cannot fit the
//! one-step noise away with short length-scales that only the full data set supports: on
//! actuator the exact optimum has noise std 0.0034 and median length-scale 3.6 (normalised),
//! the bound's 0.031 and 393 (`docs/design.md`).
//!
//! Everything is `O(n m²)` through `B = σ² K_mm + K_mn K_nm`:
//! `yᵀ(Q + σ²I)⁻¹y = (yᵀy − cᵀB⁻¹c)/σ²` with `c = K_mn y`,
//! `log|Q + σ²I| = log|B| − log|K_mm| + (n − m) log σ²`, and for the gradient
//! `K_mn (Q + σ²I)⁻¹ = K_mm B⁻¹ K_mn`. With `G = ∂F/∂Q = ½(A⁻¹ − ααᵀ) − I/(2σ²)`
//! (`A = Q + σ²I`, `α = A⁻¹y`): `∂F/∂K_mn = 2 K_mm⁻¹ K_mn G` and
//! `∂F/∂K_mm = −K_mm⁻¹ K_mn G K_nm K_mm⁻¹`, chained through the SE-ARD kernel to the
//! length-scales, the signal variance and `Z`.
//!
//! `K_mm` carries a jitter proportional to the signal variance (`1e-6 σ_f²`), part of the
//! objective (so its gradient is exact), as the packages do.

use nalgebra::{DMatrix, DVector};

use crate::error::Result;
use crate::gp::GpConfig;
use crate::gp::kernel::kernel_matrix;
use crate::numeric::dense::DenseChol;
use crate::numeric::linalg::JitterLog;
use crate::optim::Objective;

use super::hyper::{Hyper, pilco_penalty};

const LN_2PI: f64 = 1.837_877_066_409_345_3;

/// Relative jitter on `K_mm`'s diagonal (times `σ_f²`).
pub const KMM_JITTER: f64 = 1e-6;

/// The negative collapsed bound of every output, with shared pseudo-inputs.
///
/// Parameters: per output `[log ℓ_1 … log ℓ_D, log σ_f², log(σ_n² − floor)]`, then `Z`
/// (m × D, column-major), centred by the inputs' column means (the kernel sees differences).
pub(crate) struct Vfe {
    xc: DMatrix<f64>,
    /// Each output's targets; `None`: the output has no GP (not in the bound).
    ys: Vec<Option<DVector<f64>>>,
    /// Inputs' column means (added back to `Z` by [`Vfe::pseudo_inputs`]).
    offset: DVector<f64>,
    m: usize,
    config: GpConfig,
    /// `Some(std of each input dimension)` adds PILCO's penalties.
    pilco_std: Option<Vec<f64>>,
    /// Relative jitter on `K_mm` ([`KMM_JITTER`]; the tests take it off).
    pub(crate) kmm_jitter: f64,
    pub log: JitterLog,
}

/// One output's bound with its gradient in the hyperparameters and in `Z`.
struct OutputBound {
    value: f64,
    hyper: Vec<f64>,
    z: DMatrix<f64>,
}

impl Vfe {
    pub(crate) fn new(
        x: &DMatrix<f64>,
        ys: Vec<Option<DVector<f64>>>,
        m: usize,
        config: GpConfig,
        pilco_std: Option<Vec<f64>>,
    ) -> Self {
        let offset = DVector::from_fn(x.ncols(), |k, _| x.column(k).mean());
        let mut xc = x.clone();
        for (k, mut col) in xc.column_iter_mut().enumerate() {
            col.add_scalar_mut(-offset[k]);
        }
        Self {
            xc,
            ys,
            offset,
            m,
            config,
            pilco_std,
            kmm_jitter: KMM_JITTER,
            log: JitterLog::default(),
        }
    }

    /// Parameter vector from the outputs' hyperparameters and pseudo-inputs `z` (original
    /// coordinates).
    pub(crate) fn pack(&self, hypers: &[Hyper], z: &DMatrix<f64>) -> Vec<f64> {
        let mut v: Vec<f64> = hypers.iter().flat_map(|h| h.to_vec()).collect();
        for k in 0..z.ncols() {
            v.extend(z.column(k).iter().map(|zi| zi - self.offset[k]));
        }
        v
    }

    /// Output `a`'s hyperparameters in `p`.
    pub(crate) fn hyper(&self, p: &[f64], a: usize) -> Hyper {
        let d = self.xc.ncols();
        Hyper::from_vec(&p[a * (d + 2)..(a + 1) * (d + 2)])
    }

    /// The pseudo-inputs in `p`, in the inputs' coordinates.
    pub(crate) fn pseudo_inputs(&self, p: &[f64]) -> DMatrix<f64> {
        let mut z = self.centred_z(p);
        for (k, mut col) in z.column_iter_mut().enumerate() {
            col.add_scalar_mut(self.offset[k]);
        }
        z
    }

    fn centred_z(&self, p: &[f64]) -> DMatrix<f64> {
        let d = self.xc.ncols();
        let start = self.ys.len() * (d + 2);
        DMatrix::from_column_slice(self.m, d, &p[start..start + self.m * d])
    }

    fn output_bound(
        &mut self,
        h: &Hyper,
        y: &DVector<f64>,
        z: &DMatrix<f64>,
    ) -> Result<OutputBound> {
        let (n, d) = self.xc.shape();
        let m = self.m;
        let inv_l2 = h.inv_l2();
        let sf2 = h.log_signal_var.exp();
        let sn2 = self.config.noise_floor + h.log_noise.exp();
        let mut kmm = kernel_matrix(z, z, &inv_l2, sf2);
        for i in 0..m {
            kmm[(i, i)] += self.kmm_jitter * sf2;
        }
        let kmn = kernel_matrix(z, &self.xc, &inv_l2, sf2);
        let kmm_ch = DenseChol::new(&kmm, &self.config.jitter, "VFE K_mm", &mut self.log)?;
        let p_mat = &kmn * kmn.transpose();
        let b = &kmm * sn2 + &p_mat;
        let b_ch = DenseChol::new(
            &b,
            &self.config.jitter,
            "VFE σ² K_mm + K_mn K_nm",
            &mut self.log,
        )?;
        let c = &kmn * y;
        let cm = DMatrix::from_column_slice(m, 1, c.as_slice());
        let bc = b_ch.solve(&cm);
        let yy = y.dot(y);
        let cbc = c.dot(&bc.column(0));
        let kmm_inv = kmm_ch.inverse();
        let tr_q = kmm_inv.component_mul(&p_mat).sum();
        let value = 0.5 * (yy - cbc) / sn2
            + 0.5 * (b_ch.log_det() - kmm_ch.log_det() + (n - m) as f64 * sn2.ln())
            + 0.5 * n as f64 * LN_2PI
            + 0.5 * (n as f64 * sf2 - tr_q) / sn2;

        // α = A⁻¹ y = (y − K_nm B⁻¹ c)/σ²
        let alpha = (y - kmn.tr_mul(&bc).column(0)) / sn2;
        let ka = &kmn * &alpha;
        let binv_kmn = b_ch.solve(&kmn);
        let binv_p = b_ch.solve(&p_mat);
        // K_mn G and K_mn G K_nm
        let mut kg = (&kmm * &binv_kmn) * 0.5 - &kmn * (0.5 / sn2);
        kg -= &ka * alpha.transpose() * 0.5;
        let mut kgk = (&kmm * &binv_p) * 0.5 - &p_mat * (0.5 / sn2);
        kgk -= &ka * ka.transpose() * 0.5;
        let d_kmn = (&kmm_inv * &kg) * 2.0;
        let d_kmm_raw = -(&kmm_inv * &kgk * &kmm_inv);
        let d_kmm = (&d_kmm_raw + d_kmm_raw.transpose()) * 0.5;
        // ∂F/∂σ², explicit: ½ tr(A⁻¹) − ½ αᵀα − (n σ_f² − tr Q)/(2σ⁴)
        let tr_binv_p = binv_p.trace();
        let d_sn2 = 0.5 * (n as f64 - tr_binv_p) / sn2
            - 0.5 * alpha.dot(&alpha)
            - 0.5 * (n as f64 * sf2 - tr_q) / (sn2 * sn2);

        let w_mm = d_kmm.component_mul(&kmm);
        let w_mn = d_kmn.component_mul(&kmn);
        let mut hyper = vec![0.0; d + 2];
        hyper[d] = w_mm.sum() + w_mn.sum() + 0.5 * n as f64 * sf2 / sn2;
        hyper[d + 1] = d_sn2 * h.log_noise.exp();
        // Σᵢⱼ Wᵢⱼ (aᵢ − bⱼ)² = Σᵢ aᵢ² rᵢ + Σⱼ bⱼ² cⱼ − 2 Σᵢ aᵢ (W b)ᵢ per dimension
        let mm_rows = w_mm.column_sum();
        let mm_cols = w_mm.row_sum();
        let mn_rows = w_mn.column_sum();
        let mn_cols = w_mn.row_sum();
        let wz = &w_mm * z;
        let wtz = w_mm.tr_mul(z);
        let wx = &w_mn * &self.xc;
        let mut gz = DMatrix::zeros(m, d);
        for k in 0..d {
            let mut q = 0.0;
            for i in 0..m {
                let zi = z[(i, k)];
                q += zi * zi * (mm_rows[i] + mm_cols[i] + mn_rows[i])
                    - 2.0 * zi * (wz[(i, k)] + wx[(i, k)]);
            }
            for j in 0..n {
                let xj = self.xc[(j, k)];
                q += xj * xj * mn_cols[j];
            }
            hyper[k] = q * inv_l2[k];
            // ∂k(zᵢ, b)/∂zᵢ = −k (zᵢ − b)/ℓ²; K_mm has zᵢ in both arguments
            for i in 0..m {
                let zi = z[(i, k)];
                let from_mm = zi * (mm_rows[i] + mm_cols[i]) - wz[(i, k)] - wtz[(i, k)];
                let from_mn = zi * mn_rows[i] - wx[(i, k)];
                gz[(i, k)] = -(from_mm + from_mn) * inv_l2[k];
            }
        }
        Ok(OutputBound {
            value,
            hyper,
            z: gz,
        })
    }
}

impl Objective for Vfe {
    fn value_and_gradient(&mut self, p: &[f64]) -> Result<(f64, Vec<f64>)> {
        let d = self.xc.ncols();
        let z = self.centred_z(p);
        let mut grad = vec![0.0; p.len()];
        let mut value = 0.0;
        let zstart = self.ys.len() * (d + 2);
        let ys = std::mem::take(&mut self.ys);
        let mut result = Ok(());
        for (a, y) in ys.iter().enumerate() {
            let Some(y) = y else { continue };
            let h = self.hyper(p, a);
            let out = match self.output_bound(&h, y, &z) {
                Ok(o) => o,
                Err(e) => {
                    result = Err(e);
                    break;
                }
            };
            value += out.value;
            for (g, v) in grad[zstart..].iter_mut().zip(out.z.iter()) {
                *g += v;
            }
            let block = &mut grad[a * (d + 2)..(a + 1) * (d + 2)];
            for (g, v) in block.iter_mut().zip(&out.hyper) {
                *g += v;
            }
            if let Some(std) = &self.pilco_std {
                let sn2 = self.config.noise_floor + h.log_noise.exp();
                value += pilco_penalty(&h, std, sn2, block);
            }
        }
        self.ys = ys;
        result?;
        Ok((value, grad))
    }
}

#[cfg(test)]
pub(crate) mod tests {
    use super::*;

    pub(crate) fn problem(n: usize) -> (DMatrix<f64>, DVector<f64>) {
        let x = DMatrix::from_fn(n, 3, |i, k| {
            ((i * 7 + k * 3) as f64 * 0.37).sin() + 0.2 * k as f64
        });
        let y = DVector::from_fn(n, |i, _| {
            (x[(i, 0)] * 2.0).sin() + 0.3 * x[(i, 2)] + 0.05 * ((i as f64) * 1.3).cos()
        });
        (x, y)
    }

    pub(crate) fn hyper() -> Hyper {
        Hyper {
            log_lengthscales: vec![-0.3, 0.4, 0.1],
            log_signal_var: 0.2,
            log_noise: -3.0,
        }
    }

    fn check_gradient(pilco: bool) {
        let (x, y) = problem(40);
        let y2 = y.map(|v| (2.0 * v).cos());
        // the inputs' spread (what the fit hands PILCO's penalties)
        let std: Vec<f64> = x
            .column_iter()
            .map(|c| c.variance().sqrt().max(1e-6))
            .collect();
        let z = DMatrix::from_fn(6, 3, |i, k| x[(i * 6 + 1, k)] + 0.05 * k as f64);
        let mut vfe = Vfe::new(
            &x,
            vec![Some(y), None, Some(y2)],
            6,
            GpConfig::default(),
            pilco.then_some(std),
        );
        let h2 = Hyper {
            log_lengthscales: vec![0.2, -0.1, 0.5],
            log_signal_var: -0.4,
            log_noise: -2.0,
        };
        let p = vfe.pack(&[hyper(), hyper(), h2], &z);
        let (_, g) = vfe.value_and_gradient(&p).expect("value");
        for i in 0..p.len() {
            let h = 1e-4;
            let mut f = |d: f64| {
                let mut q = p.clone();
                q[i] += d;
                vfe.value_and_gradient(&q).expect("value").0
            };
            let fd = (8.0 * (f(h) - f(-h)) - (f(2.0 * h) - f(-2.0 * h))) / (12.0 * h);
            assert!(
                (fd - g[i]).abs() <= 1e-6 * fd.abs().max(1.0),
                "param {i}: analytic {} vs fd {fd}",
                g[i]
            );
        }
        // the second output has no GP: its block has no gradient
        assert!(g[5..10].iter().all(|v| *v == 0.0));
    }

    #[test]
    fn bound_gradient_matches_finite_differences_in_every_parameter() {
        check_gradient(false);
        check_gradient(true);
    }
}
