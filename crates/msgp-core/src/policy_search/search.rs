//! The search: Adam (or L-BFGS) with seeded restarts around the current gains, each gain on its
//! own scale, minimising [`PolicyProblem`]'s expected cost by its adjoint gradient — or the
//! mean expected cost of several problems, one per start ([`optimise_over`]).

use rand::{SeedableRng, rngs::StdRng};
use rand_distr::{Distribution, StandardNormal};
use serde::{Deserialize, Serialize};

use super::objective::{PolicyProblem, policy_gradient};
use super::space::{PidMask, SearchSpace};
use crate::error::{MsgpError, Result};
use crate::numeric::parallel::{Threads, map_indexed};
use crate::optim::{Adam, AdamState, Flow, Lbfgs, Objective, Solver, minimize};
use crate::policy::{PidPolicy, Policy};

/// Settings of the policy optimisation.
#[derive(Clone, Copy, Debug, PartialEq, Serialize, Deserialize)]
pub struct PolicySearchSettings {
    /// Adam steps, or most L-BFGS iterations, per start ([`PolicySearchSettings::solver`]).
    pub iterations: usize,
    /// Adam step size, relative to each gain's scale (`max(|g₀|, typical)`, see
    /// [`optimise_pid_scaled`]).
    pub learning_rate: f64,
    /// Extra starts: the current gains perturbed by `restart_spread` (relative), seeded.
    pub restarts: usize,
    /// Relative size of the restart perturbations.
    pub restart_spread: f64,
    /// Seed of the restarts and candidates.
    pub seed: u64,
    /// Random candidates screened on the model before the gradient starts: each free gain is
    /// drawn from `N(0, (candidate_spread · scale)²)` around zero (signs included, so
    /// no sign of the gains is assumed), evaluated in f64, and the `candidate_starts` cheapest
    /// become extra Adam starts. 0 switches the screening off.
    pub candidates: usize,
    /// Relative width of the candidate distribution.
    pub candidate_spread: f64,
    /// How many of the best candidates are refined by Adam.
    pub candidate_starts: usize,
    /// Trust region of one search, in units of each gain's scale: every start, candidate and
    /// Adam iterate keeps `|g − g₀| ≤ trust_region · scale` gain by gain, and the candidates
    /// are drawn around `g₀` instead of zero. Keeps the new gains where the model has seen data
    /// (a model fitted to a few episodes is least reliable for gains far from them). 0 (the
    /// default) switches it off.
    #[serde(default)]
    pub trust_region: f64,
    /// The solver of each start: Adam for `iterations` steps of `learning_rate` (the PID
    /// loop's few gains), or L-BFGS for up to `iterations` iterations, each step at most one
    /// scale per parameter (PILCO's choice for its RBF networks of many parameters). L-BFGS
    /// has no trust region.
    #[serde(default)]
    pub solver: PolicySolver,
    /// Threads of the screened candidates and the Adam starts (they are independent; the
    /// result does not depend on it).
    #[serde(skip)]
    pub threads: Threads,
}

/// The solver of each start of the policy search ([`PolicySearchSettings::solver`]).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Serialize, Deserialize)]
#[serde(rename_all = "kebab-case")]
pub enum PolicySolver {
    /// Adam.
    #[default]
    Adam,
    /// L-BFGS with a backtracking line search ([`crate::optim::Lbfgs`]).
    Lbfgs,
}

impl Default for PolicySearchSettings {
    fn default() -> Self {
        Self {
            iterations: 60,
            learning_rate: 0.05,
            restarts: 2,
            restart_spread: 0.3,
            seed: 0,
            candidates: 0,
            candidate_spread: 2.0,
            candidate_starts: 2,
            trust_region: 0.0,
            solver: PolicySolver::Adam,
            threads: Threads::default(),
        }
    }
}

/// Result of a policy optimisation.
#[derive(Clone, Debug)]
pub struct PolicySearchResult {
    /// The best policy found.
    pub policy: Policy,
    /// Their expected total cost.
    pub expected_cost: f64,
    /// Per-step (mean, variance) of the cost under the best gains.
    pub steps: Vec<(f64, f64)>,
}

/// Minimises the expected cost over the free gains, starting from `initial` and from
/// `settings.restarts` seeded perturbations of it; returns the best. Each gain's scale (of the
/// Adam steps, restarts and candidates) is `max(|g₀|, 1)`.
pub fn optimise_pid(
    problem: &PolicyProblem<'_>,
    initial: &PidPolicy<f64>,
    mask: &PidMask,
    settings: &PolicySearchSettings,
) -> Result<PolicySearchResult> {
    let typical = vec![1.0; mask.len()];
    optimise_pid_scaled(problem, initial, mask, &typical, settings)
}

