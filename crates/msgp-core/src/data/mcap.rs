//! MCAP logs as numeric signals: channels with JSON-encoded messages, fields chosen by dotted
//! path, messages ordered by log time, several topics aligned onto one time base.
//!
//! A [`Signal`] is `TOPIC:FIELD`, e.g. `/pendulum/measurement:theta` or
//! `/robot/state:pose.position.x`; array elements are addressed by index (`joints.2` or
//! `joints[2]`). [`McapLog::table`] turns signals into a [`Table`] with a time column `t`
//! (log time in seconds) and one column per signal named `TOPIC:FIELD`:
//!
//! - the rows are the messages of the *base* topic, in log-time order (ties keep file order);
//! - every other topic contributes its latest message with `log_time ≤` the row's log time
//!   (sample and hold); base messages older than the first message of some other topic are
//!   dropped. Logs that stamp all messages of one step with the same log time — such as the
//!   `msgp sim` logs — are thus joined step by step.
//!
//! Two message encodings are read: `json`, and ROS 2's `cdr` with a `ros2msg` schema (decoded
//! from the schema text by [`super::ros2`] into the same JSON values, so the paths are the same:
//! `/joint_states:position.2`). A topic with another encoding (protobuf, ...) is reported as
//! an error when selected.
//!
//! The time of a message is its log time, or with [`TimeSource::Header`] the
//! `header.stamp` (`sec` + `nanosec`) inside it, as ROS messages with a header carry it; every
//! selected topic must then have one. Corrupt or truncated files, unknown
//! topics, unknown fields and non-numeric values are errors that name the file, the topic, the
//! message and the field; nothing here panics on bad input, and a corrupt length field cannot
//! make it allocate more than 64 × the file size (at most 1 GiB) per record.

use std::collections::HashMap;
use std::fmt;
use std::path::{Path, PathBuf};

use serde_json::Value;

use super::ros2::{self, Ros2Decoder};
use super::table::{Table, TimeSource};
use crate::error::{MsgpError, Result};

/// One channel of the log.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct TopicInfo {
    /// Topic name.
    pub topic: String,
    /// Message encoding (`json`, `cdr`, ...).
    pub encoding: String,
    /// Schema name, if the channel has a schema.
    pub schema: Option<String>,
    /// Schema encoding (`ros2msg`, `jsonschema`, ...; empty without a schema).
    pub schema_encoding: String,
    /// Schema text (empty without a schema).
    pub schema_data: Vec<u8>,
    /// Number of messages.
    pub messages: usize,
    /// The channel metadata says `latent = true` (a simulator's hidden state).
    pub latent: bool,
}

impl TopicInfo {
    /// Whether its messages can be decoded (JSON, or ROS 2 CDR with its `ros2msg` schema).
    pub fn readable(&self) -> bool {
        self.encoding == "json"
            || (self.encoding == ros2::MESSAGE_ENCODING
                && self.schema_encoding == ros2::SCHEMA_ENCODING)
    }
}

/// `TOPIC:FIELD`: one numeric field of the messages on one topic.
#[derive(Clone, Debug, PartialEq, Eq, Hash)]
pub struct Signal {
    /// Topic name.
    pub topic: String,
    /// Dotted path of the field inside each message (`pose.position.x`, `data.0`).
    pub field: String,
}

impl Signal {
    /// Parses `TOPIC:FIELD` (split at the last `:`), or a bare `FIELD` on `default_topic`.
    pub fn parse(spec: &str, default_topic: Option<&str>) -> Result<Self> {
        let spec = spec.trim();
        let (topic, field) = match spec.rsplit_once(':') {
            Some((t, f)) => (t.to_string(), f.to_string()),
            None => match default_topic {
                Some(t) => (t.to_string(), spec.to_string()),
                None => {
                    return Err(MsgpError::InvalidSetting {
                        name: "MCAP signal",
                        reason: format!(
                            "`{spec}` names no topic: write TOPIC:FIELD or give a default topic"
                        ),
                    });
                }
            },
        };
        let field = normalize_path(&field);
        if topic.is_empty() || field.is_empty() {
            return Err(MsgpError::InvalidSetting {
                name: "MCAP signal",
                reason: format!("`{spec}` needs a non-empty topic and field (TOPIC:FIELD)"),
            });
        }
        Ok(Self { topic, field })
    }

