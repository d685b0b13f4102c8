//! The one place where a user's choices become a fit's settings. Every front end starts from
//! a base of defaults — the method's own for `msgp fit` and `msgp.Msgp`
//! ([`super::FitOptions::settings`]), the loop's for a policy-learning model (the pendulum
//! loop's budget, the plant learner's settings) — and hands the user's [`Overrides`] to
//! [`Overrides::apply`]: the typed ones (flags, constructor arguments, budget fields) with
//! one meaning each, then any other setting by its serialised name (Python's `settings=`
//! dict). A setting the method does not have is refused, naming it; nothing is ignored.
//! [`super::FitSettings::validate`] then checks the result against the data.

use serde_json::Value;

use super::settings::{FitSettings, MethodSettings, MsgpSettings, MsgpStart, OneStepObjective};
use crate::error::{MsgpError, Result};
use crate::gp::MeanFunction;
use crate::loss::Likelihood;
use crate::model::Method;

/// What a user changes of a fit's defaults (`None`, `false`: the base's value).
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Overrides {
    /// Iterations of the method's own solver ([`FitSettings::with_solver_iterations`]): on the
    /// trajectory likelihood for MSGP (the most of any one training), the one-step marginal
    /// likelihood for the baselines, the filter likelihood for linear-kf.
    pub iterations: Option<usize>,
    /// Pseudo-inputs of the GP (at least 1; linear-kf has no GP).
    pub inducing: Option<usize>,
    /// Prior mean of the GP. MSGP trains the base's recipes of that mean (its own, its
    /// alternative in the own one's place, or both where both have it), or where neither
    /// has it the base's own recipe with this mean. A linear-kf model is its linear mean, so
    /// it takes only [`MeanFunction::Linear`].
    pub mean: Option<MeanFunction>,
    /// The trajectory likelihood of an MSGP fit (the other methods have their own).
    pub likelihood: Option<Likelihood>,
    /// The protocol's switches.
    pub switches: Switches,
    /// Any other setting by its serialised name (a JSON object of the method's keys, as
    /// the model file's training record has them), laid over the result of the typed ones.
    pub settings: Option<Value>,
}

/// Switches of a fit's protocol that the front ends offer (`None`: the method's default).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct Switches {
    /// The one-step fit's objective: the baselines' own fit, MSGP's one-step start
    /// ([`super::OneStepFitSettings::objective`], [`MsgpSettings::one_step_objective`]).
    pub one_step_objective: Option<OneStepObjective>,
    /// MSGP: the output-variance calibration ([`MsgpSettings::calibrate`]).
    pub calibrate: Option<bool>,
    /// MSGP: the fallback heads where the zero-mean recipe's final training blows up
    /// ([`MsgpSettings::blow_up_fallback`]).
    pub blow_up_fallback: Option<bool>,
}

/// The refusal of `setting` (`what` it is) by method `method`.
pub(super) fn refused(setting: &'static str, what: &str, method: Method) -> MsgpError {
    MsgpError::InvalidSetting {
        name: setting,
        reason: format!("{what}; method {} has none", method.name()),
    }
}

/// `settings`' MSGP settings, or the refusal of `setting` (`what` it is).
fn msgp<'a>(
    settings: &'a mut FitSettings,
    setting: &'static str,
    what: &str,
) -> Result<&'a mut MsgpSettings> {
    let method = settings.method();
    settings
        .msgp_mut()
        .ok_or_else(|| refused(setting, what, method))
}

impl Overrides {
    /// `base` with these overrides, each applied once with its one meaning.
    pub fn apply(&self, base: FitSettings) -> Result<FitSettings> {
        self.apply_at(base, "")
    }

    /// [`Overrides::apply`] where the settings by name sit at the dotted `path` of the user's
    /// `settings` (a loop's fit settings at `fit`): their messages name keys from there.
    pub fn apply_at(&self, base: FitSettings, path: &str) -> Result<FitSettings> {
        let mut s = base;
        if let Some(n) = self.iterations {
            s = s.with_solver_iterations(n);
        }
        if let Some(m) = self.inducing {
            s = with_inducing(s, m)?;
        }
        if let Some(mean) = self.mean {
            with_mean(&mut s, mean)?;
        }
        if let Some(l) = self.likelihood {
            let method = s.method();
            let msgp = s.msgp_mut().ok_or_else(|| MsgpError::InvalidSetting {
                name: "likelihood",
                reason: format!(
                    "{}: the likelihood of an MSGP fit; method {} has its own",
                    l.name(),
                    method.name()
                ),
            })?;
            msgp.likelihood = l;
        }
        self.switches.apply(&mut s)?;
        match &self.settings {
            Some(user) => by_name(s, user, path),
            None => Ok(s),
        }
    }
}

/// `s` with `m` pseudo-inputs.
fn with_inducing(s: FitSettings, m: usize) -> Result<FitSettings> {
    if m == 0 {
        return Err(MsgpError::InvalidSetting {
            name: "inducing",
            reason: "need at least one pseudo-input".into(),
        });
    }
    if s.method() == Method::LinearKf {
        return Err(refused(
            "inducing",
            "the pseudo-inputs of a GP",
            Method::LinearKf,
        ));
    }
    Ok(s.with_inducing(m))
}

