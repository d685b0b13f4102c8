//! `msgp reproduce generalisation`: how the models of Table 1 do on data unlike their training
//! data. Each synthetic system of Table 2 is fitted on its Table-2 training data and simulated
//! on its Table-2 test input and on three excitations it never saw (steps, a chirp, the test
//! input at half amplitude: `msgp_core::data::synthetic::Excitation`); each real series is
//! split the other way round (the last `n_train` samples train, the samples before them
//! test). Every simulation is scored against a model that always predicts the training
//! outputs' mean, with 2σ coverage.

use std::fmt::Write as _;
use std::time::Instant;

use anyhow::{Context, bail};
use msgp_core::data::real::RealSeries;
use msgp_core::data::{Benchmark, NoiseScale, SyntheticSystem, Trajectory};
use msgp_core::fit::{FitProgress, FitSettings, fit};
use msgp_core::model::{Method, Metrics, Model, Simulated, score};
use msgp_core::numeric::parallel::Threads;
use serde_json::json;

use crate::args::GeneralisationArgs;
use crate::commands::side_by_side;
use crate::render::output::{out, out_json};
use crate::render::plot::{plot_grid, simulated};
use crate::render::progress::FitBar;
use msgp_reproduce::results::{machine, today};

const METHODS: [Method; 2] = [Method::Msgp, Method::GpNarx];

/// One benchmark: a synthetic system or a real series.
enum Source {
    Synthetic(SyntheticSystem),
    Real(RealSeries),
}

impl Source {
    fn key(&self) -> String {
        match self {
            Source::Synthetic(s) => format!("synthetic{}", s.number()),
            Source::Real(r) => r.name().to_string(),
        }
    }
}

/// One test of one benchmark and seed: the excitation's name, the training-mean predictor's
/// RMSE, and per method the metrics.
struct Case {
    key: String,
    test: String,
    seed: u64,
    mean_rmse: f64,
    metrics: Vec<Metrics>,
    /// Whether the test is an excitation the model was not trained on (not Table 2's own).
    alternate: bool,
    /// Whether the test's input leaves the training input's range.
    beyond: bool,
}

/// RMSE of always predicting `level` on `traj` from `start` on.
fn constant_rmse(traj: &Trajectory, start: usize, level: f64) -> f64 {
    let n = traj.len() - start;
    let se: f64 = (start..traj.len())
        .map(|t| (traj.y[(t, 0)] - level).powi(2))
        .sum();
    (se / n.max(1) as f64).sqrt()
}

fn fit_all(
    bench: &Benchmark,
    seed: u64,
    label: &str,
    quiet: bool,
    threads: Threads,
) -> anyhow::Result<Vec<Model>> {
    METHODS
        .iter()
        .map(|&method| {
            let settings = FitSettings {
                ly: bench.ly,
                lu: bench.lu,
                seed,
                threads,
                ..FitSettings::new(method)
            };
            let mut bar = FitBar::new(&format!("{} on {label}", method.name()), quiet);
            match fit(
                std::slice::from_ref(&bench.train),
                &settings,
                &mut |p: &FitProgress| bar.update(p),
            ) {
                Ok((model, report)) => {
                    bar.finish(&format!("{:.1} s", report.train_seconds));
                    Ok(model)
                }
                Err(e) => {
                    bar.abandon();
                    Err(e).context(format!("fitting {} on {label}", method.name()))
                }
            }
        })
        .collect()
}

/// A plot's panel: its title and the simulation it draws.
type Panel = (String, Simulated);

/// One test of a benchmark: its name, trajectory, whether it is an excitation the model was
/// not trained on, and whether its input leaves the training input's range.
type Test = (String, Trajectory, bool, bool);

