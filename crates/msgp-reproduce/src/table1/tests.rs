//! Tests of the Table 1 reproduction.

use msgp_core::fit::history::HistorySearch;
use msgp_core::fit::{FitOptions, FitSettings, Overrides, fit};
use msgp_core::model::{Rollout, score};
use msgp_core::numeric::parallel::Threads;

use super::*;

#[test]
fn mean_and_sample_standard_deviation() {
    assert_eq!(mean_std(&[]), None);
    assert_eq!(mean_std(&[2.0]), Some((2.0, 0.0)));
    let (m, sd) = mean_std(&[1.0, 2.0, 3.0]).expect("three");
    assert!((m - 2.0).abs() < 1e-15 && (sd - 1.0).abs() < 1e-15);
}

/// A plan of MSGP on the free-run likelihood alone over `seeds` and `benchmarks`.
fn free_run_msgp_plan(seeds: &[u64], benchmarks: &[&str]) -> Plan {
    let only: Vec<String> = benchmarks.iter().map(|b| b.to_string()).collect();
    Plan::new(
        seeds,
        &only,
        (&[Method::Msgp], &[Likelihood::FreeRun]),
        10,
        None,
        FitOptimizer::Adam,
        Path::new("nowhere"),
    )
    .expect("plan")
}

fn cell(x: f64) -> Cell {
    let m = Metrics {
        rmse: x,
        nll: -x,
        coverage_2sigma: 0.5,
        steps: 10,
    };
    Cell {
        metrics: [m, m],
        train_seconds: 0.0,
        iterations_run: 1,
        best_iteration: 1,
        full_data_iteration: None,
        added_std: None,
        fallback: None,
        set_aside: None,
        diverged: None,
        chosen_history: None,
    }
}

#[test]
fn results_assemble_in_any_order_and_every_unit_exactly_once() {
    let only = ["synthetic2".to_string(), "synthetic5".to_string()];
    let plan = Plan::new(
        &[3, 1],
        &only,
        (&[Method::GpNarx, Method::Msgp], &[Likelihood::Filter]),
        10,
        None,
        FitOptimizer::Adam,
        Path::new("nowhere"),
    )
    .expect("plan");
    assert_eq!(plan.columns, [Column::GpNarx, Column::MsgpFilter]);
    let units = plan.units();
    assert_eq!(units.len(), 8);
    assert_eq!(units[1].describe(), "msgp-filter on synthetic2 (seed 3)");
    let numbered: Vec<(Unit, Cell)> = units
        .iter()
        .enumerate()
        .map(|(k, u)| (u.clone(), cell(k as f64)))
        .collect();
    let in_order = assemble(&plan, numbered.clone()).expect("rows");
    let reversed = assemble(&plan, numbered.iter().rev().cloned().collect()).expect("rows");
    for (a, b) in in_order.iter().zip(&reversed) {
        assert_eq!(a.cells, b.cells);
    }
    // the targets' last line names the diverging models by column, row and seed
    let none = targets(&in_order, &plan.columns, &plan.seeds);
    assert!(
        none.last().is_some_and(|l| l.ends_with(": none")),
        "{none:?}"
    );
    let mut flagged = numbered.clone();
    flagged[7].1.diverged = Some("runs away".into());
    let rows = assemble(&plan, flagged).expect("rows");
    let lines = targets(&rows, &plan.columns, &plan.seeds);
    assert!(
        lines
            .last()
            .is_some_and(|l| l.ends_with(": MSGP (filter) on Synthetic system 5 (seed 1)")),
        "{lines:?}"
    );
    // synthetic5, msgp-filter: units 5 (seed 3) and 7 (seed 1), in seed order
    let col = &in_order[1].cells[Column::MsgpFilter.index()];
    assert_eq!(
        col.iter().map(|c| c.metrics[0].rmse).collect::<Vec<_>>(),
        [5.0, 7.0]
    );
    let e = assemble(&plan, numbered[1..].to_vec()).expect_err("missing");
    assert!(
        e.to_string()
            .contains("no result for gp-narx on synthetic2 (seed 3)"),
        "{e}"
    );
    let mut twice = numbered.clone();
    twice.push(numbered[0].clone());
    let e = assemble(&plan, twice).expect_err("duplicate");
    assert!(e.to_string().contains("two results for"), "{e}");
    let mut foreign = numbered.clone();
    foreign[0].0.seed = 9;
    let e = assemble(&plan, foreign).expect_err("foreign");
    assert!(e.to_string().contains("not part of this plan"), "{e}");
    let e = Plan::new(
        &[0],
        &["x".into()],
        (&[], &[]),
        10,
        None,
        FitOptimizer::Adam,
        Path::new("."),
    )
    .expect_err("unknown benchmark");
    assert!(e.to_string().contains("unknown benchmark `x`"), "{e}");
}

