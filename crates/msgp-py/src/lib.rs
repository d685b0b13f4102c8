//! Python bindings (a thin pyo3 layer over msgp-core). The full scikit-learn-style API is the
//! Python issue's work; this module exposes the synthetic benchmarks and a seeded fit/evaluate.

use msgp_core::data::{NoiseScale, SyntheticSystem};
use msgp_core::fit::{FitSettings, fit};
use msgp_core::model::Method;
use pyo3::exceptions::{PyRuntimeError, PyValueError};
use pyo3::prelude::*;
use pyo3::types::PyDict;

fn value_error(e: impl std::fmt::Display) -> PyErr {
    PyValueError::new_err(e.to_string())
}

fn noise_scale(noise: &str) -> PyResult<NoiseScale> {
    match noise {
        "std" => Ok(NoiseScale::StdDev),
        "var" => Ok(NoiseScale::Variance),
        other => Err(value_error(format!(
            "noise must be 'std' or 'var', not {other:?}"
        ))),
    }
}

/// Generates synthetic system `k` (1–5) of the paper's Table 2; returns a dict of lists
/// `u_train, y_train, u_test, y_test` and the history `(l_y, l_u)`.
#[pyfunction]
#[pyo3(signature = (k, seed = 0, noise = "std"))]
fn synthetic_system<'py>(
    py: Python<'py>,
    k: u8,
    seed: u64,
    noise: &str,
) -> PyResult<Bound<'py, PyDict>> {
    let bench = SyntheticSystem::new(k)
        .and_then(|s| {
            s.generate(
                seed,
                noise_scale(noise).map_err(|e| msgp_core::MsgpError::Data(e.to_string()))?,
            )
        })
        .map_err(value_error)?;
    let d = PyDict::new(py);
    d.set_item(
        "u_train",
        bench.train.u.iter().copied().collect::<Vec<f64>>(),
    )?;
    d.set_item(
        "y_train",
        bench.train.y.iter().copied().collect::<Vec<f64>>(),
    )?;
    d.set_item("u_test", bench.test.u.iter().copied().collect::<Vec<f64>>())?;
    d.set_item("y_test", bench.test.y.iter().copied().collect::<Vec<f64>>())?;
    d.set_item("history", (bench.ly, bench.lu))?;
    Ok(d)
}

/// Fits `method` ("msgp", "gp-narx", "pilco-narx") on synthetic system `k` and returns the
/// free-simulation test metrics `rmse, nll, coverage_2sigma`. Releases the GIL while fitting.
#[pyfunction]
#[pyo3(signature = (k, method = "msgp", iterations = 400, seed = 0))]
fn fit_synthetic<'py>(
    py: Python<'py>,
    k: u8,
    method: &str,
    iterations: usize,
    seed: u64,
) -> PyResult<Bound<'py, PyDict>> {
    let method = match method {
        "msgp" => Method::Msgp,
        "gp-narx" => Method::GpNarx,
        "pilco-narx" => Method::PilcoNarx,
        other => return Err(value_error(format!("unknown method {other:?}"))),
    };
    let system = SyntheticSystem::new(k).map_err(value_error)?;
    let metrics = py
        .detach(move || -> msgp_core::Result<msgp_core::model::Metrics> {
            let bench = system.generate(seed, NoiseScale::StdDev)?;
            let settings = FitSettings {
                method,
                ly: bench.ly,
                lu: bench.lu,
                iterations,
                seed,
                ..FitSettings::default()
            };
            let (model, _) = fit(std::slice::from_ref(&bench.train), &settings, &mut |_| {})?;
            model.evaluate(&bench.test)
        })
        .map_err(|e| PyRuntimeError::new_err(e.to_string()))?;
    let d = PyDict::new(py);
    d.set_item("rmse", metrics.rmse)?;
    d.set_item("nll", metrics.nll)?;
    d.set_item("coverage_2sigma", metrics.coverage_2sigma)?;
    Ok(d)
}

/// The compiled module `msgp._msgp`.
#[pymodule]
fn _msgp(m: &Bound<'_, PyModule>) -> PyResult<()> {
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add_function(wrap_pyfunction!(synthetic_system, m)?)?;
    m.add_function(wrap_pyfunction!(fit_synthetic, m)?)?;
    Ok(())
}
