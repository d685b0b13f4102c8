//! `msgp learn-policy` and `msgp reproduce figure4` end to end on a tiny budget: the JSON keys
//! the issue asks for, the files written, the policy file running in `msgp sim`, bad options.

use std::path::PathBuf;
use std::process::{Command, Output};

use serde_json::Value;

const BIN: &str = env!("CARGO_BIN_EXE_msgp");

fn scratch(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("msgp-learn-{tag}-{}", std::process::id()));
    let _ = std::fs::remove_dir_all(&dir);
    std::fs::create_dir_all(&dir).expect("create scratch folder");
    dir
}

fn run(dir: &PathBuf, args: &[&str]) -> Output {
    Command::new(BIN)
        .args(args)
        .current_dir(dir)
        .output()
        .expect("run msgp")
}

/// A budget small enough for a test: 2 random rollouts, tiny model and search.
const TINY: [&str; 12] = [
    "--random-rollouts",
    "2",
    "--fit-iters",
    "3",
    "--inducing",
    "10",
    "--search-iters",
    "2",
    "--candidates",
    "4",
    "--episode-seconds",
    "1",
];

/// `msgp learn-policy --sim pendulum --out <out> --json` with `options` on the tiny budget,
/// run in `dir`; it must succeed and print one JSON object, which is returned.
fn learn_json(dir: &PathBuf, out: &str, options: &[&str]) -> Value {
    let head = ["learn-policy", "--sim", "pendulum", "--out", out, "--json"];
    let o = run(dir, &[&head[..], options, &TINY[..]].concat());
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    serde_json::from_slice(&o.stdout).expect("one JSON object")
}

/// The iterations without their wall-clock fields.
fn without_timings(its: &Value) -> Vec<Value> {
    its.as_array()
        .map(|a| {
            a.iter()
                .map(|it| {
                    let mut it = it.clone();
                    if let Some(o) = it.as_object_mut() {
                        o.remove("fit_seconds");
                        o.remove("search_seconds");
                    }
                    it
                })
                .collect()
        })
        .unwrap_or_default()
}

