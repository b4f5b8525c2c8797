"""Damaged and hostile MCAP files (issue 13): lengths that overflow, CRCs, chunks that lie about their size or
exceed the memory budget, records shorter than their header, a JointState schema in another order.  Each gives
the right answer or a note saying what was lost, never a crash, a segfault or unbounded memory."""

from __future__ import annotations

import struct
from pathlib import Path

import numpy as np
import pytest
from mcap.writer import CompressionType
from mcap_ros2.writer import Writer as Ros2Writer

from wmrid.io.logs import read_log
from wmrid.io.mcap.reader import read_mcap
from wmrid.io.mcap.records import standard_joint_state
from wmrid.io.mcap.writer import JOINT_STATE_MSGDEF, write_joint_state_mcap
from wmrid.model.robot import BUILTIN_ROBOTS
from wmrid.sim.simulate import simulate

PAPER = BUILTIN_ROBOTS["paper"]
OP_CHUNK = 0x06
MAGIC_LEN = 8


@pytest.fixture(scope="module")
def sim():
    return simulate(PAPER.cad, PAPER.nominal, duration=3.0)


def _write(path: Path, sim, compression: str = "zstd") -> Path:
    """The simulated log as a JointState MCAP in 64 KiB chunks (several of them)."""
    write_joint_state_mcap(path, sim.to_frame(), compression=compression, odom_topic=None, chunk_size=1 << 16)
    return path


