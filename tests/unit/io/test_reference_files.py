"""Reference drives on file (wmrid.io.reference_files): each format written and read back -- by wmrid and, for MCAP,
by rosbags (an independent ROS 2 reader) -- and one clear line for every malformed file."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from mcap.writer import Writer as RawMcapWriter
from rosbags.highlevel import AnyReader

from wmrid.core.errors import LogFormatError, OutputExistsError, UsageError
from wmrid.io.mcap.series_writer import write_series_mcap
from wmrid.io.reference_files import read_reference, write_reference

DURATION = 6.0
RATE = 50.0


def _plan() -> dict[str, np.ndarray]:
    """A plan's columns: v = V sin^2(pi t / T), omega = W sin(2 pi t / T) sin^2(pi t / T), at rest at both ends, with
    the wheel speeds and the pose a plan writes alongside (values need not be consistent for a file test)."""
    t = np.arange(round(DURATION * RATE) + 1) / RATE
    s2 = np.sin(np.pi * t / DURATION) ** 2
    v = 0.4 * s2
    omega = 0.8 * np.sin(2 * np.pi * t / DURATION) * s2
    r, b = 0.05, 0.2
    return {
        "t": t, "v": v, "omega": omega, "eta_r": (v + b * omega) / r, "eta_l": (v - b * omega) / r,
        "x": np.cumsum(v) / RATE, "y": np.zeros_like(t), "phi": np.cumsum(omega) / RATE,
    }  # fmt: skip


def _one_line(err: pytest.ExceptionInfo, *needles: str) -> str:
    text = str(err.value)
    assert "\n" not in text, text
    for needle in needles:
        assert needle in text, (needle, text)
    return text


# --------------------------------------------------------------------------------------------------- round trips


@pytest.mark.parametrize("suffix", [".csv", ".parquet", ".tsv"])
def test_table_round_trip_keeps_every_column_bit_for_bit(tmp_path: Path, suffix: str) -> None:
    cols = _plan()
    path = tmp_path / f"plan{suffix}"
    write_reference(path, cols)
    t, v, omega = read_reference(path)
    np.testing.assert_array_equal(t, cols["t"])
    np.testing.assert_array_equal(v, cols["v"])
    np.testing.assert_array_equal(omega, cols["omega"])
    frame = pd.read_parquet(path) if suffix == ".parquet" else pd.read_csv(path, sep="\t" if suffix == ".tsv" else ",")
    assert list(frame.columns) == list(cols)  # every column, in the order given
    for name, values in cols.items():
        np.testing.assert_array_equal(frame[name].to_numpy(), values)


def _rosbags_messages(path: Path) -> tuple[list, list[int], list]:
    """(connections, log times ns, messages) of a bare .mcap file as rosbags reads it, with the message definitions
    taken from the file's own schemas."""
    with AnyReader([path]) as reader:
        connections = list(reader.connections)
        stamps, messages = [], []
        for conn, stamp, raw in reader.messages():
            stamps.append(stamp)
            messages.append(reader.deserialize(raw, conn.msgtype))
    return connections, stamps, messages


