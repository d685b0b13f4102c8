//! Conversions between Python objects and Rust values: numpy arrays ↔ matrices and
//! trajectories, Python containers ↔ JSON values (for settings and reports that serde
//! describes).

use msgp_core::data::Trajectory;
use nalgebra::DMatrix;
use numpy::ndarray::Array2;
use numpy::{AllowTypeChange, IntoPyArray, PyArray1, PyArray2, PyArrayLikeDyn, PyUntypedArray};
use pyo3::prelude::*;
use pyo3::types::{PyBool, PyDict, PyFloat, PyInt, PyList, PyString, PyTuple};
use serde_json::{Map, Number, Value};

use crate::error::{Error, Result, input};

/// `(n, d)` as Python prints a shape.
fn shape_text(shape: &[usize]) -> String {
    match shape {
        [n] => format!("({n},)"),
        _ => format!(
            "({})",
            shape
                .iter()
                .map(usize::to_string)
                .collect::<Vec<_>>()
                .join(", ")
        ),
    }
}

/// Refuses what numpy would turn into floats by losing or inventing information: complex
/// numbers (the imaginary part dropped), strings (`"1"` parsed), dates and times. Booleans and
/// integers of any width are real numbers and are taken as such; any memory layout is read.
fn check_real(obj: &Bound<'_, PyAny>, what: &str) -> Result<()> {
    let py = obj.py();
    let array = py
        .import("numpy")
        .and_then(|np| np.call_method1("asarray", (obj,)))
        .map_err(|e| input(format!("{what} must be an array of numbers: {e}")))?;
    let kind: String = array
        .getattr("dtype")
        .and_then(|d| d.getattr("kind"))
        .and_then(|k| k.extract())
        .map_err(|e| input(format!("{what} must be an array of numbers: {e}")))?;
    let refused = match kind.as_str() {
        "c" => "complex numbers",
        "U" | "S" => "strings",
        "M" | "m" => "dates or times",
        "V" => "structured records",
        _ => return Ok(()),
    };
    let dtype = array
        .getattr("dtype")
        .and_then(|d| d.str().map(|s| s.to_string()))
        .unwrap_or_default();
    Err(input(format!(
        "{what} must be an array of real numbers, got {refused} (dtype {dtype})"
    )))
}

/// One array argument (anything numpy turns into a real array: floats, integers, booleans, in
/// any memory layout) as an `n × d` matrix; a 1-D array is one column. `what` names the
/// argument in messages.
pub fn matrix(obj: &Bound<'_, PyAny>, what: &str) -> Result<DMatrix<f64>> {
    check_real(obj, what)?;
    let array = obj
        .extract::<PyArrayLikeDyn<'_, f64, AllowTypeChange>>()
        .map_err(|e| input(format!("{what} must be an array of numbers: {e}")))?;
    let view = array.as_array();
    let shape = view.shape().to_vec();
    let (n, d) = match shape.as_slice() {
        [n] => (*n, 1),
        [n, d] => (*n, *d),
        _ => {
            return Err(input(format!(
                "{what} must be 1-D (n,) or 2-D (n, d), got shape {}",
                shape_text(&shape)
            )));
        }
    };
    if n == 0 {
        return Err(input(format!(
            "{what} has no samples (shape {})",
            shape_text(&shape)
        )));
    }
    if d == 0 {
        return Err(input(format!(
            "{what} has no columns (shape {})",
            shape_text(&shape)
        )));
    }
    let at = |i: usize, j: usize| {
        if shape.len() == 1 {
            view[[i]]
        } else {
            view[[i, j]]
        }
    };
    let m = DMatrix::from_fn(n, d, at);
    if let Some(pos) = m.iter().position(|v| !v.is_finite()) {
        let (i, j) = (pos % n, pos / n);
        return Err(input(format!(
            "{what} has a non-finite value ({}) at sample {i}, column {j}",
            m[(i, j)]
        )));
    }
    Ok(m)
}

