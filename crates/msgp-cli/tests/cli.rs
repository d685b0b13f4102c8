//! End-to-end tests of the `msgp` binary in a temporary folder: fit → save → eval → simulate
//! round trips, JSON output, CSV episodes, MCAP logs, and every bad-input case.

use std::path::PathBuf;
use std::process::{Command, Output, Stdio};

use serde_json::Value;

const BIN: &str = env!("CARGO_BIN_EXE_msgp");

/// A scratch folder removed on drop.
struct Scratch(PathBuf);

impl Scratch {
    fn new(tag: &str) -> Self {
        let dir = std::env::temp_dir().join(format!("msgp-cli-{tag}-{}", std::process::id()));
        let _ = std::fs::remove_dir_all(&dir);
        std::fs::create_dir_all(&dir).expect("create scratch folder");
        Self(dir)
    }

    fn path(&self, name: &str) -> PathBuf {
        self.0.join(name)
    }

    fn write(&self, name: &str, text: &str) -> PathBuf {
        let p = self.path(name);
        std::fs::write(&p, text).expect("write test file");
        p
    }
}

impl Drop for Scratch {
    fn drop(&mut self) {
        let _ = std::fs::remove_dir_all(&self.0);
    }
}

fn run(dir: &Scratch, args: &[&str]) -> Output {
    Command::new(BIN)
        .args(args)
        .current_dir(&dir.0)
        .output()
        .expect("run msgp")
}

fn stdout(o: &Output) -> String {
    String::from_utf8_lossy(&o.stdout).into_owned()
}

fn stderr(o: &Output) -> String {
    String::from_utf8_lossy(&o.stderr).into_owned()
}

/// Runs and expects success.
fn ok(dir: &Scratch, args: &[&str]) -> String {
    let o = run(dir, args);
    assert!(
        o.status.success(),
        "msgp {args:?} failed:\n{}\n{}",
        stdout(&o),
        stderr(&o)
    );
    stdout(&o)
}

/// Runs with `--json` and parses the one line of output.
fn ok_json(dir: &Scratch, args: &[&str]) -> Value {
    let text = ok(dir, args);
    assert_eq!(text.lines().count(), 1, "one JSON line expected: {text}");
    serde_json::from_str(&text).expect("stdout is JSON")
}

/// Runs, expects failure, and returns stderr, which must contain each of `needles`.
fn fails(dir: &Scratch, args: &[&str], needles: &[&str]) -> String {
    let o = run(dir, args);
    let err = stderr(&o);
    assert!(
        !o.status.success(),
        "msgp {args:?} should fail:\n{}",
        stdout(&o)
    );
    assert!(!err.contains("panicked"), "panic for {args:?}: {err}");
    // warnings about the data may come first; then the error
    let mut lines = err.lines().skip_while(|l| l.starts_with("warning: "));
    assert!(
        lines.next().is_some_and(|l| l.starts_with("error: ")),
        "{err}"
    );
    for n in needles {
        assert!(err.contains(n), "msgp {args:?}: `{n}` not in:\n{err}");
    }
    err
}

/// The (width, height) of the PNG at `path`, from its header (a failure where it is not one).
fn png_size(path: &std::path::Path) -> (u32, u32) {
    let bytes = std::fs::read(path).expect("the plot");
    assert_eq!(&bytes[..8], b"\x89PNG\r\n\x1a\n", "{}", path.display());
    let be = |i: usize| u32::from_be_bytes([bytes[i], bytes[i + 1], bytes[i + 2], bytes[i + 3]]);
    // (the IHDR chunk comes first: its width, then its height)
    (be(16), be(20))
}

/// A deterministic nonlinear SISO system with a little pseudo-random noise, as `t,u,y`.
fn system_csv(n: usize, episode: Option<usize>) -> String {
    let mut s = String::from(if episode.is_some() {
        "t,u,y,episode\n"
    } else {
        "t,u,y\n"
    });
    let (mut y1, mut u1) = (0.0f64, 0.0f64);
    for t in 0..n {
        let tf = t as f64;
        let u = (0.3 * tf).sin() + 0.5 * (0.11 * tf).sin();
        let noise = 0.02 * ((tf * 12.9898).sin() * 43_758.545).fract();
        let y = 0.6 * y1 + (1.5 * u1).sin() + noise;
        match episode {
            Some(len) => s.push_str(&format!("{t},{u},{y},{}\n", t / len)),
            None => s.push_str(&format!("{t},{u},{y}\n")),
        }
        (y1, u1) = (y, u);
    }
    s
}

const FAST: [&str; 5] = ["--iters", "5", "--inducing", "10", "--quiet"];

fn args<'a>(base: &[&'a str], extra: &[&'a str]) -> Vec<&'a str> {
    base.iter().chain(extra).copied().collect()
}

#[test]
fn fit_save_eval_simulate_round_trip_is_exact() {
    let dir = Scratch::new("roundtrip");
    dir.write("d.csv", &system_csv(160, None));
    let fit = ok_json(
        &dir,
        &args(
            &[
                "fit", "--data", "d.csv", "--out", "m.json", "--plot", "fit.png", "--json",
            ],
            &FAST,
        ),
    );
    for key in [
        "method",
        "rmse",
        "nll",
        "coverage_2sigma",
        "train_seconds",
        "n_train",
        "n_test",
        "history",
        "inducing",
        "seed",
    ] {
        assert!(fit.get(key).is_some(), "fit JSON lacks `{key}`: {fit}");
    }
    assert_eq!(fit["method"], "msgp");
    assert_eq!(fit["n_train"], 80);
    assert_eq!(fit["n_test"], 80);
    assert_eq!(fit["history"], serde_json::json!([2, 2]));
    assert_eq!(fit["inducing"], 10);
    assert_eq!(fit["inputs"], serde_json::json!(["u"]));
    assert_eq!(fit["outputs"], serde_json::json!(["y"]));
    // the recipes the validation tail chose between, each with its start and validation NLL
    let recipes = fit["recipes"]
        .as_array()
        .expect("fit JSON lists the recipes");
    assert_eq!(recipes.len(), 2, "{fit}");
    let means: Vec<&str> = recipes
        .iter()
        .map(|r| r["recipe"]["mean"].as_str().expect("a recipe's mean"))
        .collect();
    assert_eq!(means, ["zero", "linear"]);
    for r in recipes {
        assert_eq!(r["start"], "one-step", "{r}");
        assert!(r["validation"].as_f64().is_some_and(f64::is_finite), "{r}");
    }
    let chosen = fit["chosen_recipe"].as_u64().expect("chosen_recipe") as usize;
    let best = recipes
        .iter()
        .enumerate()
        .min_by(|a, b| {
            let v = |r: &Value| r["validation"].as_f64().unwrap_or(f64::INFINITY);
            v(a.1).total_cmp(&v(b.1))
        })
        .map(|(k, _)| k);
    assert_eq!(
        Some(chosen),
        best,
        "the lower validation NLL is chosen: {fit}"
    );
    // the model file's training record keeps them (format 1.4)
    let file: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path("m.json")).expect("model file"))
            .expect("model JSON");
    let record = &file["training"];
    assert_eq!(record["recipes"], fit["recipes"]);
    assert_eq!(record["chosen_recipe"], fit["chosen_recipe"]);
    assert_eq!(record["full_data_iteration"], fit["full_data_iteration"]);
    assert!(record["full_data_iteration"].as_u64().is_some(), "{record}");
    let png = std::fs::read(dir.path("fit.png")).expect("plot written");
    assert!(png.starts_with(b"\x89PNG"), "not a PNG");

    let eval = ok_json(
        &dir,
        &[
            "eval", "--model", "m.json", "--data", "d.csv", "--from", "80", "--json",
        ],
    );
    for key in ["rmse", "nll", "coverage_2sigma", "test_steps"] {
        assert_eq!(eval[key], fit[key], "`{key}` differs between fit and eval");
    }
    assert!(eval["rmse"].as_f64().expect("rmse") > 0.0);

    let sim = ok_json(
        &dir,
        &[
            "simulate", "--model", "m.json", "--data", "d.csv", "--from", "80", "--out", "p.csv",
            "--json",
        ],
    );
    assert_eq!(sim["rmse"], fit["rmse"]);
    assert_eq!(sim["rows"], 78);
    let pred = std::fs::read_to_string(dir.path("p.csv")).expect("predictions");
    let mut lines = pred.lines();
    assert_eq!(lines.next(), Some("t,y_mean,y_std,y"));
    let mut se = 0.0;
    let mut n = 0usize;
    let mut first_t = None;
    for line in lines {
        let v: Vec<f64> = line
            .split(',')
            .map(|c| c.parse().expect("number"))
            .collect();
        assert!(v[2] > 0.0, "std must be positive");
        first_t.get_or_insert(v[0]);
        se += (v[3] - v[1]).powi(2);
        n += 1;
    }
    assert_eq!(n, 78);
    assert_eq!(
        first_t,
        Some(82.0),
        "first simulated step is from + max(l_y, l_u)"
    );
    let rmse = (se / n as f64).sqrt();
    let want = eval["rmse"].as_f64().expect("rmse");
    assert!((rmse - want).abs() <= 1e-12 * want, "{rmse} vs {want}");

    // a second eval of the same file gives the same text, and text output mentions the model
    let text = ok(
        &dir,
        &[
            "eval", "--model", "m.json", "--data", "d.csv", "--from", "80",
        ],
    );
    assert!(text.contains("RMSE"), "{text}");
    assert_eq!(
        text,
        ok(
            &dir,
            &[
                "eval", "--model", "m.json", "--data", "d.csv", "--from", "80"
            ]
        )
    );
}

