//! ROS 2 messages in MCAP logs: channels with message encoding `cdr` and schema encoding
//! `ros2msg`, as `ros2 bag record -s mcap` writes them, decoded generically from the schema
//! text into the same JSON values the JSON channels give, so that [`super::mcap`] addresses
//! their fields with the same `TOPIC:FIELD` paths (`/joint_states:position.2`,
//! `/imu:linear_acceleration.x`, `/cmd:data`).
//!
//! The schema language (`.msg` text: the root type, then each dependency after a line of `=`
//! and `MSG: pkg/Type`) is parsed by rerun's `re_ros_msg`, the CDR wire format read by its
//! `re_cdr`; this module adds what a log reader needs around them:
//! - type names resolve with and without `/msg/` (`std_msgs/Header` = `std_msgs/msg/Header`),
//!   relative names in the package of the message that uses them, and
//!   `builtin_interfaces/{Time,Duration}` even when a writer left them out of the schema;
//! - every type the root message needs is resolved when the channel is opened, so a schema
//!   with an unknown type is an error naming the type and the field before any message is read;
//! - the 4-byte encapsulation header selects the byte order (plain CDR, little or big endian);
//!   the other encapsulations (parameter lists, XCDR2) are refused by name;
//! - a message that ends early or has bytes left over is an error, never a guess;
//! - floating-point NaN and ±inf decode to `null` (JSON has no such numbers), which the
//!   table reader reports as "not a finite number".

use std::collections::HashMap;

use re_cdr::{BigEndian, CdrEndian, CdrReader, LittleEndian};
use re_ros_msg::MessageSchema;
use re_ros_msg::deserialize::primitive_array::PrimitiveArray;
use re_ros_msg::deserialize::{TypeResolver, Value as RosValue, decode_message};
use re_ros_msg::message_spec::{ComplexType, MessageSpecification, Type, message_package};
use serde_json::{Map, Number, Value};

/// The schema encoding of ROS 2 `.msg` schemas in MCAP.
pub const SCHEMA_ENCODING: &str = "ros2msg";
/// The message encoding of ROS 2 messages in MCAP.
pub const MESSAGE_ENCODING: &str = "cdr";

/// The standard definitions of `builtin_interfaces`, used when a schema does not carry them.
const BUILTINS: [(&str, &str); 2] = [
    ("builtin_interfaces/Time", "int32 sec\nuint32 nanosec\n"),
    ("builtin_interfaces/Duration", "int32 sec\nuint32 nanosec\n"),
];

/// `pkg/msg/Type` → `pkg/Type`; other names unchanged.
fn canonical(name: &str) -> String {
    match name.split('/').collect::<Vec<_>>().as_slice() {
        [package, "msg", ty] => format!("{package}/{ty}"),
        _ => name.to_string(),
    }
}

/// The message types of one schema, by canonical name.
#[derive(Debug)]
struct Types {
    by_name: HashMap<String, MessageSpecification>,
}

impl Types {
    fn lookup(
        &self,
        scope: &MessageSpecification,
        ty: &ComplexType,
    ) -> Option<&MessageSpecification> {
        let name = match ty {
            ComplexType::Absolute { package, name } => format!("{package}/{name}"),
            ComplexType::Relative { name } => match message_package(&scope.name) {
                Some(package) => format!("{package}/{name}"),
                None => name.clone(),
            },
        };
        self.by_name.get(&canonical(&name))
    }

    fn display(ty: &ComplexType) -> String {
        match ty {
            ComplexType::Absolute { package, name } => format!("{package}/{name}"),
            ComplexType::Relative { name } => name.clone(),
        }
    }

    /// Checks that every type reachable from `root` resolves.
    fn check(&self, root: &MessageSpecification) -> Result<(), String> {
        let mut stack = vec![root];
        let mut seen = vec![canonical(&root.name)];
        while let Some(spec) = stack.pop() {
            for field in &spec.fields {
                let mut ty = &field.ty;
                while let Type::Array { ty: inner, .. } = ty {
                    ty = inner;
                }
                let Type::Complex(complex) = ty else {
                    continue;
                };
                let Some(found) = self.lookup(spec, complex) else {
                    let mut known: Vec<&str> = self.by_name.keys().map(String::as_str).collect();
                    known.sort_unstable();
                    return Err(format!(
                        "unknown message type `{}` (field `{}` of {}); the schema defines {}",
                        Self::display(complex),
                        field.name,
                        spec.name,
                        known.join(", ")
                    ));
                };
                let name = canonical(&found.name);
                if !seen.contains(&name) {
                    seen.push(name);
                    stack.push(found);
                }
            }
        }
        Ok(())
    }
}

