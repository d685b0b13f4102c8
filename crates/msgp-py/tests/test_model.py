"""The Msgp API: shapes, save/load, pickling, and checks against independent numpy
computations of the documented equations (docs/model-format.md)."""

import json
import math
import pickle

import numpy as np
import pytest

import msgp


@pytest.fixture(scope="module")
def fitted():
    data = msgp.synthetic_system(3, seed=3)
    model = msgp.Msgp(history=data["history"], method="gp-narx", iterations=40, seed=1)
    return model.fit(data["u_train"], data["y_train"]), data


def test_fit_returns_self_and_describes_itself(fitted):
    model, data = fitted
    assert model.is_fitted
    assert model.method == "gp-narx" and model.history == (1, 1) and model.seed == 1
    assert model.inducing == 100  # min(100, 299 windows / 2)
    assert model.warmup == 1
    assert model.input_names == ["u"] and model.output_names == ["y"]
    assert "fitted on 1 trajectory, 300 samples" in repr(model)
    t = model.training
    assert t["samples"] == 300 and t["trajectories"] == 1 and t["seed"] == 1
    assert t["data_hash"].startswith("fnv1a64:")
    assert model.report["iterations_run"] == 0


def test_params_are_numpy_arrays_of_the_documented_shapes(fitted):
    model, _ = fitted
    p = model.params
    m, D = 100, 2
    assert p["pseudo_inputs"].shape == (m, D)
    assert p["pseudo_targets"].shape == (m, 1)
    assert p["log_lengthscales"].shape == (1, D)
    for k in ("log_signal_var", "log_process_noise", "log_obs_noise", "u_mean", "u_std", "y_mean", "y_std"):
        assert p[k].shape == (1,) and p[k].dtype == np.float64, k
    assert p["noise_floor"] >= 0.0


def numpy_gp(p, window):
    """Eq. (13) of the model-format doc in numpy for output 0, from `params`: the GP's mean (the
    linear prior mean not included) and variance at `window`."""
    X, ybar = p["pseudo_inputs"], p["pseudo_targets"][:, 0]
    ell = np.exp(p["log_lengthscales"][0])
    sf2 = math.exp(p["log_signal_var"][0])
    sx2 = p["noise_floor"] + math.exp(p["log_process_noise"][0])

    def k(a, b):
        d = (a[:, None, :] - b[None, :, :]) / ell
        return sf2 * np.exp(-0.5 * np.sum(d * d, axis=2))

    Kt = k(X, X) + sx2 * np.eye(len(X))
    kx = k(X, window[None, :])[:, 0]
    return kx @ np.linalg.solve(Kt, ybar), sf2 - kx @ np.linalg.solve(Kt, kx)


def test_reference_prediction_matches_numpy_gp(fitted):
    """Eq. (13) of the model-format doc in numpy, from `params`, at the reference window."""
    model, _ = fitted
    p, ref = model.params, model.reference
    mean, var = numpy_gp(p, ref["window"])
    assert abs(mean - ref["mean"][0]) < 1e-9
    assert abs(var - ref["var"][0]) < 1e-9


