//! The expected saturating cost of PILCO: `c(y) = 1 − exp(−½ Σ_f ((φ_f(y) − φ_f(y*)) / w_f)²)`
//! under a Gaussian `y ~ N(m, S)`, in closed form, with its variance for reporting.
//!
//! The features `φ` are the counted outputs (a finite width): an output itself, or, for an
//! angle, the tip of a unit pole at that angle, `(sin θ, cos θ)` (PILCO's cost on the pole's
//! tip: its squared distance to the target's tip is `2 − 2 cos(θ − θ*)`, so a swing through
//! ±π costs what it should and `θ* + 2π` is the target too). The features' mean and covariance
//! under the Gaussian are exact (PILCO's trigonometric moment matching: `E[sin θ] =
//! e^{−σ²/2} sin μ`, products by the sum-and-difference identities, cross-covariances by
//! Stein's lemma); the cost's expectation then takes the features as Gaussian (exact when no
//! output is an angle). With `z = (φ − φ*) / w ~ N(μ_z, Σ_z)`,
//! `E[exp(−½|z|²)] = |I + Σ_z|^{-½} exp(−½ μ_zᵀ (I + Σ_z)⁻¹ μ_z)` and
//! `E[exp(−|z|²)] = |I + 2Σ_z|^{-½} exp(−μ_zᵀ (I + 2Σ_z)⁻¹ μ_z)`.
//!
//! PILCO's several widths (`loss_cp.m`'s width vector): with scales `s_1 … s_K` the cost is
//! the mean of the saturating costs with every width multiplied by `s_k`,
//! `c = 1 − (1/K) Σ_k exp(−½|z|²/s_k²)`: a wide one gives the cost a slope far from the
//! target (a pole hanging 2 tip units from upright costs `1 − e^{−8}` at width 0.5, flat to
//! any search), a narrow one its precision near it. With `r_k = 1/s_k²`, `E[exp(−½ r|z|²)] =
//! |I + rΣ_z|^{-½} exp(−½ r μ_zᵀ (I + rΣ_z)⁻¹ μ_z)`, and the variance takes the products'
//! expectations `E[e_a e_b]` at `r_a + r_b`.

use nalgebra::{DMatrix, DVector};

use crate::error::{MsgpError, Result};
use crate::numeric::linalg::{JitterLog, JitterPolicy, cholesky};
use crate::numeric::scalar::{Scalar, c};

/// A saturating cost around a target.
#[derive(Clone, Debug, PartialEq)]
pub struct SaturatingCost {
    /// `y*` (original units; an angle in radians).
    pub target: DVector<f64>,
    /// Width per output (`f64::INFINITY`: the output does not count); an angle's is a
    /// distance of the unit tip, about radians near the target.
    pub widths: Vec<f64>,
    /// Per output: it is an angle, costed on its unit tip.
    pub angles: Vec<bool>,
    /// The widths' scales (see the module docs; `[1.0]`: the widths alone).
    pub scales: Vec<f64>,
    /// The outputs the cost is given are `shift + scale ∘ y` in original units (a model's
    /// normalised outputs); `None`: given in original units.
    pub units: Option<(DVector<f64>, DVector<f64>)>,
}

/// Mean and variance of the cost under a Gaussian.
#[derive(Clone, Copy, Debug)]
pub struct CostMoments<T: Scalar> {
    /// `E[c(y)]`.
    pub mean: T,
    /// `Var[c(y)]`.
    pub var: T,
}

/// One feature of the cost: an output, or the sine or cosine of an angle output.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Feature {
    Plain(usize),
    Sin(usize),
    Cos(usize),
}

impl Feature {
    fn output(self) -> usize {
        match self {
            Feature::Plain(j) | Feature::Sin(j) | Feature::Cos(j) => j,
        }
    }
}

/// Mean and covariance of features of a Gaussian.
#[derive(Clone, Debug)]
pub struct FeatureMoments<T: Scalar> {
    /// Mean per feature.
    pub mean: DVector<T>,
    /// Covariance of the features.
    pub cov: DMatrix<T>,
}

impl SaturatingCost {
    /// Each output counts on the scale `width` (∞: it does not count); none is an angle.
    pub fn with_widths(target: DVector<f64>, widths: &[f64]) -> Result<Self> {
        let angles = vec![false; widths.len()];
        Self::with_angles(target, widths, &angles)
    }