#[test]
fn baselines_text_output_and_default_model_path() {
    let dir = Scratch::new("baselines");
    dir.write("dryer.csv", &system_csv(120, None));
    let text = ok(
        &dir,
        &[
            "fit",
            "--data",
            "dryer.csv",
            "--method",
            "gp-narx",
            "--iters",
            "20",
            "--quiet",
        ],
    );
    assert!(text.contains("model written to dryer.model.json"), "{text}");
    assert!(text.contains("RMSE"), "{text}");
    assert!(dir.path("dryer.model.json").exists());
    let v = ok_json(
        &dir,
        &[
            "fit",
            "--data",
            "dryer.csv",
            "--method",
            "pilco-narx",
            "--iters",
            "20",
            "--train",
            "70",
            "--history",
            "1,1",
            "--json",
            "--out",
            "p.json",
        ],
    );
    assert_eq!(v["method"], "pilco-narx");
    assert_eq!(v["n_train"], 70);
    assert_eq!(v["history"], serde_json::json!([1, 1]));
    let model: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path("p.json")).expect("model file"))
            .expect("model JSON");
    assert_eq!(model["format"], "msgp-model");
    assert_eq!(model["format_version"], "1.4");
    assert_eq!(model["method"], "pilco-narx");
    // a one-step fit has no recipes: its training record is written as before format 1.4
    for key in [
        "recipes",
        "chosen_recipe",
        "full_data_iteration",
        "full_data_failed",
    ] {
        assert!(model["training"].get(key).is_none(), "{key}: {model}");
    }
}

#[test]
fn eval_and_simulate_offer_the_mean_feedback_rollout() {
    let dir = Scratch::new("rollout");
    dir.write("s.csv", &system_csv(160, None));
    let v = ok_json(
        &dir,
        &[
            "fit", "--data", "s.csv", "--method", "gp-narx", "--iters", "20", "--train", "80",
            "--json", "--out", "m.json",
        ],
    );
    assert_eq!(v["diverged"], false, "{v}");
    assert_eq!(v["divergence"], Value::Null);
    let model: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path("m.json")).expect("model file"))
            .expect("model JSON");
    assert_eq!(model["training"]["diverged"], Value::Null);
    let base = [
        "eval", "--model", "m.json", "--data", "s.csv", "--from", "80", "--json",
    ];
    let mm = ok_json(&dir, &base);
    assert_eq!(mm["rollout"], "mm");
    assert_eq!(
        mm["rmse"], v["rmse"],
        "the default is the fit's moment matching"
    );
    let mean = ok_json(&dir, &args(&base, &["--rollout", "mean"]));
    assert_eq!(mean["rollout"], "mean");
    let (a, b) = (
        mm["rmse"].as_f64().expect("rmse"),
        mean["rmse"].as_f64().expect("rmse"),
    );
    assert!(
        a.is_finite() && b.is_finite() && a != b,
        "MM {a}, mean feedback {b}"
    );
    let text = ok(
        &dir,
        &[
            "simulate",
            "--model",
            "m.json",
            "--data",
            "s.csv",
            "--from",
            "80",
            "--rollout",
            "mean",
            "--out",
            "p.csv",
        ],
    );
    assert!(text.contains("(mean feedback)"), "{text}");
    let csv = std::fs::read_to_string(dir.path("p.csv")).expect("prediction CSV");
    assert!(csv.lines().count() > 70, "{csv}");
    fails(
        &dir,
        &[
            "eval",
            "--model",
            "m.json",
            "--data",
            "s.csv",
            "--rollout",
            "exact",
        ],
        &["--rollout"],
    );
    // one-step-ahead filtered predictions beside the free simulation: they have seen every
    // measured output before their step, so they are closer than the free run
    let both = ok_json(&dir, &args(&base, &["--filtered"]));
    assert_eq!(both["rmse"], mm["rmse"], "the free simulation is unchanged");
    let f = &both["filtered"];
    let (free, one_step) = (
        mm["rmse"].as_f64().expect("rmse"),
        f["rmse"].as_f64().expect("filtered rmse"),
    );
    assert!(one_step < free, "filtered {one_step} vs free {free}");
    assert_eq!(f["test_steps"], mm["test_steps"]);
    let c = f["coverage_2sigma"].as_f64().expect("coverage");
    assert!((0.8..=1.0).contains(&c), "{f}");
    let text = ok(
        &dir,
        &[
            "eval",
            "--model",
            "m.json",
            "--data",
            "s.csv",
            "--from",
            "80",
            "--filtered",
        ],
    );
    assert!(text.contains("one-step-ahead filtered ("), "{text}");
    ok(
        &dir,
        &[
            "simulate",
            "--model",
            "m.json",
            "--data",
            "s.csv",
            "--from",
            "80",
            "--filtered",
            "--out",
            "f.csv",
        ],
    );
    let csv = std::fs::read_to_string(dir.path("f.csv")).expect("prediction CSV");
    let header: Vec<&str> = csv.lines().next().expect("header").split(',').collect();
    assert_eq!(
        header,
        [
            "t",
            "y_mean",
            "y_std",
            "y",
            "y_filtered_mean",
            "y_filtered_std"
        ],
        "{csv}"
    );
    // the filtered mean's error is the smaller one on this file too
    let (mut se_free, mut se_filtered) = (0.0, 0.0);
    for line in csv.lines().skip(1) {
        let v: Vec<f64> = line
            .split(',')
            .map(|x| x.parse().expect("number"))
            .collect();
        se_free += (v[1] - v[3]).powi(2);
        se_filtered += (v[4] - v[3]).powi(2);
    }
    assert!(se_filtered < se_free, "{se_filtered} vs {se_free}");
}

