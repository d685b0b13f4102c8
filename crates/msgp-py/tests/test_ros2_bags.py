"""ROS 2 bags in: MCAP files with `cdr` messages and `ros2msg` schemas, written by two libraries
nobody here wrote (`mcap-ros2-support` and `rosbags`), fitted by `msgp fit` with the same
numbers as the same data in a CSV file; broken bags fail with clear messages."""

import subprocess

import numpy as np
import pytest
from conftest import msgp_bin, write_csv

mcap_ros2_writer = pytest.importorskip("mcap_ros2.writer")
rosbags_rosbag2 = pytest.importorskip("rosbags.rosbag2")
rosbags_typesys = pytest.importorskip("rosbags.typesys")

METRICS = ("rmse", "nll", "coverage_2sigma", "test_steps", "data_hash")

FLOAT64 = "float64 data\n"
JOINT_STATE = """std_msgs/Header header
string[] name
float64[] position
float64[] velocity
float64[] effort
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
"""

# 20 ms steps from t0 = 1700000000 s: the header stamps of the bags, a ROS 2 wall clock
T0_NS = 1_700_000_000 * 10**9
STEP_NS = 20_000_000


@pytest.fixture(scope="module")
def series(sys4, tmp_path_factory):
    """System 4's train + test (600 steps) as CSV, and the fit options for all three files."""
    _, data = sys4
    u = np.concatenate([data["u_train"], data["u_test"]])[:600]
    y = np.concatenate([data["y_train"], data["y_test"]])[:600]
    csv = tmp_path_factory.mktemp("csv") / "series.csv"
    write_csv(csv, u, y)
    return csv, u, y


def fit(cli, tmp_path, data, *select):
    return cli(
        "fit", "--data", data, *select, "--train", 300, "--history", "2,2",
        "--method", "gp-narx", "--iters", 20, "--seed", 0, "--json", "--quiet",
        "--out", tmp_path / "model.json",
    )


