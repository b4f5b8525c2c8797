"""ROS 1 bags, ROS 2 .db3 bags, rosbag2 folders (sqlite3 and MCAP storage, split over several files) and several bag
files of one recording: each read through rosbags gives exactly the log, and the identification, of the MCAP it was
converted from.

The bags are written in the tests by rosbags' own writers (:mod:`tests.bagutil`) from the bundled sample
(``sample_logs/paper_sinusoid.mcap``) and from the real ME169 bags; the reference is wmrid's own MCAP reader,
which tests/unit/io/test_mcap_read.py checks against mcap_ros2's decoder.  The issue asks for the same parameters within
1e-12 relative; they are checked for exact equality (the same samples go through the same arithmetic).
"""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
from locations import ROOT_DIR

from tests import bagutil
from tests.cliutil import text, wmrid
from wmrid.io.bag.reader import read_bag
from wmrid.io.logs import open_log, read_log
from wmrid.io.mcap import log as mcap_log
from wmrid.io.table.columns import parse_column_mapping

ROOT = ROOT_DIR
SAMPLE = ROOT / "sample_logs" / "paper_sinusoid.mcap"
ME169 = ROOT.parent / "shared" / "real_logs" / "me169" / "wheel_pwm_2022-04-13-14-27-37.mcap"
ME169_OPTIONS = (
    "--velocity-topic", "/wheel_state", "--effort-topic", "/wheel_desired",
    "--right-joint", "rightwheel", "--left-joint", "leftwheel", "--effort", "pwm",
)  # fmt: skip


def _formats(folder: Path, messages: list[bagutil.Message]) -> dict[str, list[Path]]:
    """{format: the paths to give wmrid} of one recording written every way."""
    half = len(messages) // 2
    two = folder / "two"
    two.mkdir()
    out = {
        "ros1": [bagutil.write_ros1(folder / "plain.bag", messages)],
        "ros1-lz4": [bagutil.write_ros1(folder / "lz4.bag", messages, "lz4")],
        "ros1-bz2": [bagutil.write_ros1(folder / "bz2.bag", messages, "bz2")],
        "ros1-two-files": [
            bagutil.write_ros1(two / f"run_{i}.bag", part) for i, part in enumerate((messages[:half], messages[half:]))
        ],
        "db3-folder": [bagutil.write_rosbag2(folder / "db3", messages)],
        "mcap-folder": [bagutil.write_rosbag2(folder / "mcapdir", messages, "mcap")],
        "db3-split": [bagutil.write_split_rosbag2(folder / "split_db3", messages)],
        "mcap-split": [bagutil.write_split_rosbag2(folder / "split_mcap", messages, "mcap")],
    }
    out["db3-file"] = [folder / "db3" / "db3.db3"]
    out["ros1-folder"] = [two]
    return out


@pytest.fixture(scope="module")
def sample_bags(tmp_path_factory):
    return _formats(tmp_path_factory.mktemp("sample"), bagutil.recording(SAMPLE))


def _identify(paths, *options: str) -> dict:
    out = wmrid("identify", *map(str, paths), *options, "--format", "json")
    assert out.returncode == 0, text(out).stderr
    return json.loads(out.stdout)


@pytest.fixture(scope="module")
def sample_result():
    return _identify([SAMPLE])


FORMATS = ["ros1", "ros1-lz4", "ros1-bz2", "ros1-two-files", "ros1-folder", "db3-folder", "db3-file", "mcap-folder",
           "db3-split", "mcap-split"]  # fmt: skip


@pytest.mark.parametrize("kind", FORMATS)
def test_every_format_reads_as_the_mcap(sample_bags, kind):
    """Every layout gives the MCAP's log: the same samples, bit for bit, and the same notes (so the same
    identification, which the next test runs on the three layouts the issue names)."""
    reference = read_log(str(SAMPLE))
    log = read_log([str(p) for p in sample_bags[kind]])
    assert np.array_equal(log.t, reference.t)
    assert np.array_equal(log.eta, reference.eta)
    assert np.array_equal(log.tau, reference.tau)
    assert log.notes == reference.notes


@pytest.mark.parametrize("kind", ["ros1", "db3-folder", "db3-split"])
def test_the_sample_as_a_bag_identifies_as_the_mcap(sample_bags, sample_result, kind):
    """The issue's "done when": the bundled sample as a ROS 1 bag, a db3 and a split rosbag2 folder identifies to
    the parameters of the MCAP; here exactly, with the same notes and warnings."""
    result = _identify(sample_bags[kind])
    assert result["parameters"] == sample_result["parameters"]
    assert result["estimate"] == sample_result["estimate"]
    assert result["log"]["notes"] == sample_result["log"]["notes"]
    assert result["warnings"] == sample_result["warnings"]