#[test]
fn linear_prior_mean_is_fitted_saved_and_used() {
    let dir = Scratch::new("linear-mean");
    dir.write("s.csv", &system_csv(160, None));
    let v = ok_json(
        &dir,
        &args(
            &[
                "fit", "--data", "s.csv", "--mean", "linear", "--json", "--out", "m.json",
            ],
            &FAST,
        ),
    );
    let model: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path("m.json")).expect("model file"))
            .expect("model JSON");
    let a = model["gp"]["linear_mean"]
        .as_array()
        .expect("gp.linear_mean");
    assert_eq!(a.len(), 1);
    assert!(
        a[0].as_array()
            .expect("row")
            .iter()
            .all(|x| x.as_f64() != Some(0.0))
    );
    // eval of the saved model gives the numbers the fit reported
    let e = ok_json(
        &dir,
        &[
            "eval", "--model", "m.json", "--data", "s.csv", "--from", "80", "--json",
        ],
    );
    for key in ["rmse", "nll"] {
        assert_eq!(e[key], v[key], "`{key}` differs between fit and eval");
    }
    assert_eq!(e["diverged"], false, "{e}");
    assert_eq!(e["divergence"], Value::Null);
    // the same model with its output lags' coefficients replaced by a pole at 1.1 runs away on
    // the evaluated data: eval and simulate say so (stderr, text, JSON) and still report what
    // they computed
    let mut unstable = model.clone();
    unstable["gp"]["linear_mean"][0][0] = serde_json::json!(1.1);
    unstable["gp"]["linear_mean"][0][1] = serde_json::json!(0.0);
    dir.write("u.json", &unstable.to_string());
    let eval = [
        "eval", "--model", "u.json", "--data", "s.csv", "--from", "80",
    ];
    let o = run(&dir, &args(&eval, &["--json"]));
    assert!(o.status.success(), "{}", stderr(&o));
    let e: Value = serde_json::from_str(&stdout(&o)).expect("stdout is JSON");
    assert_eq!(e["diverged"], true, "{e}");
    // by default the band of the drawn functions explodes first (the pole is as uncertain as
    // the data leave it); the paper's moment matching runs away in the mean
    let why = e["divergence"].as_str().expect("why");
    assert!(
        why.contains("s.csv from sample 80") && why.contains("predicted standard deviation"),
        "{why}"
    );
    let paper = ok_json(
        &dir,
        &args(&eval, &["--json", "--rollout", "mm-independent"]),
    );
    let why = paper["divergence"].as_str().expect("why");
    assert!(
        why.contains("s.csv from sample 80") && why.contains("leaves the measured outputs' range"),
        "{why}"
    );
    assert!(
        stderr(&o).contains("warning: the model diverges on this data"),
        "{}",
        stderr(&o)
    );
    assert!(ok(&dir, &eval).contains("WARNING: the model diverges on this data"));
    let text = ok(
        &dir,
        &[
            "simulate", "--model", "u.json", "--data", "s.csv", "--out", "p.csv",
        ],
    );
    assert!(text.contains("WARNING: the model diverges"), "{text}");
    fails(
        &dir,
        &["fit", "--data", "s.csv", "--mean", "quadratic"],
        &["--mean"],
    );
}

#[test]
fn the_msgp_loss_can_be_minimised_by_lbfgs() {
    let dir = Scratch::new("lbfgs");
    dir.write("s.csv", &system_csv(160, None));
    let fit = |optimizer: &str, out: &str| {
        ok_json(
            &dir,
            &[
                "fit",
                "--data",
                "s.csv",
                "--optimizer",
                optimizer,
                "--iters",
                "15",
                "--inducing",
                "10",
                "--quiet",
                "--json",
                "--out",
                out,
            ],
        )
    };
    let lbfgs = fit("lbfgs", "l.json");
    let adam = fit("adam", "a.json");
    let settings = |name: &str| {
        let model: Value =
            serde_json::from_str(&std::fs::read_to_string(dir.path(name)).expect("model file"))
                .expect("model JSON");
        model["training"]["settings"].clone()
    };
    assert_eq!(settings("l.json")["optimizer"], "lbfgs");
    assert_eq!(settings("a.json")["optimizer"], "adam");
    // the same start, two solvers: different models
    assert_ne!(lbfgs["rmse"], adam["rmse"]);
    // the saved L-BFGS model evaluates to the numbers its fit reported
    let e = ok_json(
        &dir,
        &[
            "eval", "--model", "l.json", "--data", "s.csv", "--from", "80", "--json",
        ],
    );
    assert_eq!(e["rmse"], lbfgs["rmse"]);
    let text = ok(
        &dir,
        &[
            "fit",
            "--data",
            "s.csv",
            "--optimizer",
            "lbfgs",
            "--iters",
            "5",
            "--inducing",
            "10",
            "--quiet",
            "--out",
            "t.json",
        ],
    );
    assert!(text.contains("L-BFGS iterations, kept iteration"), "{text}");
    fails(
        &dir,
        &["fit", "--data", "s.csv", "--optimizer", "newton"],
        &["--optimizer"],
    );
}

