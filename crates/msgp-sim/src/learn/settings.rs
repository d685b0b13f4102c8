//! The loop's settings and their defaults: what the loop fits, searches and runs, and the
//! structure it declares about the plant.

use serde::{Deserialize, Serialize};

use msgp_core::fit::{
    FitOptimizer, FitSettings, LinearKfSettings, MethodSettings, MsgpSettings, MsgpStart,
    OneStepFitSettings, OneStepObjective,
};
use msgp_core::gp::MeanFunction;
use msgp_core::gp::integrator::Integrator;
use msgp_core::loss::Likelihood;
use msgp_core::model::Method;
use msgp_core::policy_search::PolicySearchSettings;

use crate::controller::ExcitationConfig;

/// Settings of the learning loop.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct LearnSettings {
    /// Policy-learning iterations after the random rollouts.
    pub iterations: usize,
    /// Random episodes before the first policy.
    pub random_rollouts: usize,
    /// The smooth random signal of the random episodes. Its band reaches 10 Hz: a NARX model at
    /// 50 Hz only learns how the pole answers quick changes of the command (the inputs' lags
    /// differ) if the first data have them, and every feedback policy makes them (its
    /// derivative term passes on measurement noise). With 0.1–2 Hz the input lags are nearly
    /// collinear and a fitted model may weight their differences arbitrarily (docs/design.md).
    #[serde(default = "learn_excitation")]
    pub excitation: ExcitationConfig,
    /// Length of every interaction episode \[s\].
    pub episode_seconds: f64,
    /// Horizon of the predicted rollouts the gains are optimised on \[s\]. Longer than an
    /// episode, so that the policy search sees the slow drift of the end effector that a
    /// 3 s episode hides but the 10 s stability test does not.
    pub policy_horizon_seconds: f64,
    /// Seed of everything random (episodes, excitation, fits, restarts).
    pub seed: u64,
    /// Model fit settings: the model's method (MSGP, the one-step GP-NARX of standard PILCO,
    /// linear-kf) and its settings (history, inducing points, iterations). The default prior mean is
    /// linear (an ARX map under the GP, started by instrumental variables): with a zero mean the
    /// fitted models lose the pole's angular velocity (docs/design.md). The end effector is
    /// declared a double integrator ([`END_EFFECTOR_INTEGRATOR`]).
    pub fit: FitSettings,
    /// Policy optimisation settings. The default trust region (1 typical magnitude per
    /// iteration) keeps the new gains near the data the model was fitted to.
    pub search: PolicySearchSettings,
    /// Cost widths for `[θ, x]` (rad, m): `c = 1 − exp(−½ Σ (y_j / w_j)²)`.
    pub cost_widths: [f64; 2],
    /// After every iteration, this many evaluation episodes of the new gains (an episode's
    /// length each, random initial angles, their own seeds) estimate the expected cost the
    /// model predicted ([`IterationReport::expected_cost`](super::IterationReport::expected_cost)):
    /// one episode's cost is a single draw whose spread is as large as its mean (the initial
    /// angle's square), so only the mean says whether the prediction was right. Like the
    /// stability test, neither interaction nor training data. 0: none.
    #[serde(default = "evaluation_episodes")]
    pub evaluation_episodes: usize,
    /// The prequential choice of the MSGP loop ([`msgp_core::learner::choice`]): every iteration also fits
    /// the linear model of the data (linear-kf), scores both on the episode that follows, and
    /// runs the search on the GP model only while its predictions of episodes it had not seen
    /// beat the linear model's in total. `false`: always the GP model.
    #[serde(default, skip_serializing_if = "std::ops::Not::not")]
    pub prequential_choice: bool,
    /// Feed-forward (random-excitation) episodes enter the model loss as overlapping segments
    /// of this many samples (stride half of it); `None` keeps them whole. MSGP only. The pendulum is
    /// open-loop unstable: a free-running prediction from an episode's first samples carries no
    /// information after a second or so (initial uncertainty grows like `e^{3.5 t}`), and fitting
    /// the trajectory likelihood of whole falls distorts the dynamics (docs/design.md).
    pub ff_segment: Option<usize>,
    /// Typical gain magnitudes `[kp_x, ki_x, kd_x, kp_θ, kd_θ]`: the first policy's gains and
    /// the optimiser's coordinate scales (units of the problem, not a solution).
    pub gain_scale: [f64; 5],
    /// Warm starts (MSGP and linear-kf): from the second iteration on, each fit continues the
    /// previous iteration's model for this many solver iterations ([`msgp_core::fit::refit_episodes`]: its
    /// normaliser, pseudo-inputs and parameters) instead of starting over from a one-step fit
    /// (linear-kf: from its two cold starts); `None` starts over every time (the default).
    /// MSGP warm starts make iterations 2–8 4.5–6× faster, but on the five Figure 4 seeds the
    /// later iterations measured worse (mean episode cost 36–97 against 28–65), so MSGP starts
    /// over by default. linear-kf warm starts kept every iteration at 2.0–2.8 s (5 s policy
    /// horizon) with the same seeds stable: [`LearnSettings::for_method`] turns them on for linear-kf
    /// ([`LINEAR_KF_WARM_START`]; BENCHMARKS.md).
    #[serde(default)]
    pub warm_start: Option<usize>,
}

