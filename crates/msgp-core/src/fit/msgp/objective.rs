//! The loss an MSGP training minimises: the trajectory NLL and complexity term per predicted
//! step, of every episode or, with segments and Adam, of a random batch of them.

use super::super::segments::Batches;
use crate::error::{MsgpError, Result};
use crate::gp::{GpConfig, GpParams, GpShape};
use crate::loss::{
    Complexity, Likelihood, LossValue, filter_loss, msgp_loss, weighted_filter_loss_and_gradient,
    weighted_loss_and_gradient,
};
use crate::narx::NarxSpec;
use crate::numeric::linalg::JitterLog;
use crate::numeric::parallel::Threads;
use crate::optim::Objective;
use crate::rollout::Episode;

/// The MSGP loss on `episodes` as a solver's objective.
pub(super) struct MsgpObjective<'a> {
    pub shape: GpShape,
    pub spec: NarxSpec,
    pub config: GpConfig,
    pub episodes: &'a [Episode],
    pub likelihood: Likelihood,
    pub complexity: Complexity,
    pub threads: Threads,
    pub log: JitterLog,
    /// The numerical failure of the latest evaluation, if it failed (the loss is then reported
    /// as NaN).
    pub failure: Option<MsgpError>,
    /// With segments and Adam: the batch of `episodes` each step evaluates.
    pub batches: Option<Batches>,
    /// Predicted steps of all of `episodes` (the batches' weight).
    pub all_steps: usize,
}

impl MsgpObjective<'_> {
    /// The loss (NLL and complexity) and its gradient on `episodes`.
    fn evaluate(
        &mut self,
        params: &GpParams<f64>,
        episodes: &[Episode],
        complexity: (Complexity, f64),
    ) -> Result<(LossValue<f64>, Vec<f64>)> {
        let evaluate = match self.likelihood {
            Likelihood::FreeRun => weighted_loss_and_gradient,
            Likelihood::Filter => weighted_filter_loss_and_gradient,
        };
        evaluate(
            params,
            &self.config,
            &self.spec,
            episodes,
            complexity,
            self.threads,
            &mut self.log,
        )
    }

    /// The loss per predicted step and its gradient: of every episode, or with batches an
    /// unbiased estimate from the next batch (its NLL per step, plus the complexity term over
    /// all the steps).
    pub(super) fn per_step(&mut self, params: &GpParams<f64>) -> Result<(f64, Vec<f64>)> {
        let Some(batches) = self.batches.as_mut() else {
            let (v, mut g) = self.evaluate(params, self.episodes, (self.complexity, 1.0))?;
            let scale = 1.0 / v.steps.max(1) as f64;
            g.iter_mut().for_each(|gi| *gi *= scale);
            return Ok((v.total() * scale, g));
        };
        let picked = batches.draw();
        self.on_batch(params, &picked)
    }

    /// The estimate of the loss per predicted step and its gradient from the episodes
    /// `picked`: their NLL per step plus the complexity term over all the steps.
    pub(super) fn on_batch(
        &mut self,
        params: &GpParams<f64>,
        picked: &[usize],
    ) -> Result<(f64, Vec<f64>)> {
        let batch: Vec<Episode> = picked.iter().map(|&k| self.episodes[k].clone()).collect();
        let steps = predicted_steps(&batch, &self.spec);
        // (NLL_batch + w · complexity) / steps_batch with w = steps_batch / steps_all
        let b = 1.0 / steps.max(1) as f64;
        let weight = steps as f64 / self.all_steps.max(1) as f64;
        let (v, mut g) = self.evaluate(params, &batch, (self.complexity, weight))?;
        g.iter_mut().for_each(|gi| *gi *= b);
        Ok((v.total() * b, g))
    }
}

impl Objective for MsgpObjective<'_> {
    fn value_and_gradient(&mut self, x: &[f64]) -> Result<(f64, Vec<f64>)> {
        let params = GpParams::from_flat(self.shape, x)?;
        match self.per_step(&params) {
            Err(e) if e.is_numerical() => {
                self.failure = Some(e);
                Ok((f64::NAN, vec![0.0; x.len()]))
            }
            Err(e) => Err(e),
            Ok(evaluated) => {
                // a line search may step back from a failed trial: only a failure at the end
                // counts
                self.failure = None;
                Ok(evaluated)
            }
        }
    }
}

