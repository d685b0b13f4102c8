//! The paper's Figure 4 as independent learning runs: PILCO on the simulated pendulum with
//! several models and seeds; per run the iteration and interaction time of the first policy
//! that passes the stability test, and the cost curves over seeds.
//!
//! A [`Plan`] (plant, models, seeds, iterations, [`Budget`], folder) lists its [`Unit`]s (one
//! model × seed each); every unit is one learning loop whose folder
//! ([`msgp_sim::learn::write_run_dir`]) is collected again by [`Plan::finished`]; [`report`]
//! draws the cost bands and renders the markdown section from the finished runs. `msgp
//! reproduce figure4` runs the units one after another (reusing finished folders), the Python
//! sweep (`python -m msgp.sweep figure4`) on processes or a Ray cluster: same units, same
//! numbers (a run's numbers do not depend on the machine or the thread count).

use std::fmt::Write as _;
use std::path::{Path, PathBuf};

use msgp_core::fit::FitOptimizer;
use msgp_core::learner::LoopModel;
use msgp_core::loss::Likelihood;
use msgp_core::model::Method;
use serde::{Deserialize, Serialize};

use msgp_sim::learn::{
    Budget, FILTERED_MSGP_INDUCING, FILTERED_MSGP_ITERATIONS, FILTERED_MSGP_SEARCH_ITERATIONS,
    FILTERED_MSGP_WARM_START, FinishedRun, IterationReport, LEARN_INDUCING,
    LINEAR_KF_POLICY_HORIZON_SECONDS, LINEAR_KF_WARM_START, LearnSettings, SearchModel,
    finished_run,
};
use msgp_sim::params::PendulumParams;
use msgp_sim::plot::CostPoint;

use crate::error::{ReproduceError, Result};
use crate::plot::plot_cost_bands;
pub use crate::results::Provenance;

/// One learning run of the plan.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Serialize, Deserialize)]
pub struct Unit {
    /// Its model.
    pub model: LoopModel,
    /// Its seed.
    pub seed: u64,
}

impl Unit {
    /// `<model>-seed<k>`: its folder's name.
    pub fn name(&self) -> String {
        format!("{}-seed{}", self.model.name(), self.seed)
    }
}

/// A validated reproduction of Figure 4.
#[derive(Clone, Debug, PartialEq, Serialize, Deserialize)]
pub struct Plan {
    /// The plant tier's name (`apollo`, `noisy`): the section is `figure4-<tier>`.
    pub tier: String,
    /// The plant every run learns on.
    pub plant: PendulumParams,
    /// Models, in the table's order.
    pub models: Vec<LoopModel>,
    /// Seeds of every model.
    pub seeds: Vec<u64>,
    /// Policy iterations per run.
    pub iterations: usize,
    /// The budget of every run (its `likelihood` unset: the models say it).
    pub budget: Budget,
    /// Folder of the runs' folders and the plot.
    pub dir: PathBuf,
}

impl Plan {
    /// Checks everything a run will use, so that no run fails on a setting after others have
    /// taken an hour. `dir` defaults to `results/figure4-<tier>`.
    pub fn new(
        tier: &str,
        plant: PendulumParams,
        models: Vec<LoopModel>,
        seeds: Vec<u64>,
        iterations: usize,
        budget: Budget,
        dir: Option<PathBuf>,
    ) -> Result<Plan> {
        let invalid = |option: &str, reason: String| ReproduceError::Plan {
            option: option.to_string(),
            reason,
        };
        if let Some(l) = budget.likelihood {
            return Err(invalid(
                "likelihood",
                format!(
                    "{}: figure 4 runs MSGP with each likelihood as its own model (models \
                     msgp, msgp-filter)",
                    l.name()
                ),
            ));
        }
        if models.is_empty() {
            return Err(invalid("models", "give at least one model".to_string()));
        }
        if seeds.is_empty() {
            return Err(invalid("seeds", "give at least one seed".to_string()));
        }
        if iterations == 0 {
            return Err(invalid("iterations", "must be at least 1".to_string()));
        }
        plant.validate()?;
        let plan = Plan {
            dir: dir.unwrap_or_else(|| PathBuf::from(format!("results/figure4-{tier}"))),
            tier: tier.to_string(),
            plant,
            models,
            seeds,
            iterations,
            budget,
        };
        let units = plan.units();
        if let Some((_, twice)) = units
            .iter()
            .enumerate()
            .find(|(k, u)| units[..*k].contains(u))
        {
            return Err(invalid(
                "models and seeds",
                format!("{} appears twice", twice.name()),
            ));
        }
        for model in &plan.models {
            plan.settings(&Unit {
                model: *model,
                seed: plan.seeds[0],
            })?;
        }
        Ok(plan)
    }

