//! Python bindings of msgp (`import msgp`): a thin pyo3 layer over msgp-core and msgp-sim.
//!
//! - [`model::Msgp`]: fit / simulate / score / save / load, through the same library calls
//!   as the `msgp` command line, so both give the same numbers;
//! - [`sim`]: the synthetic systems, the pendulum simulator, its stability test and the
//!   policy-learning loop;
//! - [`learner`]: the policy-learning loop on the user's own plant (a Gymnasium environment
//!   through `msgp.gym`) and the policy it learns;
//! - [`data`]: data files loaded as `msgp fit` loads them;
//! - [`reproduce`]: the paper's Table 1 and Figure 4 as independent units, for sweeps
//!   (`msgp.sweep`);
//! - [`convert`]: numpy arrays ↔ matrices, Python containers ↔ JSON settings;
//! - [`error`]: the exception hierarchy; no panic reaches Python.
//!
//! Every long computation releases the GIL.

pub mod convert;
pub mod data;
pub mod error;
pub mod fitting;
pub mod learner;
pub mod model;
pub mod options;
pub mod reproduce;
pub mod sim;

use pyo3::prelude::*;

/// The Rust side's allocator (Python's own is untouched): the one-step fit frees and allocates
/// `n × n` matrices of 2–8 MB hundreds of times per fit, which glibc's malloc returns to the
/// system and faults back in each time (`BENCHMARKS.md`, sixth session).
#[global_allocator]
static ALLOCATOR: mimalloc::MiMalloc = mimalloc::MiMalloc;

/// The compiled module `msgp._msgp` (re-exported by the `msgp` package).
#[pymodule]
fn _msgp(m: &Bound<'_, PyModule>) -> PyResult<()> {
    let py = m.py();
    m.add("__version__", env!("CARGO_PKG_VERSION"))?;
    m.add("MsgpError", py.get_type::<error::MsgpError>())?;
    m.add("InvalidInputError", error::invalid_input_type(py)?)?;
    m.add("NumericalError", py.get_type::<error::NumericalError>())?;
    m.add("ModelFileError", py.get_type::<error::ModelFileError>())?;
    m.add("NotFittedError", py.get_type::<error::NotFittedError>())?;
    m.add_class::<model::Msgp>()?;
    m.add_class::<learner::PyPolicy>()?;
    m.add_function(wrap_pyfunction!(learner::learn_on_plant, m)?)?;
    m.add_function(wrap_pyfunction!(data::load, m)?)?;
    m.add_function(wrap_pyfunction!(sim::synthetic_system, m)?)?;
    m.add_function(wrap_pyfunction!(sim::defaults, m)?)?;
    m.add_function(wrap_pyfunction!(sim::run_episode, m)?)?;
    m.add_function(wrap_pyfunction!(sim::stability_test, m)?)?;
    m.add_function(wrap_pyfunction!(sim::learn_policy, m)?)?;
    m.add_function(wrap_pyfunction!(reproduce::table1_plan, m)?)?;
    m.add_function(wrap_pyfunction!(reproduce::table1_unit, m)?)?;
    m.add_function(wrap_pyfunction!(reproduce::table1_report, m)?)?;
    m.add_function(wrap_pyfunction!(reproduce::figure4_plan, m)?)?;
    m.add_function(wrap_pyfunction!(reproduce::figure4_budget, m)?)?;
    m.add_function(wrap_pyfunction!(reproduce::figure4_unit, m)?)?;
    m.add_function(wrap_pyfunction!(reproduce::figure4_report, m)?)?;
    m.add_function(wrap_pyfunction!(reproduce::update_results_section, m)?)?;
    Ok(())
}
