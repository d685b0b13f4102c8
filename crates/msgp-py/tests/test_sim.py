"""The pendulum simulator, its stability test and the policy-learning loop from Python."""

import numpy as np
import pytest

import msgp


def test_episode_matches_cli_run_log(cli, tmp_path):
    """Same controller, seed and plant: the CLI's CSV log holds the same numbers."""
    kwargs = dict(seconds=2.0, seed=7, excitation_rms=0.5, params={"sigma_x": 1e-3})
    ep = msgp.run_episode("random", **kwargs)
    out = tmp_path / "run.csv"
    summary = cli("sim", "pendulum", "--random", "--seconds", 2, "--seed", 7, "--excitation-rms", 0.5,
                  "--sigma-x", 1e-3, "--json", "--out", out)
    log = np.genfromtxt(out, delimiter=",", names=True)
    n = len(ep["t"])
    assert n == len(log) == summary["samples"] > 10
    assert ep["info"]["termination"] == summary["termination"]
    assert ep["info"]["initial_theta"] == summary["initial_theta"]
    for name in log.dtype.names:
        assert np.array_equal(ep[name], log[name]), name
    assert ep["u"].shape == (n, 1) and ep["y"].shape == (n, 2)
    assert np.array_equal(ep["y"][:, 0], ep["meas_theta"]) and np.array_equal(ep["y"][:, 1], ep["meas_x"])
    assert np.array_equal(ep["u"][:, 0], ep["command"])
    assert ep["info"]["seed"] == 7
    assert np.array_equal(msgp.run_episode("random", **kwargs)["y"], ep["y"])


def test_gain_forms_agree():
    a = msgp.run_episode("hand-tuned", seconds=1.0, seed=1)
    g = {"kp_x": 0.99, "ki_x": 0.15, "kd_x": 1.865, "kp_theta": 34.55, "kd_theta": 7.03}
    b = msgp.run_episode(g, seconds=1.0, seed=1)
    c = msgp.run_episode([0.99, 0.15, 1.865, 34.55, 7.03], seconds=1.0, seed=1)
    assert np.array_equal(a["command"], b["command"]) and np.array_equal(a["command"], c["command"])


def test_stability_test():
    good = msgp.stability_test("hand-tuned", seed=0)
    # five starts, three noise draws each
    assert good["passed"] and len(good["starts"]) == 15
    assert [s["repeat"] for s in good["starts"][:3]] == [0, 1, 2]
    bad = msgp.stability_test("zero", seed=0)
    assert not bad["passed"]
    assert any("theta" in (s["failure"] or "") for s in bad["starts"])
    short = msgp.stability_test("hand-tuned", criteria={"initial_thetas": [0.01], "seconds": 6.0})
    assert len(short["starts"]) == 3
    once = msgp.stability_test(
        "hand-tuned", criteria={"initial_thetas": [0.01], "seconds": 6.0, "noise_repeats": 1}
    )
    assert len(once["starts"]) == 1


def test_pendulum_data_fits():
    """An episode of random excitation is ready for Msgp.fit: u (n, 1), y (n, 2)."""
    ep = msgp.run_episode("random", seconds=4.0, seed=3)
    model = msgp.Msgp(history=(2, 2), method="gp-narx", inducing=15, iterations=20).fit(ep["u"], ep["y"])
    assert model.output_names == ["y0", "y1"]
    mean, var = model.simulate(ep["u"], ep["y"])
    assert mean.shape == (len(ep["t"]) - 2, 2)