    /// The column name `TOPIC:FIELD`.
    pub fn name(&self) -> String {
        format!("{}:{}", self.topic, self.field)
    }
}

impl fmt::Display for Signal {
    fn fmt(&self, f: &mut fmt::Formatter<'_>) -> fmt::Result {
        write!(f, "{}:{}", self.topic, self.field)
    }
}

/// `a[2].b` → `a.2.b`.
fn normalize_path(field: &str) -> String {
    field
        .replace('[', ".")
        .replace(']', "")
        .split('.')
        .filter(|s| !s.is_empty())
        .collect::<Vec<_>>()
        .join(".")
}

/// Largest record (or decompressed chunk) accepted, for a file of `len` bytes: 64 × the file
/// size, at least 1 MiB and at most 1 GiB. A corrupt length field then gives an error instead
/// of an attempt to allocate exabytes.
fn record_limit(len: usize) -> usize {
    len.saturating_mul(64).clamp(1 << 20, 1 << 30)
}

#[derive(Clone, Debug)]
struct RawMessage {
    topic: usize,
    log_time: u64,
    data: Vec<u8>,
}

/// An MCAP file read into memory: channels and messages sorted by log time.
#[derive(Clone, Debug)]
pub struct McapLog {
    /// Where it came from (for messages).
    pub path: PathBuf,
    /// Channels by first appearance (one entry per topic).
    pub topics: Vec<TopicInfo>,
    messages: Vec<RawMessage>,
}

fn file_err(path: &Path, message: String) -> MsgpError {
    MsgpError::File {
        path: path.to_path_buf(),
        message,
    }
}

impl McapLog {
    /// Reads an MCAP file.
    pub fn read(path: &Path) -> Result<Self> {
        let bytes = std::fs::read(path).map_err(|e| file_err(path, format!("cannot read: {e}")))?;
        Self::parse(&bytes, path)
    }

    /// Parses MCAP bytes; `path` is only used in messages.
    pub fn parse(bytes: &[u8], path: &Path) -> Result<Self> {
        let corrupt =
            |e: mcap::McapError| file_err(path, format!("corrupt or truncated MCAP file: {e}"));
        if bytes.is_empty() {
            return Err(file_err(path, "empty file: not an MCAP log".into()));
        }
        if !bytes.starts_with(mcap::MAGIC) {
            return Err(file_err(
                path,
                "not an MCAP file (the file does not start with the MCAP magic bytes)".into(),
            ));
        }
        let mut topics: Vec<TopicInfo> = Vec::new();
        let mut by_topic: HashMap<String, usize> = HashMap::new();
        let mut messages = Vec::new();
        let mut reader = mcap::sans_io::MessageReader::new_with_options(
            mcap::sans_io::LinearReaderOptions::default()
                .with_record_length_limit(record_limit(bytes.len())),
        );
        let mut rest = bytes;
        while let Some(event) = reader.next_event() {
            let message = match event.map_err(corrupt)? {
                mcap::sans_io::MessageReadEvent::ReadRequest(need) => {
                    let n = need.min(rest.len());
                    reader.insert(n).copy_from_slice(&rest[..n]);
                    reader.notify_read(n);
                    rest = &rest[n..];
                    continue;
                }
                mcap::sans_io::MessageReadEvent::Message(m) => m,
            };
            let ch = &message.channel;
            let k = match by_topic.get(&ch.topic) {
                Some(&k) => {
                    if topics[k].encoding != ch.message_encoding {
                        return Err(file_err(
                            path,
                            format!(
                                "topic {} has channels with different message encodings ({} and {})",
                                ch.topic, topics[k].encoding, ch.message_encoding
                            ),
                        ));
                    }
                    k
                }
                None => {
                    by_topic.insert(ch.topic.clone(), topics.len());
                    topics.push(TopicInfo {
                        topic: ch.topic.clone(),
                        encoding: ch.message_encoding.clone(),
                        schema: ch.schema.as_ref().map(|s| s.name.clone()),
                        schema_encoding: ch
                            .schema
                            .as_ref()
                            .map(|s| s.encoding.clone())
                            .unwrap_or_default(),
                        schema_data: ch
                            .schema
                            .as_ref()
                            .map(|s| s.data.to_vec())
                            .unwrap_or_default(),
                        messages: 0,
                        latent: ch.metadata.get("latent").is_some_and(|v| v == "true"),
                    });
                    topics.len() - 1
                }
            };
            topics[k].messages += 1;
            messages.push(RawMessage {
                topic: k,
                log_time: message.log_time,
                data: message.data.into_owned(),
            });
        }
        if messages.is_empty() {
            return Err(file_err(path, "the MCAP file has no messages".into()));
        }
        // stable: equal log times keep file order
        messages.sort_by_key(|m| m.log_time);
        Ok(Self {
            path: path.to_path_buf(),
            topics,
            messages,
        })
    }