def test_linear_prior_mean_is_in_params_file_and_prediction(tmp_path):
    """`settings={"mean": "linear"}`: A in `params` and the file, and eq. (13) plus A x̃ in numpy."""
    data = msgp.synthetic_system(3, seed=3)
    model = msgp.Msgp(history=data["history"], method="gp-narx", inducing=30, iterations=40, seed=1,
                      settings={"mean": "linear"}).fit(data["u_train"], data["y_train"])
    p, ref = model.params, model.reference
    A = p["linear_mean"]
    assert A.shape == (1, 2) and np.all(A != 0.0)
    gp_mean, var = numpy_gp(p, ref["window"])
    assert abs(gp_mean + A[0] @ ref["window"] - ref["mean"][0]) < 1e-9
    assert abs(var - ref["var"][0]) < 1e-9
    path = tmp_path / "lin.json"
    model.save(path)
    doc = json.loads(path.read_text())
    assert np.array_equal(np.array(doc["gp"]["linear_mean"]), A)
    loaded = msgp.Msgp.load(str(path))
    a = model.simulate(data["u_test"], data["y_test"])
    b = loaded.simulate(data["u_test"], data["y_test"])
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    # `score` holds the simulation against the measured outputs as `msgp eval` does: silent on
    # this model, a warning and the reason when its output lag's coefficient is a pole at 1.1
    s = model.score(data["u_test"], data["y_test"])
    assert s["diverged"] is False and s["divergence"] is None
    doc["gp"]["linear_mean"][0][0] = 1.1
    unstable = msgp.Msgp.from_json(json.dumps(doc))
    with pytest.warns(RuntimeWarning, match="diverges on this data"):
        s = unstable.score(data["u_test"][:60], data["y_test"][:60])
    assert s["diverged"] is True
    # the drawn functions' band explodes first; the paper's moment matching leaves in the mean
    assert "predicted standard deviation" in s["divergence"], s["divergence"]
    with pytest.warns(RuntimeWarning, match="diverges on this data"):
        s = unstable.score(data["u_test"][:60], data["y_test"][:60], rollout="mm-independent")
    assert "the data leaves the measured outputs' range" in s["divergence"], s["divergence"]
    # without the mean the file has no such field
    plain = msgp.Msgp(history=data["history"], method="gp-narx", inducing=30, iterations=5, seed=1)
    plain.fit(data["u_train"], data["y_train"]).save(tmp_path / "plain.json")
    assert "linear_mean" not in json.loads((tmp_path / "plain.json").read_text())["gp"]
    assert np.all(plain.params["linear_mean"] == 0.0)


def test_integrating_output_is_a_setting():
    """`settings={"integrators": ...}` fixes the declared coefficient of A; without the linear
    mean it is a clear error."""
    data = msgp.synthetic_system(3, seed=3)
    declared = {"integrators": [{"output": 0, "order": 1}]}
    model = msgp.Msgp(history=data["history"], method="gp-narx", inducing=30, iterations=40, seed=1,
                      settings={"mean": "linear", **declared}).fit(data["u_train"], data["y_train"])
    A = model.params["linear_mean"]
    assert A[0, 0] == 1.0 and A[0, 1] != 0.0
    bad = msgp.Msgp(history=data["history"], method="gp-narx", inducing=30, iterations=5, seed=1,
                    settings=declared)
    with pytest.raises(ValueError, match="integrators"):
        bad.fit(data["u_train"], data["y_train"])


def test_score_matches_numpy_metrics_of_simulate(fitted):
    """RMSE, NLL and coverage recomputed in numpy from `simulate`'s mean and variance."""
    model, data = fitted
    u, y = data["u_test"], data["y_test"]
    mean, var = model.simulate(u, y[: model.warmup])
    assert mean.shape == var.shape == (len(u) - model.warmup, 1)
    assert np.all(var > 0)
    r = y[model.warmup:] - mean[:, 0]
    v = var[:, 0]
    s = model.score(u, y)
    assert s["steps"] == len(r)
    assert abs(s["rmse"] - math.sqrt(np.mean(r * r))) < 1e-12
    nll = np.mean(0.5 * (r * r / v + np.log(v) + math.log(2 * math.pi)))
    assert abs(s["nll"] - nll) < 1e-10
    assert s["coverage_2sigma"] == np.mean(np.abs(r) <= 2 * np.sqrt(v))


def test_simulate_uses_only_the_first_outputs(fitted):
    model, data = fitted
    u, y = data["u_test"], data["y_test"]
    a = model.simulate(u, y)
    b = model.simulate(u, y[: model.warmup])
    c = model.simulate(u.reshape(-1, 1), y[: model.warmup].reshape(-1, 1).tolist())
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[0], c[0])
    assert np.array_equal(a[1], b[1])


