"""The typed settings (`msgp.settings`) name exactly the fields of the Rust `FitSettings` of
each method, and every literal type admits the default the Rust side writes."""

import typing

import pytest

import msgp
from msgp import settings as typed

BY_METHOD = {
    "msgp": typed.MsgpFitSettings,
    "gp-narx": typed.OneStepFitSettings,
    "pilco-narx": typed.OneStepFitSettings,
    "linear-kf": typed.LinearKfFitSettings,
}


def keys(cls):
    return set(cls.__required_keys__) | set(cls.__optional_keys__)


@pytest.mark.parametrize("method", sorted(BY_METHOD))
def test_the_typed_settings_are_the_rust_fields(method):
    defaults = msgp.defaults("fit", method=method)
    cls = BY_METHOD[method]
    assert keys(cls) == set(defaults) - {"method"}
    admits_the_defaults(cls, defaults)
    if method == "msgp":
        assert keys(typed.Recipe) == set(defaults["alternative"])
        admits_the_defaults(typed.Recipe, defaults["alternative"])


def admits_the_defaults(cls, defaults):
    """Every string default is a value of its field's literal type, where it has one."""
    hints = typing.get_type_hints(cls)
    for name, value in defaults.items():
        literal = literal_values(hints.get(name))
        if literal is not None and isinstance(value, str):
            assert value in literal, (cls.__name__, name, value, literal)


def literal_values(hint):
    """The values a `Literal` hint (possibly inside `Optional`/`Union`/`List`) admits."""
    if hint is None:
        return None
    if typing.get_origin(hint) is typing.Literal:
        return set(typing.get_args(hint))
    found = [literal_values(a) for a in typing.get_args(hint)]
    found = [f for f in found if f is not None]
    return set().union(*found) if found else None


def test_frozen_groups_and_integrators_use_the_rust_names():
    frozen = typing.get_type_hints(typed.MsgpFitSettings)["frozen"]
    names = literal_values(frozen)
    assert set(msgp.defaults("fit")["frozen"]) <= names
    learned = msgp.defaults("learn")["fit"]
    assert keys(typed.Integrator) == set(learned["integrators"][0])
    # a typed dict is the dict a fit takes
    s: typed.MsgpFitSettings = {"mean": "linear", "integrators": [{"output": 0, "order": 2}]}
    model = msgp.Msgp(history=(2, 2), inducing=10, iterations=5, settings=s)
    assert model is not None


def test_a_field_of_another_method_is_refused_by_name():
    with pytest.raises(msgp.InvalidInputError, match="objective"):
        msgp.Msgp(method="msgp", settings={"objective": "exact"})


@pytest.mark.parametrize(
    ("what", "cls", "nested"),
    [
        ("learner", typed.LearnerSettings, {"excitation": typed.Excitation}),
        ("learn", typed.PendulumLearnSettings, {"excitation": typed.PendulumExcitation}),
    ],
)
def test_the_typed_loop_settings_are_the_rust_fields(what, cls, nested):
    defaults = msgp.defaults(what)
    assert keys(cls) == set(defaults)
    assert keys(typed.PolicySearchSettings) == set(defaults["search"])
    admits_the_defaults(typed.PolicySearchSettings, defaults["search"])
    for field, inner in nested.items():
        assert keys(inner) == set(defaults[field])
    # the loop's fit: the method's own settings, under its serialised tag
    fit = dict(defaults["fit"])
    by_tag = {"Msgp": "msgp", "GpNarx": "gp-narx", "PilcoNarx": "pilco-narx", "LinearKf": "linear-kf"}
    assert keys(BY_METHOD[by_tag[fit.pop("method")]]) == set(fit)

