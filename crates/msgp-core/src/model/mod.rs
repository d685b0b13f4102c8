//! A fitted model in context: NARX spec, GP parameters, normalisation; free simulation and
//! evaluation in original units.

use nalgebra::DMatrix;
use serde::{Deserialize, Serialize};

use crate::data::Normalizer;
use crate::data::Trajectory;
use crate::data::dataset::Part;
use crate::error::{MsgpError, Result};
use crate::gp::{GpConfig, GpParams, PreparedGp};
use crate::loss::{Complexity, msgp_loss};
use crate::narx::NarxSpec;
use crate::numeric::linalg::JitterLog;
use crate::policy::PolicySpec;
use crate::rollout::{
    Control, Episode, Excitation, FunctionDraws, sample_free_runs, simulate, simulate_correlated,
    simulate_mean_feedback,
};

mod metrics;

pub use metrics::{Metrics, pool, score, score_output};

/// How the model was trained.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub enum Method {
    /// One-step GP-NARX: a sparse GP of the one-step pairs by its marginal likelihood (the
    /// variational bound, [`crate::fit::OneStepObjective::Vfe`]).
    GpNarx,
    /// One-step GP-NARX with PILCO's hyperparameter penalties.
    PilcoNarx,
    /// Multi-step GP: trajectory likelihood (eq. 7).
    Msgp,
    /// The linear-Gaussian window model (no GP) by the exact Kalman-filter likelihood
    /// ([`crate::fit::linear_kf`]).
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

/// How a free simulation propagates the model's predictions through the NARX window.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
pub enum Rollout {
    /// Moment matching over the window's joint Gaussian (the paper's), reporting output
    /// variances that keep the GP's uncertainty about its function correlated over time
    /// ([`crate::rollout::function_uncertainty`]): the default. The means are the paper's.
    #[default]
    #[serde(rename = "mm")]
    MomentMatching,
    /// The paper's moment matching as it is: each step's function uncertainty counted as
    /// independent of the others'.
    #[serde(rename = "mm-independent")]
    MomentMatchingIndependent,
    /// Predicted means fed back, no uncertainty propagated
    /// ([`crate::rollout::mean_feedback`]): how one-step GP-NARX baselines are often simulated.
    #[serde(rename = "mean")]
    MeanFeedback,
}

impl Rollout {
    /// Name on the command line and in reports: `mm`, `mm-independent` or `mean`.
    pub fn name(&self) -> &'static str {
        match self {
            Rollout::MomentMatching => "mm",
            Rollout::MomentMatchingIndependent => "mm-independent",
            Rollout::MeanFeedback => "mean",
        }
    }

    /// Every rollout, the default first.
    pub const ALL: [Rollout; 3] = [
        Rollout::MomentMatching,
        Rollout::MomentMatchingIndependent,
        Rollout::MeanFeedback,
    ];

    /// The two a table reports: moment matching (the default) and mean feedback.
    pub const REPORTED: [Rollout; 2] = [Rollout::MomentMatching, Rollout::MeanFeedback];
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
    /// Per output, the variance (normalised units) added to every free-simulated output
    /// variance, by either rollout: the MSGP protocol's cross-validated calibration
    /// ([`crate::fit::calibration`]); empty where there is none. It moves no mean and no
    /// filtered prediction.
    pub calibration: Vec<f64>,
}

/// A free simulation in original units.
#[derive(Clone, Debug, PartialEq)]
pub struct Simulation {
    /// First simulated time index (`max(l_y, l_u)`).
    pub start: usize,
    /// Predicted output means (steps × d_y).
    pub mean: DMatrix<f64>,
    /// Predicted output variances, observation noise included (steps × d_y); by default
    /// ([`Rollout::MomentMatching`]) with the function's uncertainty kept correlated over time
    /// and the calibration's added variance.
    pub var: DMatrix<f64>,
}

impl Model {
    /// Open-loop free simulation of `traj` (original units) from its first `max(l_y, l_u)`
    /// samples, driven by its inputs, by the default rollout ([`Rollout::MomentMatching`]).
    pub fn simulate(&self, traj: &Trajectory) -> Result<Simulation> {
        self.simulate_as(traj, Rollout::MomentMatching)
    }