impl Default for LearnSettings {
    fn default() -> Self {
        Self {
            iterations: 8,
            random_rollouts: 4,
            excitation: learn_excitation(),
            episode_seconds: 3.0,
            policy_horizon_seconds: 5.0,
            seed: 0,
            fit: FitSettings {
                ly: 2,
                lu: 3,
                integrators: vec![END_EFFECTOR_INTEGRATOR],
                method: MsgpSettings {
                    inducing: LEARN_INDUCING,
                    iterations: 300,
                    learning_rate: 0.01,
                    validation_fraction: 0.0,
                    mean: MeanFunction::Linear,
                    ..MsgpSettings::default()
                }
                .into(),
                ..FitSettings::default()
            },
            search: PolicySearchSettings {
                iterations: 20,
                learning_rate: 0.1,
                restarts: 1,
                restart_spread: 0.5,
                seed: 0,
                candidates: 150,
                candidate_spread: 2.0,
                candidate_starts: 2,
                trust_region: 1.0,
                ..PolicySearchSettings::default()
            },
            cost_widths: [0.1, 0.3],
            evaluation_episodes: EVALUATION_EPISODES,
            prequential_choice: false,
            ff_segment: Some(30),
            gain_scale: [1.0, 0.3, 1.0, 10.0, 2.0],
            warm_start: None,
        }
    }
}

impl LearnSettings {
    /// The settings as a run's record holds them: without the threads of the fit and the
    /// search, which are not recorded (results do not depend on them) and read back as the
    /// default. A finished run is recognised by `stored == settings.as_recorded()`, whatever
    /// `MSGP_THREADS` says.
    pub fn as_recorded(&self) -> Self {
        let mut recorded = self.clone();
        recorded.fit.threads = Default::default();
        recorded.search.threads = Default::default();
        recorded
    }

    /// The defaults for `method`. A [`Method::LinearKf`] model has no GP to absorb what a row
    /// should not carry, so the end effector is declared kinematic
    /// ([`END_EFFECTOR_KINEMATIC`]): in closed loop the command is a function of the pole's
    /// motion, and a free row explains the end effector's acceleration by the pole's velocity
    /// instead of the command. Its fits are warm-started ([`LINEAR_KF_WARM_START`]), and its gains
    /// are optimised over [`LINEAR_KF_POLICY_HORIZON_SECONDS`].
    pub fn for_method(method: Method) -> Self {
        let mut s = Self::default();
        let one_step = OneStepFitSettings {
            inducing: LEARN_INDUCING,
            mean: MeanFunction::Linear,
            // the default solver, L-BFGS: GP-NARX's hyperparameters at the marginal
            // likelihood's optimum, as Table 1's baseline and PILCO's own training (`minimize`
            // to convergence) have them; on the apollo tier 2.6× faster than the 300 Adam steps
            // used until 2026-12-04, 4 of 5 seeds stable against 5 of 5 (`docs/design.md`).
            // The exact GP's marginal likelihood, then the projection: the loop's GP-NARX is
            // PILCO's model (the paper's Figure 4), which fits the full GP before it sparsifies
            objective: OneStepObjective::Exact,
            ..OneStepFitSettings::default()
        };
        s.fit.method = match method {
            Method::Msgp => s.fit.method,
            Method::GpNarx => MethodSettings::GpNarx(one_step),
            Method::PilcoNarx => MethodSettings::PilcoNarx(one_step),
            Method::LinearKf => LinearKfSettings { iterations: 300 }.into(),
        };
        if method == Method::LinearKf {
            for i in s.fit.integrators.iter_mut() {
                if *i == END_EFFECTOR_INTEGRATOR {
                    *i = END_EFFECTOR_KINEMATIC;
                }
            }
            s.warm_start = Some(LINEAR_KF_WARM_START);
            s.policy_horizon_seconds = LINEAR_KF_POLICY_HORIZON_SECONDS;
        }
        s
    }
}