@pytest.mark.parametrize("stamped", [False, True])
def test_mcap_round_trip_read_by_rosbags_and_by_wmrid(tmp_path: Path, stamped: bool) -> None:
    cols = _plan()
    path = tmp_path / "plan.mcap"
    start = 1_700_000_000_123_456_789
    write_reference(path, cols, topic="/robot/cmd_vel", stamped=stamped, frame_id="base_footprint", start_ns=start)

    connections, stamps, messages = _rosbags_messages(path)
    assert [(c.topic, c.msgtype) for c in connections] == [
        ("/robot/cmd_vel", "geometry_msgs/msg/TwistStamped" if stamped else "geometry_msgs/msg/Twist")
    ]
    assert connections[0].msgcount == len(cols["t"])
    assert stamps == [start + round(t * 1e9) for t in cols["t"]]  # log times: the pace ros2 bag play keeps
    twists = [m.twist for m in messages] if stamped else messages
    np.testing.assert_array_equal([m.linear.x for m in twists], cols["v"])
    np.testing.assert_array_equal([m.angular.z for m in twists], cols["omega"])
    for m in twists:
        assert (m.linear.y, m.linear.z, m.angular.x, m.angular.y) == (0.0, 0.0, 0.0, 0.0)
    if stamped:
        assert [m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in messages] == stamps
        assert {m.header.frame_id for m in messages} == {"base_footprint"}

    t, v, omega = read_reference(path)
    np.testing.assert_allclose(t, cols["t"], rtol=0, atol=1e-12)  # ns on the file: t to well within 1e-12 s
    np.testing.assert_array_equal(v, cols["v"])
    np.testing.assert_array_equal(omega, cols["omega"])


def test_zero_stamps_for_controllers_that_drop_old_commands(tmp_path: Path) -> None:
    path = tmp_path / "plan.mcap"
    write_reference(path, _plan(), stamped=True, zero_stamps=True)
    _, stamps, messages = _rosbags_messages(path)
    assert {(m.header.stamp.sec, m.header.stamp.nanosec) for m in messages} == {(0, 0)}
    assert stamps[1] == 20_000_000  # the log times still pace the replay


def test_csv_and_mcap_hold_the_same_reference(tmp_path: Path) -> None:
    cols = _plan()
    write_reference(tmp_path / "plan.csv", cols)
    write_reference(tmp_path / "plan.mcap", cols)
    for a, b in zip(read_reference(tmp_path / "plan.csv"), read_reference(tmp_path / "plan.mcap"), strict=True):
        np.testing.assert_allclose(b, a, rtol=0, atol=1e-12)


def test_mcap_times_are_relative_to_the_first_message(tmp_path: Path) -> None:
    cols = {"t": np.array([2.0, 2.5, 3.25]), "v": np.array([0.0, 0.1, 0.0]), "omega": np.zeros(3)}
    write_reference(tmp_path / "plan.mcap", cols)
    t, _, _ = read_reference(tmp_path / "plan.mcap")
    np.testing.assert_array_equal(t, [0.0, 0.5, 1.25])


def test_mcap_topic_is_chosen_by_name(tmp_path: Path) -> None:
    """Two Twist topics: the default is refused with both named, ``topic`` picks one."""
    path = tmp_path / "two.mcap"
    with path.open("wb") as fh:
        from mcap_ros2.writer import Writer

        from wmrid.io.reference_files import TWIST_MSGDEF

        writer = Writer(fh)
        schema = writer.register_msgdef("geometry_msgs/msg/Twist", TWIST_MSGDEF)
        for i in range(3):
            for topic, speed in (("/a", 0.1), ("/b", 0.2)):
                msg = {"linear": {"x": speed * i}, "angular": {"z": -speed}}
                writer.write_message(topic, schema, msg, log_time=i * 10**8, publish_time=i * 10**8)
        writer.finish()
    with pytest.raises(LogFormatError) as err:
        read_reference(path)
    _one_line(err, str(path), "/a", "/b")
    t, v, omega = read_reference(path, topic="/b")
    np.testing.assert_allclose(t, [0.0, 0.1, 0.2], rtol=0, atol=1e-15)
    np.testing.assert_array_equal(v, [0.0, 0.2, 0.4])
    np.testing.assert_array_equal(omega, [-0.2] * 3)


def test_an_existing_file_is_kept_without_force(tmp_path: Path) -> None:
    path = tmp_path / "plan.csv"
    path.write_text("keep me\n")
    with pytest.raises(OutputExistsError):
        write_reference(path, _plan())
    assert path.read_text() == "keep me\n"
    write_reference(path, _plan(), force=True)
    assert len(read_reference(path)[0]) == len(_plan()["t"])