/// The steps a loss predicts over `episodes`: every sample after each one's first window.
pub(super) fn predicted_steps(episodes: &[Episode], spec: &NarxSpec) -> usize {
    episodes
        .iter()
        .map(|e| e.traj.len().saturating_sub(spec.warmup()))
        .sum()
}

/// Mean NLL per step of `episodes` (normalised units) under `likelihood`: the MSGP loss
/// without its complexity term.
pub(super) fn validation_nll(
    params: &GpParams<f64>,
    config: &GpConfig,
    spec: &NarxSpec,
    likelihood: Likelihood,
    episodes: &[Episode],
) -> Result<f64> {
    let mut log = JitterLog::default();
    let v = match likelihood {
        Likelihood::FreeRun => {
            msgp_loss(params, config, spec, episodes, Complexity::None, &mut log)?
        }
        Likelihood::Filter => {
            filter_loss(params, config, spec, episodes, Complexity::None, &mut log)?
        }
    };
    Ok(v.nll / v.steps.max(1) as f64)
}

#[cfg(test)]
mod batch_tests {
    use super::*;
    use crate::data::Trajectory;
    use crate::fit::{FitSettings, MsgpSettings, TrainingEpisode, fit_episodes};

    /// The batched loss is an unbiased estimate of the whole one: over three segments of equal
    /// length, the mean of the three single-segment estimates is the loss per step of all of
    /// them, value and gradient (the complexity term weighted by all the steps, the NLL by the
    /// batch's), for both likelihoods.
    #[test]
    fn batches_estimate_the_whole_loss_without_bias() {
        // `y_t = 0.9 y_{t−1} + 0.5 u_{t−1} + 0.2 sin(3 y_{t−1})` under a sine input
        let n = 3 * 20 + 2;
        let u: Vec<f64> = (0..n).map(|i| (i as f64 * 0.37).sin()).collect();
        let mut y = vec![0.0; n];
        for t in 1..n {
            y[t] = 0.9 * y[t - 1] + 0.5 * u[t - 1] + 0.2 * (y[t - 1] * 3.0).sin();
        }
        let traj = Trajectory::siso(&u, &y).expect("finite");
        let settings = FitSettings {
            ly: 2,
            lu: 2,
            method: MsgpSettings {
                inducing: 8,
                iterations: 30,
                validation_fraction: 0.0,
                ..MsgpSettings::default()
            }
            .into(),
            ..FitSettings::default()
        };
        let whole = [TrainingEpisode {
            traj: traj.clone(),
            policy: None,
        }];
        let (model, _) = fit_episodes(&whole, &settings, &mut |_| {}).expect("fit");
        let episodes = crate::fit::Segments {
            length: 20,
            batch: 1,
        }
        .split(&[Episode::feed_forward(model.normalizer.apply(&traj))], 2)
        .expect("split");
        assert_eq!(episodes.len(), 3);
        for likelihood in [Likelihood::FreeRun, Likelihood::Filter] {
            let mut objective = MsgpObjective {
                shape: model.params.shape().expect("shape"),
                spec: model.spec,
                config: model.config,
                episodes: &episodes,
                likelihood,
                complexity: Complexity::HalfLogDet,
                threads: Threads::default(),
                log: JitterLog::default(),
                failure: None,
                batches: None,
                all_steps: 60,
            };
            let (value, gradient) = objective.per_step(&model.params).expect("whole");
            let mut mean = (0.0, vec![0.0; gradient.len()]);
            for k in 0..3 {
                let (v, g) = objective.on_batch(&model.params, &[k]).expect("batch");
                mean.0 += v / 3.0;
                mean.1.iter_mut().zip(&g).for_each(|(m, g)| *m += g / 3.0);
            }
            assert!(
                (mean.0 - value).abs() < 1e-12 * value.abs().max(1.0),
                "{mean:?} {value}"
            );
            let size = gradient.iter().fold(0.0_f64, |a, g| a.max(g.abs()));
            for (m, g) in mean.1.iter().zip(&gradient) {
                // (each rollout's jitter is its own: the sums agree to about 1e-8)
                assert!((m - g).abs() < 1e-6 * size, "{m} vs {g}");
            }
            // one segment alone is not the whole: the test could tell a wrong weighting
            let (v0, _) = objective.on_batch(&model.params, &[0]).expect("batch");
            assert!((v0 - value).abs() > 1e-6, "{v0} {value}");
        }
    }
}
