//! PILCO's trigonometric augmentation: the exact mean and covariance of features of a
//! Gaussian `y ~ N(m, S)` in which an angle output `θ_j` enters as its sine and cosine, and
//! the matrix `C` with `Cov(y, φ) = S C`.
//!
//! `E[sin θ] = e^{−σ²/2} sin μ` and `E[cos θ] = e^{−σ²/2} cos μ`; products by the
//! sum-and-difference identities (`θ_i ± θ_j` is Gaussian); a plain output's covariance with
//! `sin θ_j` by Stein's lemma, `Cov(y_i, sin θ_j) = Cov(y_i, θ_j) E[cos θ_j]` (and
//! `−Cov(y_i, θ_j) E[sin θ_j]` for the cosine). All exact for Gaussian `y`. The saturating cost
//! on a pole's tip ([`crate::policy_search::cost`]) and the RBF policy on angles
//! ([`crate::policy::RbfPolicy`]) use them.

use nalgebra::{DMatrix, DVector};

use crate::numeric::scalar::{Scalar, c};

/// A feature: an output, or the sine or cosine of an angle output.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Feature {
    /// Output `j` itself.
    Plain(usize),
    /// `sin θ_j`.
    Sin(usize),
    /// `cos θ_j`.
    Cos(usize),
}

impl Feature {
    /// The output the feature is of.
    pub fn output(self) -> usize {
        match self {
            Feature::Plain(j) | Feature::Sin(j) | Feature::Cos(j) => j,
        }
    }

    /// Its value at a point (an angle `θ_j = shift_j + scale_j y_j`).
    pub fn at<T: Scalar>(self, y: &[T], (shift, scale): (&[f64], &[f64])) -> T {
        let angle = |j: usize| c::<T>(shift[j]) + y[j] * c::<T>(scale[j]);
        match self {
            Feature::Plain(j) => y[j],
            Feature::Sin(j) => angle(j).sin(),
            Feature::Cos(j) => angle(j).cos(),
        }
    }
}

/// Every output as a feature, an angle's (flagged in `angles`) as its sine and cosine, in
/// output order.
pub fn features(angles: &[bool]) -> Vec<Feature> {
    let mut f = Vec::new();
    for (j, &angle) in angles.iter().enumerate() {
        if angle {
            f.extend([Feature::Sin(j), Feature::Cos(j)]);
        } else {
            f.push(Feature::Plain(j));
        }
    }
    f
}

/// Mean and covariance of features of a Gaussian.
#[derive(Clone, Debug)]
pub struct FeatureMoments<T: Scalar> {
    /// Mean per feature.
    pub mean: DVector<T>,
    /// Covariance of the features.
    pub cov: DMatrix<T>,
}

/// Exact mean and covariance of `features` of `y ~ N(m, s)`, a plain feature in the units of
/// `y`, an angle's sine and cosine of `θ_j = shift_j + scale_j y_j` (radians).
pub fn trig_moments<T: Scalar>(
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

/// `C` (d_y × features) with `Cov(y, φ) = Cov(y) C` for `y ~ N(m, s)`, exact (Stein's lemma):
/// a plain feature's column is the unit vector of its output, `sin θ_j`'s is
/// `scale_j E[cos θ_j]` on output `j`, `cos θ_j`'s is `−scale_j E[sin θ_j]`.
pub fn trig_gain<T: Scalar>(
    features: &[Feature],
    m: &DVector<T>,
    s: &DMatrix<T>,
    (shift, scale): (&[f64], &[f64]),
) -> DMatrix<T> {
    let n = m.len();
    let mut gain = DMatrix::zeros(n, features.len());
    for (f, feature) in features.iter().enumerate() {
        let j = feature.output();
        let damp = (-s[(j, j)] * c::<T>(0.5 * scale[j] * scale[j])).exp() * c::<T>(scale[j]);
        let angle = c::<T>(shift[j]) + m[j] * c::<T>(scale[j]);
        gain[(j, f)] = match feature {
            Feature::Plain(_) => T::one(),
            Feature::Sin(_) => damp * angle.cos(),
            Feature::Cos(_) => -damp * angle.sin(),
        };
    }
    gain
}
