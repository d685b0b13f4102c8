//! Accuracy on the paper's benchmarks (seeded, the default protocol): MSGP reaches the paper's
//! RMSE on synthetic system 4 (seed 0) and on the real dryer series, beats one-step GP-NARX,
//! and does not degrade when allowed many more iterations (early stopping on the held-out tail
//! of the training data).

use std::path::{Path, PathBuf};

use msgp_core::data::Benchmark;
use msgp_core::data::real::{DATA_DIR_VAR, RealSeries, data_dir};
use msgp_core::data::{NoiseScale, SyntheticSystem};
use msgp_core::fit::{FitOptimizer, FitSettings, MsgpSettings, MsgpStart, fit};
use msgp_core::gp::MeanFunction;
use msgp_core::loss::Likelihood;
use msgp_core::model::{Method, Metrics};

fn run(bench: &Benchmark, method: Method, iterations: usize) -> Metrics {
    run_with(bench, method, iterations, FitOptimizer::Adam).0
}

/// Metrics and MSGP iterations run.
fn run_with(
    bench: &Benchmark,
    method: Method,
    iterations: usize,
    optimizer: FitOptimizer,
) -> (Metrics, usize) {
    let mut settings = FitSettings {
        ly: bench.ly,
        lu: bench.lu,
        seed: 0,
        ..FitSettings::new(method)
    };
    // `iterations` are MSGP's; the baselines run their defaults
    if let Some(m) = settings.msgp_mut() {
        m.iterations = iterations;
        m.optimizer = optimizer;
    }
    let (model, report) =
        fit(std::slice::from_ref(&bench.train), &settings, &mut |_| {}).expect("fit");
    // the Table-1 fits do not set off the divergence check
    assert_eq!(report.diverged, None, "{} {}", bench.name, method.name());
    let m = model.evaluate(&bench.test).expect("evaluate");
    println!(
        "{} {}: RMSE {:.4}, NLL {:.3}, 2σ coverage {:.3}, kept iteration {} of {}, {:.1} s",
        bench.name,
        method.name(),
        m.rmse,
        m.nll,
        m.coverage_2sigma,
        report.best_iteration,
        report.iterations_run,
        report.train_seconds
    );
    (m, report.iterations_run)
}

/// The real-data folder, or `None` (with a printed reason) when it is absent and not required.
pub fn real_data() -> Option<PathBuf> {
    let dir = data_dir(&Path::new(env!("CARGO_MANIFEST_DIR")).join("../.."));
    if dir.join("dryer.csv").is_file() {
        return Some(dir);
    }
    if std::env::var_os("MSGP_REQUIRE_DATA").is_some() {
        panic!(
            "real benchmark data required (MSGP_REQUIRE_DATA) but not found at {}",
            dir.display()
        );
    }
    println!(
        "skipped: real benchmark series not found at {} (set {DATA_DIR_VAR})",
        dir.display()
    );
    None
}

#[test]
fn msgp_beats_gp_narx_on_synthetic_system_4_and_does_not_degrade() {
    let bench = SyntheticSystem::new(4)
        .expect("sys")
        .generate(0, NoiseScale::StdDev)
        .expect("gen");
    let narx = run(&bench, Method::GpNarx, 0);
    let msgp = run(&bench, Method::Msgp, 1000);
    // paper: GP-NARX 0.5711, MSGP 0.3287
    assert!(msgp.rmse <= 0.3287, "system 4 RMSE {}", msgp.rmse);
    assert!(
        msgp.coverage_2sigma > 0.8,
        "system 4 2σ coverage {}",
        msgp.coverage_2sigma
    );
    assert!(
        msgp.rmse < 0.9 * narx.rmse,
        "MSGP {} vs GP-NARX {}",
        msgp.rmse,
        narx.rmse
    );
    let long = run(&bench, Method::Msgp, 3000);
    assert!(
        long.rmse <= 1.05 * msgp.rmse,
        "3000 iterations: {} vs 1000: {}",
        long.rmse,
        msgp.rmse
    );
    assert!(long.rmse < 0.9 * narx.rmse);
}