#[test]
fn an_integrating_output_is_declared_on_the_command_line() {
    let dir = Scratch::new("integrating");
    dir.write("s.csv", &system_csv(160, None));
    let declare = [
        "fit",
        "--data",
        "s.csv",
        "--mean",
        "linear",
        "--integrating",
    ];
    // fits with `--integrating declared` and returns the saved model file
    let fit_declared = |declared: &str| -> Value {
        let cmd = [&declare[..], &[declared, "--json", "--out", "m.json"]].concat();
        ok_json(&dir, &args(&cmd, &FAST));
        let text = std::fs::read_to_string(dir.path("m.json")).expect("model file");
        serde_json::from_str(&text).expect("model JSON")
    };
    let model = fit_declared("0:1");
    // history 2,2: the window is [y_t, y_{t−1}, u_t, u_{t−1}]; order 1 fixes [1, 0] on y
    let row = model["gp"]["linear_mean"][0]
        .as_array()
        .expect("row")
        .clone();
    assert_eq!(row[0].as_f64(), Some(1.0), "{row:?}");
    assert_eq!(row[1].as_f64(), Some(0.0), "{row:?}");
    assert_eq!(
        model["training"]["settings"]["integrators"],
        serde_json::json!([{"output": 0, "order": 1, "linear": false}])
    );
    // `:linear` drops the output's GP: its pseudo-targets are zero
    let model = fit_declared("0:1:linear");
    assert_eq!(
        model["training"]["settings"]["integrators"][0]["linear"],
        serde_json::json!(true)
    );
    let targets = model["gp"]["pseudo_targets"]
        .as_array()
        .expect("pseudo_targets");
    assert!(!targets.is_empty());
    assert!(
        targets
            .iter()
            .flat_map(|r| r.as_array().expect("row").iter())
            .all(|v| v.as_f64() == Some(0.0)),
        "{targets:?}"
    );
    fails(
        &dir,
        &["fit", "--data", "s.csv", "--integrating", "0:1"],
        &["integrators", "linear mean"],
    );
    for (declared, needle) in [("1:1", "output 1 does not exist"), ("0", "OUTPUT:ORDER")] {
        fails(&dir, &[&declare[..], &[declared]].concat(), &[needle]);
    }
}

#[test]
fn episodes_and_several_files_are_several_trajectories() {
    let dir = Scratch::new("episodes");
    dir.write("e.csv", &system_csv(200, Some(100)));
    let v = ok_json(
        &dir,
        &args(
            &["fit", "--data", "e.csv", "--json", "--out", "m.json"],
            &FAST,
        ),
    );
    assert_eq!(v["trajectories"], 2);
    assert_eq!(v["n_train"], 100);
    ok(
        &dir,
        &[
            "simulate", "--model", "m.json", "--data", "e.csv", "--out", "p.csv",
        ],
    );
    let pred = std::fs::read_to_string(dir.path("p.csv")).expect("predictions");
    assert!(pred.starts_with("episode,t,y_mean,y_std,y\n"), "{pred}");
    assert!(pred.contains("\n1,"), "second episode present");
    dir.write("a.csv", &system_csv(100, None));
    dir.write("b.csv", &system_csv(90, None));
    let v = ok_json(
        &dir,
        &args(
            &["fit", "--data", "a.csv", "--data", "b.csv", "--json"],
            &FAST,
        ),
    );
    assert_eq!(v["trajectories"], 2);
    assert_eq!(v["n_train"], 95);
}

/// A pendulum log from the simulator (hanging pole: it never hits the stop limits).
fn pendulum_log(dir: &Scratch, name: &str) {
    ok(
        dir,
        &[
            "sim",
            "pendulum",
            "--random",
            "--gravity=-9.81",
            "--seconds",
            "3",
            "--out",
            name,
        ],
    );
}

#[test]
fn mcap_logs_from_the_simulator() {
    let dir = Scratch::new("mcap");
    pendulum_log(&dir, "run.mcap");
    let v = ok_json(
        &dir,
        &args(
            &["fit", "--data", "run.mcap", "--json", "--out", "m.json"],
            &FAST,
        ),
    );
    assert_eq!(
        v["inputs"],
        serde_json::json!(["/pendulum/command:acceleration"])
    );
    assert_eq!(
        v["outputs"],
        serde_json::json!(["/pendulum/measurement:theta", "/pendulum/measurement:x"])
    );
    let n_train = v["n_train"].as_u64().expect("n_train");
    assert!(
        (70..=80).contains(&n_train),
        "3 s at 50 Hz, half trains: {n_train}"
    );
    let e = ok_json(
        &dir,
        &["eval", "--model", "m.json", "--data", "run.mcap", "--json"],
    );
    assert!(e["rmse"].as_f64().expect("rmse").is_finite());
    // explicit signals with a default topic
    let v = ok_json(
        &dir,
        &args(
            &[
                "fit",
                "--data",
                "run.mcap",
                "--topic",
                "/pendulum/measurement",
                "--input",
                "/pendulum/command:acceleration",
                "--output",
                "theta",
                "--json",
            ],
            &FAST,
        ),
    );
    assert_eq!(
        v["outputs"],
        serde_json::json!(["/pendulum/measurement:theta"])
    );
    ok(
        &dir,
        &[
            "simulate", "--model", "m.json", "--data", "run.mcap", "--out", "p.csv",
        ],
    );
    let pred = std::fs::read_to_string(dir.path("p.csv")).expect("predictions");
    assert!(
        pred.starts_with("t,/pendulum/measurement:theta_mean,"),
        "{pred}"
    );
    // the CSV log of the same simulator works with the same defaults
    pendulum_log(&dir, "run.csv");
    let v = ok_json(&dir, &args(&["fit", "--data", "run.csv", "--json"], &FAST));
    assert_eq!(v["inputs"], serde_json::json!(["command"]));
    assert_eq!(v["outputs"], serde_json::json!(["meas_theta", "meas_x"]));
}