/// Runs `msgp reproduce generalisation`.
pub fn run(args: &GeneralisationArgs) -> anyhow::Result<()> {
    let started = Instant::now();
    let sources = sources(args)?;
    args.common.check_seeds()?;
    if let Some(dir) = &args.plots {
        std::fs::create_dir_all(dir)
            .with_context(|| format!("cannot create the plots' folder {}", dir.display()))?;
    }
    let units: Vec<(&Source, u64)> = sources
        .iter()
        .flat_map(|s| args.common.seeds.iter().map(move |&seed| (s, seed)))
        .collect();
    let (jobs, per_unit) =
        side_by_side::share(args.common.jobs, Threads::from_env()?.get(), units.len())?;
    let threads = per_unit.unwrap_or(Threads::from_env()?);
    // one job shows each fit's progress bar; with more, a line per finished benchmark and seed
    let quiet = args.common.quiet || jobs > 1;
    let per_unit_cases = side_by_side::run(units, jobs, |(source, seed)| {
        let unit = run_unit(args, source, seed, (quiet, threads))?;
        if jobs > 1 && !args.common.quiet {
            eprintln!(
                "{} (seed {seed}): fitted and simulated ({:.0} s)",
                source.key(),
                started.elapsed().as_secs_f64()
            );
        }
        Ok(unit)
    })?;
    // the plots written, one per benchmark and seed (in the order of the rows)
    let plots: Vec<String> = per_unit_cases
        .iter()
        .filter_map(|(_, p)| p.clone())
        .collect();
    let cases: Vec<Case> = per_unit_cases.into_iter().flat_map(|(c, _)| c).collect();
    let seconds = started.elapsed().as_secs_f64();
    let markdown = render(args, &cases, &plots, seconds);
    msgp_reproduce::results::update_section(&args.common.out, "generalisation", &markdown)?;
    if args.common.json {
        return out_json(&json!({
            "command": "reproduce generalisation",
            "out": args.common.out.display().to_string(),
            "seconds": seconds,
            "seeds": args.common.seeds,
            "plots": plots,
            "rows": json_rows(&cases),
        }));
    }
    out(&format!(
        "{}\nwritten to {} in {seconds:.0} s{}",
        summary(&cases).join("\n"),
        args.common.out.display(),
        args.plots.as_ref().map_or(String::new(), |d| format!(
            "; {} plots in {}",
            plots.len(),
            d.display()
        ))
    ))
}

/// The benchmarks `--only` keeps (all by default), each name checked.
fn sources(args: &GeneralisationArgs) -> anyhow::Result<Vec<Source>> {
    let mut sources: Vec<Source> = SyntheticSystem::all()
        .into_iter()
        .map(Source::Synthetic)
        .collect();
    sources.extend(RealSeries::ALL.into_iter().map(Source::Real));
    for name in &args.common.only {
        if !sources.iter().any(|s| s.key() == *name) {
            bail!(
                "unknown benchmark `{name}` (choose from {})",
                sources
                    .iter()
                    .map(Source::key)
                    .collect::<Vec<_>>()
                    .join(", ")
            );
        }
    }
    sources.retain(|s| args.common.only.is_empty() || args.common.only.contains(&s.key()));
    Ok(sources)
}

/// `source`'s training data for `seed` and its tests: a synthetic system's Table 2 test input,
/// its alternate excitations and those beyond the training range; a real series' swapped split.
fn tests_of(
    source: &Source,
    seed: u64,
    dir: &std::path::Path,
) -> anyhow::Result<(Benchmark, Vec<Test>)> {
    Ok(match source {
        Source::Synthetic(s) => {
            let bench = s.generate(seed, NoiseScale::StdDev)?;
            let own = (
                "Table 2 test input".to_string(),
                bench.test.clone(),
                false,
                false,
            );
            let mut tests = vec![own];
            for (e, t) in s
                .alternate_tests(seed)?
                .into_iter()
                .chain(s.beyond_tests(seed)?)
            {
                tests.push((e.name().to_string(), t, true, e.beyond_range()));
            }
            (bench, tests)
        }
        Source::Real(r) => {
            let bench = r.load_swapped(dir).with_context(|| {
                format!(
                    "loading the real series {} (set --data-dir or MSGP_DATA_DIR)",
                    r.name()
                )
            })?;
            let test = bench.test.clone();
            (
                bench,
                vec![("swapped split".to_string(), test, true, false)],
            )
        }
    })
}

