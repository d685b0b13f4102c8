//! Policy learning on the user's own plant: any Python object with `reset(seed) -> obs` and
//! `step(command) -> (obs, terminated, truncated)` (a Gymnasium environment through
//! `msgp.gym`) runs the loop of `msgp_core::learner`; the policy it learns is a Python object
//! that acts, saves and loads ([`PyPolicy`]).
//!
//! The loop runs without the GIL and takes it for every plant call and every event (where
//! Python sees Ctrl-C). An exception of the plant, of `progress` or a Ctrl-C stops the loop
//! there and is raised as it was, with the run so far (every episode, every completed
//! iteration) in its `partial` attribute.

use std::path::PathBuf;

use msgp_core::MsgpError as CoreError;
use msgp_core::learner::{
    Episode, IterationReport, LearnEvent, Learner, LearnerSettings, LoopModel, TargetTask,
    with_model,
};
use msgp_core::model::Method;
use msgp_core::numeric::parallel::Threads;
use msgp_core::plant::{Plant, PlantSpec, PlantStep};
use msgp_core::policy::Policy;
use msgp_core::policy_file::{PolicyFile, Prediction, TaskRecord};
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList};

use crate::convert::{array1, array2, matrix, to_json, to_python};
use crate::error::{Error, Result, callable, detached, input, with_python};
use crate::options::{self, loop_settings, uint};

/// A Python object as the loop's plant; the first exception it raised is kept.
struct PyPlant {
    obj: Py<PyAny>,
    spec: PlantSpec,
    raised: Option<PyErr>,
}

impl PyPlant {
    /// Keeps `e` for the caller and tells the loop the plant failed.
    fn fail(&mut self, call: &str, e: PyErr) -> CoreError {
        let message = format!("{call} raised {e}");
        self.raised.get_or_insert(e);
        CoreError::Plant(message)
    }
}

impl Plant for PyPlant {
    fn spec(&self) -> &PlantSpec {
        &self.spec
    }

    fn reset(&mut self, seed: u64) -> msgp_core::Result<Vec<f64>> {
        let got = Python::attach(|py| -> PyResult<Vec<f64>> {
            py.check_signals()?;
            self.obj.call_method1(py, "reset", (seed,))?.extract(py)
        });
        got.map_err(|e| self.fail("reset", e))
    }

    fn step(&mut self, command: &[f64]) -> msgp_core::Result<PlantStep> {
        let got = Python::attach(|py| -> PyResult<(Vec<f64>, bool, bool)> {
            self.obj
                .call_method1(py, "step", (command.to_vec(),))?
                .extract(py)
        });
        match got {
            Ok((observation, terminated, truncated)) => Ok(PlantStep {
                observation,
                done: terminated || truncated,
                truncated: truncated && !terminated,
            }),
            Err(e) => Err(self.fail("step", e)),
        }
    }
}

/// A JSON-able Python argument as `T`.
fn parse<T: serde::de::DeserializeOwned>(obj: &Bound<'_, PyAny>, what: &str) -> Result<T> {
    let value = to_json(obj, what)?;
    serde_json::from_value(value).map_err(|e| input(format!("{what}: {e}")))
}

/// A learned policy: `policy(obs)` gives the command for an observation (inside the command
/// bounds), remembering what a stateful policy needs between calls until `reset()`; `save`
/// writes the versioned policy file, `Policy.load` reads one.
#[pyclass(name = "Policy", module = "msgp")]
#[derive(Debug)]
pub struct PyPolicy {
    file: PolicyFile,
    policy: Policy,
    rest: Vec<f64>,
    state: Option<Vec<f64>>,
}

impl PyPolicy {
    fn from_file(file: PolicyFile) -> Result<Self> {
        let policy = file.to_policy()?;
        let rest = match &file.task {
            Some(t) => t.rest_command.clone(),
            None => policy.bounds().mid(),
        };
        Ok(Self {
            file,
            policy,
            rest,
            state: None,
        })
    }
}

