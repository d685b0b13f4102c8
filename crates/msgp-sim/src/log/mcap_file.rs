//! MCAP run logs with JSON-encoded messages and a 3D scene (opens in Foxglove).
//!
//! The signal channels use message encoding `json` and a schema with encoding `jsonschema`.
//! Each control step `k` produces one message on each topic, all with
//! `log_time = publish_time = round(t·10⁹)` ns and `sequence = k`:
//!
//! | topic | schema | fields |
//! |---|---|---|
//! | `/pendulum/measurement` | `msgp.pendulum.Measurement` | `step`, `t` \[s\], `theta` \[rad\], `x` \[m\] (noisy; what the controller sees) |
//! | `/pendulum/command` | `msgp.pendulum.Command` | `step`, `t` \[s\], `acceleration` \[m/s²\] (issued, clipped) |
//! | `/pendulum/latent` | `msgp.pendulum.Latent` | `step`, `t` \[s\], `theta` \[rad\], `theta_dot` \[rad/s\], `x` \[m\], `x_dot` \[m/s\], `lag_acceleration` \[m/s²\], `delayed_command` \[m/s²\] (**true latent state**, not measurable) |
//!
//! Two more channels carry the 3D scene in Foxglove's well-known schemas (protobuf encoded;
//! [`super::scene`]): `/pendulum/tf` (`foxglove.FrameTransforms`, every step: the end
//! effector and the pole from the true state) and `/pendulum/scene` (`foxglove.SceneUpdate`,
//! once at the first step: rail, end effector, pole and its centre of mass), so Foxglove's 3D
//! panel shows the pole move.
//!
//! The latent channel also carries the channel metadata `latent = true`. A metadata record
//! named `msgp.pendulum.episode` holds `format_version` (`"1"`) and `episode`: the
//! [`EpisodeInfo`] as JSON (parameters, seed, initial angle, controller, termination).
//! Chunks are zstd-compressed single-threaded, so the bytes do not depend on the machine.

use std::collections::{BTreeMap, HashMap};
use std::io::{Seek, Write};
use std::path::Path;

use foxglove::Encode;
use serde::{Deserialize, Serialize};

use crate::episode::{Episode, EpisodeInfo, Sample};
use crate::error::SimError;
use crate::log::RunLog;
use crate::log::scene;
use crate::plant::{LatentState, Measurement};

/// Topic of the noisy measurements.
pub const TOPIC_MEASUREMENT: &str = "/pendulum/measurement";
/// Topic of the issued commands.
pub const TOPIC_COMMAND: &str = "/pendulum/command";
/// Topic of the true latent states.
pub const TOPIC_LATENT: &str = "/pendulum/latent";
/// Name of the metadata record holding the [`EpisodeInfo`].
pub const METADATA_NAME: &str = "msgp.pendulum.episode";
/// Value of the `format_version` metadata key.
pub const FORMAT_VERSION: &str = "1";

const MEASUREMENT_SCHEMA: &str = r#"{"title":"msgp.pendulum.Measurement","description":"Noisy measurement seen by the controller","type":"object","properties":{"step":{"type":"integer","description":"control-step index"},"t":{"type":"number","description":"time [s]"},"theta":{"type":"number","description":"measured pole angle [rad], positive toward +x"},"x":{"type":"number","description":"measured end-effector position [m]"}},"required":["step","t","theta","x"]}"#;
const COMMAND_SCHEMA: &str = r#"{"title":"msgp.pendulum.Command","description":"Issued end-effector acceleration command","type":"object","properties":{"step":{"type":"integer","description":"control-step index"},"t":{"type":"number","description":"time [s]"},"acceleration":{"type":"number","description":"clipped acceleration command [m/s^2]"}},"required":["step","t","acceleration"]}"#;
const LATENT_SCHEMA: &str = r#"{"title":"msgp.pendulum.Latent","description":"True latent state (not measurable by the controller)","type":"object","properties":{"step":{"type":"integer","description":"control-step index"},"t":{"type":"number","description":"time [s]"},"theta":{"type":"number","description":"true pole angle [rad]"},"theta_dot":{"type":"number","description":"true pole angular velocity [rad/s]"},"x":{"type":"number","description":"true end-effector position [m]"},"x_dot":{"type":"number","description":"true end-effector velocity [m/s]"},"lag_acceleration":{"type":"number","description":"lag state = end-effector acceleration [m/s^2]"},"delayed_command":{"type":"number","description":"command applied during the next control period [m/s^2]"}},"required":["step","t","theta","theta_dot","x","x_dot","lag_acceleration","delayed_command"]}"#;