/// One benchmark and seed: both methods fitted, every test simulated and scored, and the plot
/// of the tests both simulated (where `--plots` asks for it).
fn run_unit(
    args: &GeneralisationArgs,
    source: &Source,
    seed: u64,
    (quiet, threads): (bool, Threads),
) -> anyhow::Result<(Vec<Case>, Option<String>)> {
    let key = source.key();
    let (bench, tests) = tests_of(source, seed, &args.common.data_dir())?;
    let label = format!("{key} (seed {seed})");
    let models = fit_all(&bench, seed, &label, quiet, threads)?;
    let level = bench.train.y.column(0).mean();
    let mut cases = Vec::new();
    // the plot's rows: each test that both methods simulated
    let mut drawn: Vec<Vec<Panel>> = Vec::new();
    for (name, traj, alternate, beyond) in tests {
        let (metrics, row) = simulate_both(&models, &traj, (&label, &name))
            .with_context(|| format!("simulating on {key}, {name}"))?;
        if row.len() == METHODS.len() {
            drawn.push(row);
        }
        cases.push(Case {
            key: key.clone(),
            test: name,
            seed,
            mean_rmse: constant_rmse(&traj, bench.ly.max(bench.lu), level),
            metrics,
            alternate,
            beyond,
        });
    }
    // (a benchmark whose every test failed to simulate has no plot)
    let mut plot = None;
    if let (Some(dir), false) = (&args.plots, drawn.is_empty()) {
        let path = dir.join(format!("{key}-seed{seed}.png"));
        let rows: Vec<Vec<(String, &Simulated)>> = drawn
            .iter()
            .map(|r| r.iter().map(|(t, s)| (t.clone(), s)).collect())
            .collect();
        let data = match source {
            Source::Synthetic(_) => "true output",
            Source::Real(_) => "measured",
        };
        plot_grid(&path, &rows, data)?;
        plot = Some(path.display().to_string());
    }
    Ok((cases, plot))
}

/// Each model's scores on `traj`, the test `name` of the benchmark and seed `label` (a
/// simulation that fails numerically scores +∞, a runaway model, and the table goes on), and
/// the plot's row of those that simulated.
fn simulate_both(
    models: &[Model],
    traj: &Trajectory,
    (label, name): (&str, &str),
) -> anyhow::Result<(Vec<Metrics>, Vec<Panel>)> {
    let mut metrics = Vec::new();
    let mut row = Vec::new();
    for (m, method) in models.iter().zip(METHODS) {
        let scored = match m.simulate(traj) {
            Ok(sim) => score(&sim, traj).map(|metrics| Some((sim, metrics))),
            Err(e) if e.is_numerical() => Ok(None),
            Err(e) => Err(e),
        }
        .with_context(|| format!("simulating {}", method.name()))?;
        match scored {
            Some((sim, scores)) => {
                metrics.push(scores);
                let panel = format!("{label}, {name}: {}", method.name());
                row.push((panel, simulated(name, traj, sim, scores)));
            }
            None => metrics.push(Metrics {
                rmse: f64::INFINITY,
                nll: f64::INFINITY,
                coverage_2sigma: 0.0,
                steps: traj.len().saturating_sub(m.spec.warmup()),
            }),
        }
    }
    Ok((metrics, row))
}

/// `--json`'s rows: one per test and method.
fn json_rows(cases: &[Case]) -> Vec<serde_json::Value> {
    cases
        .iter()
        .flat_map(|c| {
            METHODS.iter().zip(&c.metrics).map(move |(m, x)| {
                json!({
                    "benchmark": c.key,
                    "test": c.test,
                    "seed": c.seed,
                    "method": m.name(),
                    "rmse": x.rmse,
                    "nll": x.nll,
                    "coverage_2sigma": x.coverage_2sigma,
                    "mean_predictor_rmse": c.mean_rmse,
                    "alternate": c.alternate,
                    "beyond_range": c.beyond,
                })
            })
        })
        .collect()
}

/// The targets over the synthetic systems' alternate excitations, and MSGP against
/// GP-NARX on every test.
fn summary(cases: &[Case]) -> Vec<String> {
    let alt: Vec<&Case> = cases
        .iter()
        .filter(|c| c.alternate && !c.beyond && c.key.starts_with("synthetic"))
        .collect();
    let pass = alt
        .iter()
        .filter(|c| c.metrics[0].rmse <= 0.5 * c.mean_rmse && c.metrics[0].coverage_2sigma >= 0.9)
        .count();
    let ratio = |k: usize, set: &[&Case]| {
        set.iter()
            .map(|c| c.metrics[k].rmse / c.mean_rmse)
            .sum::<f64>()
            / set.len().max(1) as f64
    };
    let all: Vec<&Case> = cases.iter().filter(|c| c.alternate && !c.beyond).collect();
    let beyond: Vec<&Case> = cases.iter().filter(|c| c.beyond).collect();
    let covered = |k: usize| {
        beyond
            .iter()
            .filter(|c| c.metrics[k].coverage_2sigma >= 0.9)
            .count()
    };
    let mean_coverage = |k: usize| {
        beyond
            .iter()
            .map(|c| c.metrics[k].coverage_2sigma)
            .sum::<f64>()
            / beyond.len().max(1) as f64
    };
    vec![
        format!(
            "- synthetic systems, alternate excitations: MSGP RMSE ≤ 0.5 × the training-mean \
             predictor's with 2σ coverage ≥ 0.9 on {pass}/{} (system × excitation × seed)",
            alt.len()
        ),
        format!(
            "- mean RMSE / training-mean predictor's over every unseen test (synthetic and \
             swapped real): MSGP {:.3}, GP-NARX {:.3}",
            ratio(0, &all),
            ratio(1, &all)
        ),
        format!(
            "- beyond the training amplitude (synthetic systems; steps and the test input up to \
             1.5 × the training bound): 2σ coverage ≥ 0.9 on {}/{n} for MSGP (mean coverage \
             {:.2}, RMSE / training-mean predictor's {:.3}) and {}/{n} for GP-NARX ({:.2}, \
             {:.3})",
            covered(0),
            mean_coverage(0),
            ratio(0, &beyond),
            covered(1),
            mean_coverage(1),
            ratio(1, &beyond),
            n = beyond.len()
        ),
    ]
}

