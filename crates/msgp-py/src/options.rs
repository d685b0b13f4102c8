//! What `msgp.Msgp(...)` takes, turned into the fit's options and settings as `msgp fit` turns
//! its flags: the constructor's own arguments into [`FitOptions`] (checked and named as Python
//! arguments), the `settings` dict into overrides of the method's own settings (another
//! method's setting named as such), and both into a fit's [`FitSettings`] at fit time.

use msgp_core::data::Trajectory;
use msgp_core::fit::{FitOptimizer, FitOptions, FitSettings, MsgpStart, Overrides};
use msgp_core::loss::Likelihood;
use msgp_core::model::Method;
use msgp_core::numeric::parallel::Threads;
use pyo3::prelude::*;
use pyo3::types::{PyList, PyTuple};

use crate::error::{Result, input};

/// Settings that the constructor's own arguments set.
const OWN_SETTINGS: [(&str, &str); 8] = [
    ("method", "method"),
    ("ly", "history"),
    ("lu", "history"),
    ("inducing", "inducing"),
    ("iterations", "iterations"),
    ("seed", "seed"),
    ("likelihood", "likelihood"),
    ("start", "start"),
];

/// A non-negative integer argument.
pub fn uint(v: i128, name: &str) -> Result<u64> {
    u64::try_from(v).map_err(|_| {
        if v < 0 {
            input(format!("{name} must be a non-negative integer, got {v}"))
        } else {
            input(format!("{name} is too large ({v})"))
        }
    })
}

/// A non-negative integer argument that counts something.
pub fn count(v: i128, name: &str) -> Result<usize> {
    usize::try_from(uint(v, name)?).map_err(|_| input(format!("{name} is too large ({v})")))
}

/// A method name (`msgp`, `gp-narx`, `pilco-narx`).
pub fn method(name: &str) -> Result<Method> {
    Method::from_name(name).ok_or_else(|| {
        input(format!(
            "unknown method {name:?}: expected one of {}",
            Method::ALL
                .iter()
                .map(|m| format!("{:?}", m.name()))
                .collect::<Vec<_>>()
                .join(", ")
        ))
    })
}

/// The likelihood an MSGP fit trains on, by name (`free-run`, `filter`); `None`: the
/// default. Other methods have their own and refuse one.
pub fn likelihood(m: Method, name: Option<&str>) -> Result<Option<Likelihood>> {
    let Some(name) = name else { return Ok(None) };
    if m != Method::Msgp {
        return Err(input(format!(
            "likelihood={name:?}: the likelihood of an MSGP fit; method {:?} has its own",
            m.name()
        )));
    }
    [Likelihood::FreeRun, Likelihood::Filter]
        .into_iter()
        .find(|l| l.name() == name)
        .map(Some)
        .ok_or_else(|| {
            input(format!(
                "unknown likelihood {name:?}: expected \"free-run\" or \"filter\""
            ))
        })
}

/// The name of an MSGP start, as `start` reads it.
pub fn start_name(s: MsgpStart) -> &'static str {
    match s {
        MsgpStart::OneStep => "one-step",
        MsgpStart::Spread => "spread",
        MsgpStart::LinearKf => "linear-kf",
    }
}

/// Where an MSGP fit starts, by name (`one-step`, `spread`, `linear-kf`); `None`: the default
/// (another method refuses one: [`FitOptions::check`]).
fn start(name: Option<&str>) -> Result<Option<MsgpStart>> {
    let Some(name) = name else {
        return Ok(None);
    };
    match name {
        "one-step" => Ok(Some(MsgpStart::OneStep)),
        "linear-kf" => Ok(Some(MsgpStart::LinearKf)),
        "spread" => Ok(Some(MsgpStart::Spread)),
        _ => Err(input(format!(
            "unknown start {name:?}: expected \"one-step\", \"spread\" or \"linear-kf\""
        ))),
    }
}

/// The constructor's arguments as the fit's options, and whether the history is to be chosen
/// from the data (`history="auto"`: the options then hold the search's judge).
#[allow(clippy::too_many_arguments)]
pub fn fit_options(
    history: Option<&Bound<'_, PyAny>>,
    inducing: Option<i128>,
    method: &str,
    seed: i128,
    iterations: Option<i128>,
    likelihood: Option<&str>,
    start: Option<&str>,
    segment_length: Option<i128>,
) -> Result<(FitOptions, bool)> {
    let m = self::method(method)?;
    let segment_length = segment_length
        .map(|x| count(x, "segment_length"))
        .transpose()?;
    let likelihood = self::likelihood(m, likelihood)?;
    let start = self::start(start)?;
    let auto_history = history
        .and_then(|h| h.extract::<String>().ok())
        .is_some_and(|h| h == "auto");
    let (ly, lu) = match history.filter(|h| !h.is_none()) {
        None => (2, 2),
        // (the search's judge: these options with each candidate's history)
        Some(_) if auto_history => (1, 1),
        Some(h) => {
            let pair: Option<(i128, i128)> =
                if h.cast::<PyTuple>().is_ok() || h.cast::<PyList>().is_ok() {
                    h.extract().ok()
                } else {
                    None
                };
            let Some((ly, lu)) = pair else {
                return Err(input(format!(
                    "history must be a pair (l_y, l_u) of past outputs and inputs, or \
                     \"auto\", got {h}"
                )));
            };
            (count(ly, "history l_y")?, count(lu, "history l_u")?)
        }
    };
    if ly == 0 {
        return Err(input("history l_y must be at least 1"));
    }
    let inducing = inducing.map(|x| count(x, "inducing")).transpose()?;
    if inducing == Some(0) {
        return Err(input("inducing must be at least 1"));
    }
    let iterations = iterations.map(|x| count(x, "iterations")).transpose()?;
    let seed = uint(seed, "seed")?;
    let options = FitOptions {
        method: m,
        ly,
        lu,
        seed,
        integrators: Vec::new(),
        optimizer: FitOptimizer::Adam,
        start,
        threads: Threads::default(),
        segment_length,
        overrides: Overrides {
            inducing,
            iterations,
            likelihood,
            ..Overrides::default()
        },
    };
    // what the method does not have shows now, not at the fit
    options.check()?;
    Ok((options, auto_history))
}