#[derive(Debug, Serialize, Deserialize)]
struct MeasurementMsg {
    step: u64,
    t: f64,
    theta: f64,
    x: f64,
}

#[derive(Debug, Serialize, Deserialize)]
struct CommandMsg {
    step: u64,
    t: f64,
    acceleration: f64,
}

#[derive(Debug, Serialize, Deserialize)]
struct LatentMsg {
    step: u64,
    t: f64,
    #[serde(flatten)]
    state: LatentState,
}

/// Writes `episode` to `path` atomically.
pub fn write(path: &Path, episode: &Episode) -> Result<(), SimError> {
    crate::atomic::write_atomically(path, |w| write_to(w, episode, path))
}

/// Encodes `episode` as MCAP bytes in memory; `path` is only used in error messages.
pub fn encode(episode: &Episode, path: &Path) -> Result<Vec<u8>, SimError> {
    let mut cursor = std::io::Cursor::new(Vec::new());
    write_to(&mut cursor, episode, path)?;
    Ok(cursor.into_inner())
}

fn write_to<W: Write + Seek>(w: W, episode: &Episode, path: &Path) -> Result<(), SimError> {
    let mut writer = mcap::WriteOptions::new()
        .compression(Some(mcap::Compression::Zstd))
        .compression_threads(0)
        .create(w)
        .map_err(mcap_err(path))?;
    let channels = Channels::add(&mut writer, path)?;
    let mut metadata = BTreeMap::new();
    metadata.insert("format_version".to_owned(), FORMAT_VERSION.to_owned());
    metadata.insert(
        "episode".to_owned(),
        serde_json::to_string(&episode.info).map_err(json_err(path))?,
    );
    writer
        .write_metadata(&mcap::records::Metadata {
            name: METADATA_NAME.to_owned(),
            metadata,
        })
        .map_err(mcap_err(path))?;
    for s in &episode.samples {
        channels.write_sample(&mut writer, s, episode, path)?;
    }
    writer.finish().map_err(mcap_err(path))?;
    Ok(())
}

/// An MCAP failure on `path`.
fn mcap_err(path: &Path) -> impl Fn(mcap::McapError) -> SimError + '_ {
    move |source| SimError::Mcap {
        path: path.to_owned(),
        source,
    }
}

/// A JSON failure on `path`.
fn json_err(path: &Path) -> impl Fn(serde_json::Error) -> SimError + '_ {
    move |source| SimError::Json {
        context: path.display().to_string(),
        source,
    }
}

/// A failure to encode the 3D scene's `what` on `path`.
fn scene_err(path: &Path, what: &'static str, message: String) -> SimError {
    SimError::Scene {
        path: path.to_owned(),
        what,
        message,
    }
}

/// The episode's channels: its signals (JSON) and the 3D scene (Foxglove's protobuf).
struct Channels {
    measurement: u16,
    command: u16,
    latent: u16,
    transforms: u16,
    scene: u16,
}

