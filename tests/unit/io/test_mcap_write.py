"""MCAP writers: ROS 2 JointState / Odometry and JSON series read back field for field by mcap and mcap_ros2."""

from __future__ import annotations

import io
import json
import os
import time

import numpy as np
import pandas as pd
import pytest
from mcap.reader import make_reader
from mcap.well_known import MessageEncoding, SchemaEncoding
from mcap_ros2.decoder import DecoderFactory
from mcap_ros2.writer import Writer as Ros2Writer

from wmrid.core.errors import OutputExistsError, UsageError
from wmrid.io.mcap.series_writer import write_series_mcap
from wmrid.io.mcap.writer import EPOCH_NS, JOINT_STATE_MSGDEF, ODOMETRY_MSGDEF, write_joint_state_mcap

NASTY = [np.nan, -0.0, 0.0, 5e-324, -1.7976931348623157e308, np.inf, -np.inf, 1e-300, 0.1]


def make_frame(n: int = 60, seed: int = 0, angles: bool = True, pose: bool = True) -> tuple[pd.DataFrame, list[int]]:
    """A log whose times are n_i / 1e9 s for known integer n_i (returned); awkward values in every column."""
    rng = np.random.default_rng(seed)
    ns = np.cumsum(rng.integers(1, 3_000_000, size=n)).tolist()  # uneven steps, up to 3 ms
    ns[0] = 0
    frame = pd.DataFrame({"t": np.array(ns, dtype=np.float64) / 1e9})
    names = ["eta_r", "eta_l", "tau_r", "tau_l"]
    names += ["theta_r", "theta_l"] if angles else []
    names += ["x", "y", "phi"] if pose else []
    for k, name in enumerate(names):
        values = rng.normal(size=n) * 10.0 ** rng.integers(-5, 5, size=n)
        values[k % 3 :: 7][: len(NASTY)] = NASTY[: len(values[k % 3 :: 7])]
        frame[name] = values
    return frame, ns


def bits(values) -> np.ndarray:
    """Float64 bit patterns, so that NaN and -0.0 compare exactly."""
    return np.asarray(values, dtype=np.float64).view(np.uint64)


def read_all(path) -> tuple[dict, dict]:
    """{topic: [(message record, decoded)]} and the summary of an MCAP file."""
    out: dict[str, list] = {}
    with open(path, "rb") as fh:
        reader = make_reader(fh, decoder_factories=[DecoderFactory()])
        for _schema, channel, message, decoded in reader.iter_decoded_messages(log_time_order=False):
            out.setdefault(channel.topic, []).append((message, decoded))
        fh.seek(0)
        summary = make_reader(fh).get_summary()
    return out, summary


def raw_messages(data: bytes) -> dict[str, list[bytes]]:
    """{topic: [message payload]} of an MCAP file in memory, in file order."""
    out: dict[str, list[bytes]] = {}
    for _schema, channel, message in make_reader(io.BytesIO(data)).iter_messages(log_time_order=False):
        out.setdefault(channel.topic, []).append(message.data)
    return out


# ---- JointState and Odometry