/// True for a list or tuple whose elements are all numpy arrays: several trajectories.
fn is_array_list(obj: &Bound<'_, PyAny>) -> bool {
    let items: Vec<Bound<'_, PyAny>> = if let Ok(l) = obj.cast::<PyList>() {
        l.iter().collect()
    } else if let Ok(t) = obj.cast::<PyTuple>() {
        t.iter().collect()
    } else {
        return false;
    };
    !items.is_empty() && items.iter().all(|x| x.cast::<PyUntypedArray>().is_ok())
}

fn items<'py>(obj: &Bound<'py, PyAny>) -> Vec<Bound<'py, PyAny>> {
    if let Ok(l) = obj.cast::<PyList>() {
        l.iter().collect()
    } else if let Ok(t) = obj.cast::<PyTuple>() {
        t.iter().collect()
    } else {
        vec![obj.clone()]
    }
}

/// `u`, `y` as trajectories: two arrays (one trajectory) or two lists of arrays of the same
/// length (several). Checks matching sample counts and column counts across trajectories.
pub fn trajectories(u: &Bound<'_, PyAny>, y: &Bound<'_, PyAny>) -> Result<Vec<Trajectory>> {
    let (lu, ly) = (is_array_list(u), is_array_list(y));
    let (us, ys) = match (lu, ly) {
        (false, false) => (vec![u.clone()], vec![y.clone()]),
        (true, true) => (items(u), items(y)),
        (true, false) => {
            return Err(input(format!(
                "u is a list of {} arrays (several trajectories) but y is not a list of arrays",
                items(u).len()
            )));
        }
        (false, true) => {
            return Err(input(format!(
                "y is a list of {} arrays (several trajectories) but u is not a list of arrays",
                items(y).len()
            )));
        }
    };
    if us.len() != ys.len() {
        return Err(input(format!(
            "u holds {} trajectories but y holds {}",
            us.len(),
            ys.len()
        )));
    }
    let several = us.len() > 1 || lu;
    let mut out: Vec<Trajectory> = Vec::with_capacity(us.len());
    for (k, (uk, yk)) in us.iter().zip(&ys).enumerate() {
        let name = |v: &str| {
            if several {
                format!("{v}[{k}]")
            } else {
                v.to_string()
            }
        };
        let um = matrix(uk, &name("u"))?;
        let ym = matrix(yk, &name("y"))?;
        if um.nrows() != ym.nrows() {
            return Err(input(format!(
                "{} has {} samples but {} has {}",
                name("u"),
                um.nrows(),
                name("y"),
                ym.nrows()
            )));
        }
        if let Some(first) = out.first()
            && (um.ncols() != first.u.ncols() || ym.ncols() != first.y.ncols())
        {
            return Err(input(format!(
                "trajectory {k} has {} input and {} output columns; trajectory 0 has {} and {}",
                um.ncols(),
                ym.ncols(),
                first.u.ncols(),
                first.y.ncols()
            )));
        }
        out.push(Trajectory::new(um, ym)?);
    }
    Ok(out)
}

/// A matrix as a 2-D numpy array.
pub fn array2<'py>(py: Python<'py>, m: &DMatrix<f64>) -> Bound<'py, PyArray2<f64>> {
    Array2::from_shape_fn(m.shape(), |(i, j)| m[(i, j)]).into_pyarray(py)
}

/// A slice as a 1-D numpy array.
pub fn array1<'py>(py: Python<'py>, v: &[f64]) -> Bound<'py, PyArray1<f64>> {
    PyArray1::from_slice(py, v)
}