fn render(args: &GeneralisationArgs, cases: &[Case], plots: &[String], seconds: f64) -> String {
    let command: Vec<String> = std::env::args()
        .enumerate()
        .map(|(i, a)| if i == 0 { "msgp".to_string() } else { a })
        .collect();
    let mut s =
        String::from("# Generalisation: excitations and data the models were not trained on\n\n");
    let _ = writeln!(
        s,
        "Each synthetic system of Table 2 is fitted on its Table-2 training data (noise read as \
         a standard deviation) and simulated, noise-free, on its Table-2 test input and on three \
         excitations it was not trained on, all of the Table-2 test length and inside the \
         training input's range: **steps** (ten levels drawn uniformly from the training range, \
         each held for a tenth of the test), a **chirp** (amplitude 0.9 × the training bound, from \
         one period per test to 0.2 cycles per sample) and the **half test input** (Table 2's \
         test input at half amplitude); and on two beyond it: **steps ×1.5** (levels drawn from \
         1.5 × the training range) and the **test input ×1.5** (Table 2's test input scaled to \
         peak at 1.5 × the training bound), counted on their own line; the random parts are \
         seeded with the run's seed (`msgp_core::data::synthetic::Excitation`). Each real series is split the other way \
         round: its last `n_train` samples (Table 3's training length) train, the samples \
         before them test. Every method with its default settings (MSGP: the default protocol). \
         *mean*: RMSE of always predicting the training outputs' mean; *ratio*: RMSE / mean's. \
         Free simulation by moment matching, whose variances keep the function's uncertainty \
         correlated over time (`msgp_core::rollout::function_uncertainty`); 2σ coverage of the noise-free (synthetic) or \
         measured (real) outputs. Seeds: {}.\n",
        args.common
            .seeds
            .iter()
            .map(|s| s.to_string())
            .collect::<Vec<_>>()
            .join(", ")
    );
    let _ = writeln!(
        s,
        "- Command: `{}`\n- Wall time: {seconds:.0} s, msgp {} on {}\n- Date (UTC): {}\n",
        command.join(" "),
        env!("CARGO_PKG_VERSION"),
        machine(),
        today()
    );
    if let (Some(dir), Some(first)) = (&args.plots, plots.first()) {
        let _ = writeln!(
            s,
            "- Plots: one per benchmark and seed, `{}/<benchmark>-seed<k>.png`: a row per test, \
             MSGP and GP-NARX side by side, the predicted mean ± 2σ against the true (synthetic) \
             or measured (real) output (e.g. [{first}]({first}))\n",
            dir.display(),
        );
    }
    for line in summary(cases) {
        let _ = writeln!(s, "{line}");
    }
    s.push_str(
        "\n| Benchmark | test | seed | mean | MSGP RMSE | ratio | 2σ cov. | GP-NARX RMSE | ratio | 2σ cov. |\n\
         |---|---|---:|---:|---:|---:|---:|---:|---:|---:|\n",
    );
    for c in cases {
        let (a, b) = (&c.metrics[0], &c.metrics[1]);
        let _ = writeln!(
            s,
            "| {} | {} | {} | {:.4} | {:.4} | {:.2} | {:.2} | {:.4} | {:.2} | {:.2} |",
            c.key,
            c.test,
            c.seed,
            c.mean_rmse,
            a.rmse,
            a.rmse / c.mean_rmse,
            a.coverage_2sigma,
            b.rmse,
            b.rmse / c.mean_rmse,
            b.coverage_2sigma
        );
    }
    s
}
