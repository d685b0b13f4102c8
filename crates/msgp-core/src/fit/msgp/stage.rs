//! One MSGP training run ([`Stage`]): its start (the one-step fit, the spread start or the
//! Kalman filter's linear model) and the solver on the trajectory loss, with early stopping on
//! validation tails or, without them, the iterate of lowest training loss; a recipe's head
//! training ([`train_recipe`]).

use std::ops::ControlFlow;
use std::time::Instant;

use super::super::linear_kf::{KF_NOISE_FLOOR, fit_linear_kf};
use super::super::one_step::{OneStepSettings, column_std, fit_one_step, one_step_pairs};
use super::super::proxy_watch::ProxyWatch;
use super::super::segments::Batches;
use super::super::{
    FIT_LBFGS, FitOptimizer, FitProgress, FitReport, FitSettings, MsgpSettings, MsgpStart,
    NoiseStart,
};
use super::objective::{MsgpObjective, predicted_steps};
use super::outcomes::Trained;
use super::training::{Context, Training};
use crate::data::{Normalizer, Trajectory};
use crate::error::{MsgpError, Result};
use crate::gp::integrator::{IGNORED_LENGTHSCALE, NO_GP_SIGNAL_VAR, Structure};
use crate::gp::kmeans::{gp_inputs, place_pseudo_inputs};
use crate::gp::{GpConfig, GpParams, GpShape, MeanFunction, ParamGroup};
use crate::loss::Complexity;
use crate::model::Model;
use crate::narx::NarxSpec;
use crate::numeric::linalg::JitterLog;
use crate::optim::{Adam, Solver, minimize};
use crate::rollout::Episode;
use nalgebra::{DMatrix, DVector};

/// Most L-BFGS iterations of the Kalman-filter fit behind [`MsgpStart::LinearKf`] (it stops by
/// itself when converged, after 10–60 on the pendulum loop's data).
const KALMAN_START_ITERATIONS: usize = 300;

/// One recipe's head training: its start (or `previous`'s parameters) and the solver with
/// early stopping on `tails`. Returns the parameters, the chosen iteration and the best
/// validation NLL per step (`+∞` without tails), and its start (without `previous`).
pub(super) fn train_recipe(
    stage: &mut Stage<'_, '_>,
    previous: Option<&Model>,
    (heads, tails): (&[Episode], &[Episode]),
    stage_number: u8,
) -> (Result<Trained>, Option<GpParams<f64>>) {
    let init = match previous {
        Some(p) => p.params.clone(),
        None => match stage.start_params(heads) {
            Ok(init) => init,
            Err(e) => return (Err(e), None),
        },
    };
    let head_start = previous.is_none().then(|| init.clone());
    let iterations = stage.msgp.iterations;
    let trained = stage.train(init, heads, tails, iterations, stage_number, None);
    (trained, head_start)
}

/// One MSGP training run: initialisation and the solver with optional early stopping.
pub(super) struct Stage<'a, 'p> {
    pub spec: NarxSpec,
    pub config: GpConfig,
    pub settings: &'a FitSettings,
    pub msgp: &'a MsgpSettings,
    pub one_step: &'a OneStepSettings,
    pub start: Instant,
    pub progress: &'p mut dyn FnMut(&FitProgress) -> ControlFlow<()>,
    pub report: &'a mut FitReport,
    /// The calibration's proxy, read off a training with a validation tail, which then goes on
    /// past its early stop until the proxy's length ([`super::super::proxy_watch`]).
    pub proxy_watch: Option<ProxyWatch>,
    /// Whether a head at its early stop, with its best validation NLL, can still be chosen:
    /// where not, it drops its proxy instead of training on for it.
    pub proxy_ahead: Option<&'a dyn Fn(f64) -> bool>,
    /// The stage whose batches (with segments) this run draws, where not its own: a proxy
    /// trained on its own draws its head's, so that it is the proxy read off the head's
    /// training, bit for bit, whichever of the two the schedule ran.
    pub batches_of: Option<u8>,
}

impl Stage<'_, '_> {
    /// The start of a training run on `episodes`, as [`MsgpSettings::start`] says.
    pub fn start_params(&mut self, episodes: &[Episode]) -> Result<GpParams<f64>> {
        match self.msgp.start {
            MsgpStart::OneStep => {
                let one_step = *self.one_step;
                self.initial(episodes, &one_step)
            }
            MsgpStart::Spread => self.initial(
                episodes,
                &OneStepSettings {
                    iterations: 0,
                    ..*self.one_step
                },
            ),
            MsgpStart::LinearKf => self.initial_from_kalman(episodes),
        }
    }