def test_save_load_round_trip_is_exact(fitted, tmp_path):
    model, data = fitted
    path = tmp_path / "m.json"
    model.save(path)
    assert not [p for p in tmp_path.iterdir() if p.name != "m.json"], "no temporary file left"
    loaded = msgp.Msgp.load(str(path))
    assert loaded.report is None and loaded.training == model.training
    for k, v in model.params.items():
        assert np.array_equal(v, loaded.params[k]), k
    a = model.simulate(data["u_test"], data["y_test"])
    b = loaded.simulate(data["u_test"], data["y_test"])
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])
    assert model.score(data["u_test"], data["y_test"]) == loaded.score(data["u_test"], data["y_test"])
    doc = json.loads(path.read_text())
    assert doc["format"] == "msgp-model" and doc["format_version"] == "1.4"
    assert msgp.Msgp.from_json(model.to_json()).to_json() == model.to_json()


def test_pickle_round_trip(fitted):
    model, data = fitted
    back = pickle.loads(pickle.dumps(model))
    assert back.to_json() == model.to_json()
    fresh = pickle.loads(pickle.dumps(msgp.Msgp(history=(3, 1), inducing=7, seed=5)))
    assert (fresh.history, fresh.inducing, fresh.seed, fresh.is_fitted) == ((3, 1), 7, 5, False)


def test_several_outputs_and_names(tmp_path):
    """Two inputs, two outputs, two trajectories; names go into the model file."""
    rng = np.random.default_rng(0)
    trajs = []
    for _ in range(2):
        u = rng.uniform(-1, 1, size=(120, 2))
        y = np.zeros((120, 2))
        for t in range(1, 120):
            y[t, 0] = 0.7 * y[t - 1, 0] + np.sin(2 * u[t - 1, 0])
            y[t, 1] = 0.5 * y[t - 1, 1] + 0.3 * y[t - 1, 0] + u[t - 1, 1]
        trajs.append((u, y + 0.01 * rng.standard_normal(y.shape)))
    model = msgp.Msgp(history=(1, 1), method="gp-narx", inducing=15, iterations=20)
    model.fit([u for u, _ in trajs], [y for _, y in trajs], input_names=["a", "b"], output_names=["p", "q"])
    assert model.params["pseudo_inputs"].shape == (15, 4)
    assert model.input_names == ["a", "b"] and model.output_names == ["p", "q"]
    mean, var = model.simulate(*trajs[0])
    assert mean.shape == var.shape == (119, 2)
    s = model.score([u for u, _ in trajs], [y for _, y in trajs])
    assert s["steps"] == 2 * 119


def test_settings_reach_the_fit():
    data = msgp.synthetic_system(3, seed=0)
    model = msgp.Msgp(
        history=(1, 1), inducing=10, iterations=5, settings={"learning_rate": 0.01, "one_step_iterations": 20}
    ).fit(data["u_train"], data["y_train"])
    s = model.training["settings"]
    assert s["learning_rate"] == 0.01 and s["one_step_iterations"] == 20 and s["iterations"] == 5
    assert msgp.defaults("fit")["learning_rate"] == 0.002


def test_fit_reports_progress_and_stops_on_its_exception():
    """`progress` sees every MSGP training iteration with its loss; an exception it raises
    stops the fit, comes out of `fit` and leaves the model unfitted; a fit with `progress`
    gives the same model as one without."""
    data = msgp.synthetic_system(3, seed=0)
    args = dict(history=(1, 1), inducing=10, iterations=8, seed=2, settings={"one_step_iterations": 20})
    seen = []
    model = msgp.Msgp(**args).fit(data["u_train"], data["y_train"], progress=seen.append)
    assert [p["iteration"] for p in seen if p["stage"] == 1][:3] == [0, 1, 2]
    assert all(np.isfinite(p["loss"]) and p["iterations"] == 8 for p in seen)
    assert seen[-1]["elapsed"] >= seen[0]["elapsed"] >= 0.0
    plain = msgp.Msgp(**args).fit(data["u_train"], data["y_train"])
    assert all(np.array_equal(model.params[k], plain.params[k]) for k in plain.params)

    class Enough(Exception):
        pass

    def stop_at_third(p):
        if p["iteration"] == 2:
            raise Enough()

    stopped = msgp.Msgp(**args)
    with pytest.raises(Enough):
        stopped.fit(data["u_train"], data["y_train"], progress=stop_at_third)
    with pytest.raises(msgp.NotFittedError):
        _ = stopped.params
    with pytest.raises(msgp.InvalidInputError, match="callable"):
        msgp.Msgp(**args).fit(data["u_train"], data["y_train"], progress="loud")


