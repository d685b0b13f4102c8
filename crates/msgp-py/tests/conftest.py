"""Shared helpers: the `msgp` binary, the real data folder, the synthetic CSV."""

import json
import os
import subprocess
from pathlib import Path

import numpy as np
import pytest

import msgp

REPO = Path(__file__).resolve().parents[3]


def msgp_bin() -> Path:
    """The CLI: $MSGP_BIN, else $CARGO_TARGET_DIR (or target)/release/msgp."""
    if os.environ.get("MSGP_BIN"):
        return Path(os.environ["MSGP_BIN"])
    target = Path(os.environ.get("CARGO_TARGET_DIR") or REPO / "target")
    return target / "release" / "msgp"


@pytest.fixture(scope="session")
def cli():
    """Runs `msgp ARGS…` and returns its stdout parsed as JSON (or the raw text)."""
    exe = msgp_bin()
    if not exe.is_file():
        pytest.fail(
            f"the msgp binary is not at {exe}: build it with "
            "`cargo build --release --locked --bin msgp` or set MSGP_BIN"
        )

    def start(*args, parse=True):
        """Starts `msgp ARGS…`; returns a function that waits for it and returns its output."""
        proc = subprocess.Popen(
            [str(exe), *map(str, args)], stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
        )

        def wait():
            out, err = proc.communicate(timeout=300)
            if proc.returncode != 0:
                raise AssertionError(f"msgp {' '.join(map(str, args))} failed:\n{err}")
            return json.loads(out) if parse else out

        return wait

    def run(*args, parse=True):
        return start(*args, parse=parse)()

    run.start = start
    return run


def data_dir() -> Path:
    value = os.environ.get("MSGP_DATA_DIR")
    return Path(value) if value else REPO / ".." / "shared" / "data" / "real"


@pytest.fixture(scope="session")
def dryer():
    """(path, u, y) of the dryer series, read with numpy; skipped where the data are absent
    unless MSGP_REQUIRE_DATA=1."""
    path = data_dir() / "dryer.csv"
    if not path.is_file():
        reason = f"real data not found: {path} (set MSGP_DATA_DIR)"
        if os.environ.get("MSGP_REQUIRE_DATA") == "1":
            pytest.fail(reason + " and MSGP_REQUIRE_DATA=1")
        print(f"skipping: {reason}")
        pytest.skip(reason)
    table = np.genfromtxt(path, delimiter=",", names=True)
    return path, np.asarray(table["u"]), np.asarray(table["y"])


def write_csv(path: Path, u: np.ndarray, y: np.ndarray) -> None:
    """t,u,y with every float as its shortest round-trip decimal (repr)."""
    lines = ["t,u,y"] + [f"{t},{a!r},{b!r}" for t, (a, b) in enumerate(zip(u.tolist(), y.tolist()))]
    path.write_text("\n".join(lines) + "\n")


@pytest.fixture(scope="session")
def sys4(tmp_path_factory):
    """Synthetic system 4 (seed 0) and a CSV of train + test for the CLI."""
    data = msgp.synthetic_system(4, seed=0)
    u = np.concatenate([data["u_train"], data["u_test"]])
    y = np.concatenate([data["y_train"], data["y_test"]])
    path = tmp_path_factory.mktemp("sys4") / "sys4.csv"
    write_csv(path, u, y)
    return path, data


def max_diff(a, b) -> float:
    return float(np.max(np.abs(np.asarray(a, dtype=float) - np.asarray(b, dtype=float))))
