//! Episodes (seeding, delay, noise) and run logs (CSV/MCAP bytes, read-back).

use std::path::PathBuf;

use msgp_sim::log::mcap_file::{TOPIC_COMMAND, TOPIC_LATENT, TOPIC_MEASUREMENT};
use msgp_sim::log::scene::{TOPIC_SCENE, TOPIC_TRANSFORMS};
use msgp_sim::{
    Episode, EpisodeConfig, ExcitationConfig, LogFormat, PendulumParams, PidPdGains, PidPdPolicy,
    PlantTier, RandomExcitation, SimError, Termination, encode_run, read_run, run_episode,
    write_run,
};

fn scratch_dir(tag: &str) -> PathBuf {
    let dir = std::env::temp_dir().join(format!("msgp-sim-{tag}-{}", std::process::id()));
    std::fs::create_dir_all(&dir).expect("create scratch dir");
    dir
}

fn policy_episode(seed: u64, seconds: f64) -> Episode {
    let params = PendulumParams::tier(PlantTier::Noisy);
    let mut policy = PidPdPolicy::new(PidPdGains::hand_tuned(), &params).expect("valid gains");
    run_episode(
        &params,
        &mut policy,
        &EpisodeConfig {
            seconds,
            seed,
            initial_theta: None,
        },
    )
    .expect("episode runs")
}

fn random_episode(seed: u64, seconds: f64) -> Episode {
    let params = PendulumParams::tier(PlantTier::Noisy);
    let mut excitation =
        RandomExcitation::new(seed, &ExcitationConfig::default()).expect("valid config");
    run_episode(
        &params,
        &mut excitation,
        &EpisodeConfig {
            seconds,
            seed,
            initial_theta: None,
        },
    )
    .expect("episode runs")
}

