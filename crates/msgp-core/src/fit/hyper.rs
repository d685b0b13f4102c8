//! One output's GP hyperparameters as the one-step fits optimise them (log length-scales, log
//! signal variance, log noise above the floor) and PILCO's penalties on them (appendix A.1.1;
//! PILCO's `hypCurb`: `Σ_d ((log ℓ_d − log std(x_d)) / log 100)^30 +
//! ((log σ_f − log σ_n) / log 500)^30`), shared by the exact marginal likelihood
//! ([`super::one_step`]) and the variational bound ([`super::vfe`]).

/// Hyperparameters of one output's GP.
#[derive(Clone, Debug, PartialEq)]
pub struct Hyper {
    /// `log ℓ_d`.
    pub log_lengthscales: Vec<f64>,
    /// `log σ_f²`.
    pub log_signal_var: f64,
    /// `log(σ_n² − floor)`.
    pub log_noise: f64,
}

impl Hyper {
    pub(crate) fn to_vec(&self) -> Vec<f64> {
        let mut v = self.log_lengthscales.clone();
        v.push(self.log_signal_var);
        v.push(self.log_noise);
        v
    }
    pub(crate) fn from_vec(v: &[f64]) -> Self {
        let d = v.len() - 2;
        Self {
            log_lengthscales: v[..d].to_vec(),
            log_signal_var: v[d],
            log_noise: v[d + 1],
        }
    }
    /// `1/ℓ_d²`.
    pub(crate) fn inv_l2(&self) -> Vec<f64> {
        self.log_lengthscales
            .iter()
            .map(|l| (-2.0 * l).exp())
            .collect()
    }
}

/// PILCO's penalties (`hypCurb`) at `h` with `σ_n² = sn2`: their value, their gradient added
/// to `grad` (laid out as [`Hyper::to_vec`]).
pub(crate) fn pilco_penalty(h: &Hyper, std: &[f64], sn2: f64, grad: &mut [f64]) -> f64 {
    let d = h.log_lengthscales.len();
    let p30 = |z: f64| z.powi(30);
    let dp30 = |z: f64| 30.0 * z.powi(29);
    let mut value = 0.0;
    let lls = 100f64.ln();
    for dd in 0..d {
        let z = (h.log_lengthscales[dd] - std[dd].ln()) / lls;
        value += p30(z);
        grad[dd] += dp30(z) / lls;
    }
    let lsnr = 500f64.ln();
    // log σ_f − log σ_n, with σ_n² = floor + e^θ
    let z = (0.5 * h.log_signal_var - 0.5 * sn2.ln()) / lsnr;
    value += p30(z);
    grad[d] += dp30(z) * 0.5 / lsnr;
    grad[d + 1] -= dp30(z) * 0.5 / lsnr * h.log_noise.exp() / sn2;
    value
}