def test_an_input_of_the_command_is_never_overwritten(tmp_path: Path) -> None:
    from wmrid.runtime.atomic import clear_inputs, track_inputs

    path = tmp_path / "plan.mcap"
    write_reference(path, _plan())
    before = path.read_bytes()
    track_inputs()  # as the command line does while a command runs
    try:
        read_reference(path)
        with pytest.raises(UsageError) as err:
            write_reference(path, _plan(), force=True)
    finally:
        clear_inputs()
    _one_line(err, "it is the input")
    assert path.read_bytes() == before


# --------------------------------------------------------------------------------------------------- malformed


@pytest.mark.parametrize(
    ("text", "needles"),
    [
        ("t,v\n0,0\n1,0\n", ["no column 'omega'", "columns: t, v"]),
        ("t,v,omega\n0,0,0\n1,0.1,0\n1,0.2,0\n", ["t does not increase at data row 3"]),
        ("t,v,omega\n0,0,0\n2,0.1,0\n1,0.2,0\n", ["t does not increase at data row 3"]),
        ("t,v,omega\n0,0,0\n1,nan,0\n2,0,0\n", ["v is NaN or infinite at data row 2"]),
        ("t,v,omega\n0,0,0\n1,0,\n2,0,0\n", ["omega is NaN or infinite at data row 2"]),
        ("t,v,omega\n0,0,0\n1,fast,0\n", ["column 'v' holds 'fast' at data row 2"]),
        ("t,v,omega\n0,0,0\n", ["1 data rows", "at least 2"]),
        ("t,v,omega\n", ["0 data rows"]),
        ("", ["is empty"]),
    ],
    ids=["missing-column", "repeated-t", "decreasing-t", "nan", "blank", "text", "one-row", "header-only", "empty"],
)
def test_malformed_csv_gets_one_line(tmp_path: Path, text: str, needles: list[str]) -> None:
    path = tmp_path / "bad.csv"
    path.write_text(text)
    with pytest.raises(LogFormatError) as err:
        read_reference(path)
    _one_line(err, str(path), *needles)


def test_malformed_parquet_gets_one_line(tmp_path: Path) -> None:
    path = tmp_path / "bad.parquet"
    pd.DataFrame({"t": [0.0, 1.0], "speed": [0.0, 0.1], "omega": [0.0, 0.0]}).to_parquet(path)
    with pytest.raises(LogFormatError) as err:
        read_reference(path)
    _one_line(err, str(path), "no column 'v'")
    path.write_bytes(b"PAR1 not really")
    with pytest.raises(LogFormatError) as err:
        read_reference(path)
    _one_line(err, str(path), "not a readable Parquet file")


def test_mcap_without_twist_gets_one_line(tmp_path: Path) -> None:
    path = tmp_path / "series.mcap"
    write_series_mcap(path, np.array([0.0, 1.0]), {"v": np.array([0.0, 1.0])}, topic="/wmrid/estimates")
    with pytest.raises(LogFormatError) as err:
        read_reference(path)
    _one_line(err, str(path), "no geometry_msgs/msg/Twist", "/wmrid/estimates")
    write_reference(tmp_path / "plan.mcap", _plan())
    with pytest.raises(LogFormatError) as err:
        read_reference(tmp_path / "plan.mcap", topic="/other")
    _one_line(err, "no Twist or TwistStamped messages on topic '/other'")


@pytest.mark.parametrize("content", [b"", b"\x89MCAP0\r\n", b"not an mcap file at all"], ids=["empty", "cut", "text"])
def test_unreadable_mcap_gets_one_line(tmp_path: Path, content: bytes) -> None:
    path = tmp_path / "bad.mcap"
    path.write_bytes(content)
    with pytest.raises(LogFormatError) as err:
        read_reference(path)
    _one_line(err, str(path), "not a readable MCAP file")