impl Channels {
    /// Adds every channel (and its schema) to `writer`.
    fn add<W: Write + Seek>(writer: &mut mcap::Writer<W>, path: &Path) -> Result<Self, SimError> {
        let mut channel = |name: &str, schema: &str, topic: &str, latent: bool| {
            let schema_id = writer
                .add_schema(name, "jsonschema", schema.as_bytes())
                .map_err(mcap_err(path))?;
            let mut meta = BTreeMap::new();
            if latent {
                meta.insert("latent".to_owned(), "true".to_owned());
            }
            writer
                .add_channel(schema_id, topic, "json", &meta)
                .map_err(mcap_err(path))
        };
        let measurement = channel(
            "msgp.pendulum.Measurement",
            MEASUREMENT_SCHEMA,
            TOPIC_MEASUREMENT,
            false,
        )?;
        let command = channel(
            "msgp.pendulum.Command",
            COMMAND_SCHEMA,
            TOPIC_COMMAND,
            false,
        )?;
        let latent = channel("msgp.pendulum.Latent", LATENT_SCHEMA, TOPIC_LATENT, true)?;
        let mut foxglove_channel = |topic: &str,
                                    what: &'static str,
                                    schema: Option<foxglove::Schema>,
                                    encoding: String| {
            let schema =
                schema.ok_or_else(|| scene_err(path, what, "the schema is missing".into()))?;
            let schema_id = writer
                .add_schema(&schema.name, &schema.encoding, &schema.data)
                .map_err(mcap_err(path))?;
            writer
                .add_channel(schema_id, topic, &encoding, &BTreeMap::new())
                .map_err(mcap_err(path))
        };
        let transforms = foxglove_channel(
            scene::TOPIC_TRANSFORMS,
            "FrameTransforms",
            foxglove::messages::FrameTransforms::get_schema(),
            foxglove::messages::FrameTransforms::get_message_encoding(),
        )?;
        let scene = foxglove_channel(
            scene::TOPIC_SCENE,
            "SceneUpdate",
            foxglove::messages::SceneUpdate::get_schema(),
            foxglove::messages::SceneUpdate::get_message_encoding(),
        )?;
        Ok(Self {
            measurement,
            command,
            latent,
            transforms,
            scene,
        })
    }

    /// One sample's messages: measurement, command, latent state and the scene's transforms
    /// (the scene itself with the episode's first sample).
    fn write_sample<W: Write + Seek>(
        &self,
        writer: &mut mcap::Writer<W>,
        s: &Sample,
        episode: &Episode,
        path: &Path,
    ) -> Result<(), SimError> {
        let time_ns = time_to_ns(s.t);
        // Sequence numbers are u32 in MCAP; they wrap after ~2.7 years at 50 Hz.
        let sequence = s.step as u32;
        let header = |channel_id| mcap::records::MessageHeader {
            channel_id,
            sequence,
            log_time: time_ns,
            publish_time: time_ns,
        };
        let json = json_err(path);
        let meas = serde_json::to_vec(&MeasurementMsg {
            step: s.step,
            t: s.t,
            theta: s.measurement.theta,
            x: s.measurement.x,
        })
        .map_err(&json)?;
        let cmd = serde_json::to_vec(&CommandMsg {
            step: s.step,
            t: s.t,
            acceleration: s.command,
        })
        .map_err(&json)?;
        let lat = serde_json::to_vec(&LatentMsg {
            step: s.step,
            t: s.t,
            state: s.latent,
        })
        .map_err(&json)?;
        let protobuf = |what: &'static str, msg: &dyn Fn(&mut Vec<u8>) -> Result<(), String>| {
            let mut buf = Vec::new();
            msg(&mut buf).map_err(|e| scene_err(path, what, e))?;
            Ok::<_, SimError>(buf)
        };
        let tf = scene::transforms(s.t, &s.latent);
        let tf = protobuf("FrameTransforms", &|b| {
            tf.encode(b).map_err(|e| e.to_string())
        })?;
        let mut messages = vec![
            (self.measurement, meas),
            (self.command, cmd),
            (self.latent, lat),
            (self.transforms, tf),
        ];
        if s.step == episode.samples[0].step {
            let update = scene::scene(&episode.info.params, s.t);
            let update = protobuf("SceneUpdate", &|b| {
                update.encode(b).map_err(|e| e.to_string())
            })?;
            messages.push((self.scene, update));
        }
        for (channel, data) in messages {
            writer
                .write_to_known_channel(&header(channel), &data)
                .map_err(mcap_err(path))?;
        }
        Ok(())
    }
}