#[pymethods]
impl PyPolicy {
    /// The command for `observation` (a 1-D array of the plant's outputs).
    fn __call__<'py>(
        &mut self,
        py: Python<'py>,
        observation: &Bound<'py, PyAny>,
    ) -> PyResult<Bound<'py, numpy::PyArray1<f64>>> {
        let dy = self.policy.observation_dim();
        let m = matrix(observation, "observation")?;
        if m.len() != dy || (m.nrows() != 1 && m.ncols() != 1) {
            return Err(input(format!(
                "observation must hold the policy's {dy} outputs, got shape ({}, {})",
                m.nrows(),
                m.ncols()
            ))
            .into());
        }
        let y: Vec<f64> = m.iter().copied().collect();
        let state = match self.state.take() {
            Some(s) => s,
            None => msgp_core::learner::episode::rest_state(&self.policy, &y, &self.rest),
        };
        let (u, next) = self.policy.act(&y, &state).map_err(Error::from)?;
        self.state = Some(next);
        Ok(array1(py, &u))
    }

    /// Forgets the previous observations (the start of an episode).
    fn reset(&mut self) {
        self.state = None;
    }

    /// The policy's family: "pid", "linear" or "rbf".
    #[getter]
    fn kind(&self) -> &'static str {
        self.policy.kind()
    }

    /// The policy file as a dict (the policy, its plant, its task, what was predicted).
    fn to_dict<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, &self.file)
    }

    /// Writes the policy file (atomically).
    fn save(&self, path: PathBuf) -> PyResult<()> {
        Ok(self.file.write(&path).map_err(Error::from)?)
    }

    /// Reads a policy file.
    #[staticmethod]
    fn load(path: PathBuf) -> PyResult<Self> {
        let file = PolicyFile::read(&path).map_err(Error::from)?;
        Ok(Self::from_file(file)?)
    }

    fn __repr__(&self) -> String {
        format!(
            "Policy(kind={:?}, observation_dim={}, command_dim={})",
            self.policy.kind(),
            self.policy.observation_dim(),
            self.policy.command_dim()
        )
    }
}

/// One episode as a dict of arrays.
fn episode_dict<'py>(py: Python<'py>, e: &Episode) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    let rows = |v: &[Vec<f64>]| {
        let n = v.first().map_or(0, Vec::len);
        nalgebra::DMatrix::from_fn(v.len(), n, |i, j| v[i][j])
    };
    d.set_item("seed", e.seed)?;
    d.set_item("outputs", array2(py, &rows(&e.outputs)))?;
    d.set_item("commands", array2(py, &rows(&e.commands)))?;
    d.set_item("ended_early", e.ended_early)?;
    d.set_item("truncated", e.truncated)?;
    d.set_item("policy", e.policy.as_ref().map(Policy::kind))?;
    Ok(d)
}

/// The policy file of the learner's running policy.
fn policy_file(learner: &Learner, spec: &PlantSpec) -> PolicyFile {
    let mut file = PolicyFile::new(learner.policy());
    file.plant = Some(spec.clone());
    file.task = Some(TaskRecord::of(learner.task()));
    file.settings = Some(learner.settings().clone());
    let last = learner.reports().last();
    file.iteration = Some(last.map_or(0, |r| r.iteration));
    file.prediction = last.map(|r| Prediction {
        cost: r.predicted_cost,
        cost_std: r.predicted_cost_std,
        model: {
            let method = learner.settings().method();
            r.search_model
                .map_or(method.name(), |m| m.name(method))
                .into()
        },
    });
    file
}

/// The run so far as a dict: `iterations`, `episodes`, `policy`.
fn outcome<'py>(
    py: Python<'py>,
    learner: &Learner,
    spec: &PlantSpec,
) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    let reports = PyList::empty(py);
    for r in learner.reports() {
        reports.append(report_dict(py, r)?)?;
    }
    let episodes = PyList::empty(py);
    for e in learner.episodes() {
        episodes.append(episode_dict(py, e)?)?;
    }
    d.set_item("iterations", reports)?;
    d.set_item("episodes", episodes)?;
    let policy = PyPolicy::from_file(policy_file(learner, spec))?;
    d.set_item("policy", Py::new(py, policy)?)?;
    Ok(d)
}