#[test]
fn learn_policy_writes_policy_table_episodes_plot_and_json() {
    let dir = scratch("run");
    let options = ["--iterations", "2", "--seed", "3"];
    let v = learn_json(&dir, "out", &options);
    let its = v["iterations"].as_array().expect("iterations");
    assert_eq!(its.len(), 2);
    for (k, it) in its.iter().enumerate() {
        assert_eq!(it["iteration"].as_u64(), Some(k as u64 + 1));
        for key in [
            "predicted_cost",
            "predicted_cost_std",
            "actual_cost",
            "interaction_seconds",
        ] {
            assert!(it[key].as_f64().is_some_and(f64::is_finite), "{key}: {it}");
        }
        assert!(it["stable"].is_boolean());
    }
    assert!(v.get("first_stable_iteration").is_some());
    assert!(v.get("random_policies").is_none(), "the switch is gone");
    assert!(v.get("interaction_seconds_to_stable").is_some());
    let best = v["best_iteration"].as_u64().expect("best_iteration") as usize;
    assert!((1..=2).contains(&best), "{best}");
    // interaction grows by at most one episode per iteration
    let s0 = its[0]["interaction_seconds"].as_f64().unwrap_or(0.0);
    let s1 = its[1]["interaction_seconds"].as_f64().unwrap_or(0.0);
    assert!(s1 > s0 && s1 - s0 <= 1.0 + 1e-9, "{s0} → {s1}");

    let out = dir.join("out");
    for f in [
        "policy.json",
        "best_policy.json",
        "iterations.csv",
        "summary.json",
        "cost.png",
    ] {
        assert!(out.join(f).is_file(), "{f} missing");
    }
    let csv = std::fs::read_to_string(out.join("iterations.csv")).expect("csv");
    assert_eq!(csv.lines().count(), 3, "header + 2 rows:\n{csv}");
    let episodes: Vec<_> = std::fs::read_dir(out.join("episodes"))
        .expect("episodes")
        .filter_map(Result::ok)
        .collect();
    assert_eq!(episodes.len(), 4, "2 random + 2 policy episodes");
    let summary: Value =
        serde_json::from_slice(&std::fs::read(out.join("summary.json")).expect("summary"))
            .expect("summary JSON");
    assert_eq!(summary["iterations"], v["iterations"]);

    // the policy file runs in the simulator, with the sine saturation it was learned with
    let policy: Value =
        serde_json::from_slice(&std::fs::read(out.join("policy.json")).expect("policy"))
            .expect("policy JSON");
    assert_eq!(policy["saturation"], "sine");
    let o = run(
        &dir,
        &[
            "sim",
            "pendulum",
            "--policy",
            "out/policy.json",
            "--seconds",
            "1",
            "--out",
            "replay.csv",
        ],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));

    // the same seed gives the same numbers (all but the wall-clock timings)
    let v2 = learn_json(&dir, "out2", &options);
    assert_eq!(
        without_timings(&v["iterations"]),
        without_timings(&v2["iterations"])
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// `msgp reproduce figure4` for `models`, one seed and one iteration on the tiny budget, into
/// `fig/`, then `extra`.
fn figure4_args<'a>(models: &'a str, extra: &[&'a str]) -> Vec<&'a str> {
    let head = [
        "reproduce",
        "figure4",
        "--seeds",
        "1",
        "--iterations",
        "1",
        "--models",
        models,
        "--dir",
        "fig",
    ];
    [&head[..], &TINY[..], extra].concat()
}

#[test]
fn figure4_writes_its_section_and_keeps_the_others() {
    let dir = scratch("fig4");
    std::fs::write(
        dir.join("RESULTS.md"),
        "<!-- msgp:table1:begin -->\nTABLE ONE\n<!-- msgp:table1:end -->\n",
    )
    .expect("write");
    let o = run(
        &dir,
        &figure4_args("msgp,msgp-filter,gp-narx", &["--quiet"]),
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let md = std::fs::read_to_string(dir.join("RESULTS.md")).expect("results");
    assert!(md.contains("TABLE ONE"), "table 1 kept");
    assert!(md.contains("msgp:figure4-apollo:begin") && md.contains("| msgp | 0 |"));
    assert!(md.contains("| msgp-filter | 0 |") && md.contains("| gp-narx | 0 |"));
    // the filtered MSGP's runs are MSGP trained on the filter likelihood
    let summary: serde_json::Value = serde_json::from_str(
        &std::fs::read_to_string(dir.join("fig/msgp-filter-seed0/summary.json")).expect("summary"),
    )
    .expect("JSON");
    assert_eq!(summary["model"], "msgp");
    assert_eq!(
        summary["settings"]["fit"]["likelihood"], "filter",
        "{summary}"
    );
    assert_eq!(
        summary["plant"]["sigma_theta"], 5.1985e-5,
        "the default tier"
    );
    // the section names the command that made it, budget flags included
    let command = format!(
        "- Command: `cargo run --release --locked --bin msgp -- {}`",
        figure4_args("msgp,msgp-filter,gp-narx", &["--quiet"]).join(" ")
    );
    assert!(md.contains(&command), "{command}\n{md}");
    assert!(
        md.contains("from scratch: 2 random-excitation rollouts"),
        "{md}"
    );
    assert!(dir.join("fig/figure4.png").is_file());
    assert!(dir.join("fig/msgp-seed0/policy.json").is_file());
    let _ = std::fs::remove_dir_all(&dir);
}

/// `--jobs 2` runs two units at a time, one thread each: every run's iterations (wall-clock
/// fields aside) equal those of the runs one at a time on the default threads, the report
/// lists them in the plan's order, and one line per started and finished run is printed.
#[test]
fn figure4_runs_side_by_side_give_the_runs_of_one_at_a_time() {
    let dir = scratch("fig4jobs");
    let args = |jobs: &'static str, out: &'static str| -> Vec<&'static str> {
        let head = [
            "reproduce",
            "figure4",
            "--seeds",
            "2",
            "--iterations",
            "2",
            "--models",
            "msgp-filter,linear-kf",
            "--dir",
            out,
            "--out",
            "R.md",
            "--jobs",
            jobs,
        ];
        [&head[..], &TINY[..]].concat()
    };
    let one = run(&dir, &args("1", "one"));
    assert!(
        one.status.success(),
        "{}",
        String::from_utf8_lossy(&one.stderr)
    );
    let two = run(&dir, &args("2", "two"));
    assert!(
        two.status.success(),
        "{}",
        String::from_utf8_lossy(&two.stderr)
    );
    let log = String::from_utf8_lossy(&two.stderr);
    for unit in [
        "msgp-filter-seed0",
        "msgp-filter-seed1",
        "linear-kf-seed0",
        "linear-kf-seed1",
    ] {
        assert!(log.contains(&format!("== {unit}: started")), "{log}");
        assert!(log.contains(&format!("== {unit}: done in")), "{log}");
        let iterations = |folder: &str| {
            let path = dir.join(folder).join(unit).join("summary.json");
            let v: Value = serde_json::from_str(&std::fs::read_to_string(&path).expect("summary"))
                .expect("JSON");
            without_timings(&v["iterations"])
        };
        let (a, b) = (iterations("one"), iterations("two"));
        assert_eq!(a.len(), 2, "{unit}");
        assert_eq!(a, b, "{unit}");
    }
    // the report's runs in the plan's order: models as given, seeds ascending
    let md = std::fs::read_to_string(dir.join("R.md")).expect("results");
    let rows: Vec<(String, u64)> = md
        .lines()
        .filter_map(|l| {
            let cells: Vec<&str> = l.split('|').map(str::trim).collect();
            let model = *cells.get(1)?;
            let seed = cells.get(2)?.parse().ok()?;
            ["msgp-filter", "linear-kf"]
                .contains(&model)
                .then(|| (model.to_string(), seed))
        })
        .collect();
    let expected: Vec<(String, u64)> = [("msgp-filter", 0), ("msgp-filter", 1)]
        .into_iter()
        .chain([("linear-kf", 0), ("linear-kf", 1)])
        .map(|(m, k)| (m.to_string(), k))
        .collect();
    assert_eq!(rows, expected, "{md}");
    // no runs at a time is refused by name
    let zero = run(&dir, &args("0", "zero"));
    assert!(!zero.status.success());
    assert!(String::from_utf8_lossy(&zero.stderr).contains("--jobs"));
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn figure4_reuses_a_run_only_when_every_setting_matches() {
    let dir = scratch("fig4reuse");
    let base = figure4_args("msgp", &[]);
    let reused = |args: &[&str]| -> bool {
        let o = run(&dir, args);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        String::from_utf8_lossy(&o.stderr).contains("reusing")
    };
    assert!(!reused(&base), "nothing to reuse yet");
    assert!(reused(&base), "the same settings reuse the finished run");
    // the same budget, seed and model, but another prior mean
    assert!(!reused(&[&base[..], &["--mean", "zero"]].concat()));
    // … or another plant
    assert!(!reused(&[&base[..], &["--plant", "apollo"]].concat()));
    assert!(!reused(&[&base[..], &["--warm-start", "5"]].concat()));
    // a run recorded before the solver and warm-start settings existed used their defaults
    assert!(!reused(&base), "the warm-start run took the run's place");
    let path = dir.join("fig/msgp-seed0/summary.json");
    let mut summary: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(&path).expect("summary")).expect("JSON");
    let settings = summary["settings"].as_object_mut().expect("settings");
    assert!(settings.remove("warm_start").is_some());
    let fit = settings["fit"].as_object_mut().expect("fit settings");
    assert!(fit.remove("optimizer").is_some());
    std::fs::write(&path, summary.to_string()).expect("write");
    assert!(
        reused(&base),
        "an older summary with today's defaults is reused"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

#[test]
fn bad_learning_options_fail_with_a_message() {
    let dir = scratch("bad");
    for (args, needle) in [
        (
            vec![
                "learn-policy",
                "--sim",
                "pendulum",
                "--episode-seconds",
                "0",
            ],
            "--episode-seconds",
        ),
        (
            vec![
                "learn-policy",
                "--sim",
                "pendulum",
                "--random-rollouts",
                "0",
            ],
            "--random-rollouts",
        ),
        (vec!["learn-policy", "--sim", "cartpole"], "cartpole"),
        (
            vec!["learn-policy", "--sim", "pendulum", "--cost-widths", "0.1"],
            "invalid --cost-widths: needs two positive widths",
        ),
        (
            vec!["learn-policy", "--sim", "pendulum", "--cost-widths=0.1,-1"],
            "invalid --cost-widths: needs two positive widths",
        ),
        (
            vec!["learn-policy", "--sim", "pendulum", "--policy-horizon", "0"],
            "--policy-horizon",
        ),
        (
            vec![
                "learn-policy",
                "--sim",
                "pendulum",
                "--experimental",
                "trust-region=1",
            ],
            "--experimental",
        ),
        (
            // the simulator's single-parameter flags are not the learning loop's (--params is)
            vec!["learn-policy", "--sim", "pendulum", "--pole-length=-1"],
            "--pole-length",
        ),
    ] {
        let o = run(&dir, &args);
        assert!(!o.status.success(), "{args:?} should fail");
        let err = String::from_utf8_lossy(&o.stderr);
        assert!(err.contains(needle), "{args:?}: {err}");
    }
    let _ = std::fs::remove_dir_all(&dir);
}

/// `--model linear-kf` runs the loop with the Kalman-filter linear model and says so.
#[test]
fn learn_policy_runs_the_linear_kf_model() {
    let dir = scratch("linear-kf");
    let v = learn_json(&dir, "kf", &["--model", "linear-kf", "--iterations", "2"]);
    assert_eq!(v["model"], "linear-kf");
    let its = v["iterations"].as_array().expect("iterations");
    assert_eq!(its.len(), 2);
    for it in its {
        let predicted = it["predicted_cost"].as_f64().expect("predicted cost");
        assert!(predicted.is_finite() && predicted >= 0.0, "{it}");
        assert!(it["fit_numerical_stop"].is_null(), "{it}");
    }
    assert!(dir.join("kf/policy.json").is_file());
    // linear-kf fits are warm-started by default; `--warm-start 0` starts each from scratch
    assert_eq!(v["settings"]["warm_start"], 300);
    assert_eq!(v["settings"]["policy_horizon_seconds"], 10.0);
    let cold = learn_json(
        &dir,
        "kf-cold",
        &[
            "--model",
            "linear-kf",
            "--iterations",
            "2",
            "--warm-start",
            "0",
        ],
    );
    assert!(cold["settings"]["warm_start"].is_null());
    assert_eq!(
        without_timings(&cold["iterations"])[0],
        without_timings(&v["iterations"])[0],
        "the first iteration has no previous model"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// The loop's MSGP trains on the filter likelihood by default, with the filtered loop's
/// settings (linear-kf start, warm starts, 10 s horizon); a free-run MSGP loop that finds no
/// stable policy says so, and points at the filtered MSGP and linear-kf.
#[test]
fn an_unstable_msgp_loop_points_at_linear_kf() {
    let dir = scratch("msgp-hint");
    let default = learn_json(&dir, "f", &["--iterations", "1"]);
    let s = &default["settings"];
    assert_eq!(s["fit"]["likelihood"], "filter", "{s}");
    assert_eq!(s["fit"]["start"], "linear-kf", "{s}");
    assert_eq!(s["warm_start"], 40);
    assert_eq!(s["policy_horizon_seconds"], 10.0);
    assert_eq!(
        default["plant"]["sigma_theta"], 5.1985e-5,
        "apollo by default"
    );
    let args = [
        "learn-policy",
        "--sim",
        "pendulum",
        "--out",
        "m",
        "--iterations",
        "1",
        "--likelihood",
        "free-run",
        "--plant",
        "noisy",
    ];
    let o = run(&dir, &[&args[..], &TINY[..]].concat());
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let out = String::from_utf8_lossy(&o.stdout);
    let v: Value =
        serde_json::from_slice(&std::fs::read(dir.join("m/summary.json")).expect("summary"))
            .expect("summary JSON");
    assert!(
        v["settings"]["warm_start"].is_null(),
        "msgp fits start over"
    );
    assert_eq!(v["settings"]["policy_horizon_seconds"], 5.0);
    // this seed's tiny run fails the test (deterministic: everything is seeded)
    assert!(v["first_stable_iteration"].is_null(), "{out}");
    assert!(
        out.contains("no iteration passed the stability test"),
        "{out}"
    );
    assert!(
        out.contains("try --model msgp (the filter likelihood, the default) or --model linear-kf"),
        "{out}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// The real-robot route on the simulator's logs: `msgp policy improve` on the episodes a
/// `learn-policy` run logged (MCAP, read as `msgp fit` reads data) and its policy files gives,
/// round after round, the policies `learn-policy` ran with the same seed, to the bit;
/// `msgp policy eval` predicts a policy's cost on the model `improve` saved.
#[test]
fn policy_improve_on_logged_episodes_reproduces_learn_policy() {
    let dir = scratch("improve");
    let o = run(
        &dir,
        &[
            &[
                "learn-policy",
                "--sim",
                "pendulum",
                "--iterations",
                "2",
                "--seed",
                "0",
            ][..],
            &TINY[..],
            &["--out", "run", "--quiet"][..],
        ]
        .concat(),
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let episodes = [
        "run/episodes/00-random.mcap",
        "run/episodes/01-random.mcap",
        "run/episodes/02-policy-it1.mcap",
    ];
    let columns = [
        "--input",
        "/pendulum/command:acceleration",
        "--output",
        "/pendulum/measurement:theta,/pendulum/measurement:x",
    ];
    let improve = |n: usize, extra: &[&str]| -> Output {
        let mut args = vec!["policy", "improve"];
        for e in &episodes[..2 + n] {
            args.extend(["--data", e]);
        }
        args.extend(columns);
        let policies = ["run/policies/00.json", "run/policies/01.json"];
        for p in &policies[..=n] {
            args.extend(["--policy", p]);
        }
        args.extend(extra);
        run(&dir, &args)
    };
    let policy_of = |path: &str| -> Value {
        let text = std::fs::read_to_string(dir.join(path)).expect("policy file");
        serde_json::from_str::<Value>(&text).expect("JSON")["policy"].clone()
    };
    for n in 0..2 {
        let out = format!("next{n}.json");
        let o = improve(n, &["--out", &out, "--model-out", "model.json", "--json"]);
        assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
        let summary: Value = serde_json::from_slice(&o.stdout).expect("JSON summary");
        assert_eq!(summary["iteration"], n + 1);
        assert_eq!(
            policy_of(&out),
            policy_of(&format!("run/policies/{:02}.json", n + 1)),
            "round {}",
            n + 1
        );
    }
    let o = run(
        &dir,
        &[
            "policy",
            "eval",
            "--model",
            "model.json",
            "--policy",
            "next1.json",
            "--json",
        ],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let v: Value = serde_json::from_slice(&o.stdout).expect("JSON");
    assert!(
        v["expected_cost"]
            .as_f64()
            .is_some_and(|c| c.is_finite() && c >= 0.0),
        "{v}"
    );
    // bad input: episodes and policies that do not match, a log without the command column,
    // a policy file of another format version, a command outside the plant's bounds
    let o = improve(1, &["--out", "x.json"]);
    assert!(o.status.success());
    let o = run(
        &dir,
        &[
            "policy",
            "improve",
            "--data",
            episodes[0],
            "--data",
            episodes[1],
            "--input",
            "/pendulum/command:acceleration",
            "--output",
            "/pendulum/measurement:theta,/pendulum/measurement:x",
            "--policy",
            "run/policies/00.json",
            "--policy",
            "run/policies/01.json",
            "--out",
            "x.json",
        ],
    );
    assert!(!o.status.success());
    assert!(
        String::from_utf8_lossy(&o.stderr)
            .contains("2 episodes for 2 random ones and 1 policy episodes"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let o = run(
        &dir,
        &[
            "policy",
            "improve",
            "--data",
            episodes[0],
            "--data",
            episodes[1],
            "--input",
            "/pendulum/command:torque",
            "--output",
            "/pendulum/measurement:theta,/pendulum/measurement:x",
            "--policy",
            "run/policies/00.json",
            "--out",
            "x.json",
        ],
    );
    assert!(!o.status.success());
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("torque"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let text = std::fs::read_to_string(dir.join("run/policies/00.json")).expect("policy");
    std::fs::write(dir.join("future.json"), text.replace("\"1.0\"", "\"2.0\"")).expect("write");
    let o = run(
        &dir,
        &[
            "policy",
            "eval",
            "--model",
            "model.json",
            "--policy",
            "future.json",
        ],
    );
    assert!(!o.status.success());
    assert!(
        String::from_utf8_lossy(&o.stderr).contains("format version 2.0 is not supported"),
        "{}",
        String::from_utf8_lossy(&o.stderr)
    );
    let csv = "t,command,theta,x\n0,0.0,0.01,0\n0.02,9.5,0.011,0\n0.04,0.0,0.012,0\n0.06,0.0,0.013,0\n0.08,0.0,0.014,0\n0.1,0.0,0.015,0\n";
    std::fs::write(dir.join("wild.csv"), csv).expect("write");
    let o = run(
        &dir,
        &[
            "policy",
            "improve",
            "--data",
            "wild.csv",
            "--data",
            "wild.csv",
            "--input",
            "command",
            "--output",
            "theta,x",
            "--policy",
            "run/policies/00.json",
            "--out",
            "x.json",
        ],
    );
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("wild.csv: row 2: command 0") && err.contains("outside the plant's bounds"),
        "{err}"
    );
    let _ = std::fs::remove_dir_all(&dir);
}

/// `msgp policy init` writes a first policy file for a machine described only by its signals,
/// and `improve` takes the loop's next step from it and one logged episode; bad input names
/// the file or the entry and exits non-zero.
#[test]
fn policy_init_starts_a_loop_that_improve_continues() {
    let dir = scratch("init");
    let plant = r#"{"period": 0.1,
        "commands": [{"name": "u", "low": -1.0, "high": 1.0}],
        "outputs": [{"name": "angle", "angle": true, "low": -3.2, "high": 3.2},
                    {"name": "y", "low": -2.0, "high": 2.0}]}"#;
    std::fs::write(dir.join("plant.json"), plant).expect("plant");
    // one logged episode of the user's own excitation: a damped system driven by a sine
    let (mut a, mut y) = (0.3, 0.0);
    let mut csv = String::from("t,u,angle,y\n");
    for k in 0..41 {
        let u = (0.7 * k as f64).sin();
        csv.push_str(&format!("{},{u},{a},{y}\n", 0.1 * k as f64));
        (a, y) = (0.9 * a + 0.1 * y, 0.8 * y + 0.2 * u);
    }
    std::fs::write(dir.join("ep00.csv"), csv).expect("episode");
    let init = |out: &str, extra: &[&str]| -> Output {
        let base = [
            "policy",
            "init",
            "--plant",
            "plant.json",
            "--episode-steps",
            "40",
            "--basis",
            "10",
            "--out",
            out,
        ];
        run(&dir, &[&base[..], extra].concat())
    };
    let json_file = |f: &str| -> Value {
        serde_json::from_str(&std::fs::read_to_string(dir.join(f)).expect("file")).expect("JSON")
    };
    let task = ["--target", "0,0.5", "--widths", "0.5,none"];
    let o = init("p00.json", &task);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let file = json_file("p00.json");
    assert_eq!(file["policy"]["kind"], "rbf");
    assert_eq!(file["task"]["widths"], serde_json::json!([0.5, null]));
    assert_eq!(file["task"]["angles"], serde_json::json!([true, false]));
    assert_eq!(file["settings"]["random_rollouts"], 1);
    assert_eq!(file["iteration"], 0);
    assert!(
        file["settings"].get("one_step_guard").is_none(),
        "off unless asked"
    );
    let o = init("guarded.json", &[&task[..], &["--one-step-guard"]].concat());
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert_eq!(
        json_file("guarded.json")["settings"]["one_step_guard"],
        true
    );
    let o = run(
        &dir,
        &[
            "policy", "improve", "--data", "ep00.csv", "--input", "u", "--output", "angle,y",
            "--policy", "p00.json", "--out", "p01.json", "--json",
        ],
    );
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let summary: Value = serde_json::from_slice(&o.stdout).expect("summary");
    assert_eq!(summary["iteration"], 1);
    assert!(dir.join("p01.json").exists());
    // without --input/--output the plant's signal names choose the columns, in any order:
    // the same next policy from the log with its columns shuffled
    let text = std::fs::read_to_string(dir.join("ep00.csv")).expect("episode");
    let shuffled: String = text
        .lines()
        .map(|l| {
            let c: Vec<&str> = l.split(',').collect();
            format!("{},{},{},{}\n", c[3], c[0], c[2], c[1])
        })
        .collect();
    std::fs::write(dir.join("shuffled.csv"), shuffled).expect("shuffled");
    let improve = |data: &str, out: &str| {
        let a = [
            "policy", "improve", "--data", data, "--policy", "p00.json", "--out", out,
        ];
        run(&dir, &a)
    };
    let o = improve("shuffled.csv", "p01-named.json");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    assert!(!String::from_utf8_lossy(&o.stderr).contains("warning"));
    let policy = |f: &str| -> Value { json_file(f)["policy"].clone() };
    assert_eq!(policy("p01.json"), policy("p01-named.json"));
    // a log that names none of them, with fewer default columns than the plant has signals,
    // is refused with the names it lacks
    let renamed = text.replacen("t,u,angle,y", "t,cmd,a,b", 1);
    std::fs::write(dir.join("renamed.csv"), renamed).expect("renamed");
    let o = improve("renamed.csv", "p01-position.json");
    assert!(!o.status.success());
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("(commands u; outputs angle, y)") && err.contains("--input and --output"),
        "{err}"
    );
    // the simulator's log columns are as many as the plant's signals: matched by position,
    // which the warning spells out, to the same next policy
    let sim = text.replacen("t,u,angle,y", "t,command,meas_theta,meas_x", 1);
    std::fs::write(dir.join("sim.csv"), sim).expect("sim");
    let o = improve("sim.csv", "p01-position.json");
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let err = String::from_utf8_lossy(&o.stderr);
    assert!(
        err.contains("commands command as u; outputs meas_theta as angle, meas_x as y"),
        "{err}"
    );
    assert_eq!(policy("p01.json"), policy("p01-position.json"));
    // bad input: a width that is no number, a target of the wrong size, a missing plant
    let o = init("p00.json", &["--target", "0,0.5", "--widths", "0.5,wide"]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("entry 1 is \"wide\""));
    let o = init("p00.json", &["--target", "0", "--widths", "0.5,none"]);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("2 outputs"));
    std::fs::remove_file(dir.join("plant.json")).expect("remove");
    let o = init("p00.json", &task);
    assert!(!o.status.success());
    assert!(String::from_utf8_lossy(&o.stderr).contains("plant.json"));
}

/// `msgp reproduce plant-task` on the swing-up, one seed, two iterations, two models: the
/// section with a row per model and the prequential record, each run's record with every
/// iteration's score and searched model, both plots; a second call reuses the records (same
/// section, no run started) and an unknown task is refused with the known ones.
#[test]
fn plant_task_reproduction_writes_records_plots_and_its_section() {
    let dir = scratch("plant-task");
    let args = [
        "reproduce",
        "plant-task",
        "--task",
        "swing-up",
        "--models",
        "msgp-filter,linear-kf",
        "--seeds",
        "1",
        "--iterations",
        "2",
        "--dir",
        "pt",
    ];
    let o = run(&dir, &args);
    assert!(o.status.success(), "{}", String::from_utf8_lossy(&o.stderr));
    let md = std::fs::read_to_string(dir.join("RESULTS.md")).expect("results");
    assert!(md.contains("msgp:plant-task-swing-up:begin"), "{md}");
    assert!(md.contains("| msgp-filter | 0/1 |"), "{md}");
    assert!(
        md.contains("0/1 (0 %)"),
        "linear-kf never searches on a GP: {md}"
    );
    let record: Value = serde_json::from_str(
        &std::fs::read_to_string(dir.join("pt/msgp-filter-seed0.json")).expect("record"),
    )
    .expect("JSON");
    assert_eq!(record["task"], "swing-up");
    assert_eq!(record["scores"].as_array().map(Vec::len), Some(2));
    let its = record["iterations"].as_array().expect("iterations");
    assert_eq!(its.len(), 2);
    assert_eq!(its[0]["search_model"], "linear", "nothing predicted yet");
    assert!(its[1]["held_out"]["gp_nll"].is_number(), "{}", its[1]);
    assert_eq!(record["settings"]["fit"]["likelihood"], "filter");
    let linear: Value = serde_json::from_str(
        &std::fs::read_to_string(dir.join("pt/linear-kf-seed0.json")).expect("record"),
    )
    .expect("JSON");
    assert_eq!(linear["settings"]["fit"]["method"], "LinearKf");
    assert_eq!(linear["settings"]["prequential_choice"], false);
    for png in ["pt/scores.png", "pt/costs.png", "pt/swing-up.png"] {
        assert!(dir.join(png).is_file(), "{png}");
    }
    let again = run(&dir, &args);
    assert!(again.status.success());
    let err = String::from_utf8_lossy(&again.stderr);
    assert!(err.contains("reusing") && !err.contains("started"), "{err}");
    let md2 = std::fs::read_to_string(dir.join("RESULTS.md")).expect("results");
    let table = |m: &str| {
        m.lines()
            .filter(|l| l.starts_with("| "))
            .collect::<Vec<_>>()
            .join("\n")
    };
    assert_eq!(
        table(&md),
        table(&md2),
        "the same rows from the reused records"
    );
    let bad = run(&dir, &["reproduce", "plant-task", "--task", "cartpole"]);
    assert!(!bad.status.success());
    let bad = String::from_utf8_lossy(&bad.stderr);
    assert!(bad.contains("pendulum-v1, swing-up"), "{bad}");
    let _ = std::fs::remove_dir_all(&dir);
}
