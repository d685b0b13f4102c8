//! The one error type of the bindings and its Python exceptions.
//!
//! Python sees this hierarchy (all importable from `msgp`):
//!
//! ```text
//! Exception
//! └── MsgpError                       every error msgp raises
//!     ├── InvalidInputError           (also a ValueError) bad arrays, settings, names, gains
//!     ├── NumericalError              a matrix not positive definite, a non-finite value
//!     ├── ModelFileError              a model file that cannot be read, parsed or written
//!     └── NotFittedError              predicting with a model that was neither fitted nor loaded
//! ```
//!
//! A panic inside the Rust code (a bug) is caught before it reaches Python and raised as
//! `MsgpError` with an "internal error" message.

use std::any::Any;
use std::panic::{AssertUnwindSafe, catch_unwind};

use msgp_core::MsgpError as CoreError;
use msgp_reproduce::ReproduceError;
use msgp_sim::SimError;
use pyo3::exceptions::{PyException, PyValueError};
use pyo3::prelude::*;
use pyo3::sync::PyOnceLock;
use pyo3::types::{PyDict, PyTuple, PyType};

pyo3::create_exception!(
    msgp,
    MsgpError,
    PyException,
    "Base class of every error raised by msgp."
);
pyo3::create_exception!(
    msgp,
    NumericalError,
    MsgpError,
    "A numerical failure: a matrix that stays indefinite with the largest allowed jitter, or a non-finite value during a computation."
);
pyo3::create_exception!(
    msgp,
    ModelFileError,
    MsgpError,
    "A model file that cannot be read, parsed, checked or written."
);
pyo3::create_exception!(
    msgp,
    NotFittedError,
    MsgpError,
    "The model has neither been fitted nor loaded."
);

/// `InvalidInputError(MsgpError, ValueError)`: two bases, so made at import time with `type()`.
static INVALID_INPUT: PyOnceLock<Py<PyType>> = PyOnceLock::new();

const INVALID_INPUT_DOC: &str = "Bad input: wrong shapes, non-finite values, too few samples \
for the history, unknown names or settings. Also a ValueError.";

