//! `msgp reproduce table1`: the paper's Table 1 (free-simulation test RMSE of GP-NARX, PILCO's
//! GP-NARX and MSGP on five synthetic and five real benchmarks) over several seeds, written as
//! markdown beside the paper's numbers, with MSGP trained on both likelihoods, the baselines
//! simulated both by moment matching and by mean feedback, our NLL and 2σ coverage.

use std::fmt::Write as _;
use std::time::Instant;

use anyhow::{Context, bail};
use msgp_core::data::real::RealSeries;
use msgp_core::data::{Benchmark, NoiseScale, SyntheticSystem};
use msgp_core::fit::{FitOptimizer, FitProgress, FitSettings, MsgpSettings, fit};
use msgp_core::loss::Likelihood;
use msgp_core::model::{Method, Metrics, Rollout};
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

/// A column of the table: a method and, for MSGP, its likelihood.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Column {
    GpNarx,
    PilcoNarx,
    Msgp,
    MsgpFilter,
}

const COLUMNS: [Column; 4] = [
    Column::GpNarx,
    Column::PilcoNarx,
    Column::Msgp,
    Column::MsgpFilter,
];

impl Column {
    fn method(self) -> Method {
        match self {
            Column::GpNarx => Method::GpNarx,
            Column::PilcoNarx => Method::PilcoNarx,
            Column::Msgp | Column::MsgpFilter => Method::Msgp,
        }
    }

    /// The paper's column of Table 1, if it has one.
    fn paper(self) -> Option<usize> {
        match self {
            Column::GpNarx => Some(0),
            Column::PilcoNarx => Some(1),
            Column::Msgp => Some(2),
            Column::MsgpFilter => None,
        }
    }

    fn name(self) -> &'static str {
        match self {
            Column::GpNarx => "gp-narx",
            Column::PilcoNarx => "pilco-narx",
            Column::Msgp => "msgp",
            Column::MsgpFilter => "msgp-filter",
        }
    }

    fn label(self) -> &'static str {
        match self {
            Column::GpNarx => "GP-NARX",
            Column::PilcoNarx => "PILCO GP-NARX",
            Column::Msgp => "MSGP",
            Column::MsgpFilter => "MSGP (filter)",
        }
    }

    /// The rollout the column is judged by: the baselines' mean feedback is reported beside
    /// their moment matching, MSGP is the paper's moment matching.
    fn is_baseline(self) -> bool {
        matches!(self, Column::GpNarx | Column::PilcoNarx)
    }

    fn index(self) -> usize {
        COLUMNS.iter().position(|c| *c == self).unwrap_or(0)
    }
}

/// One fitted cell: a column on one benchmark with one seed.
struct Cell {
    /// Test metrics of the moment-matching and the mean-feedback simulation
    /// ([`Rollout::ALL`] order).
    metrics: [Metrics; 2],
    train_seconds: f64,
    iterations_run: usize,
    best_iteration: usize,
}

/// One benchmark's results: per column, one cell per seed.
struct Row<'t> {
    task: &'t Task,
    /// The first seed's data (sizes and history for the table).
    bench: Benchmark,
    cells: Vec<Vec<Cell>>,
}

/// Mean and sample standard deviation.
fn mean_std(v: &[f64]) -> Option<(f64, f64)> {
    if v.is_empty() {
        return None;
    }
    let n = v.len() as f64;
    let mean = v.iter().sum::<f64>() / n;
    let var = if v.len() > 1 {
        v.iter().map(|x| (x - mean).powi(2)).sum::<f64>() / (n - 1.0)
    } else {
        0.0
    };
    Some((mean, var.sqrt()))
}

/// `mean ± std` of `f` over a column's cells (just the value for one seed; `—` for none).
fn stat(cells: &[Cell], digits: usize, f: impl Fn(&Cell) -> f64) -> String {
    let v: Vec<f64> = cells.iter().map(f).collect();
    match mean_std(&v) {
        None => "—".into(),
        Some((m, _)) if v.len() == 1 => format!("{m:.digits$}"),
        Some((m, sd)) => format!("{m:.digits$} ± {sd:.digits$}"),
    }
}

fn mean_of(cells: &[Cell], f: impl Fn(&Cell) -> f64) -> Option<f64> {
    mean_std(&cells.iter().map(f).collect::<Vec<_>>()).map(|(m, _)| m)
}

const MM: usize = 0;
const MEAN: usize = 1;