def test_learn_policy_runs_and_reports():
    """A tiny seeded learning loop: one iteration, reports as dicts, deterministic."""
    settings = {
        "random_rollouts": 1,
        "episode_seconds": 1.0,
        "fit": {"inducing": 10, "iterations": 3, "one_step_iterations": 10},
        "search": {"iterations": 2, "candidates": 4},
    }
    reports = msgp.learn_policy(method="msgp", iterations=1, seed=2, settings=settings)
    assert len(reports) == 1
    r = reports[0]
    assert r["iteration"] == 1 and isinstance(r["stable"], bool)
    assert set(r["gains"]) >= {"kp_x", "ki_x", "kd_x", "kp_theta", "kd_theta"}
    assert 0.0 < r["interaction_seconds"] <= 2.0
    assert np.isfinite(r["predicted_cost"]) and np.isfinite(r["actual_cost"])
    assert r["fit_seconds"] > 0.0 and r["search_seconds"] > 0.0
    # the filtered MSGP loop's prequential choice: the first search on the linear model, both
    # models scored on the episode that followed
    assert r["search_model"] == "linear"
    assert set(r["held_out"]) == {"gp_nll", "linear_nll", "steps"} and r["held_out"]["steps"] > 0

    def untimed(rs):
        return [{k: v for k, v in x.items() if k not in ("fit_seconds", "search_seconds")} for x in rs]

    again = msgp.learn_policy(method="msgp", iterations=1, seed=2, settings=settings)
    assert untimed(again) == untimed(reports)
    assert msgp.defaults("learn")["iterations"] == 8


def test_learn_policy_reports_progress_and_stops_on_its_exception():
    """`progress` sees each iteration's report as it completes, the same dicts the call
    returns; an exception it raises stops the loop and comes out of the call."""
    settings = {
        "random_rollouts": 1,
        "episode_seconds": 1.0,
        "fit": {"inducing": 10, "iterations": 3, "one_step_iterations": 10},
        "search": {"iterations": 2, "candidates": 4},
    }
    seen = []
    reports = msgp.learn_policy(
        method="msgp", iterations=2, seed=2, settings=settings, progress=seen.append
    )
    assert [r["iteration"] for r in seen] == [1, 2]
    assert seen == reports

    class Enough(Exception):
        pass

    calls = []

    def stop_after_first(report):
        calls.append(report["iteration"])
        raise Enough(report["iteration"])

    with pytest.raises(Enough):
        msgp.learn_policy(
            method="msgp", iterations=3, seed=2, settings=settings, progress=stop_after_first
        )
    assert calls == [1]
    with pytest.raises(msgp.InvalidInputError, match="callable"):
        msgp.learn_policy(iterations=1, settings=settings, progress=3)


def test_learn_defaults_per_model():
    """`defaults("learn", method=...)` are the loop's defaults for that model: linear-kf and
    the filtered MSGP (the default MSGP loop) warm-start their fits and search over the
    stability test's 10 s; the free-run MSGP loop does not."""
    msgp_defaults = msgp.defaults("learn")
    assert msgp_defaults == msgp.defaults("learn", method="msgp")
    assert msgp_defaults == msgp.defaults("learn", method="msgp", likelihood="filter")
    assert msgp_defaults["warm_start"] == 40
    assert msgp_defaults["policy_horizon_seconds"] == 10.0
    assert msgp_defaults["fit"]["likelihood"] == "filter"
    assert msgp_defaults["fit"]["start"] == "linear-kf"
    assert msgp_defaults["prequential_choice"] is True
    free = msgp.defaults("learn", likelihood="free-run")
    assert free["warm_start"] is None and free["policy_horizon_seconds"] == 5.0
    assert free["fit"]["likelihood"] == "free-run" and free["fit"]["start"] == "one-step"
    assert "prequential_choice" not in free
    with pytest.raises(ValueError, match="likelihood"):
        msgp.defaults("learn", method="linear-kf", likelihood="filter")
    with pytest.raises(ValueError, match="free-run"):
        msgp.defaults("learn", likelihood="joint")
    with pytest.raises(ValueError, match="likelihood"):
        msgp.learn_policy(method="gp-narx", likelihood="filter")
    kf = msgp.defaults("learn", method="linear-kf")
    assert kf["warm_start"] == 300
    assert kf["policy_horizon_seconds"] == 10.0
    assert kf["fit"]["method"] == "LinearKf"  # the fit settings' serde name
    assert kf["fit"]["iterations"] == 300 and "learning_rate" not in kf["fit"]
    assert msgp.defaults("fit", method="linear-kf")["method"] == "LinearKf"
    with pytest.raises(ValueError, match="learn"):
        msgp.defaults("pendulum", method="linear-kf")
    with pytest.raises(ValueError, match="method"):
        msgp.defaults("learn", method="pilco")
