"""Bad input raises ValueError (msgp.InvalidInputError) with a message that says what is
wrong; other failures raise msgp.MsgpError subclasses; nothing panics."""

import json

import numpy as np
import pytest

import msgp

U = np.linspace(-1, 1, 60)
Y = np.sin(3 * U)


def test_exception_hierarchy():
    assert issubclass(msgp.InvalidInputError, ValueError)
    for cls in (msgp.InvalidInputError, msgp.NumericalError, msgp.ModelFileError, msgp.NotFittedError):
        assert issubclass(cls, msgp.MsgpError), cls
    assert issubclass(msgp.MsgpError, Exception)
    assert msgp.InvalidInputError.__module__ == "msgp"


@pytest.mark.parametrize(
    "u, y, message",
    [
        (U, Y[:-1], "u has 60 samples but y has 59"),
        (U.reshape(2, 3, 10), Y, r"u must be 1-D \(n,\) or 2-D \(n, d\), got shape \(2, 3, 10\)"),
        (np.where(U > 0.5, np.nan, U), Y, r"u has a non-finite value \(NaN\) at sample 45, column 0"),
        (U, np.where(U > 0, np.inf, Y), r"y has a non-finite value \(inf\) at sample 30"),
        (U[:2], Y[:2], "has 2 samples; the history \\(l_y=2, l_u=2\\) needs more than 2"),
        (np.zeros(0), np.zeros(0), "u has no samples"),
        (["a", "b"], Y[:2], r"u must be an array of real numbers, got strings \(dtype <U1\)"),
        (U + 1j, Y, r"u must be an array of real numbers, got complex numbers \(dtype complex128\)"),
        (U, np.array([str(v) for v in Y]), r"y must be an array of real numbers, got strings"),
        (U.astype("datetime64[s]"), Y, r"u must be an array of real numbers, got dates or times"),
        ([U, U], Y, "u is a list of 2 arrays .* but y is not"),
        ([U, U], [Y], "u holds 2 trajectories but y holds 1"),
        ([U, U.reshape(-1, 1).repeat(2, axis=1)], [Y, Y], "trajectory 1 has 2 input and 1 output columns; trajectory 0 has 1 and 1"),
    ],
)
def test_bad_fit_data(u, y, message):
    with pytest.raises(ValueError, match=message):
        msgp.Msgp(inducing=5, iterations=1).fit(u, y)


def test_integer_and_strided_arrays_are_read_as_their_values():
    """Integers, booleans and arrays in any memory layout are real numbers: the same fit as the
    equal float64 C-contiguous arrays, bit for bit."""
    steps = np.rint(U * 10).astype(np.int32)

    def rmse(u, y):
        model = msgp.Msgp(inducing=5, iterations=3, seed=0).fit(u, y)
        return model.score(U, Y)["rmse"]

    assert rmse(steps, Y) == rmse(steps.astype(float), Y)
    assert rmse(U > 0, Y) == rmse((U > 0).astype(float), Y)
    wide = np.repeat(np.stack([U, Y], axis=1), 2, axis=0)
    strided_u, strided_y = wide[::2, 0], wide[::2, 1]
    assert not strided_u.flags.c_contiguous
    assert rmse(strided_u, strided_y) == rmse(U.copy(), Y.copy())
    both = np.asfortranarray(np.stack([U, U**2], axis=1))
    fitted = msgp.Msgp(inducing=5, iterations=3, seed=0).fit(both, Y)
    again = msgp.Msgp(inducing=5, iterations=3, seed=0).fit(np.ascontiguousarray(both), Y)
    assert fitted.score(both, Y) == again.score(np.ascontiguousarray(both), Y)