/// One iteration's report as a dict, its policy as a `Policy`.
fn report_dict<'py>(py: Python<'py>, r: &IterationReport) -> PyResult<Bound<'py, PyAny>> {
    let d = to_python(py, r)?;
    if let (Some(p), Ok(dict)) = (&r.policy, d.cast::<PyDict>()) {
        dict.set_item("policy_kind", p.kind())?;
    }
    Ok(d)
}

/// The loop model of a `method` ("msgp", "gp-narx", "linear-kf") and, for "msgp", a
/// `likelihood` ("filter" or "free-run"), derived from the plant's settings as `msgp reproduce
/// plant-task --models` derives it; `None` (MSGP without a likelihood) keeps the settings' own.
fn loop_model(method: &str, likelihood: Option<&str>) -> Result<Option<LoopModel>> {
    let m = options::method(method)?;
    let l = options::likelihood(m, likelihood)?;
    if m == Method::Msgp && l.is_none() {
        return Ok(None);
    }
    LoopModel::ALL
        .into_iter()
        .find(|lm| lm.model() == (m, l))
        .map(Some)
        .ok_or_else(|| {
            input(format!(
                "method {method:?} is not a model of the learning loop (its models: \"msgp\", \
                 \"gp-narx\", \"linear-kf\")"
            ))
        })
}

/// The PILCO loop on `plant` (see the module docs): `spec` describes its signals (as
/// `msgp_core::plant::PlantSpec` serialises), `task` is the target form
/// (`msgp_core::learner::TargetTask`), `settings` overrides the loop's defaults on this plant,
/// and `method` / `likelihood` then choose the loop's model (`loop_model`). Returns
/// `{"iterations", "episodes", "policy", "settings"}`.
#[pyfunction]
#[pyo3(signature = (plant, spec, task, *, settings = None, method = "msgp", likelihood = None, seed = 0, progress = None))]
#[allow(clippy::too_many_arguments)]
pub fn learn_on_plant<'py>(
    py: Python<'py>,
    plant: &Bound<'py, PyAny>,
    spec: &Bound<'py, PyAny>,
    task: &Bound<'py, PyAny>,
    settings: Option<&Bound<'py, PyAny>>,
    method: &str,
    likelihood: Option<&str>,
    seed: i128,
    progress: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let progress = callable(progress, "one iteration's dict")?;
    let seed = uint(seed, "seed")?;
    let spec: PlantSpec = parse(spec, "spec")?;
    spec.validate().map_err(Error::from)?;
    let target: TargetTask = parse(task, "task")?;
    let task = target.task(&spec, seed).map_err(Error::from)?;
    let defaults = LearnerSettings {
        seed,
        ..LearnerSettings::for_plant(&spec)
    };
    let mut s = loop_settings(&defaults, settings, |s| &mut s.fit)?;
    if let Some(model) = loop_model(method, likelihood)? {
        s = with_model(s, model).map_err(Error::from)?;
    }
    s.seed = seed;
    let threads = Threads::from_env().map_err(Error::Core)?;
    s.fit.threads = threads;
    s.search.threads = threads;
    let settings_json = to_python(py, &s)?;
    let mut learner = Learner::new(task, s).map_err(Error::from)?;
    let mut py_plant = PyPlant {
        obj: plant.clone().unbind(),
        spec: spec.clone(),
        raised: None,
    };
    let (run, raised, learner, py_plant) = detached(py, move || {
        let mut raised: Option<PyErr> = None;
        let run = learner.run(&mut py_plant, None, &mut |e| {
            with_python(&mut raised, |py| {
                if let (LearnEvent::Iteration(r), Some(f)) = (&e, &progress) {
                    f.call1(py, (report_dict(py, r)?,))?;
                }
                Ok(())
            })
        });
        Ok((run, raised, learner, py_plant))
    })?;
    let result = outcome(py, &learner, &spec)?;
    result.set_item("settings", settings_json)?;
    let error: Option<PyErr> = match run {
        Ok(()) => None,
        // an exception of the plant, of `progress`, or Ctrl-C: raised as it was
        Err(e) => Some(match (py_plant.raised, raised) {
            (Some(err), _) | (None, Some(err)) => err,
            (None, None) => PyErr::from(Error::from(e)),
        }),
    };
    match error {
        None => Ok(result),
        Some(err) => {
            let _ = err.value(py).setattr("partial", &result);
            Err(err)
        }
    }
}
