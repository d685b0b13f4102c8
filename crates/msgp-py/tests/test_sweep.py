"""msgp.sweep: Table 1's units spread over local processes or a Ray cluster give the numbers of
the serial `msgp reproduce table1` run, and write the same markdown section but for the
provenance lines and the timings."""

import json
import os
import re
import subprocess
import sys

import pytest

from msgp import sweep

# a small sweep: two synthetic systems, two seeds, GP-NARX and both MSGP likelihoods
SMALL = dict(
    seeds=[0, 1],
    only=["synthetic2", "synthetic5"],
    methods=["gp-narx", "msgp"],
    inducing=10,
    iters=10,
)
CLI_ARGS = [
    "reproduce", "table1", "--seeds", "0,1", "--only", "synthetic2,synthetic5",
    "--methods", "gp-narx,msgp", "--inducing", 10, "--iters", 10, "--json", "--quiet",
]


def numbers(rows):
    """Everything but the wall times."""
    return [{k: v for k, v in r.items() if k != "train_seconds"} for r in rows]


def comparable(markdown):
    """The section without its provenance lines and timing columns."""
    lines = [line for line in markdown.splitlines() if not line.startswith(("- Command", "- Wall time"))]
    # calibration rows end with "| train s | iterations (kept) |"
    return [re.sub(r"\| [^|]* \| [^|]* \|$", "| |", line) if line.startswith("| Synthetic") else line
            for line in lines]


@pytest.fixture(scope="module")
def serial(cli, tmp_path_factory):
    out = tmp_path_factory.mktemp("serial") / "RESULTS.md"
    report = cli(*CLI_ARGS, "--out", out)
    return report["rows"], out.read_text()


def section(text):
    return text.split("<!-- msgp:table1:begin -->")[1].split("<!-- msgp:table1:end -->")[0]


def test_local_processes_equal_the_serial_run(serial, tmp_path):
    rows, text = serial
    assert len(rows) == 2 * 2 * 3 * 2  # benchmarks × seeds × columns × rollouts
    out = tmp_path / "RESULTS.md"
    report = sweep.table1(**SMALL, out=str(out), workers=2, quiet=True)
    assert numbers(report["rows"]) == numbers(rows)
    assert comparable(section(out.read_text())) == comparable(section(text))


def test_the_command_line_entry_point(serial, tmp_path):
    rows, _ = serial
    out = tmp_path / "RESULTS.md"
    proc = subprocess.run(
        [sys.executable, "-m", "msgp.sweep", "table1", "--seeds", "0-1",
         "--only", "synthetic2,synthetic5", "--methods", "gp-narx,msgp", "--inducing", "10",
         "--iters", "10", "--workers", "1", "--json", "--quiet", "--out", str(out)],
        capture_output=True, text=True, timeout=600,
    )
    assert proc.returncode == 0, proc.stderr
    assert numbers(json.loads(proc.stdout)["rows"]) == numbers(rows)
    assert "- Command: `python -m msgp.sweep table1 --seeds 0-1" in out.read_text()
    bad = subprocess.run(
        [sys.executable, "-m", "msgp.sweep", "table1", "--only", "nowhere", "--out", str(out)],
        capture_output=True, text=True, timeout=60,
    )
    assert bad.returncode == 1 and "unknown benchmark `nowhere`" in bad.stderr, bad.stderr


def test_histories_chosen_from_the_data_as_the_command_line_chooses_them(cli, tmp_path):
    args = dict(seeds=[0], only=["synthetic1"], methods=["gp-narx"], inducing=10)
    before = os.environ.get("MSGP_THREADS")
    report = sweep.table1(**args, history="auto", out=None, workers=1, quiet=True)
    # the units ran here single-threaded, and the caller's environment is as it was
    assert os.environ.get("MSGP_THREADS") == before
    assert report["section"] == "table1-auto-history"
    serial = cli("reproduce", "table1", "--seeds", "0", "--only", "synthetic1", "--methods",
                 "gp-narx", "--inducing", 10, "--history", "auto", "--json", "--quiet",
                 "--out", tmp_path / "t.md")
    assert numbers(report["rows"]) == numbers(serial["rows"])
    choice = report["rows"][0]["history_choice"]
    assert report["rows"][0]["history"] == [choice["ly"], choice["lu"]]
    assert "## Chosen histories" in report["markdown"]
    with pytest.raises(ValueError, match="unknown history"):
        sweep.table1(**args, history="table3", out=None, workers=1, quiet=True)


def test_a_local_ray_cluster_equals_the_serial_run(serial, tmp_path):
    ray = pytest.importorskip("ray")
    rows, text = serial
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    try:
        out = tmp_path / "RESULTS.md"
        report = sweep.table1(**SMALL, out=str(out), ray="auto", quiet=True)
    finally:
        ray.shutdown()
    assert numbers(report["rows"]) == numbers(rows)
    written = section(out.read_text())
    assert comparable(written) == comparable(section(text))
    assert "a Ray cluster (auto) of 1 node(s), 2 CPUs" in written
