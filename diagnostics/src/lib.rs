//! The diagnostics behind the figures of docs/design.md and BENCHMARKS.md, one binary each
//! (`src/bin/`), run as `cargo run --release -p msgp-diagnostics --bin NAME -- ARGS`:
//!
//! - `experiment`: one benchmark fit, one method, its test metrics; the tables of docs/design.md
//!   "Noise of the synthetic systems", "The complexity term: sign and form" and "Guarding
//!   against noise collapse and overfitting".
//! - `dump_sim`: one benchmark fit's free simulation of its test part as CSV (t, y, mean, std),
//!   the data of a free-simulation plot (no section cites it).
//! - `probe`: the pendulum loop's model fitted to fixed data, its predicted cost against the
//!   plant's for seven gain sets; docs/experiments/2026-11-27-what-the-diagnostics-of-2026-11-27-evening.md "What the diagnostics of 2026-11-27 (evening)
//!   found", "The start of the training rollouts, the pole row's basin, and the sensor noise",
//!   "Exploration: …" ("What the loop's models believe about the pole") and "The models' noise
//!   split and the filter likelihood".
//! - `loop_fit_convergence`: where the loop's MSGP fit spends its time and how far its loss has
//!   come; BENCHMARKS.md "2026-11-29 (fourth session): the loop's MSGP fit is an unconverged
//!   300-iteration run" and docs/design.md "Guarding against noise collapse and overfitting".
//! - `stable_region`: how much of a box of PID + PD gains passes the stability test;
//!   docs/experiments/2026-11-28-exploration-how-much-of-the-gain-box-balances.md "Exploration: how much of the gain box balances, …".
//! - `history_choice`: the history `msgp_core::fit::history` chooses on each Table 1
//!   benchmark, and the default MSGP fit's test RMSE with it; docs/experiments/2026-12-06-table-1-against-all-six-columns-and-the.md ("Table 1 against
//!   all six columns, and the history chosen from the data").
//! - `swing_up`: the learning loop on the arm swing-up, iteration by iteration; docs/experiments/2026-12-06-angles-on-the-poles-tip-and-the-arm.md
//!   "Angles on the pole's tip, and the arm swing-up plant".
//! - `swing_up_models`: MSGP and GP-NARX fitted to the same swing-up episodes, each model's
//!   predictions of both searched policies against the plant; docs/experiments/2026-12-06-the-plant-tasks-per-model.md "The plant
//!   tasks, per model".
//! - `true_cost`: the loop's cost minimised with the plant as the model, and whether its
//!   minimiser is stable; docs/experiments/2026-11-28-exploration-how-much-of-the-gain-box-balances.md "Exploration: …" ("The objective itself: what a perfect
//!   model would choose").
//!
//! No diagnostic reads an environment variable except `MSGP_DATA_DIR` (where the real series
//! are, [`msgp_core::data::real::data_dir`]). Each takes its positional arguments and then
//! `key=value` switches ([`Switches`]); an unknown switch is an error that lists the known ones.

use std::collections::BTreeMap;
use std::fmt::Display;
use std::str::FromStr;

use msgp_core::numeric::parallel::Threads;

/// A diagnostic's command line: positional arguments and `key=value` switches (any argument
/// with a `=`; the key is what precedes the first one). Every key must be one of the
/// diagnostic's known switches and may be given once.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Switches {
    positional: Vec<String>,
    values: BTreeMap<String, String>,
    known: &'static [&'static str],
}

impl Switches {
    /// Splits `args` (without the program name) into positional arguments, at most
    /// `max_positional` of them, and switches, each key one of `known`.
    pub fn parse<I, S>(
        args: I,
        max_positional: usize,
        known: &'static [&'static str],
    ) -> Result<Self, String>
    where
        I: IntoIterator<Item = S>,
        S: Into<String>,
    {
        let mut positional = Vec::new();
        let mut values = BTreeMap::new();
        for arg in args {
            let arg = arg.into();
            let Some((key, value)) = arg.split_once('=') else {
                positional.push(arg);
                continue;
            };
            if !known.contains(&key) {
                return Err(format!("unknown switch `{key}` ({})", known_list(known)));
            }
            if values.insert(key.to_string(), value.to_string()).is_some() {
                return Err(format!("switch `{key}` given twice"));
            }
        }
        if positional.len() > max_positional {
            return Err(format!(
                "at most {max_positional} positional argument{}, got {}: {}",
                if max_positional == 1 { "" } else { "s" },
                positional.len(),
                positional.join(" ")
            ));
        }
        Ok(Self {
            positional,
            values,
            known,
        })
    }

    /// [`Switches::parse`] of the process's arguments.
    pub fn from_args(
        max_positional: usize,
        known: &'static [&'static str],
    ) -> Result<Self, String> {
        Self::parse(std::env::args().skip(1), max_positional, known)
    }

    /// The positional arguments, in order.
    pub fn positional(&self) -> &[String] {
        &self.positional
    }

    /// Positional argument `index` (from 0) parsed, `None` if there are fewer; `name` is what the
    /// error calls it.
    pub fn arg<T>(&self, index: usize, name: &str) -> Result<Option<T>, String>
    where
        T: FromStr,
        T::Err: Display,
    {
        self.positional
            .get(index)
            .map(|v| {
                v.parse()
                    .map_err(|e| format!("argument {} ({name}) `{v}`: {e}", index + 1))
            })
            .transpose()
    }

    /// Switch `key` parsed, `None` if it was not given. `key` must be one of the known switches.
    pub fn get<T>(&self, key: &str) -> Result<Option<T>, String>
    where
        T: FromStr,
        T::Err: Display,
    {
        if !self.known.contains(&key) {
            return Err(format!(
                "switch `{key}` asked for but not declared ({})",
                known_list(self.known)
            ));
        }
        self.values
            .get(key)
            .map(|v| v.parse().map_err(|e| format!("{key}={v}: {e}")))
            .transpose()
    }

    /// The `threads=N` switch (N ≥ 1), else every core ([`Threads::default`], what the
    /// libraries' settings default to).
    pub fn threads(&self) -> Result<Threads, String> {
        match self.get::<usize>("threads")? {
            None => Ok(Threads::default()),
            Some(n) => Threads::new(n).map_err(|e| format!("threads={n}: {e}")),
        }
    }
}

