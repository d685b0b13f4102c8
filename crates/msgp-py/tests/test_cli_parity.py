"""Python and the `msgp` command line give the same numbers for the same data, settings and
seed, and read each other's model files."""

import json
import math

import numpy as np
import pytest
from conftest import max_diff, write_csv

import msgp

TOL = 1e-12
METRICS = ("rmse", "nll", "coverage_2sigma")


def cli_fit(cli, csv, out, train, history, method="msgp", iters=20, inducing=None, extra=()):
    """Starts `msgp fit` in the background (it runs while Python fits); call the result to wait."""
    args = [
        "fit", "--data", csv, "--train", train, "--history", f"{history[0]},{history[1]}",
        "--method", method, "--iters", iters, "--seed", 0, "--json", "--quiet", "--out", out,
    ]
    if inducing is not None:
        args += ["--inducing", inducing]
    return cli.start(*args, *extra)


def assert_same_fit(report, model, metrics, out):
    """The CLI's report and model file against the Python model and its score."""
    diffs = {k: abs(report[k] - metrics[k]) for k in METRICS}
    print("CLI − Python metric differences:", diffs)
    assert all(d <= TOL for d in diffs.values()), (report, metrics)
    assert report["test_steps"] == metrics["steps"]
    assert report["inducing"] == model.inducing
    assert report["data_hash"] == model.training["data_hash"]
    saved = json.loads(out.read_text())
    mine = json.loads(model.to_json())
    for key in ("gp", "normalization", "reference", "history", "inputs", "outputs", "method"):
        assert saved[key] == mine[key], key
    # every setting agrees (train_seconds aside)
    assert saved["training"]["settings"] == mine["training"]["settings"]
    p = model.params
    assert max_diff(p["pseudo_targets"], saved["gp"]["pseudo_targets"]) == 0.0


@pytest.fixture(scope="module")
def sys4_fit(sys4, cli, tmp_path_factory):
    csv, data = sys4
    out = tmp_path_factory.mktemp("cli") / "sys4.model.json"
    report = cli_fit(cli, csv, out, 500, data["history"], inducing=20)
    model = msgp.Msgp(history=data["history"], inducing=20, iterations=20, seed=0)
    model.fit(data["u_train"], data["y_train"])
    return report(), model, out


def test_synthetic_msgp_matches_cli(sys4, sys4_fit):
    _, data = sys4
    report, model, out = sys4_fit
    metrics = model.score(data["u_test"], data["y_test"])
    assert_same_fit(report, model, metrics, out)
    assert report["iterations_run"] == model.training["iterations_run"]
    assert report["best_iteration"] == model.training["best_iteration"]
    # the chosen recipe's final training on all the data, reported alike by both
    assert report["full_data_iteration"] == model.report["full_data_iteration"]
    assert (report["full_data_iteration"] is None) != (report["full_data_failed"] is None)
    # … and the output-variance calibration its proxy judged on the tail
    assert report["calibration"] is not None
    assert report["calibration"] == model.report["calibration"]


def test_dryer_msgp_matches_cli(dryer, cli, tmp_path):
    path, u, y = dryer
    out = tmp_path / "dryer.model.json"
    report = cli_fit(cli, path, out, 500, (2, 2), inducing=20)
    model = msgp.Msgp(history=(2, 2), inducing=20, iterations=20, seed=0).fit(u[:500], y[:500])
    report = report()
    assert_same_fit(report, model, model.score(u[500:], y[500:]), out)


def test_dryer_msgp_by_lbfgs_matches_cli(dryer, cli, tmp_path):
    """`settings={"optimizer": "lbfgs"}` in Python is `--optimizer lbfgs` on the command line."""
    path, u, y = dryer
    out = tmp_path / "dryer.model.json"
    report = cli_fit(cli, path, out, 500, (2, 2), inducing=20, extra=("--optimizer", "lbfgs"))
    model = msgp.Msgp(
        history=(2, 2), inducing=20, iterations=20, seed=0, settings={"optimizer": "lbfgs"}
    ).fit(u[:500], y[:500])
    report = report()
    assert json.loads(model.to_json())["training"]["settings"]["optimizer"] == "lbfgs"
    assert_same_fit(report, model, model.score(u[500:], y[500:]), out)


def test_dryer_linear_kf_matches_cli(dryer, cli, tmp_path):
    """The Kalman-filter linear model: the same fit from Python and the command line, and its
    file loads back as a linear-kf model without a GP."""
    path, u, y = dryer
    out = tmp_path / "dryer.model.json"
    report = cli_fit(cli, path, out, 500, (2, 2), method="linear-kf", iters=50)
    model = msgp.Msgp(history=(2, 2), method="linear-kf", iterations=50, seed=0).fit(u[:500], y[:500])
    report = report()
    assert_same_fit(report, model, model.score(u[500:], y[500:]), out)
    loaded = msgp.Msgp.load(out)
    assert loaded.method == "linear-kf" and loaded.iterations == 50
    assert np.all(np.asarray(loaded.params["pseudo_targets"]) == 0.0)


