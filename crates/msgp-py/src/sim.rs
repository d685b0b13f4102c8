//! Experiments: the paper's synthetic systems, the pendulum simulator (msgp-sim), its
//! stability test and the PILCO learning loop with MSGP models.

use msgp_core::data::{NoiseScale, SyntheticSystem};
use msgp_core::fit::FitSettings;
use msgp_core::learner::LoopModel;
use msgp_core::numeric::parallel::Threads;
use msgp_sim::learn::{LearnEvent, LearnSettings, episode_trajectory, learn_policy_observed};
use msgp_sim::plant_tasks::PlantTask;
use msgp_sim::{
    Controller, Episode, EpisodeConfig, ExcitationConfig, PendulumParams, PidPdGains, PidPdPolicy,
    RandomExcitation, StabilityCriteria, run_episode as run_sim_episode,
    stability_test as run_stability,
};
use numpy::PyArray1;
use pyo3::prelude::*;
use pyo3::types::{PyDict, PyList, PyString};

use crate::convert::{array1, array2, to_json, to_python, with_overrides};
use crate::error::{Error, Result, callable, detached, input, with_python};
use crate::options::loop_settings;
use crate::options::{count, uint};

fn noise_scale(noise: &str) -> Result<NoiseScale> {
    match noise {
        "std" => Ok(NoiseScale::StdDev),
        "var" => Ok(NoiseScale::Variance),
        other => Err(input(format!(
            "noise must be \"std\" (s is the noise standard deviation) or \"var\" (its variance), not {other:?}"
        ))),
    }
}

/// Synthetic system `k` (1–5) of the paper's Table 2, seeded: a dict of 1-D arrays
/// `u_train`, `y_train`, `u_test`, `y_test` (test outputs noise-free) and `history`
/// `(l_y, l_u)`.
#[pyfunction]
#[pyo3(signature = (k, seed = 0, noise = "std"))]
pub fn synthetic_system<'py>(
    py: Python<'py>,
    k: i128,
    seed: i128,
    noise: &str,
) -> PyResult<Bound<'py, PyDict>> {
    let number = uint(k, "k").and_then(|n| {
        u8::try_from(n).map_err(|_| input(format!("synthetic system {n} is not one of 1–5")))
    })?;
    let system = SyntheticSystem::new(number).map_err(Error::from)?;
    let scale = noise_scale(noise)?;
    let seed = uint(seed, "seed")?;
    let bench = system.generate(seed, scale).map_err(Error::from)?;
    let d = PyDict::new(py);
    d.set_item("u_train", array1(py, bench.train.u.as_slice()))?;
    d.set_item("y_train", array1(py, bench.train.y.as_slice()))?;
    d.set_item("u_test", array1(py, bench.test.u.as_slice()))?;
    d.set_item("y_test", array1(py, bench.test.y.as_slice()))?;
    d.set_item("history", (bench.ly, bench.lu))?;
    Ok(d)
}