    /// Open-loop free simulation of `traj` (original units) by `rollout`.
    pub fn simulate_as(&self, traj: &Trajectory, rollout: Rollout) -> Result<Simulation> {
        traj.check(&self.spec)?;
        let norm = self.normalizer.apply(traj);
        let mut log = JitterLog::default();
        let gp = PreparedGp::new(&self.params, &self.config, &mut log)?;
        let dy = self.spec.dy;
        if rollout == Rollout::MeanFeedback {
            let (mut mean, mut var) = simulate_mean_feedback(&gp, &self.spec, &norm, traj.len())?;
            for i in 0..mean.nrows() {
                for j in 0..dy {
                    mean[(i, j)] = self.normalizer.y_to_original(j, mean[(i, j)]);
                    var[(i, j)] = self
                        .normalizer
                        .y_var_to_original(j, var[(i, j)] + self.added_variance(j));
                }
            }
            return Ok(Simulation {
                start: self.spec.warmup(),
                mean,
                var,
            });
        }
        // the linear-Gaussian model has no GP whose function could be drawn: its one dummy
        // pseudo-input carries no data
        let steps =
            if rollout == Rollout::MomentMatchingIndependent || self.method == Method::LinearKf {
                simulate(
                    &gp,
                    &self.spec,
                    &norm,
                    &Control::FeedForward,
                    traj.len(),
                    &mut log,
                )?
            } else {
                simulate_correlated(&gp, &self.spec, &norm, traj.len(), &mut log)?
            };
        let n = steps.len();
        let mut mean = DMatrix::zeros(n, dy);
        let mut var = DMatrix::zeros(n, dy);
        for (i, s) in steps.iter().enumerate() {
            for j in 0..dy {
                mean[(i, j)] = self.normalizer.y_to_original(j, s.mean[j]);
                var[(i, j)] = self
                    .normalizer
                    .y_var_to_original(j, s.cov[(j, j)] + self.added_variance(j));
            }
        }
        Ok(Simulation {
            start: self.spec.warmup(),
            mean,
            var,
        })
    }

    /// `paths` free simulations of `traj` (original units), each under one whole function drawn
    /// from the GP's posterior and its own process noise, seeded by `seed`
    /// ([`crate::rollout::function_uncertainty::sample_free_runs`]): the Monte Carlo picture of
    /// what [`Model::simulate`]'s band summarises. Each path holds the latent outputs (steps ×
    /// d_y, from the simulation's first step), without observation noise or the calibration's
    /// variance. A linear-kf model has no function posterior to draw from and is refused.
    pub fn sample_free_runs(
        &self,
        traj: &Trajectory,
        paths: usize,
        seed: u64,
    ) -> Result<Vec<DMatrix<f64>>> {
        use rand::SeedableRng;
        if self.method == Method::LinearKf {
            return Err(MsgpError::InvalidSetting {
                name: "method",
                reason: "a linear-kf model has no GP whose function could be drawn".into(),
            });
        }
        traj.check(&self.spec)?;
        let norm = self.normalizer.apply(traj);
        let mut log = JitterLog::default();
        let gp = PreparedGp::new(&self.params, &self.config, &mut log)?;
        let mut rng = rand::rngs::StdRng::seed_from_u64(seed);
        let mut out = sample_free_runs(
            &gp,
            &self.spec,
            &norm,
            traj.len(),
            paths,
            FunctionDraws::Whole,
            &mut rng,
        )?;
        for y in &mut out {
            for j in 0..self.spec.dy {
                for v in y.column_mut(j).iter_mut() {
                    *v = self.normalizer.y_to_original(j, *v);
                }
            }
        }
        Ok(out)
    }

    /// The calibration's added variance of output `j` (normalised units; 0 without one).
    fn added_variance(&self, j: usize) -> f64 {
        self.calibration.get(j).copied().unwrap_or(0.0)
    }

    /// Free simulation of `traj` scored against its measured outputs.
    pub fn evaluate(&self, traj: &Trajectory) -> Result<Metrics> {
        self.evaluate_as(traj, Rollout::MomentMatching)
    }

    /// Free simulation of `traj` by `rollout`, scored against its measured outputs.
    pub fn evaluate_as(&self, traj: &Trajectory, rollout: Rollout) -> Result<Metrics> {
        let sim = self.simulate_as(traj, rollout)?;
        score(&sim, traj)
    }

    /// Free simulation and scores of every part of a dataset; an error names the part.
    pub fn simulate_parts(&self, parts: &[Part]) -> Result<Vec<Simulated>> {
        self.simulate_parts_as(parts, Rollout::MomentMatching)
    }

    /// One-step-ahead filtered predictions of `traj` (original units): for every `t ≥ max(l_y,
    /// l_u)` the predictive distribution of `y_t` given the measured `y_{<t}` and the inputs,
    /// by the moment-matched filter of the filter likelihood ([`crate::loss::filter_steps`]:
    /// predict the window, score `y_t`, condition the window on it). The variance is the
    /// innovation's (observation noise included), as in [`Simulation::var`]. Not a free
    /// simulation: every step has seen the measured outputs before it.
    pub fn filtered(&self, traj: &Trajectory) -> Result<Simulation> {
        traj.check(&self.spec)?;
        let norm = self.normalizer.apply(traj);
        let mut log = JitterLog::default();
        let gp = PreparedGp::new(&self.params, &self.config, &mut log)?;
        let (dy, t0) = (self.spec.dy, self.spec.warmup());
        let n = traj.len().saturating_sub(t0);
        let mut mean = DMatrix::zeros(n, dy);
        let mut var = DMatrix::zeros(n, dy);
        crate::loss::filter_steps(&gp, &self.spec, &norm, &mut log, |step| {
            let i = step.t - t0;
            for j in 0..dy {
                mean[(i, j)] = self.normalizer.y_to_original(j, step.x_mean[j]);
                var[(i, j)] = self
                    .normalizer
                    .y_var_to_original(j, step.innovation_cov[(j, j)]);
            }
            Ok(())
        })?;
        Ok(Simulation {
            start: t0,
            mean,
            var,
        })
    }