#[test]
fn bad_inputs_fail_with_clear_messages() {
    let dir = Scratch::new("bad");
    dir.write("d.csv", &system_csv(120, None));
    let fit = |extra: &[&str], needles: &[&str]| {
        let mut a = vec!["fit"];
        a.extend_from_slice(extra);
        a.extend_from_slice(&FAST);
        fails(&dir, &a, needles)
    };
    fit(
        &["--data", "d.csv", "--output", "nope"],
        &["no column `nope`", "columns: t, u, y"],
    );
    dir.write("text.csv", "t,u,y\n0,1,2\n1,abc,3\n");
    fit(
        &["--data", "text.csv"],
        &["text.csv:3:2:", "`abc` in column `u` is not a number"],
    );
    // a file without a header line: its first sample is not taken for column names
    let headless: String = system_csv(120, None)
        .lines()
        .skip(1)
        .map(|l| l.to_string() + "\n")
        .collect();
    dir.write("headless.csv", &headless);
    fit(
        &["--data", "headless.csv"],
        &[
            "headless.csv:1:1:",
            "is all numbers, not a header",
            "`t,u,y`",
        ],
    );
    dir.write("nan.csv", "t,u,y\n0,1,2\n1,2,NaN\n");
    fit(
        &["--data", "nan.csv"],
        &["nan.csv:3:3:", "non-finite value `NaN`"],
    );
    // a time column that goes back (or repeats) within a trajectory
    let backwards = system_csv(120, None).replacen("\n2,", "\n0.5,", 1);
    dir.write("back.csv", &backwards);
    fit(
        &["--data", "back.csv"],
        &[
            "back.csv:4:1:",
            "time `t` = 0.5 does not increase",
            "--sort-time",
        ],
    );
    // --sort-time sorts such rows, says so, and fits what the ordered file fits
    let ordered_csv = system_csv(120, None);
    let mut rows: Vec<&str> = ordered_csv.lines().collect();
    rows.swap(3, 7);
    rows.swap(50, 51);
    dir.write("shuffled.csv", &(rows.join("\n") + "\n"));
    let sorted = run(
        &dir,
        &args(
            &["fit", "--data", "shuffled.csv", "--sort-time", "--json"],
            &FAST,
        ),
    );
    assert!(
        sorted.status.success(),
        "{}",
        String::from_utf8_lossy(&sorted.stderr)
    );
    assert!(
        String::from_utf8_lossy(&sorted.stderr).contains(
            "warning: shuffled.csv: sorted the rows by `t` within each trajectory: 4 of 120 rows moved"
        ),
        "{}",
        String::from_utf8_lossy(&sorted.stderr)
    );
    let sorted: serde_json::Value = serde_json::from_slice(&sorted.stdout).expect("json");
    let ordered = ok_json(&dir, &args(&["fit", "--data", "d.csv", "--json"], &FAST));
    assert_eq!(sorted["data_hash"], ordered["data_hash"]);
    assert_eq!(sorted["rmse"], ordered["rmse"]);
    // a time that repeats stays an error
    dir.write(
        "repeat.csv",
        &system_csv(120, None).replacen("\n2,", "\n1,", 1),
    );
    fit(
        &["--data", "repeat.csv", "--sort-time"],
        &["repeat.csv:", "time `t` = 1 does not increase"],
    );
    dir.write("inf.csv", "t,u,y\n0,1,2\n1,-inf,1\n");
    fit(
        &["--data", "inf.csv"],
        &["inf.csv:3:2:", "non-finite value `-inf`"],
    );
    dir.write("short.csv", &system_csv(4, None));
    fit(
        &["--data", "short.csv"],
        &["short.csv", "2 samples", "history needs more than 2"],
    );
    dir.write("few.csv", &system_csv(6, None));
    fit(&["--data", "few.csv"], &["few.csv", "too few"]);
    dir.write("empty.csv", "");
    fit(&["--data", "empty.csv"], &["empty.csv", "empty file"]);
    dir.write("header.csv", "t,u,y\n");
    fit(&["--data", "header.csv"], &["header.csv", "no data rows"]);
    dir.write("ragged.csv", "t,u,y\n0,1,2\n1,2\n");
    fit(
        &["--data", "ragged.csv"],
        &["ragged.csv:3:", "2 fields, the header has 3"],
    );
    fit(&["--data", "missing.csv"], &["missing.csv"]);
    fit(
        &["--data", "d.csv", "--train-frac", "1.5"],
        &["--train-frac must be in (0, 1]"],
    );
    fit(
        &["--data", "d.csv", "--input", "y", "--output", "y"],
        &["`y` is both an input and an output"],
    );

    pendulum_log(&dir, "run.mcap");
    let bytes = std::fs::read(dir.path("run.mcap")).expect("log");
    std::fs::write(dir.path("cut.mcap"), &bytes[..bytes.len() * 2 / 3]).expect("write");
    fit(
        &["--data", "cut.mcap"],
        &["cut.mcap", "corrupt or truncated MCAP"],
    );
    std::fs::write(dir.path("fake.mcap"), b"t,u,y\n1,2,3\n").expect("write");
    fit(&["--data", "fake.mcap"], &["fake.mcap", "not an MCAP file"]);
    fit(
        &[
            "--data",
            "run.mcap",
            "--input",
            "/nope:x",
            "--output",
            "/pendulum/measurement:x",
        ],
        &["run.mcap", "no topic `/nope`", "/pendulum/measurement"],
    );
    fit(
        &[
            "--data",
            "run.mcap",
            "--input",
            "/pendulum/command:acceleration",
            "--output",
            "/pendulum/measurement:nope",
        ],
        &[
            "run.mcap",
            "no field `nope`",
            "numeric fields: step, t, theta, x",
        ],
    );
    fit(
        &[
            "--data",
            "run.mcap",
            "--input",
            "acceleration",
            "--output",
            "theta",
        ],
        &["names no topic"],
    );

    // model files: another major version, wrong shapes, not a model
    ok(
        &dir,
        &args(&["fit", "--data", "d.csv", "--out", "m.json"], &FAST),
    );
    let text = std::fs::read_to_string(dir.path("m.json")).expect("model");
    let mut v: Value = serde_json::from_str(&text).expect("json");
    v["format_version"] = Value::from("2.0");
    dir.write("v2.json", &v.to_string());
    let eval = |model: &str, needles: &[&str]| {
        fails(
            &dir,
            &["eval", "--model", model, "--data", "d.csv"],
            needles,
        )
    };
    eval(
        "v2.json",
        &["v2.json", "format version 2.0 is not supported", "1.x"],
    );
    let mut v: Value = serde_json::from_str(&text).expect("json");
    v["gp"]["log_lengthscales"][0] = serde_json::json!([0.0]);
    dir.write("shape.json", &v.to_string());
    eval(
        "shape.json",
        &["shape.json", "invalid model file", "`gp.log_lengthscales`"],
    );
    eval("d.csv", &["d.csv", "not valid JSON"]);
    eval("nothing.json", &["nothing.json", "cannot read"]);
    fails(
        &dir,
        &[
            "eval", "--model", "m.json", "--data", "d.csv", "--output", "a,b",
        ],
        &["the model has 1 output(s) (y); --output names 2"],
    );
    fails(
        &dir,
        &[
            "eval", "--model", "m.json", "--data", "d.csv", "--from", "500",
        ],
        &["--from 500 is past its 120 samples"],
    );
    fails(
        &dir,
        &["eval", "--model", "m.json", "--data", "run.mcap"],
        &["run.mcap", "names no topic"],
    );
}

#[test]
fn closed_stdout_is_not_a_panic() {
    let dir = Scratch::new("pipe");
    dir.write("d.csv", &system_csv(120, None));
    ok(
        &dir,
        &args(&["fit", "--data", "d.csv", "--out", "m.json"], &FAST),
    );
    for extra in [&[][..], &["--json"][..]] {
        let mut child = Command::new(BIN)
            .args(["eval", "--model", "m.json", "--data", "d.csv"])
            .args(extra)
            .current_dir(&dir.0)
            .stdout(Stdio::piped())
            .stderr(Stdio::piped())
            .spawn()
            .expect("spawn");
        drop(child.stdout.take()); // the reader goes away before anything is printed
        let o = child.wait_with_output().expect("wait");
        let err = stderr(&o);
        assert!(!err.contains("panicked"), "{err}");
        assert!(o.status.success(), "{err}");
    }
}

#[test]
fn help_lists_the_commands() {
    let dir = Scratch::new("help");
    let text = ok(&dir, &["--help"]);
    for cmd in ["fit", "eval", "simulate", "reproduce", "demo", "sim"] {
        assert!(text.contains(cmd), "{cmd} missing from --help");
    }
    let text = ok(&dir, &["fit", "--help"]);
    assert!(text.contains("--train-frac"), "{text}");
}

