//! Property-based fuzzing of everything that reads user files: the CSV reader, the MCAP reader
//! (and its signal alignment) and the model-file loader. Arbitrary bytes, and random mutations
//! of valid files, must give `Ok` or an error — never a panic.
//!
//! Cases per property: `MSGP_FUZZ_CASES` (default 256, so the suite stays fast); a long run is
//! `MSGP_FUZZ_CASES=20000 cargo test --release -p msgp-cli --test fuzz_readers`.

use std::collections::BTreeMap;
use std::path::Path;
use std::sync::OnceLock;

use msgp_core::data::Trajectory;
use msgp_core::data::mcap::{McapLog, Signal};
use msgp_core::data::table::{Table, TimeSource};
use msgp_core::data::{NoiseScale, SyntheticSystem};
use msgp_core::fit::{FitSettings, MethodSettings, OneStepFitSettings, fit};
use msgp_core::model_file::{FitRecord, ModelFile};
use proptest::prelude::*;
use serde_json::Value;

fn cases() -> u32 {
    std::env::var("MSGP_FUZZ_CASES")
        .ok()
        .and_then(|v| v.parse().ok())
        .unwrap_or(256)
}

fn config() -> ProptestConfig {
    ProptestConfig {
        cases: cases(),
        failure_persistence: None,
        ..ProptestConfig::default()
    }
}

/// The schema of the ROS 2 topic `/c`: a header, a sequence of doubles, a string.
const ROS2_SCHEMA: &str = "std_msgs/Header header\nfloat64[] v\nstring s\n===\n\
    MSG: std_msgs/Header\nbuiltin_interfaces/Time stamp\nstring frame_id\n";

/// One `/c` message in little-endian CDR (header, `v = [x, 2x]`, `s = "ok"`).
fn ros2_message(k: u64, x: f64) -> Vec<u8> {
    let mut m = vec![0u8, 1, 0, 0];
    let pad = |m: &mut Vec<u8>, n: usize| {
        while !(m.len() - 4).is_multiple_of(n) {
            m.push(0);
        }
    };
    m.extend_from_slice(&(k as i32).to_le_bytes());
    m.extend_from_slice(&0u32.to_le_bytes());
    m.extend_from_slice(&5u32.to_le_bytes());
    m.extend_from_slice(b"base\0");
    pad(&mut m, 4);
    m.extend_from_slice(&2u32.to_le_bytes());
    pad(&mut m, 8);
    m.extend_from_slice(&x.to_le_bytes());
    m.extend_from_slice(&(2.0 * x).to_le_bytes());
    m.extend_from_slice(&3u32.to_le_bytes());
    m.extend_from_slice(b"ok\0");
    m
}