impl TypeResolver for Types {
    fn resolve(
        &self,
        scope: &MessageSpecification,
        ty: &ComplexType,
    ) -> Option<&MessageSpecification> {
        self.lookup(scope, ty)
    }
}

/// A decoder for the messages of one `cdr`/`ros2msg` channel.
#[derive(Debug)]
pub struct Ros2Decoder {
    root: String,
    types: Types,
}

impl Ros2Decoder {
    /// Parses the schema `name` (e.g. `sensor_msgs/msg/JointState`) from its `.msg` text and
    /// resolves every type it uses. The error says what is wrong with the schema.
    pub fn new(name: &str, text: &[u8]) -> Result<Self, String> {
        let text = std::str::from_utf8(text)
            .map_err(|e| format!("schema {name} is not UTF-8 text: {e}"))?;
        let schema = MessageSchema::parse(name, text)
            .map_err(|e| format!("cannot parse the ros2msg schema {name}: {e:#}"))?;
        let mut by_name = HashMap::new();
        for (builtin, body) in BUILTINS {
            let spec = MessageSchema::parse(builtin, body)
                .map_err(|e| format!("builtin {builtin}: {e:#}"))?
                .spec;
            by_name.insert(builtin.to_string(), spec);
        }
        for spec in schema.dependencies {
            by_name.insert(canonical(&spec.name), spec);
        }
        let root = canonical(&schema.spec.name);
        by_name.insert(root.clone(), schema.spec);
        let types = Types { by_name };
        if let Some(spec) = types.by_name.get(&root) {
            types
                .check(spec)
                .map_err(|e| format!("schema {name}: {e}"))?;
        }
        Ok(Self { root, types })
    }

    /// Decodes one message (with its 4-byte CDR encapsulation header) into a JSON value.
    pub fn decode(&self, data: &[u8]) -> Result<Value, String> {
        let Some(spec) = self.types.by_name.get(&self.root) else {
            return Err(format!("schema {} has no root type", self.root));
        };
        if data.len() < 4 {
            return Err(format!(
                "{} bytes: too short for the 4-byte CDR encapsulation header",
                data.len()
            ));
        }
        let (header, body) = data.split_at(4);
        let value = match (header[0], header[1]) {
            (0, 0) => self.decode_body::<BigEndian>(body, spec)?,
            (0, 1) => self.decode_body::<LittleEndian>(body, spec)?,
            (a, b) => {
                let kind = match (a, b) {
                    (0, 2) | (0, 3) => "parameter-list CDR",
                    (0, 6..=11) => "XCDR2",
                    _ => "an unknown encapsulation",
                };
                return Err(format!(
                    "encapsulation 0x{a:02x}{b:02x} ({kind}) is not supported; ROS 2 writes \
                     plain CDR (0x0000 or 0x0001)"
                ));
            }
        };
        Ok(to_json(value))
    }

    fn decode_body<BO: CdrEndian>(
        &self,
        body: &[u8],
        spec: &MessageSpecification,
    ) -> Result<RosValue, String> {
        let mut reader = CdrReader::<BO>::new(body);
        let value = decode_message(&mut reader, spec, &self.types)
            .map_err(|e| format!("cannot decode as {}: {e}", self.root))?;
        // CDR pads the end of a message to 4 bytes at most (8 after a trailing 8-byte value)
        if reader.remaining() >= 8 {
            return Err(format!(
                "{} bytes left after decoding {}: the message does not match its schema",
                reader.remaining(),
                self.root
            ));
        }
        Ok(value)
    }
}

fn number(x: f64) -> Value {
    Number::from_f64(x).map_or(Value::Null, Value::Number)
}