@pytest.mark.parametrize("kind", ["ros1", "db3-split"])
def test_the_samples_are_the_mcap_samples_and_stream_the_same(sample_bags, kind, monkeypatch):
    """Read whole, streamed in small pieces with the scan's parts replayed, and streamed decoding the files again:
    the MCAP's samples, bit for bit."""
    reference = read_log(str(SAMPLE))
    paths = [str(p) for p in sample_bags[kind]]
    whole = read_log(paths)
    for replay in (mcap_log._MCAP_REPLAY_BYTES, 0):
        monkeypatch.setattr(mcap_log, "_MCAP_REPLAY_BYTES", replay)
        stream = open_log(paths, rows=3001)
        pieces = list(stream)
        assert hasattr(stream, "_mcap_peak"), "the streaming path was not taken"
        assert max(len(p) for p in pieces) == 3001
        joined = np.concatenate([p.eta for p in pieces]), np.concatenate([p.tau for p in pieces])
        assert np.array_equal(joined[0], reference.eta)
        assert np.array_equal(joined[1], reference.tau)
        assert stream.notes == reference.notes
    for log in (whole,):
        assert np.array_equal(log.t, reference.t)
        assert np.array_equal(log.eta, reference.eta)
        assert np.array_equal(log.tau, reference.tau)


def test_the_fast_path_equals_rosbags_deserialiser_message_by_message(sample_bags):
    """Every JointState of the ROS 1 bag and the db3 decoded by wmrid's kernels against rosbags' deserialiser."""
    from rosbags.highlevel import AnyReader

    for kind in ("ros1-lz4", "db3-folder"):
        series = read_bag([str(p) for p in sample_bags[kind]]).joints["/joint_states"]
        with AnyReader(sample_bags[kind]) as reader:
            msgs = [reader.deserialize(raw, c.msgtype) for c, _, raw in reader.messages()]
        assert len(msgs) == len(series.log_ns)
        assert list(series.names) == list(msgs[0].name)
        stamps = np.array([m.header.stamp.sec * 10**9 + m.header.stamp.nanosec for m in msgs])
        assert np.array_equal(series.stamp_ns, stamps)
        for field in ("position", "velocity", "effort"):
            assert np.array_equal(getattr(series, field), np.array([getattr(m, field) for m in msgs])), (kind, field)


def _read_both_ways(paths, monkeypatch, **options):
    """The log of ``paths`` read with wmrid's own sqlite3 reader, and with rosbags' message generators; and the
    recordings wmrid's reader was given (None when it left them to rosbags)."""
    import wmrid as api
    from wmrid.io.bag import db3_file

    plans = []
    real_files = db3_file.db3_files

    def recorded(paths):
        plans.append(real_files(paths))
        return plans[-1]

    monkeypatch.setattr(db3_file, "db3_files", recorded)
    own = api.read_log([str(p) for p in paths], **options)
    monkeypatch.setattr(db3_file, "db3_files", lambda paths: None)
    theirs = api.read_log([str(p) for p in paths], **options)
    return own, theirs, plans


@pytest.mark.parametrize("kind", ["db3-folder", "db3-file", "db3-split"])
def test_sqlite_storage_read_by_wmrid_equals_rosbags_reading(sample_bags, kind, monkeypatch):
    """Uncompressed sqlite3 storage is read by wmrid's own reader (every storage file of the recording); the log is
    rosbags' message-by-message reading, bit for bit."""
    own, theirs, plans = _read_both_ways(sample_bags[kind], monkeypatch)
    assert plans
    assert all(plan is not None for plan in plans), "wmrid's sqlite3 reading was not used"
    assert sum(len(recording) for recording in plans[0]) == (2 if kind == "db3-split" else 1)
    for field in ("t", "eta", "tau"):
        assert np.array_equal(getattr(own, field), getattr(theirs, field)), field
    assert own.notes == theirs.notes


def test_sqlite_reading_of_two_topics_and_of_overlapping_recordings(tmp_path, monkeypatch):
    """Two topics in one file (speeds in a JointState, currents in a vendor message) are read by wmrid's queries;
    the same topics given as two recordings that overlap in time go to rosbags, which merges them by time.  All
    three give the same log."""
    messages = bagutil.as_wheel_and_motor(bagutil.recording(SAMPLE))[:4000]  # 2 s of both topics
    store = bagutil.motor_store()
    one = bagutil.write_rosbag2(tmp_path / "one", messages, store=store)
    wheel = bagutil.write_rosbag2(tmp_path / "wheel", [m for m in messages if m.topic == "/wheel_state"], store=store)
    motor = bagutil.write_rosbag2(tmp_path / "motor", [m for m in messages if m.topic == "/motor_state"], store=store)
    options = {"columns": VENDOR_COLUMNS, "effort": "current", "torque_constant": 1.0, "gear_ratio": 1.0}
    own, theirs, plans = _read_both_ways([one], monkeypatch, **options)
    assert plans
    assert all(plan is not None and len(plan[0][0].topics) == 2 for plan in plans)
    overlapping, _, overlap_plans = _read_both_ways([wheel, motor], monkeypatch, **options)
    assert overlap_plans
    assert all(plan is None for plan in overlap_plans), "overlapping recordings must be merged"
    for field in ("t", "eta", "tau"):
        assert np.array_equal(getattr(own, field), getattr(theirs, field)), field
        assert np.array_equal(getattr(overlapping, field), getattr(own, field)), field


