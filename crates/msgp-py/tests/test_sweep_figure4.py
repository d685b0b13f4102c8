"""msgp.sweep.figure4: Figure 4's learning runs spread over local processes or a Ray cluster
give the run folders (policies, iterations, episodes) and the markdown of the serial `msgp
reproduce figure4` run, but for the provenance lines and the measured seconds; finished runs
are reused."""

import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

from msgp import sweep

# a small figure: the linear model and the filtered MSGP, two seeds, two short iterations
MODELS = ["linear-kf", "msgp-filter"]
BUDGET = {"episode_seconds": 1.0, "random_rollouts": 1, "fit_iters": 5, "candidates": 8,
          "search_iters": 5}
CLI_ARGS = [
    "reproduce", "figure4", "--models", ",".join(MODELS), "--seeds", 2, "--iterations", 2,
    "--episode-seconds", 1, "--random-rollouts", 1, "--fit-iters", 5, "--candidates", 8,
    "--search-iters", 5, "--quiet",
]
RUNS = [f"{m}-seed{k}" for m in MODELS for k in (0, 1)]
TIMES = ("wall_seconds", "fit_seconds", "search_seconds")


def without_times(value):
    """A summary without its measured seconds."""
    if isinstance(value, dict):
        return {k: without_times(v) for k, v in value.items() if k not in TIMES}
    if isinstance(value, list):
        return [without_times(v) for v in value]
    return value


def folder(root: Path):
    """Every file of every run: the summary without times, the rest byte for byte (the cost
    plots are drawn from the same numbers; their pixels are not compared)."""
    out = {}
    for run in RUNS:
        for path in sorted((root / run).rglob("*")):
            name = path.relative_to(root).as_posix()
            if path.name == "summary.json":
                out[name] = without_times(json.loads(path.read_text()))
            elif path.suffix != ".png" and path.is_file():
                out[name] = path.read_bytes()
    return out


def comparable(markdown, runs: Path):
    """The section without its provenance lines and the columns of measured seconds, the runs'
    folder `runs` named DIR."""
    markdown = markdown.strip().replace(str(runs), "DIR")
    lines = [line for line in markdown.splitlines() if not line.startswith(("- Command", "- Wall time"))]
    return [re.sub(r"\| [^|]* \|$", "| |", line) if line.startswith("| ") else line for line in lines]


def section(text):
    return text.split("<!-- msgp:figure4-apollo:begin -->")[1].split(
        "<!-- msgp:figure4-apollo:end -->")[0]


@pytest.fixture(scope="module")
def serial(cli, tmp_path_factory):
    root = tmp_path_factory.mktemp("serial")
    cli(*CLI_ARGS, "--dir", root / "runs", "--out", root / "RESULTS.md", parse=False)
    return folder(root / "runs"), comparable(section((root / "RESULTS.md").read_text()),
                                             root / "runs")


def test_local_processes_equal_the_serial_run(serial, tmp_path):
    files, text = serial
    assert len([n for n in files if n.endswith("summary.json")]) == 4
    assert any(n.endswith(".mcap") for n in files) and any(n.endswith(".csv") for n in files)
    out = tmp_path / "RESULTS.md"
    report = sweep.figure4([0, 1], models=MODELS, iterations=2, budget=BUDGET,
                           dir=str(tmp_path / "runs"), out=str(out), workers=2, quiet=True)
    assert (report["ran"], report["reused"]) == (4, 0)
    assert folder(tmp_path / "runs") == files
    assert (tmp_path / "runs" / "figure4.png").stat().st_size > 10_000
    assert comparable(section(out.read_text()), tmp_path / "runs") == text
    # a second call finds every run finished and only redraws the report
    again = sweep.figure4([0, 1], models=MODELS, iterations=2, budget=BUDGET,
                          dir=str(tmp_path / "runs"), out=None, quiet=True)
    assert (again["ran"], again["reused"]) == (0, 4)
    assert comparable(again["markdown"], tmp_path / "runs") == text


def test_the_command_line_entry_point(serial, tmp_path):
    files, text = serial
    out = tmp_path / "RESULTS.md"
    proc = subprocess.run(
        [sys.executable, "-m", "msgp.sweep", "figure4", "--seeds", "0-1", "--models",
         ",".join(MODELS), "--iterations", "2", "--episode-seconds", "1", "--random-rollouts",
         "1", "--fit-iters", "5", "--budget", '{"candidates": 8, "search_iters": 5}',
         "--workers", "2", "--quiet", "--dir", str(tmp_path / "runs"), "--out", str(out)],
        capture_output=True, text=True, timeout=900,
    )
    assert proc.returncode == 0, proc.stderr
    assert folder(tmp_path / "runs") == files
    written = section(out.read_text())
    assert comparable(written, tmp_path / "runs") == text
    assert "- Command: `python -m msgp.sweep figure4 --seeds 0-1" in written
    for args, message in [
        (["--models", "nope"], "unknown model `nope`"),
        (["--budget", '{"likelihood": "filter"}'], "figure 4 runs MSGP with each likelihood"),
        (["--budget", '{"episodes": 2}'], "unknown setting `episodes`"),
        (["--episode-seconds", "-1"], "invalid episode-seconds: must be positive"),
    ]:
        bad = subprocess.run(
            [sys.executable, "-m", "msgp.sweep", "figure4", *args, "--out", str(out)],
            capture_output=True, text=True, timeout=60,
        )
        assert bad.returncode == 1 and message in bad.stderr, (args, bad.stderr)


def test_a_local_ray_cluster_equals_the_serial_run(serial, tmp_path):
    ray = pytest.importorskip("ray")
    files, text = serial
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        out = tmp_path / "RESULTS.md"
        sweep.figure4([0, 1], models=MODELS, iterations=2, budget=BUDGET,
                      dir=str(tmp_path / "runs"), out=str(out), ray="auto", quiet=True)
    finally:
        ray.shutdown()
    assert folder(tmp_path / "runs") == files
    written = section(out.read_text())
    assert comparable(written, tmp_path / "runs") == text
    assert "a Ray cluster (auto) of 1 node(s), 2 CPUs" in written