/// Runs `msgp reproduce table1`.
pub fn run(args: &Table1Args) -> anyhow::Result<()> {
    let started = Instant::now();
    let all = tasks();
    for name in &args.common.only {
        if !all.iter().any(|t| t.key == name.as_str()) {
            bail!(
                "unknown benchmark `{name}` (choose from {})",
                all.iter().map(|t| t.key).collect::<Vec<_>>().join(", ")
            );
        }
    }
    args.common.check_seeds()?;
    let chosen: Vec<&Task> = all
        .iter()
        .filter(|t| args.common.only.is_empty() || args.common.only.iter().any(|n| n == t.key))
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
    let likelihoods: Vec<Likelihood> = if args.likelihoods.is_empty() {
        vec![Likelihood::FreeRun, Likelihood::Filter]
    } else {
        args.likelihoods.iter().map(|&l| l.into()).collect()
    };
    let columns: Vec<Column> = COLUMNS
        .into_iter()
        .filter(|c| {
            args.methods.is_empty() || args.methods.iter().any(|a| Method::from(*a) == c.method())
        })
        .filter(|c| match c {
            Column::Msgp => likelihoods.contains(&Likelihood::FreeRun),
            Column::MsgpFilter => likelihoods.contains(&Likelihood::Filter),
            _ => true,
        })
        .collect();
    let dir = args.common.data_dir();
    let threads = Threads::from_env()?;
    let total = chosen.len() * columns.len() * args.common.seeds.len();
    let mut done = 0;
    let mut rows: Vec<Row> = Vec::new();
    for task in &chosen {
        let mut cells: Vec<Vec<Cell>> = COLUMNS.iter().map(|_| Vec::new()).collect();
        let mut first = None;
        for &seed in &args.common.seeds {
            let bench = match task.source {
                Source::Synthetic(k) => {
                    SyntheticSystem::new(k)?.generate(seed, NoiseScale::StdDev)?
                }
                Source::Real(s) => s.load(&dir).with_context(|| {
                    format!(
                        "loading the real series {} (set --data-dir or MSGP_DATA_DIR)",
                        s.name()
                    )
                })?,
            };
            for &column in &columns {
                done += 1;
                let method = column.method();
                let mut settings = FitSettings {
                    ly: bench.ly,
                    lu: bench.lu,
                    seed,
                    threads,
                    ..FitSettings::new(method)
                }
                .with_inducing(args.inducing);
                if let Some(msgp) = settings.msgp_mut() {
                    msgp.optimizer = args.optimizer.into();
                    if column == Column::MsgpFilter {
                        msgp.likelihood = Likelihood::Filter;
                    }
                }
                if let (Some(n), Method::Msgp) = (args.iters, method) {
                    settings = settings.with_solver_iterations(n);
                }
                let what = format!("{} on {} (seed {seed})", column.name(), task.key);
                let label = format!("[{done}/{total}] {what}");
                let mut bar = FitBar::new(&label, args.common.quiet);
                let fitted = fit(
                    std::slice::from_ref(&bench.train),
                    &settings,
                    &mut |p: &FitProgress| bar.update(p),
                );
                let (model, report) = match fitted {
                    Ok(r) => r,
                    Err(e) => {
                        bar.abandon();
                        return Err(e).context(format!("fitting {what}"));
                    }
                };
                let mut metrics = [Metrics {
                    rmse: f64::NAN,
                    nll: f64::NAN,
                    coverage_2sigma: f64::NAN,
                    steps: 0,
                }; 2];
                for (k, rollout) in Rollout::ALL.into_iter().enumerate() {
                    metrics[k] = model.evaluate_as(&bench.test, rollout).with_context(|| {
                        format!("evaluating {what} ({} rollout)", rollout.name())
                    })?;
                }
                let paper = column
                    .paper()
                    .map_or_else(String::new, |i| format!(" (paper {:.4})", task.paper[i]));
                bar.finish(&format!(
                    "RMSE {:.4}{paper}, mean feedback {:.4}, NLL {:.3}, coverage {:.2}, {:.1} s",
                    metrics[MM].rmse,
                    metrics[MEAN].rmse,
                    metrics[MM].nll,
                    metrics[MM].coverage_2sigma,
                    report.train_seconds
                ));
                cells[column.index()].push(Cell {
                    metrics,
                    train_seconds: report.train_seconds,
                    iterations_run: report.iterations_run,
                    best_iteration: report.best_iteration,
                });
            }
            first.get_or_insert(bench);
        }
        if let Some(bench) = first {
            rows.push(Row { task, bench, cells });
        }
    }
    let seconds = started.elapsed().as_secs_f64();
    let markdown = render(args, &rows, &columns, seconds);
    let section = match args.optimizer {
        OptimizerArg::Adam => "table1",
        OptimizerArg::Lbfgs => "table1-lbfgs",
    };
    crate::render::results_file::update_section(&args.common.out, section, &markdown)?;
    if args.common.json {
        let mut list = Vec::new();
        for row in &rows {
            for &column in &columns {
                for (cell, seed) in row.cells[column.index()].iter().zip(&args.common.seeds) {
                    for (k, rollout) in Rollout::ALL.into_iter().enumerate() {
                        let m = &cell.metrics[k];
                        list.push(json!({
                            "benchmark": row.task.key,
                            "method": column.method().name(),
                            "column": column.name(),
                            "seed": seed,
                            "rollout": rollout.name(),
                            "rmse": m.rmse,
                            "paper_rmse": column.paper().map(|i| row.task.paper[i]),
                            "nll": m.nll,
                            "coverage_2sigma": m.coverage_2sigma,
                            "train_seconds": cell.train_seconds,
                            "history": [row.bench.ly, row.bench.lu],
                            "n_train": row.bench.train.len(),
                            "n_test": row.bench.test.len(),
                        }));
                    }
                }
            }
        }
        return out_json(&json!({
            "command": "reproduce table1",
            "out": args.common.out.display().to_string(),
            "seconds": seconds,
            "seeds": args.common.seeds,
            "inducing": args.inducing,
            "rows": list,
        }));
    }
    out(&format!(
        "{}\n{}\nwritten to {} in {:.0} s",
        rmse_table(&rows, &columns),
        targets(&rows, &columns).join("\n"),
        args.common.out.display(),
        seconds
    ))
}

