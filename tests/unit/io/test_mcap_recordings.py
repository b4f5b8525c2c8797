"""Recordings stored as MCAP files -- a rosbag2 folder with MCAP storage, one split over several files, the folder a
crash leaves (no metadata.yaml, the last file cut short), several .mcap files given together -- read by wmrid's own
MCAP walker (wmrid/io/bag/mcap_files.py) instead of rosbags.

The reference is rosbags' message-by-message reading of the same files (the path wmrid took before, and still
takes for files that overlap in time): the log must be the same bit for bit, notes included.  A recording cut short
is the case rosbags refuses and wmrid reads up to its last whole record.  The files' time spans are checked against
the mcap library's own summary (an independent reading of the same files).
"""

from __future__ import annotations

import shutil
from pathlib import Path

import numpy as np
import pytest
from locations import ROOT_DIR

import wmrid as api
from tests import bagutil
from tests.cliutil import text, wmrid
from wmrid.core.errors import LogFormatError
from wmrid.io.bag import mcap_files

ROOT = ROOT_DIR
SAMPLE = ROOT / "sample_logs" / "paper_sinusoid.mcap"
VENDOR_COLUMNS = (
    "eta_r=/wheel_state:velocity@right_wheel_joint,eta_l=/wheel_state:velocity@left_wheel_joint,"
    "tau_r=/motor_state:right.current,tau_l=/motor_state:left.current"
)
VENDOR_OPTIONS = {"columns": VENDOR_COLUMNS, "effort": "current", "torque_constant": 1.0, "gear_ratio": 1.0}


@pytest.fixture(scope="module")
def messages():
    return bagutil.recording(SAMPLE)[:6000]  # 6 s at 1 kHz


@pytest.fixture(scope="module")
def layouts(tmp_path_factory, messages):
    """{layout: the paths given to wmrid} of the 6 s recording."""
    folder = tmp_path_factory.mktemp("mcap_layouts")
    split = bagutil.write_split_rosbag2(folder / "split", messages, "mcap", parts=3)
    bare = folder / "bare"  # what a crash leaves: the storage files, no metadata.yaml
    shutil.copytree(split, bare)
    (bare / "metadata.yaml").unlink()
    files = sorted(split.glob("*.mcap"))
    return {
        "folder": [bagutil.write_rosbag2(folder / "one", messages, "mcap")],
        "split": [split],
        "bare-folder": [bare],
        "files-in-reverse": files[::-1],
    }


def _read_both_ways(paths, monkeypatch, **options):
    """The log of ``paths`` read by wmrid's MCAP walker and by rosbags' generators, and the file lists the walker
    was given (None where it left the recording to rosbags)."""
    plans = []
    real = mcap_files.mcap_files

    def recorded(paths):
        plans.append(real(paths))
        return plans[-1]

    paths = [str(p) for p in paths]
    monkeypatch.setattr(mcap_files, "mcap_files", recorded)
    own = api.read_log(paths, **options)
    monkeypatch.setattr(mcap_files, "mcap_files", lambda paths: None)
    theirs = api.read_log(paths, **options)
    monkeypatch.setattr(mcap_files, "mcap_files", real)
    return own, theirs, plans


@pytest.mark.parametrize("layout", ["folder", "split", "bare-folder", "files-in-reverse"])
def test_mcap_storage_read_by_wmrid_equals_rosbags_reading(layouts, layout, monkeypatch):
    own, theirs, plans = _read_both_ways(layouts[layout], monkeypatch)
    assert plans
    assert all(plan is not None for plan in plans), "wmrid's MCAP walker was not used"
    assert len(plans[0]) == (1 if layout == "folder" else 3)
    assert [Path(p).name for p in plans[0]] == sorted(Path(p).name for p in plans[0]), "files not in time order"
    for field in ("t", "eta", "tau"):
        assert np.array_equal(getattr(own, field), getattr(theirs, field)), field
    assert own.notes == theirs.notes
    assert len(own) == 6000