/// The default values of a group of settings as a dict: "pendulum" (plant parameters),
/// "stability" (stability-test criteria), "learn" (policy-learning loop; `method` picks the
/// model's defaults, as `learn_policy(method)` uses them), "learner" (the loop on a plant, as
/// `learn_policy(env=...)` takes its `settings`: the named Pendulum-v1 task's), "fit" (model
/// fit; `method` picks the method's own settings, as `Msgp(method=...)` uses them).
#[pyfunction]
#[pyo3(signature = (what, *, method = None, likelihood = None))]
pub fn defaults<'py>(
    py: Python<'py>,
    what: &str,
    method: Option<&str>,
    likelihood: Option<&str>,
) -> PyResult<Bound<'py, PyAny>> {
    if method.is_some() && what != "learn" && what != "fit" {
        return Err(input(format!(
            "defaults({what:?}): method applies to the \"learn\" and \"fit\" defaults only"
        ))
        .into());
    }
    if likelihood.is_some() && what != "learn" {
        return Err(input(format!(
            "defaults({what:?}): likelihood applies to the \"learn\" defaults only (a fit's \
             is Msgp(likelihood=...))"
        ))
        .into());
    }
    match what {
        "pendulum" => to_python(py, &PendulumParams::default()),
        "stability" => to_python(py, &StabilityCriteria::default()),
        "learn" => {
            let m = crate::options::method(method.unwrap_or("msgp"))?;
            let l = crate::options::likelihood(m, likelihood)?;
            to_python(py, &LearnSettings::for_model(m, l))
        }
        "fit" => {
            let m = crate::options::method(method.unwrap_or("msgp"))?;
            to_python(py, &FitSettings::new(m))
        }
        "learner" => {
            let preset = PlantTask::PendulumV1
                .settings(LoopModel::MsgpFilter, 0)
                .map_err(Error::from)?;
            to_python(py, &preset)
        }
        other => Err(input(format!(
            "no defaults for {other:?}: expected \"pendulum\", \"stability\", \"learn\", \
             \"learner\" or \"fit\""
        ))
        .into()),
    }
}

fn plant(params: Option<&Bound<'_, PyAny>>) -> Result<PendulumParams> {
    let p: PendulumParams = with_overrides(&PendulumParams::default(), params, "params")?;
    p.validate()?;
    Ok(p)
}

/// What drives an episode.
enum Drive {
    Gains(PidPdGains),
    Random,
}

const PRESETS: &str = "\"hand-tuned\", \"apollo-lqr\" or \"zero\"";

/// Gains from a preset name, a dict (`kp_x`, `ki_x`, `kd_x`, `kp_theta`, `kd_theta`, optional
/// `saturation`) or five numbers in that order; "random" when `allow_random`.
fn drive(obj: &Bound<'_, PyAny>, allow_random: bool) -> Result<Drive> {
    if let Ok(s) = obj.cast::<PyString>() {
        let name = s.to_string();
        return match name.as_str() {
            "hand-tuned" => Ok(Drive::Gains(PidPdGains::hand_tuned())),
            "apollo-lqr" => Ok(Drive::Gains(PidPdGains::apollo_lqr())),
            "zero" => Ok(Drive::Gains(PidPdGains::default())),
            "random" if allow_random => Ok(Drive::Random),
            other => Err(input(format!(
                "unknown controller {other:?}: expected {PRESETS}{}, a dict of gains or 5 gains \
                 [kp_x, ki_x, kd_x, kp_theta, kd_theta]",
                if allow_random { ", \"random\"" } else { "" }
            ))),
        };
    }
    let gains = if obj.cast::<PyDict>().is_ok() {
        serde_json::from_value::<PidPdGains>(to_json(obj, "gains")?)
            .map_err(|e| input(format!("gains: {e}")))?
    } else {
        let v: Vec<f64> = obj.extract().map_err(|_| {
            input(format!(
                "gains must be {PRESETS}, a dict or 5 numbers [kp_x, ki_x, kd_x, kp_theta, kd_theta], got {obj}"
            ))
        })?;
        let g: [f64; 5] = v.as_slice().try_into().map_err(|_| {
            input(format!(
                "gains need 5 numbers [kp_x, ki_x, kd_x, kp_theta, kd_theta], got {}",
                v.len()
            ))
        })?;
        PidPdGains::from_array(g)
    };
    gains.validate()?;
    Ok(Drive::Gains(gains))
}

fn column<'py>(
    py: Python<'py>,
    ep: &Episode,
    f: impl Fn(&msgp_sim::Sample) -> f64,
) -> Bound<'py, PyArray1<f64>> {
    let v: Vec<f64> = ep.samples.iter().map(f).collect();
    array1(py, &v)
}