@pytest.mark.parametrize(
    "kwargs, message",
    [
        (dict(method="magic"), 'unknown method "magic": expected one of "msgp", "gp-narx", "pilco-narx"'),
        (dict(history=(0, 2)), "l_y must be at least 1"),
        (dict(history=3), r"history must be a pair \(l_y, l_u\)"),
        (dict(history=(1, 2, 3)), r"history must be a pair"),
        (dict(inducing=0), "inducing must be at least 1"),
        (dict(inducing=-4), "inducing must be a non-negative integer, got -4"),
        (dict(seed=-1), "seed must be a non-negative integer, got -1"),
        (dict(settings={"learning_rat": 0.1}), "unknown setting `learning_rat`"),
        (dict(settings={"seed": 3}), r"Msgp\(seed=...\)"),
        (dict(settings={"learning_rate": "fast"}), "settings.learning_rate: invalid type: string \"fast\", expected f64"),
        (dict(settings={"learning_rate": float("nan")}), "not finite"),
        # each method has its own settings: another method's is named as such
        (
            dict(method="gp-narx", settings={"learning_rate": 0.1}),
            r'settings\["learning_rate"\]: a setting of method msgp, not of gp-narx, whose settings are integrators, mean',
        ),
        (
            dict(method="linear-kf", settings={"mean": "zero"}),
            r'settings\["mean"\]: a setting of method msgp and gp-narx and pilco-narx, not of linear-kf',
        ),
    ],
)
def test_bad_constructor_arguments(kwargs, message):
    with pytest.raises(ValueError, match=message):
        msgp.Msgp(**kwargs)


def test_fit_defaults_are_the_methods_own():
    """`defaults("fit", method=...)`: the shared settings and the method's own only."""
    shared = {"ly", "lu", "seed", "integrators", "method"}
    assert set(msgp.defaults("fit", method="gp-narx")) == shared | {"inducing", "mean", "iterations", "solver", "objective"}
    assert set(msgp.defaults("fit", method="linear-kf")) == shared | {"iterations"}
    full = msgp.defaults("fit")
    assert full == msgp.defaults("fit", method="msgp")
    assert {"learning_rate", "one_step_iterations", "start_window", "alternative"} <= set(full)
    with pytest.raises(ValueError, match=r'settings\["fit"\]\["method"\]: set it with the learn_policy\(method=...\)'):
        msgp.learn_policy(iterations=1, settings={"fit": {"method": "GpNarx"}})


def test_bad_names():
    with pytest.raises(ValueError, match="input_names has 2 names for 1 columns"):
        msgp.Msgp(inducing=5, iterations=1).fit(U, Y, input_names=["a", "b"])
    with pytest.raises(ValueError, match='"x" is both an input and an output name'):
        msgp.Msgp(inducing=5, iterations=1).fit(U, Y, input_names=["x"], output_names=["x"])


@pytest.fixture(scope="module")
def small():
    return msgp.Msgp(history=(2, 2), method="gp-narx", inducing=5, iterations=5).fit(U, Y)


def test_bad_prediction_inputs(small):
    with pytest.raises(ValueError, match="data with 2 input and 1 output columns; the model has 1 and 1"):
        small.score(np.ones((10, 2)), np.ones(10))
    with pytest.raises(ValueError, match=r"y_init has 1 samples; the simulation starts from the first 2 outputs"):
        small.simulate(U, Y[:1])
    with pytest.raises(ValueError, match="u has 2 samples; the history"):
        small.simulate(U[:2], Y[:2])
    with pytest.raises(ValueError, match="y_init has 61 samples, more than the 60 of u"):
        small.simulate(U, np.ones(61))
    with pytest.raises(ValueError, match="trajectory 1: 2 samples"):
        small.score([U, U[:2]], [Y, Y[:2]])


def test_not_fitted():
    with pytest.raises(msgp.NotFittedError, match="not fitted yet"):
        msgp.Msgp().simulate(U, Y)
    with pytest.raises(msgp.NotFittedError):
        _ = msgp.Msgp().params