/// Synthetic system 4 under its Table-2 test input at half amplitude, which it never saw (a
/// slow sine: the input dwells, and the plant's static gain of 10 sums the same function error
/// step after step). The band that keeps the GP's function uncertainty correlated over time
/// holds the noise-free outputs; the paper's moment matching, which draws the function afresh
/// every step, does not (seed 1: 2σ coverage 0.80 with the same means, `docs/experiments/2026-12-05-correlated-function-uncertainty.md`,
/// "Correlated function uncertainty").
#[test]
fn synthetic_system_4_keeps_its_band_on_an_input_it_never_saw() {
    use msgp_core::data::synthetic::Excitation;
    use msgp_core::model::Rollout;
    let sys = SyntheticSystem::new(4).expect("sys");
    let bench = sys.generate(1, NoiseScale::StdDev).expect("gen");
    let settings = FitSettings {
        ly: bench.ly,
        lu: bench.lu,
        seed: 1,
        ..FitSettings::new(Method::Msgp)
    };
    let (model, _) = fit(std::slice::from_ref(&bench.train), &settings, &mut |_| {}).expect("fit");
    let half = sys
        .alternate_test(Excitation::HalfTest, 1)
        .expect("excitation");
    let level = bench.train.y.column(0).mean();
    let start = model.spec.warmup();
    let n = half.len() - start;
    let mean_rmse = ((start..half.len())
        .map(|t| (half.y[(t, 0)] - level).powi(2))
        .sum::<f64>()
        / n as f64)
        .sqrt();
    let wide = model.evaluate(&half).expect("mm");
    let paper = model
        .evaluate_as(&half, Rollout::MomentMatchingIndependent)
        .expect("mm-independent");
    println!(
        "system 4 seed 1, half test input: RMSE {:.4} (training mean {mean_rmse:.4}), 2σ \
         coverage {:.3} (independent draws {:.3}), NLL {:.3} ({:.3})",
        wide.rmse, wide.coverage_2sigma, paper.coverage_2sigma, wide.nll, paper.nll
    );
    assert_eq!(wide.rmse, paper.rmse, "the means are moment matching's");
    assert!(
        wide.rmse <= 0.5 * mean_rmse,
        "RMSE {} against {mean_rmse}",
        wide.rmse
    );
    assert!(
        wide.coverage_2sigma >= 0.9,
        "coverage {}",
        wide.coverage_2sigma
    );
    assert!(
        paper.coverage_2sigma < 0.9,
        "independent: {}",
        paper.coverage_2sigma
    );
    assert!(
        wide.nll < paper.nll,
        "NLL {} against {}",
        wide.nll,
        paper.nll
    );
}

#[test]
fn msgp_reaches_paper_accuracy_on_dryer() {
    let Some(dir) = real_data() else { return };
    let bench = RealSeries::Dryer.load(&dir).expect("load dryer");
    let msgp = run(&bench, Method::Msgp, 1000);
    // paper: MSGP 0.1523, GP-NARX 0.2856
    assert!(msgp.rmse <= 0.1523, "dryer RMSE {}", msgp.rmse);
    assert!(
        msgp.coverage_2sigma > 0.8,
        "dryer 2σ coverage {}",
        msgp.coverage_2sigma
    );
}

#[test]
fn msgp_by_lbfgs_reaches_paper_accuracy_on_dryer_in_a_fraction_of_the_iterations() {
    let Some(dir) = real_data() else { return };
    let bench = RealSeries::Dryer.load(&dir).expect("load dryer");
    let (msgp, iterations) = run_with(&bench, Method::Msgp, 400, FitOptimizer::Lbfgs);
    // paper: MSGP 0.1523; Adam: 400 iterations, 0.1585
    assert!(msgp.rmse <= 0.155, "dryer RMSE {}", msgp.rmse);
    assert!(
        msgp.coverage_2sigma > 0.8,
        "dryer 2σ coverage {}",
        msgp.coverage_2sigma
    );
    // early stopping (patience 20 validation checks, one per iteration) ends it
    assert!(iterations < 120, "{iterations} L-BFGS iterations");
}

/// The rows the final training on all the data brought to the paper's MSGP (seed 0; the head's
/// early-stopped models gave drives 0.47–0.52 and furnace 1.2106): drives 0.333, furnace 1.196.
/// With the output-variance calibration (`msgp_core::fit::calibration`) furnace's 2σ band holds
/// its test outputs (coverage 1.00; 0.46 without it) and MSGP's NLL falls below GP-NARX's
/// (2.01 against 10.83; 13.35 without it).
#[test]
fn msgp_reaches_paper_accuracy_on_drives_and_furnace() {
    let Some(dir) = real_data() else { return };
    for (series, paper) in [(RealSeries::Drives, 0.4217), (RealSeries::Furnace, 1.2013)] {
        let bench = series.load(&dir).expect("load");
        let msgp = run(&bench, Method::Msgp, 1000);
        assert!(
            msgp.rmse <= paper,
            "{}: MSGP RMSE {} (paper {paper})",
            series.name(),
            msgp.rmse
        );
        if series == RealSeries::Furnace {
            let narx = run(&bench, Method::GpNarx, 0);
            assert!(
                msgp.coverage_2sigma >= 0.9 && msgp.nll < narx.nll,
                "furnace: MSGP NLL {} (2σ coverage {}) against GP-NARX's {}",
                msgp.nll,
                msgp.coverage_2sigma,
                narx.nll
            );
        }
    }
}