/// The `InvalidInputError` type.
pub fn invalid_input_type(py: Python<'_>) -> PyResult<&Bound<'_, PyType>> {
    let ty = INVALID_INPUT.get_or_try_init(py, || -> PyResult<Py<PyType>> {
        let namespace = PyDict::new(py);
        namespace.set_item("__module__", "msgp")?;
        namespace.set_item("__doc__", INVALID_INPUT_DOC)?;
        let bases = PyTuple::new(
            py,
            [py.get_type::<MsgpError>(), py.get_type::<PyValueError>()],
        )?;
        let made = py
            .get_type::<PyType>()
            .call1(("InvalidInputError", bases, namespace))?;
        Ok(made.cast_into::<PyType>()?.unbind())
    })?;
    Ok(ty.bind(py))
}

/// Everything that can go wrong in the bindings.
#[derive(Debug, thiserror::Error)]
pub enum Error {
    /// Bad input caught by the bindings themselves (shapes, names, settings).
    #[error("{0}")]
    Input(String),
    /// The model has not been fitted or loaded.
    #[error(
        "this Msgp model is not fitted yet: call fit(u, y) first or load one with Msgp.load(path)"
    )]
    NotFitted,
    /// From msgp-core.
    #[error(transparent)]
    Core(#[from] CoreError),
    /// From msgp-sim.
    #[error(transparent)]
    Sim(#[from] SimError),
    /// From msgp-reproduce, other than the two above.
    #[error(transparent)]
    Reproduce(ReproduceError),
    /// The object is borrowed elsewhere (cannot happen under the GIL; reported, not panicked).
    #[error("this Msgp model is in use by another call: {0}")]
    Busy(String),
    /// A panic in Rust code: a bug, reported instead of crashing the interpreter.
    #[error("internal error (a bug in msgp, please report it): {0}")]
    Panic(String),
}

impl From<ReproduceError> for Error {
    /// The model's and the simulator's errors as they are, so that they become the same Python
    /// exceptions whichever crate passed them on.
    fn from(e: ReproduceError) -> Self {
        match e {
            ReproduceError::Core(e) => Error::Core(e),
            ReproduceError::Sim(e) => Error::Sim(e),
            other => Error::Reproduce(other),
        }
    }
}

/// Result alias of the bindings.
pub type Result<T> = std::result::Result<T, Error>;

/// Shorthand for [`Error::Input`].
pub fn input(message: impl Into<String>) -> Error {
    Error::Input(message.into())
}

/// Which Python exception an error becomes.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
enum Kind {
    Input,
    Numerical,
    ModelFile,
    NotFitted,
    Other,
}

fn core_kind(e: &CoreError) -> Kind {
    match e {
        CoreError::Shape(_)
        | CoreError::InvalidSetting { .. }
        | CoreError::Overrides(_)
        | CoreError::Data(_) => Kind::Input,
        CoreError::NotPositiveDefinite { .. } | CoreError::NonFinite(_) => Kind::Numerical,
        CoreError::File { .. } | CoreError::FileAt { .. } | CoreError::ModelVersion { .. } => {
            Kind::ModelFile
        }
        CoreError::Stopped { .. } | CoreError::Plant(_) => Kind::Other,
    }
}

/// `e` followed by the messages of its sources that it does not already contain.
fn chain(e: &(dyn std::error::Error + 'static)) -> String {
    let mut text = e.to_string();
    let mut source = e.source();
    while let Some(s) = source {
        let more = s.to_string();
        if !text.contains(&more) {
            text.push_str(": ");
            text.push_str(&more);
        }
        source = s.source();
    }
    text
}

impl Error {
    fn kind(&self) -> Kind {
        match self {
            Error::Input(_) => Kind::Input,
            Error::NotFitted => Kind::NotFitted,
            Error::Core(e) => core_kind(e),
            Error::Sim(SimError::Model(e)) => core_kind(e),
            Error::Sim(SimError::InvalidParameter { .. } | SimError::Budget { .. }) => Kind::Input,
            Error::Sim(SimError::NonFiniteCommand { .. } | SimError::NonFiniteState { .. }) => {
                Kind::Numerical
            }
            Error::Reproduce(ReproduceError::Plan { .. }) => Kind::Input,
            Error::Sim(_) | Error::Reproduce(_) | Error::Busy(_) | Error::Panic(_) => Kind::Other,
        }
    }

    fn message(&self) -> String {
        match self {
            Error::Sim(SimError::Model(e)) => format!("model: {}", chain(e)),
            Error::Sim(e) => chain(e),
            Error::Core(e) => chain(e),
            Error::Reproduce(e) => chain(e),
            other => other.to_string(),
        }
    }
}

impl From<Error> for PyErr {
    fn from(e: Error) -> Self {
        let message = e.message();
        match e.kind() {
            Kind::Numerical => NumericalError::new_err(message),
            Kind::ModelFile => ModelFileError::new_err(message),
            Kind::NotFitted => NotFittedError::new_err(message),
            Kind::Other => MsgpError::new_err(message),
            Kind::Input => Python::attach(|py| match invalid_input_type(py) {
                Ok(ty) => PyErr::from_type(ty.clone(), message),
                // cannot happen once the module is imported; still a ValueError
                Err(_) => PyValueError::new_err(message),
            }),
        }
    }
}

fn panic_message(payload: &(dyn Any + Send)) -> String {
    if let Some(s) = payload.downcast_ref::<&str>() {
        (*s).to_string()
    } else if let Some(s) = payload.downcast_ref::<String>() {
        s.clone()
    } else {
        "unknown panic".to_string()
    }
}

/// Runs `f` with the GIL released (other Python threads run meanwhile); a panic becomes
/// [`Error::Panic`].
pub fn detached<T, F>(py: Python<'_>, f: F) -> Result<T>
where
    T: Send,
    F: FnOnce() -> Result<T> + Send,
{
    py.detach(|| {
        catch_unwind(AssertUnwindSafe(f))
            .unwrap_or_else(|p| Err(Error::Panic(panic_message(p.as_ref()))))
    })
}

/// For an observer inside [`detached`] work: takes the GIL, lets Python see signals (Ctrl-C),
/// then runs `f`. Continue when both went well; otherwise Break, with the first exception kept
/// in `raised` for the caller to raise once the work has stopped.
pub fn with_python(
    raised: &mut Option<PyErr>,
    f: impl FnOnce(Python<'_>) -> PyResult<()>,
) -> std::ops::ControlFlow<()> {
    let seen = Python::attach(|py| {
        py.check_signals()?;
        f(py)
    });
    match seen {
        Ok(()) => std::ops::ControlFlow::Continue(()),
        Err(err) => {
            raised.get_or_insert(err);
            std::ops::ControlFlow::Break(())
        }
    }
}

/// A callable argument, or a clear error naming `what` it should be.
pub fn callable(arg: Option<&Bound<'_, PyAny>>, what: &str) -> Result<Option<Py<PyAny>>> {
    match arg {
        Some(f) if !f.is_callable() => Err(input(format!(
            "progress must be a callable taking {what}, not a {}",
            f.get_type()
                .name()
                .map_or_else(|_| "non-callable".to_string(), |n| n.to_string())
        ))),
        f => Ok(f.map(|f| f.clone().unbind())),
    }
}