@pytest.mark.parametrize("kind", ["ros1-two-files", "db3-split"])
def test_inspect_shows_a_bag_recording(sample_bags, kind):
    out = wmrid("inspect", *map(str, sample_bags[kind]), "--format", "json")
    assert out.returncode == 0, text(out).stderr
    info = json.loads(out.stdout)
    assert info["format"] == ("ros1 bag" if kind.startswith("ros1") else "ros2 bag")
    (topic,) = info["topics"]
    assert topic["topic"] == "/joint_states"
    assert topic["messages"] == 40001
    assert sorted(topic["joints"]) == ["left_wheel_joint", "right_wheel_joint"]
    assert topic["fields"]["velocity"] == "yes"
    assert round(topic["rate_hz"]) == 1000
    table = text(wmrid("inspect", *map(str, sample_bags[kind]), "--format", "table", columns="160"))
    assert ("ROS 1 bag" if kind.startswith("ros1") else "ROS 2 bag") in table.stdout
    assert "right_wheel_joint" in table.stdout


@pytest.mark.skipif(not ME169.exists(), reason="../shared/real_logs is not beside the checkout")
def test_the_real_me169_bag_in_every_format_identifies_the_same(tmp_path):
    """A real recording (50 Hz, speed and PWM on two topics) converted to each format: the same parameters (the
    docs/how-to/ros-bags.md claims it, so it runs by default: about 3 s)."""
    formats = _formats(tmp_path, bagutil.recording(ME169))
    reference = _identify([ME169], *ME169_OPTIONS)
    for kind in ("ros1", "db3-file", "db3-split", "ros1-two-files", "mcap-folder", "mcap-split"):
        result = _identify(formats[kind], *ME169_OPTIONS)
        assert result["parameters"] == reference["parameters"], kind
        assert result["warnings"] == reference["warnings"], kind


def test_a_mixed_recording_or_an_empty_folder_is_one_clear_error(tmp_path, sample_bags):
    csv = tmp_path / "a.csv"
    csv.write_text("t,eta_r,eta_l,tau_r,tau_l\n")
    empty = tmp_path / "empty"
    empty.mkdir()
    cases = {
        (str(sample_bags["ros1"][0]), str(sample_bags["db3-file"][0])): "ROS 1 bags and ROS 2 recordings mixed",
        (str(csv), str(csv)): "several files are read as one recording only when they are bags",
        (str(empty),): "a folder with no recording in it",
    }
    for args, needle in cases.items():
        out = text(wmrid("identify", *args))
        assert out.returncode == 2, args
        assert len(out.stderr.strip().splitlines()) == 1, out.stderr
        assert needle in out.stderr, out.stderr


def test_the_same_bag_given_twice_is_refused_by_name(sample_bags, tmp_path):
    """Its messages would count twice (the time steps of 0 then refused far from the cause): one line naming both."""
    bag = sample_bags["ros1"][0]
    link = tmp_path / "again.bag"
    link.symlink_to(bag)
    for second in (bag, link):
        out = text(wmrid("identify", bag, second, "--format", "json"))
        assert out.returncode == 2
        expected = f"wmrid: error: {second}: the same file as {bag}; give each file of the recording once"
        assert out.stderr.strip() == expected


