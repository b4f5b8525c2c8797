"""A structure-aware fuzzer of MCAP framing (issue 13): record lengths, chunk sizes and the lengths inside chunks
mutated to edge values (0, a few bytes, 2^31, 2^32 - 1, 2^63 - 1, 2^63, 2^64 - 1, off by one, random u64).

Every mutated file must read to a result or a WmridError (one clear line), never another exception, a hang or a
segfault (a length near 2^63 used to overflow the compiled scanner's bounds check).  The default run tries
WMRID_FUZZ_EXAMPLES examples (default 150, about 3 s); ``python bench/fuzz/fuzz_mcap.py --seconds 600`` runs it for
ten minutes in fresh processes, so that a segfault is counted rather than ending the run.
"""

from __future__ import annotations

import os
import struct

import pytest
from hypothesis import HealthCheck, given, settings, strategies as st

from wmrid.core.errors import WmridError
from wmrid.io.logs import read_log
from wmrid.io.mcap.reader import read_mcap
from wmrid.io.mcap.writer import write_joint_state_mcap
from wmrid.model.robot import BUILTIN_ROBOTS
from wmrid.sim.simulate import simulate

EXAMPLES = int(os.environ.get("WMRID_FUZZ_EXAMPLES", "150"))
MAGIC_LEN = 8
OP_CHUNK = 0x06
EDGES = (0, 1, 8, 9, 21, 22, 2**31 - 1, 2**31, 2**32 - 1, 2**32, 2**62, 2**63 - 9, 2**63 - 1, 2**63, 2**64 - 1)


def _records(data: bytes, start: int, end: int) -> list[tuple[int, int, int]]:
    """(offset, opcode, length) of the records framed in data[start:end] (stops at one that runs past end)."""
    out, p = [], start
    while p + 9 <= end:
        (length,) = struct.unpack_from("<Q", data, p + 1)
        out.append((p, data[p], length))
        if length > end - p - 9:
            break
        p += 9 + length
    return out


def length_fields(data: bytes) -> list[tuple[int, str]]:
    """(offset, format) of every length or size field of an MCAP's framing: each top-level record's u64 length;
    in a chunk, uncompressed_size (u64), the compression string's length (u32), the records' byte length (u64),
    and, for an uncompressed chunk, every inner record's u64 length."""
    fields = []
    for p, op, length in _records(data, MAGIC_LEN, len(data)):
        fields.append((p + 1, "<Q"))
        if op != OP_CHUNK or p + 9 + length > len(data):
            continue
        body = p + 9
        fields.append((body + 16, "<Q"))  # uncompressed_size, after the message start and end times
        (name_len,) = struct.unpack_from("<I", data, body + 28)
        fields.append((body + 28, "<I"))
        records_at = body + 32 + name_len
        fields.append((records_at, "<Q"))
        if name_len == 0:
            inner = records_at + 8
            fields.extend((q + 1, "<Q") for q, _, _ in _records(data, inner, p + 9 + length))
    return fields


@pytest.fixture(scope="module")
def seeds(tmp_path_factory) -> dict[str, bytes]:
    robot = BUILTIN_ROBOTS["paper"]
    frame = simulate(robot.reference, robot.nominal, duration=0.3, seed=0).to_frame()
    folder = tmp_path_factory.mktemp("fuzz-mcap")
    out = {}
    for compression in ("", "zstd", "lz4"):
        path = folder / f"seed-{compression or 'none'}.mcap"
        write_joint_state_mcap(path, frame, odom_topic=None, chunk_size=2048, compression=compression)
        out[compression or "none"] = path.read_bytes()
    return out


@st.composite
def framing_edits(draw, data: bytes):
    fields = length_fields(data)
    edits = []
    for _ in range(draw(st.integers(1, 3))):
        offset, fmt = draw(st.sampled_from(fields))
        (old,) = struct.unpack_from(fmt, data, offset)
        top = 2**64 - 1 if fmt == "<Q" else 2**32 - 1
        value = draw(
            st.one_of(st.sampled_from(EDGES), st.integers(max(old - 16, 0), min(old + 16, top)), st.integers(0, top))
        )
        edits.append((offset, fmt, min(value, top)))
    return edits


def apply(data: bytes, edits) -> bytes:
    buf = bytearray(data)
    for offset, fmt, value in edits:
        struct.pack_into(fmt, buf, offset, value)
    return bytes(buf)


def test_length_fields_cover_every_record(seeds):
    """The fuzzer reaches the framing: every top-level record and every record inside an uncompressed chunk."""
    data = seeds["none"]
    fields = {offset for offset, _ in length_fields(data)}
    top = _records(data, MAGIC_LEN, len(data))
    assert all(p + 1 in fields for p, _, _ in top)
    assert len(fields) > 3 * len(top)  # the chunks' own fields and their inner records


@pytest.mark.parametrize("compression", ["none", "zstd", "lz4"])
@settings(max_examples=EXAMPLES, deadline=None, database=None, suppress_health_check=[HealthCheck.too_slow,
          HealthCheck.function_scoped_fixture, HealthCheck.data_too_large])  # fmt: skip
@given(data=st.data())
def test_mutated_framing_reads_or_fails_cleanly(tmp_path, seeds, compression, data):
    seed = seeds[compression]
    mutated = apply(seed, data.draw(framing_edits(seed)))
    path = tmp_path / "fuzz.mcap"
    path.write_bytes(mutated)
    message = ""
    try:
        read_mcap(str(path))
        read_log(str(path))
    except WmridError as err:
        message = str(err).strip()
    assert "\n" not in message