/// [`optimise_pid`] with each free gain's scale `max(|g₀|, typical)`, `typical` packed like
/// [`PidMask::pack`]: a gain that has come near zero keeps the scale of its kind, so the
/// candidates and the Adam steps can still reach typical magnitudes again. The candidates and
/// starts run on [`PolicySearchSettings::threads`] threads.
pub fn optimise_pid_scaled(
    problem: &PolicyProblem<'_>,
    initial: &PidPolicy<f64>,
    mask: &PidMask,
    typical: &[f64],
    settings: &PolicySearchSettings,
) -> Result<PolicySearchResult> {
    optimise(problem, &SearchSpace::pid(initial, mask), typical, settings)
}

/// Minimises the expected cost over the free parameters of `space`, from its base's values and
/// from seeded perturbations and screened candidates ([`PolicySearchSettings`]); each free
/// parameter's scale is `max(|θ₀|, typical)` (`typical` packed like [`SearchSpace::pack`]).
/// The candidates and starts run on [`PolicySearchSettings::threads`] threads; the result does
/// not depend on their number.
pub fn optimise(
    problem: &PolicyProblem<'_>,
    space: &SearchSpace,
    typical: &[f64],
    settings: &PolicySearchSettings,
) -> Result<PolicySearchResult> {
    optimise_over(std::slice::from_ref(problem), space, typical, settings, &[])
}