    /// The section of the results file: `figure4-<tier>`.
    pub fn section(&self) -> String {
        format!("figure4-{}", self.tier)
    }

    /// Every run, model by model, seeds in order: the serial run's order and the report's.
    pub fn units(&self) -> Vec<Unit> {
        self.models
            .iter()
            .flat_map(|&model| self.seeds.iter().map(move |&seed| Unit { model, seed }))
            .collect()
    }

    /// The loop's settings of `unit`.
    pub fn settings(&self, unit: &Unit) -> Result<LearnSettings> {
        let (method, likelihood) = unit.model.model();
        Ok(Budget {
            likelihood,
            ..self.budget.clone()
        }
        .settings(method, unit.seed, self.iterations)?)
    }

    /// The folder of `unit`'s run.
    pub fn run_dir(&self, unit: &Unit) -> PathBuf {
        self.dir.join(unit.name())
    }

    /// `unit`'s run if its folder holds it, finished, with this plan's plant and settings.
    pub fn finished(&self, unit: &Unit) -> Result<Option<FinishedRun>> {
        Ok(finished_run(
            &self.run_dir(unit),
            &self.settings(unit)?,
            &self.plant,
        ))
    }
}

/// A finished run of a unit.
#[derive(Clone, Debug, PartialEq)]
pub struct Run {
    /// Which.
    pub unit: Unit,
    /// What it did.
    pub run: FinishedRun,
}

impl Run {
    /// The run's first iteration whose gains passed the stability test.
    pub fn first_stable(&self) -> Option<&IterationReport> {
        self.run.iterations.iter().find(|r| r.stable)
    }
}

/// Every unit's finished run, in the plan's order; a unit whose folder lacks it is an error
/// naming the folder.
pub fn collect(plan: &Plan) -> Result<Vec<Run>> {
    plan.units()
        .into_iter()
        .map(|unit| match plan.finished(&unit)? {
            Some(run) => Ok(Run { unit, run }),
            None => Err(ReproduceError::MalformedRecord {
                path: plan.run_dir(&unit).join("summary.json"),
                reason: format!(
                    "no finished run of {} with this plan's plant and settings",
                    unit.name()
                ),
            }),
        })
        .collect()
}

/// Draws `figure4.png` into the plan's folder and returns the markdown section for `runs`
/// (every unit of the plan, [`collect`]).
pub fn report(plan: &Plan, runs: &[Run], provenance: &Provenance) -> Result<String> {
    let plot = plan.dir.join("figure4.png");
    let bands: Vec<(String, Vec<Vec<CostPoint>>)> = plan
        .models
        .iter()
        .map(|&m| {
            (
                m.name().to_string(),
                runs.iter()
                    .filter(|r| r.unit.model == m)
                    .map(|r| r.run.iterations.iter().map(CostPoint::from).collect())
                    .collect(),
            )
        })
        .collect();
    plot_cost_bands(&plot, &bands)?;
    // the free-run MSGP loop's settings: the line "model fit" describes its fits and
    // GP-NARX's (msgp-filter and linear-kf get their own words)
    let learned = Budget {
        likelihood: Some(Likelihood::FreeRun),
        ..plan.budget.clone()
    }
    .settings(Method::Msgp, 0, plan.iterations)?;
    Ok(render(plan, &learned, runs, provenance, &plot))
}

