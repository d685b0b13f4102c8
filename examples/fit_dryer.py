"""Fit MSGP and one-step GP-NARX on the hair-dryer series and compare their free simulations.

    python examples/fit_dryer.py [--data DIR] [--iters N] [--inducing M] [--out dryer.png]

Reads DIR/dryer.csv (columns t,u,y; default $MSGP_DATA_DIR or ../shared/data/real beside the
checkout), trains on the first 500 samples (the paper's split, l_y = l_u = 2), simulates the
remaining 500 from their first two samples, prints RMSE / NLL / 2σ coverage, saves the MSGP
model (the same JSON file `msgp fit` writes) and, when matplotlib is installed, plots both
simulations with ±2σ bands. Needs only numpy and the msgp wheel (`maturin develop`).
"""

import argparse
import os
import sys
from pathlib import Path

import numpy as np

import msgp

ROOT = Path(__file__).resolve().parents[1]


def main() -> int:
    default_dir = os.environ.get("MSGP_DATA_DIR") or ROOT / ".." / "shared" / "data" / "real"
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--data", type=Path, default=Path(default_dir), help="folder with dryer.csv")
    ap.add_argument("--iters", type=int, default=None, help="MSGP Adam iterations (default 400)")
    ap.add_argument("--inducing", type=int, default=None, help="pseudo-inputs (default 100)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--out", type=Path, default=Path("dryer.png"), help="plot file")
    args = ap.parse_args()

    path = args.data / "dryer.csv"
    if not path.is_file():
        print(f"no {path}: pass --data DIR or set MSGP_DATA_DIR", file=sys.stderr)
        return 1
    table = np.genfromtxt(path, delimiter=",", names=True)
    u, y = table["u"], table["y"]
    n_train = 500

    results = {}
    for method in ("gp-narx", "msgp"):
        model = msgp.Msgp(
            history=(2, 2), method=method, seed=args.seed, iterations=args.iters, inducing=args.inducing
        )
        model.fit(u[:n_train], y[:n_train])
        mean, var = model.simulate(u[n_train:], y[n_train:])
        score = model.score(u[n_train:], y[n_train:])
        seconds = model.training["train_seconds"]
        print(
            f"{method:8s} RMSE {score['rmse']:.4f}  NLL/step {score['nll']:.3f}  "
            f"2σ coverage {score['coverage_2sigma']:.3f}  ({model.inducing} pseudo-inputs, {seconds:.1f} s)"
        )
        results[method] = (model, mean[:, 0], var[:, 0])

    model = results["msgp"][0]
    saved = args.out.with_name("dryer.model.json")
    model.save(saved)
    print(f"MSGP model written to {saved} (try: msgp eval --model {saved} --data {path})")

    try:
        import matplotlib

        matplotlib.use("Agg")
        import matplotlib.pyplot as plt
    except ImportError:
        print("matplotlib is not installed: no plot")
        return 0
    t = np.arange(n_train + model.warmup, len(u))
    fig, axes = plt.subplots(2, 1, sharex=True, figsize=(10, 6))
    for ax, (method, (_, mean, var)) in zip(axes, results.items()):
        sd = np.sqrt(var)
        ax.plot(np.arange(n_train, len(u)), y[n_train:], "k", lw=0.8, label="measured")
        ax.plot(t, mean, "C0", label=f"{method} mean")
        ax.fill_between(t, mean - 2 * sd, mean + 2 * sd, color="C0", alpha=0.25, label="±2σ")
        ax.set_ylabel("y")
        ax.set_title(f"{method}: free simulation of the test part")
        ax.legend(loc="upper right")
    axes[-1].set_xlabel("sample")
    fig.tight_layout()
    fig.savefig(args.out, dpi=120)
    print(f"plot written to {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