/// A valid MCAP log: two JSON topics (one nested), one ROS 2 CDR topic.
fn valid_mcap() -> Vec<u8> {
    let mut buf = std::io::Cursor::new(Vec::new());
    {
        let mut w = mcap::Writer::new(&mut buf).expect("writer");
        let meta = BTreeMap::new();
        let schema = w
            .add_schema("m", "jsonschema", br#"{"type":"object"}"#)
            .expect("schema");
        let a = w.add_channel(schema, "/a", "json", &meta).expect("a");
        let b = w.add_channel(0, "/b", "json", &meta).expect("b");
        let ros2 = w
            .add_schema("pkg/msg/C", "ros2msg", ROS2_SCHEMA.as_bytes())
            .expect("ros2 schema");
        let c = w.add_channel(ros2, "/c", "cdr", &meta).expect("c");
        for k in 0..20u64 {
            let header = |ch| mcap::records::MessageHeader {
                channel_id: ch,
                sequence: k as u32,
                log_time: k * 1_000_000,
                publish_time: k * 1_000_000,
            };
            let x = (k as f64 * 0.3).sin();
            let body = format!(r#"{{"step": {k}, "x": {x}, "p": {{"q": [{x}, 1.5]}}}}"#);
            w.write_to_known_channel(&header(a), body.as_bytes())
                .expect("a");
            w.write_to_known_channel(&header(b), format!(r#"{{"u": {}}}"#, -x).as_bytes())
                .expect("b");
            w.write_to_known_channel(&header(c), &ros2_message(k, x))
                .expect("c");
        }
        w.finish().expect("finish");
    }
    buf.into_inner()
}

/// Exercises a parsed log the way the CLI does.
fn use_log(log: &McapLog) {
    let _ = log.topic_list();
    for t in &log.topics {
        let _ = log.numeric_fields(&t.topic);
    }
    for spec in [
        vec!["/b:u", "/a:x"],
        vec!["/a:p.q[0]", "/a:p.q.1"],
        vec!["/c:v.1", "/a:x"],
        vec!["/a:x", "/c:header.stamp.sec"],
        vec!["/a:nope", "/b:u"],
    ] {
        let signals: Vec<Signal> = spec
            .iter()
            .filter_map(|s| Signal::parse(s, None).ok())
            .collect();
        for time in [TimeSource::Log, TimeSource::Header] {
            if let Some(last) = signals.last()
                && let Ok(table) = log.table(&signals, &last.topic, time)
            {
                let names: Vec<String> = signals.iter().map(Signal::name).collect();
                let n: Vec<&str> = names.iter().map(String::as_str).collect();
                let _ = table.trajectories(&n[..1], &n[1..]);
            }
        }
    }
}

/// A small fitted model's file as JSON, and a short trajectory to simulate (fitted once).
fn valid_model() -> (Value, Trajectory) {
    static MODEL: OnceLock<(Value, Trajectory)> = OnceLock::new();
    MODEL.get_or_init(fit_small_model).clone()
}

fn fit_small_model() -> (Value, Trajectory) {
    let bench = SyntheticSystem::new(4)
        .expect("system")
        .generate(1, NoiseScale::StdDev)
        .expect("data");
    let train = bench.train.slice(0, 60);
    let settings = FitSettings {
        ly: 2,
        lu: 1,
        method: MethodSettings::GpNarx(OneStepFitSettings {
            inducing: 6,
            iterations: 10,
            ..OneStepFitSettings::default()
        }),
        ..FitSettings::default()
    };
    let (model, report) = fit(std::slice::from_ref(&train), &settings, &mut |_| {}).expect("fit");
    let names = |s: &str| vec![s.to_string()];
    let file = ModelFile::from_fit(
        &model,
        &FitRecord {
            inputs: &names("u"),
            outputs: &names("y"),
            settings: &settings,
            report: &report,
            train: std::slice::from_ref(&train),
        },
    )
    .expect("describe");
    (
        serde_json::to_value(&file).expect("json"),
        bench.test.slice(0, 12),
    )
}

/// JSON pointers of every node of `v`.
fn pointers(v: &Value, at: String, out: &mut Vec<String>) {
    out.push(at.clone());
    match v {
        Value::Object(m) => {
            for (k, x) in m {
                pointers(x, format!("{at}/{k}"), out);
            }
        }
        Value::Array(a) => {
            for (i, x) in a.iter().enumerate() {
                pointers(x, format!("{at}/{i}"), out);
            }
        }
        _ => {}
    }
}

fn json_value() -> impl Strategy<Value = Value> {
    prop_oneof![
        Just(Value::Null),
        any::<bool>().prop_map(Value::from),
        any::<i64>().prop_map(Value::from),
        any::<f64>()
            .prop_filter("JSON numbers are finite", |f| f.is_finite())
            .prop_map(Value::from),
        prop_oneof![
            Just(-1e308),
            Just(1e308),
            Just(-745.0),
            Just(710.0),
            Just(0.0)
        ]
        .prop_map(Value::from),
        "[a-z0-9.]{0,6}".prop_map(Value::from),
        prop::collection::vec(-5.0f64..5.0, 0..5).prop_map(Value::from),
        Just(serde_json::json!([[]])),
        Just(serde_json::json!({})),
    ]
}

/// A CSV-like text: digits, separators, special words.
fn csv_text() -> impl Strategy<Value = String> {
    prop::collection::vec(
        prop_oneof![
            Just("t".to_string()),
            Just("u".to_string()),
            Just("y".to_string()),
            Just("episode".to_string()),
            Just(",".to_string()),
            Just("\n".to_string()),
            Just("\r\n".to_string()),
            Just("\"".to_string()),
            Just(" ".to_string()),
            Just("NaN".to_string()),
            Just("-inf".to_string()),
            Just("1e400".to_string()),
            (-1000i32..1000).prop_map(|i| i.to_string()),
            any::<f64>().prop_map(|f| f.to_string()),
            any::<char>().prop_map(|c| c.to_string()),
        ],
        0..60,
    )
    .prop_map(|parts| parts.concat())
}

fn use_table(table: &Table) {
    let names: Vec<&str> = table.columns.iter().map(String::as_str).collect();
    let _ = table.time_column();
    let _ = table.episodes();
    let _ = table.times(0..table.len());
    if names.len() >= 2 {
        let _ = table.trajectories(&names[..1], &names[1..]);
    }
    let _ = table.trajectories(&[], &["y"]);
}

proptest! {
    #![proptest_config(config())]

    #[test]
    fn csv_reader_never_panics_on_bytes(bytes in prop::collection::vec(any::<u8>(), 0..400)) {
        if let Ok(t) = Table::parse_csv(&bytes, Path::new("f.csv")) {
            use_table(&t);
        }
    }

    #[test]
    fn csv_reader_never_panics_on_csv_like_text(text in csv_text()) {
        match Table::parse_csv(text.as_bytes(), Path::new("f.csv")) {
            Ok(t) => {
                use_table(&t);
                prop_assert!(t.rows.iter().flatten().all(|v| v.is_finite()));
                prop_assert!(t.rows.iter().all(|r| r.len() == t.columns.len()));
            }
            Err(e) => prop_assert!(e.to_string().starts_with("f.csv")),
        }
    }

    #[test]
    fn mcap_reader_never_panics_on_bytes(
        bytes in prop::collection::vec(any::<u8>(), 0..400),
        magic in any::<bool>(),
    ) {
        let mut data = if magic { mcap::MAGIC.to_vec() } else { Vec::new() };
        data.extend_from_slice(&bytes);
        if let Ok(log) = McapLog::parse(&data, Path::new("f.mcap")) {
            use_log(&log);
        }
    }

    #[test]
    fn mcap_reader_never_panics_on_mutated_logs(
        flips in prop::collection::vec((any::<prop::sample::Index>(), any::<u8>()), 0..8),
        cut in prop::option::of(any::<prop::sample::Index>()),
    ) {
        let mut data = valid_mcap();
        for (at, byte) in &flips {
            let i = at.index(data.len());
            data[i] = *byte;
        }
        if let Some(c) = cut {
            data.truncate(c.index(data.len()));
        }
        if let Ok(log) = McapLog::parse(&data, Path::new("f.mcap")) {
            use_log(&log);
        }
    }

    #[test]
    fn model_loader_never_panics_on_bytes(bytes in prop::collection::vec(any::<u8>(), 0..300)) {
        let _ = ModelFile::from_json(&bytes, Path::new("m.json"));
    }

    #[test]
    fn model_loader_never_panics_on_mutated_models(
        edits in prop::collection::vec((any::<prop::sample::Index>(), json_value(), any::<bool>()), 1..4),
    ) {
        let (mut v, test) = valid_model();
        for (at, value, remove) in edits {
            let mut ptrs = Vec::new();
            pointers(&v, String::new(), &mut ptrs);
            let p = &ptrs[at.index(ptrs.len())];
            if remove && let Some((parent, key)) = p.rsplit_once('/')
                && let Some(Value::Object(m)) = v.pointer_mut(parent)
            {
                m.remove(key);
                continue;
            }
            if p.is_empty() {
                v = value;
            } else if let Some(slot) = v.pointer_mut(p) {
                *slot = value;
            }
        }
        let text = v.to_string();
        if let Ok(file) = ModelFile::from_json(text.as_bytes(), Path::new("m.json"))
            && let Ok(model) = file.to_model()
        {
            // an accepted model must simulate (or fail) without panicking
            let _ = model.simulate(&test);
            let _ = model.evaluate(&test);
        }
    }
}

#[test]
fn the_seed_files_are_valid() {
    let log = McapLog::parse(&valid_mcap(), Path::new("f.mcap")).expect("valid log");
    assert_eq!(log.topic_list(), "/a, /b, /c");
    let signals = [
        Signal::parse("/b:u", None).expect("signal"),
        Signal::parse("/a:x", None).expect("signal"),
    ];
    assert_eq!(
        log.table(&signals, "/a", TimeSource::Log)
            .expect("table")
            .len(),
        20
    );
    // the ROS 2 topic decodes, by log time and by header stamp (sec = k, log time = k ms)
    let ros2 = [
        Signal::parse("/c:v.1", None).expect("signal"),
        Signal::parse("/c:header.stamp.sec", None).expect("signal"),
    ];
    for time in [TimeSource::Log, TimeSource::Header] {
        let t = log.table(&ros2, "/c", time).expect("ros2 table");
        assert_eq!(t.len(), 20);
        let scale = if time == TimeSource::Log { 1e-3 } else { 1.0 };
        assert_eq!(
            t.rows[7],
            vec![7.0 * scale, 2.0 * (7.0f64 * 0.3).sin(), 7.0]
        );
    }
    let (v, test) = valid_model();
    let file = ModelFile::from_json(v.to_string().as_bytes(), Path::new("m.json")).expect("model");
    file.to_model()
        .expect("model")
        .simulate(&test)
        .expect("simulate");
}