fn primitives(a: PrimitiveArray) -> Value {
    fn all<T>(v: Vec<T>, f: impl Fn(T) -> Value) -> Value {
        Value::Array(v.into_iter().map(f).collect())
    }
    match a {
        PrimitiveArray::Bool(v) => all(v, Value::Bool),
        PrimitiveArray::I8(v) => all(v, Value::from),
        PrimitiveArray::U8(v) => all(v, Value::from),
        PrimitiveArray::I16(v) => all(v, Value::from),
        PrimitiveArray::U16(v) => all(v, Value::from),
        PrimitiveArray::I32(v) => all(v, Value::from),
        PrimitiveArray::U32(v) => all(v, Value::from),
        PrimitiveArray::I64(v) => all(v, Value::from),
        PrimitiveArray::U64(v) => all(v, Value::from),
        PrimitiveArray::F32(v) => all(v, |x| number(f64::from(x))),
        PrimitiveArray::F64(v) => all(v, number),
        PrimitiveArray::String(v) => all(v, Value::String),
    }
}

fn to_json(v: RosValue) -> Value {
    match v {
        RosValue::Bool(b) => Value::Bool(b),
        RosValue::I8(x) => Value::from(x),
        RosValue::U8(x) => Value::from(x),
        RosValue::I16(x) => Value::from(x),
        RosValue::U16(x) => Value::from(x),
        RosValue::I32(x) => Value::from(x),
        RosValue::U32(x) => Value::from(x),
        RosValue::I64(x) => Value::from(x),
        RosValue::U64(x) => Value::from(x),
        RosValue::F32(x) => number(f64::from(x)),
        RosValue::F64(x) => number(x),
        RosValue::String(s) => Value::String(s),
        RosValue::Array(items) | RosValue::Sequence(items) => {
            Value::Array(items.into_iter().map(to_json).collect())
        }
        RosValue::PrimitiveArray(a) | RosValue::PrimitiveSeq(a) => primitives(a),
        RosValue::Message(fields) => Value::Object(
            fields
                .into_iter()
                .map(|(k, v)| (k, to_json(v)))
                .collect::<Map<_, _>>(),
        ),
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// Little-endian CDR writer for the tests, with the alignment rules written out here
    /// (independently of the reader): each primitive aligned to its size, relative to the
    /// first byte after the encapsulation header.
    struct Cdr(Vec<u8>);

    impl Cdr {
        fn new() -> Self {
            Self(vec![0, 1, 0, 0])
        }
        fn align(&mut self, n: usize) {
            while !(self.0.len() - 4).is_multiple_of(n) {
                self.0.push(0);
            }
        }
        fn u32(&mut self, x: u32) -> &mut Self {
            self.align(4);
            self.0.extend_from_slice(&x.to_le_bytes());
            self
        }
        fn i32(&mut self, x: i32) -> &mut Self {
            self.align(4);
            self.0.extend_from_slice(&x.to_le_bytes());
            self
        }
        fn f64(&mut self, x: f64) -> &mut Self {
            self.align(8);
            self.0.extend_from_slice(&x.to_le_bytes());
            self
        }
        fn string(&mut self, s: &str) -> &mut Self {
            self.u32(s.len() as u32 + 1);
            self.0.extend_from_slice(s.as_bytes());
            self.0.push(0);
            self
        }
    }

    const JOINT_STATE: &str = "std_msgs/Header header\nstring[] name\nfloat64[] position\n\
        float64[] velocity\nfloat64[] effort\n\
        ================================================================================\n\
        MSG: std_msgs/Header\n# a comment\nbuiltin_interfaces/Time stamp\nstring frame_id\n";

    fn joint_state(big_endian: bool) -> Vec<u8> {
        let mut m = Cdr::new();
        m.i32(12).u32(500_000_000).string("base");
        m.u32(2).string("a").string("bc");
        m.u32(2).f64(0.25).f64(-1.5);
        m.u32(1).f64(f64::NAN);
        m.u32(0);
        if big_endian {
            // the same message written big-endian, byte by byte
            let mut b = Cdr(vec![0, 0, 0, 0]);
            b.0.extend_from_slice(&12i32.to_be_bytes());
            b.0.extend_from_slice(&500_000_000u32.to_be_bytes());
            b.0.extend_from_slice(&5u32.to_be_bytes());
            b.0.extend_from_slice(b"base\0");
            b.align(4);
            b.0.extend_from_slice(&2u32.to_be_bytes());
            b.0.extend_from_slice(&2u32.to_be_bytes());
            b.0.extend_from_slice(b"a\0");
            b.align(4);
            b.0.extend_from_slice(&3u32.to_be_bytes());
            b.0.extend_from_slice(b"bc\0");
            b.align(4);
            b.0.extend_from_slice(&2u32.to_be_bytes());
            b.align(8);
            b.0.extend_from_slice(&0.25f64.to_be_bytes());
            b.0.extend_from_slice(&(-1.5f64).to_be_bytes());
            b.0.extend_from_slice(&1u32.to_be_bytes());
            b.align(8);
            b.0.extend_from_slice(&f64::NAN.to_be_bytes());
            b.0.extend_from_slice(&0u32.to_be_bytes());
            return b.0;
        }
        m.0
    }

    #[test]
    fn decodes_a_joint_state_in_both_byte_orders() {
        let d =
            Ros2Decoder::new("sensor_msgs/msg/JointState", JOINT_STATE.as_bytes()).expect("schema");
        for big in [false, true] {
            let v = d.decode(&joint_state(big)).expect("message");
            assert_eq!(v["header"]["stamp"]["sec"], 12, "{v}");
            assert_eq!(v["header"]["stamp"]["nanosec"], 500_000_000);
            assert_eq!(v["header"]["frame_id"], "base");
            assert_eq!(v["name"], serde_json::json!(["a", "bc"]));
            assert_eq!(v["position"], serde_json::json!([0.25, -1.5]));
            assert_eq!(v["velocity"], serde_json::json!([null]));
            assert_eq!(v["effort"], serde_json::json!([]));
        }
    }

    #[test]
    fn relative_and_msg_qualified_names_resolve() {
        // `Vector3` relative to geometry_msgs, the dependency named with /msg/
        let text = "std_msgs/msg/Header header\nVector3 v\nfloat64[3] fixed\n\
            ===\nMSG: geometry_msgs/msg/Vector3\nfloat64 x\nfloat64 y\nfloat64 z\n\
            ===\nMSG: std_msgs/msg/Header\nbuiltin_interfaces/msg/Time stamp\nstring frame_id\n\
            ===\nMSG: builtin_interfaces/msg/Time\nint32 sec\nuint32 nanosec\n";
        let d =
            Ros2Decoder::new("geometry_msgs/msg/Vector3Stamped", text.as_bytes()).expect("schema");
        let mut m = Cdr::new();
        m.i32(-1).u32(7).string("");
        m.f64(1.0).f64(2.0).f64(3.0);
        m.f64(4.0).f64(5.0).f64(6.0);
        let v = d.decode(&m.0).expect("message");
        assert_eq!(v["header"]["stamp"]["sec"], -1);
        assert_eq!(v["v"]["z"], 3.0);
        assert_eq!(v["fixed"], serde_json::json!([4.0, 5.0, 6.0]));
    }

    #[test]
    fn errors_are_clear() {
        let e = Ros2Decoder::new("pkg/msg/A", b"float64 x\npkg/Missing m\n").expect_err("unknown");
        assert!(
            e.contains("unknown message type `pkg/Missing` (field `m` of pkg/msg/A)"),
            "{e}"
        );
        let e = Ros2Decoder::new("pkg/msg/A", b"float64 x y z\n").expect_err("syntax");
        assert!(
            e.contains("cannot parse the ros2msg schema pkg/msg/A"),
            "{e}"
        );
        let d = Ros2Decoder::new("std_msgs/msg/Float64", b"float64 data\n").expect("schema");
        let mut m = Cdr::new();
        m.f64(2.5);
        assert_eq!(d.decode(&m.0).expect("ok")["data"], 2.5);
        let e = d.decode(&m.0[..8]).expect_err("truncated");
        assert!(e.contains("cannot decode as std_msgs/Float64"), "{e}");
        let e = d.decode(&[0, 1]).expect_err("short");
        assert!(e.contains("encapsulation header"), "{e}");
        let mut xcdr2 = m.0.clone();
        xcdr2[1] = 7;
        let e = d.decode(&xcdr2).expect_err("xcdr2");
        assert!(e.contains("XCDR2"), "{e}");
        m.f64(1.0);
        let e = d.decode(&m.0).expect_err("left over");
        assert!(e.contains("8 bytes left"), "{e}");
    }
}
