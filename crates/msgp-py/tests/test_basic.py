import numpy as np

import msgp


def test_version():
    assert msgp.__version__.count(".") == 2


def test_synthetic_system_is_seeded_and_shaped():
    a = msgp.synthetic_system(4, seed=3)
    b = msgp.synthetic_system(4, seed=3)
    c = msgp.synthetic_system(4, seed=4)
    for k in ("u_train", "y_train", "u_test", "y_test"):
        assert isinstance(a[k], np.ndarray) and a[k].dtype == np.float64
        assert np.array_equal(a[k], b[k])
    assert not np.array_equal(a["y_train"], c["y_train"])
    assert a["u_train"].shape == (500,) and a["y_test"].shape == (500,)
    assert tuple(a["history"]) == (2, 1)


def test_synthetic_system_follows_its_difference_equation():
    """System 4's noise-free test outputs, recomputed in numpy from the paper's equation."""
    d = msgp.synthetic_system(4, seed=0)
    u = d["u_test"]
    y = np.zeros_like(u)
    for t in range(len(u)):
        y1 = y[t - 1] if t >= 1 else 0.0
        y2 = y[t - 2] if t >= 2 else 0.0
        u1 = u[t - 1] if t >= 1 else 0.0
        y[t] = 0.3 * y1 + 0.6 * y2 + 0.3 * np.sin(3 * np.pi * u1) + 0.1 * np.sin(5 * np.pi * u1)
    assert np.max(np.abs(y - d["y_test"])) < 1e-12