    /// Topic names, comma-separated (for messages).
    pub fn topic_list(&self) -> String {
        self.topics
            .iter()
            .map(|t| t.topic.as_str())
            .collect::<Vec<_>>()
            .join(", ")
    }

    fn topic_index(&self, topic: &str) -> Result<usize> {
        self.topics
            .iter()
            .position(|t| t.topic == topic)
            .ok_or_else(|| {
                file_err(
                    &self.path,
                    format!("no topic `{topic}` (topics: {})", self.topic_list()),
                )
            })
    }

    /// The channel of `topic`.
    pub fn topic(&self, topic: &str) -> Result<&TopicInfo> {
        Ok(&self.topics[self.topic_index(topic)?])
    }

    /// The decoder of topic `k`'s messages, or an error if its encoding is not read.
    fn decoder(&self, k: usize) -> Result<Decoder> {
        let info = &self.topics[k];
        match (
            info.readable(),
            info.encoding.as_str(),
            info.schema_encoding.as_str(),
        ) {
            (true, "json", _) => Ok(Decoder::Json),
            (true, _, _) => {
                let name = info.schema.as_deref().unwrap_or_default();
                Ros2Decoder::new(name, &info.schema_data)
                    .map(Decoder::Ros2)
                    .map_err(|e| file_err(&self.path, format!("topic {}: {e}", info.topic)))
            }
            (false, encoding, schema) => Err(file_err(
                &self.path,
                format!(
                    "topic {} uses message encoding `{encoding}`{}; supported are `json` and ROS 2 \
                     `cdr` with a `ros2msg` schema",
                    info.topic,
                    if schema.is_empty() {
                        " without a schema".to_string()
                    } else {
                        format!(" with a `{schema}` schema")
                    }
                ),
            )),
        }
    }

    /// Messages of topic `k` decoded into JSON values, in log-time order, with their times
    /// (nanoseconds, from `time`); with [`TimeSource::Header`] ordered by that time.
    fn decoded(&self, k: usize, time: TimeSource) -> Result<Vec<(u64, Value)>> {
        let info = &self.topics[k];
        let decoder = self.decoder(k)?;
        let mut out = self
            .messages
            .iter()
            .filter(|m| m.topic == k)
            .enumerate()
            .map(|(i, m)| {
                let here = || {
                    format!(
                        "topic {} message {} (log time {} ns)",
                        info.topic,
                        i + 1,
                        m.log_time
                    )
                };
                let v = decoder
                    .decode(&m.data)
                    .map_err(|e| file_err(&self.path, format!("{}: {e}", here())))?;
                let t = match time {
                    TimeSource::Log => m.log_time,
                    TimeSource::Header => header_stamp(&v).ok_or_else(|| {
                        file_err(
                            &self.path,
                            format!(
                                "{}: no `header.stamp` (sec, nanosec) to take the time from; \
                                 use the log time (--time log)",
                                here()
                            ),
                        )
                    })?,
                };
                Ok((t, v))
            })
            .collect::<Result<Vec<_>>>()?;
        if time == TimeSource::Header {
            // stable: equal stamps keep log order
            out.sort_by_key(|(t, _)| *t);
        }
        Ok(out)
    }

