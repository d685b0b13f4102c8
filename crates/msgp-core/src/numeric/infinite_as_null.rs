//! An `f64` in JSON with infinity as `null` (JSON has no infinity), and `null` read back as
//! infinity, so a record holding one (a held-out NLL whose filter failed, a diverged
//! simulation's score) reads back as it was written. For `#[serde(with = …)]`.

use serde::{Deserialize, Deserializer, Serializer};

/// Writes a finite value as a number, any other as `null`.
pub fn serialize<S: Serializer>(v: &f64, s: S) -> Result<S::Ok, S::Error> {
    if v.is_finite() {
        s.serialize_f64(*v)
    } else {
        s.serialize_none()
    }
}

/// Reads a number, or `null` as infinity.
pub fn deserialize<'de, D: Deserializer<'de>>(d: D) -> Result<f64, D::Error> {
    Ok(Option::<f64>::deserialize(d)?.unwrap_or(f64::INFINITY))
}
