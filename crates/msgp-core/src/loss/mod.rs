//! The MSGP objective, eqs. (4)–(7): the negative log-likelihood of every observed trajectory
//! under its free-running predictive distribution, plus a complexity term.
//!
//! Each step contributes `½[(y_t − M_t)ᵀ V_t⁻¹ (y_t − M_t) + log|V_t| + d_y log 2π]` with
//! `V_t = S_t + Σ_x + Σ_y` (the product of per-step marginals along the rollout; correlations
//! between time steps are carried in the window state, as in PILCO). Feed-forward episodes use
//! their measured inputs (`L_ff`), feedback episodes close the loop with the policy that
//! produced them (`L_fb`).
//!
//! ## The complexity term
//! The paper writes `L_comp = −½ log|K̃|` (`K̃ = K + σ_x² I`) and calls it the GP marginal
//! likelihood's complexity penalty. In a *negative* log-likelihood that penalty is
//! `+½ log|K̃|`, but alone it is unbounded below: scaling `σ_f²` and `σ_x²` by `s → 0` leaves
//! every predicted mean unchanged (`k(x)ᵀK̃⁻¹ȳ` is invariant) and only shrinks variances, while
//! `½ log|K̃|` falls like `(m/2) log s`. The default, [`Complexity::PseudoDataNll`], keeps the
//! penalty's sign and adds its companion data-fit term: the full negative log marginal likelihood
//! of the pseudo-data, `½ ȳᵀK̃⁻¹ȳ + ½ log|K̃| + (m/2) log 2π` (a GP prior on the pseudo-targets).
//! Under the same scaling `½ ȳᵀK̃⁻¹ȳ` grows like `1/s`, so the objective is bounded below. The
//! paper's literal sign, [`Complexity::NegHalfLogDet`], rewards variance inflation and is bounded
//! only when the rollouts predict more steps than there are pseudo-inputs; it and
//! [`Complexity::None`] remain selectable. `docs/design.md` has the comparison over all ten
//! benchmarks that chose the default.
//!
//! The loss is written once, generic over the scalar ([`msgp_loss`]: what forward-mode duals
//! differentiate); its gradient for the fits is the adjoint sweep of `gradient`
//! ([`loss_and_gradient`]).
//!
//! ## The filter likelihood
//! [`filter`] scores the same trajectories by their joint density instead of the product of the
//! free run's marginals: an assumed-density filter over the same window state, conditioned on
//! each observation ([`filter_nll`], [`filter_loss`]; forward pass, generic over the scalar). Its
//! gradient for the fits is the adjoint sweep of `filter_gradient` ([`filter_loss_and_gradient`],
//! the signature and conventions of [`loss_and_gradient`]).

use nalgebra::{DMatrix, DVector};
use serde::{Deserialize, Serialize};

pub mod filter;
mod filter_gradient;
mod gradient;

pub use filter::{FilterNll, FilterStep, filter_loss, filter_nll, filter_steps};
pub use filter_gradient::filter_loss_and_gradient;
pub(crate) use filter_gradient::weighted_filter_loss_and_gradient;
pub use gradient::loss_and_gradient;
pub(crate) use gradient::weighted_loss_and_gradient;

use crate::error::{MsgpError, Result};
use crate::gp::{GpConfig, GpParams, PreparedGp};
use crate::moments::MomentMatch;
use crate::narx::NarxSpec;
use crate::numeric::linalg::{Cholesky, JitterLog, JitterPolicy, cholesky};
use crate::numeric::scalar::{Scalar, c};
use crate::policy::FeedbackPolicy;
use crate::rollout::{Control, rollout_started};
use crate::rollout::{Episode, Excitation};

const LN_2PI: f64 = 1.837_877_066_409_345_3;

/// The trajectory likelihood an MSGP fit maximises (eq. 4): both score the same observations
/// with the same model and parameters.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Likelihood {
    /// The paper's: the product of a free simulation's per-step marginals ([`msgp_loss`]).
    #[default]
    FreeRun,
    /// The joint density of the observations by the moment-matched filter ([`filter`]:
    /// [`filter_loss`]).
    Filter,
}

impl Likelihood {
    /// Name on the command line: `free-run` or `filter`.
    pub fn name(&self) -> &'static str {
        match self {
            Likelihood::FreeRun => "free-run",
            Likelihood::Filter => "filter",
        }
    }
}

/// Which complexity term is added to the trajectory likelihood.
/// Serialised in kebab-case (`pseudo-data-nll`); the Rust names that model files and reports
/// written before 2026-12-05 (fifth session) hold are read as well.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum Complexity {
    /// No complexity term.
    #[serde(alias = "None")]
    None,
    /// `½ ȳᵀK̃⁻¹ȳ + ½ log|K̃| + (m/2) log 2π` per output (default; bounded).
    #[default]
    #[serde(alias = "PseudoDataNll")]
    PseudoDataNll,
    /// The paper's literal `−½ log|K̃|`.
    #[serde(alias = "NegHalfLogDet")]
    NegHalfLogDet,
    /// `+½ log|K̃|` alone: unbounded below over long training (the signal and process
    /// variances drift to zero together), so used only with early stopping on a validation
    /// tail, as in the default protocol's linear-mean recipe (`fit::LINEAR_RECIPE`).
    #[serde(alias = "HalfLogDet")]
    HalfLogDet,
}