/// The iteration column says which MSGP models are not the tail's first recipe's own: a
/// fallback head's, or the next recipe's after the first diverged.
#[test]
fn the_iteration_column_marks_fallback_heads_and_set_aside_recipes() {
    let plan = free_run_msgp_plan(&[0, 1, 2], &["synthetic4"]);
    let marked = |k: usize| {
        let mut c = cell(k as f64);
        c.iterations_run = 1000 + k;
        c.best_iteration = 10 * k;
        match k {
            0 => c.fallback = Some("linear".into()),
            1 => {
                c.set_aside = Some("linear".into());
                c.full_data_iteration = Some(388);
                c.added_std = Some(0.079);
            }
            _ => c.full_data_iteration = Some(400),
        }
        c
    };
    let results = plan
        .units()
        .iter()
        .enumerate()
        .map(|(k, u)| (u.clone(), marked(k)))
        .collect();
    let rows = assemble(&plan, results).expect("rows");
    let provenance = Provenance {
        command: "msgp reproduce table1".into(),
        seconds: 1.0,
        machine: "test".into(),
        date: "2026-12-05".into(),
    };
    let text = render(&plan, &rows, &provenance);
    let line = text
        .lines()
        .find(|l| l.starts_with("| Synthetic system 4 | msgp | mm |"))
        .expect("the MSGP line");
    assert!(
        line.ends_with(
            "| 1000 (linear 0), 1001 (10, linear set aside; 388) +0.079, 1002 (20; 400) |"
        ),
        "{line}"
    );
}

/// The target line counts a row at the best only when it is at or below all six of the
/// paper's columns: synthetic system 1 at 0.2079 is below the paper's GP-NARX, PILCO and
/// MSGP but behind REVARB 2 (0.1717); synthetic system 2 at 0.29 is below all six.
#[test]
fn the_best_column_is_the_best_of_all_six() {
    let plan = free_run_msgp_plan(&[0], &["synthetic1", "synthetic2"]);
    let results = plan
        .units()
        .iter()
        .map(|u| {
            let x = if u.benchmark == "synthetic1" {
                0.2079
            } else {
                0.29
            };
            (u.clone(), cell(x))
        })
        .collect();
    let rows = assemble(&plan, results).expect("rows");
    let lines = targets(&rows, &plan.columns, &plan.seeds);
    assert_eq!(
        lines[0],
        "- MSGP: seed-mean RMSE at or below the paper's MSGP on 2/2 rows, at or below the \
         best of the paper's six columns on 1/2; NLL below GP-NARX's (MM) on 0/2 (behind \
         the best on Synthetic system 1 0.2079 vs REVARB 2 0.1717)"
    );
    let table = rmse_table(&rows, &plan.columns);
    let head = table.lines().next().expect("a heading");
    assert!(
        head.ends_with("| NIGP (paper) | REVARB 1 (paper) | REVARB 2 (paper) |"),
        "{head}"
    );
    assert!(table.contains("| 0.2453 | 0.2129 | 0.1717 |"), "{table}");
}

/// With histories from the data, each unit fits the history chosen on its training part by
/// the column's own fit as judge, and the section lists the choices.
#[test]
fn an_auto_history_unit_fits_the_history_its_training_part_chooses() {
    let plan = Plan::new(
        &[0],
        &["synthetic1".into()],
        (&[Method::GpNarx], &[]),
        10,
        None,
        FitOptimizer::Adam,
        Path::new("nowhere"),
    )
    .expect("plan")
    .with_history(TableHistory::Auto);
    assert_eq!(plan.section(), "table1-auto-history");
    let unit = plan.units().remove(0);
    let threads = Threads::new(1).expect("one thread");
    let (cell, test, _) = fit_unit_simulated(&plan, &unit, threads, &mut |_| {}).expect("fitted");
    let bench = benchmark(&task("synthetic1").expect("task"), 0, Path::new("")).expect("data");
    let judge = FitOptions {
        overrides: Overrides {
            inducing: Some(10),
            ..Overrides::default()
        },
        threads,
        ..FitOptions::new(Method::GpNarx, 1, 1)
    };
    let expected = msgp_core::fit::history::choose_history(
        std::slice::from_ref(&bench.train),
        &HistorySearch::default(),
        &judge,
    )
    .expect("a choice");
    assert_eq!(cell.chosen_history.as_ref(), Some(&expected));
    // the paper's (2, 1) is not what the search picks here (it does on systems 2–5), so the test
    // tells the two apart
    assert_ne!((expected.ly, expected.lu), (bench.ly, bench.lu));
    let settings = FitSettings {
        ly: expected.ly,
        lu: expected.lu,
        threads,
        ..FitSettings::new(Method::GpNarx)
    }
    .with_inducing(10);
    let (model, _) = fit(std::slice::from_ref(&bench.train), &settings, &mut |_| {}).expect("fit");
    let sim = model
        .simulate_as(&test, Rollout::REPORTED[MM])
        .expect("simulated");
    assert_eq!(
        score(&sim, &test).expect("scored").rmse,
        cell.metrics[MM].rmse
    );
    let rows = assemble(&plan, vec![(unit, cell)]).expect("rows");
    let provenance = Provenance {
        command: "c".into(),
        seconds: 1.0,
        machine: "m".into(),
        date: "d".into(),
    };
    let markdown = render(&plan, &rows, &provenance);
    assert!(markdown.starts_with("# Table 1, reproduced, histories chosen from the data"));
    let line = format!(
        "| Synthetic system 1 | gp-narx | 2, 1 | ({}, {}) (",
        expected.ly, expected.lu
    );
    assert!(markdown.contains(&line), "{markdown}");
}

#[test]
fn ten_tasks_with_paper_numbers() {
    let t = tasks();
    assert_eq!(t.len(), 10);
    assert_eq!(t[3].paper, [0.5711, 0.6016, 0.7814, 0.6978, 0.4554, 0.3287]);
    assert_eq!(t[0].paper_best(), (0.1717, "REVARB 2"));
    assert_eq!(t[8].paper_best(), (1.1949, "NIGP"));
    assert_eq!(t[9].key, "dryer");
}