def test_the_divergence_check_reaches_python(fitted, tmp_path):
    """A sound fit is not flagged; a model whose noise floor (10⁶ in normalised units) makes its
    predicted spread hundreds of times the outputs' range is: the fit warns, `diverged` says
    why, and the reason survives saving and loading."""
    model, data = fitted
    assert model.diverged is None
    assert model.training["diverged"] is None
    assert model.report["diverged"] is None
    wide = msgp.Msgp(history=(1, 1), inducing=8, iterations=2, seed=0,
                     settings={"noise_floor": 1e6})
    with pytest.warns(RuntimeWarning, match="diverges"):
        wide.fit(data["u_train"], data["y_train"])
    assert "standard deviation" in wide.diverged
    path = tmp_path / "wide.json"
    wide.save(str(path))
    assert msgp.Msgp.load(str(path)).diverged == wide.diverged


def test_segment_length_trains_by_segments_and_says_so():
    data = msgp.synthetic_system(3, seed=3)
    kw = dict(history=data["history"], inducing=10, iterations=5, seed=0)
    cut = msgp.Msgp(segment_length=50, **kw).fit(data["u_train"], data["y_train"])
    # 300 samples, a window of 1: 299 predicted steps in segments of 50
    (segments, count) = cut.report["segments"]
    assert segments == {"length": 50, "batch": 2} and count == 6
    whole = msgp.Msgp(segment_length=0, **kw).fit(data["u_train"], data["y_train"])
    assert whole.report["segments"] is None
    with pytest.raises(ValueError, match="segment_length"):
        msgp.Msgp(method="gp-narx", segment_length=50)


def test_history_auto_chooses_on_the_training_data_and_says_so():
    # a linear ARX system of orders (3, 2) under a piecewise-constant input, a little noise
    rng = np.random.default_rng(0)
    n = 600
    u = np.repeat(rng.uniform(-1, 1, n // 7 + 1), 7)[:n]
    y = np.zeros(n)
    for t in range(2, n - 1):
        y[t + 1] = 1.2 * y[t] - 0.55 * y[t - 1] + 0.1 * y[t - 2] + 0.5 * u[t] + 0.3 * u[t - 1]
    y += 0.02 * rng.uniform(-1, 1, n)
    model = msgp.Msgp(history="auto", method="linear-kf", iterations=60)
    assert model.history is None and "history='auto'" in repr(model)
    seen = []
    model.fit(u, y, progress=seen.append)
    choice = model.report["history_choice"]
    assert model.history == (choice["ly"], choice["lu"])
    assert model.training["history_choice"] == choice
    # one progress event of stage 0 per judged candidate, then none (linear-kf has no Adam)
    judged = [e for e in seen if e["stage"] == 0]
    assert len(judged) == len(choice["judged"]) >= 10
    assert judged[-1]["iteration"] == judged[-1]["iterations"] == len(choice["judged"])
    scores = {tuple(e["history"]): e["loss"] for e in judged}
    assert all(
        math.isclose(scores[(s["ly"], s["lu"])], s["score"]) for s in choice["judged"] if s["score"]
    )
    with pytest.raises(ValueError, match="auto"):
        msgp.Msgp(history="automatic")