def test_model_file_errors(tmp_path, small):
    with pytest.raises(msgp.ModelFileError, match="cannot read the model"):
        msgp.Msgp.load(tmp_path / "missing.json")
    bad = tmp_path / "bad.json"
    bad.write_text('{"format": "msgp-model", "format_version": "2.0"}')
    with pytest.raises(msgp.ModelFileError, match="version 2.0 is not supported"):
        msgp.Msgp.load(bad)
    bad.write_text(small.to_json().replace('"log_signal_var": [', '"log_signal_var": [1.0, '))
    with pytest.raises(msgp.ModelFileError, match="`gp.log_signal_var` has 2 entries, expected 1"):
        msgp.Msgp.load(bad)
    with pytest.raises(msgp.ModelFileError, match="cannot create a temporary file"):
        small.save(tmp_path / "no" / "such" / "folder" / "m.json")


def test_numerical_failure_is_a_numerical_error(small):
    """A model file whose signal variance overflows: it loads, but predicting fails cleanly."""
    doc = json.loads(small.to_json())
    doc["gp"]["log_signal_var"] = [800.0]
    model = msgp.Msgp.from_json(json.dumps(doc))
    with pytest.raises(msgp.NumericalError, match="not positive definite"):
        model.score(U, Y)


def test_bad_experiment_arguments():
    with pytest.raises(ValueError, match="`synthetic system`: 9 is not one of 1–5"):
        msgp.synthetic_system(9)
    with pytest.raises(ValueError, match="noise must be"):
        msgp.synthetic_system(4, noise="loud")
    with pytest.raises(ValueError, match='unknown controller "wobbly"'):
        msgp.run_episode("wobbly")
    with pytest.raises(ValueError, match="gains need 5 numbers"):
        msgp.stability_test([1.0, 2.0])
    with pytest.raises(ValueError, match="missing field `kd_theta`"):
        msgp.stability_test({"kp_x": 1, "ki_x": 0, "kd_x": 1, "kp_theta": 30})
    with pytest.raises(ValueError, match="invalid pole_mass = -1"):
        msgp.run_episode("zero", seconds=0.1, params={"pole_mass": -1.0})
    with pytest.raises(ValueError, match="unknown setting `pole_mas`"):
        msgp.run_episode("zero", seconds=0.1, params={"pole_mas": 1.0})
    with pytest.raises(ValueError, match="seconds"):
        msgp.run_episode("zero", seconds=-1.0)
    with pytest.raises(ValueError, match="unknown setting `fit.iteratons`"):
        msgp.learn_policy(iterations=1, settings={"fit": {"iteratons": 3}})
    with pytest.raises(ValueError, match='unknown method "pilco"'):
        msgp.learn_policy(method="pilco")
    with pytest.raises(ValueError, match="no defaults for"):
        msgp.defaults("robot")


def test_the_msgp_likelihood_is_an_argument():
    """`Msgp(likelihood="filter")` trains MSGP on the filter likelihood (recorded in the saved
    model's training settings, read back by `load`, kept by pickling an unfitted model); another
    method refuses it by name, as does `settings`; a bad value is named."""
    import json
    import pickle
    d = msgp.synthetic_system(4, seed=0)
    u, y = d["u_train"][:120], d["y_train"][:120]
    m = msgp.Msgp(history=(2, 1), inducing=8, iterations=5, likelihood="filter")
    assert m.likelihood == "filter" and "likelihood='filter'" in repr(m)
    assert pickle.loads(pickle.dumps(m)).likelihood == "filter"
    m.fit(u, y)
    free = msgp.Msgp(history=(2, 1), inducing=8, iterations=5).fit(u, y)
    assert free.likelihood == "free-run" and "likelihood" not in repr(free)
    doc = json.loads(m.to_json())
    assert doc["training"]["settings"]["likelihood"] == "filter"
    assert msgp.Msgp.from_json(m.to_json()).likelihood == "filter"
    assert json.loads(free.to_json())["training"]["settings"]["likelihood"] == "free-run"
    assert m.params["pseudo_targets"].tolist() != free.params["pseudo_targets"].tolist()
    assert msgp.Msgp(method="gp-narx").likelihood is None
    with pytest.raises(ValueError, match='likelihood="filter": the likelihood of an MSGP fit; method "gp-narx"'):
        msgp.Msgp(method="gp-narx", likelihood="filter")
    with pytest.raises(ValueError, match=r'settings\["likelihood"\]: set it with the Msgp\(likelihood=...\) argument'):
        msgp.Msgp(settings={"likelihood": "filter"})
    with pytest.raises(ValueError, match='unknown likelihood "kalman"'):
        msgp.Msgp(likelihood="kalman")