#[test]
fn same_seed_gives_identical_bytes() {
    let dir = scratch_dir("determinism");
    for (name, make) in [
        ("policy", policy_episode as fn(u64, f64) -> Episode),
        ("random", random_episode),
    ] {
        let a = make(11, 3.0);
        let b = make(11, 3.0);
        let c = make(12, 3.0);
        for ext in ["csv", "mcap"] {
            let pa = dir.join(format!("{name}-a.{ext}"));
            let pb = dir.join(format!("{name}-b.{ext}"));
            write_run(&pa, &a).expect("write a");
            write_run(&pb, &b).expect("write b");
            let bytes_a = std::fs::read(&pa).expect("read a");
            let bytes_b = std::fs::read(&pb).expect("read b");
            assert!(!bytes_a.is_empty());
            assert!(
                bytes_a == bytes_b,
                "{name}.{ext}: same seed, different bytes"
            );
            let format = LogFormat::from_path(&pa).expect("known extension");
            assert_eq!(encode_run(format, &a).expect("encode"), bytes_a);
            assert_ne!(
                encode_run(format, &c).expect("encode"),
                bytes_a,
                "{name}.{ext}: seed has no effect"
            );
        }
    }
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn logs_read_back_exactly() {
    let dir = scratch_dir("readback");
    let episode = random_episode(3, 5.0);
    for ext in ["csv", "mcap"] {
        let path = dir.join(format!("run.{ext}"));
        write_run(&path, &episode).expect("write");
        let log = read_run(&path).expect("read back");
        assert_eq!(log.samples, episode.samples, "{ext} samples differ");
        if ext == "mcap" {
            assert_eq!(log.info.as_ref(), Some(&episode.info));
        } else {
            assert!(log.info.is_none());
        }
    }
    let entries: Vec<_> = std::fs::read_dir(&dir).expect("list").collect();
    assert_eq!(entries.len(), 2, "temporary files left behind");
    std::fs::remove_dir_all(&dir).expect("cleanup");
}

#[test]
fn mcap_has_documented_topics_and_json_schemas() {
    let episode = policy_episode(5, 1.0);
    let bytes = encode_run(LogFormat::Mcap, &episode).expect("encode");
    let summary = mcap::Summary::read(&bytes)
        .expect("summary parses")
        .expect("summary present");
    let mut topics: Vec<_> = summary.channels.values().map(|c| c.topic.clone()).collect();
    topics.sort();
    assert_eq!(
        topics,
        vec![
            TOPIC_COMMAND,
            TOPIC_LATENT,
            TOPIC_MEASUREMENT,
            TOPIC_SCENE,
            TOPIC_TRANSFORMS
        ]
    );
    for channel in summary.channels.values() {
        if [TOPIC_SCENE, TOPIC_TRANSFORMS].contains(&channel.topic.as_str()) {
            // the 3D scene: Foxglove's well-known protobuf schemas
            let schema = channel.schema.as_ref().expect("schema present");
            assert_eq!(
                (channel.message_encoding.as_str(), schema.encoding.as_str()),
                ("protobuf", "protobuf")
            );
            let expected = if channel.topic == TOPIC_SCENE {
                "foxglove.SceneUpdate"
            } else {
                "foxglove.FrameTransforms"
            };
            assert_eq!(schema.name, expected);
            continue;
        }
        assert_eq!(channel.message_encoding, "json");
        let schema = channel.schema.as_ref().expect("schema present");
        assert_eq!(schema.encoding, "jsonschema");
        let parsed: serde_json::Value =
            serde_json::from_slice(&schema.data).expect("schema is JSON");
        assert_eq!(parsed["type"], "object");
        assert_eq!(
            channel.metadata.get("latent").map(String::as_str),
            (channel.topic == TOPIC_LATENT).then_some("true")
        );
    }
    let stats = summary.stats.expect("statistics present");
    // per step three signals and a transform, and the scene once
    assert_eq!(stats.message_count, 4 * episode.samples.len() as u64 + 1);
    // Messages are plain JSON objects with the documented fields and nanosecond log times.
    let mut seen = 0;
    for message in mcap::MessageStream::new(&bytes).expect("stream") {
        let message = message.expect("message parses");
        if message.channel.message_encoding == "protobuf" {
            continue;
        }
        let value: serde_json::Value = serde_json::from_slice(&message.data).expect("JSON body");
        let step = value["step"].as_u64().expect("step field") as usize;
        let sample = &episode.samples[step];
        assert_eq!(message.log_time, (sample.t * 1e9).round() as u64);
        match message.channel.topic.as_str() {
            TOPIC_MEASUREMENT => {
                assert_eq!(value["theta"].as_f64(), Some(sample.measurement.theta));
                assert_eq!(value["x"].as_f64(), Some(sample.measurement.x));
            }
            TOPIC_COMMAND => assert_eq!(value["acceleration"].as_f64(), Some(sample.command)),
            TOPIC_LATENT => {
                assert_eq!(value["theta_dot"].as_f64(), Some(sample.latent.theta_dot));
                assert_eq!(
                    value["lag_acceleration"].as_f64(),
                    Some(sample.latent.lag_acceleration)
                );
            }
            other => panic!("unexpected topic {other}"),
        }
        seen += 1;
    }
    assert_eq!(seen, 3 * episode.samples.len());
}

#[test]
fn episode_structure_delay_and_noise() {
    let params = PendulumParams::tier(PlantTier::Noisy);
    let episode = policy_episode(21, 20.0);
    assert_eq!(episode.info.termination, Termination::Completed);
    assert_eq!(episode.samples.len(), 1001);
    let mut err_theta = Vec::new();
    let mut err_x = Vec::new();
    for (k, pair) in episode.samples.windows(2).enumerate() {
        let (prev, cur) = (&pair[0], &pair[1]);
        assert_eq!(cur.step, k as u64 + 1);
        assert!((cur.t - cur.step as f64 * 0.02).abs() < 1e-12);
        // One control step of delay: the command waiting at row k+1 is the one issued at k.
        assert_eq!(cur.latent.delayed_command, prev.command);
        assert!(cur.command.abs() <= params.action_limit);
    }
    for s in &episode.samples {
        err_theta.push(s.measurement.theta - s.latent.theta);
        err_x.push(s.measurement.x - s.latent.x);
    }
    let std = |v: &[f64]| {
        let mean = v.iter().sum::<f64>() / v.len() as f64;
        (v.iter().map(|e| (e - mean).powi(2)).sum::<f64>() / v.len() as f64).sqrt()
    };
    let (st, sx) = (std(&err_theta), std(&err_x));
    assert!(
        (st / params.sigma_theta - 1.0).abs() < 0.1,
        "theta noise std {st}"
    );
    assert!((sx / params.sigma_x - 1.0).abs() < 0.1, "x noise std {sx}");
    assert_eq!(episode.samples[0].latent.delayed_command, 0.0);
    assert_eq!(episode.samples[0].latent.x, 0.0);
}

#[test]
fn random_excitation_is_clipped_and_stops_early() {
    let params = PendulumParams::tier(PlantTier::Noisy);
    let mut stopped = 0;
    for seed in 0..4 {
        let episode = random_episode(seed, 30.0);
        let last = episode.samples.last().expect("non-empty");
        match episode.info.termination {
            Termination::ThetaLimit => {
                assert!(last.latent.theta.abs() > params.stop_theta);
                stopped += 1;
            }
            Termination::PositionLimit => {
                assert!(last.latent.x.abs() > params.stop_x);
                stopped += 1;
            }
            Termination::Completed => {}
        }
        for s in &episode.samples {
            assert!(s.command.abs() <= params.action_limit);
            assert!(s.latent.theta.abs() <= params.stop_theta + 0.2);
        }
    }
    assert_eq!(stopped, 4, "an unbalanced pole should fall within 30 s");
}

#[test]
fn initial_angle_distribution() {
    let params = PendulumParams::tier(PlantTier::Noisy);
    let mut policy = PidPdPolicy::new(PidPdGains::default(), &params).expect("valid");
    let angles: Vec<f64> = (0..400)
        .map(|seed| {
            run_episode(
                &params,
                &mut policy,
                &EpisodeConfig {
                    seconds: 0.0,
                    seed,
                    initial_theta: None,
                },
            )
            .expect("episode")
            .info
            .initial_theta
        })
        .collect();
    let mean = angles.iter().sum::<f64>() / angles.len() as f64;
    let std = (angles.iter().map(|a| a * a).sum::<f64>() / angles.len() as f64).sqrt();
    assert!(mean.abs() < 0.004, "mean {mean}");
    assert!((std / 0.02 - 1.0).abs() < 0.12, "std {std}");
}

#[test]
fn bad_inputs_are_errors_not_panics() {
    let episode = policy_episode(1, 0.1);
    let dir = scratch_dir("errors");
    assert!(matches!(
        write_run(&dir.join("run.txt"), &episode),
        Err(SimError::UnsupportedExtension { .. })
    ));
    assert!(matches!(
        read_run(&dir.join("missing.csv")),
        Err(SimError::Io { .. })
    ));
    std::fs::write(dir.join("junk.mcap"), b"not an mcap").expect("write junk");
    assert!(read_run(&dir.join("junk.mcap")).is_err());
    std::fs::write(dir.join("junk.csv"), b"a,b\n1,2\n").expect("write junk");
    assert!(matches!(
        read_run(&dir.join("junk.csv")),
        Err(SimError::MalformedLog { .. })
    ));
    assert!(write_run(&dir.join("no-such-dir").join("run.csv"), &episode).is_err());
    let params = PendulumParams::tier(PlantTier::Noisy);
    let mut policy = PidPdPolicy::new(PidPdGains::default(), &params).expect("valid");
    for seconds in [-1.0, f64::NAN, 1e9] {
        let config = EpisodeConfig {
            seconds,
            seed: 0,
            initial_theta: None,
        };
        assert!(run_episode(&params, &mut policy, &config).is_err());
    }
    let config = EpisodeConfig {
        seconds: 1.0,
        seed: 0,
        initial_theta: Some(3.0),
    };
    assert!(run_episode(&params, &mut policy, &config).is_err());
    std::fs::remove_dir_all(&dir).expect("cleanup");
}
