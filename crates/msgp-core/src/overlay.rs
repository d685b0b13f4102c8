//! Settings given by name: a user's JSON object (Python's `settings=`, `budget=`, `params=`
//! dicts) laid over the serialised defaults of a settings type and read back as that type, so
//! a key the type does not have, or a value of the wrong type, is refused with its dotted
//! name. Every front end that takes settings by name goes through [`merged`].

use serde::Serialize;
use serde::de::DeserializeOwned;
use serde_json::{Map, Value};

use crate::error::{MsgpError, Result};

/// `base` with `user` (a JSON object) laid over it, read back as `T`; `what` names the
/// argument in messages (`settings.inducing: invalid type …`).
pub fn merged<T: Serialize + DeserializeOwned>(base: &T, user: &Value, what: &str) -> Result<T> {
    let base = serde_json::to_value(base)
        .map_err(|e| MsgpError::Overrides(format!("cannot describe the {what} defaults: {e}")))?;
    merged_value(&base, user, what)
}

/// [`merged`] over defaults already serialised.
pub fn merged_value<T: DeserializeOwned>(base: &Value, user: &Value, what: &str) -> Result<T> {
    merged_at(base, user, what, "")
}

/// [`merged_value`] of settings that sit at the dotted `path` of the argument `what` (the
/// loop's fit settings at `fit` of its `settings`): messages name their keys from there
/// (`settings: unknown setting \`fit.x\``, `settings.fit.x: invalid type …`).
pub fn merged_at<T: DeserializeOwned>(
    base: &Value,
    user: &Value,
    what: &str,
    path: &str,
) -> Result<T> {
    let at = match path {
        "" => what.to_string(),
        _ => format!("{what}.{path}"),
    };
    if !user.is_object() {
        return Err(MsgpError::Overrides(format!(
            "{at} must be a dict of settings, got {user}"
        )));
    }
    let mut full = base.clone();
    overlay(&mut full, user, path).map_err(|e| MsgpError::Overrides(format!("{what}: {e}")))?;
    let what = at;
    serde_json::from_value(full).map_err(|e| {
        // name the culprit: apply the user's settings one at a time
        for (name, single) in singles(user) {
            let mut one = base.clone();
            if overlay(&mut one, &single, "").is_ok()
                && let Err(e) = serde_json::from_value::<T>(one)
            {
                return MsgpError::Overrides(format!("{what}.{name}: {e}"));
            }
        }
        MsgpError::Overrides(format!("{what}: {e}"))
    })
}

/// Lays `user` over `base` (both JSON objects), recursing into nested objects; a key that
/// `base` does not have is refused with the list of known keys. `path` prefixes key names.
fn overlay(base: &mut Value, user: &Value, path: &str) -> std::result::Result<(), String> {
    let (Value::Object(b), Value::Object(u)) = (&mut *base, user) else {
        *base = user.clone();
        return Ok(());
    };
    for (k, v) in u {
        let name = if path.is_empty() {
            k.clone()
        } else {
            format!("{path}.{k}")
        };
        match b.get_mut(k) {
            Some(slot @ Value::Object(_)) if v.is_object() => overlay(slot, v, &name)?,
            Some(slot) => *slot = v.clone(),
            None => {
                let known: Vec<&str> = b.keys().map(String::as_str).collect();
                return Err(format!(
                    "unknown setting `{name}` (known: {})",
                    known.join(", ")
                ));
            }
        }
    }
    Ok(())
}

/// Every leaf of the JSON object `user` as (dotted path, an object holding only that leaf).
fn singles(user: &Value) -> Vec<(String, Value)> {
    let Value::Object(map) = user else {
        return Vec::new();
    };
    let mut out = Vec::new();
    for (k, v) in map {
        let inner = if v.as_object().is_some_and(|o| !o.is_empty()) {
            singles(v)
        } else {
            vec![(String::new(), v.clone())]
        };
        for (path, leaf) in inner {
            let mut wrapped = Map::new();
            wrapped.insert(k.clone(), leaf);
            let name = if path.is_empty() {
                k.clone()
            } else {
                format!("{k}.{path}")
            };
            out.push((name, Value::Object(wrapped)));
        }
    }
    out
}

#[cfg(test)]
mod tests {
    use super::*;
    use serde::Deserialize;
    use serde_json::json;

    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    struct Inner {
        rate: f64,
    }

    #[derive(Debug, PartialEq, Serialize, Deserialize)]
    struct Outer {
        count: usize,
        inner: Inner,
    }

    fn base() -> Outer {
        Outer {
            count: 3,
            inner: Inner { rate: 0.5 },
        }
    }

    #[test]
    fn a_nested_setting_replaces_only_itself() {
        let m: Outer = merged(&base(), &json!({"inner": {"rate": 2.0}}), "s").expect("merged");
        assert_eq!(
            m,
            Outer {
                count: 3,
                inner: Inner { rate: 2.0 }
            }
        );
    }

    #[test]
    fn an_unknown_key_is_named_with_the_known_ones() {
        let e =
            merged::<Outer>(&base(), &json!({"inner": {"rat": 2.0}}), "s").expect_err("refused");
        assert_eq!(
            e.to_string(),
            "s: unknown setting `inner.rat` (known: rate)"
        );
    }

    #[test]
    fn a_value_of_the_wrong_type_is_named_by_its_path() {
        let e = merged::<Outer>(&base(), &json!({"count": 4, "inner": {"rate": "x"}}), "s")
            .expect_err("refused")
            .to_string();
        assert!(e.starts_with("s.inner.rate: invalid type"), "{e}");
    }

    #[test]
    fn settings_at_a_path_are_named_from_there() {
        let b = serde_json::to_value(base()).expect("value");
        let e = merged_at::<Outer>(&b, &json!({"inner": {"rat": 2.0}}), "s", "fit")
            .expect_err("refused");
        assert_eq!(
            e.to_string(),
            "s: unknown setting `fit.inner.rat` (known: rate)"
        );
        let e = merged_at::<Outer>(&b, &json!({"inner": {"rate": "x"}}), "s", "fit")
            .expect_err("refused")
            .to_string();
        assert!(e.starts_with("s.fit.inner.rate: invalid type"), "{e}");
        let e = merged_at::<Outer>(&b, &json!(3), "s", "fit").expect_err("refused");
        assert!(e.to_string().starts_with("s.fit must be a dict"), "{e}");
    }

    #[test]
    fn settings_that_are_not_a_dict_are_refused() {
        let e = merged::<Outer>(&base(), &json!([1]), "s").expect_err("refused");
        assert!(e.to_string().contains("must be a dict"), "{e}");
    }
}
