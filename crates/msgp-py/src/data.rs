//! Data files as `msgp fit` reads them: [`load`] is `msgp_core::data::dataset::Dataset::load`,
//! the same column defaults, episode splitting and messages naming the file, line and column.

use std::path::PathBuf;

use msgp_core::data::dataset::{Dataset, Selection};
use msgp_core::data::table::TimeSource;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyString};

use crate::convert::{array1, array2};
use crate::error::{Result, detached, input};

/// The `files` argument: one path (str or `os.PathLike`) or a sequence of them.
fn paths(files: &Bound<'_, PyAny>) -> Result<Vec<PathBuf>> {
    if files.is_instance_of::<PyString>() || files.hasattr("__fspath__").unwrap_or(false) {
        let one: PathBuf = files
            .extract()
            .map_err(|e| input(format!("files: not a path: {e}")))?;
        return Ok(vec![one]);
    }
    let many: Vec<PathBuf> = files
        .extract()
        .map_err(|e| input(format!("files must be a path or a list of paths: {e}")))?;
    if many.is_empty() {
        return Err(input("files: no data files given"));
    }
    Ok(many)
}

/// Reads CSV data files into trajectories exactly as `msgp fit --data FILE …` does: a header
/// line, columns chosen by name (`inputs`, `outputs`; default: the first non-time column is the
/// input and the last the output; a `msgp sim` run log's command → its measured angle and
/// position), an `episode` column or several files giving several trajectories. Returns a dict:
/// `inputs`, `outputs` (the names chosen) and `parts`, a list of dicts `source`, `episode`
/// (None without an episode column), `t` (the time column, or the row number), `u` (T × d_u)
/// and `y` (T × d_y) numpy arrays, and `warnings`, lines about the data that do not stop the
/// load (an irregular time step, rows sorted). Bad data raise `InvalidInputError` naming the
/// file, line and column; a time column that goes back within a trajectory is one, unless
/// `sort_time` sorts each trajectory's rows by time first (as `msgp fit --sort-time`). MCAP
/// logs are read by the `msgp` command line (this module is built without MCAP).
#[pyfunction]
#[pyo3(signature = (files, *, inputs = None, outputs = None, topic = None, sort_time = false))]
pub fn load<'py>(
    py: Python<'py>,
    files: &Bound<'py, PyAny>,
    inputs: Option<Vec<String>>,
    outputs: Option<Vec<String>>,
    topic: Option<String>,
    sort_time: bool,
) -> PyResult<Bound<'py, PyDict>> {
    let files = paths(files)?;
    let (inputs, outputs) = (inputs.unwrap_or_default(), outputs.unwrap_or_default());
    let selection = Selection {
        inputs: &inputs,
        outputs: &outputs,
        topic: topic.as_deref(),
        time: TimeSource::Log,
        sort_time,
    };
    let data = detached(py, || {
        Dataset::load(&files, &selection).map_err(|e| input(e.to_string()))
    })?;
    let parts = PyList::empty(py);
    for p in &data.parts {
        let d = PyDict::new(py);
        d.set_item("source", p.source.display().to_string())?;
        d.set_item("episode", p.episode)?;
        d.set_item("t", array1(py, &p.times))?;
        d.set_item("u", array2(py, &p.traj.u))?;
        d.set_item("y", array2(py, &p.traj.y))?;
        parts.append(d)?;
    }
    let out = PyDict::new(py);
    out.set_item("inputs", &data.inputs)?;
    out.set_item("outputs", &data.outputs)?;
    out.set_item("parts", parts)?;
    out.set_item("warnings", &data.warnings)?;
    Ok(out)
}