    /// process and the observation noise as [`MsgpSettings::noise_start`] says.
    fn initial(
        &mut self,
        episodes: &[Episode],
        one_step: &OneStepSettings,
    ) -> Result<GpParams<f64>> {
        let refs: Vec<&Trajectory> = episodes.iter().map(|e| &e.traj).collect();
        let data = one_step_pairs(&self.spec, &refs)?;
        let mut init = fit_one_step(
            &data,
            self.msgp.inducing,
            one_step,
            &self.config,
            &Structure::new(&self.settings.integrators, &self.spec),
            self.settings.seed,
            &mut self.report.jitter,
        )?;
        let floor = self.config.noise_floor;
        let share = match self.msgp.noise_start {
            NoiseStart::Split => 0.5,
            NoiseStart::Full => 1.0,
        };
        for a in 0..self.spec.dy {
            let total = init.log_process_noise[a].exp() + floor;
            let part = (share * total - floor).max(1e-3 * floor);
            init.log_process_noise[a] = part.ln();
            init.log_obs_noise[a] = part.ln();
        }
        let m = init.pseudo_inputs.nrows();
        let predicted: usize = episodes
            .iter()
            .map(|e| e.traj.len() - self.spec.warmup())
            .sum();
        if self.msgp.complexity == Complexity::NegHalfLogDet && predicted <= m {
            return Err(MsgpError::InvalidSetting {
                name: "inducing",
                reason: format!(
                    "the complexity term −½log|K̃| is bounded only when the training rollouts predict \
                     more steps ({predicted}) than there are pseudo-inputs ({m}); use fewer pseudo-inputs"
                ),
            });
        }
        Ok(init)
    }

    /// The linear-kf start ([`MsgpStart::LinearKf`]): the Kalman-filter fit of the linear window
    /// model on `episodes` (inputs as logged, feedback episodes included) gives the linear mean
    /// and both noise levels; the GP starts at zero on top of it: `m` pseudo-inputs by k-means
    /// over the training windows, pseudo-targets 0 (so the predictive mean is the filter's),
    /// length-scales at the windows' spread, and a signal variance equal to the filter's
    /// process noise (so the predictive variance at most doubles it). Outputs without a GP and
    /// ignored window coordinates get their [`Structure`] values.
    fn initial_from_kalman(&mut self, episodes: &[Episode]) -> Result<GpParams<f64>> {
        let trajs: Vec<Trajectory> = episodes.iter().map(|e| e.traj.clone()).collect();
        let structure = Structure::new(&self.settings.integrators, &self.spec);
        let (linear, kf) = fit_linear_kf(
            &trajs,
            self.spec,
            &structure,
            Normalizer::identity(self.spec.dy, self.spec.du),
            KALMAN_START_ITERATIONS,
            None,
        )?;
        self.report.jitter.merge(&kf.jitter);
        let refs: Vec<&Trajectory> = trajs.iter().collect();
        let data = one_step_pairs(&self.spec, &refs)?;
        let d = data.x.ncols();
        let gx = gp_inputs(&data.x, &structure.ignored);
        let pseudo = place_pseudo_inputs(&gx, self.msgp.inducing, self.settings.seed)?;
        let e = self.spec.dy;
        let floor = self.config.noise_floor;
        // the filter's noise variances (its floor is far below any setting's) as `floor + e^θ`
        let above_floor = |log_var: f64| {
            (log_var.exp() + KF_NOISE_FLOOR - floor)
                .max(1e-3 * floor)
                .ln()
        };
        let lengthscales: Vec<f64> = (0..d)
            .map(|k| match structure.ignored.contains(&k) {
                true => IGNORED_LENGTHSCALE.ln(),
                false => column_std(&gx, k).max(1e-6).ln(),
            })
            .collect();
        let lp = &linear.params;
        let mut params = GpParams {
            pseudo_targets: DMatrix::zeros(pseudo.nrows(), e),
            pseudo_inputs: pseudo,
            log_lengthscales: DMatrix::from_fn(e, d, |_, k| lengthscales[k]),
            log_signal_var: DVector::from_fn(e, |a, _| {
                (lp.log_process_noise[a].exp() + KF_NOISE_FLOOR).ln()
            }),
            log_process_noise: lp.log_process_noise.map(above_floor),
            log_obs_noise: lp.log_obs_noise.map(above_floor),
            linear_mean: lp.linear_mean.clone(),
        };
        for &a in &structure.without_gp {
            params.log_signal_var[a] = NO_GP_SIGNAL_VAR.ln();
        }
        Ok(params)
    }