@pytest.mark.parametrize("compression", ["zstd", "lz4", ""])
def test_joint_state_round_trip_is_exact(tmp_path, compression):
    frame, ns = make_frame()
    path = tmp_path / "log.mcap"
    meta = {"truth": json.dumps({"m11": 0.787}), "note": "ünïcode"}
    write_joint_state_mcap(path, frame, metadata=meta, compression=compression)
    topics, summary = read_all(path)
    assert sorted(topics) == ["/joint_states", "/odom"]

    joints = topics["/joint_states"]
    assert len(joints) == len(frame)
    for i, (message, msg) in enumerate(joints):
        stamp = EPOCH_NS + ns[i]
        assert message.log_time == message.publish_time == stamp
        assert message.sequence == i
        assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == divmod(stamp, 1_000_000_000)
        assert msg.header.frame_id == "base_link"
        assert msg.name == ["left_wheel_joint", "right_wheel_joint"]  # left first
        row = frame.iloc[i]
        np.testing.assert_array_equal(bits(msg.position), bits([row["theta_l"], row["theta_r"]]))
        np.testing.assert_array_equal(bits(msg.velocity), bits([row["eta_l"], row["eta_r"]]))
        np.testing.assert_array_equal(bits(msg.effort), bits([row["tau_l"], row["tau_r"]]))

    odoms = topics["/odom"]
    assert len(odoms) == len(frame)
    phi = frame["phi"].to_numpy()
    with np.errstate(invalid="ignore"):
        half_sin, half_cos = np.sin(0.5 * phi), np.cos(0.5 * phi)
    for i, (message, msg) in enumerate(odoms):
        assert message.log_time == message.publish_time == EPOCH_NS + ns[i]
        assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == divmod(EPOCH_NS + ns[i], 1_000_000_000)
        assert (msg.header.frame_id, msg.child_frame_id) == ("odom", "base_link")
        pose = msg.pose.pose
        np.testing.assert_array_equal(
            bits([pose.position.x, pose.position.y, pose.position.z]), bits([frame["x"][i], frame["y"][i], 0.0])
        )
        q = pose.orientation
        np.testing.assert_array_equal(bits([q.x, q.y, q.z, q.w]), bits([0.0, 0.0, half_sin[i], half_cos[i]]))
        if np.isfinite(phi[i]) and abs(phi[i]) < 1e6:  # the quaternion is the yaw phi
            assert np.isclose(np.angle(np.exp(1j * (2.0 * np.arctan2(q.z, q.w) - phi[i]))), 0.0, atol=1e-9)
        twist = msg.twist.twist
        assert [twist.linear.x, twist.linear.y, twist.linear.z, twist.angular.x, twist.angular.y, twist.angular.z] == [
            0.0
        ] * 6
        assert list(msg.pose.covariance) == [0.0] * 36
        assert list(msg.twist.covariance) == [0.0] * 36

    with open(path, "rb") as fh:
        reader = make_reader(fh)
        assert reader.get_header().profile == "ros2"
        records = list(reader.iter_metadata())
    assert [(r.name, r.metadata) for r in records] == [("wmrid", meta)]
    stats = summary.statistics
    assert stats.message_count == 2 * len(frame)
    assert (stats.schema_count, stats.channel_count, stats.metadata_count) == (2, 2, 1)
    assert stats.message_start_time == EPOCH_NS
    assert stats.message_end_time == EPOCH_NS + ns[-1]
    by_topic = {ch.topic: ch for ch in summary.channels.values()}
    assert {stats.channel_message_counts[ch.id] for ch in by_topic.values()} == {len(frame)}
    for topic, name, text in (
        ("/joint_states", "sensor_msgs/msg/JointState", JOINT_STATE_MSGDEF),
        ("/odom", "nav_msgs/msg/Odometry", ODOMETRY_MSGDEF),
    ):
        channel = by_topic[topic]
        assert channel.message_encoding == MessageEncoding.CDR
        schema = summary.schemas[channel.schema_id]
        assert (schema.name, schema.encoding, schema.data.decode()) == (name, SchemaEncoding.ROS2, text)
    assert {index.compression for index in summary.chunk_indexes} == {compression}


def test_without_angles_or_pose_position_is_empty_and_no_odometry(tmp_path):
    frame, ns = make_frame(n=20, angles=False, pose=False)
    path = tmp_path / "log.mcap"
    write_joint_state_mcap(path, frame, right_joint="R", left_joint="the_left_one", topic="/wheels")
    topics, summary = read_all(path)
    assert list(topics) == ["/wheels"]
    for i, (_message, msg) in enumerate(topics["/wheels"]):
        assert msg.name == ["the_left_one", "R"]
        assert list(msg.position) == []
        np.testing.assert_array_equal(bits(msg.velocity), bits(frame.loc[i, ["eta_l", "eta_r"]]))
        np.testing.assert_array_equal(bits(msg.effort), bits(frame.loc[i, ["tau_l", "tau_r"]]))
        assert msg.header.stamp.nanosec == (EPOCH_NS + ns[i]) % 1_000_000_000
    assert summary.statistics.message_count == 20
    assert summary.statistics.metadata_count == 0