/// A Python value (None, bool, int, float, str, list, tuple, dict with str keys, numpy
/// scalars and arrays) as JSON; `path` names it in messages.
pub fn to_json(obj: &Bound<'_, PyAny>, path: &str) -> Result<Value> {
    if obj.is_none() {
        return Ok(Value::Null);
    }
    if let Ok(b) = obj.cast::<PyBool>() {
        return Ok(Value::Bool(b.is_true()));
    }
    if let Ok(s) = obj.cast::<PyString>() {
        return Ok(Value::String(s.to_string()));
    }
    if let Ok(d) = obj.cast::<PyDict>() {
        let mut map = Map::new();
        for (k, v) in d.iter() {
            let key: String = k
                .extract()
                .map_err(|_| input(format!("{path}: keys must be strings, got {k}")))?;
            let sub = format!("{path}.{key}");
            map.insert(key, to_json(&v, &sub)?);
        }
        return Ok(Value::Object(map));
    }
    if obj.cast::<PyList>().is_ok() || obj.cast::<PyTuple>().is_ok() {
        return items(obj)
            .iter()
            .enumerate()
            .map(|(i, x)| to_json(x, &format!("{path}[{i}]")))
            .collect::<Result<Vec<_>>>()
            .map(Value::Array);
    }
    if obj.cast::<PyUntypedArray>().is_ok() {
        let list = obj
            .call_method0("tolist")
            .map_err(|e| input(format!("{path}: {e}")))?;
        return to_json(&list, path);
    }
    // Python ints, and numpy integers through __index__
    if obj.cast::<PyFloat>().is_err() {
        if let Ok(i) = obj.extract::<i64>() {
            return Ok(Value::from(i));
        }
        if let Ok(i) = obj.extract::<u64>() {
            return Ok(Value::from(i));
        }
        if obj.cast::<PyInt>().is_ok() {
            return Err(input(format!("{path}: the integer {obj} is out of range")));
        }
    }
    if let Ok(f) = obj.extract::<f64>() {
        return Number::from_f64(f)
            .map(Value::Number)
            .ok_or_else(|| input(format!("{path} is not finite ({f})")));
    }
    let type_name = obj
        .get_type()
        .name()
        .map_or_else(|_| "?".to_string(), |n| n.to_string());
    Err(input(format!(
        "{path}: cannot use a value of type {type_name} (expected a number, string, bool, list or dict)"
    )))
}

/// JSON as Python objects (objects become dicts, arrays lists).
pub fn from_json<'py>(py: Python<'py>, v: &Value) -> PyResult<Bound<'py, PyAny>> {
    Ok(match v {
        Value::Null => py.None().into_bound(py),
        Value::Bool(b) => PyBool::new(py, *b).to_owned().into_any(),
        Value::Number(n) => {
            if let Some(i) = n.as_i64() {
                i.into_pyobject(py)?.into_any()
            } else if let Some(u) = n.as_u64() {
                u.into_pyobject(py)?.into_any()
            } else {
                n.as_f64().unwrap_or(f64::NAN).into_pyobject(py)?.into_any()
            }
        }
        Value::String(s) => PyString::new(py, s).into_any(),
        Value::Array(a) => {
            let list = PyList::empty(py);
            for x in a {
                list.append(from_json(py, x)?)?;
            }
            list.into_any()
        }
        Value::Object(o) => {
            let d = PyDict::new(py);
            for (k, x) in o {
                d.set_item(k, from_json(py, x)?)?;
            }
            d.into_any()
        }
    })
}

/// Any serialisable value as Python objects.
pub fn to_python<'py, T: serde::Serialize>(py: Python<'py>, v: &T) -> PyResult<Bound<'py, PyAny>> {
    let value = serde_json::to_value(v)
        .map_err(|e| Error::Panic(format!("cannot describe a result as JSON: {e}")))?;
    from_json(py, &value)
}

/// `base` with `user` (a dict, or None) laid over it ([`msgp_core::overlay::merged`]); `what`
/// names the argument in messages.
pub fn with_overrides<T>(base: &T, user: Option<&Bound<'_, PyAny>>, what: &str) -> Result<T>
where
    T: serde::Serialize + serde::de::DeserializeOwned,
{
    let Some(obj) = user.filter(|o| !o.is_none()) else {
        let value = serde_json::to_value(base)
            .map_err(|e| Error::Panic(format!("cannot describe the {what} defaults: {e}")))?;
        return serde_json::from_value(value).map_err(|e| input(format!("{what}: {e}")));
    };
    if obj.cast::<PyDict>().is_err() {
        return Err(input(format!("{what} must be a dict, got {obj}")));
    }
    Ok(msgp_core::overlay::merged(
        base,
        &to_json(obj, what)?,
        what,
    )?)
}