    /// Dotted paths of the numeric fields of the first message on `topic`.
    pub fn numeric_fields(&self, topic: &str) -> Result<Vec<String>> {
        let k = self.topic_index(topic)?;
        let first = self
            .messages
            .iter()
            .find(|m| m.topic == k)
            .ok_or_else(|| file_err(&self.path, format!("topic {} has no messages", topic)))?;
        let v = self
            .decoder(k)?
            .decode(&first.data)
            .map_err(|e| file_err(&self.path, format!("topic {topic} message 1: {e}")))?;
        let mut out = Vec::new();
        numeric_leaves(&v, String::new(), &mut out);
        Ok(out)
    }

    /// Aligns `signals` onto the messages of `base_topic` (see the module docs): columns `t`
    /// (the message time from `time`, in seconds) and one per signal, named `TOPIC:FIELD`.
    pub fn table(&self, signals: &[Signal], base_topic: &str, time: TimeSource) -> Result<Table> {
        let base = self.topic_index(base_topic)?;
        // topics in use, base first
        let mut used = vec![base];
        for s in signals {
            let k = self.topic_index(&s.topic)?;
            if !used.contains(&k) {
                used.push(k);
            }
        }
        // per used topic: (log times, one value column per signal on that topic)
        let mut series: Vec<(Vec<u64>, Vec<Vec<f64>>)> = Vec::with_capacity(used.len());
        for &k in &used {
            let msgs = self.decoded(k, time)?;
            let topic = &self.topics[k].topic;
            let fields: Vec<&Signal> = signals.iter().filter(|s| &s.topic == topic).collect();
            let mut cols = vec![Vec::with_capacity(msgs.len()); fields.len()];
            for (i, (log_time, v)) in msgs.iter().enumerate() {
                for (c, s) in fields.iter().enumerate() {
                    cols[c].push(self.field_value(v, s, i, *log_time)?);
                }
            }
            series.push((msgs.iter().map(|(t, _)| *t).collect(), cols));
        }
        let mut columns = vec!["t".to_string()];
        columns.extend(signals.iter().map(Signal::name));
        // where each signal lives: (index into `used`/`series`, column there)
        let mut place = Vec::with_capacity(signals.len());
        for s in signals {
            let k = self.topic_index(&s.topic)?;
            let u = used.iter().position(|&x| x == k).unwrap_or(0);
            let col = signals[..]
                .iter()
                .filter(|o| o.topic == s.topic)
                .position(|o| o == s)
                .unwrap_or(0);
            place.push((u, col));
        }
        let (base_times, _) = &series[0];
        let mut cursor = vec![0usize; series.len()];
        let mut rows = Vec::with_capacity(base_times.len());
        let mut lines = Vec::with_capacity(base_times.len());
        for (i, &tau) in base_times.iter().enumerate() {
            // latest message at or before tau on every other topic
            let mut latest = vec![Some(i); series.len()];
            for u in 1..series.len() {
                let times = &series[u].0;
                while cursor[u] < times.len() && times[cursor[u]] <= tau {
                    cursor[u] += 1;
                }
                latest[u] = cursor[u].checked_sub(1);
            }
            if latest.iter().any(Option::is_none) {
                continue;
            }
            let mut row = Vec::with_capacity(columns.len());
            row.push(tau as f64 * 1e-9);
            for &(u, col) in &place {
                let j = latest[u].unwrap_or(0);
                row.push(series[u].1[col][j]);
            }
            rows.push(row);
            lines.push(i as u64 + 1);
        }
        if rows.is_empty() {
            return Err(file_err(
                &self.path,
                format!(
                    "no message of {base_topic} comes at or after a message of every selected topic"
                ),
            ));
        }
        Ok(Table {
            path: self.path.clone(),
            columns,
            rows,
            lines,
        })
    }