def test_mcap_with_repeated_log_times_names_the_message(tmp_path: Path) -> None:
    """A Twist recording whose log times repeat (two messages in one nanosecond) is not a reference."""
    from mcap_ros2.writer import Writer

    from wmrid.io.reference_files import TWIST_MSGDEF

    path = tmp_path / "repeat.mcap"
    with path.open("wb") as fh:
        writer = Writer(fh)
        schema = writer.register_msgdef("geometry_msgs/msg/Twist", TWIST_MSGDEF)
        for i, stamp in enumerate([0, 10**8, 10**8, 3 * 10**8]):
            writer.write_message("/cmd_vel", schema, {"linear": {"x": 0.1 * i}}, log_time=stamp, publish_time=stamp)
        writer.finish()
    with pytest.raises(LogFormatError) as err:
        read_reference(path)
    _one_line(err, str(path), "t does not increase at message 3 on /cmd_vel")


def test_mcap_twist_in_json_is_refused(tmp_path: Path) -> None:
    path = tmp_path / "json.mcap"
    with path.open("wb") as fh:
        writer = RawMcapWriter(fh)
        writer.start(profile="", library="test")
        schema = writer.register_schema("geometry_msgs/msg/Twist", "jsonschema", b"{}")
        channel = writer.register_channel("/cmd_vel", "json", schema)
        for i in range(2):
            writer.add_message(channel, i, b'{"linear": {"x": 0.1}}', i)
        writer.finish()
    with pytest.raises(LogFormatError) as err:
        read_reference(path)
    _one_line(err, str(path), "'json'", "CDR")


def test_missing_file_and_unknown_suffix(tmp_path: Path) -> None:
    with pytest.raises(UsageError) as err:
        read_reference(tmp_path / "nowhere.csv")
    _one_line(err, "does not exist")
    with pytest.raises(UsageError) as err:
        read_reference(tmp_path)
    _one_line(err, "is a folder")
    with pytest.raises(UsageError) as err:
        write_reference(tmp_path / "plan.json", _plan())
    _one_line(err, ".csv, .parquet or .mcap")


# --------------------------------------------------------------------------------------------------- writer checks


def test_writer_refuses_what_no_reader_would_take(tmp_path: Path) -> None:
    cols = _plan()
    with pytest.raises(UsageError) as err:
        write_reference(tmp_path / "a.csv", {"t": cols["t"], "v": cols["v"]})
    _one_line(err, "missing 'omega'")
    with pytest.raises(UsageError) as err:
        write_reference(tmp_path / "a.csv", {**cols, "x": cols["x"][:-1]})
    _one_line(err, "column 'x' has")
    bad_t = cols["t"].copy()
    bad_t[5] = bad_t[4]
    with pytest.raises(LogFormatError) as err:
        write_reference(tmp_path / "a.mcap", {**cols, "t": bad_t})
    _one_line(err, "t does not increase at data row 6")
    bad_v = cols["v"].copy()
    bad_v[3] = math.inf
    with pytest.raises(LogFormatError) as err:
        write_reference(tmp_path / "a.parquet", {**cols, "v": bad_v})
    _one_line(err, "v is NaN or infinite at data row 4")
    with pytest.raises(LogFormatError) as err:  # distinct in float seconds, one nanosecond on the MCAP clock
        write_reference(tmp_path / "a.mcap", {"t": np.array([0.0, 1e-10]), "v": np.zeros(2), "omega": np.zeros(2)})
    _one_line(err, "same nanosecond")
    with pytest.raises(UsageError) as err:
        write_reference(tmp_path / "a.mcap", {"t": np.array([0.0, 1.0]), "v": np.zeros(2), "omega": np.zeros(2)},
                        start_ns=-5)  # fmt: skip
    _one_line(err, "range of a ROS stamp")
    assert sorted(p.name for p in tmp_path.iterdir()) == []  # nothing written, not even a temporary file