/// [`optimise`] of the mean expected cost over several problems: one model, rollouts from
/// several starts (PILCO's policy for a plant whose episodes start anywhere in a region:
/// a single Gaussian over such starts is no state the plant is ever in). The result's
/// expected cost and per-step moments are the problems' means. `also_from` are further
/// starts (free parameters packed like [`SearchSpace::pack`]), run like the base's: the
/// learner's first policy, so that a search whose running policy saturates (every gradient
/// near zero) still has PILCO's fresh start.
pub fn optimise_over(
    problems: &[PolicyProblem<'_>],
    space: &SearchSpace,
    typical: &[f64],
    settings: &PolicySearchSettings,
    also_from: &[Vec<f64>],
) -> Result<PolicySearchResult> {
    check_search(problems, space, typical, settings)?;
    let threads = settings.threads.get();
    let region = Region::new(space.start(), typical, settings.trust_region);
    let starts = search_starts(problems, space, settings, &region, also_from)?;
    // each start's run is independent; its best (value, gains), earliest first on ties
    let run_start = |_: usize, start: &Vec<f64>| -> Result<Option<(f64, Vec<f64>)>> {
        match settings.solver {
            PolicySolver::Lbfgs => {
                lbfgs_start(problems, space, &region.scale, start, settings.iterations)
            }
            PolicySolver::Adam => adam_start(problems, space, &region, settings, start),
        }
    };
    let mut best: Option<(f64, Vec<f64>)> = None;
    // reduced in start order with a strict `<`: the same answer for any thread count
    for found in map_indexed(&starts, threads, run_start) {
        if let Some((value, g)) = found?
            && best.as_ref().is_none_or(|b| value < b.0)
        {
            best = Some((value, g));
        }
    }
    let (value, g) =
        best.ok_or_else(|| MsgpError::NonFinite("every policy-search start diverged".into()))?;
    let policy = space.controller(&g)?;
    let (_, steps) = mean_evaluate(problems, space, &g)?;
    Ok(PolicySearchResult {
        policy,
        expected_cost: value,
        steps,
    })
}

/// The search's settings checked against its problems and space.
fn check_search(
    problems: &[PolicyProblem<'_>],
    space: &SearchSpace,
    typical: &[f64],
    settings: &PolicySearchSettings,
) -> Result<()> {
    if problems.is_empty() {
        return Err(MsgpError::InvalidSetting {
            name: "policy search starts",
            reason: "the search needs at least one start".into(),
        });
    }
    space.validate()?;
    if typical.len() != space.len() || typical.iter().any(|t| !(t.is_finite() && *t > 0.0)) {
        return Err(MsgpError::InvalidSetting {
            name: "policy search scales",
            reason: format!(
                "need {} positive finite typical parameter magnitudes, got {typical:?}",
                space.len()
            ),
        });
    }
    if !(settings.trust_region.is_finite() && settings.trust_region >= 0.0) {
        return Err(MsgpError::InvalidSetting {
            name: "trust_region",
            reason: format!("must be finite and ≥ 0, got {}", settings.trust_region),
        });
    }
    if settings.solver == PolicySolver::Lbfgs && settings.trust_region > 0.0 {
        return Err(MsgpError::InvalidSetting {
            name: "trust_region",
            reason: "the L-BFGS policy search has no trust region; set it to 0".into(),
        });
    }
    Ok(())
}

/// Where the search may go: around the base's parameters `x0`, each free parameter on its
/// scale `max(|θ₀|, typical)`, within `trust` scales of `x0` where the trust region is on.
struct Region {
    x0: Vec<f64>,
    scale: Vec<f64>,
    trust: f64,
}

impl Region {
    fn new(x0: Vec<f64>, typical: &[f64], trust: f64) -> Self {
        let scale = x0
            .iter()
            .zip(typical)
            .map(|(g, t)| g.abs().max(*t))
            .collect();
        Self { x0, scale, trust }
    }

    /// `x` projected into the trust region (unchanged when it is off).
    fn project(&self, x: &mut [f64]) {
        if self.trust > 0.0 {
            for ((g, g0), s) in x.iter_mut().zip(&self.x0).zip(&self.scale) {
                *g = g.clamp(g0 - self.trust * s, g0 + self.trust * s);
            }
        }
    }

    /// `centre + spread · scale · z`, z ~ N(0, I), kept in the trust region.
    fn draw(&self, rng: &mut StdRng, centre: &[f64], spread: f64) -> Vec<f64> {
        let mut x: Vec<f64> = centre
            .iter()
            .zip(&self.scale)
            .map(|(c, s)| {
                let z: f64 = StandardNormal.sample(rng);
                c + spread * s * z
            })
            .collect();
        self.project(&mut x);
        x
    }
}

/// The search's starts, in order: the base's parameters, `also_from` (those that differ),
/// the seeded perturbations, and the cheapest of the screened candidates.
fn search_starts(
    problems: &[PolicyProblem<'_>],
    space: &SearchSpace,
    settings: &PolicySearchSettings,
    region: &Region,
    also_from: &[Vec<f64>],
) -> Result<Vec<Vec<f64>>> {
    let x0 = &region.x0;
    let mut rng = StdRng::seed_from_u64(settings.seed);
    let mut starts = vec![x0.clone()];
    for extra in also_from {
        if extra.len() != x0.len() {
            return Err(MsgpError::InvalidSetting {
                name: "policy search starts",
                reason: format!(
                    "a start has {} parameters, the space {}",
                    extra.len(),
                    x0.len()
                ),
            });
        }
        if extra != x0 {
            starts.push(extra.clone());
        }
    }
    for _ in 0..settings.restarts {
        starts.push(region.draw(&mut rng, x0, settings.restart_spread));
    }
    if settings.candidates > 0 {
        let centre: Vec<f64> = if region.trust > 0.0 {
            x0.clone()
        } else {
            vec![0.0; x0.len()]
        };
        // drawn in sequence (one stream), evaluated in parallel
        let drawn: Vec<Vec<f64>> = (0..settings.candidates)
            .map(|_| region.draw(&mut rng, &centre, settings.candidate_spread))
            .collect();
        let threads = settings.threads.get();
        let k = settings.candidate_starts;
        starts.extend(cheapest_candidates(problems, space, &drawn, k, threads));
    }
    Ok(starts)
}

/// One start's Adam run in scaled coordinates `z = g / scale` (one step size fits every
/// gain), kept in the trust region: its best value and parameters, `None` where none was
/// finite. Parameters whose rollout fails numerically end the run; the best so far stays.
fn adam_start(
    problems: &[PolicyProblem<'_>],
    space: &SearchSpace,
    region: &Region,
    settings: &PolicySearchSettings,
    start: &[f64],
) -> Result<Option<(f64, Vec<f64>)>> {
    let (scale, tr) = (&region.scale, region.trust);
    let mut best: Option<(f64, Vec<f64>)> = None;
    let mut objective = Scaled::new(problems, space, scale);
    let mut z: Vec<f64> = start.iter().zip(scale).map(|(g, s)| g / s).collect();
    let adam = Adam {
        learning_rate: settings.learning_rate,
        ..Adam::default()
    };
    let mut state = AdamState::new(z.len());
    let on = vec![true; z.len()];
    for _ in 0..settings.iterations {
        let (value, gz) = objective.value_and_gradient(&z)?;
        if value.is_nan() {
            break;
        }
        if value.is_finite() && best.as_ref().is_none_or(|b| value < b.0) {
            best = Some((value, objective.unscaled(&z)));
        }
        adam.step(&mut state, &mut z, &gz, &on);
        if tr > 0.0 {
            for ((z, g0), s) in z.iter_mut().zip(&region.x0).zip(scale) {
                *z = z.clamp(g0 / s - tr, g0 / s + tr);
            }
        }
    }
    let g: Vec<f64> = z.iter().zip(scale).map(|(z, s)| z * s).collect();
    if let Ok((value, _)) = mean_evaluate(problems, space, &g)
        && value.is_finite()
        && best.as_ref().is_none_or(|b| value < b.0)
    {
        best = Some((value, g));
    }
    Ok(best)
}

/// The search's objective in scaled coordinates `z = x / scale`; a point where a rollout
/// fails numerically has no value (NaN: the line search's "too far").
/// Both solvers of the search run on it.
struct Scaled<'a, 'p> {
    problems: &'a [PolicyProblem<'p>],
    space: &'a SearchSpace,
    scale: &'a [f64],
    active: Vec<usize>,
}

impl<'a, 'p> Scaled<'a, 'p> {
    fn new(problems: &'a [PolicyProblem<'p>], space: &'a SearchSpace, scale: &'a [f64]) -> Self {
        Self {
            problems,
            space,
            scale,
            active: (0..scale.len()).collect(),
        }
    }

    /// The parameters at `z`.
    fn unscaled(&self, z: &[f64]) -> Vec<f64> {
        z.iter().zip(self.scale).map(|(z, s)| z * s).collect()
    }
}

impl Objective for Scaled<'_, '_> {
    fn value_and_gradient(&mut self, z: &[f64]) -> Result<(f64, Vec<f64>)> {
        let x = self.unscaled(z);
        match mean_gradient(self.problems, self.space, &x, &self.active) {
            Ok((v, g)) => Ok((v, g.iter().zip(self.scale).map(|(d, s)| d * s).collect())),
            Err(e) if e.is_numerical() => Ok((f64::NAN, vec![0.0; z.len()])),
            Err(e) => Err(e),
        }
    }
}

/// One start's L-BFGS run: the best (value, parameters) it reached, `None` when its start
/// cannot be evaluated.
fn lbfgs_start(
    problems: &[PolicyProblem<'_>],
    space: &SearchSpace,
    scale: &[f64],
    start: &[f64],
    iterations: usize,
) -> Result<Option<(f64, Vec<f64>)>> {
    let mut objective = Scaled::new(problems, space, scale);
    let z0: Vec<f64> = start.iter().zip(scale).map(|(x, s)| x / s).collect();
    let solver = Solver::Lbfgs(Lbfgs::default());
    let on = vec![true; z0.len()];
    let (z, value) = minimize(&mut objective, &solver, z0, &on, iterations, |_, _, _| {
        Ok(Flow::Continue)
    })?;
    Ok(value.is_finite().then(|| (value, objective.unscaled(&z))))
}

/// The problems' mean expected cost of the policy at `x` and their mean per-step moments.
fn mean_evaluate(
    problems: &[PolicyProblem<'_>],
    space: &SearchSpace,
    x: &[f64],
) -> Result<(f64, Vec<(f64, f64)>)> {
    let policy = space.policy::<f64>(x)?;
    let n = problems.len() as f64;
    let mut total = 0.0;
    let mut steps: Vec<(f64, f64)> = Vec::new();
    for problem in problems {
        let (value, s) = problem.evaluate(policy.as_ref())?;
        total += value / n;
        steps.resize(s.len().max(steps.len()), (0.0, 0.0));
        for (acc, (m, v)) in steps.iter_mut().zip(s) {
            acc.0 += m / n;
            acc.1 += v / n;
        }
    }
    Ok((total, steps))
}

/// The problems' mean expected cost at `x` if it is at most `bound` (each rollout stops once
/// the mean can no longer come in under it), `None` otherwise.
fn mean_bounded(
    problems: &[PolicyProblem<'_>],
    space: &SearchSpace,
    x: &[f64],
    bound: f64,
) -> Result<Option<f64>> {
    let policy = space.policy::<f64>(x)?;
    let n = problems.len() as f64;
    let mut sum = 0.0;
    for problem in problems {
        let left = if bound.is_finite() {
            n * bound - sum
        } else {
            f64::INFINITY
        };
        match problem.evaluate_bounded(policy.as_ref(), left)? {
            Some(value) => sum += value,
            None => return Ok(None),
        }
    }
    Ok(Some(sum / n))
}

/// The problems' mean expected cost at `x` and its gradient.
fn mean_gradient(
    problems: &[PolicyProblem<'_>],
    space: &SearchSpace,
    x: &[f64],
    active: &[usize],
) -> Result<(f64, Vec<f64>)> {
    let n = problems.len() as f64;
    let mut value = 0.0;
    let mut grad = vec![0.0; x.len()];
    for problem in problems {
        let (v, g) = policy_gradient(problem, space, x, active)?;
        value += v / n;
        for (acc, d) in grad.iter_mut().zip(g) {
            *acc += d / n;
        }
    }
    Ok((value, grad))
}

/// The `keep` cheapest of the `drawn` candidates (cheapest first, the earlier drawn first on
/// ties), screened on up to `threads` threads. Each thread screens every `threads`-th candidate
/// in order and bounds each rollout by the `keep`-th cheapest it has fully evaluated so far
/// ([`PolicyProblem::evaluate_bounded`]): a candidate dearer than that cannot be among the
/// `keep` cheapest of all, so the answer is that of evaluating every candidate in full, for any
/// thread count, while most of the bad candidates (the pole falls, the cost climbs by about one
/// per step) stop after a fraction of the horizon. A candidate whose rollout fails numerically
/// is simply not a start.
fn cheapest_candidates(
    problems: &[PolicyProblem<'_>],
    space: &SearchSpace,
    drawn: &[Vec<f64>],
    keep: usize,
    threads: usize,
) -> Vec<Vec<f64>> {
    if keep == 0 || drawn.is_empty() {
        return Vec::new();
    }
    let groups = threads.clamp(1, drawn.len());
    let members: Vec<Vec<usize>> = (0..groups)
        .map(|w| (w..drawn.len()).step_by(groups).collect())
        .collect();
    let screen = |_: usize, group: &Vec<usize>| -> Result<Vec<(f64, usize)>> {
        // this group's cheapest so far, ascending by (value, index), at most `keep`
        let mut best: Vec<(f64, usize)> = Vec::with_capacity(keep + 1);
        for &k in group {
            let bound = if best.len() == keep {
                best[keep - 1].0
            } else {
                f64::INFINITY
            };
            let Ok(Some(value)) = mean_bounded(problems, space, &drawn[k], bound) else {
                continue;
            };
            if !value.is_finite() {
                continue;
            }
            let at = best.partition_point(|&(v, i)| (v, i) < (value, k));
            best.insert(at, (value, k));
            best.truncate(keep);
        }
        Ok(best)
    };
    let mut found: Vec<(f64, usize)> = map_indexed(&members, groups, screen)
        .into_iter()
        .flatten()
        .flatten()
        .collect();
    found.sort_by(|a, b| a.0.total_cmp(&b.0).then(a.1.cmp(&b.1)));
    found
        .into_iter()
        .take(keep)
        .map(|(_, k)| drawn[k].clone())
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::data::Trajectory;
    use crate::fit::{
        FitSettings, MethodSettings, OneStepFitSettings, OneStepObjective, OneStepSolver, fit,
    };
    use crate::gp::MeanFunction;
    use crate::model::Model;
    use crate::policy::{
        CommandBounds, FeedbackPolicy, Normalized, Policy, RbfPolicy, RestEntry, StateFeedback,
    };
    use crate::policy_search::{SaturatingCost, policy_gradient_duals};
    use nalgebra::{DMatrix, DVector};

    /// A one-step GP-NARX model (l_y = 2, l_u = 1, m = 20) of two outputs
    /// `cos(0.1t + j) + extra(t, j)` driven by `u = sin(0.31t)`.
    fn two_output_model(extra: impl Fn(usize, usize) -> f64) -> Model {
        two_output_model_with(extra, MeanFunction::Zero)
    }

    fn two_output_model_with(extra: impl Fn(usize, usize) -> f64, mean: MeanFunction) -> Model {
        let n = 120;
        let u = DMatrix::from_fn(n, 1, |t, _| (t as f64 * 0.31).sin());
        let y = DMatrix::from_fn(n, 2, |t, j| (t as f64 * 0.1 + j as f64).cos() + extra(t, j));
        let traj = Trajectory::new(u, y).expect("traj");
        let settings = FitSettings {
            ly: 2,
            lu: 1,
            method: MethodSettings::GpNarx(OneStepFitSettings {
                inducing: 20,
                iterations: 30,
                mean,
                // a one-step fit stopped short: on these noise-free outputs the optimum's noise
                // sits at the floor and the rollouts lose the digits these tests compare
                solver: OneStepSolver::Adam,
                objective: OneStepObjective::Exact,
            }),
            ..FitSettings::default()
        };
        fit(&[traj], &settings, &mut |_| {}).expect("fit").0
    }

    /// The problem of driving the two outputs from an uncertain start off rest to zero over
    /// `horizon` steps.
    fn off_rest_problem(model: &Model, horizon: usize) -> PolicyProblem<'_> {
        PolicyProblem {
            model,
            y0_mean: vec![0.2, -0.1],
            y0_var: vec![0.01, 0.02],
            u0: vec![0.0],
            cost: SaturatingCost::with_widths(DVector::zeros(2), &[0.5, 0.5]).expect("cost"),
            horizon,
        }
    }

    /// Zero PID gains on two outputs (one input, limit 2) and a mask freeing `kp` and `kd`.
    fn zero_pd_gains() -> (PidPolicy<f64>, PidMask) {
        let initial = PidPolicy::new(
            DMatrix::zeros(1, 2),
            DMatrix::zeros(1, 2),
            DMatrix::zeros(1, 2),
            0.1,
            vec![2.0],
        )
        .expect("policy");
        let mask = PidMask {
            kp: DMatrix::from_element(1, 2, true),
            ki: DMatrix::from_element(1, 2, false),
            kd: DMatrix::from_element(1, 2, true),
        };
        (initial, mask)
    }

    /// The search's gradient (one dual lane per free gain) equals the generic 8-lane dual
    /// gradient to rounding and central finite differences to their truncation error.
    #[test]
    fn the_adjoint_search_gradient_matches_duals_and_finite_differences() {
        for mean in [MeanFunction::Zero, MeanFunction::Linear] {
            search_gradient_matches_duals_and_finite_differences(mean, &free_pid(), false);
        }
    }

    /// The same for the state feedback (duals through its map) and the RBF network (its map's
    /// closed-form VJP through the moment matching's backward pass).
    #[test]
    fn the_state_feedback_and_rbf_gradients_match_duals_and_finite_differences() {
        for space in [free_state_feedback(), free_rbf()] {
            search_gradient_matches_duals_and_finite_differences(
                MeanFunction::Linear,
                &space,
                false,
            );
        }
    }

    /// The same with the first output an angle costed on its unit tip (the trigonometric
    /// moments inside every step's cost).
    #[test]
    fn the_tip_cost_gradient_matches_duals_and_finite_differences() {
        for space in [free_pid(), free_rbf()] {
            search_gradient_matches_duals_and_finite_differences(
                MeanFunction::Linear,
                &space,
                true,
            );
        }
    }

    /// The bounded screening returns exactly the `keep` cheapest of every candidate evaluated
    /// in full (same order, ties to the earlier drawn), on one thread and on three, and a
    /// bounded evaluation stops only rollouts that end above the bound.
    #[test]
    fn the_bounded_screening_keeps_the_cheapest_candidates_of_a_full_evaluation() {
        let model = two_output_model_with(
            |t, _| 0.3 * (t as f64 * 0.31 - 0.4).sin(),
            MeanFunction::Linear,
        );
        let problem = off_rest_problem(&model, 40);
        let (initial, mask) = zero_pd_gains();
        let mut rng = StdRng::seed_from_u64(7);
        let drawn: Vec<Vec<f64>> = (0..40)
            .map(|_| {
                (0..4)
                    .map(|_| {
                        let z: f64 = StandardNormal.sample(&mut rng);
                        2.0 * z
                    })
                    .collect()
            })
            .collect();
        let full: Vec<f64> = drawn
            .iter()
            .map(|x| {
                problem
                    .evaluate(&mask.unpack::<f64>(&initial, x))
                    .expect("full")
                    .0
            })
            .collect();
        let spread = full.iter().fold(0.0f64, |m, v| m.max(*v))
            - full.iter().fold(f64::INFINITY, |m, v| m.min(*v));
        assert!(spread > 1.0, "candidates that differ: {full:?}");
        let mut order: Vec<usize> = (0..drawn.len()).collect();
        order.sort_by(|a, b| full[*a].total_cmp(&full[*b]).then(a.cmp(b)));
        for keep in [1, 3] {
            let expected: Vec<Vec<f64>> = order[..keep].iter().map(|k| drawn[*k].clone()).collect();
            for threads in [1, 3] {
                let space = SearchSpace::pid(&initial, &mask);
                let got = cheapest_candidates(
                    std::slice::from_ref(&problem),
                    &space,
                    &drawn,
                    keep,
                    threads,
                );
                assert_eq!(got, expected, "keep {keep}, {threads} threads");
            }
        }
        // a bound below a candidate's cost stops it, one at or above returns the full value
        let median = {
            let mut v = full.clone();
            v.sort_by(f64::total_cmp);
            v[v.len() / 2]
        };
        for (x, v) in drawn.iter().zip(&full) {
            let p = mask.unpack::<f64>(&initial, x);
            let bounded = problem.evaluate_bounded(&p, median).expect("bounded");
            if *v <= median {
                assert_eq!(bounded.map(f64::to_bits), Some(v.to_bits()));
            } else if *v > median * (1.0 + 1e-6) + 1e-6 {
                assert_eq!(bounded, None, "{v} above the bound {median}");
            }
            let open = problem
                .evaluate_bounded(&p, f64::INFINITY)
                .expect("unbounded");
            assert_eq!(open.map(f64::to_bits), Some(v.to_bits()));
        }
    }

    #[test]
    fn the_gradient_refuses_gains_that_do_not_fit_the_mask() {
        let model = two_output_model(|_, _| 0.0);
        let problem = PolicyProblem {
            model: &model,
            y0_mean: vec![0.0, 0.0],
            y0_var: vec![0.01, 0.01],
            u0: vec![0.0],
            cost: SaturatingCost::with_widths(DVector::zeros(2), &[0.5, 0.5]).expect("cost"),
            horizon: 5,
        };
        let (initial, mask) = zero_pd_gains();
        let space = SearchSpace::pid(&initial, &mask);
        let err = problem
            .gradient(&space, &[0.1, 0.2, 0.3])
            .expect_err("three gains for a mask that frees four");
        assert!(
            err.to_string()
                .contains("3 parameters given, the search frees 4"),
            "{err}"
        );
        assert!(problem.gradient(&space, &[0.1; 4]).is_ok());
    }

    /// A PID policy with every gain free, gains small enough for the saturation to stay
    /// smooth.
    fn free_pid() -> SearchSpace {
        let initial = PidPolicy::new(
            DMatrix::from_row_slice(1, 2, &[-0.3, 0.2]),
            DMatrix::from_row_slice(1, 2, &[0.05, -0.02]),
            DMatrix::from_row_slice(1, 2, &[0.1, 0.04]),
            0.1,
            vec![2.0],
        )
        .expect("policy");
        SearchSpace::all(Policy::Pid(initial))
    }

    /// A state feedback on two observations and one past command, asymmetric bounds.
    fn free_state_feedback() -> SearchSpace {
        let bounds = CommandBounds::new(vec![-1.5], vec![2.5]).expect("bounds");
        let sf = StateFeedback::new(
            DMatrix::from_row_slice(1, 5, &[-0.4, 0.3, 0.1, -0.05, 0.2]),
            DVector::from_vec(vec![0.1]),
            2,
            (2, 1),
            bounds,
        )
        .expect("state feedback");
        SearchSpace::all(Policy::StateFeedback(sf))
    }

    /// An RBF network of four centres on the two observations.
    fn free_rbf() -> SearchSpace {
        let bounds = CommandBounds::new(vec![-2.0], vec![2.0]).expect("bounds");
        let rbf = RbfPolicy::new(
            DMatrix::from_row_slice(4, 2, &[0.3, -0.2, -0.1, 0.4, 0.0, 0.1, 0.5, 0.5]),
            DMatrix::from_row_slice(4, 1, &[0.8, -0.6, 0.4, -0.3]),
            DVector::from_vec(vec![-0.7, -0.4]),
            bounds,
        )
        .expect("rbf");
        SearchSpace::all(Policy::Rbf(rbf))
    }

    fn search_gradient_matches_duals_and_finite_differences(
        mean: MeanFunction,
        space: &SearchSpace,
        angle: bool,
    ) {
        // outputs that follow the input, so the parameters matter
        let model = two_output_model_with(|t, _| 0.3 * (t as f64 * 0.31 - 0.4).sin(), mean);
        let mut problem = off_rest_problem(&model, 30);
        if angle {
            problem.cost = SaturatingCost::with_angles(
                DVector::from_vec(vec![0.4, 0.0]),
                &[0.5, 0.5],
                &[true, false],
            )
            .expect("cost");
        }
        let g = space.start();
        let active: Vec<usize> = (0..g.len()).collect();
        // the search's gradient: the adjoint sweep
        let (value, grad) = policy_gradient(&problem, space, &g, &active).expect("grad");
        // the references: duals with one lane per parameter (up to eight), and with eight
        let (value6, grad6) = policy_gradient_duals(&problem, space, &g, &active).expect("grad6");
        let (value8, grad8) = crate::numeric::dual::gradient(&g, &active, 1, |gd| {
            Ok(problem.evaluate(space.policy(gd)?.as_ref())?.0)
        })
        .expect("grad8");
        assert_eq!(value6.to_bits(), value8.to_bits());
        assert_eq!(grad6, grad8);
        let f = |x: &[f64]| {
            problem
                .evaluate(space.policy::<f64>(x).expect("policy").as_ref())
                .expect("f")
                .0
        };
        // the f64 run takes the vectorised moment-matching path: equal up to rounding
        let v64 = f(&g);
        assert!((value - v64).abs() <= 1e-12 * v64.abs(), "{value} vs {v64}");
        let scale = grad.iter().fold(0.0f64, |m, d| m.max(d.abs()));
        assert!(scale > 1e-3, "a gradient to compare: {grad:?}");
        assert!(
            (value8 - v64).abs() <= 1e-12 * v64.abs(),
            "{value8} vs {v64}"
        );
        for i in 0..g.len() {
            // different orders of the same arithmetic: equal to rounding
            assert!(
                (grad[i] - grad8[i]).abs() <= 1e-10 * scale,
                "{} {i}: adjoint {grad:?} vs duals {grad8:?}",
                space.base.kind()
            );
            let h = 1e-5;
            let (mut gp, mut gm) = (g.clone(), g.clone());
            gp[i] += h;
            gm[i] -= h;
            let fd = (f(&gp) - f(&gm)) / (2.0 * h);
            assert!(
                (grad[i] - fd).abs() <= 1e-6 * scale,
                "{} {i}: dual {} vs fd {fd}",
                space.base.kind(),
                grad[i]
            );
        }
    }

    /// A window policy's state at rest: two earlier observations of each output (the latent
    /// start plus independent observation noise: correlated by `y0_var`) and the earlier
    /// command at `u0`.
    #[test]
    fn a_window_policys_start_holds_earlier_observations_and_commands() {
        let model = two_output_model(|t, j| 0.01 * ((t * 7 + j) as f64).sin());
        let problem = PolicyProblem {
            u0: vec![0.7],
            ..off_rest_problem(&model, 5)
        };
        let space = free_state_feedback();
        let Policy::StateFeedback(sf) = &space.base else {
            panic!("a state feedback")
        };
        let policy = Normalized {
            inner: sf.clone(),
            normalizer: model.normalizer.clone(),
        };
        let rest = policy.rest_state();
        assert_eq!(
            rest,
            vec![
                RestEntry::Observation(0),
                RestEntry::Observation(1),
                RestEntry::Command(0)
            ]
        );
        let start = problem.start::<f64>(&rest);
        let d = model.spec.input_dim();
        assert_eq!(start.mean[d], problem.y0_mean[0]);
        assert_eq!(start.mean[d + 1], problem.y0_mean[1]);
        assert_eq!(start.mean[d + 2], 0.7);
        assert_eq!(start.cov[(d + 2, d + 2)], 0.0);
        assert_eq!(start.cov[(d, d + 1)], 0.0);
        // the window's own lags at rest hold u0 too
        let n = &model.normalizer;
        let u = start.mean[model.spec.u_index(0, 0)] * n.u_std[0] + n.u_mean[0];
        assert!((u - 0.7).abs() < 1e-12);
    }

    #[test]
    fn the_policy_start_sees_observation_noise_not_the_start_spread() {
        // two outputs, so the window has several output lags per output
        let model = two_output_model(|t, j| 0.01 * ((t * 7 + j) as f64).sin());
        let y0_var = [0.04, 0.09];
        let problem = PolicyProblem {
            model: &model,
            y0_mean: vec![0.2, -0.1],
            y0_var: y0_var.to_vec(),
            u0: vec![0.0],
            cost: SaturatingCost::with_widths(DVector::zeros(2), &[0.5, 0.5]).expect("cost"),
            horizon: 5,
        };
        let rest = [
            RestEntry::Observation(0),
            RestEntry::Observation(1),
            RestEntry::Zero,
            RestEntry::Zero,
        ];
        let start = problem.start::<f64>(&rest);
        let (spec, norm) = (model.spec, &model.normalizer);
        let d = spec.input_dim();
        for j in 0..2 {
            let std = norm.y_std[j];
            let sy2 = model.params.log_obs_noise[j].exp() + model.config.noise_floor;
            let p = d + j;
            assert!((start.mean[p] - problem.y0_mean[j]).abs() < 1e-15);
            for k in 0..spec.ly {
                // the policy's previous observation minus the latent output at lag k, in
                // original units: only observation noise (the old deterministic start gave
                // this difference the whole y0_var, a random kick to any derivative term)
                let i = spec.y_index(k, j);
                let var_diff = start.cov[(p, p)] + std * std * start.cov[(i, i)]
                    - 2.0 * std * start.cov[(p, i)];
                let want = sy2 * std * std;
                assert!(
                    (var_diff - want).abs() <= 1e-12 * y0_var[j],
                    "output {j} lag {k}: {var_diff:e} vs {want:e}"
                );
            }
            // and nothing links the two outputs
            assert_eq!(start.cov[(d, d + 1)], 0.0);
        }
    }
}