/// The RMSE table: ours (mean ± std over the seeds) beside the paper's; the baselines with
/// moment-matching and mean-feedback simulations.
fn rmse_table(rows: &[Row], columns: &[Column]) -> String {
    let mut head = String::from("| Task ");
    let mut rule = String::from("|---");
    for c in columns {
        if c.paper().is_some() {
            let _ = write!(head, "| {} (paper) ", c.label());
            rule.push_str("|---:");
        }
        if c.is_baseline() {
            let _ = write!(head, "| {0} (ours, MM) | {0} (ours, mean) ", c.label());
            rule.push_str("|---:|---:");
        } else {
            let _ = write!(head, "| {} (ours) ", c.label());
            rule.push_str("|---:");
        }
    }
    let mut s = format!("{head}|\n{rule}|\n");
    for row in rows {
        let _ = write!(s, "| {} ", row.task.label);
        for c in columns {
            let cells = &row.cells[c.index()];
            if let Some(i) = c.paper() {
                let _ = write!(s, "| {:.4} ", row.task.paper[i]);
            }
            let _ = write!(s, "| {} ", stat(cells, 4, |x| x.metrics[MM].rmse));
            if c.is_baseline() {
                let _ = write!(s, "| {} ", stat(cells, 4, |x| x.metrics[MEAN].rmse));
            }
        }
        s.push_str("|\n");
    }
    s
}

/// The targets, counted over the rows (seed means).
fn targets(rows: &[Row], columns: &[Column]) -> Vec<String> {
    let mut lines = Vec::new();
    let rmse =
        |row: &Row, c: Column, k: usize| mean_of(&row.cells[c.index()], |x| x.metrics[k].rmse);
    for c in [Column::Msgp, Column::MsgpFilter] {
        if !columns.contains(&c) {
            continue;
        }
        let (mut at_paper, mut at_best, mut nll_better, mut n) = (0, 0, 0, 0);
        for row in rows {
            let Some(r) = rmse(row, c, MM) else { continue };
            n += 1;
            let paper_msgp = row.task.paper[2];
            let best = row.task.paper.iter().copied().fold(f64::INFINITY, f64::min);
            at_paper += usize::from(r <= paper_msgp);
            at_best += usize::from(r <= best);
            let nll = mean_of(&row.cells[c.index()], |x| x.metrics[MM].nll);
            let base = mean_of(&row.cells[Column::GpNarx.index()], |x| x.metrics[MM].nll);
            if let (Some(a), Some(b)) = (nll, base) {
                nll_better += usize::from(a < b);
            }
        }
        lines.push(format!(
            "- {}: seed-mean RMSE at or below the paper's MSGP on {at_paper}/{n} rows, at or \
             below the best column of Table 1 on {at_best}/{n}; NLL below GP-NARX's (MM) on \
             {nll_better}/{n}",
            c.label()
        ));
    }
    for c in [Column::GpNarx, Column::PilcoNarx] {
        if !columns.contains(&c) {
            continue;
        }
        let (mut within, mut n) = (0, 0);
        for row in rows {
            let (Some(r), Some(i)) = (rmse(row, c, MEAN), c.paper()) else {
                continue;
            };
            n += 1;
            within += usize::from((r - row.task.paper[i]).abs() <= 0.1 * row.task.paper[i]);
        }
        lines.push(format!(
            "- {} (mean feedback): within 10 % of the paper's column on {within}/{n} rows",
            c.label()
        ));
    }
    lines
}

