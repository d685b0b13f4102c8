//! `msgp reproduce table1`: the paper's Table 1 (free-simulation test RMSE of GP-NARX, PILCO's
//! GP-NARX and MSGP on five synthetic and five real benchmarks), written as markdown beside the
//! paper's numbers, with our NLL and 2σ coverage.

use std::fmt::Write as _;
use std::path::Path;
use std::time::Instant;

use anyhow::{Context, bail};
use msgp_core::data::real::{RealSeries, data_dir};
use msgp_core::data::{Benchmark, NoiseScale, SyntheticSystem};
use msgp_core::fit::{FitOptimizer, FitProgress, FitSettings, MsgpSettings, fit};
use msgp_core::model::{Method, Metrics};
use msgp_core::numeric::parallel::Threads;
use serde_json::json;

use crate::args::{OptimizerArg, Table1Args};
use crate::render::output::{out, out_json};
use crate::render::progress::FitBar;
use crate::render::results_file::{machine, today};

/// One benchmark of Table 1 and the paper's RMSE for (GP-NARX, PILCO, MSGP).
struct Task {
    key: &'static str,
    label: &'static str,
    paper: [f64; 3],
    source: Source,
}

enum Source {
    Synthetic(u8),
    Real(RealSeries),
}

const METHODS: [Method; 3] = [Method::GpNarx, Method::PilcoNarx, Method::Msgp];

fn tasks() -> Vec<Task> {
    let syn = |k: u8, key, label, paper| Task {
        key,
        label,
        paper,
        source: Source::Synthetic(k),
    };
    let real = |s, key, label, paper| Task {
        key,
        label,
        paper,
        source: Source::Real(s),
    };
    vec![
        syn(
            1,
            "synthetic1",
            "Synthetic system 1",
            [0.2265, 0.3511, 0.3805],
        ),
        syn(
            2,
            "synthetic2",
            "Synthetic system 2",
            [0.3535, 0.3467, 0.3424],
        ),
        syn(
            3,
            "synthetic3",
            "Synthetic system 3",
            [0.1572, 0.1487, 0.1341],
        ),
        syn(
            4,
            "synthetic4",
            "Synthetic system 4",
            [0.5711, 0.6016, 0.3287],
        ),
        syn(
            5,
            "synthetic5",
            "Synthetic system 5",
            [0.0164, 0.0150, 0.0143],
        ),
        real(
            RealSeries::Actuator,
            "actuator",
            "Actuator",
            [0.6376, 1.3767, 0.7124],
        ),
        real(
            RealSeries::Ballbeam,
            "ballbeam",
            "Balancing (ballbeam)",
            [0.0773, 0.0881, 0.0599],
        ),
        real(
            RealSeries::Drives,
            "drives",
            "Drives",
            [0.6888, 0.7024, 0.4217],
        ),
        real(
            RealSeries::Furnace,
            "furnace",
            "Furnace",
            [1.1996, 1.2012, 1.2013],
        ),
        real(
            RealSeries::Dryer,
            "dryer",
            "Dryer",
            [0.2856, 0.2956, 0.1523],
        ),
    ]
}

/// One fitted cell.
struct Cell {
    metrics: Metrics,
    train_seconds: f64,
    iterations_run: usize,
    best_iteration: usize,
}

