"""`msgp.load` reads data files as `msgp fit --data` does: the same column defaults, episodes
and error messages (both call msgp_core's dataset loader)."""

import numpy as np
import pytest

import msgp


def test_default_columns_and_episodes(tmp_path):
    path = tmp_path / "runs.csv"
    rows = ["t,a,b,y,episode"]
    for ep in (0, 1):
        for k in range(5):
            rows.append(f"{k * 0.1!r},{k + ep},{-k},{k * k + 0.5 * ep!r},{ep}")
    path.write_text("\n".join(rows) + "\n")
    data = msgp.load(path)
    # the first non-time column is the input, the last the output; `episode` splits
    assert data["inputs"] == ["a"] and data["outputs"] == ["y"]
    assert [p["episode"] for p in data["parts"]] == [0.0, 1.0]
    second = data["parts"][1]
    assert second["source"] == str(path)
    np.testing.assert_array_equal(second["u"], np.arange(1, 6, dtype=float).reshape(5, 1))
    np.testing.assert_array_equal(second["y"][:, 0], [k * k + 0.5 for k in range(5)])
    np.testing.assert_array_equal(second["t"], [k * 0.1 for k in range(5)])
    # named columns, several files
    both = msgp.load([str(path), path], inputs=["a", "b"], outputs=["y"])
    assert len(both["parts"]) == 4 and both["parts"][0]["u"].shape == (5, 2)


def test_a_loaded_file_fits_like_the_arrays(tmp_path, sys4):
    csv, data = sys4
    loaded = msgp.load(csv)["parts"][0]
    n = len(data["u_train"])
    np.testing.assert_array_equal(loaded["u"][:n, 0], data["u_train"])
    np.testing.assert_array_equal(loaded["y"][:n, 0], data["y_train"])


@pytest.mark.parametrize(
    "text, options, needles",
    [
        ("t,u,y\n0,1,2\n1,2,3\n", {"outputs": ["nope"]}, ["no column `nope`", "columns: t, u, y"]),
        ("t,u,y\n0,1,2\n1,2,NaN\n", {}, ["bad.csv:3:3:", "non-finite value `NaN`"]),
        ("t,u,y\n0,1,2\n1,abc,3\n", {}, ["bad.csv:3:2:", "`abc` in column `u` is not a number"]),
        ("t,u,y\n0,1,2\n1,2\n", {}, ["bad.csv:3:", "2 fields, the header has 3"]),
        ("t,u,y\n0,1,2\n", {"inputs": ["y"], "outputs": ["y"]}, ["`y` is both an input and an output"]),
    ],
)
def test_bad_files_raise_with_the_place(tmp_path, text, options, needles):
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(msgp.InvalidInputError) as raised:
        msgp.load(path, **options)
    for needle in needles:
        assert needle in str(raised.value), str(raised.value)


def test_missing_files_and_mcap_are_refused_clearly(tmp_path):
    with pytest.raises(msgp.InvalidInputError, match="missing.csv: cannot read"):
        msgp.load(tmp_path / "missing.csv")
    with pytest.raises(msgp.InvalidInputError, match="no data files"):
        msgp.load([])
    log = tmp_path / "run.mcap"
    log.write_bytes(b"\x89MCAP0\r\n")
    with pytest.raises(msgp.InvalidInputError, match="reads no MCAP"):
        msgp.load(log)
    with pytest.raises(msgp.InvalidInputError, match="files"):
        msgp.load(42)


def test_rows_out_of_time_order_are_refused_or_sorted(tmp_path):
    path = tmp_path / "late.csv"
    path.write_text("t,u,y\n0,1,10\n2,3,12\n1,2,11\n3,4,13\n")
    with pytest.raises(msgp.InvalidInputError, match=r"late.csv:4:1: time `t` = 1 does not"):
        msgp.load(path)
    data = msgp.load(path, sort_time=True)
    np.testing.assert_array_equal(data["parts"][0]["y"][:, 0], [10, 11, 12, 13])
    assert any("2 of 4 rows moved" in w for w in data["warnings"]), data["warnings"]
    path.write_text("t,u,y\n0,1,10\n1,3,12\n1,2,11\n")
    with pytest.raises(msgp.InvalidInputError, match="time `t` = 1 does not increase"):
        msgp.load(path, sort_time=True)