fn render(args: &Table1Args, rows: &[Row], columns: &[Column], seconds: f64) -> String {
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
    let seeds: Vec<String> = args.common.seeds.iter().map(|s| s.to_string()).collect();
    let mut s = String::from(title);
    let _ = writeln!(
        s,
        "Free-simulation RMSE on the test part (original units) of the paper's Table 1 \
         (Doerr et al., CoRL 2017), ours beside the paper's, as mean ± sample standard \
         deviation over seeds {seeds}. Synthetic systems: generated as in Table 2 with each \
         seed, training noise `N(0, s)` read as a standard deviation (`docs/design.md`), \
         noise-free test outputs. Real series: the paper's Table 3 splits and history lengths \
         (first samples train, the rest test; only the fits' seeds vary). Every method: m = {m} \
         pseudo-inputs; MSGP: the default protocol of `msgp_core::fit::MsgpSettings` with at \
         most {iters} {solver} iterations. MM: moment-matching simulation (the paper's method \
         and our default); mean: the predicted means fed back, no uncertainty propagated \
         (`msgp eval --rollout mean`), the reading that matches the paper's baseline columns.\n",
        seeds = seeds.join(", "),
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
        rows.iter()
            .map(|r| r.cells.iter().map(Vec::len).sum::<usize>())
            .sum::<usize>(),
        env!("CARGO_PKG_VERSION"),
        machine()
    );
    let _ = writeln!(s, "- Date (UTC): {}\n", today());
    s.push_str("## RMSE\n\n");
    s.push_str(&rmse_table(rows, columns));
    s.push('\n');
    for line in targets(rows, columns) {
        let _ = writeln!(s, "{line}");
    }
    let _ = write!(
        s,
        "\n## Our calibration\n\nMean negative log predictive density per step (NLL, original \
         units) and the fraction of test outputs inside mean ± 2σ, per rollout, with the \
         training time (means ± standard deviations over the seeds).\n\n\
         | Task | method | rollout | RMSE | NLL/step | 2σ coverage | train s | {} iterations (kept) |\n\
         |---|---|---|---:|---:|---:|---:|---:|\n",
        FitOptimizer::from(args.optimizer).name()
    );
    for row in rows {
        for &c in columns {
            let cells = &row.cells[c.index()];
            if cells.is_empty() {
                continue;
            }
            for (k, rollout) in Rollout::ALL.into_iter().enumerate() {
                let iters = if c.method() == Method::Msgp {
                    cells
                        .iter()
                        .map(|x| format!("{} ({})", x.iterations_run, x.best_iteration))
                        .collect::<Vec<_>>()
                        .join(", ")
                } else {
                    "—".to_string()
                };
                let _ = writeln!(
                    s,
                    "| {} | {} | {} | {} | {} | {} | {} | {} |",
                    row.task.label,
                    c.name(),
                    rollout.name(),
                    stat(cells, 4, |x| x.metrics[k].rmse),
                    stat(cells, 3, |x| x.metrics[k].nll),
                    stat(cells, 3, |x| x.metrics[k].coverage_2sigma),
                    stat(cells, 1, |x| x.train_seconds),
                    iters
                );
            }
        }
    }
    s.push_str(
        "\n## Data\n\n| Task | training samples | test samples | l_y, l_u |\n|---|---:|---:|---|\n",
    );
    for row in rows {
        let _ = writeln!(
            s,
            "| {} | {} | {} | {}, {} |",
            row.task.label,
            row.bench.train.len(),
            row.bench.test.len(),
            row.bench.ly,
            row.bench.lu
        );
    }
    s
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn mean_and_sample_standard_deviation() {
        assert_eq!(mean_std(&[]), None);
        assert_eq!(mean_std(&[2.0]), Some((2.0, 0.0)));
        let (m, sd) = mean_std(&[1.0, 2.0, 3.0]).expect("three");
        assert!((m - 2.0).abs() < 1e-15 && (sd - 1.0).abs() < 1e-15);
    }

    #[test]
    fn ten_tasks_with_paper_numbers() {
        let t = tasks();
        assert_eq!(t.len(), 10);
        assert_eq!(t[3].paper, [0.5711, 0.6016, 0.3287]);
        assert_eq!(t[9].key, "dryer");
    }
}