    /// [`Self::with_widths`] with the outputs flagged in `angles` costed on their unit tip.
    pub fn with_angles(target: DVector<f64>, widths: &[f64], angles: &[bool]) -> Result<Self> {
        let n = target.len();
        if widths.len() != n || widths.iter().any(|w| w.is_nan() || *w <= 0.0) {
            return Err(MsgpError::InvalidSetting {
                name: "cost widths",
                reason: format!("need {n} positive widths, got {widths:?}"),
            });
        }
        if angles.len() != n || target.iter().any(|t| !t.is_finite()) {
            return Err(MsgpError::InvalidSetting {
                name: "cost target",
                reason: format!(
                    "need {n} finite targets and {n} angle flags, got {target:?} and {angles:?}"
                ),
            });
        }
        Ok(Self {
            target,
            widths: widths.to_vec(),
            angles: angles.to_vec(),
            scales: vec![1.0],
            units: None,
        })
    }

    /// The same cost as the mean of its saturating costs at the widths times each of `scales`
    /// (PILCO's several widths; see the module docs).
    pub fn with_scales(self, scales: &[f64]) -> Result<Self> {
        if scales.is_empty() || scales.iter().any(|s| !(s.is_finite() && *s > 0.0)) {
            return Err(MsgpError::InvalidSetting {
                name: "cost width scales",
                reason: format!("need one or more positive finite scales, got {scales:?}"),
            });
        }
        Ok(Self {
            scales: scales.to_vec(),
            ..self
        })
    }

    /// The same cost on outputs given as `shift + scale ∘ y`.
    pub fn in_units(&self, shift: DVector<f64>, scale: DVector<f64>) -> Self {
        Self {
            units: Some((shift, scale)),
            ..self.clone()
        }
    }

    /// The counted features, in output order.
    fn features(&self) -> Vec<Feature> {
        let mut f = Vec::new();
        for (j, w) in self.widths.iter().enumerate() {
            if w.is_finite() {
                if self.angles[j] {
                    f.extend([Feature::Sin(j), Feature::Cos(j)]);
                } else {
                    f.push(Feature::Plain(j));
                }
            }
        }
        f
    }

    /// Exact mean and covariance of the counted features of `y ~ N(mean, cov)` (original
    /// units): an output itself, an angle's `(sin θ, cos θ)`.
    pub fn feature_moments<T: Scalar>(
        &self,
        mean: &DVector<T>,
        cov: &DMatrix<T>,
    ) -> FeatureMoments<T> {
        let (shift, scale) = self.unit_map(mean.len());
        trig_moments(&self.features(), mean, cov, (&shift, &scale))
    }

    /// `(shift, scale)` per output: the identity in original units.
    fn unit_map(&self, n: usize) -> (Vec<f64>, Vec<f64>) {
        match &self.units {
            Some((shift, scale)) => (
                shift.iter().copied().collect(),
                scale.iter().copied().collect(),
            ),
            None => (vec![0.0; n], vec![1.0; n]),
        }
    }

    /// The cost at a point (original units).
    pub fn at(&self, y: &[f64]) -> f64 {
        let features = self.features();
        let n = y.len();
        let ones = (vec![0.0; n], vec![1.0; n]);
        let point = trig_moments(
            &features,
            &DVector::from_column_slice(y),
            &DMatrix::zeros(n, n),
            (&ones.0, &ones.1),
        );
        let (target, weight) = self.targets_and_weights(&features, &ones);
        let q: f64 = (0..features.len())
            .map(|f| (weight[f] * (point.mean[f] - target[f])).powi(2))
            .sum();
        let k = self.scales.len() as f64;
        1.0 - self
            .scales
            .iter()
            .map(|s| (-0.5 * q / (s * s)).exp())
            .sum::<f64>()
            / k
    }

    /// The target's features and each feature's weight, in the given units: a plain
    /// output's target `(y*_j − shift_j) / scale_j` and weight `scale_j / w_j` (the cost on
    /// normalised outputs), an angle's tip in original units and weight `1 / w_j`.
    fn targets_and_weights(
        &self,
        features: &[Feature],
        (shift, scale): &(Vec<f64>, Vec<f64>),
    ) -> (Vec<f64>, Vec<f64>) {
        let t = &self.target;
        features
            .iter()
            .map(|f| {
                let j = f.output();
                let inv_w = 1.0 / self.widths[j];
                match *f {
                    Feature::Plain(j) => ((t[j] - shift[j]) / scale[j], inv_w * scale[j]),
                    Feature::Sin(j) => (t[j].sin(), inv_w),
                    Feature::Cos(j) => (t[j].cos(), inv_w),
                }
            })
            .unzip()
    }