fn known_list(known: &[&str]) -> String {
    if known.is_empty() {
        "this diagnostic takes none".to_string()
    } else {
        format!("known: {}", known.join(", "))
    }
}

/// A comma-separated list of numbers (`1.5,0.3`; spaces around each allowed).
pub fn numbers(list: &str) -> Result<Vec<f64>, String> {
    list.split(',')
        .map(|v| {
            v.trim()
                .parse::<f64>()
                .map_err(|e| format!("`{}` in `{list}`: {e}", v.trim()))
        })
        .collect()
}

/// Prints `error: …` and the usage line to stderr and exits with status 2.
pub fn usage_error(usage: &str, error: &str) -> ! {
    eprintln!("error: {error}\nusage: {usage}");
    std::process::exit(2)
}

fn merge(base: &mut serde_json::Value, over: &serde_json::Value) {
    use serde_json::Value;
    match (base, over) {
        (Value::Object(b), Value::Object(o)) => {
            for (k, v) in o {
                merge(b.entry(k.clone()).or_insert(Value::Null), v);
            }
        }
        (b, o) => *b = o.clone(),
    }
}

/// The seed (the first argument, 0 when absent) and the `starts=N` switch (`default` when
/// absent) of the loop diagnostics.
pub fn seed_and_starts(args: &[String], default: usize) -> (u64, usize) {
    let seed = args.first().map_or(0, |s| s.parse().expect("seed"));
    let starts = args
        .iter()
        .find_map(|a| {
            a.strip_prefix("starts=")
                .map(|n| n.parse().expect("starts"))
        })
        .unwrap_or(default);
    (seed, starts)
}

/// `base` with the JSON object `arg` (a file holding one, or the text itself; absent, empty or
/// `-`: none) merged in, key by key.
pub fn overridden<T: serde::Serialize + serde::de::DeserializeOwned>(
    base: &T,
    arg: Option<&String>,
) -> T {
    let mut v = serde_json::to_value(base).expect("serialisable");
    if let Some(path) = arg.filter(|a| !a.is_empty() && *a != "-") {
        let text = std::fs::read_to_string(path)
            .ok()
            .unwrap_or_else(|| path.clone());
        let over: serde_json::Value = serde_json::from_str(&text).expect("JSON overrides");
        merge(&mut v, &over);
    }
    serde_json::from_value(v).expect("valid overrides")
}

#[cfg(test)]
mod tests {
    use super::*;

    const KNOWN: &[&str] = &["lr", "lbfgs", "threads"];

    #[test]
    fn positional_and_switches_separate() {
        let s =
            Switches::parse(["sys4", "msgp", "lr=0.01", "lbfgs=true"], 6, KNOWN).expect("parses");
        assert_eq!(s.positional(), ["sys4", "msgp"]);
        assert_eq!(s.get::<f64>("lr"), Ok(Some(0.01)));
        assert_eq!(s.get::<bool>("lbfgs"), Ok(Some(true)));
        assert_eq!(s.get::<usize>("threads"), Ok(None));
        assert_eq!(s.arg::<String>(1, "method"), Ok(Some("msgp".to_string())));
        assert_eq!(s.arg::<u64>(2, "iters"), Ok(None));
    }

    #[test]
    fn a_value_keeps_everything_after_the_first_equals_sign() {
        let s = Switches::parse(["lr=a=b"], 0, KNOWN).expect("parses");
        assert_eq!(s.get::<String>("lr"), Ok(Some("a=b".to_string())));
    }

    #[test]
    fn an_unknown_switch_lists_the_known_ones() {
        let e = Switches::parse(["lrr=0.01"], 6, KNOWN).expect_err("unknown");
        assert_eq!(e, "unknown switch `lrr` (known: lr, lbfgs, threads)");
        let e = Switches::parse(["x=1"], 6, &[]).expect_err("unknown");
        assert!(e.contains("takes none"), "{e}");
    }

    #[test]
    fn repeated_switches_extra_arguments_and_bad_values_are_errors() {
        assert!(Switches::parse(["lr=1", "lr=2"], 6, KNOWN).is_err());
        assert!(Switches::parse(["a", "b"], 1, KNOWN).is_err());
        let s =
            Switches::parse(["x", "lr=fast", "lbfgs=yes", "threads=0"], 1, KNOWN).expect("parses");
        assert!(s.get::<f64>("lr").is_err());
        assert!(s.get::<bool>("lbfgs").is_err());
        assert!(s.threads().is_err());
        assert!(s.arg::<u64>(0, "seed").is_err());
        assert!(s.get::<f64>("undeclared").is_err());
    }

    #[test]
    fn threads_default_to_every_core() {
        let s = Switches::parse(Vec::<String>::new(), 0, KNOWN).expect("parses");
        assert_eq!(s.threads(), Ok(Threads::default()));
        let s = Switches::parse(["threads=1"], 0, KNOWN).expect("parses");
        assert_eq!(s.threads(), Ok(Threads::ONE));
    }

    #[test]
    fn numbers_are_strict() {
        assert_eq!(numbers("0.1, 0.3"), Ok(vec![0.1, 0.3]));
        assert!(numbers("0.1,x").is_err());
        assert!(numbers("").is_err());
    }
}
