"""Long MCAP recordings are streamed: the pieces of ``open_log(bag, rows=small)`` join to exactly what the
whole decode gives (t, eta, tau, notes), and identify on the stream equals identify on the whole log.

Every test that reads a log through ``open_log`` runs twice (:func:`second_pass`): with the survey reading the parts
the scan kept (the default for recordings of up to about 70 min), and with ``_MCAP_REPLAY_BYTES = 0``, the file
decoded again on every pass (longer recordings).  The few that never reach ``open_log`` (the scan and the whole
decode alone, which that setting does not reach) run once (:data:`ONE_PASS`).

The reference is :func:`wmrid.io.logs.read_log` with the default piece size, which decodes these small bags
whole (the path tests/unit/io/test_mcap_read.py checks against mcap_ros2's generic decoder); with a small ``rows``
the same bags are over the whole-decode limit and take the streaming path.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pytest
from mcap.writer import CompressionType
from mcap_ros2.writer import Writer as Ros2Writer

from wmrid.core import wheel_log
from wmrid.core.errors import LogFormatError
from wmrid.core.wheel_log import stream_arrays
from wmrid.io.logs import open_log, read_log
from wmrid.io.mcap import log as mcap_log
from wmrid.io.mcap.reader import read_mcap, scan_mcap
from wmrid.io.mcap.records import scan as _scan
from wmrid.io.mcap.writer import JOINT_STATE_MSGDEF, write_joint_state_mcap
from wmrid.io.ros.selection import TopicSelection
from wmrid.io.signals import SignalOptions
from wmrid.model.robot import BUILTIN_ROBOTS
from wmrid.pipeline.identify import identify
from wmrid.sim.simulate import simulate

PAPER = BUILTIN_ROBOTS["paper"]
T0 = 1_700_000_000 * 10**9
NAMES = ["left_wheel_joint", "right_wheel_joint"]


#: For a test that reads no log through ``open_log``: the second pass would run it again unchanged.
ONE_PASS = pytest.mark.parametrize("second_pass", ["replayed"])


@pytest.fixture(autouse=True, params=["replayed", "decoded again"])
def second_pass(request, monkeypatch) -> str:
    if request.param == "decoded again":
        monkeypatch.setattr(mcap_log, "_MCAP_REPLAY_BYTES", 0)
    return request.param


def write_messages(path: Path, messages, compression=CompressionType.ZSTD, chunked=True, chunk_size=16384) -> Path:
    """(topic, log_time_ns, JointState dict) messages, in the order given, by mcap_ros2's own writer."""
    from mcap.writer import Writer as McapWriter

    with open(path, "wb") as fh:
        writer = Ros2Writer.__new__(Ros2Writer)  # mcap_ros2's Writer, set up as its __init__ does, chunking chosen
        writer._writer = McapWriter(fh, compression=compression, use_chunking=chunked, chunk_size=chunk_size)
        writer._encoders, writer._channel_ids, writer._finished = {}, {}, False
        writer._writer.start(profile="ros2", library="wmrid-tests")
        schema = writer.register_msgdef("sensor_msgs/msg/JointState", JOINT_STATE_MSGDEF)
        for topic, log_ns, msg in messages:
            writer.write_message(topic, schema, msg, log_time=log_ns, publish_time=log_ns)
        writer.finish()
    return path