impl LearnSettings {
    /// The loop's defaults for `method` and, for MSGP, `likelihood`. An MSGP model trained by
    /// the filter likelihood — the loop's default for MSGP (`None`): it balanced the pendulum
    /// where the free-run MSGP did not, `RESULTS.md` — gets [`LearnSettings::filtered_msgp`];
    /// one trained by the free-run likelihood (the paper's) the MSGP defaults of
    /// [`LearnSettings::for_method`].
    pub fn for_model(method: Method, likelihood: Option<Likelihood>) -> Self {
        match (method, likelihood) {
            (Method::Msgp, None | Some(Likelihood::Filter)) => Self::filtered_msgp(),
            (Method::Msgp, Some(l)) => {
                let mut s = Self::for_method(method);
                if let Some(m) = s.fit.msgp_mut() {
                    m.likelihood = l;
                }
                s
            }
            _ => Self::for_method(method),
        }
    }

    /// The filtered MSGP loop: the GP-NARX window model trained by the filter likelihood
    /// ([`Likelihood::Filter`]), started from the linear-kf model of the same data
    /// ([`MsgpStart::LinearKf`]: the filter likelihood's own optimum without a GP, in scaled,
    /// uncentred units) with a GP of [`LEARN_INDUCING`] pseudo-inputs that starts at zero.
    /// Everything the linear-kf loop needs it gets too: the end effector kinematic, noise
    /// floors far below the sensor's ([`FILTER_NOISE_FLOOR`]), whole episodes (the filter
    /// restarts nothing), a 10 s policy horizon and warm starts. Its searches run on the GP
    /// model only while the GP predicts the episodes it had not seen better than the linear
    /// model of the same data ([`LearnSettings::prequential_choice`]).
    pub fn filtered_msgp() -> Self {
        let mut s = Self::for_method(Method::LinearKf);
        let mut fit = Self::default().fit;
        fit.integrators = s.fit.integrators.clone();
        fit.method = MsgpSettings {
            inducing: FILTERED_MSGP_INDUCING,
            iterations: FILTERED_MSGP_ITERATIONS,
            optimizer: FitOptimizer::Lbfgs,
            likelihood: Likelihood::Filter,
            validation_fraction: 0.0,
            noise_floor: FILTER_NOISE_FLOOR,
            mean: MeanFunction::Linear,
            start: MsgpStart::LinearKf,
            alternative: None,
            ..MsgpSettings::default()
        }
        .into();
        s.fit = fit;
        s.ff_segment = None;
        s.warm_start = Some(FILTERED_MSGP_WARM_START);
        s.search.iterations = FILTERED_MSGP_SEARCH_ITERATIONS;
        s.prequential_choice = true;
        s
    }

    /// The model's training method ([`FitSettings::method`]).
    pub fn method(&self) -> Method {
        self.fit.method()
    }
}

/// Evaluation episodes per iteration ([`LearnSettings::evaluation_episodes`]): the mean of 50
/// costs whose spread equals their mean is known to ±14 % (one standard error).
pub const EVALUATION_EPISODES: usize = 50;

fn evaluation_episodes() -> usize {
    EVALUATION_EPISODES
}

/// Most L-BFGS iterations of the filtered MSGP loop's first fit (from the linear-kf model of
/// the random episodes).
pub const FILTERED_MSGP_ITERATIONS: usize = 100;

/// Most L-BFGS iterations of the filtered MSGP loop's later fits, each continuing the previous
/// model ([`LearnSettings::warm_start`]). Under the prequential choice the GP model decides the
/// search only once it predicts unseen episodes better than the linear model, so its fit needs
/// to be good, not converged: 40 instead of 100 kept every run's model choices and stable
/// iterations (Figure 4's both tiers, five seeds each; the 100 Hz and the short pendulum, two
/// seeds each) at 45–65 % of the iteration time (`docs/design.md`). Before the choice, when
/// every search ran on the GP model, 40 lost the stable gains of two noisy-tier seeds of five.
pub const FILTERED_MSGP_WARM_START: usize = 40;