    /// The filter likelihood of `traj` under this model in original units: `Σ_t −log p(y_t |
    /// y_{<t}, u)` over `t ≥ max(l_y, l_u)` (the joint density of the outputs the filter
    /// likelihood trains on, [`crate::loss::filter_nll`], with the normaliser's Jacobian
    /// `Σ_j log σ_{y,j}` per step), and the number of scored steps. Models with different
    /// normalisers score the same data on the same scale, so two models' values on data
    /// neither was trained on compare their predictions of it.
    pub fn filter_nll(&self, traj: &Trajectory) -> Result<(f64, usize)> {
        traj.check(&self.spec)?;
        let norm = self.normalizer.apply(traj);
        let mut log = JitterLog::default();
        let gp = PreparedGp::new(&self.params, &self.config, &mut log)?;
        let f = crate::loss::filter_nll(&gp, &self.spec, &norm, &mut log)?;
        let jacobian: f64 = self.normalizer.y_std.iter().map(|s| s.ln()).sum();
        Ok((f.nll + f.steps as f64 * jacobian, f.steps))
    }

    /// The free-run likelihood of `traj` under this model in original units: the episode
    /// rolled out by moment matching from its first window, in closed loop under `policy`
    /// (original units) when it ran one — the rollout a policy search predicts — and on its
    /// measured inputs otherwise, each output scored against the prediction, `Σ_t −log
    /// N(y_t; μ_t, Σ_t)` over `t ≥ max(l_y, l_u)` (the paper's loss, eq. 4, without its
    /// complexity term), with the normaliser's Jacobian as [`filter_nll`](Self::filter_nll);
    /// and the number of scored steps.
    pub fn rollout_nll(
        &self,
        traj: &Trajectory,
        policy: Option<&PolicySpec>,
    ) -> Result<(f64, usize)> {
        traj.check(&self.spec)?;
        let excitation = match policy {
            Some(p) => Excitation::Feedback(Box::new(p.normalized(&self.normalizer)?)),
            None => Excitation::FeedForward,
        };
        let episode = Episode {
            traj: self.normalizer.apply(traj),
            excitation,
        };
        let mut log = JitterLog::default();
        let loss = msgp_loss(
            &self.params,
            &self.config,
            &self.spec,
            std::slice::from_ref(&episode),
            Complexity::None,
            &mut log,
        )?;
        let jacobian: f64 = self.normalizer.y_std.iter().map(|s| s.ln()).sum();
        Ok((loss.nll + loss.steps as f64 * jacobian, loss.steps))
    }

    /// [`filtered`](Self::filtered) predictions of every part, with their metrics.
    pub fn filtered_parts(&self, parts: &[Part]) -> Result<Vec<Simulated>> {
        self.parts_by(parts, "filtering", |traj| self.filtered(traj))
    }

    /// [`simulate_parts`](Self::simulate_parts) by `rollout`.
    pub fn simulate_parts_as(&self, parts: &[Part], rollout: Rollout) -> Result<Vec<Simulated>> {
        self.parts_by(parts, "simulating", |traj| self.simulate_as(traj, rollout))
    }

    /// `predict` of every part, scored.
    fn parts_by(
        &self,
        parts: &[Part],
        doing: &str,
        predict: impl Fn(&Trajectory) -> Result<Simulation>,
    ) -> Result<Vec<Simulated>> {
        parts
            .iter()
            .map(|p| {
                let named = |what: &str, e: MsgpError| {
                    MsgpError::Data(format!("{what} {}: {e}", p.label()))
                };
                let sim = predict(&p.traj).map_err(|e| named(doing, e))?;
                let metrics = score(&sim, &p.traj).map_err(|e| named("scoring", e))?;
                Ok(Simulated {
                    part: p.clone(),
                    sim,
                    metrics,
                })
            })
            .collect()
    }
}

/// A simulated part of a dataset, ready for metrics, plots and CSV.
#[derive(Clone, Debug)]
pub struct Simulated {
    /// The measured data.
    pub part: Part,
    /// The free simulation.
    pub sim: Simulation,
    /// Its metrics.
    pub metrics: Metrics,
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
