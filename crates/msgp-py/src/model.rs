//! `msgp.Msgp`: fit, simulate, score, save and load, through the same library calls as
//! `msgp fit` / `msgp eval` (settings from [`FitOptions::settings`], the model file from
//! [`ModelFile::from_fit`], predictions from the model as saved), so both give the same
//! numbers for the same data, options and seed.

use std::path::PathBuf;
use std::sync::Arc;

use msgp_core::data::Trajectory;
use msgp_core::fit::{FitOptions, FitReport, MsgpStart, OutputRange, Overrides, Switches};
use msgp_core::loss::Likelihood;
use msgp_core::model::{Method, Metrics, Model, Rollout, pool, score};
use msgp_core::model_file::ModelFile;
use msgp_core::numeric::parallel::Threads;
use nalgebra::DMatrix;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyTuple};

use crate::convert::{array1, array2, matrix, to_python, trajectories};
use crate::error::{Error, Result, callable, detached, input};
use crate::fitting::{Fitted, fit_detached};
use crate::options::{self, start_name};

/// A rollout by name (`mm`, `mm-independent`, `mean`).
fn rollout(name: &str) -> Result<Rollout> {
    Rollout::ALL
        .into_iter()
        .find(|r| r.name() == name)
        .ok_or_else(|| {
            input(format!(
                "unknown rollout {name:?}: expected \"mm\" (moment matching), \
                 \"mm-independent\" (the paper's moment matching) or \"mean\" (mean feedback)"
            ))
        })
}

/// Gaussian-process dynamics model trained for long-term predictions (MSGP, Doerr et al.,
/// CoRL 2017), or the one-step GP-NARX baselines.
#[pyclass(module = "msgp", name = "Msgp")]
#[derive(Debug)]
pub struct Msgp {
    options: FitOptions,
    /// `history="auto"`: each fit chooses the history from its training data first
    /// ([`with_chosen_history`]); `options` then hold the last choice.
    auto_history: bool,
    /// Shared so that long calls hold no borrow of the object while the GIL is released.
    fitted: Option<Arc<Fitted>>,
}

impl Msgp {
    fn fitted(&self) -> Result<&Fitted> {
        self.fitted.as_deref().ok_or(Error::NotFitted)
    }

    /// The fitted model, borrowing the object only for the moment it takes to share it.
    fn shared(slf: &Bound<'_, Self>) -> PyResult<Arc<Fitted>> {
        let me = slf.try_borrow().map_err(|e| Error::Busy(e.to_string()))?;
        Ok(me.fitted.clone().ok_or(Error::NotFitted)?)
    }

    fn from_file(file: ModelFile, model: Model, report: Option<FitReport>) -> Self {
        // before format 1.2 the record held every method's settings, a one-step model's
        // own count under `one_step_iterations`
        let before_1_2 = file.format_version == "1.0" || file.format_version == "1.1";
        let iterations = match model.method {
            Method::GpNarx | Method::PilcoNarx if before_1_2 => {
                file.training.settings.get("one_step_iterations")
            }
            _ => file.training.settings.get("iterations"),
        }
        .and_then(serde_json::Value::as_u64)
        .and_then(|n| usize::try_from(n).ok());
        Self {
            options: FitOptions {
                method: model.method,
                ly: model.spec.ly,
                lu: model.spec.lu,
                seed: file.training.seed,
                integrators: Vec::new(),
                optimizer: file
                    .training
                    .settings
                    .get("optimizer")
                    .and_then(|v| serde_json::from_value(v.clone()).ok())
                    .unwrap_or_default(),
                start: file
                    .training
                    .settings
                    .get("start")
                    .and_then(|v| serde_json::from_value(v.clone()).ok()),
                threads: Threads::default(),
                segment_length: None,
                overrides: Overrides {
                    iterations,
                    // (a linear-kf model's idle pseudo-input is no GP's)
                    inducing: (model.method != Method::LinearKf)
                        .then(|| model.params.pseudo_inputs.nrows()),
                    mean: Some(model.config.mean),
                    likelihood: (model.method == Method::Msgp).then(|| {
                        file.training
                            .settings
                            .get("likelihood")
                            .and_then(|v| serde_json::from_value(v.clone()).ok())
                            .unwrap_or_default()
                    }),
                    switches: Switches::default(),
                    settings: options::recorded_overrides(model.method, &file.training.settings),
                },
            },
            auto_history: false,
            fitted: Some(Arc::new(Fitted {
                file,
                model,
                report,
            })),
        }
    }