/// Runs `msgp reproduce table1`.
pub fn run(args: &Table1Args) -> anyhow::Result<()> {
    let started = Instant::now();
    let all = tasks();
    for name in &args.only {
        if !all.iter().any(|t| t.key == name.as_str()) {
            bail!(
                "unknown benchmark `{name}` (choose from {})",
                all.iter().map(|t| t.key).collect::<Vec<_>>().join(", ")
            );
        }
    }
    let chosen: Vec<&Task> = all
        .iter()
        .filter(|t| args.only.is_empty() || args.only.iter().any(|n| n == t.key))
        .collect();
    if let Some(other) = args
        .methods
        .iter()
        .map(|&a| Method::from(a))
        .find(|m| !METHODS.contains(m))
    {
        anyhow::bail!(
            "--methods {}: table 1 compares the paper's methods (msgp, gp-narx, pilco-narx)",
            other.name()
        );
    }
    let methods: Vec<Method> = if args.methods.is_empty() {
        METHODS.to_vec()
    } else {
        METHODS
            .into_iter()
            .filter(|m| args.methods.iter().any(|a| Method::from(*a) == *m))
            .collect()
    };
    let dir = args
        .data_dir
        .clone()
        .unwrap_or_else(|| data_dir(Path::new(".")));
    let total = chosen.len() * methods.len();
    let mut done = 0;
    let mut rows: Vec<(&Task, Benchmark, Vec<Option<Cell>>)> = Vec::new();
    for task in &chosen {
        let bench = match task.source {
            Source::Synthetic(k) => {
                SyntheticSystem::new(k)?.generate(args.seed, NoiseScale::StdDev)?
            }
            Source::Real(s) => s.load(&dir).with_context(|| {
                format!(
                    "loading the real series {} (set --data-dir or MSGP_DATA_DIR)",
                    s.name()
                )
            })?,
        };
        let mut cells: Vec<Option<Cell>> = METHODS.iter().map(|_| None).collect();
        let threads = Threads::from_env()?;
        for &method in &methods {
            done += 1;
            let mut settings = FitSettings {
                ly: bench.ly,
                lu: bench.lu,
                seed: args.seed,
                threads,
                ..FitSettings::new(method)
            }
            .with_inducing(args.inducing);
            if let Some(msgp) = settings.msgp_mut() {
                msgp.optimizer = args.optimizer.into();
            }
            if let (Some(n), Method::Msgp | Method::LinearKf) = (args.iters, method) {
                settings = settings.with_solver_iterations(n);
            }
            let label = format!("[{done}/{total}] {} on {}", method.name(), task.key);
            let mut bar = FitBar::new(&label, args.quiet);
            let fitted = fit(
                std::slice::from_ref(&bench.train),
                &settings,
                &mut |p: &FitProgress| bar.update(p),
            );
            let (model, report) = match fitted {
                Ok(r) => r,
                Err(e) => {
                    bar.abandon();
                    return Err(e).context(format!("fitting {} on {}", method.name(), task.key));
                }
            };
            let metrics = model
                .evaluate(&bench.test)
                .with_context(|| format!("evaluating {} on {}", method.name(), task.key))?;
            bar.finish(&format!(
                "RMSE {:.4} (paper {:.4}), NLL {:.3}, coverage {:.2}, {:.1} s",
                metrics.rmse,
                task.paper[method_index(method)],
                metrics.nll,
                metrics.coverage_2sigma,
                report.train_seconds
            ));
            cells[method_index(method)] = Some(Cell {
                metrics,
                train_seconds: report.train_seconds,
                iterations_run: report.iterations_run,
                best_iteration: report.best_iteration,
            });
        }
        rows.push((task, bench, cells));
    }
    let seconds = started.elapsed().as_secs_f64();
    let markdown = render(args, &rows, &methods, seconds);
    let section = match args.optimizer {
        OptimizerArg::Adam => "table1",
        OptimizerArg::Lbfgs => "table1-lbfgs",
    };
    crate::render::results_file::update_section(&args.out, section, &markdown)?;
    if args.json {
        let list: Vec<_> = rows
            .iter()
            .flat_map(|(task, bench, cells)| {
                cells.iter().enumerate().filter_map(move |(i, c)| {
                    c.as_ref().map(|c| {
                        json!({
                            "benchmark": task.key,
                            "method": METHODS[i].name(),
                            "rmse": c.metrics.rmse,
                            "paper_rmse": task.paper[i],
                            "nll": c.metrics.nll,
                            "coverage_2sigma": c.metrics.coverage_2sigma,
                            "train_seconds": c.train_seconds,
                            "history": [bench.ly, bench.lu],
                            "n_train": bench.train.len(),
                            "n_test": bench.test.len(),
                        })
                    })
                })
            })
            .collect();
        return out_json(&json!({
            "command": "reproduce table1",
            "out": args.out.display().to_string(),
            "seconds": seconds,
            "seed": args.seed,
            "inducing": args.inducing,
            "rows": list,
        }));
    }
    out(&format!(
        "{}\nwritten to {} in {:.0} s",
        rmse_table(&rows),
        args.out.display(),
        seconds
    ))
}

fn method_index(m: Method) -> usize {
    METHODS.iter().position(|x| *x == m).unwrap_or(0)
}

fn cell(c: Option<&Cell>, f: impl Fn(&Cell) -> String) -> String {
    c.map_or_else(|| "—".to_string(), f)
}