fn episode_dict<'py>(py: Python<'py>, ep: &Episode) -> PyResult<Bound<'py, PyDict>> {
    let d = PyDict::new(py);
    let steps: Vec<u64> = ep.samples.iter().map(|s| s.step).collect();
    d.set_item("step", PyArray1::from_vec(py, steps))?;
    d.set_item("t", column(py, ep, |s| s.t))?;
    d.set_item("command", column(py, ep, |s| s.command))?;
    d.set_item("meas_theta", column(py, ep, |s| s.measurement.theta))?;
    d.set_item("meas_x", column(py, ep, |s| s.measurement.x))?;
    d.set_item("latent_theta", column(py, ep, |s| s.latent.theta))?;
    d.set_item("latent_theta_dot", column(py, ep, |s| s.latent.theta_dot))?;
    d.set_item("latent_x", column(py, ep, |s| s.latent.x))?;
    d.set_item("latent_x_dot", column(py, ep, |s| s.latent.x_dot))?;
    d.set_item(
        "latent_lag_acceleration",
        column(py, ep, |s| s.latent.lag_acceleration),
    )?;
    d.set_item(
        "latent_delayed_command",
        column(py, ep, |s| s.latent.delayed_command),
    )?;
    let traj = episode_trajectory(ep).map_err(Error::from)?;
    d.set_item("u", array2(py, &traj.u))?;
    d.set_item("y", array2(py, &traj.y))?;
    d.set_item("info", to_python(py, &ep.info)?)?;
    Ok(d)
}

/// One seeded episode of the pendulum on the robot end effector (same as `msgp sim
/// pendulum`). `controller`: "hand-tuned", "apollo-lqr", "zero", "random" (smooth random
/// excitation, RMS `excitation_rms`), a dict of gains or 5 gains. `params`: plant parameters
/// overriding `defaults("pendulum")`. Returns a dict of arrays (`t`, `command`, `meas_theta`,
/// `meas_x`, `latent_*`, `u` (n, 1) and `y` (n, 2) = [θ, x] ready for `Msgp.fit`) and `info`.
#[pyfunction]
#[pyo3(signature = (controller = None, *, seconds = 10.0, seed = 0, theta0 = None, excitation_rms = 1.0, params = None))]
pub fn run_episode<'py>(
    py: Python<'py>,
    controller: Option<&Bound<'py, PyAny>>,
    seconds: f64,
    seed: i128,
    theta0: Option<f64>,
    excitation_rms: f64,
    params: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyDict>> {
    let p = plant(params)?;
    let seed = uint(seed, "seed")?;
    let choice = match controller.filter(|c| !c.is_none()) {
        Some(c) => drive(c, true)?,
        None => Drive::Gains(PidPdGains::hand_tuned()),
    };
    if let Some(t) = theta0.filter(|t| !t.is_finite()) {
        return Err(input(format!("theta0 must be finite, got {t}")).into());
    }
    let episode = detached(py, move || {
        let mut controller: Box<dyn Controller> = match choice {
            Drive::Gains(g) => Box::new(PidPdPolicy::new(g, &p)?),
            Drive::Random => Box::new(RandomExcitation::new(
                seed,
                &ExcitationConfig {
                    rms: excitation_rms,
                    ..ExcitationConfig::default()
                },
            )?),
        };
        Ok(run_sim_episode(
            &p,
            controller.as_mut(),
            &EpisodeConfig {
                seconds,
                seed,
                initial_theta: theta0,
            },
        )?)
    })?;
    episode_dict(py, &episode)
}