def test_two_topics_in_split_mcap_files_read_as_rosbags_reads_them(tmp_path, messages, monkeypatch):
    """Speeds in a JointState and currents in a vendor message (its definition taken from the files), split in
    two: the same log as rosbags' reading; the same two topics as two recordings that overlap in time go to rosbags,
    which merges them by time, and give that log too."""
    vendor = bagutil.as_wheel_and_motor(messages[:2000])
    store = bagutil.motor_store()
    split = tmp_path / "split"
    halves = (vendor[: len(vendor) // 2], vendor[len(vendor) // 2 :])
    split.mkdir()
    for i, half in enumerate(halves):
        bagutil.write_rosbag2(tmp_path / f"part{i}", half, "mcap", store=store)
        shutil.move(str(tmp_path / f"part{i}" / f"part{i}.mcap"), str(split / f"run_{i}.mcap"))
    own, theirs, plans = _read_both_ways([split], monkeypatch, **VENDOR_OPTIONS)
    assert plans
    assert all(plan is not None and len(plan) == 2 for plan in plans)
    for field in ("t", "eta", "tau"):
        assert np.array_equal(getattr(own, field), getattr(theirs, field)), field
    assert own.notes == theirs.notes
    wheel = bagutil.write_rosbag2(tmp_path / "wheel", [m for m in vendor if m.topic == "/wheel_state"], "mcap",
                                  store=store)  # fmt: skip
    motor = bagutil.write_rosbag2(tmp_path / "motor", [m for m in vendor if m.topic == "/motor_state"], "mcap",
                                  store=store)  # fmt: skip
    merged, _, merged_plans = _read_both_ways([wheel, motor], monkeypatch, **VENDOR_OPTIONS)
    assert merged_plans
    assert all(plan is None for plan in merged_plans), "overlapping files must be merged by rosbags"
    for field in ("t", "eta", "tau"):
        assert np.array_equal(getattr(merged, field), getattr(own, field)), field


@pytest.fixture(scope="module")
def long_split(tmp_path_factory):
    """The whole 40 s sample split in two MCAP files (each of several chunks)."""
    return bagutil.write_split_rosbag2(tmp_path_factory.mktemp("long") / "run", bagutil.recording(SAMPLE), "mcap")


@pytest.mark.parametrize("metadata", [True, False])
def test_a_recording_whose_last_file_was_cut_short_is_read_up_to_its_last_whole_record(
    long_split, metadata, tmp_path, monkeypatch
):
    """A crash cuts the last file of a recording (and may leave no metadata.yaml): rosbags refuses the whole
    recording; wmrid reads every file, the last up to its last whole record, and a note names that file and the
    bytes lost."""
    folder = tmp_path / "crashed"
    shutil.copytree(long_split, folder)
    if not metadata:
        (folder / "metadata.yaml").unlink()
    last = sorted(folder.glob("*.mcap"))[-1]
    data = last.read_bytes()
    last.write_bytes(data[: len(data) * 3 // 5])
    whole = api.read_log(str(SAMPLE))
    log = api.read_log(str(folder))
    assert 20_000 < len(log) < 40_000
    for field in ("t", "eta", "tau"):
        assert np.array_equal(getattr(log, field), getattr(whole, field)[: len(log)]), field
    (cut,) = [n for n in log.notes if "it was cut short" in n]
    assert cut.startswith(str(last)), cut
    assert "bytes at the end are lost" in cut
    monkeypatch.setattr(mcap_files, "mcap_files", lambda paths: None)
    with pytest.raises(LogFormatError, match="rosbags cannot open"):
        api.read_log(str(folder))
    monkeypatch.undo()
    out = text(wmrid("identify", str(folder), "--robot", "paper"))
    assert out.returncode == 0, out.stderr
    shown = text(wmrid("inspect", str(folder), "--format", "json"))
    assert shown.returncode == 0, shown.stderr
    assert f'"messages": {len(log)}' in shown.stdout


def test_file_spans_equal_the_mcap_librarys_summary(layouts, messages, tmp_path):
    """:func:`mcap_span` (top-level records only) against the statistics the mcap library reads from each file's
    summary; an unchunked file and a file with no message; a file that is not MCAP."""
    from mcap.reader import make_reader
    from mcap.writer import Writer

    for path in sorted(layouts["split"][0].glob("*.mcap")):
        with open(path, "rb") as fh:
            stats = make_reader(fh).get_summary().statistics
        assert mcap_files.mcap_span(str(path)) == (stats.message_start_time, stats.message_end_time), path
    flat = tmp_path / "flat.mcap"
    with open(flat, "wb") as fh:
        writer = Writer(fh, use_chunking=False)
        writer.start("ros2", "test")
        schema = writer.register_schema("std_msgs/msg/Empty", "ros2msg", b"")
        channel = writer.register_channel("/tick", "cdr", schema)
        for t in (30, 10, 20):
            writer.add_message(channel, log_time=t, data=b"\x00\x01\x00\x00", publish_time=t)
        writer.finish()
    assert mcap_files.mcap_span(str(flat)) == (10, 30)
    empty = tmp_path / "empty.mcap"
    with open(empty, "wb") as fh:
        writer = Writer(fh)
        writer.start("ros2", "test")
        writer.finish()
    assert mcap_files.mcap_span(str(empty)) == (None, None)
    other = tmp_path / "other.mcap"
    other.write_bytes(b"not an mcap file at all")
    assert mcap_files.mcap_span(str(other)) is None
    assert mcap_files.mcap_files([str(other)]) is None


def test_a_topic_of_another_type_in_a_later_file_is_skipped_with_a_note(tmp_path, messages):
    """The recording's first file has /joint_states as a JointState; the second has /joint_states as a vendor
    message: those messages are skipped, and a note names the file, the topic and both types."""
    first, later = messages[:1000], bagutil.as_wheel_and_motor(messages[1000:2000])
    renamed = [bagutil.Message("/joint_states", m.msgtype, m.log_ns, m.cdr) for m in later if m.topic == "/motor_state"]
    a = bagutil.write_rosbag2(tmp_path / "a", first, "mcap") / "a.mcap"
    b = bagutil.write_rosbag2(tmp_path / "b", renamed, "mcap", store=bagutil.motor_store()) / "b.mcap"
    log = api.read_log([str(b), str(a)])
    whole = api.read_log(str(SAMPLE))
    assert len(log) == 1000
    assert np.array_equal(log.eta, whole.eta[:1000])
    (note,) = [n for n in log.notes if "besides" in n]
    assert note.startswith(str(b)), note
    assert "acme_msgs/msg/MotorState" in note
    assert "sensor_msgs/msg/JointState" in note


def test_ros1_files_whose_last_was_cut_short_read_likewise(tmp_path):
    """The same crash in a recording of two ROS 1 bags, given in any order: the unclosed bag (no index) is read
    last, up to its last whole record, with a note naming it; in their folder, named ``.bag.active`` as rosbag
    record leaves it, likewise."""
    messages = bagutil.recording(SAMPLE)
    first = bagutil.write_ros1(tmp_path / "run_0.bag", messages[:20_000])
    last = bagutil.write_ros1(tmp_path / "run_1.bag", messages[20_000:])
    data = last.read_bytes()
    last.write_bytes(data[: len(data) * 3 // 5])
    whole = api.read_log(str(SAMPLE))
    log = api.read_log([str(last), str(first)])
    assert 20_000 < len(log) < 40_000
    for field in ("t", "eta", "tau"):
        assert np.array_equal(getattr(log, field), getattr(whole, field)[: len(log)]), field
    (cut,) = [n for n in log.notes if "it was cut short" in n]
    assert cut.startswith(str(last))
    active = tmp_path / "run_1.bag.active"  # the name rosbag record gives the file it is writing
    last.rename(active)
    folder = api.read_log(str(tmp_path))
    for field in ("t", "eta", "tau"):
        assert np.array_equal(getattr(folder, field), getattr(log, field)), field


def test_big_endian_joint_states_in_bags_take_rosbags_deserialiser(tmp_path, messages):
    """JointStates serialised big-endian (which the compiled CDR kernel refuses) in a db3 folder, an MCAP folder and
    a split MCAP folder: every message goes through rosbags' deserialiser (numpy arrays, not lists) and the log is
    the little-endian sample's, bit for bit.  (Before, every such message was dropped: "carries neither wheel
    speeds nor positions".)"""
    store = bagutil.motor_store()
    big = [
        bagutil.Message(m.topic, m.msgtype, m.log_ns,
                        bytes(store.serialize_cdr(store.deserialize_cdr(m.cdr, m.msgtype), m.msgtype,
                                                  little_endian=False)))
        for m in messages[:3000]
    ]  # fmt: skip
    assert big[0].cdr[:2] == b"\x00\x00"  # CDR_BE
    whole = api.read_log(str(SAMPLE))
    for folder in (
        bagutil.write_rosbag2(tmp_path / "db3", big),
        bagutil.write_rosbag2(tmp_path / "mcap", big, "mcap"),
        bagutil.write_split_rosbag2(tmp_path / "split", big, "mcap"),
    ):
        log = api.read_log(str(folder))
        for field in ("t", "eta", "tau"):
            assert np.array_equal(getattr(log, field), getattr(whole, field)[:3000]), (folder.name, field)


def _record_ends(path: Path, op: int | None = None) -> list[int]:
    """The offsets where the top-level records of an MCAP file (those of opcode ``op``) end."""
    from wmrid.io.mcap.records import MAGIC, scan

    buf = np.frombuffer(path.read_bytes(), dtype=np.uint8)
    ops, starts, lengths = np.empty(1 << 16, np.uint8), np.empty(1 << 16, np.int64), np.empty(1 << 16, np.int64)
    n, _ = scan(buf, len(MAGIC), len(buf), ops, starts, lengths)
    return [int(s + length) for o, s, length in zip(ops[:n], starts[:n], lengths[:n], strict=True) if op in (None, o)]


@pytest.mark.parametrize("kind", ["empty", "magic", "half-header"])
def test_a_last_file_the_crash_left_before_its_first_record_is_skipped_with_a_note(long_split, kind, tmp_path):
    """What a power cut right after a split leaves: a third file that is empty, the magic bytes alone, or the magic
    and part of the header record.  The two whole files are read, and a note names the third (rosbags refused the
    whole recording)."""
    from wmrid.io.mcap.records import MAGIC

    folder = tmp_path / "crashed"
    shutil.copytree(long_split, folder)
    (folder / "metadata.yaml").unlink()
    first = sorted(folder.glob("*.mcap"))[0].read_bytes()
    header_end = _record_ends(sorted(folder.glob("*.mcap"))[0])[0]
    stub = {"empty": b"", "magic": MAGIC, "half-header": first[: header_end - 5]}[kind]
    (folder / "run_9.mcap").write_bytes(stub)
    log = api.read_log(str(folder))
    whole = api.read_log(str(SAMPLE))
    for field in ("t", "eta", "tau"):
        assert np.array_equal(getattr(log, field), getattr(whole, field)), field
    (note,) = [n for n in log.notes if "holds no whole MCAP record" in n]
    assert note.startswith(str(folder / "run_9.mcap"))
    assert f"({len(stub)} bytes" in note


def test_a_file_that_ends_between_records_without_its_footer_is_said_to_be_unclosed(long_split, tmp_path):
    """A last file cut exactly after a chunk (no record cut in two): every message before is read, and a note says
    the file was not closed -- in a recording and as a file alone -- instead of saying nothing."""
    from wmrid.io.mcap.reader import UNCLOSED_NOTE

    folder = tmp_path / "crashed"
    shutil.copytree(long_split, folder)
    last = sorted(folder.glob("*.mcap"))[-1]
    from wmrid.io.mcap.records import OP_CHUNK

    chunks = _record_ends(last, OP_CHUNK)
    assert len(chunks) >= 2
    last.write_bytes(last.read_bytes()[: chunks[0]])
    log = api.read_log(str(folder))
    assert any(n == f"{last}: {UNCLOSED_NOTE}" for n in log.notes), log.notes
    assert not any("cut short" in n for n in log.notes)
    alone = api.read_log(str(last))
    assert UNCLOSED_NOTE in alone.notes
    assert UNCLOSED_NOTE not in api.read_log(str(SAMPLE)).notes
    assert 20_000 < len(log) < 40_000


def test_the_span_walk_hands_the_pages_back(long_split, monkeypatch):
    """:func:`mcap_span` asks for the mapped pages it walked past to be released (an unchunked file of 340 MB
    raised the peak memory by 380 MB without it, by 65 MB with it)."""
    asked: list[int] = []
    real = mcap_files.map_file

    def recorded(path, data):
        buf, release = real(path, data)
        assert release is not None

        def wrapped(offset: int) -> None:
            asked.append(offset)
            release(offset)

        return buf, wrapped

    monkeypatch.setattr(mcap_files, "map_file", recorded)
    last = sorted(long_split.glob("*.mcap"))[-1]
    assert mcap_files.mcap_span(str(last))[0] is not None
    assert asked
    assert asked[-1] >= last.stat().st_size - 8


CONFORMANCE = ROOT.parent / "shared" / "real_logs" / "rosbag2_conformance"


@pytest.mark.skipif(not CONFORMANCE.exists(), reason="../shared/real_logs is not beside the checkout")
def test_a_folder_of_overlapping_mcap_files_goes_to_rosbags_and_inspect_counts_its_messages():
    """The rosbag2 conformance bags as one folder: two files span the same instants, so rosbags reads them; its
    counts of the topics come without times, and inspect says so instead of "no messages"."""
    files = sorted(str(p) for p in CONFORMANCE.glob("*.mcap"))
    assert mcap_files.mcap_files(files) is None
    out = text(wmrid("inspect", str(CONFORMANCE), "--format", "table", columns="200"))
    assert out.returncode == 0, out.stderr
    assert "47 messages, times not read" in out.stdout
