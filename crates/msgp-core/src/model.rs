//! A fitted model in context: NARX spec, GP parameters, normalisation; free simulation and
//! evaluation in original units.

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use crate::data::Normalizer;
use crate::error::{MsgpError, Result};
use crate::gp::{GpConfig, GpParams, PreparedGp};
use crate::linalg::JitterLog;
use crate::narx::NarxSpec;
use crate::rollout::{Control, simulate};
use crate::trajectory::Trajectory;

/// How the model was trained.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Method {
    /// One-step GP-NARX, marginal likelihood (eq. 5).
    GpNarx,
    /// One-step GP-NARX with PILCO's hyperparameter penalties.
    PilcoNarx,
    /// Multi-step GP: trajectory likelihood (eq. 7).
    Msgp,
    /// The linear-Gaussian window model (no GP) by the exact Kalman-filter likelihood
    /// ([`crate::kalman`]).
    LinearKf,
}

impl Method {
    /// Name used on the command line and in reports.
    pub fn name(&self) -> &'static str {
        match self {
            Method::GpNarx => "gp-narx",
            Method::PilcoNarx => "pilco-narx",
            Method::Msgp => "msgp",
            Method::LinearKf => "linear-kf",
        }
    }

    /// Every method, the paper's first.
    pub const ALL: [Method; 4] = [
        Method::Msgp,
        Method::GpNarx,
        Method::PilcoNarx,
        Method::LinearKf,
    ];

    /// The method called `name` (see [`name`](Self::name)).
    pub fn from_name(name: &str) -> Option<Self> {
        Self::ALL.into_iter().find(|m| m.name() == name)
    }
}

/// A model ready to simulate.
#[derive(Clone, Debug)]
pub struct Model {
    /// Training method.
    pub method: Method,
    /// NARX layout.
    pub spec: NarxSpec,
    /// GP parameters (normalised units).
    pub params: GpParams<f64>,
    /// Noise floor and jitter policy.
    pub config: GpConfig,
    /// Training statistics.
    pub normalizer: Normalizer,
}

/// A free simulation in original units.
#[derive(Clone, Debug, PartialEq)]
pub struct Simulation {
    /// First simulated time index (`max(l_y, l_u)`).
    pub start: usize,
    /// Predicted output means (steps × d_y).
    pub mean: DMatrix<f64>,
    /// Predicted output variances, observation noise included (steps × d_y).
    pub var: DMatrix<f64>,
}

/// Free-simulation metrics in original units.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct Metrics {
    /// Root mean squared error of the predicted mean.
    pub rmse: f64,
    /// Mean negative log predictive density per step (per output dimension summed).
    pub nll: f64,
    /// Fraction of measured outputs inside mean ± 2σ.
    pub coverage_2sigma: f64,
    /// Number of evaluated steps.
    pub steps: usize,
}

impl Model {
    /// Open-loop free simulation of `traj` (original units) from its first `max(l_y, l_u)`
    /// samples, driven by its inputs.
    pub fn simulate(&self, traj: &Trajectory) -> Result<Simulation> {
        traj.check(&self.spec)?;
        let norm = self.normalizer.apply(traj);
        let mut log = JitterLog::default();
        let gp = PreparedGp::new(&self.params, &self.config, &mut log)?;
        let steps = simulate(
            &gp,
            &self.spec,
            &norm,
            &Control::FeedForward,
            traj.len(),
            &mut log,
        )?;
        let dy = self.spec.dy;
        let n = steps.len();
        let mut mean = DMatrix::zeros(n, dy);
        let mut var = DMatrix::zeros(n, dy);
        for (i, s) in steps.iter().enumerate() {
            for j in 0..dy {
                mean[(i, j)] = self.normalizer.y_to_original(j, s.mean[j]);
                var[(i, j)] = self.normalizer.y_var_to_original(j, s.cov[(j, j)]);
            }
        }
        Ok(Simulation {
            start: self.spec.warmup(),
            mean,
            var,
        })
    }

    /// Free simulation of `traj` scored against its measured outputs.
    pub fn evaluate(&self, traj: &Trajectory) -> Result<Metrics> {
        let sim = self.simulate(traj)?;
        score(&sim, traj)
    }
}

/// RMSE, mean NLL and 2σ coverage of a simulation against measured outputs.
pub fn score(sim: &Simulation, traj: &Trajectory) -> Result<Metrics> {
    let (n, dy) = sim.mean.shape();
    if n == 0 || sim.start + n > traj.len() {
        return Err(MsgpError::Data(
            "simulation does not fit the measured trajectory".into(),
        ));
    }
    let mut se = 0.0;
    let mut nll = 0.0;
    let mut inside = 0usize;
    for i in 0..n {
        for j in 0..dy {
            let y = traj.y[(sim.start + i, j)];
            let (m, v) = (sim.mean[(i, j)], sim.var[(i, j)].max(f64::MIN_POSITIVE));
            let r = y - m;
            se += r * r;
            nll += 0.5 * (r * r / v + v.ln() + (2.0 * std::f64::consts::PI).ln());
            if r.abs() <= 2.0 * v.sqrt() {
                inside += 1;
            }
        }
    }
    Ok(Metrics {
        rmse: (se / (n * dy) as f64).sqrt(),
        nll: nll / n as f64,
        coverage_2sigma: inside as f64 / (n * dy) as f64,
        steps: n,
    })
}

/// Metrics of several simulations pooled over all steps.
pub fn pool(metrics: &[Metrics], dy: usize) -> Option<Metrics> {
    let steps: usize = metrics.iter().map(|m| m.steps).sum();
    if steps == 0 {
        return None;
    }
    let w = |m: &Metrics| m.steps as f64;
    let n = steps as f64;
    let se: f64 = metrics
        .iter()
        .map(|m| m.rmse * m.rmse * w(m) * dy as f64)
        .sum();
    Some(Metrics {
        rmse: if metrics.len() == 1 {
            metrics[0].rmse
        } else {
            (se / (n * dy as f64)).sqrt()
        },
        nll: if metrics.len() == 1 {
            metrics[0].nll
        } else {
            metrics.iter().map(|m| m.nll * w(m)).sum::<f64>() / n
        },
        coverage_2sigma: if metrics.len() == 1 {
            metrics[0].coverage_2sigma
        } else {
            metrics
                .iter()
                .map(|m| m.coverage_2sigma * w(m))
                .sum::<f64>()
                / n
        },
        steps,
    })
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn pooled_metrics_weight_by_steps() {
        let a = Metrics {
            rmse: 1.0,
            nll: 1.0,
            coverage_2sigma: 1.0,
            steps: 1,
        };
        let b = Metrics {
            rmse: 2.0,
            nll: 4.0,
            coverage_2sigma: 0.0,
            steps: 3,
        };
        let p = pool(&[a, b], 1).expect("steps");
        assert!((p.rmse - (13.0f64 / 4.0).sqrt()).abs() < 1e-15);
        assert!((p.nll - 13.0 / 4.0).abs() < 1e-15);
        assert!((p.coverage_2sigma - 0.25).abs() < 1e-15);
        assert_eq!(pool(&[a], 1), Some(a));
        assert_eq!(pool(&[], 1), None);
    }
}