def _write_unchunked(path: Path, sim) -> Path:
    """The same, every message at top level (mcap_ros2's Writer always chunks: given an unchunked mcap Writer)."""
    from mcap.writer import Writer as McapWriter

    with open(path, "wb") as fh:
        writer = Ros2Writer.__new__(Ros2Writer)
        writer._writer = McapWriter(fh, compression=CompressionType.NONE, use_chunking=False)
        writer._encoders, writer._channel_ids, writer._finished = {}, {}, False
        writer._writer.start(profile="ros2", library="wmrid-tests")
        schema = writer.register_msgdef("sensor_msgs/msg/JointState", JOINT_STATE_MSGDEF)
        for i in range(len(sim.t)):
            ns = 10**18 + round(sim.t[i] * 1e9)
            msg = {
                "header": {"stamp": {"sec": ns // 10**9, "nanosec": ns % 10**9}, "frame_id": ""},
                "name": ["right_wheel_joint", "left_wheel_joint"], "position": [], "velocity": list(sim.eta[i]),
                "effort": list(sim.tau[i]),
            }  # fmt: skip
            writer.write_message("/joint_states", schema, msg, log_time=ns, publish_time=ns)
        writer.finish()
    return path


def _records(data: bytes) -> list[tuple[int, int, int]]:
    """(offset, opcode, length) of each top-level record after the magic."""
    out, p = [], MAGIC_LEN
    while p + 9 <= len(data):
        op = data[p]
        (length,) = struct.unpack_from("<Q", data, p + 1)
        out.append((p, op, length))
        if p + 9 + length > len(data):
            break
        p += 9 + length
    return out


def _first_chunk(data: bytes) -> tuple[int, int]:
    return next((p, length) for p, op, length in _records(data) if op == OP_CHUNK)


@pytest.mark.parametrize("length", [2**63 - 1, 2**63 - 9, 2**64 - 1, 2**62])
def test_a_record_length_near_two_to_the_63_is_not_followed(tmp_path, sim, length):
    """A 9-byte change (opcode + length of the first chunk) made the compiled scanner's bounds check overflow and
    read outside the file: a segfault.  Now the record is taken as running past the end: a truncated file, said."""
    data = bytearray(_write(tmp_path / "a.mcap", sim).read_bytes())
    p, _ = _first_chunk(bytes(data))
    struct.pack_into("<Q", data, p + 1, length)
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    contents = read_mcap(str(bad))
    assert any("cut short" in n or "mid-record" in n or "lost" in n for n in contents.notes), contents.notes


def test_a_flipped_bit_in_a_chunk_fails_its_crc(tmp_path, sim):
    """An uncompressed chunk with one bit flipped inside a message: the CRC check skips the chunk, with a note giving
    its size and time range (before, the changed velocity went into the estimate unnoticed)."""
    good = _write(tmp_path / "good.mcap", sim, compression="")
    data = bytearray(good.read_bytes())
    p, length = _first_chunk(bytes(data))
    data[p + 9 + length - 40] ^= 0x10  # inside the chunk's last message payload
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    intact = read_mcap(str(good))
    damaged = read_mcap(str(bad))
    (note,) = [n for n in damaged.notes if "CRC" in n]
    assert "bytes" in note
    assert "s of log time" in note
    count = {c.topic: c.count for c in intact.channels}
    assert sum(c.count for c in damaged.channels) < sum(count.values())


def test_the_crc_check_can_be_switched_off(tmp_path, sim, monkeypatch):
    """WMRID_MCAP_CRC=0 reads a chunk whose CRC does not match (documented for files written with wrong CRCs)."""
    data = bytearray(_write(tmp_path / "good.mcap", sim, compression="").read_bytes())
    p, length = _first_chunk(bytes(data))
    data[p + 9 + length - 40] ^= 0x10
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    monkeypatch.setenv("WMRID_MCAP_CRC", "0")
    assert not [n for n in read_mcap(str(bad)).notes if "CRC" in n]


def test_a_chunk_beyond_the_memory_budget_is_skipped_unread(tmp_path, sim, monkeypatch):
    """Every chunk declares more than a 16 KiB budget: each is skipped before it is decompressed, with a note that
    names the budget and its variable, and the read ends with no data instead of gigabytes of memory."""
    path = _write(tmp_path / "a.mcap", sim)
    monkeypatch.setenv("WMRID_MEMORY_BUDGET", "16K")
    contents = read_mcap(str(path))
    notes = [n for n in contents.notes if "memory budget" in n]
    assert notes
    assert "WMRID_MEMORY_BUDGET" in notes[0]
    assert all(c.count == 0 for c in contents.channels)


def test_a_chunk_that_lies_about_its_size_is_not_decompressed_beyond_it(tmp_path, sim):
    """A zstd chunk whose declared uncompressed size is cut to 100 bytes: decompression stops at 101 bytes and the
    chunk is skipped with a note (a chunk declaring a small size cannot make wmrid allocate a large one)."""
    data = bytearray(_write(tmp_path / "a.mcap", sim).read_bytes())
    p, _ = _first_chunk(bytes(data))
    struct.pack_into("<Q", data, p + 9 + 16, 100)  # message_start_time, message_end_time, then uncompressed_size
    bad = tmp_path / "bad.mcap"
    bad.write_bytes(bytes(data))
    notes = read_mcap(str(bad)).notes
    assert any("not the 100 it declares" in n for n in notes), notes


def test_a_message_record_shorter_than_its_header_is_skipped(tmp_path, sim):
    """An unchunked file whose last message record is cut to 10 bytes (and the file ends there): it was an internal
    error; now the record is skipped with a note, and the messages before it are read."""
    data = _write_unchunked(tmp_path / "u.mcap", sim).read_bytes()
    messages = [(p, length) for p, op, length in _records(data) if op == 0x05]
    p, _ = messages[-1]
    short = data[:p] + bytes([0x05]) + struct.pack("<Q", 10) + data[p + 9 : p + 9 + 10]
    bad = tmp_path / "short.mcap"
    bad.write_bytes(short)
    contents = read_mcap(str(bad))
    assert any("shorter than a message header" in n for n in contents.notes), contents.notes
    assert sum(c.count for c in contents.channels) == len(messages) - 1


REORDERED = """std_msgs/Header header
string[] name
float64[] effort
float64[] velocity
float64[] position
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
"""


def test_schema_field_order_is_checked():
    """The standard definition is recognised (with comments, a Header alias); other orders or an IDL are not."""
    assert standard_joint_state("ros2msg", JOINT_STATE_MSGDEF.encode())
    assert standard_joint_state("ros2msg", b"# comment\nHeader header  # the stamp\nstring[] name\nfloat64[] position\n"
                                b"float64[] velocity\nfloat64[] effort\n")  # fmt: skip
    assert not standard_joint_state("ros2msg", REORDERED.encode())
    assert not standard_joint_state("ros2idl", JOINT_STATE_MSGDEF.encode())


def test_a_joint_state_schema_in_another_order_is_decoded_by_field_name(tmp_path, sim):
    """A sensor_msgs/msg/JointState channel whose schema lists effort before position was decoded in the standard
    order: positions used as efforts, m11 = 0.011 instead of 1.18.  Now it goes to the generic decoder: the wheel
    speeds and efforts read back exactly as written, with a note."""
    path = tmp_path / "reordered.mcap"
    with open(path, "wb") as fh:
        writer = Ros2Writer(fh, compression=CompressionType.ZSTD)
        schema = writer.register_msgdef("sensor_msgs/msg/JointState", REORDERED)
        for i in range(len(sim.t)):
            ns = 10**18 + round(sim.t[i] * 1e9)
            msg = {
                "header": {"stamp": {"sec": ns // 10**9, "nanosec": ns % 10**9}, "frame_id": ""},
                "name": ["right_wheel_joint", "left_wheel_joint"], "effort": list(sim.tau[i]),
                "velocity": list(sim.eta[i]), "position": [0.1 * i, -0.1 * i],
            }  # fmt: skip
            writer.write_message("/joint_states", schema, msg, log_time=ns, publish_time=ns)
        writer.finish()
    log = read_log(str(path))
    np.testing.assert_array_equal(log.eta, sim.eta)
    np.testing.assert_array_equal(log.tau, sim.tau)
    assert any("not the standard one" in n for n in log.notes)


def test_a_zstd_bomb_is_skipped_unread(tmp_path):
    """A chunk of 80 MB of zeros compresses to kilobytes; declaring more than 64 MiB and more than 1000 times its
    compressed size, it is skipped before decompression (a 366 KB file reached 6.3 GB this way), with a note."""
    from mcap.writer import Writer

    path = tmp_path / "bomb.mcap"
    with open(path, "wb") as fh:
        writer = Writer(fh, compression=CompressionType.ZSTD, chunk_size=1 << 30)
        writer.start(profile="", library="wmrid-tests")
        schema = writer.register_schema(name="blob", encoding="", data=b"")
        channel = writer.register_channel(topic="/blob", message_encoding="", schema_id=schema)
        writer.add_message(channel, log_time=1, data=bytes(80 << 20), publish_time=1)
        writer.finish()
    assert path.stat().st_size < 1 << 20
    notes = read_mcap(str(path)).notes
    assert any("1000 times its compressed size" in n for n in notes), notes


def test_a_joint_state_naming_thousands_of_joints_is_skipped(tmp_path):
    """A 500 KB file whose first message names 50,000 joints made the per-joint arrays need 14 GB; a topic naming
    more than MAX_JOINTS joints is skipped with a note."""
    from wmrid.io.mcap.records import MAX_JOINTS

    path = tmp_path / "wide.mcap"
    names = [f"j{i}" for i in range(MAX_JOINTS + 1)]
    with open(path, "wb") as fh:
        writer = Ros2Writer(fh, compression=CompressionType.ZSTD)
        schema = writer.register_msgdef("sensor_msgs/msg/JointState", JOINT_STATE_MSGDEF)
        for i in range(3):
            msg = {"header": {"stamp": {"sec": 1, "nanosec": i}, "frame_id": ""}, "name": names,
                   "position": [], "velocity": [0.0] * len(names), "effort": []}  # fmt: skip
            writer.write_message("/joint_states", schema, msg, log_time=i + 1, publish_time=i + 1)
        writer.finish()
    notes = read_mcap(str(path)).notes
    assert any("more than the 4,096 wmrid decodes" in n for n in notes), notes


def test_deep_json_in_a_json_topic_skips_that_message_only(tmp_path):
    """A JSON message nested 100,000 deep raised RecursionError: an internal error, or (in a chunk) the chunk's good
    messages lost with it.  Now that message is skipped and the others are read."""
    from mcap.writer import Writer

    path = tmp_path / "json.mcap"
    with open(path, "wb") as fh:
        writer = Writer(fh, compression=CompressionType.ZSTD)
        writer.start(profile="", library="wmrid-tests")
        schema = writer.register_schema(name="w", encoding="jsonschema", data=b"{}")
        channel = writer.register_channel(topic="/w", message_encoding="json", schema_id=schema)
        for i in range(50):
            data = ('{"a":' * 100_000 + "1" + "}" * 100_000).encode() if i == 7 else b'{"a": 1.5}'
            writer.add_message(channel, log_time=10**9 + i * 10**6, data=data, publish_time=10**9 + i * 10**6)
        writer.finish()
    contents = read_mcap(str(path), json_fields={"/w": {"a": "a"}})
    series = contents.json["/w"]
    assert len(series.log_ns) == 49
    assert np.all(series.values["a"] == 1.5)
