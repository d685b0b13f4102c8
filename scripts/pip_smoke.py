"""A pip-installed msgp, as a user meets it: imported from the virtualenv's site-packages (not
from the source tree), a fit on synthetic system 4, its score, a save and a load. Argument: the
virtualenv's folder. Fails (non-zero exit) on any mismatch."""

import sys
import tempfile
from pathlib import Path

import numpy as np

import msgp

venv = Path(sys.argv[1]).resolve()
where = Path(msgp.__file__).resolve()
assert venv in where.parents, f"msgp imported from {where}, not from {venv}"
data = msgp.synthetic_system(4, seed=0)
model = msgp.Msgp(history=data["history"], inducing=20, iterations=30, seed=0)
model.fit(data["u_train"], data["y_train"])
score = model.score(data["u_test"], data["y_test"])
assert np.isfinite(score["rmse"]) and score["rmse"] < 1.0, score
with tempfile.TemporaryDirectory() as tmp:
    path = Path(tmp) / "m.model.json"
    model.save(path)
    again = msgp.Msgp.load(path).score(data["u_test"], data["y_test"])
assert again == score, (again, score)
print(f"pip-installed msgp at {where.parent}: system 4 test RMSE {score['rmse']:.4f}")