def stamp(k):
    ns = T0_NS + k * STEP_NS
    return {"sec": ns // 10**9, "nanosec": ns % 10**9}


def test_bag_from_mcap_ros2_support_fits_like_the_csv(series, cli, tmp_path):
    """/cmd (std_msgs/Float64) and /joint_states (sensor_msgs/JointState, the output as its
    second position), both at the same log time per step: the same fit as the CSV."""
    csv, u, y = series
    bag = tmp_path / "run.mcap"
    with open(bag, "wb") as f:
        w = mcap_ros2_writer.Writer(f)
        cmd = w.register_msgdef("std_msgs/msg/Float64", FLOAT64)
        js = w.register_msgdef("sensor_msgs/msg/JointState", JOINT_STATE)
        for k, (a, b) in enumerate(zip(u.tolist(), y.tolist())):
            t = T0_NS + k * STEP_NS
            w.write_message("/cmd", cmd, {"data": a}, log_time=t, publish_time=t)
            w.write_message(
                "/joint_states",
                js,
                {
                    "header": {"stamp": stamp(k), "frame_id": "base"},
                    "name": ["shoulder", "elbow"],
                    "position": [0.5 * b, b],
                    "velocity": [0.0, 0.0],
                    "effort": [],
                },
                log_time=t,
                publish_time=t,
            )
        w.finish()
    want = fit(cli, tmp_path, csv, "--input", "u", "--output", "y")
    got = fit(
        cli, tmp_path, bag, "--input", "/cmd:data", "--output", "/joint_states:position.1"
    )
    for key in METRICS:
        assert got[key] == want[key], key


def test_rosbag2_written_by_rosbags_fits_like_the_csv_on_header_time(series, cli, tmp_path):
    """A rosbag2 folder with MCAP storage, as `ros2 bag record -s mcap` writes it (rosbags'
    own CDR serialiser and Humble message definitions); input and output both in one
    geometry_msgs/TwistStamped topic, times from the header stamps."""
    csv, u, y = series
    store = rosbags_typesys.get_typestore(rosbags_typesys.Stores.ROS2_HUMBLE)
    Twist = store.types["geometry_msgs/msg/TwistStamped"]
    TwistInner = store.types["geometry_msgs/msg/Twist"]
    Vector3 = store.types["geometry_msgs/msg/Vector3"]
    Header = store.types["std_msgs/msg/Header"]
    Time = store.types["builtin_interfaces/msg/Time"]
    folder = tmp_path / "bag"
    writer = rosbags_rosbag2.Writer(
        folder, version=9, storage_plugin=rosbags_rosbag2.StoragePlugin.MCAP
    )
    with writer:
        conn = writer.add_connection(
            "/twist", "geometry_msgs/msg/TwistStamped", typestore=store
        )
        for k, (a, b) in enumerate(zip(u.tolist(), y.tolist())):
            s = stamp(k)
            msg = Twist(
                header=Header(stamp=Time(sec=s["sec"], nanosec=s["nanosec"]), frame_id="base"),
                twist=TwistInner(
                    linear=Vector3(x=a, y=0.0, z=0.0), angular=Vector3(x=0.0, y=0.0, z=b)
                ),
            )
            # log times in reverse order of the stamps' steps within pairs: only the header
            # time keeps the series in order
            log = T0_NS + (k ^ 1) * STEP_NS + 5_000_000
            writer.write(conn, log, store.serialize_cdr(msg, Twist.__msgtype__))
    bags = sorted(folder.glob("*.mcap"))
    assert len(bags) == 1, list(folder.iterdir())
    want = fit(cli, tmp_path, csv, "--input", "u", "--output", "y")
    select = ("--topic", "/twist", "--input", "twist.linear.x", "--output", "twist.angular.z")
    got = fit(cli, tmp_path, bags[0], *select, "--time", "header")
    for key in METRICS:
        assert got[key] == want[key], key
    # by log time the pairs are swapped: different data
    swapped = fit(cli, tmp_path, bags[0], *select)
    assert swapped["data_hash"] != want["data_hash"]


def run_fails(*args):
    proc = subprocess.run(
        [str(msgp_bin()), *map(str, args)], capture_output=True, text=True, timeout=120
    )
    assert proc.returncode != 0, proc.stdout
    return proc.stderr


def small_bag(path, msgdef_name="std_msgs/msg/Float64", msgdef=FLOAT64):
    with open(path, "wb") as f:
        w = mcap_ros2_writer.Writer(f)
        schema = w.register_msgdef(msgdef_name, msgdef)
        for k in range(50):
            t = T0_NS + k * STEP_NS
            w.write_message("/cmd", schema, {"data": float(k)}, log_time=t, publish_time=t)
            w.write_message("/out", schema, {"data": float(k) ** 0.5}, log_time=t, publish_time=t)
        w.finish()


def test_broken_bags_fail_with_clear_messages(tmp_path):
    bag = tmp_path / "ok.mcap"
    small_bag(bag)
    truncated = tmp_path / "truncated.mcap"
    truncated.write_bytes(bag.read_bytes()[: bag.stat().st_size // 2])
    err = run_fails("fit", "--data", truncated, "--input", "/cmd:data", "--output", "/out:data")
    assert "truncated.mcap" in err and "corrupt or truncated" in err, err

    # a schema naming a type it does not define, written with the plain mcap writer
    from mcap.writer import Writer

    unknown = tmp_path / "unknown.mcap"
    with open(unknown, "wb") as f:
        w = Writer(f)
        w.start(profile="ros2")
        sid = w.register_schema(
            name="pkg/msg/Odd", encoding="ros2msg", data=b"float64 x\npkg/Missing extra\n"
        )
        cid = w.register_channel(topic="/odd", message_encoding="cdr", schema_id=sid)
        for k in range(10):
            w.add_message(cid, log_time=k, publish_time=k, data=b"\x00\x01\x00\x00" + bytes(16))
        w.finish()
    err = run_fails("fit", "--data", unknown, "--input", "/odd:x", "--output", "/odd:x")
    assert "unknown.mcap" in err and "unknown message type `pkg/Missing`" in err, err

    # a field the message does not have, and header time on a message without a header
    err = run_fails("fit", "--data", bag, "--input", "/cmd:data", "--output", "/out:value")
    assert "no field `value`" in err and "numeric fields: data" in err, err
    err = run_fails(
        "fit", "--data", bag, "--input", "/cmd:data", "--output", "/out:data", "--time", "header"
    )
    assert "no `header.stamp`" in err and "--time log" in err, err