/// The RMSE table: ours beside the paper's.
fn rmse_table(rows: &[(&Task, Benchmark, Vec<Option<Cell>>)]) -> String {
    let mut s = String::from(
        "| Task | GP-NARX (paper) | GP-NARX (ours) | PILCO GP-NARX (paper) | PILCO GP-NARX (ours) | MSGP (paper) | MSGP (ours) |\n\
         |---|---:|---:|---:|---:|---:|---:|\n",
    );
    for (task, _, cells) in rows {
        let _ = write!(s, "| {} ", task.label);
        for i in 0..3 {
            let _ = write!(
                s,
                "| {:.4} | {} ",
                task.paper[i],
                cell(cells[i].as_ref(), |c| format!("{:.4}", c.metrics.rmse))
            );
        }
        s.push_str("|\n");
    }
    s
}

fn render(
    args: &Table1Args,
    rows: &[(&Task, Benchmark, Vec<Option<Cell>>)],
    methods: &[Method],
    seconds: f64,
) -> String {
    let command: Vec<String> = std::env::args()
        .enumerate()
        .map(|(i, a)| if i == 0 { "msgp".to_string() } else { a })
        .collect();
    let (title, solver) = match args.optimizer {
        OptimizerArg::Adam => ("# Table 1, reproduced\n\n", "Adam"),
        OptimizerArg::Lbfgs => (
            "# Table 1, reproduced with MSGP fitted by L-BFGS\n\n",
            "L-BFGS (`msgp_core::fit::FIT_LBFGS`, validation after every iteration)",
        ),
    };
    let mut s = String::from(title);
    let _ = writeln!(
        s,
        "Free-simulation RMSE on the test part (original units) of the paper's Table 1 \
         (Doerr et al., CoRL 2017), ours beside the paper's. Synthetic systems: generated as in \
         Table 2 with seed {seed}, training noise `N(0, s)` read as a standard deviation \
         (`docs/design.md`), noise-free test outputs. Real series: the paper's Table 3 splits \
         and history lengths (first samples train, the rest test). Every method: m = {m} \
         pseudo-inputs, seed {seed}; MSGP: at most {iters} {solver} iterations with early stopping \
         on the last 20 % of the training data (`msgp_core::fit::MsgpSettings` defaults).\n",
        seed = args.seed,
        m = args.inducing,
        iters = args.iters.unwrap_or(MsgpSettings::default().iterations),
    );
    let _ = writeln!(
        s,
        "- Command: `cargo run --release --locked --bin msgp -- {}` (i.e. `{}`)",
        command.get(1..).map_or_else(String::new, |a| a.join(" ")),
        command.join(" ")
    );
    let _ = writeln!(
        s,
        "- Wall time: {:.0} s ({:.1} min) for {} fits, msgp {} on {}",
        seconds,
        seconds / 60.0,
        rows.len() * methods.len(),
        env!("CARGO_PKG_VERSION"),
        machine()
    );
    let _ = writeln!(s, "- Date (UTC): {}\n", today());
    s.push_str("## RMSE\n\n");
    s.push_str(&rmse_table(rows));
    let _ = write!(
        s,
        "\n## Our calibration\n\nMean negative log predictive density per step (NLL, original \
         units) and the fraction of test outputs inside mean ± 2σ, with the training time.\n\n\
         | Task | method | RMSE | NLL/step | 2σ coverage | train s | {} iterations (kept) |\n\
         |---|---|---:|---:|---:|---:|---:|\n",
        FitOptimizer::from(args.optimizer).name()
    );
    for (task, _, cells) in rows {
        for (i, c) in cells.iter().enumerate() {
            if let Some(c) = c {
                let iters = if METHODS[i] == Method::Msgp {
                    format!("{} ({})", c.iterations_run, c.best_iteration)
                } else {
                    "—".to_string()
                };
                let _ = writeln!(
                    s,
                    "| {} | {} | {:.4} | {:.3} | {:.3} | {:.1} | {} |",
                    task.label,
                    METHODS[i].name(),
                    c.metrics.rmse,
                    c.metrics.nll,
                    c.metrics.coverage_2sigma,
                    c.train_seconds,
                    iters
                );
            }
        }
    }
    s.push_str(
        "\n## Data\n\n| Task | training samples | test samples | l_y, l_u |\n|---|---:|---:|---|\n",
    );
    for (task, bench, _) in rows {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {}, {} |",
            task.label,
            bench.train.len(),
            bench.test.len(),
            bench.ly,
            bench.lu
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ten_tasks_with_paper_numbers() {
        let t = tasks();
        assert_eq!(t.len(), 10);
        assert_eq!(t[3].paper, [0.5711, 0.6016, 0.3287]);
        assert_eq!(t[9].key, "dryer");
    }
}