/// `s` with the GP's prior mean `mean` ([`Overrides::mean`]).
fn with_mean(s: &mut FitSettings, mean: MeanFunction) -> Result<()> {
    match &mut s.method {
        MethodSettings::Msgp(m) => {
            let alternative = m.alternative.filter(|r| r.mean == mean);
            *m = match (m.mean == mean, m.alternative) {
                (true, _) => MsgpSettings {
                    alternative,
                    ..m.clone()
                },
                (false, Some(r)) if r.mean == mean => m.with_recipe(r),
                (false, _) => MsgpSettings {
                    mean,
                    alternative: None,
                    ..m.clone()
                },
            }
        }
        MethodSettings::GpNarx(o) | MethodSettings::PilcoNarx(o) => o.mean = mean,
        MethodSettings::LinearKf(_) if mean == MeanFunction::Linear => {}
        MethodSettings::LinearKf(_) => {
            return Err(MsgpError::InvalidSetting {
                name: "mean",
                reason: "a linear-kf model is its linear mean; it has no other".into(),
            });
        }
    }
    Ok(())
}

impl Switches {
    /// Turns the switches that are set in `s`.
    fn apply(&self, s: &mut FitSettings) -> Result<()> {
        if let Some(o) = self.one_step_objective {
            one_step_objective(s, o)?;
        }
        if let Some(on) = self.calibrate {
            msgp(s, "calibrate", "only msgp fits are calibrated")?.calibrate = on;
        }
        if let Some(on) = self.blow_up_fallback {
            let what = "where an msgp fit's zero-mean recipe may retrain";
            msgp(s, "blow_up_fallback", what)?.blow_up_fallback = on;
        }
        Ok(())
    }
}

/// `s` with its one-step fit's objective `o`: the baselines' own fit, MSGP's one-step start.
fn one_step_objective(s: &mut FitSettings, o: OneStepObjective) -> Result<()> {
    let method = s.method();
    let what = |of: &str| {
        format!(
            "the objective of a one-step fit; method {} {of}",
            method.name()
        )
    };
    let reason = match &mut s.method {
        MethodSettings::GpNarx(one) | MethodSettings::PilcoNarx(one) => {
            one.objective = o;
            return Ok(());
        }
        MethodSettings::Msgp(m) if m.start == MsgpStart::OneStep => {
            m.one_step_objective = o;
            return Ok(());
        }
        MethodSettings::Msgp(m) => what(&format!(
            "started from {} has none",
            match m.start {
                MsgpStart::Spread => "spread",
                _ => "linear-kf",
            }
        )),
        MethodSettings::LinearKf(_) => what("has none"),
    };
    Err(MsgpError::InvalidSetting {
        name: "one_step_objective",
        reason,
    })
}