/// Pseudo-inputs of the filtered MSGP loop's GP: the linear mean carries the pendulum's
/// dynamics and the GP what is left over, and the moment-matching steps of the fit and the
/// search cost ∝ m². 30 instead of [`LEARN_INDUCING`] (50) kept the Figure 4 results on both
/// tiers (`RESULTS.md`, `docs/design.md`) at about half the time per iteration.
pub const FILTERED_MSGP_INDUCING: usize = 30;

/// Adam steps per start of the filtered MSGP loop's policy search: at step 0.1 (relative to each
/// gain's scale) 10 steps cross the trust region (±1 scale), so 12 reach anywhere in it; the
/// other loops keep 20.
pub const FILTERED_MSGP_SEARCH_ITERATIONS: usize = 12;

/// The noise floor of the filtered MSGP loop's models (normalised variance): the pole's process
/// noise is ~1e-4 rad per step against an angle spread of ~0.1 rad, a variance of ~1e-6 in
/// normalised units; MSGP's default floor (1e-4) would force process noise of the sensor's
/// size on the unstable pole, the failure the filter likelihood exists to avoid.
pub const FILTER_NOISE_FLOOR: f64 = 1e-9;

/// Pseudo-inputs of the loop's GP models.
pub const LEARN_INDUCING: usize = 50;

/// The policy horizon of a linear-kf loop \[s\]: the stability test's length. Once the pole is
/// held, a 5 s horizon lets the search trade a slow drift of the end effector (an ever more
/// negative `ki_x`) for a cheaper 5 s; on the five Figure 4 seeds 33–34 of 40 iterations then
/// passed the 10 s test and two runs of five ended on failing gains; with this horizon 36–37
/// of 40 passed (docs/design.md). The search takes about twice as long as at 5 s (1.1–1.2 s
/// per iteration alone on the 2-core machine, BENCHMARKS.md).
pub const LINEAR_KF_POLICY_HORIZON_SECONDS: f64 = 10.0;

/// The default warm start of a linear-kf loop ([`LearnSettings::warm_start`]): from the second
/// iteration on, at most this many L-BFGS iterations from the previous model (the solver stops
/// by itself when converged, after 10–40), instead of two cold starts. The filter likelihood
/// changes little when one episode is added, so the previous optimum is a start next to the new
/// one; from scratch, the fit's time grows with the data (to 5–14 s by iteration 8), warm it
/// stays at 0.6–2.3 s.
pub const LINEAR_KF_WARM_START: usize = 300;

/// [`END_EFFECTOR_INTEGRATOR`] declared kinematic as well: its acceleration is a linear function
/// of the commands alone (the robot's actuator), so its row is zero on the pole's lags.
pub const END_EFFECTOR_KINEMATIC: Integrator = Integrator {
    linear: true,
    ..END_EFFECTOR_INTEGRATOR
};

/// The end-effector position (output 1) is the double integral of the commanded acceleration,
/// and the plant is the same wherever the end effector is and however fast it moves: a pure
/// integrator of order 2 ([`msgp_core::gp::integrator`]). Declared by default: four random rollouts
/// do not identify it, and a model that misses it cannot tell a position loop from none
/// (docs/design.md).
pub const END_EFFECTOR_INTEGRATOR: Integrator = Integrator {
    output: 1,
    order: 2,
    linear: false,
};

/// The excitation of the random rollouts: 20 sines in 0.1–10 Hz, 1 m/s² RMS.
pub fn learn_excitation() -> ExcitationConfig {
    ExcitationConfig {
        components: 20,
        min_hz: 0.1,
        max_hz: 10.0,
        rms: 1.0,
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use msgp_core::numeric::parallel::Threads;

    /// A run made on one thread (`MSGP_THREADS=1`) reads back as the same settings: the
    /// threads are not recorded.
    #[test]
    fn settings_read_back_whatever_the_threads() {
        let mut settings = LearnSettings::for_method(Method::LinearKf);
        let one = Threads::new(1).expect("one thread");
        settings.fit.threads = one;
        settings.search.threads = one;
        let text = serde_json::to_string(&settings).expect("written");
        let stored: LearnSettings = serde_json::from_str(&text).expect("read");
        assert_eq!(stored, settings.as_recorded());
        assert_eq!(stored.fit.threads, Threads::default());
    }
}
