"""examples/fit_dryer.py runs (tiny settings) and writes a model that loads."""

import subprocess
import sys

from conftest import REPO

import msgp


def test_fit_dryer_example_runs(dryer, tmp_path):
    path, _, _ = dryer
    done = subprocess.run(
        [sys.executable, str(REPO / "examples" / "fit_dryer.py"), "--data", str(path.parent),
         "--iters", "5", "--inducing", "10", "--out", str(tmp_path / "dryer.png")],
        capture_output=True, text=True, timeout=300, cwd=tmp_path,
    )
    assert done.returncode == 0, done.stderr
    assert "msgp     RMSE" in done.stdout and "gp-narx  RMSE" in done.stdout
    assert msgp.Msgp.load(tmp_path / "dryer.model.json").method == "msgp"
