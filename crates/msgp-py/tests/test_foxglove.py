"""Foxglove out: the simulator's MCAP logs carry the 3D scene in Foxglove's well-known protobuf
schemas, and `msgp simulate --out pred.mcap` writes the prediction with ±2σ next to the
measurement; both are read back with the `mcap` Python library (and its protobuf decoder),
written by nobody here."""

import json
import math

import numpy as np
import pytest
from conftest import write_csv

import msgp

mcap_reader = pytest.importorskip("mcap.reader")
mcap_protobuf = pytest.importorskip("mcap_protobuf.decoder")


def read(path, topics=None):
    """{topic: [(log_time, decoded message)]} and the summary."""
    out = {}
    with open(path, "rb") as f:
        reader = mcap_reader.make_reader(f, decoder_factories=[mcap_protobuf.DecoderFactory()])
        summary = reader.get_summary()
        for schema, channel, message in reader.iter_messages(topics=topics):
            if channel.message_encoding == "json":
                decoded = json.loads(message.data)
            else:
                decoded = mcap_protobuf.DecoderFactory().decoder_for(
                    channel.message_encoding, schema
                )(message.data)
            out.setdefault(channel.topic, []).append((message.log_time, decoded))
    return out, summary


def test_sim_log_carries_the_scene(cli, tmp_path):
    run = tmp_path / "run.mcap"
    cli("sim", "pendulum", "--preset", "hand-tuned", "--seconds", 2, "--theta0", 0.05,
        "--out", run, parse=False)
    msgs, summary = read(run)
    kinds = {
        c.topic: (c.message_encoding, summary.schemas[c.schema_id].name,
                  summary.schemas[c.schema_id].encoding)
        for c in summary.channels.values()
    }
    assert kinds["/pendulum/tf"] == ("protobuf", "foxglove.FrameTransforms", "protobuf")
    assert kinds["/pendulum/scene"] == ("protobuf", "foxglove.SceneUpdate", "protobuf")
    latent = dict(msgs["/pendulum/latent"])
    tf = msgs["/pendulum/tf"]
    assert len(tf) == len(latent) == 101
    for log_time, m in tf:
        state = latent[log_time]
        ee, pole = m.transforms
        assert (ee.parent_frame_id, ee.child_frame_id) == ("world", "end_effector")
        assert (pole.parent_frame_id, pole.child_frame_id) == ("end_effector", "pole")
        assert ee.translation.x == state["x"]
        assert pole.rotation.y == pytest.approx(math.sin(state["theta"] / 2), abs=1e-15)
        assert pole.rotation.w == pytest.approx(math.cos(state["theta"] / 2), abs=1e-15)
        assert ee.timestamp.seconds * 10**9 + ee.timestamp.nanos == log_time
    # the scene comes once, at the first step, with the plant's pole
    (first, scene), = msgs["/pendulum/scene"]
    assert first == tf[0][0]
    episode = json.loads(_metadata(run)["episode"])
    pole = next(e for e in scene.entities if e.id == "pole")
    assert pole.frame_id == "pole" and pole.frame_locked
    assert pole.cylinders[0].size.z == episode["params"]["pole_length"]
    assert pole.spheres[0].pose.position.z == episode["params"]["pole_com"]


def _metadata(path):
    with open(path, "rb") as f:
        reader = mcap_reader.make_reader(f)
        return next(m.metadata for m in reader.iter_metadata() if m.name == "msgp.pendulum.episode")


def test_simulate_writes_a_foxglove_plot_log_equal_to_the_csv(sys4, cli, tmp_path):
    _, data = sys4
    model = msgp.Msgp(history=data["history"], inducing=10, iterations=10, seed=0)
    model.fit(data["u_train"], data["y_train"])
    path = tmp_path / "m.model.json"
    model.save(path)
    test_csv = tmp_path / "test.csv"
    write_csv(test_csv, data["u_test"], data["y_test"])
    common = ("simulate", "--model", path, "--data", test_csv, "--filtered", "--json")
    cli(*common, "--out", tmp_path / "pred.csv")
    report = cli(*common, "--out", tmp_path / "pred.mcap")
    table = np.genfromtxt(tmp_path / "pred.csv", delimiter=",", names=True)
    msgs, summary = read(tmp_path / "pred.mcap")
    (channel,) = summary.channels.values()
    assert channel.topic == "/msgp/prediction"
    assert summary.schemas[channel.schema_id].name == "msgp.Prediction"
    steps = msgs["/msgp/prediction"]
    assert len(steps) == len(table) == report["rows"]
    for row, (log_time, m) in zip(table, steps):
        assert log_time == round(row["t"] * 1e9)
        (out,) = m["outputs"]
        assert out["name"] == "y"
        assert out["mean"] == row["y_mean"] and out["std"] == row["y_std"]
        assert out["measured"] == row["y"]
        assert out["lower"] == out["mean"] - 2 * out["std"]
        assert out["upper"] == out["mean"] + 2 * out["std"]
        assert out["filtered_mean"] == row["y_filtered_mean"]


def test_simulate_refuses_an_unknown_extension_before_simulating(sys4, cli, tmp_path):
    import subprocess

    from conftest import msgp_bin

    csv, _ = sys4
    proc = subprocess.run(
        [str(msgp_bin()), "simulate", "--model", tmp_path / "missing.json", "--data", csv,
         "--out", tmp_path / "pred.txt"],
        capture_output=True, text=True, timeout=60,
    )
    assert proc.returncode != 0
    assert "extension must be .csv or .mcap" in proc.stderr, proc.stderr