def joint_msg(stamp_ns: int, names, position=(), velocity=(), effort=()) -> dict:
    return {
        "header": {"stamp": {"sec": stamp_ns // 10**9, "nanosec": stamp_ns % 10**9}, "frame_id": "base_link"},
        "name": list(names), "position": list(position), "velocity": list(velocity), "effort": list(effort),
    }  # fmt: skip


def single_topic_messages(n: int = 3000, seed: int = 0, zero_stamps: bool = False) -> list:
    """One topic with what cleaning must get right across piece boundaries: runs of repeated stamps,
    messages without a speed or an effort, joints in either order, an extra joint."""
    rng = np.random.default_rng(seed)
    out = []
    stamp = T0
    for _ in range(n):
        stamp += 0 if rng.random() < 0.08 else int(rng.integers(900_000, 1_100_000))  # repeats, jitter
        names = [*NAMES, "caster"] if rng.random() < 0.5 else ["caster", *NAMES[::-1]]
        values = {name: rng.standard_normal(3) for name in names}
        vel = [values[name][1] for name in names]
        eff = [values[name][2] for name in names]
        if rng.random() < 0.05:
            vel = []
        if rng.random() < 0.05:
            eff = eff[:1]  # the effort of the first joint only
        header = 0 if zero_stamps and rng.random() < 0.01 else stamp
        out.append(("/joint_states", stamp + 200_000, joint_msg(header, names, velocity=vel, effort=eff)))
    return out


def _same(streamed, whole) -> None:
    assert np.array_equal(streamed.t, whole.t)
    assert np.array_equal(streamed.eta, whole.eta)
    assert np.array_equal(streamed.tau, whole.tau)
    assert streamed.notes == whole.notes
    assert streamed.effort_unit == whole.effort_unit


def _streamed(path: Path, rows: int, **kwargs):
    stream = open_log(str(path), rows=rows, **kwargs)
    pieces = list(stream)
    assert hasattr(stream, "_mcap_peak"), "the streaming path was not taken"
    assert all(len(p) == rows for p in pieces[:-1])
    assert 0 < len(pieces[-1]) <= rows
    return stream, stream.read()


@pytest.fixture(scope="module")
def written(tmp_path_factory):
    """``written(name, messages, **options)``: the path of ``messages`` written as :func:`write_messages` does, once per
    module and name (the tests below only read these files, each with several piece sizes and on both passes)."""
    folder = tmp_path_factory.mktemp("written")
    paths: dict[str, Path] = {}

    def write(name: str, messages: Callable[[], list], **options) -> Path:
        if name not in paths:
            paths[name] = write_messages(folder / f"{name}.mcap", messages(), **options)
        return paths[name]

    return write


@pytest.mark.parametrize(
    ("compression", "chunked"),
    [
        (CompressionType.ZSTD, True),
        (CompressionType.LZ4, True),
        (CompressionType.NONE, True),
        (CompressionType.NONE, False),
    ],
    ids=["zstd", "lz4", "uncompressed", "unchunked"],
)
@pytest.mark.parametrize("rows", [7, 333])
def test_single_topic_pieces_join_to_the_whole_decode(written, compression, chunked, rows):
    name = f"one-{compression.name}-{'chunked' if chunked else 'unchunked'}"
    path = written(name, single_topic_messages, compression=compression, chunked=chunked)
    whole = read_log(str(path))
    assert any("messages repeat the previous time stamp" in n for n in whole.notes)
    assert any("without the wheel speed" in n for n in whole.notes)
    assert any("without the wheel effort" in n for n in whole.notes)
    _, streamed = _streamed(path, rows)
    _same(streamed, whole)


def test_single_topic_on_log_time_and_with_signal_options(tmp_path):
    path = write_messages(tmp_path / "zeros.mcap", single_topic_messages(2000, seed=1, zero_stamps=True))
    signals = SignalOptions(speed_unit="rpm", effort="current", torque_constant=0.1, gear_ratio=20, mirror_left=True)
    whole = read_log(str(path), signals=signals)
    assert any("not the header stamps (some are zero)" in n for n in whole.notes)
    assert any("rpm" in n for n in whole.notes)
    _, streamed = _streamed(path, 250, signals=signals)
    _same(streamed, whole)


def test_simulated_bag_streams_the_sample_exactly(tmp_path):
    sim = simulate(PAPER.reference, PAPER.nominal, trajectory="sinusoid", duration=6.0, seed=2)
    path = tmp_path / "sim.mcap"
    write_joint_state_mcap(path, sim.to_frame(), odom_topic=None, chunk_size=1 << 14)
    whole = read_log(str(path))
    for rows in (10, 1000, 1024):
        _, streamed = _streamed(path, rows)
        _same(streamed, whole)


def split_messages(
    n: int = 4000, seed: int = 0, effort_every: int = 2, tail: int = 40, head: int = 30, order: str = "log"
) -> list:
    """Speeds on /wheel_state (1 kHz, jittered stamps) and efforts on /wheel_effort (every ``effort_every``-th
    sample, stamped 0.3 ms later with its own jitter, received 3 ms after its stamp); the efforts start
    ``head`` speed samples late and stop ``tail`` samples early."""
    rng = np.random.default_rng(seed)
    msgs = []
    for i in range(n):
        stamp = T0 + i * 1_000_000 + int(rng.integers(-20_000, 20_000))
        speed = [np.sin(0.01 * i) + 2.0, np.cos(0.013 * i) + 2.0]
        msgs.append(("/wheel_state", stamp + 100_000, joint_msg(stamp, NAMES, velocity=speed)))
        if i % effort_every == 0 and head <= i < n - tail:
            e_stamp = stamp + 300_000 + int(rng.integers(0, 5_000))
            torque = [np.sin(0.02 * i), np.cos(0.017 * i)]
            msgs.append(("/wheel_effort", e_stamp + 3_000_000, joint_msg(e_stamp, NAMES, effort=torque)))
    if order == "log":
        msgs.sort(key=lambda m: m[1])
    return msgs


@pytest.mark.parametrize("rule", ["linear", "zoh"])
@pytest.mark.parametrize("time_source", ["auto", "log"])
@pytest.mark.parametrize("rows", [5, 256])
def test_split_topics_pieces_join_to_the_whole_decode(written, rule, time_source, rows):
    path = written("split", split_messages)
    sel = TopicSelection(
        velocity_topic="/wheel_state", effort_topic="/wheel_effort", align=rule, time_source=time_source
    )
    whole = read_log(str(path), selection=sel)
    assert any("speed samples outside the effort's time span dropped" in n for n in whole.notes)
    _, streamed = _streamed(path, rows, selection=sel)
    _same(streamed, whole)


@pytest.mark.parametrize("rule", ["linear", "zoh"])
def test_split_topics_with_a_lagging_topic_and_exact_periods(tmp_path, rule):
    # efforts written in one block after all speeds (a topic far behind in the file), steps of exactly 2 ms
    msgs = []
    for i in range(3000):
        stamp = T0 + i * 1_000_000
        msgs.append(("/v", stamp, joint_msg(stamp, NAMES, velocity=[np.sin(0.01 * i), 1.0])))
    for i in range(10, 2990, 2):
        stamp = T0 + i * 1_000_000 + 1
        msgs.append(("/e", stamp, joint_msg(stamp, NAMES, effort=[np.cos(0.01 * i), 0.5])))
    path = write_messages(tmp_path / "lag.mcap", msgs, chunk_size=4096)
    sel = TopicSelection(velocity_topic="/v", effort_topic="/e", align=rule)
    whole = read_log(str(path), selection=sel)
    _, streamed = _streamed(path, 100, selection=sel)
    _same(streamed, whole)


def _damaged_bag(tmp_path: Path, where: str) -> tuple[Path, int]:
    sim = simulate(PAPER.reference, PAPER.nominal, trajectory="sinusoid", duration=4.0, seed=3)
    path = tmp_path / "sim.mcap"
    write_joint_state_mcap(path, sim.to_frame(), odom_topic=None, chunk_size=1 << 13)
    data = bytearray(path.read_bytes())
    buf = np.frombuffer(bytes(data), dtype=np.uint8)
    ops, starts, lengths = (np.empty(100_000, dtype=d) for d in (np.uint8, np.int64, np.int64))
    n, _ = _scan(buf, 8, len(buf), ops, starts, lengths)
    chunk = np.flatnonzero(ops[:n] == 0x06)[3]  # the fourth chunk
    if where == "frame":  # the zstd frame's magic number (after 3 u64, a u32 crc, "zstd" and a u64 length)
        at = int(starts[chunk]) + 8 + 8 + 8 + 4 + 4 + 4 + 8
        data[at : at + 4] = b"\0\0\0\0"
    else:  # the compressed records: garbage comes out
        at = int(starts[chunk] + lengths[chunk] // 2)
        data[at : at + 64] = bytes(64)
    path.write_bytes(bytes(data))
    return path, len(sim.t)


def test_a_damaged_chunk_gives_the_same_log_and_notes(tmp_path):
    path, n = _damaged_bag(tmp_path, "frame")
    whole = read_log(str(path))
    assert any("could not be decompressed" in note for note in whole.notes), whole.notes
    assert len(whole) < n
    _, streamed = _streamed(path, 300)
    _same(streamed, whole)


def test_a_chunk_of_garbage_gives_the_whole_decode(tmp_path):
    path, _ = _damaged_bag(tmp_path, "records")
    whole = read_log(str(path))
    stream = open_log(str(path), rows=300)
    log = stream.read()
    if not hasattr(stream, "_mcap_peak"):  # decoded whole (here: the garbage is out of time order)
        assert log.notes[-1].startswith("the recording was decoded whole")
        log = wheel_log.WheelLog(t=log.t, eta=log.eta, tau=log.tau, source=log.source, notes=log.notes[:-1])
    _same(log, whole)


def test_identify_on_the_stream_equals_identify_on_the_whole_log(tmp_path, monkeypatch):
    sim = simulate(PAPER.reference, PAPER.nominal, trajectory="sinusoid", duration=20.0, seed=4)
    path = tmp_path / "sim.mcap"
    write_joint_state_mcap(path, sim.to_frame(), odom_topic=None)
    whole_log = read_log(str(path))
    whole = identify(whole_log, PAPER)
    # pieces of the default size (as the CLI cuts them), the bag streamed as a long one would be
    monkeypatch.setattr(mcap_log, "_MCAP_WHOLE_PIECES", 0)
    stream = open_log(str(path))
    streamed = identify(stream, PAPER)
    assert hasattr(stream, "_mcap_peak")
    assert json.dumps(streamed.to_dict()) == json.dumps(whole.to_dict())  # bit for bit, every figure
    # small pieces, and the replay reading the file a second time
    monkeypatch.setattr(wheel_log, "CACHE_ROWS", 0)
    small = identify(open_log(str(path), rows=4096), PAPER)
    assert json.dumps(small.to_dict()) == json.dumps(identify(stream_arrays(whole_log, 4096), PAPER).to_dict())


def test_the_streaming_path_holds_a_bounded_number_of_messages(tmp_path, second_pass):
    sim = simulate(PAPER.reference, PAPER.nominal, trajectory="sinusoid", duration=30.0, seed=5)
    path = tmp_path / "sim.mcap"
    write_joint_state_mcap(path, sim.to_frame(), odom_topic=None, chunk_size=1 << 15)
    per_chunk = max(read_mcap(str(path)).joints["/joint_states"].log_ns.size // 60, 1)  # messages per chunk, about
    for rows in (500, 2000):
        stream, log = _streamed(path, rows)
        assert len(log) == len(sim.t) == 30_001
        if second_pass == "replayed":  # the scan's parts, let go as they are handed out: never more than the log
            assert 0 < stream._mcap_peak <= len(log) + 2 * rows
            continue
        # decoded at once (a chunk), waiting to be cleaned (a piece), cut into pieces (a piece): never the log
        assert 0 < stream._mcap_peak <= 3 * rows + 4 * per_chunk
        assert stream._mcap_peak < len(log) / 4


def test_within_the_replay_budget_the_file_is_decoded_once(tmp_path, second_pass):
    """The survey's pass reads what the scan kept: the file can be gone by then (and the result is the whole
    decode's).  Decoded again, its absence is an error; either way the replay (second pass) is the same."""
    path = write_messages(tmp_path / "one.mcap", single_topic_messages(3000))
    whole = read_log(str(path))
    stream = open_log(str(path), rows=333)
    gone = tmp_path / "elsewhere.mcap"
    path.rename(gone)
    if second_pass == "decoded again":
        with pytest.raises(LogFormatError, match="cannot be read"):
            list(stream)
        return
    pieces = list(stream)
    assert hasattr(stream, "_mcap_peak")
    _same(stream.read(), whole)
    assert sum(len(p) for p in pieces) == len(whole)


def test_a_short_bag_is_decoded_whole_in_one_pass(tmp_path):
    path = write_messages(tmp_path / "one.mcap", single_topic_messages(500))
    stream = open_log(str(path))
    assert not hasattr(stream, "_mcap_peak")
    assert scan_mcap(str(path), keep=1000).complete
    assert not scan_mcap(str(path), keep=100).complete


@ONE_PASS
def test_summaries_agree_with_the_decoded_series(tmp_path):
    msgs = single_topic_messages(1500, zero_stamps=True) + [m for m in split_messages(1500) if m[0] != "/wheel_state"]
    msgs.sort(key=lambda m: m[1])
    path = write_messages(tmp_path / "mixed.mcap", msgs)
    full = read_mcap(str(path))
    summary = scan_mcap(str(path), keep=10)
    assert not summary.complete
    assert summary.notes == full.notes
    assert summary.channels == full.channels
    assert set(summary.joints) == set(full.joints)
    for topic, series in full.joints.items():
        s = summary.joints[topic]
        assert s.names == series.names
        assert s.count == len(series.log_ns)
        for name in ("position", "velocity", "effort"):
            assert s.populated(name) == series.populated(name), (topic, name)
            for col in range(len(series.names)):
                assert s.any_nonzero(name, [col]) == series.any_nonzero(name, [col])
        for key, values in (("log", series.log_ns), ("header", series.stamp_ns)):
            times = s.times[key]
            assert (times.first, times.last) == (values[0], values[-1])
            assert (times.low, times.high) == (values.min(), values.max())
            assert times.ordered == bool(np.all(np.diff(values) >= 0))
            assert times.all_positive == bool(np.all(values > 0))


def test_messages_out_of_time_order_in_the_file_are_decoded_whole_with_a_note(tmp_path):
    msgs = single_topic_messages(1200, zero_stamps=True)
    msgs[500], msgs[700] = msgs[700], msgs[500]  # log time (the time source) goes back in the file
    path = write_messages(tmp_path / "unordered.mcap", msgs)
    whole = read_log(str(path))
    stream = open_log(str(path), rows=100)
    log = stream.read()
    assert not hasattr(stream, "_mcap_peak")
    assert log.notes[:-1] == whole.notes
    assert log.notes[-1].startswith("the recording was decoded whole")
    assert "not in time order" in log.notes[-1]
    assert np.array_equal(log.t, whole.t)
    assert np.array_equal(log.tau, whole.tau)


def test_speeds_from_positions_are_decoded_whole_with_a_note(tmp_path):
    msgs = []
    for i in range(800):
        stamp = T0 + i * 1_000_000
        pos = [0.002 * i + 0.1 * np.sin(0.01 * i), 0.003 * i]
        msgs.append(("/js", stamp, joint_msg(stamp, NAMES, position=pos, effort=[np.sin(0.02 * i), 0.3])))
    path = write_messages(tmp_path / "positions.mcap", msgs)
    whole = read_log(str(path))
    log = open_log(str(path), rows=50).read()
    assert log.notes[:-1] == whole.notes
    assert "derived from positions" in log.notes[-1]
    assert np.array_equal(log.eta, whole.eta)


def test_split_topics_that_do_not_overlap_fail_as_the_whole_decode_does(tmp_path):
    msgs = []
    for i in range(600):  # speeds over 0..3 s and 9..12 s, efforts over 4..7 s: none inside
        for start, topic, field in ((0, "/v", "velocity"), (9, "/v", "velocity"), (4, "/e", "effort")):
            stamp = T0 + start * 10**9 + i * 5_000_000
            msgs.append((topic, stamp, joint_msg(stamp, NAMES, **{field: [1.0 + np.sin(i), 2.0]})))
    msgs.sort(key=lambda m: m[1])
    path = write_messages(tmp_path / "apart.mcap", msgs)
    sel = TopicSelection(velocity_topic="/v", effort_topic="/e")
    with pytest.raises(LogFormatError, match="do not overlap in time") as whole:
        read_log(str(path), selection=sel)
    stream = open_log(str(path), selection=sel, rows=10)
    with pytest.raises(LogFormatError, match="do not overlap in time") as streamed:
        list(stream)
    assert str(streamed.value) == str(whole.value)


def test_a_file_that_changes_between_passes_is_refused(tmp_path, monkeypatch):
    monkeypatch.setattr(wheel_log, "CACHE_ROWS", 0)
    path = write_messages(tmp_path / "one.mcap", single_topic_messages(1000))
    stream = open_log(str(path), rows=100)
    list(stream)
    write_messages(path, single_topic_messages(900))
    with pytest.raises(LogFormatError, match="changed while it was read"):
        list(stream)


@ONE_PASS
@pytest.mark.parametrize("seed", range(6))
def test_the_median_step_is_exact_from_the_histogram_and_a_second_look(seed):
    from wmrid.io.mcap.records import STEP_BUCKETS, step_buckets
    from wmrid.io.ros.joint_stream import _StepMedian

    rng = np.random.default_rng(seed)
    n = int(rng.integers(1, 5000))
    kind = seed % 3
    if kind == 0:  # a clock with jitter
        steps = 1_000_000 + rng.integers(-30_000, 30_000, n)
    elif kind == 1:  # a few exact values
        steps = rng.choice([999_999, 1_000_000, 1_000_001, 2_000_000], n)
    else:  # anything from 1 ns to minutes
        steps = np.exp(rng.uniform(0, 25, n)).astype(np.int64) + 1
    steps = steps.astype(np.int64)
    median = _StepMedian(np.bincount(step_buckets(steps), minlength=STEP_BUCKETS))
    for part in np.array_split(steps, int(rng.integers(1, 20))):
        median.add(part)
    assert median.value() == float(np.median(steps))


@ONE_PASS
def test_many_joints_a_message_count_against_the_memory_budget_in_bytes(tmp_path, monkeypatch):
    """Few messages of many joints are large: the scan stops keeping them past a quarter of the budget (bytes,
    not only messages), and a whole read beyond the budget is refused by name (a 2.4 MB bag of 4096-joint
    messages reached 5.9 GB with a 1 GB budget before)."""
    names = [f"j{i}" for i in range(600)]
    messages = [("/joint_states", T0 + i * 10**6, joint_msg(T0 + i * 10**6, names, velocity=np.zeros(600)))
                for i in range(300)]  # fmt: skip
    path = write_messages(tmp_path / "wide.mcap", messages)
    monkeypatch.setenv("WMRID_MEMORY_BUDGET", "4M")  # the parts: 300 x 600 joints x 24 B = 4.3 MB
    assert not scan_mcap(str(path), keep=10**6).complete
    with pytest.raises(LogFormatError, match="need more than the memory budget"):
        read_mcap(str(path))
    monkeypatch.setenv("WMRID_MEMORY_BUDGET", "64M")
    assert scan_mcap(str(path), keep=10**6).complete