    fn field_value(&self, v: &Value, s: &Signal, i: usize, log_time: u64) -> Result<f64> {
        let here = || {
            format!(
                "topic {} message {} (log time {log_time} ns)",
                s.topic,
                i + 1
            )
        };
        let Some(x) = lookup(v, &s.field) else {
            let mut fields = Vec::new();
            numeric_leaves(v, String::new(), &mut fields);
            return Err(file_err(
                &self.path,
                format!(
                    "{}: no field `{}` (numeric fields: {})",
                    here(),
                    s.field,
                    if fields.is_empty() {
                        "none".to_string()
                    } else {
                        fields.join(", ")
                    }
                ),
            ));
        };
        let value = match x {
            Value::Number(n) => n.as_f64(),
            _ => None,
        };
        match value {
            Some(f) if f.is_finite() => Ok(f),
            _ => Err(file_err(
                &self.path,
                format!(
                    "{}: field `{}` is {}, not a finite number",
                    here(),
                    s.field,
                    describe(x)
                ),
            )),
        }
    }
}

/// How a message's JSON value is made from its bytes.
#[derive(Debug)]
enum Decoder {
    Json,
    Ros2(Ros2Decoder),
}

impl Decoder {
    fn decode(&self, data: &[u8]) -> std::result::Result<Value, String> {
        match self {
            Self::Json => serde_json::from_slice(data).map_err(|e| format!("invalid JSON: {e}")),
            Self::Ros2(d) => d.decode(data),
        }
    }
}

/// `header.stamp` in nanoseconds (`sec` may be negative only as far as the sum is not).
fn header_stamp(v: &Value) -> Option<u64> {
    let stamp = v.get("header")?.get("stamp")?;
    let sec = stamp.get("sec")?.as_i64()?;
    let nanosec = stamp.get("nanosec")?.as_u64()?;
    let ns = i128::from(sec) * 1_000_000_000 + i128::from(nanosec);
    u64::try_from(ns).ok()
}

fn describe(v: &Value) -> String {
    match v {
        Value::Null => "null (JSON null, or NaN/inf in a binary message)".into(),
        Value::Bool(b) => format!("the boolean {b}"),
        Value::Number(n) => format!("the number {n}"),
        Value::String(s) => format!("the string {s:?}"),
        Value::Array(_) => "an array".into(),
        Value::Object(_) => "an object".into(),
    }
}

/// The value at a dotted path (`a.b.0.c`).
fn lookup<'v>(v: &'v Value, path: &str) -> Option<&'v Value> {
    path.split('.').try_fold(v, |cur, seg| match cur {
        Value::Object(map) => map.get(seg),
        Value::Array(items) => seg.parse::<usize>().ok().and_then(|i| items.get(i)),
        _ => None,
    })
}

/// Collects the dotted paths of all numeric leaves.
fn numeric_leaves(v: &Value, prefix: String, out: &mut Vec<String>) {
    let join = |seg: &str| {
        if prefix.is_empty() {
            seg.to_string()
        } else {
            format!("{prefix}.{seg}")
        }
    };
    match v {
        Value::Number(_) if !prefix.is_empty() => out.push(prefix),
        Value::Object(map) => {
            for (k, x) in map {
                numeric_leaves(x, join(k), out);
            }
        }
        Value::Array(items) => {
            for (i, x) in items.iter().enumerate() {
                numeric_leaves(x, join(&i.to_string()), out);
            }
        }
        _ => {}
    }
}

#[cfg(test)]
mod tests {
    use std::collections::BTreeMap;

    use super::*;