    /// One trajectory for simulation: `u` (T × d_u) and the first `max(l_y, l_u)` rows of
    /// `y_init`; the outputs after them are not used (feed-forward rollout) and set to 0.
    fn simulation_input(
        model: &Model,
        u: &Bound<'_, PyAny>,
        y_init: &Bound<'_, PyAny>,
    ) -> Result<Trajectory> {
        let spec = model.spec;
        let u = matrix(u, "u")?;
        let y0 = matrix(y_init, "y_init")?;
        check_columns(model, u.ncols(), y0.ncols(), "")?;
        let w = spec.warmup();
        if u.nrows() <= w {
            return Err(input(format!(
                "u has {} samples; the history (l_y={}, l_u={}) needs more than {w} to predict anything",
                u.nrows(),
                spec.ly,
                spec.lu
            )));
        }
        if y0.nrows() < w {
            return Err(input(format!(
                "y_init has {} samples; the simulation starts from the first {w} outputs \
                 (max(l_y, l_u) with l_y={}, l_u={})",
                y0.nrows(),
                spec.ly,
                spec.lu
            )));
        }
        if y0.nrows() > u.nrows() {
            return Err(input(format!(
                "y_init has {} samples, more than the {} of u",
                y0.nrows(),
                u.nrows()
            )));
        }
        let y = DMatrix::from_fn(
            u.nrows(),
            spec.dy,
            |i, j| if i < w { y0[(i, j)] } else { 0.0 },
        );
        Ok(Trajectory::new(u, y)?)
    }

    /// One measured trajectory `u`, `y`, checked against the model.
    fn measured(model: &Model, u: &Bound<'_, PyAny>, y: &Bound<'_, PyAny>) -> Result<Trajectory> {
        let u = matrix(u, "u")?;
        let y = matrix(y, "y")?;
        if u.nrows() != y.nrows() {
            return Err(input(format!(
                "u has {} samples but y has {}",
                u.nrows(),
                y.nrows()
            )));
        }
        let traj = Trajectory::new(u, y)?;
        Msgp::check_measured(model, &traj, "")?;
        Ok(traj)
    }

    /// `traj`'s columns match the model and it is longer than the history; `prefix` names it.
    fn check_measured(model: &Model, traj: &Trajectory, prefix: &str) -> Result<()> {
        let spec = model.spec;
        check_columns(model, traj.u.ncols(), traj.y.ncols(), prefix)?;
        if traj.len() <= spec.warmup() {
            return Err(input(format!(
                "{prefix}{} samples; the history (l_y={}, l_u={}) needs more than {}",
                traj.len(),
                spec.ly,
                spec.lu,
                spec.warmup()
            )));
        }
        Ok(())
    }
}

/// Checks `du`, `dy` against the model; `prefix` names the trajectory.
fn check_columns(model: &Model, du: usize, dy: usize, prefix: &str) -> Result<()> {
    let spec = model.spec;
    if du != spec.du || dy != spec.dy {
        return Err(input(format!(
            "{prefix}data with {du} input and {dy} output columns; the model has {} and {}",
            spec.du, spec.dy
        )));
    }
    Ok(())
}

fn default_names(prefix: &str, n: usize) -> Vec<String> {
    if n == 1 {
        vec![prefix.to_string()]
    } else {
        (0..n).map(|i| format!("{prefix}{i}")).collect()
    }
}