/// Nanoseconds for a non-negative time in seconds.
fn time_to_ns(t: f64) -> u64 {
    // Episode times are within 0..=86400 s, far inside u64 nanoseconds.
    (t * 1e9).round().max(0.0) as u64
}

#[derive(Default)]
struct Partial {
    t: Option<f64>,
    measurement: Option<Measurement>,
    command: Option<f64>,
    latent: Option<LatentState>,
}

/// Parses MCAP bytes written by [`write()`]; `path` is only used in error messages. Messages
/// on other topics are ignored.
pub fn decode(bytes: &[u8], path: &Path) -> Result<RunLog, SimError> {
    let mcap_err = |source| SimError::Mcap {
        path: path.to_owned(),
        source,
    };
    let malformed = |reason: String| SimError::MalformedLog {
        path: path.to_owned(),
        reason,
    };
    let json_err = |topic: &str| {
        let context = format!("{} topic {topic}", path.display());
        move |source| SimError::Json { context, source }
    };
    let mut steps: BTreeMap<u64, Partial> = BTreeMap::new();
    for message in mcap::MessageStream::new(bytes).map_err(mcap_err)? {
        let message = message.map_err(mcap_err)?;
        let topic = message.channel.topic.as_str();
        let data = message.data.as_ref();
        match topic {
            TOPIC_MEASUREMENT => {
                let m: MeasurementMsg = serde_json::from_slice(data).map_err(json_err(topic))?;
                let entry = steps.entry(m.step).or_default();
                entry.t = Some(m.t);
                entry.measurement = Some(Measurement {
                    theta: m.theta,
                    x: m.x,
                });
            }
            TOPIC_COMMAND => {
                let m: CommandMsg = serde_json::from_slice(data).map_err(json_err(topic))?;
                let entry = steps.entry(m.step).or_default();
                entry.t = Some(m.t);
                entry.command = Some(m.acceleration);
            }
            TOPIC_LATENT => {
                let m: LatentMsg = serde_json::from_slice(data).map_err(json_err(topic))?;
                let entry = steps.entry(m.step).or_default();
                entry.t = Some(m.t);
                entry.latent = Some(m.state);
            }
            _ => {}
        }
    }
    let mut samples = Vec::with_capacity(steps.len());
    for (step, p) in steps {
        match (p.t, p.measurement, p.command, p.latent) {
            (Some(t), Some(measurement), Some(command), Some(latent)) => samples.push(Sample {
                step,
                t,
                command,
                measurement,
                latent,
            }),
            _ => {
                return Err(malformed(format!(
                    "step {step} lacks a message on one of {TOPIC_MEASUREMENT}, {TOPIC_COMMAND}, {TOPIC_LATENT}"
                )));
            }
        }
    }
    Ok(RunLog {
        info: read_info(bytes, path)?,
        samples,
    })
}

/// The [`EpisodeInfo`] metadata record, if the file has one.
fn read_info(bytes: &[u8], path: &Path) -> Result<Option<EpisodeInfo>, SimError> {
    let mcap_err = |source| SimError::Mcap {
        path: path.to_owned(),
        source,
    };
    let Some(summary) = mcap::Summary::read(bytes).map_err(mcap_err)? else {
        return Ok(None);
    };
    for index in summary
        .metadata_indexes
        .iter()
        .filter(|i| i.name == METADATA_NAME)
    {
        let record = mcap::read::metadata(bytes, index).map_err(mcap_err)?;
        let fields: HashMap<_, _> = record.metadata.into_iter().collect();
        if let Some(json) = fields.get("episode") {
            let info = serde_json::from_str(json).map_err(|source| SimError::Json {
                context: format!("{} metadata {METADATA_NAME}", path.display()),
                source,
            })?;
            return Ok(Some(info));
        }
    }
    Ok(None)
}