    /// `E[c]` and `Var[c]` for `y ~ N(mean, cov)` (in [`Self::units`]).
    pub fn moments<T: Scalar>(
        &self,
        mean: &DVector<T>,
        cov: &DMatrix<T>,
        jitter: &JitterPolicy,
        log: &mut JitterLog,
    ) -> Result<CostMoments<T>> {
        let units = self.unit_map(mean.len());
        let features = self.features();
        let fm = trig_moments(&features, mean, cov, (&units.0, &units.1));
        let (target, weight) = self.targets_and_weights(&features, &units);
        let k = features.len();
        let w = |f: usize| c::<T>(weight[f]);
        let mu = DVector::from_fn(k, |f, _| w(f) * (fm.mean[f] - c::<T>(target[f])));
        let sz = DMatrix::from_fn(k, k, |f, g| w(f) * fm.cov[(f, g)] * w(g));
        // E[exp(−½ r |z|²)]
        let mut gauss = |r: f64| -> Result<T> {
            let m = DMatrix::<T>::identity(k, k) + &sz * c::<T>(r);
            let ch = cholesky(&m, jitter, "I + Σ_z")?;
            log.record(ch.jitter);
            let sol = ch.solve_vec(&mu);
            Ok((-(ch.log_det() + mu.dot(&sol) * c::<T>(r)) * c::<T>(0.5)).exp())
        };
        let r: Vec<f64> = self.scales.iter().map(|s| 1.0 / (s * s)).collect();
        let inv_k = c::<T>(1.0 / r.len() as f64);
        let e: Vec<T> = r.iter().map(|&r| gauss(r)).collect::<Result<_>>()?;
        let mean_e = e.iter().fold(T::zero(), |a, &b| a + b) * inv_k;
        let mut second = T::zero();
        for (a, &ra) in r.iter().enumerate() {
            for (b, &rb) in r.iter().enumerate().skip(a) {
                let both = gauss(ra + rb)?;
                second += if a == b { both } else { both * c::<T>(2.0) };
            }
        }
        Ok(CostMoments {
            mean: T::one() - mean_e,
            var: second * inv_k * inv_k - mean_e * mean_e,
        })
    }
}

