//! `msgp reproduce figure4`: the paper's Figure 4 on the simulated pendulum — PILCO with MSGP
//! and with one-step GP-NARX models, several seeds each; per run the iteration and interaction
//! time of the first policy that passes the stability test, and the cost curves.

use anyhow::Context;
use msgp_core::fit::FitOptimizer;
use msgp_sim::PendulumParams;
use msgp_sim::learn::{IterationReport, LearnSettings};

use crate::args::{BudgetArgs, Figure4Args, Figure4Model, ModelArg};
use crate::commands::learn::{learn, model_name, settings, summary_json, write_outputs};
use crate::render::cost_plot::plot_cost_bands;
use msgp_core::reproduce::results::{machine, today};

/// One finished run.
struct Run {
    model: Figure4Model,
    seed: u64,
    iterations: Vec<IterationReport>,
    seconds: f64,
}

impl Run {
    fn first_stable(&self) -> Option<&IterationReport> {
        self.iterations.iter().find(|r| r.stable)
    }
}

/// A run already in `dir` (its `summary.json`, written last, as `msgp learn-policy --out DIR`
/// writes it) made with the same model on the same plant and exactly the same settings (seed,
/// budget, fit and search settings, integrators, all of them); runs can so be split over
/// several processes and
/// collected afterwards. The stored settings are read back as [`LearnSettings`], so a setting
/// added after the run was made takes its default, which is what the run used; a summary
/// without any settings (older runs) is not reused.
fn finished_run(
    dir: &std::path::Path,
    model: Figure4Model,
    seed: u64,
    settings: &LearnSettings,
    params: &PendulumParams,
) -> Option<Run> {
    let text = std::fs::read_to_string(dir.join("summary.json")).ok()?;
    let v: serde_json::Value = serde_json::from_str(&text).ok()?;
    let iterations: Vec<IterationReport> =
        serde_json::from_value(v.get("iterations")?.clone()).ok()?;
    let stored: LearnSettings = serde_json::from_value(v.get("settings")?.clone()).ok()?;
    let stored_plant: PendulumParams = serde_json::from_value(v.get("plant")?.clone()).ok()?;
    let same = v["model"] == model_name(model.model().0)
        && stored == *settings
        && stored_plant == *params
        && iterations.len() == settings.iterations;
    same.then(|| Run {
        model,
        seed,
        iterations,
        seconds: v["wall_seconds"].as_f64().unwrap_or(f64::NAN),
    })
}

/// Runs `msgp reproduce figure4`.
pub fn run(args: &Figure4Args) -> anyhow::Result<()> {
    if let Some(l) = args.budget.likelihood {
        anyhow::bail!(
            "--likelihood {}: figure4 runs MSGP with each likelihood as its own model \
             (--models msgp,msgp-filter)",
            msgp_core::loss::Likelihood::from(l).name()
        );
    }
    let params = args.plant.resolve()?;
    let tier = msgp_sim::PlantTier::from(args.plant.plant).name();
    let dir = args
        .dir
        .clone()
        .unwrap_or_else(|| std::path::PathBuf::from(format!("results/figure4-{tier}")));
    let mut runs = Vec::new();
    for &model in &args.models {
        let (arg, likelihood) = model.model();
        for seed in 0..args.seeds {
            let settings = settings(
                arg,
                seed,
                args.iterations,
                &BudgetArgs {
                    likelihood,
                    ..args.budget.clone()
                },
            )?;
            let run_dir = dir.join(format!("{}-seed{seed}", model.name()));
            if let Some(done) = finished_run(&run_dir, model, seed, &settings, &params) {
                if !args.quiet {
                    eprintln!(
                        "== {} seed {seed}: reusing {}",
                        model.name(),
                        run_dir.join("summary.json").display()
                    );
                }
                runs.push(done);
                continue;
            }
            if !args.quiet {
                eprintln!("== {} seed {seed}", model.name());
            }
            let (outcome, seconds) = learn(&params, &settings, args.quiet)?;
            let summary = summary_json(&outcome, &settings, arg, &params, seconds);
            write_outputs(
                &run_dir,
                &outcome,
                &settings,
                &summary,
                &format!("{} seed {seed}", model.name()),
            )
            .with_context(|| format!("writing {}", run_dir.display()))?;
            runs.push(Run {
                model,
                seed,
                iterations: outcome.iterations,
                seconds,
            });
        }
    }
    let plot = dir.join("figure4.png");
    let bands: Vec<(String, Vec<Vec<IterationReport>>)> = args
        .models
        .iter()
        .map(|&m| {
            (
                m.name().to_string(),
                runs.iter()
                    .filter(|r| r.model == m)
                    .map(|r| r.iterations.clone())
                    .collect(),
            )
        })
        .collect();
    plot_cost_bands(&plot, &bands)?;
    let total: f64 = runs
        .iter()
        .map(|r| r.seconds)
        .filter(|s| s.is_finite())
        .sum();
    let learned = settings(ModelArg::Msgp, 0, args.iterations, &args.budget)?;
    let markdown = render(args, &dir, &params, &learned, &runs, total, &plot);
    msgp_core::reproduce::results::update_section(
        &args.out,
        &format!("figure4-{tier}"),
        &markdown,
    )?;
    crate::render::output::out(&markdown)
}