def test_dryer_gp_narx_by_the_exact_gp_matches_cli(dryer, cli, tmp_path):
    """`settings={"objective": "exact"}` in Python is `--one-step exact` on the command line;
    the default GP-NARX (the variational bound) is a different model."""
    path, u, y = dryer
    out = tmp_path / "dryer.model.json"
    report = cli_fit(
        cli, path, out, 500, (2, 2), method="gp-narx", iters=30, inducing=20,
        extra=("--one-step", "exact"),
    )
    model = msgp.Msgp(
        method="gp-narx", inducing=20, iterations=30, seed=0, settings={"objective": "exact"}
    ).fit(u[:500], y[:500])
    report = report()
    assert json.loads(model.to_json())["training"]["settings"]["objective"] == "exact"
    assert_same_fit(report, model, model.score(u[500:], y[500:]), out)
    default = msgp.Msgp(method="gp-narx", inducing=20, iterations=30, seed=0).fit(u[:500], y[:500])
    assert json.loads(default.to_json())["training"]["settings"]["objective"] == "vfe"
    assert not np.array_equal(
        np.asarray(default.params["pseudo_inputs"]), np.asarray(model.params["pseudo_inputs"])
    )


def test_a_loaded_model_refits_with_its_own_settings(dryer, cli, tmp_path):
    """`msgp fit --one-step exact`'s file, loaded in Python and fitted again on the same data,
    is the same fit: the method's own settings the constructor has no argument for (here the
    one-step objective) come from the file's record, not from the defaults."""
    path, u, y = dryer
    out = tmp_path / "dryer.model.json"
    cli_fit(
        cli, path, out, 500, (2, 2), method="gp-narx", iters=30, inducing=20,
        extra=("--one-step", "exact"),
    )()
    saved = json.loads(out.read_text())
    refit = msgp.Msgp.load(out).fit(u[:500], y[:500])
    mine = json.loads(refit.to_json())
    assert mine["training"]["settings"]["objective"] == "exact"
    assert mine["training"]["settings"] == saved["training"]["settings"]
    for key in ("pseudo_inputs", "pseudo_targets", "log_lengthscales"):
        np.testing.assert_array_equal(
            np.asarray(refit.params[key]), np.asarray(msgp.Msgp.load(out).params[key])
        )


def test_dryer_gp_narx_default_inducing_matches_cli(dryer, cli, tmp_path):
    """No --inducing: both take min(100, training windows / 2) = 100 pseudo-inputs."""
    path, u, y = dryer
    out = tmp_path / "dryer.model.json"
    report = cli_fit(cli, path, out, 500, (2, 2), method="gp-narx", iters=30)
    model = msgp.Msgp(method="gp-narx", iterations=30, seed=0).fit(u[:500], y[:500])
    report = report()
    assert model.inducing == report["inducing"] == 100
    assert_same_fit(report, model, model.score(u[500:], y[500:]), out)


def test_several_trajectories_match_cli(sys4, cli, tmp_path):
    """Two files for the CLI, a list of two arrays for Python; pooled test metrics."""
    _, data = sys4
    u = np.concatenate([data["u_train"], data["u_test"]])
    y = np.concatenate([data["y_train"], data["y_test"]])
    halves = [(u[:500], y[:500]), (u[500:], y[500:])]
    files = []
    for k, (uk, yk) in enumerate(halves):
        files.append(tmp_path / f"part{k}.csv")
        write_csv(files[-1], uk, yk)
    out = tmp_path / "parts.model.json"
    report = cli(
        "fit", "--data", files[0], "--data", files[1], "--train", 300, "--history", "2,1",
        "--method", "pilco-narx", "--iters", 20, "--seed", 0, "--json", "--quiet", "--out", out,
    )
    model = msgp.Msgp(history=(2, 1), method="pilco-narx", iterations=20, seed=0)
    model.fit([uk[:300] for uk, _ in halves], [yk[:300] for _, yk in halves])
    metrics = model.score([uk[300:] for uk, _ in halves], [yk[300:] for _, yk in halves])
    assert model.training["trajectories"] == 2
    assert_same_fit(report, model, metrics, out)


def test_cli_model_loads_in_python(sys4, sys4_fit):
    """The CLI's model file predicts in Python exactly what the Python-fitted model does."""
    _, data = sys4
    _, model, out = sys4_fit
    loaded = msgp.Msgp.load(out)
    assert loaded.method == "msgp" and loaded.history == (2, 1) and loaded.inducing == 20
    assert loaded.iterations == 20 and loaded.seed == 0
    a = loaded.simulate(data["u_test"], data["y_test"])
    b = model.simulate(data["u_test"], data["y_test"])
    assert np.array_equal(a[0], b[0]) and np.array_equal(a[1], b[1])