/// `s` with the user's settings by name (at `path` of `settings`) laid over it
/// ([`crate::overlay`]); the threads are the base's (they are not a recorded setting).
fn by_name(s: FitSettings, user: &Value, path: &str) -> Result<FitSettings> {
    let threads = s.threads;
    let base = serde_json::to_value(&s)
        .map_err(|e| MsgpError::Overrides(format!("cannot describe the fit's defaults: {e}")))?;
    let merged: FitSettings = crate::overlay::merged_at(&base, user, "settings", path)?;
    Ok(FitSettings { threads, ..merged })
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::fit::settings::LINEAR_RECIPE;
    use crate::numeric::parallel::Threads;
    use serde_json::json;

    /// The policy loop's kind of base: one recipe, a linear prior mean.
    fn loop_base() -> FitSettings {
        let mut s = FitSettings::new(Method::Msgp);
        if let Some(m) = s.msgp_mut() {
            *m = m.with_recipe(LINEAR_RECIPE);
            m.learning_rate = 0.05;
        }
        s
    }

    fn mean(mean: MeanFunction) -> Overrides {
        Overrides {
            mean: Some(mean),
            ..Overrides::default()
        }
    }

    fn refusal(o: &Overrides, method: Method) -> (&'static str, String) {
        match o.apply(FitSettings::new(method)) {
            Err(MsgpError::InvalidSetting { name, reason }) => (name, reason),
            other => panic!("not refused: {other:?}"),
        }
    }

    #[test]
    fn no_overrides_leave_the_base_as_it_is() {
        for method in Method::ALL {
            let base = FitSettings::new(method);
            assert_eq!(Overrides::default().apply(base.clone()).expect("ok"), base);
        }
    }

    /// A mean picks the base's recipe of that mean where it trains two, and otherwise sets
    /// the mean of its one recipe (keeping the rest of it): one meaning whichever base.
    #[test]
    fn a_mean_trains_that_means_recipe_alone() {
        let two = FitSettings::new(Method::Msgp);
        let linear = mean(MeanFunction::Linear).apply(two.clone()).expect("ok");
        let m = linear.msgp().expect("msgp");
        assert_eq!((m.recipe(), m.alternative), (LINEAR_RECIPE, None));
        let zero = mean(MeanFunction::Zero).apply(two.clone()).expect("ok");
        let z = zero.msgp().expect("msgp");
        let own = two.msgp().expect("msgp").recipe();
        assert_eq!((z.recipe(), z.alternative), (own, None));
        let one = mean(MeanFunction::Zero).apply(loop_base()).expect("ok");
        let o = one.msgp().expect("msgp");
        assert_eq!(
            (o.mean, o.learning_rate, o.complexity),
            (MeanFunction::Zero, 0.05, LINEAR_RECIPE.complexity)
        );
        let same = mean(MeanFunction::Linear).apply(loop_base()).expect("ok");
        assert_eq!(same, loop_base());
        // both recipes of the mean asked for: both stay
        let mut both = loop_base();
        if let Some(m) = both.msgp_mut() {
            m.alternative = Some(LINEAR_RECIPE);
        }
        let kept = mean(MeanFunction::Linear).apply(both.clone()).expect("ok");
        assert_eq!(kept, both);
        let narx = mean(MeanFunction::Linear)
            .apply(FitSettings::new(Method::GpNarx))
            .expect("ok");
        assert_eq!(narx.mean(), MeanFunction::Linear);
        let kf = FitSettings::new(Method::LinearKf);
        assert_eq!(
            mean(MeanFunction::Linear).apply(kf.clone()).expect("ok"),
            kf
        );
    }

    #[test]
    fn iterations_and_pseudo_inputs_reach_the_methods_own_solver_and_gp() {
        let o = Overrides {
            iterations: Some(17),
            inducing: Some(9),
            ..Overrides::default()
        };
        for method in [Method::Msgp, Method::GpNarx, Method::PilcoNarx] {
            let s = o.apply(FitSettings::new(method)).expect("ok");
            assert_eq!((s.solver_iterations(), s.inducing()), (17, Some(9)));
        }
        let msgp = o.apply(FitSettings::new(Method::Msgp)).expect("ok");
        assert_eq!(
            msgp.msgp().expect("msgp").one_step_iterations,
            FitSettings::new(Method::Msgp)
                .msgp()
                .expect("msgp")
                .one_step_iterations,
            "the one-step start keeps its own"
        );
    }

    #[test]
    fn what_a_method_has_not_is_refused_by_name() {
        let inducing = |m| Overrides {
            inducing: Some(m),
            ..Overrides::default()
        };
        let (name, reason) = refusal(&inducing(0), Method::Msgp);
        assert_eq!(
            (name, reason.as_str()),
            ("inducing", "need at least one pseudo-input")
        );
        let (name, reason) = refusal(&inducing(5), Method::LinearKf);
        assert_eq!(name, "inducing");
        assert!(reason.contains("method linear-kf has none"), "{reason}");
        let (name, _) = refusal(&mean(MeanFunction::Zero), Method::LinearKf);
        assert_eq!(name, "mean");
        let filter = Overrides {
            likelihood: Some(Likelihood::Filter),
            ..Overrides::default()
        };
        let (name, reason) = refusal(&filter, Method::PilcoNarx);
        assert_eq!(name, "likelihood");
        assert!(reason.starts_with("filter: the likelihood of an MSGP fit; method pilco-narx"));
        let spread = FitSettings {
            method: MethodSettings::Msgp(MsgpSettings {
                start: MsgpStart::Spread,
                ..MsgpSettings::default()
            }),
            ..FitSettings::new(Method::Msgp)
        };
        let objective = Overrides {
            switches: Switches {
                one_step_objective: Some(OneStepObjective::Vfe),
                ..Switches::default()
            },
            ..Overrides::default()
        };
        match objective.apply(spread) {
            Err(MsgpError::InvalidSetting { name, reason }) => {
                assert_eq!(name, "one_step_objective");
                assert!(reason.contains("started from spread has none"), "{reason}");
            }
            other => panic!("not refused: {other:?}"),
        }
    }

    /// Settings by name come after the typed overrides (the dict has the last word), keep the
    /// base's threads, and an unknown or ill-typed one is named.
    #[test]
    fn settings_by_name_come_last_and_are_named_when_wrong() {
        let base = FitSettings {
            threads: Threads::new(1).expect("one"),
            ..FitSettings::new(Method::Msgp)
        };
        let o = Overrides {
            iterations: Some(50),
            settings: Some(json!({"iterations": 70, "patience": 3})),
            ..Overrides::default()
        };
        let s = o.apply(base.clone()).expect("ok");
        let m = s.msgp().expect("msgp");
        assert_eq!((m.iterations, m.patience, s.threads), (70, 3, base.threads));
        let unknown = Overrides {
            settings: Some(json!({"patienc": 3})),
            ..Overrides::default()
        };
        let e = unknown
            .apply(base.clone())
            .expect_err("unknown")
            .to_string();
        assert!(e.starts_with("settings: unknown setting `patienc`"), "{e}");
        let typed = Overrides {
            settings: Some(json!({"patience": "many"})),
            ..Overrides::default()
        };
        let e = typed.apply(base).expect_err("ill-typed").to_string();
        assert!(e.starts_with("settings.patience: invalid type"), "{e}");
    }
}
