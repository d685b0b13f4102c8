import pytest

import msgp


def test_version():
    assert msgp.__version__.count(".") == 2


def test_synthetic_system_is_seeded_and_shaped():
    a = msgp.synthetic_system(4, seed=3)
    b = msgp.synthetic_system(4, seed=3)
    c = msgp.synthetic_system(4, seed=4)
    assert a == b
    assert a["y_train"] != c["y_train"]
    assert len(a["u_train"]) == 500 and len(a["y_test"]) == 500
    assert tuple(a["history"]) == (2, 1)


def test_bad_inputs_raise_value_error():
    with pytest.raises(ValueError, match="1–5"):
        msgp.synthetic_system(9)
    with pytest.raises(ValueError, match="noise"):
        msgp.synthetic_system(4, noise="loud")
    with pytest.raises(ValueError, match="unknown method"):
        msgp.fit_synthetic(4, method="magic")


def test_gp_narx_fit_matches_expected_accuracy():
    m = msgp.fit_synthetic(4, method="gp-narx", seed=0)
    # same seed as the Rust test: 0.6768
    assert abs(m["rmse"] - 0.6768) < 1e-3
    assert 0.0 <= m["coverage_2sigma"] <= 1.0