/// `0–4` for consecutive seeds, else the list.
fn seed_list(seeds: &[u64]) -> String {
    let consecutive = seeds.windows(2).all(|w| w[1] == w[0] + 1);
    match (seeds, consecutive) {
        ([one], _) => one.to_string(),
        ([first, .., last], true) => format!("{first}–{last}"),
        _ => seeds
            .iter()
            .map(u64::to_string)
            .collect::<Vec<_>>()
            .join(", "),
    }
}

/// `k/n (p %)`, or `—` when nothing was scored.
fn fraction(k: usize, n: usize) -> String {
    match n {
        0 => "—".to_string(),
        n => format!("{k}/{n} ({:.0} %)", 100.0 * k as f64 / n as f64),
    }
}

/// The markdown section; `learned` holds the loop's settings (of a free-run MSGP run: what the
/// budget and the experiment switches resolved to).
fn render(
    plan: &Plan,
    learned: &LearnSettings,
    runs: &[Run],
    provenance: &Provenance,
    plot: &Path,
) -> String {
    let d = &plan.budget;
    let mut s = intro(plan, learned, provenance);
    s.push_str(&budget(plan, learned));
    s.push_str(&wall_time(plan, runs, provenance));
    s.push_str(&summary_table(plan, runs));
    s.push_str(&runs_table(runs));
    let _ = write!(
        s,
        "\nCost over each {} s episode (a step after an early stop counts 1): mean ± 1 standard deviation over the seeds, predicted by the model (left) and measured on the simulator (right). Per-run artefacts (policy, iterations.csv, episodes as MCAP, cost.png) are in `{}/<model>-seed<k>/`.\n\n![cost curves]({})\n",
        d.episode_seconds,
        plan.dir.display(),
        plot.display()
    );
    s
}

/// The section's title, what was learned and how, and the command.
fn intro(plan: &Plan, learned: &LearnSettings, provenance: &Provenance) -> String {
    let d = &plan.budget;
    let params = &plan.plant;
    let models: Vec<&str> = plan.models.iter().map(|&m| m.name()).collect();
    let tier = &plan.tier;
    let mut s =
        format!("# PILCO on the simulated pendulum (the paper's Figure 4), {tier} plant\n\n");
    let _ = write!(
        s,
        "Learning to balance the pole on the robot's end effector (`msgp-sim`, `--plant {tier}`: σθ {} rad, σx {} m, {}-step delay, {} s lag, {} Hz control) from scratch: {} random-excitation rollouts, then per iteration fit the model on all data, optimise the PID + PD gains on it, run them for one {} s episode. After every iteration the simulator's stability test (5 starts × 3 noise draws, 10 s each; not interaction, not training data) judges the gains, and {} evaluation episodes of the episode's length from random initial angles (neither interaction nor training data either) measure their expected cost, what the model's predicted cost predicts: one episode's cost is a single draw spread as widely as its mean (its random initial angle, squared), so a perfect prediction is within 2× of it only about a third of the time. Interaction seconds count every episode so far, random rollouts included. Models: {}; seeds {}; {} iterations per run.\n\n",
        params.sigma_theta,
        params.sigma_x,
        params.command_delay_steps,
        params.lag_time_constant,
        params.control_rate_hz,
        d.random_rollouts,
        d.episode_seconds,
        learned.evaluation_episodes,
        models.join(", "),
        seed_list(&plan.seeds),
        plan.iterations
    );
    let _ = writeln!(s, "- Command: {}", provenance.command);
    s
}