fn names(given: Option<Vec<String>>, prefix: &str, n: usize, what: &str) -> Result<Vec<String>> {
    let Some(v) = given else {
        return Ok(default_names(prefix, n));
    };
    if v.len() != n {
        return Err(input(format!(
            "{what} has {} names for {n} columns",
            v.len()
        )));
    }
    if v.iter().any(String::is_empty) {
        return Err(input(format!("{what}: names must not be empty")));
    }
    Ok(v)
}

fn metrics_dict<'py>(py: Python<'py>, m: &Metrics) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    d.set_item("rmse", m.rmse)?;
    d.set_item("nll", m.nll)?;
    d.set_item("coverage_2sigma", m.coverage_2sigma)?;
    d.set_item("steps", m.steps)?;
    Ok(d)
}

#[pymethods]
impl Msgp {
    #[new]
    #[pyo3(
        signature = (history = None, inducing = None, method = "msgp", seed = 0, iterations = None, settings = None, likelihood = None, start = None, segment_length = None),
        text_signature = "(history=(2, 2), inducing=None, method='msgp', seed=0, iterations=None, settings=None, likelihood=None, start=None, segment_length=None)"
    )]
    // (the Python constructor's keyword arguments, one parameter each)
    #[allow(clippy::too_many_arguments)]
    fn new(
        history: Option<&Bound<'_, PyAny>>,
        inducing: Option<i128>,
        method: &str,
        seed: i128,
        iterations: Option<i128>,
        settings: Option<&Bound<'_, PyAny>>,
        likelihood: Option<&str>,
        start: Option<&str>,
        segment_length: Option<i128>,
    ) -> PyResult<Self> {
        let (options, auto_history) = options::fit_options(
            history,
            inducing,
            method,
            seed,
            iterations,
            likelihood,
            start,
            segment_length,
        )?;
        let options = FitOptions {
            overrides: Overrides {
                settings: options::user_overrides(options.method, settings)?,
                ..options.overrides
            },
            ..options
        };
        Ok(Self {
            options,
            auto_history,
            fitted: None,
        })
    }

    /// Fits the model on `u`, `y` (arrays (n, d) or (n,), or lists of such arrays for several
    /// trajectories); returns self. Releases the GIL while fitting. `progress`, a callable, is
    /// called with a dict (stage, iteration, iterations, loss, validation, elapsed) after every
    /// training iteration of an MSGP fit; Ctrl-C, or an exception `progress` raises, stops
    /// that training at its next iteration and raises (the model stays as it was).
    #[pyo3(signature = (u, y, *, input_names = None, output_names = None, progress = None))]
    fn fit<'py>(
        slf: Bound<'py, Self>,
        u: &Bound<'py, PyAny>,
        y: &Bound<'py, PyAny>,
        input_names: Option<Vec<String>>,
        output_names: Option<Vec<String>>,
        progress: Option<&Bound<'py, PyAny>>,
    ) -> PyResult<Bound<'py, Self>> {
        let py = slf.py();
        let progress = callable(progress, "one training iteration's dict")?;
        let (options, auto_history) = {
            let me = slf.try_borrow().map_err(|e| Error::Busy(e.to_string()))?;
            (me.options.clone(), me.auto_history)
        };
        let train = trajectories(u, y)?;
        let (du, dy) = train.first().map_or((0, 0), |t| (t.u.ncols(), t.y.ncols()));
        let inputs = names(input_names, "u", du, "input_names")?;
        let outputs = names(output_names, "y", dy, "output_names")?;
        if let Some(n) = inputs.iter().find(|n| outputs.contains(n)) {
            return Err(input(format!("{n:?} is both an input and an output name")).into());
        }
        for note in [
            options.history_warning(&train),
            options.inducing_warning(&train),
        ]
        .into_iter()
        .flatten()
        {
            // what `msgp fit` prints as a warning: the fit goes on with what it says
            let warning = py.get_type::<pyo3::exceptions::PyUserWarning>();
            PyErr::warn(
                py,
                &warning,
                &std::ffi::CString::new(note).unwrap_or_default(),
                1,
            )?;
        }
        let names = (inputs, outputs);
        let fitted = detached(py, move || {
            fit_detached((options, auto_history), &train, &names, progress)
        })??;
        let diverged = fitted.file.training.diverged.clone();
        slf.try_borrow_mut()
            .map_err(|e| Error::Busy(e.to_string()))?
            .fitted = Some(Arc::new(fitted));
        if let Some(why) = diverged {
            // the model is kept (and says so in `diverged`); the user is told at once
            runtime_warning(py, &format!("the fitted model diverges: {why}"))?;
        }
        Ok(slf)
    }

    /// Free simulation driven by the inputs `u` (T samples) from the first
    /// `max(l_y, l_u)` measured outputs in `y_init` (further rows are ignored). Returns
    /// `(mean, var)`, each of shape (T − max(l_y, l_u), d_y): row `i` predicts sample
    /// `max(l_y, l_u) + i`, variance including observation noise, original units. `rollout`:
    /// "mm" (moment matching, the default), "mm-independent" (the paper's moment matching) or
    /// "mean" (mean feedback), as `msgp simulate --rollout`.
    #[pyo3(signature = (u, y_init, *, rollout = "mm"))]
    fn simulate<'py>(
        slf: &Bound<'py, Self>,
        u: &Bound<'py, PyAny>,
        y_init: &Bound<'py, PyAny>,
        rollout: &str,
    ) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
        let py = slf.py();
        let rollout = crate::model::rollout(rollout)?;
        let fitted = Msgp::shared(slf)?;
        let traj = Msgp::simulation_input(&fitted.model, u, y_init)?;
        let sim = detached(py, move || Ok(fitted.model.simulate_as(&traj, rollout)?))?;
        Ok((
            array2(py, &sim.mean).into_any(),
            array2(py, &sim.var).into_any(),
        ))
    }

    /// One-step-ahead filtered predictions of the measured trajectory `u`, `y` (T samples
    /// each): row `i` is the predictive distribution of sample `max(l_y, l_u) + i` given the
    /// inputs and every measured output before it, by the moment-matched filter of the filter
    /// likelihood (`msgp simulate --filtered`). Returns `(mean, var)`, each (T − max(l_y,
    /// l_u), d_y), original units, variance including observation noise. Not a free
    /// simulation: every step has seen the measurements before it.
    fn filtered<'py>(
        slf: &Bound<'py, Self>,
        u: &Bound<'py, PyAny>,
        y: &Bound<'py, PyAny>,
    ) -> PyResult<(Bound<'py, PyAny>, Bound<'py, PyAny>)> {
        let py = slf.py();
        let fitted = Msgp::shared(slf)?;
        let traj = Msgp::measured(&fitted.model, u, y)?;
        let f = detached(py, move || Ok(fitted.model.filtered(&traj)?))?;
        Ok((
            array2(py, &f.mean).into_any(),
            array2(py, &f.var).into_any(),
        ))
    }

    /// Free simulation of each trajectory of `u`, `y` from its first `max(l_y, l_u)` samples,
    /// scored against `y`: dict of `rmse`, `nll` (mean per step), `coverage_2sigma`, `steps`,
    /// pooled over all trajectories like `msgp eval`, and `diverged`/`divergence`: whether (and
    /// why) the simulation runs away from the measured outputs, as `msgp eval` tests it (also
    /// warned as a RuntimeWarning). `rollout` as in `simulate`; with `filtered=True` the dict
    /// also holds `filtered`, the same metrics of the one-step-ahead filtered predictions
    /// (`msgp eval --filtered`).
    #[pyo3(signature = (u, y, *, rollout = "mm", filtered = false))]
    fn score<'py>(
        slf: &Bound<'py, Self>,
        u: &Bound<'py, PyAny>,
        y: &Bound<'py, PyAny>,
        rollout: &str,
        filtered: bool,
    ) -> PyResult<Bound<'py, PyDict>> {
        let py = slf.py();
        let rollout = crate::model::rollout(rollout)?;
        let fitted = Msgp::shared(slf)?;
        let trajs = trajectories(u, y)?;
        let several = trajs.len() > 1;
        for (k, t) in trajs.iter().enumerate() {
            let prefix = if several {
                format!("trajectory {k}: ")
            } else {
                String::new()
            };
            Msgp::check_measured(&fitted.model, t, &prefix)?;
        }
        let (metrics, filtered, diverged) = detached(py, move || {
            let model = &fitted.model;
            let dy = model.spec.dy;
            let pooled =
                |each: Vec<Metrics>| pool(&each, dy).ok_or_else(|| input("nothing to score"));
            // the free simulation, scored and held against each trajectory's measured outputs
            // (`msgp eval`'s divergence test)
            let mut diverged = None;
            let mut each = Vec::with_capacity(trajs.len());
            for (k, t) in trajs.iter().enumerate() {
                let sim = model.simulate_as(t, rollout)?;
                if diverged.is_none() {
                    let what = if several {
                        format!("trajectory {k}")
                    } else {
                        "the data".to_string()
                    };
                    diverged = OutputRange::of(&[t], dy).divergence(&sim, &what);
                }
                each.push(score(&sim, t)?);
            }
            let metrics = pooled(each)?;
            let filtered = match filtered {
                true => Some(pooled(
                    trajs
                        .iter()
                        .map(|t| Ok(score(&model.filtered(t)?, t)?))
                        .collect::<Result<Vec<Metrics>>>()?,
                )?),
                false => None,
            };
            Ok((metrics, filtered, diverged))
        })?;
        let d = metrics_dict(py, &metrics)?;
        if let Some(f) = &filtered {
            d.set_item("filtered", metrics_dict(py, f)?)?;
        }
        d.set_item("diverged", diverged.is_some())?;
        if let Some(why) = &diverged {
            runtime_warning(py, &format!("the model diverges on this data: {why}"))?;
        }
        d.set_item("divergence", diverged)?;
        Ok(d)
    }

    /// Writes the model file (the JSON format of `msgp fit`, atomically).
    fn save(slf: &Bound<'_, Self>, path: PathBuf) -> PyResult<()> {
        let fitted = Msgp::shared(slf)?;
        detached(slf.py(), move || Ok(fitted.file.write(&path)?))?;
        Ok(())
    }

    /// Reads a model file written by `msgp fit` or `Msgp.save`.
    #[staticmethod]
    fn load(py: Python<'_>, path: PathBuf) -> PyResult<Self> {
        let (file, model) = detached(py, move || {
            let file = ModelFile::read(&path)?;
            let model = file.to_model_at(&path)?;
            Ok((file, model))
        })?;
        Ok(Self::from_file(file, model, None))
    }

    /// The model file as JSON text (what `save` writes).
    fn to_json(&self) -> PyResult<String> {
        Ok(self.fitted()?.file.to_json().map_err(Error::from)?)
    }

    /// A model from model-file JSON text.
    #[staticmethod]
    fn from_json(text: &str) -> PyResult<Self> {
        let path = std::path::Path::new("<json>");
        let file = ModelFile::from_json(text.as_bytes(), path).map_err(Error::from)?;
        let model = file.to_model_at(path).map_err(Error::from)?;
        Ok(Self::from_file(file, model, None))
    }

    /// True once fitted or loaded.
    #[getter]
    fn is_fitted(&self) -> bool {
        self.fitted.is_some()
    }

    /// Training method: "msgp", "gp-narx" or "pilco-narx".
    #[getter]
    fn method(&self) -> &'static str {
        self.options.method.name()
    }

    /// `(l_y, l_u)`: the fitted model's; before a fit, as given (None for "auto").
    #[getter]
    fn history(&self) -> Option<(usize, usize)> {
        match (&self.fitted, self.auto_history) {
            (Some(f), _) => Some((f.model.spec.ly, f.model.spec.lu)),
            (None, true) => None,
            (None, false) => Some((self.options.ly, self.options.lu)),
        }
    }

    /// Number of pseudo-inputs (None before fitting with the default).
    #[getter]
    fn inducing(&self) -> Option<usize> {
        match &self.fitted {
            Some(f) => Some(f.model.params.pseudo_inputs.nrows()),
            None => self.options.overrides.inducing,
        }
    }

    /// Adam iterations (None: the method's default).
    #[getter]
    fn iterations(&self) -> Option<usize> {
        self.options.overrides.iterations
    }

    /// Seed of every random choice of the fit.
    #[getter]
    fn seed(&self) -> u64 {
        self.options.seed
    }

    /// Likelihood of the MSGP fit ("free-run", the paper's, or "filter"); None for the
    /// one-step baselines and linear-kf, which have their own. A loaded model reports what
    /// its file records.
    #[getter]
    fn likelihood(&self) -> Option<&'static str> {
        (self.options.method == Method::Msgp)
            .then(|| self.options.overrides.likelihood.unwrap_or_default().name())
    }

    /// `max(l_y, l_u)`: samples that start a simulation; predictions begin at this index.
    #[getter]
    fn warmup(&self) -> usize {
        self.options.ly.max(self.options.lu)
    }

    /// Input column names of the fitted model.
    #[getter]
    fn input_names(&self) -> PyResult<Vec<String>> {
        Ok(self.fitted()?.file.inputs.clone())
    }

    /// Output column names of the fitted model.
    #[getter]
    fn output_names(&self) -> PyResult<Vec<String>> {
        Ok(self.fitted()?.file.outputs.clone())
    }

    /// The fitted parameters as numpy arrays, named as in the model file (normalised units):
    /// `pseudo_inputs` (m, D), `pseudo_targets` (m, d_y), `log_lengthscales` (d_y, D),
    /// `log_signal_var`, `log_process_noise`, `log_obs_noise` (d_y,), `linear_mean` (d_y, D;
    /// zero unless fitted with `settings={"mean": "linear"}`), `u_mean`, `u_std` (d_u,),
    /// `y_mean`, `y_std` (d_y,), and the float `noise_floor`.
    #[getter]
    fn params<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyDict>> {
        let f = self.fitted()?;
        let p = &f.model.params;
        let n = &f.model.normalizer;
        let d = PyDict::new(py);
        d.set_item("pseudo_inputs", array2(py, &p.pseudo_inputs))?;
        d.set_item("pseudo_targets", array2(py, &p.pseudo_targets))?;
        d.set_item("log_lengthscales", array2(py, &p.log_lengthscales))?;
        d.set_item("log_signal_var", array1(py, p.log_signal_var.as_slice()))?;
        d.set_item(
            "log_process_noise",
            array1(py, p.log_process_noise.as_slice()),
        )?;
        d.set_item("log_obs_noise", array1(py, p.log_obs_noise.as_slice()))?;
        d.set_item("linear_mean", array2(py, &p.linear_mean))?;
        d.set_item("u_mean", array1(py, &n.u_mean))?;
        d.set_item("u_std", array1(py, &n.u_std))?;
        d.set_item("y_mean", array1(py, &n.y_mean))?;
        d.set_item("y_std", array1(py, &n.y_std))?;
        d.set_item("noise_floor", f.model.config.noise_floor)?;
        Ok(d)
    }

    /// Provenance from the model file: seed, data_hash, trajectories, samples,
    /// train_seconds, iterations_run, best_iteration, settings.
    #[getter]
    fn training<'py>(&self, py: Python<'py>) -> PyResult<Bound<'py, PyAny>> {
        to_python(py, &self.fitted()?.file.training)
    }

    /// Why the fitted model's free simulation over its training inputs diverges (the fit also
    /// warns with a RuntimeWarning), or None when it does not; read from the model file, so
    /// also for a loaded model.
    #[getter]
    fn diverged(&self) -> PyResult<Option<String>> {
        Ok(self.fitted()?.file.training.diverged.clone())
    }

    /// The fit's report (iterations_run, best_iteration, history of (iteration, training loss,
    /// validation NLL), train_seconds, jitter; MSGP: recipes, chosen_recipe and
    /// full_data_iteration, the iterate of the final training on all the data that the model
    /// is, or full_data_failed; calibration, the output-variance calibration: added_std
    /// per output, original units, and its judge; history_choice, with history="auto": the
    /// chosen ly, lu and every candidate's score); None for a loaded model.
    #[getter]
    fn report<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyAny>>> {
        self.fitted()?
            .report
            .as_ref()
            .map(|r| to_python(py, r))
            .transpose()
    }

    /// The one-step check value of the model file (window, mean, var; normalised units), if any.
    #[getter]
    fn reference<'py>(&self, py: Python<'py>) -> PyResult<Option<Bound<'py, PyDict>>> {
        let Some(r) = &self.fitted()?.file.reference else {
            return Ok(None);
        };
        let d = PyDict::new(py);
        d.set_item("window", array1(py, &r.window))?;
        d.set_item("mean", array1(py, &r.mean))?;
        d.set_item("var", array1(py, &r.var))?;
        Ok(Some(d))
    }

    fn __repr__(&self) -> String {
        let o = &self.options;
        let opt = |v: Option<usize>| v.map_or_else(|| "None".to_string(), |n| n.to_string());
        let history = match (self.auto_history, self.history()) {
            (true, None) => "'auto'".to_string(),
            (_, Some((ly, lu))) => format!("({ly}, {lu})"),
            (false, None) => format!("({}, {})", o.ly, o.lu),
        };
        let mut s = format!(
            "Msgp(history={history}, inducing={}, method='{}', seed={}, iterations={})",
            opt(self.inducing()),
            o.method.name(),
            o.seed,
            opt(o.overrides.iterations)
        );
        if let Some(l) = o
            .overrides
            .likelihood
            .filter(|l| *l != Likelihood::default())
        {
            s.insert_str(s.len() - 1, &format!(", likelihood='{}'", l.name()));
        }
        if let Some(start) = o.start.filter(|s| *s != MsgpStart::default()) {
            s.insert_str(s.len() - 1, &format!(", start='{}'", start_name(start)));
        }
        if let Some(f) = &self.fitted {
            let t = &f.file.training;
            s.push_str(&format!(
                " fitted on {} trajector{}, {} samples",
                t.trajectories,
                if t.trajectories == 1 { "y" } else { "ies" },
                t.samples
            ));
        }
        s
    }

    /// Pickling goes through the model-file JSON (an unfitted model through its arguments).
    fn __reduce__<'py>(slf: &Bound<'py, Self>) -> PyResult<Bound<'py, PyTuple>> {
        let py = slf.py();
        let me = slf.try_borrow().map_err(|e| Error::Busy(e.to_string()))?;
        let cls = slf.get_type();
        match &me.fitted {
            Some(f) => {
                let text = f.file.to_json().map_err(Error::from)?;
                PyTuple::new(
                    py,
                    [
                        cls.getattr("from_json")?,
                        PyTuple::new(py, [text])?.into_any(),
                    ],
                )
            }
            None => {
                let o = &me.options;
                let settings = match &o.overrides.settings {
                    Some(v) => crate::convert::from_json(py, v)?,
                    None => py.None().into_bound(py),
                };
                let likelihood = o.overrides.likelihood.map(|l| l.name());
                let start = o.start.map(start_name);
                let args = (
                    (o.ly, o.lu),
                    o.overrides.inducing,
                    o.method.name(),
                    o.seed,
                    o.overrides.iterations,
                    settings,
                    likelihood,
                    start,
                )
                    .into_pyobject(py)?;
                PyTuple::new(py, [cls.into_any(), args.into_any()])
            }
        }
    }
}

/// Warns `message` as a Python `RuntimeWarning` at the caller's line.
fn runtime_warning(py: Python<'_>, message: &str) -> PyResult<()> {
    let warning = py.get_type::<pyo3::exceptions::PyRuntimeWarning>();
    PyErr::warn(
        py,
        &warning,
        &std::ffi::CString::new(message).unwrap_or_default(),
        1,
    )
}
