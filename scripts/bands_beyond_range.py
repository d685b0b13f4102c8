#!/usr/bin/env python3
"""Bands beyond the training range: the reported 2σ band against the paper's variances, and the
fitted hyperparameters, on the generalisation table's worst beyond-range cells.

Behind docs/experiments/2026-12-06-bands-beyond-the-training-range.md. Synthetic systems 1 and 3
(Table 2), seeds 0-2, each fitted as `msgp reproduce generalisation` fits it (the default MSGP
fit on Table 2's training data), then simulated on Table 2's test input scaled to peak at 1.5 x
the training bound (the table's "test input x1.5"), from the true first window, against the
noise-free truth. Prints one JSON line per cell. Needs the wheel (`maturin develop`).

Usage: python scripts/bands_beyond_range.py [SYSTEMS] [SEEDS]   (default: 1,3 0,1,2)
"""
import json
import sys

import numpy as np

import msgp

BOUND = {1: 2.0, 3: 1.0}  # Table 2's training input bounds


def truth(k, u):
    """The noise-free output of Table 2's system k under the input u, from rest."""
    y = np.zeros(len(u))
    for t in range(2, len(u)):
        if k == 1:
            y[t] = y[t - 1] * y[t - 2] * (y[t - 1] + 2.5) / (1 + y[t - 1] ** 2 + y[t - 2] ** 2) + u[t - 1]
        elif k == 3:
            y[t] = 0.8 * y[t - 1] + (u[t - 1] - 0.8) * u[t - 1] * (u[t - 1] + 0.5)
    return y


def cell(k, seed):
    d = msgp.synthetic_system(k, seed=seed)
    u_test = np.asarray(d["u_test"], float).ravel()
    u = u_test / np.max(np.abs(u_test)) * 1.5 * BOUND[k]
    y = truth(k, u)
    model = msgp.Msgp(history=d["history"], seed=seed).fit(d["u_train"], d["y_train"])
    lag = max(d["history"])
    out = {"system": k, "seed": seed, "beyond_fraction": float(np.mean(np.abs(u) > BOUND[k]))}
    for rollout in ("mm", "mm-independent"):
        mean, var = model.simulate(u, y[:lag], rollout=rollout)
        mean = np.asarray(mean).ravel()
        sd = np.sqrt(np.asarray(var).ravel())
        err = np.abs(mean - y[len(y) - len(mean):])
        out[rollout] = {
            "rmse": float(np.sqrt(np.mean(err**2))),
            "coverage_2sigma": float(np.mean(err <= 2 * sd)),
            "sd_median": float(np.median(sd)),
            "err_over_2sd_p90": float(np.quantile(err / (2 * sd), 0.9)),
        }
    gp = json.loads(model.to_json())["gp"]
    out["signal_sd"] = float(np.exp(0.5 * gp["log_signal_var"][0]))
    out["lengthscales"] = [float(x) for x in np.exp(np.array(gp["log_lengthscales"][0]))]
    out["linear_mean"] = gp.get("linear_mean")
    return out


def main():
    systems = [int(a) for a in (sys.argv[1] if len(sys.argv) > 1 else "1,3").split(",")]
    seeds = [int(a) for a in (sys.argv[2] if len(sys.argv) > 2 else "0,1,2").split(",")]
    for k in systems:
        for seed in seeds:
            print(json.dumps(cell(k, seed)), flush=True)


if __name__ == "__main__":
    main()