/// The stability test of PID + PD gains (same as `msgp sim stability`): five starts, three
/// noise draws each, 10 s each; a dict with `passed`, `gains`, `seed` and per-start reports in `starts`.
/// `criteria` overrides `defaults("stability")`, `params` the plant.
#[pyfunction]
#[pyo3(signature = (gains, *, seed = 0, params = None, criteria = None))]
pub fn stability_test<'py>(
    py: Python<'py>,
    gains: &Bound<'py, PyAny>,
    seed: i128,
    params: Option<&Bound<'py, PyAny>>,
    criteria: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyAny>> {
    let p = plant(params)?;
    let seed = uint(seed, "seed")?;
    let Drive::Gains(g) = drive(gains, false)? else {
        return Err(input("the stability test needs gains").into());
    };
    let c: StabilityCriteria = with_overrides(&StabilityCriteria::default(), criteria, "criteria")?;
    let report = detached(py, move || Ok(run_stability(&p, &g, seed, &c)?))?;
    to_python(py, &report)
}

/// Learning to balance the pendulum from scratch (PILCO with MSGP, GP-NARX or linear-kf models;
/// paper section 4.2): random rollouts, then per iteration fit the model, optimise the gains on it,
/// run them. Returns one dict per iteration (`iteration`, `predicted_cost`,
/// `predicted_cost_std`, `actual_cost`, `interaction_seconds`, `stable`, `gains`, …).
/// `settings` overrides other fields of `defaults("learn", method=method)` (nested dicts
/// merge), `params` the plant. Takes minutes; releases the GIL. `progress`, a callable, is
/// called with each iteration's dict as it completes. Ctrl-C (or an exception raised by
/// `progress`) stops the loop within one model fit and raises.
#[pyfunction]
#[pyo3(signature = (method = "msgp", iterations = 8, seed = 0, *, likelihood = None, params = None, settings = None, progress = None))]
#[allow(clippy::too_many_arguments)]
pub fn learn_policy<'py>(
    py: Python<'py>,
    method: &str,
    iterations: i128,
    seed: i128,
    likelihood: Option<&str>,
    params: Option<&Bound<'py, PyAny>>,
    settings: Option<&Bound<'py, PyAny>>,
    progress: Option<&Bound<'py, PyAny>>,
) -> PyResult<Bound<'py, PyList>> {
    let progress = callable(progress, "one iteration's dict")?;
    let m = crate::options::method(method)?;
    let l = crate::options::likelihood(m, likelihood)?;
    let iterations = count(iterations, "iterations")?;
    let seed = uint(seed, "seed")?;
    let p = plant(params)?;
    if let Some(d) = settings.and_then(|s| s.cast::<PyDict>().ok()) {
        for key in ["method", "iterations", "seed"] {
            if d.contains(key)? {
                return Err(input(format!(
                    "settings[{key:?}]: set it with the learn_policy({key}=...) argument"
                ))
                .into());
            }
        }
        if let Some(fit) = d
            .get_item("fit")?
            .and_then(|f| f.cast_into::<PyDict>().ok())
            && fit.contains("method")?
        {
            return Err(input(
                "settings[\"fit\"][\"method\"]: set it with the learn_policy(method=...) argument",
            )
            .into());
        }
    }
    let base = loop_settings(&LearnSettings::for_model(m, l), settings, |s| &mut s.fit)?;
    let mut s = LearnSettings {
        iterations,
        seed,
        ..base
    };
    let threads = Threads::from_env().map_err(Error::Core)?;
    s.fit.threads = threads;
    s.search.threads = threads;
    // the loop runs without the GIL; at every event it takes it back to let Python see
    // signals, and at the end of an iteration to call `progress`
    let (learned, raised) = detached(py, move || {
        let mut raised: Option<PyErr> = None;
        let learned = learn_policy_observed(&p, &s, &mut |e| {
            with_python(&mut raised, |py| {
                if let (LearnEvent::Iteration(r), Some(f)) = (&e, &progress) {
                    f.call1(py, (to_python(py, *r)?,))?;
                }
                Ok(())
            })
        });
        Ok((learned, raised))
    })?;
    if let Some(err) = raised {
        return Err(err);
    }
    let outcome = learned.map_err(Error::from)?;
    let list = PyList::empty(py);
    for r in &outcome.iterations {
        list.append(to_python(py, r)?)?;
    }
    Ok(list)
}
