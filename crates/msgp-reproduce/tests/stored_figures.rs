//! A Table 1 row with short budgets against figures stored from an earlier build: the guard of
//! refactors that must leave every fit as it was ("to the last digit"). Synthetic system 5,
//! seed 0, every column (MSGP on both likelihoods through the whole default protocol — recipes,
//! final training, calibration — and both one-step baselines), 40 solver iterations, 20
//! pseudo-inputs: a few seconds. Figure 4's counterpart is msgp-sim's
//! `short_runs_keep_their_stored_figures`.
//!
//! The figures were printed by this test (`STORE=1 cargo test --release -p msgp-reproduce
//! --test stored_figures -- --nocapture`) at commit 82bd71c. A change that moves them must say
//! why in its commit, and store the new ones.

use std::path::PathBuf;

use msgp_core::fit::FitOptimizer;
use msgp_core::numeric::parallel::Threads;
use msgp_reproduce::table1::{COLUMNS, Plan, fit_unit};

/// (column, RMSE and NLL of the moment-matching simulation, RMSE of the mean-feedback one,
/// solver iterations run).
type Stored = (&'static str, f64, f64, f64, usize);

const STORED: [Stored; 4] = [
    (
        "gp-narx",
        0.008011994836732294,
        -3.7463114340572097,
        0.008015224503245925,
        0,
    ),
    (
        "pilco-narx",
        0.011014638973565742,
        -3.080262261244605,
        0.01099728512917534,
        0,
    ),
    (
        "msgp",
        0.009641505330408211,
        -3.399348937178384,
        0.009643603936034629,
        123,
    ),
    (
        "msgp-filter",
        0.01173134729214046,
        -3.1948537569594166,
        0.011728099473254223,
        123,
    ),
];

fn close(a: f64, b: f64) -> bool {
    a == b || (a - b).abs() <= 1e-12 * a.abs().max(b.abs())
}

#[test]
fn a_table1_row_keeps_its_stored_figures() {
    let plan = Plan::new(
        &[0],
        &["synthetic5".to_string()],
        (&[], &[]),
        20,
        Some(40),
        FitOptimizer::Adam,
        &PathBuf::from("unused: synthetic data only"),
    )
    .expect("plan");
    let units = plan.units();
    assert_eq!(units.len(), COLUMNS.len());
    let store = std::env::var_os("STORE").is_some();
    for (unit, stored) in units.iter().zip(STORED) {
        // two threads: the default protocol's race; its figures do not depend on the count
        let cell =
            fit_unit(&plan, unit, Threads::new(2).expect("threads"), &mut |_| {}).expect("fit");
        let [mm, mean] = cell.metrics;
        let got = (
            unit.column.name(),
            mm.rmse,
            mm.nll,
            mean.rmse,
            cell.iterations_run,
        );
        if store {
            println!("    {got:?},");
            continue;
        }
        assert_eq!(got.0, stored.0, "column order");
        assert!(
            close(got.1, stored.1) && close(got.2, stored.2) && close(got.3, stored.3),
            "{}: {got:?} against the stored {stored:?}",
            unit.describe()
        );
        assert_eq!(got.4, stored.4, "{}: iterations run", unit.describe());
    }
}