/// `--saturation` chooses how the gains' command is limited: the stability report records it,
/// the episodes change with it, and `--random` (no gains) refuses it.
#[test]
fn the_simulator_takes_the_command_saturation() {
    let dir = Scratch::new("saturation");
    let report = |extra: &[&str]| -> Value {
        let o = run(
            &dir,
            &args(
                &["sim", "stability", "--preset", "hand-tuned", "--json"],
                extra,
            ),
        );
        assert!(!stderr(&o).contains("panicked"), "{}", stderr(&o));
        serde_json::from_str(&stdout(&o)).expect("stdout is the JSON report")
    };
    let clip = report(&[]);
    let sine = report(&["--saturation", "sine"]);
    assert_eq!(clip["gains"]["saturation"], "clip");
    assert_eq!(sine["gains"]["saturation"], "sine");
    assert_eq!(report(&["--saturation", "clip"]), clip);
    let max_theta = |v: &Value| v["starts"][0]["max_abs_theta"].as_f64().expect("a number");
    assert_ne!(max_theta(&clip), max_theta(&sine));
    fails(
        &dir,
        &[
            "sim",
            "pendulum",
            "--random",
            "--saturation",
            "sine",
            "--out",
            "r.csv",
        ],
        &["--saturation applies to gains"],
    );
}

/// `msgp fit` of `s.csv` in `dir` with `extra` options and the fast settings, written to
/// `out`; the model file it wrote.
fn fitted_model(dir: &Scratch, extra: &[&str], out: &str) -> Value {
    let base = [&["fit", "--data", "s.csv", "--out", out][..], extra].concat();
    ok(dir, &args(&base, &FAST));
    let text = std::fs::read_to_string(dir.path(out)).expect("model file written");
    serde_json::from_str(&text).expect("model file")
}

/// `msgp fit` of `s.csv` in `dir` by `method` with `option`, which that method refuses: the
/// message has each of `needles`.
fn refused_by(dir: &Scratch, method: &str, option: &[&str], needles: &[&str]) {
    let base = [&["fit", "--data", "s.csv", "--method", method][..], option].concat();
    // (linear-kf has no GP: it refuses pseudo-inputs too)
    let fast = match method {
        "linear-kf" => &["--iters", "5", "--quiet"][..],
        _ => &FAST[..],
    };
    fails(dir, &args(&base, fast), needles);
}

/// `--likelihood filter` fits MSGP on the filter's joint density: the model file records it,
/// the model differs from the free-run one, and another method refuses the option.
#[test]
fn the_msgp_likelihood_is_an_option_of_fit() {
    let dir = Scratch::new("likelihood");
    dir.write("s.csv", &system_csv(120, None));
    let model = |likelihood: &str, out: &str| -> Value {
        fitted_model(&dir, &["--likelihood", likelihood], out)
    };
    let filter = model("filter", "f.json");
    let free = model("free-run", "r.json");
    assert_eq!(filter["training"]["settings"]["likelihood"], "filter");
    assert_eq!(free["training"]["settings"]["likelihood"], "free-run");
    assert_ne!(filter["gp"], free["gp"]);
    refused_by(
        &dir,
        "gp-narx",
        &["--likelihood", "filter"],
        &[
            "--likelihood: filter: the likelihood of an MSGP fit",
            "gp-narx",
        ],
    );
}

/// `--segment-length N` trains MSGP on segments of the training part, says so and records it
/// in the model file; 0 trains whole; another method refuses the option.
#[test]
fn segments_are_an_option_of_fit() {
    let dir = Scratch::new("segments");
    dir.write("s.csv", &system_csv(120, None));
    let base = [
        &["fit", "--data", "s.csv", "--segment-length", "20"][..],
        &FAST[..4],
    ]
    .concat();
    let text = ok(&dir, &base);
    // 60 training samples, a window of 2: 58 predicted steps in segments of 20
    assert!(
        text.contains("trained by segments (a long log): 3 segments of up to 20"),
        "{text}"
    );
    // the final training on batches returns the mean of its second half's iterates
    assert!(
        text.contains("kept the mean of iterations 3–5 of the final training"),
        "{text}"
    );
    let cut = fitted_model(&dir, &["--segment-length", "20"], "c.json");
    assert_eq!(
        cut["training"]["settings"]["segments"],
        serde_json::json!({"length": 20, "batch": 2})
    );
    let whole = fitted_model(&dir, &["--segment-length", "0"], "w.json");
    assert_eq!(whole["training"]["settings"]["segments"], Value::Null);
    refused_by(
        &dir,
        "gp-narx",
        &["--segment-length", "20"],
        &["--segment-length", "gp-narx"],
    );
}

/// `--start linear-kf` starts MSGP from the linear-kf model of the data (as the filtered
/// policy-learning loop does): the model file records the start and the linear mean it implies,
/// and the model differs from the one-step start's; a zero mean and another method are refused.
#[test]
fn the_msgp_start_is_an_option_of_fit() {
    let dir = Scratch::new("start");
    dir.write("s.csv", &system_csv(120, None));
    let model = |extra: &[&str], out: &str| -> Value {
        fitted_model(&dir, &[&["--likelihood", "filter"], extra].concat(), out)
    };
    let kalman = model(&["--start", "linear-kf"], "k.json");
    let one_step = model(&["--mean", "linear"], "o.json");
    let settings = &kalman["training"]["settings"];
    assert_eq!(settings["start"], "linear-kf");
    assert_eq!(settings["mean"], "linear");
    assert_eq!(settings["alternative"], Value::Null);
    assert_eq!(one_step["training"]["settings"]["start"], "one-step");
    assert_eq!(one_step["training"]["settings"]["blow_up_fallback"], true);
    assert_ne!(kalman["gp"], one_step["gp"]);
    // the fallback heads can be switched off (no final training blows up here, so
    // the model is the same)
    let kept = model(&["--mean", "linear", "--no-blow-up-fallback"], "n.json");
    assert_eq!(kept["training"]["settings"]["blow_up_fallback"], false);
    assert_eq!(kept["gp"], one_step["gp"]);
    refused_by(
        &dir,
        "gp-narx",
        &["--no-blow-up-fallback"],
        &["--no-blow-up-fallback", "gp-narx"],
    );
    fails(
        &dir,
        &args(
            &[
                "fit",
                "--data",
                "s.csv",
                "--start",
                "linear-kf",
                "--mean",
                "zero",
            ],
            &FAST,
        ),
        &["linear-kf start", "mean: linear"],
    );
    refused_by(
        &dir,
        "gp-narx",
        &["--start", "linear-kf"],
        &["--start", "gp-narx"],
    );
}

/// `--one-step` picks the one-step fit's objective: gp-narx defaults to the variational bound
/// (its pseudo-inputs move from the k-means start), pilco-narx and MSGP's start to the exact GP;
/// the model file records the choice, and linear-kf (no one-step fit) refuses the option.
#[test]
fn the_one_step_objective_is_an_option_of_fit() {
    let dir = Scratch::new("one-step");
    dir.write("s.csv", &system_csv(120, None));
    let vfe = fitted_model(&dir, &["--method", "gp-narx"], "v.json");
    let exact = fitted_model(
        &dir,
        &["--method", "gp-narx", "--one-step", "exact"],
        "e.json",
    );
    assert_eq!(vfe["training"]["settings"]["objective"], "vfe");
    assert_eq!(exact["training"]["settings"]["objective"], "exact");
    assert_ne!(vfe["gp"]["pseudo_inputs"], exact["gp"]["pseudo_inputs"]);
    let pilco = fitted_model(&dir, &["--method", "pilco-narx"], "p.json");
    assert_eq!(pilco["training"]["settings"]["objective"], "exact");
    let msgp = fitted_model(&dir, &["--one-step", "vfe"], "m.json");
    assert_eq!(msgp["training"]["settings"]["one_step_objective"], "vfe");
    refused_by(
        &dir,
        "linear-kf",
        &["--one-step", "vfe"],
        &["--one-step", "linear-kf"],
    );
}