/// Ballbeam (seed 0): the one-step fit that starts the training explains the next output by the
/// past outputs (the input lags get length-scales of 55–110 in normalised units), and from that
/// start the zero-mean recipe's final training on all the data blows up, so the head's model
/// stood (0.0822; the training mean predicts the test part at 0.0733). The recipe's two fallback
/// heads (`MsgpSettings::blow_up_fallback`) are ordered by the validation tail: the one with a
/// linear prior mean (validation NLL 0.78) before the one from the spread start (1.03), and its
/// final training on all the data completes: 0.0576, below the paper's MSGP (0.0599; the spread
/// head's gave 0.0619).
#[test]
fn ballbeam_trains_on_all_its_data_from_a_fallback_head() {
    let Some(dir) = real_data() else { return };
    let bench = RealSeries::Ballbeam.load(&dir).expect("load ballbeam");
    let settings = FitSettings {
        ly: bench.ly,
        lu: bench.lu,
        seed: 0,
        ..FitSettings::new(Method::Msgp)
    };
    let (model, report) =
        fit(std::slice::from_ref(&bench.train), &settings, &mut |_| {}).expect("fit");
    assert_eq!(report.diverged, None);
    let m = model.evaluate(&bench.test).expect("evaluate");
    println!(
        "ballbeam: RMSE {:.4}, NLL {:.3}, 2σ coverage {:.3}, heads {:?}, kept {:?}",
        m.rmse,
        m.nll,
        m.coverage_2sigma,
        report
            .recipes
            .iter()
            .map(|r| (
                r.recipe.mean,
                r.start,
                r.validation,
                r.final_failed.is_some()
            ))
            .collect::<Vec<_>>(),
        report.full_data_iteration,
    );
    assert!(
        report.recipes[0].final_failed.is_some(),
        "the one-step start's final training blows up"
    );
    let kept = report
        .fallback()
        .expect("a fallback head's final training is kept");
    assert_eq!(kept.recipe.mean, MeanFunction::Linear);
    assert_eq!(
        kept.recipe.learning_rate,
        report.recipes[0].recipe.learning_rate
    );
    // the tail ordered the fallback heads: the spread head's final training was never tried
    let spread = report
        .recipes
        .iter()
        .find(|r| r.start == MsgpStart::Spread)
        .expect("the spread head trained");
    assert!(kept.validation < spread.validation, "{:?}", report.recipes);
    assert_eq!(spread.final_failed, None);
    assert!(report.full_data_iteration.is_some());
    assert!(
        m.rmse <= 0.0599,
        "ballbeam RMSE {} (the paper's MSGP: 0.0599)",
        m.rmse
    );
    assert!(
        m.coverage_2sigma >= 0.9,
        "2σ coverage {}",
        m.coverage_2sigma
    );
}

/// Under the filter likelihood on ballbeam (seed 1), the validation tail prefers the
/// linear-mean recipe, whose free simulation of the training inputs runs away (its band
/// passes five times the outputs' range within 140 steps; the test part's mean reached 56
/// against outputs within 0.26). That model is set aside and the zero-mean recipe's returned.
#[test]
fn ballbeam_under_the_filter_likelihood_sets_a_diverging_recipe_aside() {
    let Some(dir) = real_data() else { return };
    let bench = RealSeries::Ballbeam.load(&dir).expect("load ballbeam");
    let mut settings = FitSettings {
        ly: bench.ly,
        lu: bench.lu,
        seed: 1,
        ..FitSettings::new(Method::Msgp)
    };
    if let Some(m) = settings.msgp_mut() {
        m.likelihood = Likelihood::Filter;
    }
    let (model, report) =
        fit(std::slice::from_ref(&bench.train), &settings, &mut |_| {}).expect("fit");
    let m = model.evaluate(&bench.test).expect("evaluate");
    println!(
        "ballbeam (filter, seed 1): RMSE {:.4}, NLL {:.3}, 2σ coverage {:.3}, recipes {:?}",
        m.rmse, m.nll, m.coverage_2sigma, report.recipes
    );
    assert_eq!(report.diverged, None);
    let aside = report.set_aside().expect("a recipe was set aside");
    assert_eq!(aside.recipe.mean, MeanFunction::Linear);
    assert!(aside.diverged.is_some());
    assert_eq!(model.config.mean, MeanFunction::Zero);
    assert!(report.full_data_iteration.is_some());
    // it stays in range (0.092), though no better than the training outputs' mean (0.074):
    // the filter likelihood does not learn ballbeam's free run (the paper's MSGP: 0.0599)
    assert!(m.rmse < 0.1, "ballbeam RMSE {}", m.rmse);
}