def test_odometry_can_be_left_out(tmp_path):
    frame, _ = make_frame(n=10)
    write_joint_state_mcap(tmp_path / "log.mcap", frame, odom_topic=None)
    topics, _ = read_all(tmp_path / "log.mcap")
    assert list(topics) == ["/joint_states"]


# Joint names of every length modulo 8 (so every string padding case occurs), and non-ASCII names.
NAME_PAIRS = [("l", "r"), ("le", "rig"), ("left", "right"), ("left_wheel_joint", "right_wheel_joint"),
              ("lé", "右輪"), ("a" * 13, "b" * 7), ("x" * 6, "y" * 31)]  # fmt: skip


@pytest.mark.parametrize("names", NAME_PAIRS)
@pytest.mark.parametrize("angles", [True, False])
def test_hand_written_cdr_equals_mcap_ros2(tmp_path, names, angles):
    """The bytes wmrid lays out are those mcap_ros2's own CDR writer produces, and decode back exactly."""
    left, right = names
    frame, ns = make_frame(n=12, seed=len(left), angles=angles)
    path = tmp_path / "log.mcap"
    write_joint_state_mcap(path, frame, left_joint=left, right_joint=right)
    ours = raw_messages(path.read_bytes())

    reference = io.BytesIO()
    writer = Ros2Writer(reference)
    joint_schema = writer.register_msgdef("sensor_msgs/msg/JointState", JOINT_STATE_MSGDEF)
    odom_schema = writer.register_msgdef("nav_msgs/msg/Odometry", ODOMETRY_MSGDEF)
    with np.errstate(invalid="ignore"):
        half_sin, half_cos = np.sin(0.5 * frame["phi"].to_numpy()), np.cos(0.5 * frame["phi"].to_numpy())
    for i, row in frame.iterrows():
        stamp = EPOCH_NS + ns[i]
        header = {"stamp": {"sec": stamp // 1_000_000_000, "nanosec": stamp % 1_000_000_000}, "frame_id": "base_link"}
        joint = {
            "header": header,
            "name": [left, right],
            "position": [row["theta_l"], row["theta_r"]] if angles else [],
            "velocity": [row["eta_l"], row["eta_r"]],
            "effort": [row["tau_l"], row["tau_r"]],
        }
        writer.write_message("/joint_states", joint_schema, joint, log_time=stamp)
        odom = {
            "header": {**header, "frame_id": "odom"},
            "child_frame_id": "base_link",
            "pose": {
                "pose": {
                    "position": {"x": row["x"], "y": row["y"], "z": 0.0},
                    "orientation": {"x": 0.0, "y": 0.0, "z": half_sin[i], "w": half_cos[i]},
                },
                "covariance": [0.0] * 36,
            },
            "twist": {
                "twist": {"linear": {"x": 0.0, "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": 0.0}},
                "covariance": [0.0] * 36,
            },
        }
        writer.write_message("/odom", odom_schema, odom, log_time=stamp)
    writer.finish()
    theirs = raw_messages(reference.getvalue())
    assert ours == theirs

    topics, _ = read_all(path)
    for i, (_message, msg) in enumerate(topics["/joint_states"]):
        assert msg.name == [left, right]
        assert (msg.header.stamp.sec, msg.header.stamp.nanosec) == divmod(EPOCH_NS + ns[i], 1_000_000_000)
        expected = [frame["theta_l"][i], frame["theta_r"][i]] if angles else []
        np.testing.assert_array_equal(bits(msg.position), bits(expected))
        np.testing.assert_array_equal(bits(msg.velocity), bits([frame["eta_l"][i], frame["eta_r"][i]]))
        np.testing.assert_array_equal(bits(msg.effort), bits([frame["tau_l"][i], frame["tau_r"][i]]))


def test_epoch_and_stamps_are_exact_to_the_nanosecond(tmp_path):
    frame = pd.DataFrame({"t": [0.0, 1e-9, 0.999999999, 1.0, 86400.000000001, 1e6 + 1e-6]})
    for name in ("eta_r", "eta_l", "tau_r", "tau_l"):
        frame[name] = 1.0
    write_joint_state_mcap(tmp_path / "a.mcap", frame, t0_ns=0)
    topics, _ = read_all(tmp_path / "a.mcap")
    stamps = [(m.header.stamp.sec, m.header.stamp.nanosec) for _, m in topics["/joint_states"]]
    assert stamps == [(0, 0), (0, 1), (0, 999_999_999), (1, 0), (86400, 1), (1_000_000, 1000)]


# ---- Atomic output and refusal


def test_refuses_to_overwrite_without_force_and_leaves_no_temp_file(tmp_path):
    frame, _ = make_frame(n=10)
    path = tmp_path / "log.mcap"
    path.write_bytes(b"precious")
    with pytest.raises(OutputExistsError):
        write_joint_state_mcap(path, frame)
    with pytest.raises(OutputExistsError):
        write_series_mcap(path, frame["t"].to_numpy(), {"a": frame["eta_r"].to_numpy()})
    assert path.read_bytes() == b"precious"
    assert os.listdir(tmp_path) == ["log.mcap"]
    write_joint_state_mcap(path, frame, force=True)
    assert path.read_bytes().startswith(b"\x89MCAP0\r\n")
    assert os.listdir(tmp_path) == ["log.mcap"]
    _, summary = read_all(path)
    assert summary.statistics.message_count == 20


def test_a_failure_while_writing_leaves_nothing(tmp_path):
    frame, _ = make_frame(n=10)
    path = tmp_path / "log.mcap"
    with pytest.raises(UsageError, match="metadata"):
        write_joint_state_mcap(path, frame, metadata={"truth": {"not": "a string"}})  # type: ignore[dict-item]
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize(
    ("change", "match"),
    [
        (lambda f: f.drop(columns=["tau_l"]), "tau_l"),
        (lambda f: f.drop(columns=["theta_l"]), "theta_r"),
        (lambda f: f.drop(columns=["phi"]), "x, y, phi"),
        (lambda f: f.assign(t=np.arange(len(f)) * 1_000_000), "integer"),
        (lambda f: f.assign(t=f["t"].to_numpy()[::-1].copy()), "decreases"),
        (lambda f: f.assign(t=np.where(np.arange(len(f)) == 3, np.nan, f["t"])), "data row 4"),
        (lambda f: f.assign(t=f["t"] + 2.0**31), "range"),
    ],
)
def test_malformed_logs_are_refused(tmp_path, change, match):
    frame, _ = make_frame(n=10)
    with pytest.raises(UsageError, match=match):
        write_joint_state_mcap(tmp_path / "log.mcap", change(frame))
    assert os.listdir(tmp_path) == []


@pytest.mark.parametrize(
    ("options", "match"),
    [
        ({"compression": "gzip"}, "compression"),
        ({"chunk_size": 0}, "chunk size"),
        ({"left_joint": "j", "right_joint": "j"}, "two names"),
        ({"odom_topic": "/joint_states"}, "odom_topic"),
    ],
)
def test_bad_options_are_refused(tmp_path, options, match):
    frame, _ = make_frame(n=10)
    with pytest.raises(UsageError, match=match):
        write_joint_state_mcap(tmp_path / "log.mcap", frame, **options)
    assert os.listdir(tmp_path) == []


def test_small_chunks_split_the_log_and_keep_every_message(tmp_path):
    frame, _ = make_frame(n=500)
    write_joint_state_mcap(tmp_path / "log.mcap", frame, chunk_size=4096)
    topics, summary = read_all(tmp_path / "log.mcap")
    assert len(summary.chunk_indexes) == summary.statistics.chunk_count > 10
    assert [m.sequence for m, _ in topics["/joint_states"]] == list(range(500))


# ---- JSON series


@pytest.mark.parametrize("compression", ["zstd", ""])
def test_series_round_trip(tmp_path, compression):
    rng = np.random.default_rng(3)
    n = 300
    t = np.cumsum(rng.uniform(1e-4, 1e-2, n))
    series = {
        "theta11": rng.normal(size=n),
        "e_r": rng.normal(size=n) * 1e-12,
        "lambda_min": np.array(NASTY * (n // len(NASTY) + 1))[:n],
        "count": np.arange(n),
        'odd "name"/ü': -rng.normal(size=n),
    }
    path = tmp_path / "est.mcap"
    write_series_mcap(path, t, series, metadata={"run": "1"}, t0_ns=5, compression=compression)

    with open(path, "rb") as fh:
        reader = make_reader(fh)
        messages = list(reader.iter_messages())
        summary = reader.get_summary()
        records = list(reader.iter_metadata())
    assert len(messages) == n
    for i, (schema, channel, message) in enumerate(messages):
        assert (channel.topic, channel.message_encoding) == ("/wmrid/estimates", "json")
        assert (schema.name, schema.encoding) == ("wmrid.Series", "jsonschema")
        assert message.log_time == message.publish_time == 5 + round(t[i] * 1e9)
        assert message.sequence == i
        obj = json.loads(message.data)
        assert list(obj) == ["t", *series]
        assert bits(obj["t"]) == bits(t[i])
        for name, values in series.items():
            if np.isfinite(values[i]):
                assert bits(obj[name]) == bits(values[i]), name
            else:
                assert obj[name] is None
    schema = json.loads(messages[0][0].data)
    assert schema["type"] == "object"
    assert list(schema["properties"]) == ["t", *series]
    assert all(p["type"] == "number" for p in schema["properties"].values())
    assert [(r.name, r.metadata) for r in records] == [("wmrid", {"run": "1"})]
    stats = summary.statistics
    assert (stats.message_count, stats.channel_count, stats.schema_count) == (n, 1, 1)
    assert dict(stats.channel_message_counts) == {messages[0][1].id: n}


def test_series_rejects_bad_input(tmp_path):
    t = np.arange(5) * 0.1
    with pytest.raises(UsageError, match="shape"):
        write_series_mcap(tmp_path / "a.mcap", t, {"a": np.zeros(4)})
    with pytest.raises(UsageError, match="'t'"):
        write_series_mcap(tmp_path / "a.mcap", t, {"t": np.zeros(5)})
    with pytest.raises(UsageError, match="float seconds"):
        write_series_mcap(tmp_path / "a.mcap", np.arange(5), {"a": np.zeros(5)})
    assert os.listdir(tmp_path) == []


# ---- A long log


@pytest.mark.slow  # 600,000 messages written and read back: 2.7 s
def test_ten_minutes_at_1khz(tmp_path, record_property):
    """600 001 rows: summary counts right across many chunks; the write speed is recorded, not asserted."""
    n = 600_001
    rng = np.random.default_rng(0)
    frame = pd.DataFrame({"t": np.arange(n) * 1e-3})
    for name in ("eta_r", "eta_l", "tau_r", "tau_l", "theta_r", "theta_l"):
        frame[name] = rng.normal(size=n)
    path = tmp_path / "long.mcap"
    start = time.perf_counter()
    write_joint_state_mcap(path, frame)
    elapsed = time.perf_counter() - start
    record_property("joint_state_messages_per_second", round(n / elapsed))
    with open(path, "rb") as fh:
        summary = make_reader(fh).get_summary()
    stats = summary.statistics
    assert stats.message_count == n
    assert list(stats.channel_message_counts.values()) == [n]
    assert stats.message_end_time - stats.message_start_time == 600 * 1_000_000_000
    assert stats.chunk_count == len(summary.chunk_indexes) > 1