/// The budget line: each model's fit and the policy search per iteration.
fn budget(plan: &Plan, learned: &LearnSettings) -> String {
    let d = &plan.budget;
    let has = |m: LoopModel| plan.models.contains(&m);
    let mut s = String::new();
    let solver = learned
        .fit
        .msgp()
        .map_or(FitOptimizer::default(), |s| s.optimizer)
        .name();
    let warm = match d.warm_start {
        None | Some(0) => String::new(),
        Some(n) => format!(", from the second iteration on warm-started for {n} iterations"),
    };
    let kf = match (has(LoopModel::LinearKf), d.warm_start) {
        (false, _) => String::new(),
        (true, None) => format!(
            " (linear-kf: no GP, at most that many L-BFGS iterations on the filter likelihood from each of two starts at iteration 1, then at most {LINEAR_KF_WARM_START} from the previous model)"
        ),
        (true, Some(0)) => {
            " (linear-kf: no GP, at most that many L-BFGS iterations on the filter likelihood from each of two starts)"
                .to_string()
        }
        (true, Some(_)) => {
            " (linear-kf: no GP, L-BFGS on the filter likelihood, at iteration 1 from each of two starts)"
                .to_string()
        }
    };
    let kf = match has(LoopModel::MsgpFilter) {
        false => kf,
        true => format!(
            "{kf} (msgp-filter: m = {}, {} L-BFGS iterations on the filter likelihood at iteration 1 from the linear-kf model of the data under a GP that starts at zero, then {} from the previous model, {} Adam steps per search start; with the prequential choice each iteration also fits the linear-kf model of the same data, and the search runs on the GP model only while the GP's filter likelihood of the episodes neither had seen beats the linear model's)",
            d.inducing.unwrap_or(FILTERED_MSGP_INDUCING),
            d.fit_iters.unwrap_or(FILTERED_MSGP_ITERATIONS),
            match d.warm_start {
                Some(0) => "each fit from scratch".to_string(),
                n => format!("at most {}", n.unwrap_or(FILTERED_MSGP_WARM_START)),
            },
            d.search_iters.unwrap_or(FILTERED_MSGP_SEARCH_ITERATIONS),
        ),
    };
    let horizon = match d.policy_horizon {
        Some(h) => format!("{h} s"),
        None if has(LoopModel::LinearKf) || has(LoopModel::MsgpFilter) => format!(
            "{} s (linear-kf and msgp-filter: {LINEAR_KF_POLICY_HORIZON_SECONDS} s)",
            LearnSettings::default().policy_horizon_seconds,
        ),
        None => format!("{} s", LearnSettings::default().policy_horizon_seconds),
    };
    let _ = writeln!(
        s,
        "- Budget per iteration: model fit {} {solver} iterations{warm} (m = {}){kf}, policy search: {} random gain candidates screened, {} Adam steps per start, on predicted rollouts over {horizon}",
        d.fit_iters
            .map_or_else(|| "default".to_string(), |n| n.to_string()),
        d.inducing.unwrap_or(LEARN_INDUCING),
        d.candidates,
        d.search_iters
            .unwrap_or(LearnSettings::default().search.iterations)
    );
    s
}

/// Wall time and date.
fn wall_time(plan: &Plan, runs: &[Run], provenance: &Provenance) -> String {
    let mut s = String::new();
    let summed: f64 = runs
        .iter()
        .map(|r| r.run.seconds)
        .filter(|s| s.is_finite())
        .sum();
    let _ = write!(
        s,
        "- Wall time: {summed:.0} s ({:.1} min) summed over the runs (runs may be split over processes: `msgp learn-policy --out {}/<model>-seed<k>` writes a run that `msgp reproduce figure4` then collects, `python -m msgp.sweep figure4` spreads them over processes or a Ray cluster); this report: {:.0} s, msgp {} on {}\n- Date (UTC): {}\n\n",
        summed / 60.0,
        plan.dir.display(),
        provenance.seconds,
        env!("CARGO_PKG_VERSION"),
        provenance.machine,
        provenance.date
    );
    s
}