/// `--plant` picks the measurement-noise tier: the Apollo LQR gains, at the edge on the noisy
/// tier (their derivative term turns 5 mrad of angle noise into command noise), pass the
/// stability test on the Apollo tier; individual flags and a params file override the tier.
#[test]
fn the_plant_tier_sets_the_measurement_noise() {
    let dir = Scratch::new("plant-tier");
    let report = |extra: &[&str]| -> Value {
        let o = run(
            &dir,
            &args(
                &["sim", "stability", "--preset", "apollo-lqr", "--json"],
                extra,
            ),
        );
        assert!(!stderr(&o).contains("panicked"), "{}", stderr(&o));
        serde_json::from_str(&stdout(&o)).expect("stdout is the JSON report")
    };
    let passed = |v: &Value| v["passed"].as_bool().expect("passed");
    let noisy = report(&["--plant", "noisy"]);
    assert!(!passed(&noisy), "{noisy}");
    assert_eq!(noisy["params"]["sigma_theta"], 5e-3);
    let apollo = report(&["--plant", "apollo"]);
    assert_eq!(report(&[]), apollo, "apollo is the default");
    assert!(passed(&apollo), "{apollo}");
    assert_eq!(apollo["params"]["sigma_theta"], 5.1985e-5);
    assert_eq!(apollo["params"]["sigma_x"], 1e-4);
    // the individual flag wins over the tier
    let louder = report(&["--plant", "apollo", "--sigma-theta", "5e-3"]);
    assert_eq!(louder["params"]["sigma_theta"], 5e-3);
    assert_eq!(louder["params"]["sigma_x"], 1e-4);
    // a params file's fields go over the tier's, the rest keep the tier's values
    dir.write("p.json", r#"{"lag_time_constant": 0.02}"#);
    let file = report(&["--plant", "apollo", "--params", "p.json"]);
    assert_eq!(file["params"]["lag_time_constant"], 0.02);
    assert_eq!(file["params"]["sigma_theta"], 5.1985e-5);
    dir.write("bad.json", r#"{"sigma_thetta": 0.1}"#);
    fails(
        &dir,
        &[
            "sim",
            "stability",
            "--preset",
            "apollo-lqr",
            "--params",
            "bad.json",
        ],
        &["bad.json", "sigma_thetta"],
    );
    fails(
        &dir,
        &[
            "sim",
            "stability",
            "--preset",
            "apollo-lqr",
            "--plant",
            "robot",
        ],
        &["apollo", "noisy"],
    );
}

/// The thread count comes from `MSGP_THREADS`: a positive integer, else a clear error; the
/// numbers do not depend on it.
#[test]
fn the_thread_count_is_checked_and_changes_no_number() {
    let dir = Scratch::new("threads");
    dir.write("s.csv", &system_csv(120, None));
    let fit = |threads: &str| {
        Command::new(BIN)
            .args(args(
                &["fit", "--data", "s.csv", "--json", "--out", "m.json"],
                &FAST,
            ))
            .env("MSGP_THREADS", threads)
            .current_dir(&dir.0)
            .output()
            .expect("run msgp")
    };
    for bad in ["0", "two", "-1"] {
        let o = fit(bad);
        assert!(!o.status.success(), "MSGP_THREADS={bad} should fail");
        let err = stderr(&o);
        assert!(err.contains("MSGP_THREADS") && err.contains(bad), "{err}");
        assert!(!err.contains("panicked"), "{err}");
    }
    let (one, two) = (fit("1"), fit("2"));
    assert!(
        one.status.success() && two.status.success(),
        "{}",
        stderr(&one)
    );
    let rmse = |o: &Output| -> Value {
        let v: Value = serde_json::from_str(&stdout(o)).expect("JSON");
        v["rmse"].clone()
    };
    assert_eq!(rmse(&one), rmse(&two));
    assert!(rmse(&one).is_f64());
}

/// `reproduce table1` over two seeds: one row per seed, method and rollout in the JSON, mean ±
/// standard deviation in the markdown with both rollouts of the baselines; `reproduce
/// generalisation` scores the unseen excitations against the training-mean predictor.
#[test]
fn reproductions_run_over_seeds_and_unseen_excitations() {
    let dir = Scratch::new("reproduce");
    // `reproduce table1` on system 5, seeds 0 and 1, the free-run likelihood, with `extra`
    let table1 = |extra: &[&'static str]| {
        let mut args = vec![
            "reproduce",
            "table1",
            "--only",
            "synthetic5",
            "--seeds",
            "0,1",
            "--likelihoods",
            "free-run",
        ];
        args.extend(extra);
        args
    };
    let v = ok_json(&dir, &table1(&["--out", "t.md", "--json", "--quiet"]));
    let rows = v["rows"].as_array().expect("rows");
    // 3 methods × 2 seeds × 2 rollouts
    assert_eq!(rows.len(), 12, "{v}");
    assert_eq!(v["seeds"], serde_json::json!([0, 1]));
    for r in rows {
        assert!(r["rmse"].as_f64().expect("rmse").is_finite(), "{r}");
    }
    // fits side by side (`--jobs`) give the same figures as one at a time
    // (`--plots` with two jobs: the figures are the same with and without it)
    let run = |jobs: &'static str| {
        let mut args = table1(&[
            "--methods",
            "msgp",
            "--iters",
            "30",
            "--jobs",
            jobs,
            "--out",
            "j.md",
            "--json",
            "--quiet",
        ]);
        if jobs == "2" {
            args.extend(["--plots", "table-plots"]);
        }
        let v = ok_json(&dir, &args);
        let plots = if jobs == "2" {
            serde_json::json!([
                "table-plots/synthetic5-seed0.png",
                "table-plots/synthetic5-seed1.png"
            ])
        } else {
            serde_json::json!([])
        };
        assert_eq!(v["plots"], plots, "{v}");
        v["rows"]
            .as_array()
            .expect("rows")
            .iter()
            .map(|r| {
                (
                    r["seed"].clone(),
                    r["rollout"].clone(),
                    r["rmse"].clone(),
                    r["nll"].clone(),
                )
            })
            .collect::<Vec<_>>()
    };
    let (one, two) = (run("1"), run("2"));
    assert_eq!(one.len(), 4);
    assert_eq!(one, two);
    // one panel per plot: the one column, MSGP
    for seed in ["0", "1"] {
        let png = dir.path(&format!("table-plots/synthetic5-seed{seed}.png"));
        assert_eq!(png_size(&png), (1200, 340));
    }
    let md = std::fs::read_to_string(dir.path("j.md")).expect("markdown");
    assert!(md.contains("table-plots/<benchmark>-seed<k>.png"), "{md}");
    let md = std::fs::read_to_string(dir.path("t.md")).expect("markdown");
    assert!(md.contains(" ± "), "{md}");
    assert!(md.contains("GP-NARX (ours, mean)"), "{md}");
    assert!(md.contains("at or below the paper's MSGP"), "{md}");
    // histories chosen from the data: their own section, each fit's choice in the JSON
    let v = ok_json(
        &dir,
        &[
            "reproduce",
            "table1",
            "--only",
            "synthetic1",
            "--seeds",
            "0",
            "--methods",
            "gp-narx",
            "--history",
            "auto",
            "--out",
            "t.md",
            "--json",
            "--quiet",
        ],
    );
    let row = &v["rows"][0];
    let chosen = &row["history_choice"];
    assert_eq!(
        row["history"],
        serde_json::json!([chosen["ly"], chosen["lu"]]),
        "{row}"
    );
    let md = std::fs::read_to_string(dir.path("t.md")).expect("markdown");
    assert!(
        md.contains("<!-- msgp:table1-auto-history:begin -->"),
        "{md}"
    );
    assert!(md.contains("<!-- msgp:table1:begin -->"), "{md}");
    assert!(md.contains("## Chosen histories"), "{md}");
    fails(
        &dir,
        &[
            "reproduce",
            "table1",
            "--only",
            "synthetic9",
            "--out",
            "t.md",
        ],
        &["synthetic9"],
    );
    // `reproduce generalisation` on system 5 with `extra` arguments
    let generalisation = |extra: &[&'static str]| {
        let mut args = vec![
            "reproduce",
            "generalisation",
            "--only",
            "synthetic5",
            "--out",
            "g.md",
        ];
        args.extend(extra);
        args
    };
    let g = ok_json(&dir, &generalisation(&["--json", "--quiet"]));
    let rows = g["rows"].as_array().expect("rows");
    // (Table 2 test + 3 excitations in range + 2 beyond it) × 2 methods
    assert_eq!(rows.len(), 12, "{g}");
    assert_eq!(rows.iter().filter(|r| r["alternate"] == true).count(), 10);
    assert_eq!(rows.iter().filter(|r| r["beyond_range"] == true).count(), 4);
    for r in rows {
        let m = r["mean_predictor_rmse"].as_f64().expect("mean predictor");
        assert!(
            m > 0.0 && r["rmse"].as_f64().expect("rmse").is_finite(),
            "{r}"
        );
    }
    let md = std::fs::read_to_string(dir.path("g.md")).expect("markdown");
    assert!(
        md.contains("msgp:generalisation:begin")
            && md.contains("chirp")
            && md.contains("- beyond the training amplitude")
            && md.contains("test input ×1.5"),
        "{md}"
    );
    // `--plots` draws the same simulations: the figures are unchanged, and one PNG of the
    // benchmark's six tests (rows) by two methods (columns) is written into a new folder
    let p = ok_json(
        &dir,
        &generalisation(&["--plots", "plots/new", "--json", "--quiet"]),
    );
    assert_eq!(p["rows"], g["rows"]);
    assert_eq!(
        p["plots"],
        serde_json::json!(["plots/new/synthetic5-seed0.png"]),
        "{p}"
    );
    let png = dir.path("plots/new/synthetic5-seed0.png");
    assert_eq!(png_size(&png), (2 * 800, 6 * 340));
    let md = std::fs::read_to_string(dir.path("g.md")).expect("markdown");
    assert!(md.contains("plots/new/<benchmark>-seed<k>.png"), "{md}");
    // a plots' folder that cannot be made: a clear error before any fit, for both reproductions
    std::fs::write(dir.path("file"), "x").expect("a file");
    fails(
        &dir,
        &generalisation(&["--plots", "file/sub"]),
        &["plots' folder", "file/sub"],
    );
    fails(
        &dir,
        &table1(&["--plots", "file/sub", "--out", "t.md"]),
        &["plots' folder", "file/sub"],
    );
}

/// `n` samples of a linear ARX system of orders (3, 2) (`y_{t+1} = 1.2 y_t − 0.55 y_{t−1} +
/// 0.1 y_{t−2} + 0.5 u_t + 0.3 u_{t−1}`) under a piecewise-constant input (a new level every 7
/// samples, from a fixed hash), with a little output noise.
fn arx_csv(n: usize) -> String {
    let hash = |k: f64| ((k * 12.9898).sin() * 43_758.545).fract();
    let u: Vec<f64> = (0..n).map(|t| hash((t / 7) as f64 + 0.5)).collect();
    let mut y = vec![0.0; n];
    for t in 2..n - 1 {
        y[t + 1] = 1.2 * y[t] - 0.55 * y[t - 1] + 0.1 * y[t - 2] + 0.5 * u[t] + 0.3 * u[t - 1];
    }
    let mut s = String::from("t,u,y\n");
    for t in 0..n {
        let noise = 0.02 * hash(t as f64 + 1000.25);
        s.push_str(&format!("{t},{},{}\n", u[t], y[t] + noise));
    }
    s
}

/// `--history auto` chooses the history on the training part, with the fit's own settings
/// as the judge (here linear-kf at 60 iterations; the recovery of the true orders by the
/// default search is `msgp_core::fit::history`'s test), says how it chose, and records the
/// choice (with every score) in `--json` and in the model file; neither a history nor `auto`
/// is refused by name.
#[test]
fn the_history_is_chosen_from_the_data() {
    let dir = Scratch::new("history-auto");
    dir.write("a.csv", &arx_csv(1200));
    dir.write("s.csv", &system_csv(120, None));
    let base = [
        "fit",
        "--data",
        "a.csv",
        "--method",
        "linear-kf",
        "--iters",
        "60",
        "--history",
        "auto",
    ];
    let v = ok_json(&dir, &args(&base, &["--json", "--out", "a.json"]));
    let choice = &v["history_choice"];
    let (ly, lu) = (choice["ly"].as_u64(), choice["lu"].as_u64());
    assert_eq!(v["history"], serde_json::json!([ly, lu]), "{v}");
    let judged = choice["judged"].as_array().expect("judged");
    assert!(
        judged.len() >= 10,
        "the equal histories (l, l) are judged: {choice}"
    );
    // the linear stage tried every history up to 10 lags; the chosen one was judged
    assert_eq!(choice["linear"].as_array().map(Vec::len), Some(100));
    assert!(
        judged
            .iter()
            .any(|s| (s["ly"].as_u64(), s["lu"].as_u64()) == (ly, lu))
    );
    let file: Value =
        serde_json::from_str(&std::fs::read_to_string(dir.path("a.json")).expect("model"))
            .expect("model file");
    assert_eq!(file["training"]["history_choice"], *choice);
    assert_eq!(file["history"], serde_json::json!({"ly": ly, "lu": lu}));
    let text = ok(&dir, &args(&base, &["--out", "b.json"]));
    assert!(
        text.contains(&format!(
            "history l_y={}, l_u={}",
            ly.unwrap_or(0),
            lu.unwrap_or(0)
        )) && text.contains("history chosen from the training part:")
            && text.contains("fitted by linear-kf"),
        "{text}"
    );
    let given = fitted_model(&dir, &["--history", "2,2"], "g.json");
    assert_eq!(given["training"]["history_choice"], Value::Null);
    fails(
        &dir,
        &["fit", "--data", "a.csv", "--history", "auto,2"],
        &["LY,LU", "`auto`"],
    );
}
