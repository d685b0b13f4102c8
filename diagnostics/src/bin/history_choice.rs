//! The history `msgp_core::fit::history` chooses on each Table 1 benchmark (training part only), beside
//! the paper's, with the linear scores of the best few; `fit` also fits the default MSGP on the
//! whole training part with the chosen history and reports its test RMSE (and with the
//! paper's, for comparison).
//!
//! `cargo run --release -p msgp-diagnostics --bin history_choice -- [kf|msgp-judge] [narx|msgp]
//! [fit] [folds=2] [inducing=M] [only=name,...] [name=ly,lu ...]`: the judge of the search's
//! second stage (default one-step GP-NARX), `narx`/`msgp` also print each equal history's
//! validation RMSE, `fit` fits the default MSGP with the chosen (or given) history on the whole
//! training part, `folds=2` judges on the first part too (each judged candidate's score per
//! fold printed), `inducing` sets the pseudo-inputs of every fit (Table 1: 100).
use std::path::PathBuf;

use msgp_core::data::Benchmark;
use msgp_core::data::real::RealSeries;
use msgp_core::fit::{FitOptions, HistorySearch, Overrides, choose_history, fit};
use msgp_core::model::{Method, Rollout};

fn options(method: Method, ly: usize, lu: usize) -> FitOptions {
    let inducing = std::env::args().find_map(|a| a.strip_prefix("inducing=")?.parse().ok());
    FitOptions {
        overrides: Overrides {
            // (the linear-kf judge has no GP)
            inducing: inducing.filter(|_| method != Method::LinearKf),
            ..Overrides::default()
        },
        ..FitOptions::new(method, ly, lu)
    }
}

/// The validation RMSE (mean feedback and moment matching) of `method` fitted on the first
/// 80 % of the training part with history `(ly, lu)`, simulated over the last 20 % from the
/// 10 samples before it.
fn judge(b: &Benchmark, method: Method, ly: usize, lu: usize) -> (f64, f64, f64) {
    let n = b.train.len();
    let cut = (0.8 * n as f64).round() as usize;
    let fit_part = [b.train.slice(0, cut)];
    let tail = b.train.slice(cut - 10, n);
    let clock = std::time::Instant::now();
    let settings = options(method, ly, lu)
        .settings(&fit_part)
        .expect("settings");
    let (model, _) = fit(&fit_part, &settings, &mut |_| {}).expect("fit");
    let mean = model
        .evaluate_as(&tail, Rollout::MeanFeedback)
        .map_or(f64::NAN, |m| m.rmse);
    let mm = model.evaluate(&tail).map_or(f64::NAN, |m| m.rmse);
    (mean, mm, clock.elapsed().as_secs_f64())
}

fn test_rmse(b: &Benchmark, ly: usize, lu: usize) -> (f64, f64) {
    let options = options(Method::Msgp, ly, lu);
    let train = [b.train.clone()];
    let clock = std::time::Instant::now();
    let settings = options.settings(&train).expect("settings");
    let (model, _) = fit(&train, &settings, &mut |_| {}).expect("fit");
    let m = model.evaluate(&b.test).expect("evaluate");
    (m.rmse, clock.elapsed().as_secs_f64())
}

fn main() {
    let args: Vec<String> = std::env::args().skip(1).collect();
    let do_fit = args.iter().any(|a| a == "fit");
    let judge_with: Option<Method> = args.iter().find_map(|a| match a.as_str() {
        "narx" => Some(Method::GpNarx),
        "msgp" => Some(Method::Msgp),
        _ => None,
    });
    let only: Option<Vec<String>> = args
        .iter()
        .find_map(|a| a.strip_prefix("only="))
        .map(|s| s.split(',').map(str::to_string).collect());
    let dir = PathBuf::from(
        std::env::var("MSGP_DATA_DIR").unwrap_or_else(|_| "../shared/data/real".into()),
    );
    let mut benches: Vec<(String, Benchmark)> = RealSeries::ALL
        .iter()
        .map(|s| (s.name().to_string(), s.load(&dir).expect("series")))
        .collect();
    for k in 1..=5u8 {
        let b = msgp_core::data::synthetic::SyntheticSystem::new(k)
            .expect("system")
            .generate(0, Default::default())
            .expect("data");
        benches.push((format!("synthetic{k}"), b));
    }
    for (name, b) in benches {
        if only.as_ref().is_some_and(|o| !o.contains(&name)) {
            continue;
        }
        let clock = std::time::Instant::now();
        let judge_method = if args.iter().any(|a| a == "kf") {
            Method::LinearKf
        } else if args.iter().any(|a| a == "msgp-judge") {
            Method::Msgp
        } else {
            Method::GpNarx
        };
        let folds = args
            .iter()
            .find_map(|a| a.strip_prefix("folds=")?.parse().ok())
            .unwrap_or(1);
        let choice = choose_history(
            std::slice::from_ref(&b.train),
            &HistorySearch {
                folds,
                ..HistorySearch::default()
            },
            &options(judge_method, 1, 1),
        )
        .expect("choice");
        let secs = clock.elapsed().as_secs_f64();
        let best: Vec<String> = choice
            .judged
            .iter()
            .take(5)
            .map(|s| format!("({},{}) {:.4}", s.ly, s.lu, s.score))
            .collect();
        let paper = choice
            .linear
            .iter()
            .find(|s| s.ly == b.ly && s.lu == b.lu)
            .map_or(f64::NAN, |s| s.score);
        println!(
            "{name}: chose ({}, {}) in {secs:.2} s; paper ({}, {}) scores {paper:.4} (linear); judged: {}",
            choice.ly,
            choice.lu,
            b.ly,
            b.lu,
            best.join(", ")
        );
        for s in choice.judged.iter().filter(|s| s.by_fold.is_some()) {
            let f = s.by_fold.expect("two folds");
            println!(
                "  ({},{}) pooled {:.4}: last part {:.4}, first part {:.4}",
                s.ly, s.lu, s.score, f.last, f.first
            );
        }
        if let Some(method) = judge_with {
            let mut cands: Vec<(usize, usize)> =
                [1, 2, 3, 5, 7, 10].iter().map(|&l| (l, l)).collect();
            cands.push((choice.ly, choice.lu));
            for (ly, lu) in cands {
                let (mean, mm, s) = judge(&b, method, ly, lu);
                println!("  ({ly},{lu}) validation RMSE mean {mean:.4} mm {mm:.4} ({s:.1} s)");
            }
        }
        let forced: Option<(usize, usize)> = args.iter().find_map(|a| {
            let v = a.strip_prefix(&format!("{name}="))?;
            let (l, u) = v.split_once(',')?;
            Some((l.parse().ok()?, u.parse().ok()?))
        });
        if do_fit {
            let (ly, lu) = forced.unwrap_or((choice.ly, choice.lu));
            let (r, s) = test_rmse(&b, ly, lu);
            println!("  MSGP test RMSE with ({ly}, {lu}) {r:.4} ({s:.0} s)");
        }
    }
}