/// Per model: stable seeds, iterations and interaction to the first stable policy, kept and
/// calibrated iterations, searches on the GP, time per iteration.
fn summary_table(plan: &Plan, runs: &[Run]) -> String {
    let mut s = String::new();
    s.push_str("## Summary\n\n| model | stable within the budget | iterations to first stable policy (per seed) | interaction s to stable (median) | kept: later iterations stable | calibrated: iterations ≥ 3 with the predicted cost within 2× of the expected (mean of the evaluation episodes) | … within 2× of the one episode run | searches on the GP model (prequential choice) | fit + search s per iteration (median) |\n|---|---:|---|---:|---:|---:|---:|---:|---:|\n");
    for &m in &plan.models {
        let mine: Vec<&Run> = runs.iter().filter(|r| r.unit.model == m).collect();
        let firsts: Vec<Option<&IterationReport>> = mine.iter().map(|r| r.first_stable()).collect();
        let ok = firsts.iter().filter(|f| f.is_some()).count();
        let per_seed: Vec<String> = firsts
            .iter()
            .map(|f| f.map_or_else(|| "—".to_string(), |r| r.iteration.to_string()))
            .collect();
        let mut secs: Vec<f64> = firsts
            .iter()
            .flatten()
            .map(|r| r.interaction_seconds)
            .collect();
        secs.sort_by(f64::total_cmp);
        let median = secs
            .get(secs.len() / 2)
            .map_or_else(|| "—".to_string(), |t| format!("{t:.1}"));
        let (kept, later) = mine.iter().fold((0, 0), |(k, n), r| {
            let after: Vec<&IterationReport> = match r.first_stable() {
                Some(f) => r
                    .run
                    .iterations
                    .iter()
                    .filter(|i| i.iteration > f.iteration)
                    .collect(),
                None => Vec::new(),
            };
            (
                k + after.iter().filter(|i| i.stable).count(),
                n + after.len(),
            )
        });
        let within = |measured: fn(&IterationReport) -> Option<f64>| {
            mine.iter()
                .flat_map(|r| r.run.iterations.iter().filter(|i| i.iteration >= 3))
                .filter_map(|i| Some(measured(i)? / i.predicted_cost))
                .fold((0, 0), |(c, n), ratio| {
                    (c + usize::from((0.5..=2.0).contains(&ratio)), n + 1)
                })
        };
        let (calibrated, scored) = within(|i| i.expected_cost);
        let (single, episodes) = within(|i| Some(i.actual_cost));
        let mut per_iteration: Vec<f64> = mine
            .iter()
            .flat_map(|r| {
                r.run
                    .iterations
                    .iter()
                    .map(|i| i.fit_seconds + i.search_seconds)
            })
            .collect();
        per_iteration.sort_by(f64::total_cmp);
        let (on_gp, chosen) = mine
            .iter()
            .flat_map(|r| r.run.iterations.iter().filter_map(|i| i.search_model))
            .fold((0, 0), |(g, n), m| {
                (g + usize::from(m == SearchModel::Gp), n + 1)
            });
        let _ = writeln!(
            s,
            "| {} | {ok}/{} | {} | {median} | {} | {} | {} | {} | {} |",
            m.name(),
            mine.len(),
            per_seed.join(", "),
            fraction(kept, later),
            fraction(calibrated, scored),
            fraction(single, episodes),
            fraction(on_gp, chosen),
            per_iteration
                .get(per_iteration.len() / 2)
                .map_or_else(|| "—".to_string(), |t| format!("{t:.1}"))
        );
    }
    s
}