    /// The solver from `init` for up to `iterations` steps. With validation episodes, checks them
    /// every `eval_every` steps, stops after `patience` checks without improvement and returns the
    /// parameters of the best validation NLL and their iteration; otherwise returns the iterate of
    /// the lowest training loss (the last one, unless a late Adam step threw the loss up). With
    /// `blow_up` (and no validation episodes), a training loss that rises by more than that (per
    /// predicted step) above its lowest since iteration 10 ([`super::super::blow_up`]) stops the
    /// run and is reported in [`FitReport::full_data_failed`].
    pub fn train(
        &mut self,
        init: GpParams<f64>,
        episodes: &[Episode],
        tails: &[Episode],
        iterations: usize,
        stage: u8,
        blow_up: Option<f64>,
    ) -> Result<Trained> {
        let shape = init.shape()?;
        let active = self.free(shape);
        let mut objective = self.objective(shape, episodes, stage);
        let solver = match self.msgp.optimizer {
            FitOptimizer::Adam => Solver::Adam(Adam {
                learning_rate: self.msgp.learning_rate,
                ..Adam::default()
            }),
            FitOptimizer::Lbfgs => Solver::Lbfgs(FIT_LBFGS),
        };
        let batched = objective.batches.is_some();
        let context = Context {
            report: &mut *self.report,
            progress: &mut *self.progress,
            spec: self.spec,
            config: self.config,
            msgp: self.msgp,
            start: self.start,
            proxy_ahead: self.proxy_ahead,
            proxy_watch: self.proxy_watch.take(),
        };
        let mut run = Training::new(context, &init, tails, (iterations, stage), blow_up, batched)?;
        let x0 = init.to_flat();
        let last_x = minimize(
            &mut objective,
            &solver,
            x0,
            &active,
            iterations + 1,
            |it, loss, x| run.observe(it, loss, x),
        );
        let leftovers = run.leftovers();
        self.report.jitter.merge(&objective.log);
        let (last_x, _) = last_x?;
        self.proxy_watch = leftovers.watch;
        leftovers.result.finish(
            self.report,
            (shape, last_x),
            objective.failure.take(),
            (iterations, stage),
            &mut self.proxy_watch,
        )
    }

    /// Which parameters move: all but the frozen groups (and `A` without a linear mean), and
    /// what integrating outputs fix (their rows of `A` on their own lags, the length-scales of
    /// ignored inputs, the GP of outputs without one).
    fn free(&self, shape: GpShape) -> Vec<bool> {
        let mut free = GpParams::filled(shape, true);
        let no_mean = (self.config.mean == MeanFunction::Zero).then_some(ParamGroup::LinearMean);
        for g in self.msgp.frozen.iter().chain(no_mean.iter()) {
            free.fill_group(*g, false);
        }
        let structure = Structure::new(&self.settings.integrators, &self.spec);
        for c in &structure.fixed {
            free.linear_mean[(c.row, c.col)] = false;
        }
        for &col in &structure.ignored {
            free.log_lengthscales.column_mut(col).fill(false);
        }
        for &a in &structure.without_gp {
            free.pseudo_targets.column_mut(a).fill(false);
            free.log_lengthscales.row_mut(a).fill(false);
            free.log_signal_var[a] = false;
        }
        free.to_flat()
    }

    /// The loss on `episodes` (batched with segments and Adam, by a seed of the stage's own).
    fn objective<'e>(
        &self,
        shape: GpShape,
        episodes: &'e [Episode],
        stage: u8,
    ) -> MsgpObjective<'e> {
        MsgpObjective {
            shape,
            spec: self.spec,
            config: self.config,
            episodes,
            likelihood: self.msgp.likelihood,
            complexity: self.msgp.complexity,
            threads: self.settings.threads,
            log: JitterLog::default(),
            failure: None,
            batches: match (self.msgp.segments, self.msgp.optimizer) {
                (Some(s), FitOptimizer::Adam) => Batches::new(
                    episodes.len(),
                    s.batch,
                    self.settings.seed ^ (u64::from(self.batches_of.unwrap_or(stage)) << 32),
                ),
                _ => None,
            },
            all_steps: predicted_steps(episodes, &self.spec),
        }
    }
}