def test_a_ros1_bag_cut_short_is_read_up_to_its_last_whole_record(tmp_path, sample_bags):
    """As an MCAP cut by a crash: the messages before the cut, and a note saying how many bytes were lost."""
    data = sample_bags["ros1"][0].read_bytes()
    cut = tmp_path / "cut.bag"
    cut.write_bytes(data[: len(data) // 2])
    log = read_log(str(cut))
    whole = read_log(str(SAMPLE))
    assert 15_000 < len(log) < 25_000
    assert np.array_equal(log.eta, whole.eta[: len(log)])
    assert any("it was cut short" in n and "bytes at the end are lost" in n for n in log.notes), log.notes
    garbage = tmp_path / "garbage.bag"
    garbage.write_bytes(b"#ROSBAG V2.0\n" + bytes(64))
    out = text(wmrid("identify", str(garbage)))
    assert out.returncode == 2
    assert "JointState" in out.stderr


def test_a_ros1_bags_pages_are_handed_back_as_it_is_walked(sample_bags, monkeypatch):
    """The mapped file's pages leave the resident memory as the walk passes them (as the MCAP reader's do): an
    hour's ROS 1 bag peaked at 1.03 GB before, 0.47 GB after (bench/speed/bench_bags.py --duration 3600, /usr/bin/time).
    Here: the release is asked for past every chunk, up to the file's end, and the log is unchanged."""
    from wmrid.io.bag import ros1_file

    path = sample_bags["ros1"][0]
    asked: list[int] = []
    real = ros1_file.page_releaser

    def recording(mapped):
        release = real(mapped)
        assert release is not None, "this platform cannot hand pages back"

        def wrapped(offset: int) -> None:
            asked.append(offset)
            release(offset)

        return wrapped

    monkeypatch.setattr(ros1_file, "page_releaser", recording)
    log = read_log(str(path))
    assert asked == sorted(asked)
    assert len(asked) >= 5  # one per chunk (8 in this bag) and the end
    assert asked[-1] >= path.stat().st_size - 4096
    reference = read_log(str(SAMPLE))
    assert np.array_equal(log.eta, reference.eta)
    assert np.array_equal(log.tau, reference.tau)


def test_columns_are_refused_for_a_bag_with_the_options_that_apply(sample_bags):
    out = text(wmrid("identify", str(sample_bags["ros1"][0]), "--columns", "t=a,eta_r=b,eta_l=c,tau_r=d,tau_l=e"))
    assert out.returncode == 2
    assert "--velocity-topic" in out.stderr


def test_the_library_reads_several_files_as_one_log_and_leaves_them_as_they_were(sample_bags):
    import hashlib

    import wmrid as api

    paths = sample_bags["ros1-two-files"]
    before = [hashlib.sha256(p.read_bytes()).hexdigest() for p in paths]
    log = api.read_log([str(p) for p in paths])
    assert len(log) == 40001
    assert np.array_equal(log.eta, read_log(str(SAMPLE)).eta)
    assert [hashlib.sha256(p.read_bytes()).hexdigest() for p in paths] == before


def test_split_ros1_bags_given_in_any_order_are_read_in_time_order(sample_bags, sample_result):
    """Bags are ordered by their first message (the chunk-info records), not by the order they are named in."""
    later_first = list(reversed(sample_bags["ros1-two-files"]))
    assert _identify(later_first)["parameters"] == sample_result["parameters"]


def test_other_topics_of_a_ros1_bag_are_listed_with_their_counts(tmp_path):
    """A bag with a JointState topic and another type: the other is counted and listed, not decoded."""
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    ros1 = get_typestore(Stores.ROS1_NOETIC)
    messages = bagutil.recording(SAMPLE)[:500]
    path = bagutil.write_ros1(tmp_path / "a.bag", messages)
    extra = tmp_path / "b.bag"
    string = ros1.types["std_msgs/msg/String"]
    with Writer(extra) as writer:
        conn = writer.add_connection("/chatter", "std_msgs/msg/String", typestore=ros1)
        for i, m in enumerate(messages[:40]):
            writer.write(conn, m.log_ns + 1, ros1.serialize_ros1(string(data=f"hello {i}"), "std_msgs/msg/String"))
    info = json.loads(wmrid("inspect", str(path), str(extra), "--format", "json").stdout)
    by_topic = {t["topic"]: t for t in info["topics"]}
    assert by_topic["/chatter"]["messages"] == 40
    assert by_topic["/chatter"]["type"] == "std_msgs/msg/String"
    assert by_topic["/joint_states"]["messages"] == 500


#: Seconds of the sample the DynamicJointState and vendor-message bags hold.  Those are read message by message in
#: Python (field paths: about 0.1 ms a message, 3 s for the whole sample's two topics, read four times by one test),
#: and what their tests check is that each gives exactly the log and the parameters of the JointState recording of
#: the same messages, whatever its length: its first 10 s (10,001 messages a topic, over a reading batch) suffice.
SHORT_S = 10


@pytest.fixture(scope="module")
def short_messages() -> list[bagutil.Message]:
    """The sample's JointState messages of its first SHORT_S seconds."""
    messages = bagutil.recording(SAMPLE)
    return [m for m in messages if m.log_ns - messages[0].log_ns <= SHORT_S * 1_000_000_000]


@pytest.fixture(scope="module")
def short_sample(tmp_path_factory, short_messages) -> tuple[Path, dict]:
    """Those messages as an MCAP file (a rosbag2 folder's, read by wmrid's MCAP reader), and its identification:
    what the bags of the same messages in other message types must give."""
    path = bagutil.write_rosbag2(tmp_path_factory.mktemp("short") / "mcapdir", short_messages, "mcap") / "mcapdir.mcap"
    return path, _identify([path])


@pytest.fixture(scope="module")
def dynamic_bags(tmp_path_factory, short_messages):
    """The sample (its first SHORT_S seconds) as ros2_control's DynamicJointState (/dynamic_joint_states), in a db3
    folder and an MCAP file, with an 'effort' interface, and in a db3 folder with a 'current' one instead."""
    folder = tmp_path_factory.mktemp("dynamic")
    messages = short_messages
    store = bagutil.dynamic_store()
    effort = bagutil.as_dynamic(messages)
    return {
        "db3": bagutil.write_rosbag2(folder / "db3", effort, store=store),
        "mcap": bagutil.write_rosbag2(folder / "mcapdir", effort, "mcap", store=store) / "mcapdir.mcap",
        "current": bagutil.write_rosbag2(folder / "current", bagutil.as_dynamic(messages, "current"), store=store),
    }


def test_dynamic_joint_state_is_read_like_a_joint_state(dynamic_bags, short_sample):
    """The issue's "done when": a ros2_control DynamicJointState bag identifies, with no option, to the
    parameters of the JointState recording it holds; the MCAP file (through wmrid's MCAP reader) gives the same
    log, sample for sample."""
    sample, sample_result = short_sample
    result = _identify([dynamic_bags["db3"]])
    assert result["parameters"] == sample_result["parameters"]
    assert any("DynamicJointState (ros2_control), read like a JointState" in n for n in result["log"]["notes"])
    reference = read_log(str(sample))
    log = read_log(str(dynamic_bags["mcap"]))
    assert np.array_equal(log.eta, reference.eta)
    assert np.array_equal(log.tau, reference.tau)
    assert any("DynamicJointState (ros2_control)" in n for n in log.notes)


def test_a_current_interface_stands_for_the_effort(dynamic_bags, short_sample):
    """Interfaces position, velocity, current: the current is the effort, converted by --effort current (here
    with k_t = k_r = 1, so the same numbers as the torque)."""
    options = ("--effort", "current", "--torque-constant", "1", "--gear-ratio", "1")
    result = _identify([dynamic_bags["current"]], *options)
    assert result["parameters"] == short_sample[1]["parameters"]
    assert any("its 'current' interface is read as the effort" in n for n in result["log"]["notes"])


VENDOR_COLUMNS = (
    "eta_r=/wheel_state:velocity@right_wheel_joint,eta_l=/wheel_state:velocity@left_wheel_joint,"
    "tau_r=/motor_state:right.current,tau_l=/motor_state:left.current"
)
AS_TORQUE = ("--effort", "current", "--torque-constant", "1", "--gear-ratio", "1")


@pytest.fixture(scope="module")
def vendor_bags(tmp_path_factory, short_messages):
    """Speeds in a JointState (/wheel_state), currents in a vendor message (/motor_state, acme_msgs/MotorState):
    a db3 folder, an MCAP file and a ROS 1 bag, each with the message definitions stored (the sample's first SHORT_S
    seconds)."""
    folder = tmp_path_factory.mktemp("vendor")
    messages = bagutil.as_wheel_and_motor(short_messages)
    store = bagutil.motor_store()
    return {
        "db3": bagutil.write_rosbag2(folder / "db3", messages, store=store),
        "mcap": bagutil.write_rosbag2(folder / "mcapdir", messages, "mcap", store=store) / "mcapdir.mcap",
        "ros1": bagutil.write_ros1_wheel_and_motor(folder / "vendor.bag", messages),
    }


def test_signals_by_field_path_from_a_vendor_message(vendor_bags, short_sample):
    """The issue's "done when": speeds in one message type, currents in another, identified with documented
    options (--columns with TOPIC:FIELD paths); the efforts put on the speeds' stamps (the same stamps here, so
    the figures are the sample's exactly).  The MCAP file and the ROS 1 bag give the db3's log, sample for
    sample and note for note."""
    result = _identify([vendor_bags["db3"]], "--columns", VENDOR_COLUMNS, *AS_TORQUE)
    assert result["parameters"] == short_sample[1]["parameters"]
    notes = " | ".join(result["log"]["notes"])
    assert "wheel signals read by field path (effort /motor_state:right.current" in notes
    assert "speed read from /wheel_state, effort from /motor_state" in notes
    import wmrid as api

    options = {"columns": VENDOR_COLUMNS, "effort": "current", "torque_constant": 1.0, "gear_ratio": 1.0}
    reference = api.read_log(str(vendor_bags["db3"]), **options)
    for kind in ("mcap", "ros1"):
        log = api.read_log(str(vendor_bags[kind]), **options)
        assert np.array_equal(log.t, reference.t), kind
        assert np.array_equal(log.eta, reference.eta), kind
        assert np.array_equal(log.tau, reference.tau), kind
        assert log.notes == reference.notes, kind


def test_a_dynamic_joint_state_by_field_path(dynamic_bags, short_sample):
    """ros2_control's interfaces reached by path: interface_values@JOINT.values@INTERFACE."""
    columns = ",".join(
        f"{key}=/dynamic_joint_states:interface_values@{side}_wheel_joint.values@{interface}"
        for key, side, interface in (("eta_r", "right", "velocity"), ("eta_l", "left", "velocity"),
                                     ("tau_r", "right", "effort"), ("tau_l", "left", "effort"))
    )  # fmt: skip
    result = _identify([dynamic_bags["db3"]], "--columns", columns)
    assert result["parameters"] == short_sample[1]["parameters"]


def test_bad_field_paths_are_one_clear_error(vendor_bags):
    bag = str(vendor_bags["db3"])
    cases = {
        "eta_r=/wheel_state:velocity@right_wheel_joint": "needs exactly eta_r, eta_l, tau_r and tau_l",
        VENDOR_COLUMNS.replace("eta_l=/wheel_state", "eta_l=/motor_state"): "both speeds must come from one topic",
        VENDOR_COLUMNS.replace("right.current", "right..current"): 'field@NAME or field@"NAME"',
    }
    for columns, needle in cases.items():
        out = text(wmrid("identify", bag, "--columns", columns, *AS_TORQUE))
        assert out.returncode == 2, columns
        assert needle in out.stderr, out.stderr
    # a path that names nothing: every value NaN, said as such
    out = text(wmrid("identify", bag, "--columns", VENDOR_COLUMNS.replace("right.current", "right.torque"), *AS_TORQUE))
    assert out.returncode == 2
    assert "/motor_state" in out.stderr


def test_inspect_lists_the_numeric_field_paths(vendor_bags, dynamic_bags):
    """inspect shows the paths --columns takes, from the definitions stored in the recording."""
    info = json.loads(wmrid("inspect", str(vendor_bags["ros1"]), "--format", "json").stdout)
    motor = next(t for t in info["topics"] if t["topic"] == "/motor_state")
    assert motor["field_paths"] == [
        f"/motor_state:{side}.{f}" for side in ("left", "right") for f in ("current", "voltage", "temperature")
    ]
    table = text(wmrid("inspect", str(vendor_bags["mcap"]), "--format", "table", columns="160")).stdout
    assert "right.current" in table
    assert "[i] by position" in table  # not eaten as markup
    from wmrid.io.ros.field_paths import numeric_paths

    store = bagutil.dynamic_store()
    assert numeric_paths(store.fielddefs, bagutil.DYNAMIC_JOINT_STATE) == ["interface_values@NAME.values@NAME"]
    assert numeric_paths(store.fielddefs, bagutil.JOINT_STATE) == ["position@NAME", "velocity@NAME", "effort@NAME"]


def test_a_field_path_evaluates_as_documented():
    from types import SimpleNamespace as M

    from wmrid.io.ros.field_paths import parse

    msg = M(name=["a", "b"], velocity=[1.5, 2.5], arr=[7.0], nested=M(x=M(y=3)))
    dynamic = M(joint_names=["j"], interface_values=[M(interface_names=["velocity", "current"], values=[4.0, 5.0])])
    cases = {"velocity@b": 2.5, "arr[0]": 7.0, "nested.x.y": 3.0}
    for path, expected in cases.items():
        assert parse(f"/t:{path}").value(msg) == expected, path
    assert parse("/t:interface_values@j.values@current").value(dynamic) == 5.0
    for missing in ("velocity@c", "arr[3]"):  # absent from this message: NaN
        assert np.isnan(parse(f"/t:{missing}").value(msg)), missing
    from wmrid.io.ros.field_paths import FieldPathError

    for bad in ("nested.z", "name", "nested", "velocity.size", "__class__.__name__", "nested.x.y[0]"):
        with pytest.raises(FieldPathError, match="does not name a number"):  # no field there, or not a number
            parse(f"/t:{bad}").value(msg)
    assert np.isnan(parse("/t:interface_values@j.values@effort").value(dynamic))


def test_a_message_class_s_fields_are_found_once_and_released_with_the_class():
    """The declared fields of a dataclass message are kept per class (every message of a topic shares its class), a
    namespace's without ``__slots__`` are read per message (each may differ), and a class made for one recording is
    not kept alive by wmrid."""
    import dataclasses
    import gc
    import weakref
    from types import SimpleNamespace as M

    from wmrid.io.ros import field_paths

    def made() -> type:
        @dataclasses.dataclass
        class Wheel:
            velocity: float
            __msgtype__: str = "vendor/msg/Wheel"

        return Wheel

    cls = made()
    assert field_paths.message_fields(cls(1.0)) == ("velocity",)
    assert field_paths._CLASS_FIELDS[cls] == ("velocity",)
    assert field_paths.parse("/t:velocity").value(cls(2.5)) == 2.5
    assert field_paths.message_fields(M(a=1)) == ("a",)
    assert field_paths.message_fields(M(b=1)) == ("b",)
    gone = weakref.ref(cls)
    del cls
    gc.collect()
    assert gone() is None


def test_a_name_with_a_dot_or_a_comma_is_given_in_double_quotes():
    from types import SimpleNamespace as M

    from wmrid.core.errors import UsageError
    from wmrid.io.ros.field_paths import parse

    msg = M(name=["base.wheel_r", "wheel,l", "plain"], velocity=[1.0, 2.0, 3.0])
    assert parse('/t:velocity@"base.wheel_r"').value(msg) == 1.0
    assert parse('/t:velocity@"wheel,l"').value(msg) == 2.0
    assert parse('/t:velocity@"plain"').value(msg) == 3.0
    assert np.isnan(parse("/t:velocity@base.wheel_r").value(msg))  # unquoted: the field 'wheel_r' of a number
    mapping = parse_column_mapping('eta_r=/t:velocity@"base.wheel_r",eta_l=/t:velocity@"wheel,l",tau_r="a,b",tau_l=c')
    assert mapping == {"eta_r": '/t:velocity@"base.wheel_r"', "eta_l": '/t:velocity@"wheel,l"', "tau_r": "a,b",
                       "tau_l": "c"}  # fmt: skip
    assert parse_column_mapping('tau_r=cur"r,tau_l=x') == {"tau_r": 'cur"r', "tau_l": "x"}  # a lone quote: a name
    for bad in ('/t:velocity@"open', '/t:velocity@""', '/t:velocity@"a"b'):
        with pytest.raises(UsageError, match="not a field"):
            parse(bad)


def test_joint_names_with_dots_read_by_field_path_from_a_bag(tmp_path):
    """A JointState whose joints are named 'base.right_wheel' and 'base,left_wheel' (6 s of the sample): the field
    paths quote them and give the sample's samples exactly (so its identification)."""
    store = bagutil.motor_store()
    js = store.types[bagutil.JOINT_STATE]
    renamed = []
    for m in bagutil.recording(SAMPLE)[:6000]:
        msg = store.deserialize_cdr(m.cdr, bagutil.JOINT_STATE)
        names = [{"right_wheel_joint": "base.right_wheel", "left_wheel_joint": "base,left_wheel"}[n] for n in msg.name]
        out = js(header=msg.header, name=names, position=msg.position, velocity=msg.velocity, effort=msg.effort)
        renamed.append(bagutil.Message(m.topic, m.msgtype, m.log_ns, bytes(store.serialize_cdr(out, m.msgtype))))
    bag = bagutil.write_ros1(tmp_path / "dotted.bag", renamed)
    columns = ",".join(
        f'{key}=/joint_states:{field}@"base{sep}{side}_wheel"'
        for key, field, sep, side in (("eta_r", "velocity", ".", "right"), ("eta_l", "velocity", ",", "left"),
                                      ("tau_r", "effort", ".", "right"), ("tau_l", "effort", ",", "left"))
    )  # fmt: skip
    log, whole = read_log(str(bag), columns=parse_column_mapping(columns)), read_log(str(SAMPLE))
    for field in ("t", "eta", "tau"):
        assert np.array_equal(getattr(log, field), getattr(whole, field)[:6000]), field
    assert _identify([bag], "--columns", columns)["log"]["samples"] == 6000


def test_formats_are_found_by_magic_bytes_and_an_unknown_one_lists_the_supported(tmp_path, sample_bags):
    """A ROS 1 bag named .csv or with no suffix is read as a bag; a binary file of no known format is refused
    with the list of what wmrid reads."""
    for name in ("run.csv", "run"):
        disguised = tmp_path / name
        disguised.write_bytes(sample_bags["ros1"][0].read_bytes())
        assert len(read_log(str(disguised))) == 40001
    unknown = tmp_path / "blob.dat"
    unknown.write_bytes(b"\x7fELF\x02\x01\x01\x00" + bytes(64))
    out = text(wmrid("identify", str(unknown)))
    assert out.returncode == 2
    assert "a ROS 1 bag, a ROS 2 .db3 bag or a rosbag2 folder" in out.stderr
    assert "MCAP" in out.stderr


def test_a_damaged_ros2_recording_is_one_line_not_an_internal_error(tmp_path, sample_bags):
    """A db3 whose message rows were overwritten: rosbags fails while reading; wmrid says the recording is
    damaged, naming it."""
    import sqlite3

    folder = tmp_path / "damaged"
    shutil.copytree(sample_bags["db3-folder"][0], folder)
    db = next(folder.glob("*.db3"))
    with sqlite3.connect(db) as con:
        con.execute("UPDATE topics SET name = CAST(X'F1F2' AS TEXT) WHERE id = 1")
    out = text(wmrid("identify", str(folder)))
    assert out.returncode == 2
    assert len(out.stderr.strip().splitlines()) == 1, out.stderr
    assert "internal error" not in out.stderr


def test_other_topics_of_a_db3_are_counted_in_the_same_pass(tmp_path, monkeypatch):
    """A db3 with a JointState topic and another type: wmrid's reader counts the other topic (and its time range) in
    the pass that reads the JointState bytes; `inspect` says what it says when rosbags reads the file, and also the
    other topic's time range and rate (rosbags' counts come without them)."""
    from rosbags.typesys import Stores, get_typestore

    from wmrid.io.bag import db3_file

    store = get_typestore(Stores.ROS2_HUMBLE)
    string = store.types["std_msgs/msg/String"]
    joints = bagutil.recording(SAMPLE)[:500]
    chatter = [
        bagutil.Message("/chatter", "std_msgs/msg/String", m.log_ns + 1,
                        bytes(store.serialize_cdr(string(data=f"hello {i}"), "std_msgs/msg/String")))
        for i, m in enumerate(joints[:40])
    ]  # fmt: skip
    folder = bagutil.write_rosbag2(tmp_path / "two", sorted(joints + chatter, key=lambda m: m.log_ns), store=store)
    assert db3_file.db3_files([str(folder)]) is not None, "wmrid's reader must take this recording"
    own = json.loads(wmrid("inspect", str(folder), "--format", "json").stdout)
    monkeypatch.setattr(db3_file, "db3_files", lambda paths: None)
    theirs = json.loads(wmrid("inspect", str(folder), "--format", "json").stdout)
    by_topic = {t["topic"]: t for t in own["topics"]}
    assert by_topic["/chatter"]["messages"] == 40
    assert by_topic["/chatter"]["type"] == "std_msgs/msg/String"
    assert by_topic["/joint_states"]["messages"] == 500
    same = ("topic", "type", "encoding", "messages")
    assert [{k: t[k] for k in same} for t in own["topics"]] == [{k: t[k] for k in same} for t in theirs["topics"]]
    assert by_topic["/chatter"]["start_s"] == chatter[0].log_ns * 1e-9
    assert by_topic["/chatter"]["end_s"] == chatter[-1].log_ns * 1e-9
    assert by_topic["/chatter"]["rate_hz"] == pytest.approx(39 / ((chatter[-1].log_ns - chatter[0].log_ns) * 1e-9))


@pytest.mark.parametrize("damage", ["cut short", "pages overwritten"])
def test_a_db3_damaged_inside_its_messages_is_one_line(tmp_path, sample_bags, damage):
    """A .db3 cut in half, or with its message pages overwritten, fails inside wmrid's own reading: one line that
    names the file and says it is damaged (rc 2), never a traceback."""
    folder = tmp_path / "damaged"
    shutil.copytree(sample_bags["db3-folder"][0], folder)
    db = next(folder.glob("*.db3"))
    data = bytearray(db.read_bytes())
    if damage == "cut short":
        data = data[: len(data) // 2]
    else:
        data[len(data) // 3 : len(data) // 3 + 200_000] = b"\xa5" * 200_000
    db.write_bytes(bytes(data))
    out = text(wmrid("identify", str(folder)))
    assert out.returncode == 2, out.stderr
    assert len(out.stderr.strip().splitlines()) == 1, out.stderr
    assert "damaged" in out.stderr, out.stderr
    assert str(folder) in out.stderr, out.stderr
    assert "Traceback" not in out.stderr
    assert "internal error" not in out.stderr


def test_a_db3_under_a_path_with_uri_characters(tmp_path, sample_bags, sample_result):
    """The file is opened by an SQLite URI: '#', '?', '%' and spaces in its folder's name are quoted, not read as
    URI syntax."""
    folder = tmp_path / "run #1 ?x=%20 done"
    shutil.copytree(sample_bags["db3-folder"][0], folder)
    assert _identify([folder])["parameters"] == sample_result["parameters"]