/// Per run: its first stable iteration, stable iterations and costs.
fn runs_table(runs: &[Run]) -> String {
    let mut s = String::new();
    s.push_str("\n## Runs\n\n| model | seed | first stable iteration | interaction s to stable | stable iterations | lowest actual cost | last actual cost | wall s |\n|---|---:|---:|---:|---|---:|---:|---:|\n");
    for r in runs {
        let first = r.first_stable();
        let stable: Vec<String> = r
            .run
            .iterations
            .iter()
            .filter(|i| i.stable)
            .map(|i| i.iteration.to_string())
            .collect();
        let lowest = r
            .run
            .iterations
            .iter()
            .map(|i| i.actual_cost)
            .fold(f64::INFINITY, f64::min);
        let last = r.run.iterations.last().map_or(f64::NAN, |i| i.actual_cost);
        let _ = writeln!(
            s,
            "| {} | {} | {} | {} | {} | {lowest:.2} | {last:.2} | {:.0} |",
            r.unit.model.name(),
            r.unit.seed,
            first.map_or_else(|| "—".to_string(), |i| i.iteration.to_string()),
            first.map_or_else(
                || "—".to_string(),
                |i| format!("{:.1}", i.interaction_seconds)
            ),
            if stable.is_empty() {
                "none".to_string()
            } else {
                stable.join(", ")
            },
            r.run.seconds
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;
    use msgp_sim::SimError;

    fn plan(models: Vec<LoopModel>, seeds: Vec<u64>, budget: Budget) -> Result<Plan> {
        Plan::new(
            "apollo",
            PendulumParams::default(),
            models,
            seeds,
            2,
            budget,
            None,
        )
    }

    #[test]
    fn units_run_model_by_model_in_seed_order() {
        let p = plan(
            vec![LoopModel::LinearKf, LoopModel::Msgp],
            vec![0, 1, 2],
            Budget::default(),
        )
        .expect("valid plan");
        let names: Vec<String> = p.units().iter().map(Unit::name).collect();
        assert_eq!(
            names,
            [
                "linear-kf-seed0",
                "linear-kf-seed1",
                "linear-kf-seed2",
                "msgp-seed0",
                "msgp-seed1",
                "msgp-seed2"
            ]
        );
        assert_eq!(p.dir, PathBuf::from("results/figure4-apollo"));
        assert_eq!(p.section(), "figure4-apollo");
        let s = p.settings(&p.units()[4]).expect("settings");
        assert_eq!(s.seed, 1);
        assert_eq!(
            s.fit.msgp().map(|m| m.likelihood),
            Some(Likelihood::FreeRun)
        );
        let back: Plan =
            serde_json::from_str(&serde_json::to_string(&p).expect("json")).expect("reads");
        assert_eq!(back, p);
        assert_eq!(seed_list(&[0, 1, 2]), "0–2");
        assert_eq!(seed_list(&[0, 2]), "0, 2");
        assert_eq!(seed_list(&[3]), "3");
    }

    #[test]
    fn a_plan_refuses_what_no_run_could_use() {
        let refused = [
            plan(Vec::new(), vec![0], Budget::default()),
            plan(vec![LoopModel::Msgp], Vec::new(), Budget::default()),
            plan(vec![LoopModel::Msgp], vec![1, 1], Budget::default()),
            plan(
                vec![LoopModel::Msgp],
                vec![0],
                Budget {
                    likelihood: Some(Likelihood::Filter),
                    ..Budget::default()
                },
            ),
            plan(
                vec![LoopModel::GpNarx],
                vec![0],
                Budget {
                    episode_seconds: 0.0,
                    ..Budget::default()
                },
            ),
        ];
        for r in refused {
            let refused = matches!(
                r,
                Err(ReproduceError::Plan { .. } | ReproduceError::Sim(SimError::Budget { .. }))
            );
            assert!(refused, "{r:?}");
        }
        assert_eq!("msgp-filter".parse(), Ok(LoopModel::MsgpFilter));
        assert!("msgp_filter".parse::<LoopModel>().is_err());
    }
}