    /// A small log: /a at t = 1, 2, 3 ms (fields x, nested p.q, arr), /b at 0 and 2 ms (u).
    fn sample() -> Vec<u8> {
        let mut buf = std::io::Cursor::new(Vec::new());
        {
            let mut w = mcap::Writer::new(&mut buf).expect("writer");
            let meta = BTreeMap::new();
            let a = w.add_channel(0, "/a", "json", &meta).expect("channel a");
            let b = w.add_channel(0, "/b", "json", &meta).expect("channel b");
            let c = w.add_channel(0, "/c", "cdr", &meta).expect("channel c");
            let msg = |ch, t: u64| mcap::records::MessageHeader {
                channel_id: ch,
                sequence: 0,
                log_time: t,
                publish_time: t,
            };
            // written out of order: the reader sorts by log time
            for (t, x) in [(3_000_000u64, 3.0), (1_000_000, 1.0), (2_000_000, 2.0)] {
                let body = format!(
                    r#"{{"x": {x}, "p": {{"q": {}}}, "arr": [0, {x}], "s": "k"}}"#,
                    10.0 * x
                );
                w.write_to_known_channel(&msg(a, t), body.as_bytes())
                    .expect("write a");
            }
            for (t, u) in [(0u64, -1.0), (2_000_000, -2.0)] {
                w.write_to_known_channel(&msg(b, t), format!(r#"{{"u": {u}}}"#).as_bytes())
                    .expect("write b");
            }
            w.write_to_known_channel(&msg(c, 0), &[0, 1, 0, 0])
                .expect("write c");
            w.finish().expect("finish");
        }
        buf.into_inner()
    }

    fn log() -> McapLog {
        McapLog::parse(&sample(), Path::new("x.mcap")).expect("valid log")
    }

    #[test]
    fn signals_parse() {
        let s = Signal::parse("/a/b:pose.position[2]", None).expect("full");
        assert_eq!(s.topic, "/a/b");
        assert_eq!(s.field, "pose.position.2");
        assert_eq!(s.name(), "/a/b:pose.position.2");
        assert_eq!(
            Signal::parse("x", Some("/t"))
                .expect("default topic")
                .name(),
            "/t:x"
        );
        assert!(Signal::parse("x", None).is_err());
        assert!(Signal::parse("/t:", None).is_err());
    }

    #[test]
    fn aligns_topics_by_log_time() {
        let log = log();
        assert_eq!(log.topic_list(), "/a, /b, /c");
        assert_eq!(
            log.numeric_fields("/a").expect("fields"),
            vec!["arr.0", "arr.1", "p.q", "x"]
        );
        let sig = |s: &str| Signal::parse(s, None).expect("signal");
        let t = log
            .table(
                &[sig("/b:u"), sig("/a:x"), sig("/a:p.q"), sig("/a:arr[1]")],
                "/a",
                TimeSource::Log,
            )
            .expect("table");
        assert_eq!(t.columns, vec!["t", "/b:u", "/a:x", "/a:p.q", "/a:arr.1"]);
        assert_eq!(
            t.rows,
            vec![
                vec![0.001, -1.0, 1.0, 10.0, 1.0],
                vec![0.002, -2.0, 2.0, 20.0, 2.0],
                vec![0.003, -2.0, 3.0, 30.0, 3.0],
            ]
        );
        // with /b as the base, /a has no message at or before t = 0: that row is dropped
        let t = log
            .table(&[sig("/a:x"), sig("/b:u")], "/b", TimeSource::Log)
            .expect("table");
        assert_eq!(t.rows, vec![vec![0.002, 2.0, -2.0]]);
    }

    #[test]
    fn errors_are_clear() {
        let log = log();
        let sig = |s: &str| Signal::parse(s, None).expect("signal");
        let e = log
            .table(&[sig("/nope:x")], "/a", TimeSource::Log)
            .expect_err("topic");
        assert!(
            e.to_string()
                .contains("no topic `/nope` (topics: /a, /b, /c)"),
            "{e}"
        );
        let e = log
            .table(&[sig("/a:y")], "/a", TimeSource::Log)
            .expect_err("field");
        assert!(e.to_string().contains("no field `y`"), "{e}");
        let e = log
            .table(&[sig("/a:s")], "/a", TimeSource::Log)
            .expect_err("string");
        assert!(e.to_string().contains("the string \"k\""), "{e}");
        let e = log
            .table(&[sig("/c:x")], "/c", TimeSource::Log)
            .expect_err("cdr");
        assert!(e.to_string().contains("message encoding `cdr`"), "{e}");
        let bytes = sample();
        let e =
            McapLog::parse(&bytes[..bytes.len() / 2], Path::new("x.mcap")).expect_err("truncated");
        assert!(e.to_string().contains("corrupt or truncated"), "{e}");
        let e = McapLog::parse(b"t,u,y\n", Path::new("x.mcap")).expect_err("csv");
        assert!(e.to_string().contains("not an MCAP file"), "{e}");
    }
}