def test_python_model_evaluates_in_cli(sys4, sys4_fit, cli, tmp_path):
    """`msgp eval` on a model saved by Python reproduces Python's score."""
    csv, data = sys4
    _, model, _ = sys4_fit
    path = tmp_path / "py.model.json"
    model.save(path)
    test_csv = tmp_path / "test.csv"
    write_csv(test_csv, data["u_test"], data["y_test"])
    report = cli("eval", "--model", path, "--data", test_csv, "--json")
    metrics = model.score(data["u_test"], data["y_test"])
    for k in METRICS:
        assert abs(report[k] - metrics[k]) <= TOL, k
    # `msgp simulate` writes the same mean and standard deviation
    pred = tmp_path / "pred.csv"
    cli("simulate", "--model", path, "--data", test_csv, "--out", pred, "--json")
    table = np.genfromtxt(pred, delimiter=",", names=True)
    mean, var = model.simulate(data["u_test"], data["y_test"])
    assert max_diff(table["y_mean"], mean[:, 0]) == 0.0
    assert max_diff(table["y_std"], np.sqrt(var[:, 0])) == 0.0


def test_filtered_and_mean_feedback_predictions_match_the_cli(sys4, cli, tmp_path):
    """`filtered`, `score(filtered=True)` and `rollout="mean"` are `msgp eval/simulate
    --filtered` and `--rollout mean` on the saved model; the filtered score is the score of
    `filtered`'s predictions, recomputed here in numpy."""
    _, data = sys4
    model = msgp.Msgp(history=data["history"], inducing=10, iterations=10, seed=0, likelihood="filter")
    model.fit(data["u_train"], data["y_train"])
    u, y = data["u_test"], data["y_test"]
    path = tmp_path / "m.model.json"
    model.save(path)
    test_csv = tmp_path / "test.csv"
    write_csv(test_csv, u, y)
    base = ("--model", path, "--data", test_csv, "--json")

    mine = model.score(u, y, filtered=True)
    report = cli("eval", *base, "--filtered")
    for k in METRICS:
        assert abs(report[k] - mine[k]) <= TOL, k
        assert abs(report["filtered"][k] - mine["filtered"][k]) <= TOL, k
    assert "filtered" not in model.score(u, y)

    mean, var = model.filtered(u, y)
    w = model.warmup
    assert mean.shape == var.shape == (len(y) - w, 1)
    err = y[w:] - mean[:, 0]
    f = mine["filtered"]
    assert f["steps"] == len(err)
    assert abs(f["rmse"] - math.sqrt(np.mean(err**2))) <= 1e-12
    nll = np.mean(0.5 * (np.log(2 * math.pi * var[:, 0]) + err**2 / var[:, 0]))
    assert abs(f["nll"] - nll) <= 1e-10
    assert abs(f["coverage_2sigma"] - np.mean(np.abs(err) <= 2 * np.sqrt(var[:, 0]))) <= 1e-12
    # each step has seen the measurements before it: far closer than the free simulation
    assert f["rmse"] < 0.5 * mine["rmse"], (f["rmse"], mine["rmse"])

    pred = tmp_path / "pred.csv"
    cli("simulate", *base, "--filtered", "--out", pred)
    table = np.genfromtxt(pred, delimiter=",", names=True)
    assert max_diff(table["y_filtered_mean"], mean[:, 0]) == 0.0
    assert max_diff(table["y_filtered_std"], np.sqrt(var[:, 0])) == 0.0

    by_mean = model.score(u, y, rollout="mean")
    report = cli("eval", *base, "--rollout", "mean")
    for k in METRICS:
        assert abs(report[k] - by_mean[k]) <= TOL, k
    assert by_mean["rmse"] != mine["rmse"]
    cli("simulate", *base, "--rollout", "mean", "--out", pred)
    table = np.genfromtxt(pred, delimiter=",", names=True)
    sim_mean, sim_var = model.simulate(u, y[:w], rollout="mean")
    assert max_diff(table["y_mean"], sim_mean[:, 0]) == 0.0
    assert max_diff(table["y_std"], np.sqrt(sim_var[:, 0])) == 0.0

    # the paper's moment matching: the same means, each step's function uncertainty drawn
    # afresh, so no wider a band than the default's; the CLI agrees
    paper = model.score(u, y, rollout="mm-independent")
    report = cli("eval", *base, "--rollout", "mm-independent")
    for k in METRICS:
        assert abs(report[k] - paper[k]) <= TOL, k
    assert paper["rmse"] == mine["rmse"]
    default_mean, default_var = model.simulate(u, y[:w])
    paper_mean, paper_var = model.simulate(u, y[:w], rollout="mm-independent")
    assert max_diff(paper_mean, default_mean) == 0.0
    assert np.all(paper_var <= default_var)

    with pytest.raises(ValueError, match='unknown rollout "exact"'):
        model.simulate(u, y[:w], rollout="exact")
    with pytest.raises(ValueError, match="needs more than"):
        model.filtered(u[:w], y[:w])
    with pytest.raises(ValueError, match=f"u has {len(u)} samples but y has {len(u) - 1}"):
        model.filtered(u, y[:-1])