/// Exact mean and covariance of `features` of `y ~ N(m, s)`, a plain feature in the units of
/// `y`, an angle's sine and cosine of `θ_j = shift_j + scale_j y_j` (radians).
fn trig_moments<T: Scalar>(
    features: &[Feature],
    m: &DVector<T>,
    s: &DMatrix<T>,
    (shift, scale): (&[f64], &[f64]),
) -> FeatureMoments<T> {
    let half = c::<T>(0.5);
    // the angles' mean and covariance in radians
    let am = |j: usize| c::<T>(shift[j]) + m[j] * c::<T>(scale[j]);
    let ac = |i: usize, j: usize| s[(i, j)] * c::<T>(scale[i] * scale[j]);
    // E[sin θ], E[cos θ] of output j
    let es = |j: usize| (-ac(j, j) * half).exp() * am(j).sin();
    let ec = |j: usize| (-ac(j, j) * half).exp() * am(j).cos();
    let mean = DVector::from_fn(features.len(), |f, _| match features[f] {
        Feature::Plain(j) => m[j],
        Feature::Sin(j) => es(j),
        Feature::Cos(j) => ec(j),
    });
    // E[cos(θ_i ± θ_j)] and E[sin(θ_i ± θ_j)]: θ_i ± θ_j is Gaussian
    let pair = |i: usize, j: usize, sign: f64| {
        let v = ac(i, i) + ac(j, j) + ac(i, j) * c::<T>(2.0 * sign);
        let a = am(i) + am(j) * c::<T>(sign);
        let damp = (-v * half).exp();
        (damp * a.cos(), damp * a.sin())
    };
    let second = |f: Feature, g: Feature| -> T {
        use Feature::{Cos, Plain, Sin};
        match (f, g) {
            (Plain(i), Plain(j)) => s[(i, j)],
            (Plain(i), Sin(j)) | (Sin(j), Plain(i)) => s[(i, j)] * c::<T>(scale[j]) * ec(j),
            (Plain(i), Cos(j)) | (Cos(j), Plain(i)) => -s[(i, j)] * c::<T>(scale[j]) * es(j),
            (Sin(i), Sin(j)) => {
                let ((cm, _), (cp, _)) = (pair(i, j, -1.0), pair(i, j, 1.0));
                (cm - cp) * half - es(i) * es(j)
            }
            (Cos(i), Cos(j)) => {
                let ((cm, _), (cp, _)) = (pair(i, j, -1.0), pair(i, j, 1.0));
                (cm + cp) * half - ec(i) * ec(j)
            }
            (Sin(i), Cos(j)) | (Cos(j), Sin(i)) => {
                let ((_, sm), (_, sp)) = (pair(i, j, -1.0), pair(i, j, 1.0));
                (sp + sm) * half - es(i) * ec(j)
            }
        }
    };
    let n = features.len();
    let cov = DMatrix::from_fn(n, n, |a, b| second(features[a], features[b]));
    FeatureMoments { mean, cov }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::numeric::dual::moments_gradient;
    use std::f64::consts::PI;

    fn pole() -> SaturatingCost {
        SaturatingCost::with_angles(
            DVector::from_vec(vec![0.0, 0.1]),
            &[0.5, 0.3],
            &[true, false],
        )
        .expect("cost")
    }

    /// On the tip, a swing through ±π costs the same on either side, a full turn is the
    /// target again, and hanging costs the most a unit tip can be from upright.
    #[test]
    fn a_swing_through_pi_costs_what_it_should() {
        let cost = pole();
        let a = cost.at(&[PI - 0.01, 0.1]);
        let b = cost.at(&[-PI + 0.01, 0.1]);
        assert!((a - b).abs() < 1e-12, "{a} vs {b}");
        assert!(cost.at(&[2.0 * PI, 0.1]).abs() < 1e-12);
        let hanging = 1.0 - (-0.5 * 4.0 / (0.5f64 * 0.5)).exp();
        assert!((cost.at(&[PI, 0.1]) - hanging).abs() < 1e-12);
        // near the target the tip's distance is the angle's
        let small = cost.at(&[1e-3, 0.1]);
        let plain = 1.0 - (-0.5 * (1e-3f64 / 0.5).powi(2)).exp();
        // (2 − 2 cos θ = θ² (1 − θ²/12 + …): 8·10⁻⁸ relative at 1 mrad)
        assert!((small - plain).abs() < 1e-6 * plain, "{small} vs {plain}");
    }

    /// At a point (zero covariance) the expected cost is the cost there, in original and in
    /// scaled units alike.
    #[test]
    fn the_expectation_at_a_point_is_the_cost_and_units_only_rescale() {
        let cost = pole();
        let (y, s) = (DVector::from_vec(vec![2.5, -0.4]), DMatrix::zeros(2, 2));
        let mut log = JitterLog::default();
        let e = cost
            .moments(&y, &s, &JitterPolicy::default(), &mut log)
            .expect("moments");
        assert!((e.mean - cost.at(y.as_slice())).abs() < 1e-12);
        assert!(e.var.abs() < 1e-12);
        let (shift, scale) = (
            DVector::from_vec(vec![1.0, -0.2]),
            DVector::from_vec(vec![2.0, 0.5]),
        );
        let z = DVector::from_fn(2, |i, _| (y[i] - shift[i]) / scale[i]);
        let sz = DMatrix::from_row_slice(2, 2, &[0.04, 0.01, 0.01, 0.09]);
        let so = DMatrix::from_fn(2, 2, |i, j| sz[(i, j)] * scale[i] * scale[j]);
        let scaled = cost.in_units(shift, scale);
        let jp = JitterPolicy::default();
        let a = scaled.moments(&z, &sz, &jp, &mut log).expect("scaled");
        let b = cost.moments(&y, &so, &jp, &mut log).expect("original");
        assert!((a.mean - b.mean).abs() < 1e-14 && (a.var - b.var).abs() < 1e-14);
    }

    /// Several widths: at a point the cost is the mean of the single-width costs; under a
    /// Gaussian on plain outputs (where the closed form is exact) mean and variance match a
    /// Monte Carlo estimate within 4 standard errors, and `[1.0]` is the single width.
    #[test]
    fn several_widths_are_the_mean_of_their_costs_and_match_monte_carlo() {
        use rand::SeedableRng;
        use rand_distr::{Distribution, StandardNormal};
        let target = DVector::from_vec(vec![0.3, -0.2]);
        let one = SaturatingCost::with_widths(target.clone(), &[0.5, 0.8]).expect("cost");
        let two = one.clone().with_scales(&[1.0, 3.0]).expect("scales");
        let wide = SaturatingCost::with_widths(target, &[1.5, 2.4]).expect("cost");
        let y = [1.1, 0.4];
        let mean_of = 0.5 * (one.at(&y) + wide.at(&y));
        assert!((two.at(&y) - mean_of).abs() < 1e-14);
        assert_eq!(one.clone().with_scales(&[1.0]).expect("one"), one);
        assert!(one.clone().with_scales(&[]).is_err() && one.with_scales(&[0.0]).is_err());
        let m = DVector::from_vec(vec![0.9, 0.1]);
        let s = DMatrix::from_row_slice(2, 2, &[0.25, 0.06, 0.06, 0.16]);
        let e = two
            .moments(&m, &s, &JitterPolicy::default(), &mut JitterLog::default())
            .expect("moments");
        let l = s.clone().cholesky().expect("spd").l();
        let mut rng = rand::rngs::Xoshiro256PlusPlus::seed_from_u64(7);
        let n = 200_000;
        let draws: Vec<f64> = (0..n)
            .map(|_| {
                let z = DVector::from_fn(2, |_, _| StandardNormal.sample(&mut rng));
                let y = &m + &l * z;
                two.at(y.as_slice())
            })
            .collect();
        let mc_mean = draws.iter().sum::<f64>() / n as f64;
        let mc_var = draws.iter().map(|c| (c - mc_mean).powi(2)).sum::<f64>() / (n - 1) as f64;
        let se = (mc_var / n as f64).sqrt();
        assert!(
            (e.mean - mc_mean).abs() < 4.0 * se,
            "{} vs {mc_mean} ± {se}",
            e.mean
        );
        // the variance's standard error, from the fourth moment
        let m4 = draws.iter().map(|c| (c - mc_mean).powi(4)).sum::<f64>() / n as f64;
        let se_var = ((m4 - mc_var * mc_var) / n as f64).sqrt();
        assert!(
            (e.var - mc_var).abs() < 4.0 * se_var,
            "{} vs {mc_var} ± {se_var}",
            e.var
        );
        assert!(
            e.var > 20.0 * se_var,
            "a variance the test can tell: {}",
            e.var
        );
    }

    /// The expected tip cost's gradient in the mean and covariance (duals, as the adjoint
    /// sweep takes it) against central finite differences, with one width and with two.
    #[test]
    fn the_tip_cost_gradient_matches_finite_differences() {
        for cost in [pole(), pole().with_scales(&[1.0, 2.5]).expect("scales")] {
            tip_cost_gradient(&cost);
        }
    }

    fn tip_cost_gradient(cost: &SaturatingCost) {
        let m = DVector::from_vec(vec![0.9, 0.3]);
        let s = DMatrix::from_row_slice(2, 2, &[0.3, 0.05, 0.05, 0.02]);
        let jp = JitterPolicy::default();
        let f = |m: &DVector<f64>, s: &DMatrix<f64>| {
            cost.moments(m, s, &jp, &mut JitterLog::default())
                .expect("f")
                .mean
        };
        let (gm, gs) = moments_gradient(&m, &s, |m, s| {
            Ok(cost.moments(m, s, &jp, &mut JitterLog::default())?.mean)
        })
        .expect("duals");
        let h = 1e-6;
        for i in 0..2 {
            let (mut p, mut q) = (m.clone(), m.clone());
            p[i] += h;
            q[i] -= h;
            let fd = (f(&p, &s) - f(&q, &s)) / (2.0 * h);
            assert!((gm[i] - fd).abs() < 1e-8, "mean {i}: {} vs {fd}", gm[i]);
            for j in 0..2 {
                let (mut p, mut q) = (s.clone(), s.clone());
                p[(i, j)] += h;
                q[(i, j)] -= h;
                let fd = (f(&m, &p) - f(&m, &q)) / (2.0 * h);
                assert!(
                    (gs[(i, j)] - fd).abs() < 1e-8,
                    "cov {i}{j}: {} vs {fd}",
                    gs[(i, j)]
                );
            }
        }
        assert!(gm[0].abs() > 1e-2, "the angle matters: {gm}");
    }
}