/// The loss and its parts.
#[derive(Clone, Copy, Debug)]
pub struct LossValue<T: Scalar> {
    /// `L_ff + L_fb`: summed trajectory negative log-likelihood.
    pub nll: T,
    /// The complexity term.
    pub complexity: T,
    /// Number of predicted steps summed in `nll`.
    pub steps: usize,
}

impl<T: Scalar> LossValue<T> {
    /// `nll + complexity`.
    pub fn total(&self) -> T {
        self.nll + self.complexity
    }
}

/// Negative log density of `y` under `N(mean, cov)`.
pub fn gaussian_nll<T: Scalar>(
    y: &[f64],
    mean: &DVector<T>,
    cov: &DMatrix<T>,
    jitter: &JitterPolicy,
    log: &mut JitterLog,
) -> Result<T> {
    let ch = cholesky(cov, jitter, "predictive covariance")?;
    log.record(ch.jitter);
    let r = DVector::from_iterator(
        y.len(),
        y.iter().zip(mean.iter()).map(|(&a, &m)| c::<T>(a) - m),
    );
    Ok(factored_nll(&ch, &r))
}

/// Negative log density of the residual `r` under `N(0, L Lᵀ)` (`ch` the factor `L`): what
/// [`gaussian_nll`] computes once it has factorised the covariance.
pub(crate) fn factored_nll<T: Scalar>(ch: &Cholesky<T>, r: &DVector<T>) -> T {
    let z = ch.solve_lower(&DMatrix::from_column_slice(r.len(), 1, r.as_slice()));
    let quad = z.iter().fold(T::zero(), |s, v| s + *v * *v);
    (quad + ch.log_det() + c::<T>(r.len() as f64 * LN_2PI)) * c::<T>(0.5)
}

/// The complexity term for prepared GP factors.
pub fn complexity_term<T: Scalar>(params: &GpParams<T>, gp: &PreparedGp<T>, kind: Complexity) -> T {
    let m = params.pseudo_inputs.nrows() as f64;
    let mut total = T::zero();
    for (a, o) in gp.outputs.iter().enumerate() {
        let logdet = o.chol.log_det();
        total += match kind {
            Complexity::None => T::zero(),
            Complexity::HalfLogDet => logdet * c::<T>(0.5),
            Complexity::NegHalfLogDet => -logdet * c::<T>(0.5),
            Complexity::PseudoDataNll => {
                let fit = params.pseudo_targets.column(a).dot(&o.beta);
                (fit + logdet + c::<T>(m * LN_2PI)) * c::<T>(0.5)
            }
        };
    }
    total
}

/// The frame both likelihoods share: the GP prepared once, every episode checked against `spec`
/// and scored by `score` (which adds its NLL terms to the running sum and counts its scored
/// steps), then the complexity term.
pub(crate) fn over_episodes<T: MomentMatch>(
    params: &GpParams<T>,
    config: &GpConfig,
    spec: &NarxSpec,
    episodes: &[Episode],
    complexity: Complexity,
    log: &mut JitterLog,
    mut score: impl FnMut(&PreparedGp<T>, &Episode, &mut T, &mut usize, &mut JitterLog) -> Result<()>,
) -> Result<LossValue<T>> {
    let gp = PreparedGp::new(params, config, log)?;
    let mut nll = T::zero();
    let mut steps = 0usize;
    for (k, ep) in episodes.iter().enumerate() {
        ep.traj
            .check(spec)
            .map_err(|e| MsgpError::Data(format!("episode {k}: {e}")))?;
        score(&gp, ep, &mut nll, &mut steps, log)?;
    }
    Ok(LossValue {
        nll,
        complexity: complexity_term(params, &gp, complexity),
        steps,
    })
}

/// The MSGP loss (eq. 7) over a set of episodes.
pub fn msgp_loss<T: MomentMatch>(
    params: &GpParams<T>,
    config: &GpConfig,
    spec: &NarxSpec,
    episodes: &[Episode],
    complexity: Complexity,
    log: &mut JitterLog,
) -> Result<LossValue<T>> {
    over_episodes(
        params,
        config,
        spec,
        episodes,
        complexity,
        log,
        |gp, ep, nll, steps, log| {
            let lifted: Option<Box<dyn FeedbackPolicy<T>>> = match &ep.excitation {
                Excitation::FeedForward => None,
                Excitation::Feedback(p) => Some(p.lift::<T>()),
            };
            let control = match &lifted {
                None => Control::FeedForward,
                Some(p) => Control::Feedback(p.as_ref()),
            };
            let y = &ep.traj.y;
            let mut row = vec![0.0; spec.dy];
            let mut nll_log = JitterLog::default();
            rollout_started(
                gp,
                spec,
                &ep.traj,
                &control,
                ep.traj.len(),
                gp.start,
                log,
                None,
                |p| {
                    for j in 0..spec.dy {
                        row[j] = y[(p.t, j)];
                    }
                    *nll += gaussian_nll(&row, &p.mean, &p.cov, &config.jitter, &mut nll_log)?;
                    *steps += 1;
                    Ok(())
                },
            )?;
            log.merge(&nll_log);
            Ok(())
        },
    )
}