/// On the training loss itself (no held-out tail, no early stopping), L-BFGS gets lower in 40
/// iterations than Adam does, from the same one-step start.
#[test]
fn lbfgs_lowers_the_msgp_training_loss_faster_than_adam() {
    let bench = SyntheticSystem::new(4)
        .expect("sys")
        .generate(0, NoiseScale::StdDev)
        .expect("gen");
    let last_loss = |optimizer: FitOptimizer| {
        let settings = FitSettings {
            ly: bench.ly,
            lu: bench.lu,
            method: MsgpSettings {
                inducing: 30,
                iterations: 40,
                validation_fraction: 0.0,
                optimizer,
                ..MsgpSettings::default()
            }
            .into(),
            ..FitSettings::default()
        };
        let mut losses = Vec::new();
        fit(std::slice::from_ref(&bench.train), &settings, &mut |p| {
            losses.push(p.loss)
        })
        .expect("fit");
        losses
    };
    let adam = last_loss(FitOptimizer::Adam);
    let lbfgs = last_loss(FitOptimizer::Lbfgs);
    println!(
        "loss per step: start {:.4}; after 40 iterations Adam {:.4}, L-BFGS {:.4} ({} iterations)",
        adam[0],
        adam[adam.len() - 1],
        lbfgs[lbfgs.len() - 1],
        lbfgs.len() - 1
    );
    assert_eq!(adam[0], lbfgs[0], "same start");
    // L-BFGS only accepts decreasing points
    assert!(lbfgs.windows(2).all(|w| w[1] < w[0]), "{lbfgs:?}");
    let (a, l) = (adam[adam.len() - 1], lbfgs[lbfgs.len() - 1]);
    assert!(
        adam[0] - l > 1.5 * (adam[0] - a),
        "decrease: L-BFGS {} vs Adam {}",
        adam[0] - l,
        adam[0] - a
    );
}

/// `--mean linear` on drives (`l_y = l_u = 10`, 250 training samples) does not diverge: the
/// instrumental-variables start had an unstable autoregressive part (test RMSE 1.90 before any
/// training, 2.04 after), which the fit now scales inside the unit circle.
#[test]
fn a_linear_mean_on_drives_does_not_diverge() {
    use msgp_core::fit::{FitOptions, Overrides};
    use msgp_core::gp::MeanFunction;
    let Some(dir) = real_data() else { return };
    let bench = RealSeries::Drives.load(&dir).expect("load drives");
    let settings = FitOptions {
        method: Method::Msgp,
        ly: bench.ly,
        lu: bench.lu,
        seed: 0,
        integrators: Vec::new(),
        optimizer: FitOptimizer::Adam,
        start: Default::default(),
        threads: Default::default(),
        segment_length: None,
        overrides: Overrides {
            mean: Some(MeanFunction::Linear),
            ..Overrides::default()
        },
    }
    .settings(std::slice::from_ref(&bench.train))
    .expect("settings");
    let (model, report) =
        fit(std::slice::from_ref(&bench.train), &settings, &mut |_| {}).expect("fit");
    assert_eq!(report.diverged, None);
    let m = model.evaluate(&bench.test).expect("evaluate");
    println!(
        "drives, linear mean: RMSE {:.4}, 2σ coverage {:.3}",
        m.rmse, m.coverage_2sigma
    );
    // paper MSGP 0.4217; the zero-mean recipe 0.47
    assert!(m.rmse < 0.6, "drives with a linear mean: RMSE {}", m.rmse);
}

/// The one-step baselines read as the paper ran them (appendix A.1.1, `docs/design.md`):
/// GP-NARX a sparse GP of 100 pseudo-inputs by its own likelihood (the variational bound), PILCO's
/// GP-NARX the full GP's penalised likelihood, then sparsified. On actuator the two differ by 2×,
/// and each lands within 10 % of its column of Table 1 (seed 0, moment matching; the exact fit
/// gives GP-NARX 1.45, the bound PILCO's variant ≈ 0.7).
#[test]
fn the_baselines_match_their_table_1_columns_on_actuator_and_furnace() {
    let Some(dir) = real_data() else { return };
    let actuator = RealSeries::Actuator.load(&dir).expect("load actuator");
    let narx = run(&actuator, Method::GpNarx, 0);
    assert!(
        narx.rmse <= 1.1 * 0.6376,
        "actuator GP-NARX RMSE {}",
        narx.rmse
    );
    let pilco = run(&actuator, Method::PilcoNarx, 0);
    assert!(
        (pilco.rmse / 1.3767 - 1.0).abs() <= 0.1,
        "actuator PILCO GP-NARX RMSE {}",
        pilco.rmse
    );
    // the exact fit's 1.28 is 7 % above the paper's 1.1996
    let furnace = RealSeries::Furnace.load(&dir).expect("load furnace");
    let narx = run(&furnace, Method::GpNarx, 0);
    assert!(
        narx.rmse <= 1.02 * 1.1996,
        "furnace GP-NARX RMSE {}",
        narx.rmse
    );
}