/// The `settings` dict as overrides of method `m`'s own settings, checked against its defaults
/// now so that mistakes show at construction: a setting a constructor argument sets, or another
/// method's, is refused and named.
pub fn user_overrides(
    m: Method,
    settings: Option<&Bound<'_, PyAny>>,
) -> Result<Option<serde_json::Value>> {
    Ok(match settings.filter(|s| !s.is_none()) {
        None => None,
        Some(s) => {
            let user = crate::convert::to_json(s, "settings")?;
            let Some(obj) = user.as_object() else {
                return Err(input(format!("settings must be a dict, got {s}")));
            };
            for (key, arg) in OWN_SETTINGS {
                if obj.contains_key(key) {
                    return Err(input(format!(
                        "settings[{key:?}]: set it with the Msgp({arg}=...) argument"
                    )));
                }
            }
            // another method's setting, named as such
            let keys = |m: Method| {
                serde_json::to_value(FitSettings::new(m))
                    .ok()
                    .and_then(|v| v.as_object().map(|o| o.keys().cloned().collect::<Vec<_>>()))
                    .unwrap_or_default()
            };
            let own = keys(m);
            for key in obj.keys().filter(|k| !own.contains(k)) {
                let of = Method::ALL
                    .into_iter()
                    .filter(|&o| keys(o).contains(key))
                    .map(|o| o.name())
                    .collect::<Vec<_>>();
                if !of.is_empty() {
                    let mut takes: Vec<&str> = own
                        .iter()
                        .map(String::as_str)
                        .filter(|k| !OWN_SETTINGS.iter().any(|(o, _)| o == k))
                        .collect();
                    takes.sort_unstable();
                    return Err(input(format!(
                        "settings[{key:?}]: a setting of method {}, not of {}, whose settings \
                         are {}",
                        of.join(" and "),
                        m.name(),
                        takes.join(", ")
                    )));
                }
            }
            // checked now against the method's defaults, so mistakes show at construction
            let by_name = Overrides {
                settings: Some(user.clone()),
                ..Overrides::default()
            };
            by_name.apply(FitSettings::new(m))?;
            Some(user)
        }
    })
}

/// Settings for `train`: exactly `msgp fit`'s for the same options, resolved once
/// ([`FitOptions::settings`]: the method's base, the arguments, then the `settings` dict);
/// threads from `MSGP_THREADS` at the time of the call, as `msgp fit` takes them.
pub fn settings(options: &FitOptions, train: &[Trajectory]) -> Result<FitSettings> {
    let options = FitOptions {
        threads: Threads::from_env()?,
        ..options.clone()
    };
    Ok(options.settings(train)?)
}

/// The settings a model file records that the constructor's arguments do not carry (the
/// one-step solver and objective, the learning rate, the integrators, …), as the `settings`
/// overrides of a refit: `Msgp.load(f).fit(...)` trains as the file's own fit did. `None` when
/// the record is not this method's settings (files before format 1.2 held every method's).
pub fn recorded_overrides(
    method: Method,
    recorded: &serde_json::Value,
) -> Option<serde_json::Value> {
    let defaults = serde_json::to_value(FitSettings::new(method)).ok()?;
    let own = defaults.as_object()?;
    let kept: serde_json::Map<String, serde_json::Value> = recorded
        .as_object()?
        .iter()
        .filter(|(k, _)| {
            own.contains_key(k.as_str())
                && k.as_str() != "threads"
                && !OWN_SETTINGS.iter().any(|(o, _)| o == k)
        })
        .map(|(k, v)| (k.clone(), v.clone()))
        .collect();
    let kept = serde_json::Value::Object(kept);
    let by_name = Overrides {
        settings: Some(kept.clone()),
        ..Overrides::default()
    };
    by_name
        .apply(FitSettings::new(method))
        .is_ok()
        .then_some(kept)
}

/// A learning loop's settings: `defaults` with the user's `settings` dict, its `"fit"` entry
/// resolved as a fit's settings by name ([`Overrides::apply`], as `Msgp(settings=...)`
/// resolves them) and the rest laid over the loop's own; `fit` reaches the loop's fit.
pub fn loop_settings<T>(
    defaults: &T,
    settings: Option<&Bound<'_, PyAny>>,
    fit: fn(&mut T) -> &mut FitSettings,
) -> Result<T>
where
    T: serde::Serialize + serde::de::DeserializeOwned + Clone,
{
    let Some(user) = settings.filter(|s| !s.is_none()) else {
        return Ok(defaults.clone());
    };
    let mut user = crate::convert::to_json(user, "settings")?;
    let Some(obj) = user.as_object_mut() else {
        return Err(input(format!("settings must be a dict, got {user}")));
    };
    let fit_user = obj.remove("fit");
    let mut s: T = msgp_core::overlay::merged(defaults, &user, "settings")?;
    if let Some(fit_user) = fit_user {
        let by_name = Overrides {
            settings: Some(fit_user),
            ..Overrides::default()
        };
        *fit(&mut s) = by_name.apply_at(fit(&mut s).clone(), "fit")?;
    }
    Ok(s)
}