/// This process's arguments after the binary, quoted for a POSIX shell where needed: the
/// section names exactly what made it, budget flags included.
fn invocation() -> String {
    std::env::args_os()
        .skip(1)
        .map(|a| {
            let a = a.to_string_lossy().into_owned();
            let plain = !a.is_empty()
                && a.chars()
                    .all(|c| c.is_ascii_alphanumeric() || "-_=.,/:+@%".contains(c));
            if plain {
                a
            } else {
                format!("'{}'", a.replace('\'', "'\\''"))
            }
        })
        .collect::<Vec<_>>()
        .join(" ")
}

/// The markdown section; `learned` holds the loop's settings (of an MSGP run: what the budget
/// and the experiment switches resolved to).
fn render(
    args: &Figure4Args,
    dir: &std::path::Path,
    params: &PendulumParams,
    learned: &LearnSettings,
    runs: &[Run],
    seconds: f64,
    plot: &std::path::Path,
) -> String {
    let d = &args.budget;
    let models: Vec<&str> = args.models.iter().map(|&m| m.name()).collect();
    let tier = msgp_sim::PlantTier::from(args.plant.plant).name();
    let mut s =
        format!("# PILCO on the simulated pendulum (the paper's Figure 4), {tier} plant\n\n");
    s.push_str(&format!(
        "Learning to balance the pole on the robot's end effector (`msgp-sim`, `--plant {tier}`: σθ {} rad, σx {} m, {}-step delay, {} s lag, {} Hz control) from scratch: {} rollouts, then per iteration fit the model on all data, optimise the PID + PD gains on it, run them for one {} s episode. After every iteration the simulator's stability test (5 starts × 3 noise draws, 10 s each; not interaction, not training data) judges the gains. Interaction seconds count every episode so far, random rollouts included. Models: {}; seeds 0–{}; {} iterations per run.\n\n",
        params.sigma_theta,
        params.sigma_x,
        params.command_delay_steps,
        params.lag_time_constant,
        params.control_rate_hz,
        match learned.random_policies {
            0 => format!("{} random-excitation", d.random_rollouts),
            k => format!(
                "{} random-excitation and {k} random-policy (gains drawn uniformly in [0, 2 × typical])",
                d.random_rollouts - k
            ),
        },
        d.episode_seconds,
        models.join(", "),
        args.seeds.saturating_sub(1),
        args.iterations
    ));
    s.push_str(&format!(
        "- Command: `cargo run --release --locked --bin msgp -- {}`\n",
        invocation()
    ));
    let solver = learned
        .fit
        .msgp()
        .map_or(FitOptimizer::default(), |s| s.optimizer)
        .name();
    let warm = match d.warm_start {
        None | Some(0) => String::new(),
        Some(n) => format!(", from the second iteration on warm-started for {n} iterations"),
    };
    let kf = match (args.models.contains(&Figure4Model::LinearKf), d.warm_start) {
        (false, _) => String::new(),
        (true, None) => format!(
            " (linear-kf: no GP, at most that many L-BFGS iterations on the filter likelihood from each of two starts at iteration 1, then at most {} from the previous model)",
            msgp_sim::learn::LINEAR_KF_WARM_START
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
    let kf = match args.models.contains(&Figure4Model::MsgpFilter) {
        false => kf,
        true => format!(
            "{kf} (msgp-filter: {} L-BFGS iterations on the filter likelihood, at iteration 1 from the linear-kf model of the data under a GP that starts at zero, then from the previous model unless --warm-start 0)",
            d.fit_iters
                .unwrap_or(msgp_sim::learn::FILTERED_MSGP_ITERATIONS)
        ),
    };
    let horizon = match d.policy_horizon {
        Some(h) => format!("{h} s"),
        None if args.models.contains(&Figure4Model::LinearKf)
            || args.models.contains(&Figure4Model::MsgpFilter) =>
        {
            format!(
                "{} s (linear-kf and msgp-filter: {} s)",
                LearnSettings::default().policy_horizon_seconds,
                msgp_sim::learn::LINEAR_KF_POLICY_HORIZON_SECONDS
            )
        }
        None => format!("{} s", LearnSettings::default().policy_horizon_seconds),
    };
    s.push_str(&format!(
        "- Budget per iteration: model fit {} {solver} iterations{warm} (m = {}){kf}, policy search: {} random gain candidates screened, {} Adam steps per start, on predicted rollouts over {horizon}\n",
        d.fit_iters.map_or_else(|| "default".to_string(), |n| n.to_string()),
        d.inducing,
        d.candidates,
        d.search_iters
    ));
    s.push_str(&format!(
        "- Wall time: {seconds:.0} s ({:.1} min) summed over the runs (runs may be split over processes: `msgp learn-policy --out {}/<model>-seed<k>` writes a run this command then collects), msgp {} on {}\n- Date (UTC): {}\n\n",
        seconds / 60.0,
        dir.display(),
        env!("CARGO_PKG_VERSION"),
        machine(),
        today()
    ));
    s.push_str("## Summary\n\n| model | stable within the budget | iterations to first stable policy (per seed) | interaction s to stable (median) | kept: later iterations stable | calibrated: iterations ≥ 3 with the measured cost within 2× of the predicted | fit + search s per iteration (median) |\n|---|---:|---|---:|---:|---:|---:|\n");
    for &m in &args.models {
        let mine: Vec<&Run> = runs.iter().filter(|r| r.model == m).collect();
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
        let median = if secs.is_empty() {
            "—".to_string()
        } else {
            format!("{:.1}", secs[secs.len() / 2])
        };
        let (kept, later) = mine.iter().fold((0, 0), |(k, n), r| {
            let after: Vec<&IterationReport> = match r.first_stable() {
                Some(f) => r
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
        let (calibrated, scored) = mine
            .iter()
            .flat_map(|r| r.iterations.iter().filter(|i| i.iteration >= 3))
            .fold((0, 0), |(c, n), i| {
                let ratio = i.actual_cost / i.predicted_cost;
                (c + usize::from((0.5..=2.0).contains(&ratio)), n + 1)
            });
        let mut per_iteration: Vec<f64> = mine
            .iter()
            .flat_map(|r| {
                r.iterations
                    .iter()
                    .map(|i| i.fit_seconds + i.search_seconds)
            })
            .collect();
        per_iteration.sort_by(f64::total_cmp);
        let fraction = |k: usize, n: usize| match n {
            0 => "—".to_string(),
            n => format!("{k}/{n} ({:.0} %)", 100.0 * k as f64 / n as f64),
        };
        s.push_str(&format!(
            "| {} | {ok}/{} | {} | {median} | {} | {} | {} |\n",
            m.name(),
            mine.len(),
            per_seed.join(", "),
            fraction(kept, later),
            fraction(calibrated, scored),
            per_iteration
                .get(per_iteration.len() / 2)
                .map_or_else(|| "—".to_string(), |t| format!("{t:.1}"))
        ));
    }
    s.push_str("\n## Runs\n\n| model | seed | first stable iteration | interaction s to stable | stable iterations | lowest actual cost | last actual cost | wall s |\n|---|---:|---:|---:|---|---:|---:|---:|\n");
    for r in runs {
        let first = r.first_stable();
        let stable: Vec<String> = r
            .iterations
            .iter()
            .filter(|i| i.stable)
            .map(|i| i.iteration.to_string())
            .collect();
        let lowest = r
            .iterations
            .iter()
            .map(|i| i.actual_cost)
            .fold(f64::INFINITY, f64::min);
        let last = r.iterations.last().map_or(f64::NAN, |i| i.actual_cost);
        s.push_str(&format!(
            "| {} | {} | {} | {} | {} | {lowest:.2} | {last:.2} | {:.0} |\n",
            r.model.name(),
            r.seed,
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
            r.seconds
        ));
    }
    s.push_str(&format!(
        "\nCost over each {} s episode (a step after an early stop counts 1): mean ± 1 standard deviation over the seeds, predicted by the model (left) and measured on the simulator (right). Per-run artefacts (policy, iterations.csv, episodes as MCAP, cost.png) are in `{}/<model>-seed<k>/`.\n\n![cost curves]({})\n",
        d.episode_seconds,
        dir.display(),
        plot.display()
    ));
    s
}