def test_the_msgp_start_is_an_argument():
    """`Msgp(start="linear-kf")` starts MSGP from the linear-kf model (recorded in the model
    file with the linear mean it implies, kept by pickling an unfitted model), as `msgp fit
    --start linear-kf`, and `start="spread"` from the one-step fit's starting point; another
    method and an unknown start are refused by name."""
    import json
    import pickle
    d = msgp.synthetic_system(4, seed=0)
    u, y = d["u_train"][:120], d["y_train"][:120]
    m = msgp.Msgp(history=(2, 1), inducing=8, iterations=5, likelihood="filter", start="linear-kf")
    assert "start='linear-kf'" in repr(m)
    assert "start='linear-kf'" in repr(pickle.loads(pickle.dumps(m)))
    m.fit(u, y)
    settings = json.loads(m.to_json())["training"]["settings"]
    assert (settings["start"], settings["mean"], settings["alternative"]) == ("linear-kf", "linear", None)
    with pytest.raises(ValueError, match="`start`: where an MSGP fit starts; method gp-narx has none"):
        msgp.Msgp(method="gp-narx", start="linear-kf")
    with pytest.raises(ValueError, match='unknown start "kalman": expected "one-step", "spread" or "linear-kf"'):
        msgp.Msgp(start="kalman")
    # the spread start: the one-step fit's starting point, not optimised (`msgp fit --start spread`)
    s = msgp.Msgp(history=(2, 1), inducing=8, iterations=5, start="spread", seed=0).fit(u, y)
    assert "start='spread'" in repr(s)
    settings = json.loads(s.to_json())["training"]["settings"]
    assert (settings["start"], settings["blow_up_fallback"]) == ("spread", True)
    with pytest.raises(ValueError, match=r'settings\["start"\]: set it with the Msgp\(start=...\) argument'):
        msgp.Msgp(settings={"start": "linear-kf"})


def test_warnings_about_the_data_do_not_stop_a_fit(tmp_path):
    """Too few training windows for the pseudo-inputs and an irregular time step are warnings
    that say what was done, in Python and on the command line (stderr and --json)."""
    import subprocess

    from conftest import msgp_bin

    with pytest.warns(UserWarning, match="only 4 windows .* so the model gets 2 pseudo-inputs"):
        msgp.Msgp(iterations=2).fit(U[:6], Y[:6])
    with pytest.warns(UserWarning, match="100 pseudo-inputs requested but .* 58 windows"):
        msgp.Msgp(inducing=100, iterations=1, method="gp-narx").fit(U, Y)
    with pytest.warns(UserWarning, match="l_y=40, l_u=40 makes 80 GP inputs but .* only 20 windows"):
        msgp.Msgp(history=(40, 40), iterations=1, method="gp-narx").fit(U, Y)
    t = np.arange(60) * 0.02
    t[30:] += 0.02  # one dropped sample
    path = tmp_path / "gap.csv"
    rows = zip(t.tolist(), U.tolist(), Y.tolist())
    path.write_text("t,u,y\n" + "".join(f"{a!r},{b!r},{c!r}\n" for a, b, c in rows))
    loaded = msgp.load(path)
    (warning,) = loaded["warnings"]
    assert "gap.csv: the time step of `t` is irregular: 1 of 59 steps" in warning
    assert "line 32 (a step of 0.04, 100 % off)" in warning
    proc = subprocess.run(
        [str(msgp_bin()), "fit", "--data", path, "--method", "gp-narx", "--iters", "2", "--json",
         "--out", tmp_path / "m.json"],
        capture_output=True, text=True, timeout=120,
    )
    assert proc.returncode == 0, proc.stderr
    assert f"warning: {warning}" in proc.stderr
    assert json.loads(proc.stdout)["warnings"] == [warning]
