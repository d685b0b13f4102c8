//! The rows of Table 1 from its cells, and the markdown section: the RMSE table beside the
//! paper's six columns, the NLL and coverage, the target lines, divergences and the chosen
//! histories.

use std::fmt::Write as _;

use msgp_core::MsgpError;
use msgp_core::data::Benchmark;
use msgp_core::fit::{FitOptimizer, MsgpSettings};
use msgp_core::model::{Method, Rollout};

use super::*;
use crate::error::Result;

/// One benchmark's results: per column, one cell per seed.
#[derive(Debug)]
pub struct Row {
    /// The benchmark.
    pub task: Task,
    /// The first seed's data (sizes and history for the table).
    pub bench: Benchmark,
    /// Per column of [`COLUMNS`], the cells in seed order.
    pub cells: Vec<Vec<Cell>>,
}

/// Mean and sample standard deviation.
pub fn mean_std(v: &[f64]) -> Option<(f64, f64)> {
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

/// The rows of the table from every unit's cell (any order; each unit exactly once).
pub fn assemble(plan: &Plan, results: Vec<(Unit, Cell)>) -> Result<Vec<Row>> {
    let units = plan.units();
    let mut slots: Vec<Option<Cell>> = units.iter().map(|_| None).collect();
    for (unit, cell) in results {
        let Some(k) = units.iter().position(|u| *u == unit) else {
            return Err(MsgpError::Data(format!(
                "a result for {} is not part of this plan",
                unit.describe()
            ))
            .into());
        };
        if slots[k].replace(cell).is_some() {
            return Err(MsgpError::Data(format!("two results for {}", unit.describe())).into());
        }
    }
    let mut cells = units.into_iter().zip(slots);
    let mut rows = Vec::with_capacity(plan.benchmarks.len());
    for key in &plan.benchmarks {
        let task = task(key)?;
        let mut by_column: Vec<Vec<Cell>> = COLUMNS.iter().map(|_| Vec::new()).collect();
        for _ in 0..plan.seeds.len() * plan.columns.len() {
            match cells.next() {
                Some((unit, Some(cell))) => by_column[unit.column.index()].push(cell),
                Some((unit, None)) => {
                    return Err(
                        MsgpError::Data(format!("no result for {}", unit.describe())).into(),
                    );
                }
                None => return Err(MsgpError::Data("fewer units than the plan".into()).into()),
            }
        }
        let bench = benchmark(&task, plan.seeds[0], &plan.data_dir)?;
        rows.push(Row {
            task,
            bench,
            cells: by_column,
        });
    }
    Ok(rows)
}

/// The rows as JSON records, one per cell and rollout (what `--json` prints).
pub fn rows_json(plan: &Plan, rows: &[Row]) -> Vec<serde_json::Value> {
    let mut list = Vec::new();
    for row in rows {
        for &column in &plan.columns {
            for (cell, seed) in row.cells[column.index()].iter().zip(&plan.seeds) {
                for (k, rollout) in Rollout::REPORTED.into_iter().enumerate() {
                    let m = &cell.metrics[k];
                    list.push(serde_json::json!({
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
                        "diverged": cell.diverged,
                        "history": cell.chosen_history.as_ref()
                            .map_or([row.bench.ly, row.bench.lu], |c| [c.ly, c.lu]),
                        "history_choice": cell.chosen_history,
                        "n_train": row.bench.train.len(),
                        "n_test": row.bench.test.len(),
                    }));
                }
            }
        }
    }
    list
}

/// The RMSE table: ours (mean ± std over the seeds) beside the paper's; the baselines with
/// moment-matching and mean-feedback simulations.
pub fn rmse_table(rows: &[Row], columns: &[Column]) -> String {
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
    for k in PAPER_ONLY {
        let _ = write!(head, "| {} (paper) ", PAPER_COLUMNS[k]);
        rule.push_str("|---:");
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
        for k in PAPER_ONLY {
            let _ = write!(s, "| {:.4} ", row.task.paper[k]);
        }
        s.push_str("|\n");
    }
    s
}

/// The targets, counted over the rows (seed means).
pub fn targets(rows: &[Row], columns: &[Column], seeds: &[u64]) -> Vec<String> {
    let mut lines = Vec::new();
    let rmse =
        |row: &Row, c: Column, k: usize| mean_of(&row.cells[c.index()], |x| x.metrics[k].rmse);
    for c in [Column::Msgp, Column::MsgpFilter] {
        if !columns.contains(&c) {
            continue;
        }
        let (mut at_paper, mut at_best, mut nll_better, mut n) = (0, 0, 0, 0);
        let mut behind = Vec::new();
        for row in rows {
            let Some(r) = rmse(row, c, MM) else { continue };
            n += 1;
            let paper_msgp = row.task.paper[PAPER_MSGP];
            let (best, best_column) = row.task.paper_best();
            at_paper += usize::from(r <= paper_msgp);
            at_best += usize::from(r <= best);
            if r > best {
                behind.push(format!(
                    "{} {r:.4} vs {best_column} {best:.4}",
                    row.task.label
                ));
            }
            let nll = mean_of(&row.cells[c.index()], |x| x.metrics[MM].nll);
            let base = mean_of(&row.cells[Column::GpNarx.index()], |x| x.metrics[MM].nll);
            if let (Some(a), Some(b)) = (nll, base) {
                nll_better += usize::from(a < b);
            }
        }
        lines.push(format!(
            "- {}: seed-mean RMSE at or below the paper's MSGP on {at_paper}/{n} rows, at or \
             below the best of the paper's six columns on {at_best}/{n}; NLL below GP-NARX's (MM) on \
             {nll_better}/{n}{}",
            c.label(),
            if behind.is_empty() {
                String::new()
            } else {
                format!(" (behind the best on {})", behind.join(", "))
            }
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
    lines.push(divergences(rows, columns, seeds));
    lines
}

/// The line naming every diverging model ([`Cell::diverged`]) by column, row and seed (`seeds`:
/// the cells' seeds, in order).
fn divergences(rows: &[Row], columns: &[Column], seeds: &[u64]) -> String {
    let mut found = Vec::new();
    for &c in columns {
        for row in rows {
            let diverging: Vec<String> = row.cells[c.index()]
                .iter()
                .zip(seeds)
                .filter(|(x, _)| x.diverged.is_some())
                .map(|(_, seed)| seed.to_string())
                .collect();
            if diverging.is_empty() {
                continue;
            }
            found.push(format!(
                "{} on {} (seed {})",
                c.label(),
                row.task.label,
                diverging.join(", ")
            ));
        }
    }
    let list = match found.is_empty() {
        true => "none".to_string(),
        false => found.join("; "),
    };
    format!(
        "- Diverging models (the fit's check on its training inputs, or the test part's \
         simulation leaving the test outputs by 5 ranges, `msgp eval`'s check): {list}"
    )
}

/// The markdown section for `rows` (see [`Plan::section`]).
pub fn render(plan: &Plan, rows: &[Row], provenance: &Provenance) -> String {
    let columns = &plan.columns[..];
    let mut s = header(plan, rows, provenance);
    s.push_str("## RMSE\n\n");
    s.push_str(&rmse_table(rows, columns));
    s.push('\n');
    for line in targets(rows, columns, &plan.seeds) {
        let _ = writeln!(s, "{line}");
    }
    s.push_str(&calibration_table(plan, rows));
    if plan.history == TableHistory::Auto {
        s.push_str(&chosen_histories(rows, columns));
    }
    s.push_str(&data_table(plan, rows));
    s
}

/// The section's title, what the table is and how it was made.
fn header(plan: &Plan, rows: &[Row], provenance: &Provenance) -> String {
    let (title, solver) = match plan.optimizer {
        FitOptimizer::Adam => ("# Table 1, reproduced", "Adam"),
        FitOptimizer::Lbfgs => (
            "# Table 1, reproduced with MSGP fitted by L-BFGS",
            "L-BFGS (`msgp_core::fit::FIT_LBFGS`, validation after every iteration)",
        ),
    };
    let seeds: Vec<String> = plan.seeds.iter().map(|s| s.to_string()).collect();
    let mut s = String::from(title);
    s.push_str(match plan.history {
        TableHistory::Paper => "\n\n",
        TableHistory::Auto => ", histories chosen from the data\n\n",
    });
    let _ = writeln!(
        s,
        "Free-simulation RMSE on the test part (original units) of the paper's Table 1 \
         (Doerr et al., CoRL 2017), ours beside the paper's, as mean ± sample standard \
         deviation over seeds {seeds}. Synthetic systems: generated as in Table 2 with each \
         seed, training noise `N(0, s)` read as a standard deviation (`docs/design.md`), \
         noise-free test outputs. Real series: the paper's Table 3 splits{lengths} \
         (first samples train, the rest test; only the fits' seeds vary). Every method: m = {m} \
         pseudo-inputs; GP-NARX: a sparse GP by the variational bound (hyperparameters and \
         pseudo-inputs jointly); PILCO GP-NARX: the full GP's penalised marginal likelihood, \
         then projected onto k-means pseudo-inputs; MSGP: the default protocol of \
         `msgp_core::fit::MsgpSettings` (two recipes trained on the first 80 % of the training \
         data, with at most {iters} {solver} iterations each and early stopping on the last \
         20 %, which also chooses the recipe; the chosen recipe then trains again from its start \
         on all the training data for {full} iterations). MM: \
         moment-matching simulation (the paper's method for every column and our default), \
         whose variances keep the function's uncertainty correlated over time (the same means; \
         `msgp_core::rollout::function_uncertainty`); \
         mean: the predicted means fed back, no uncertainty propagated (`msgp eval --rollout \
         mean`).\n",
        seeds = seeds.join(", "),
        lengths = match plan.history {
            TableHistory::Paper => " and history lengths",
            TableHistory::Auto => "",
        },
        m = plan.inducing,
        iters = plan.iters.unwrap_or(MsgpSettings::default().iterations),
        full = plan
            .iters
            .unwrap_or(MsgpSettings::default().iterations)
            .min(msgp_core::fit::DEFAULT_FULL_DATA_ITERATIONS),
    );
    if plan.history == TableHistory::Auto {
        s.push_str(AUTO_HISTORY_NOTE);
    }
    let _ = writeln!(s, "- Command: {}", provenance.command);
    let _ = writeln!(
        s,
        "- Wall time: {:.0} s ({:.1} min) for {} fits, msgp {} on {}",
        provenance.seconds,
        provenance.seconds / 60.0,
        rows.iter()
            .map(|r| r.cells.iter().map(Vec::len).sum::<usize>())
            .sum::<usize>(),
        env!("CARGO_PKG_VERSION"),
        provenance.machine
    );
    let _ = writeln!(s, "- Date (UTC): {}\n", provenance.date);
    s
}

/// NLL, coverage, training time and the MSGP fits' iterations, per row, column and rollout.
fn calibration_table(plan: &Plan, rows: &[Row]) -> String {
    let columns = &plan.columns[..];
    let mut s = String::new();
    let _ = write!(
        s,
        "\n## Our calibration\n\nMean negative log predictive density per step (NLL, original \
         units) and the fraction of test outputs inside mean ± 2σ, per rollout, with the \
         training time (means ± standard deviations over the seeds). MSGP's iterations: all \
         solver iterations of the fit, then in brackets the iteration the validation tail kept \
         (\"spread\", \"linear\": the zero-mean recipe's final training blew up and its fallback head from \
         the spread start, or with a linear prior mean, is the model: `msgp_core::fit::MsgpSettings::blow_up_fallback`; \
         \"linear set aside\", \"zero set aside\": the recipe the tail preferred, with that prior mean, \
         had a model whose free simulation of the training inputs diverges, and the next recipe's \
         is the model: `msgp_core::fit::FitReport::set_aside`) \
         and, where the chosen recipe trained again on all the training data, the iterate of \
         that training the model is; after them, the standard deviation (original units) the \
         output-variance calibration adds to every simulated output (`msgp_core::fit::calibration`: \
         judged on the validation tail by the final training's proxy; it moves no mean).\n\n\
         | Task | method | rollout | RMSE | NLL/step | 2σ coverage | train s | {} iterations (kept) |\n\
         |---|---|---|---:|---:|---:|---:|---:|\n",
        plan.optimizer.name()
    );
    for row in rows {
        for &c in columns {
            let cells = &row.cells[c.index()];
            if cells.is_empty() {
                continue;
            }
            for (k, rollout) in Rollout::REPORTED.into_iter().enumerate() {
                let iters = if c.method() == Method::Msgp {
                    msgp_iterations(cells)
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
    s
}

/// The MSGP iterations column of a column's cells: all solver iterations, then in brackets the
/// fallback head, the kept iteration and a set-aside recipe, and the final training's iterate;
/// after them, the standard deviation the calibration adds.
fn msgp_iterations(cells: &[Cell]) -> String {
    cells
        .iter()
        .map(|x| {
            let start = x
                .fallback
                .as_ref()
                .map_or(String::new(), |f| format!("{f} "));
            let aside = x
                .set_aside
                .as_ref()
                .map_or(String::new(), |r| format!(", {r} set aside"));
            let (run, best) = (x.iterations_run, x.best_iteration);
            let kept = match x.full_data_iteration {
                Some(j) => format!("{run} ({start}{best}{aside}; {j})"),
                None => format!("{run} ({start}{best}{aside})"),
            };
            match x.added_std {
                Some(a) => format!("{kept} +{a:.3}"),
                None => kept,
            }
        })
        .collect::<Vec<_>>()
        .join(", ")
}

/// The data of every row: training and test lengths, the history.
fn data_table(plan: &Plan, rows: &[Row]) -> String {
    let mut s = String::new();
    s.push_str(match plan.history {
        TableHistory::Paper => {
            "\n## Data\n\n| Task | training samples | test samples | l_y, l_u |\n|---|---:|---:|---|\n"
        }
        TableHistory::Auto => {
            "\n## Data\n\n| Task | training samples | test samples | the paper's l_y, l_u |\n|---|---:|---:|---|\n"
        }
    });
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

/// What a section of histories chosen from the data adds to the table's description.
const AUTO_HISTORY_NOTE: &str = "Here the history `l_y, l_u` of every fit is not the paper's \
     Table 3 but chosen on that fit's training part alone, as `msgp fit --history auto` chooses \
     it (`msgp_core::fit::history`): the first 80 % of the training part fits, the last 20 % \
     judges; every history up to 10 lags is scored as a linear ARX model, and the best three \
     with the equal histories `(l, l)` are each fitted by the column's own fit and scored by \
     their free simulation of the judged part; the shortest within one standard error of the \
     best wins. The test part plays no part in the choice.\n\n";

/// The section's table of the histories chosen per row, column and seed, with each one's
/// judged score and the runner-up.
fn chosen_histories(rows: &[Row], columns: &[Column]) -> String {
    let mut s = String::from(
        "\n## Chosen histories\n\nPer fit (seed order): the history chosen on the training \
         part, its judged score (free-simulation RMSE of the judged 20 % per output standard \
         deviation) and the best other judged history's (lower where the \
         one-standard-error rule took the shorter history).\n\n\
         | Task | column | paper's l_y, l_u | chosen (score; next) |\n|---|---|---|---|\n",
    );
    let score = |x: f64| match x.is_finite() {
        true => format!("{x:.4}"),
        false => "diverged".into(),
    };
    for row in rows {
        for &c in columns {
            let picks: Vec<String> = row.cells[c.index()]
                .iter()
                .filter_map(|cell| cell.chosen_history.as_ref())
                .map(|h| {
                    let own = h.judged.iter().find(|j| (j.ly, j.lu) == (h.ly, h.lu));
                    let next = h.judged.iter().find(|j| (j.ly, j.lu) != (h.ly, h.lu));
                    format!(
                        "({}, {}) ({}; {})",
                        h.ly,
                        h.lu,
                        own.map_or("—".into(), |j| score(j.score)),
                        next.map_or("—".into(), |j| format!(
                            "({}, {}) {}",
                            j.ly,
                            j.lu,
                            score(j.score)
                        ))
                    )
                })
                .collect();
            if picks.is_empty() {
                continue;
            }
            let _ = writeln!(
                s,
                "| {} | {} | {}, {} | {} |",
                row.task.label,
                c.name(),
                row.bench.ly,
                row.bench.lu,
                picks.join(", ")
            );
        }
    }
    s
}
