"""MCAP's records at the byte level: opcodes, limits, the compiled scanners (record framing, JointState's CDR
fields), chunk decompression with its bomb guard, and the check that a JointState schema is the standard one.

The compiled functions work on a numpy view of the file's bytes; what they cannot decode they report by a status
code, never by reading out of bounds."""

from __future__ import annotations

import io
import struct

import numpy as np

from wmrid.core.errors import LogFormatError
from wmrid.core.jit import COMPILED, kernel

#: A JointState topic whose first message names more joints than this is skipped (a wheel log names a few; 50,000
#: names in a 500 KB file made the per-joint arrays need 14 GB).
MAX_JOINTS = 4096


#: A chunk declaring more than BOMB_FLOOR bytes and more than BOMB_RATIO times its compressed size is skipped
#: unread: a recording's chunks (1-4 MiB of messages) compress 3-20 times; a 366 KB zstd chunk of zeros declaring
#: gigabytes is a bomb.
BOMB_RATIO = 1000


BOMB_FLOOR = 64 << 20


#: Set to 0 to read chunks whose CRC does not match (a file known to be written with wrong CRCs).
CRC_ENV = "WMRID_MCAP_CRC"


MAGIC = b"\x89MCAP0\r\n"


JOINT_STATE = "sensor_msgs/msg/JointState"


JOINT_STATE_NAMES = (JOINT_STATE, "sensor_msgs/JointState")


OP_HEADER = 0x01


OP_FOOTER = 0x02


OP_SCHEMA = 0x03


OP_CHANNEL = 0x04


OP_MESSAGE = 0x05


OP_CHUNK = 0x06


OP_METADATA = 0x0C


OP_DATA_END = 0x0F


STATUS_OK = 0


STATUS_MALFORMED = 1


STATUS_NOT_LE_CDR = 2


@kernel
def _u32(buf, p):
    return np.int64(buf[p]) | (np.int64(buf[p + 1]) << 8) | (np.int64(buf[p + 2]) << 16) | (np.int64(buf[p + 3]) << 24)


@kernel
def _u64(buf, p):
    lo = _u32(buf, p)
    hi = _u32(buf, p + 4)
    return lo | (hi << 32)


@kernel
def scan(buf, start, end, ops, starts, lengths):
    """Walk records (opcode u8, length u64, body) in buf[start:end].

    Fills ops/starts (body offset)/lengths and returns (count, offset after the last complete record).
    Stops early when the arrays are full (the caller grows them and continues from that offset) or
    when a record runs past ``end`` (a truncated file).
    """
    p = start
    n = 0
    cap = ops.shape[0]
    while p + 9 <= end and n < cap:
        length = _u64(buf, p + 1)
        if length < 0 or length > end - p - 9:  # compared without adding: a length near 2^63 would overflow
            break
        ops[n] = buf[p]
        starts[n] = p + 9
        lengths[n] = length
        n += 1
        p += 9 + length
    return n, p


if COMPILED:
    from numba.core import types
    from numba.extending import intrinsic

    @intrinsic
    def _as_float64(typingctx, bits):  # pragma: no cover - compiled
        """The float64 whose IEEE 754 bits are the int64 ``bits``: a move between registers."""

        def codegen(context, builder, signature, args):
            return builder.bitcast(args[0], context.get_value_type(types.float64))

        return types.float64(types.int64), codegen

else:

    def _as_float64(bits):
        """The float64 whose IEEE 754 bits are the int64 ``bits`` (plain Python: numba is not installed)."""
        return struct.unpack("<d", struct.pack("<q", int(bits)))[0]


@kernel
def _f64(buf, p):
    """The little-endian float64 at buf[p] (its bytes as an integer, read as a float: a view of the bytes made an array
    per value, whose reference counting took a sixth of the decode's time)."""
    return _as_float64(_u64(buf, p))


@kernel
def joint_states(buf, starts, lengths, ref, ref_off, stamp, pos, vel, eff, status):
    """Decode JointState CDR payloads buf[starts[i] : starts[i] + lengths[i]] into per-joint arrays.

    ref, ref_off: the reference joint names, concatenated bytes and offsets (K + 1,).
    stamp (n,) int64 header stamp in ns; pos, vel, eff (n, K) float64, NaN where the message lacks the
    joint or the field; status (n,) int8: 0 ok, 1 malformed, 2 not little-endian CDR (for the caller
    to decode another way).
    """
    n = starts.shape[0]
    k_ref = ref_off.shape[0] - 1
    idx = np.empty(k_ref, dtype=np.int64)
    for i in range(n):
        b = starts[i]
        end = b + lengths[i]
        status[i] = STATUS_OK
        for k in range(k_ref):
            pos[i, k] = np.nan
            vel[i, k] = np.nan
            eff[i, k] = np.nan
        if lengths[i] < 16:
            status[i] = STATUS_MALFORMED
            continue
        if buf[b] != 0 or buf[b + 1] != 1:
            status[i] = STATUS_NOT_LE_CDR
            continue
        o = b + 4  # CDR alignment is relative to the payload after the encapsulation header
        sec = _u32(buf, o)
        if sec >= 2**31:
            sec -= 2**32
        nsec = _u32(buf, o + 4)
        stamp[i] = sec * 1_000_000_000 + nsec
        p = 8
        slen = _u32(buf, o + p)
        p += 4 + slen
        p = (p + 3) & ~3
        if o + p + 4 > end:
            status[i] = STATUS_MALFORMED
            continue
        count = _u32(buf, o + p)
        p += 4
        for k in range(k_ref):
            idx[k] = -1
        bad = False
        for j in range(count):
            p = (p + 3) & ~3
            if o + p + 4 > end:
                bad = True
                break
            slen = _u32(buf, o + p)
            p += 4
            if o + p + slen > end or slen < 1:
                bad = True
                break
            name_len = slen - 1  # the length counts the terminating NUL
            for k in range(k_ref):
                a = ref_off[k]
                if ref_off[k + 1] - a != name_len or idx[k] >= 0:
                    continue
                same = True
                for c in range(name_len):
                    if buf[o + p + c] != ref[a + c]:
                        same = False
                        break
                if same:
                    idx[k] = j
            p += slen
        if bad:
            status[i] = STATUS_MALFORMED
            continue
        for which in range(3):
            p = (p + 3) & ~3
            if o + p + 4 > end:
                bad = True
                break
            m = _u32(buf, o + p)
            p += 4
            if m > 0:
                p = (p + 7) & ~7
                if o + p + 8 * m > end:
                    bad = True
                    break
            for k in range(k_ref):
                j = idx[k]
                if j >= 0 and j < m:
                    value = _f64(buf, o + p + 8 * j)
                    if which == 0:
                        pos[i, k] = value
                    elif which == 1:
                        vel[i, k] = value
                    else:
                        eff[i, k] = value
            p += 8 * m
        if bad:
            status[i] = STATUS_MALFORMED


def cdr_joint_names(payload: bytes) -> list[str] | None:
    """The ``name`` array of a standard little-endian CDR JointState, read straight from its bytes; None when the
    message is another encoding or is not a whole JointState (names, then three float64 arrays, then at most 3 bytes
    of padding: what rosbags' deserialiser accepts), for the caller to decode it generically.  (The first message's
    names were decoded by mcap_ros2 or rosbags, whose import and type store cost 0.1-0.2 s of a command's start-up.)"""
    if len(payload) < 16 or payload[0] != 0 or payload[1] != 1:
        return None
    body = memoryview(payload)[4:]  # CDR alignment is relative to the payload after the encapsulation header
    return _joint_names(body, (8 + 4 + int.from_bytes(body[8:12], "little") + 3) & ~3, align=True)


def ros1_joint_names(payload: bytes) -> list[str] | None:
    """The ``name`` array of a standard ROS 1 JointState (after seq, stamp and frame_id), read straight from its
    bytes; None when it is not a whole JointState (names and three float64 arrays, nothing after them)."""
    if len(payload) < 16:
        return None
    body = memoryview(payload)
    return _joint_names(body, 12 + 4 + int.from_bytes(body[12:16], "little"), align=False)


def _joint_names(body: memoryview, p: int, *, align: bool) -> list[str] | None:
    """The names of a JointState whose name array starts at ``p``, checking the three arrays after them (CDR
    ``align``-ed to 4 and 8 bytes, strings ending in one NUL; ROS 1 packed, strings without one)."""
    end = len(body)

    def u32(at: int) -> int:
        return int.from_bytes(body[at : at + 4], "little")

    def aligned(at: int, to: int) -> int:
        return (at + to - 1) & ~(to - 1) if align else at

    if p + 4 > end:
        return None
    count = u32(p)
    p += 4
    if count > (end - p) // 4:  # each name takes at least its length
        return None
    names = []
    for _ in range(count):
        p = aligned(p, 4)
        if p + 4 > end:
            return None
        n = u32(p)
        p += 4
        if p + n > end:
            return None
        name = bytes(body[p : p + n])
        if align:  # a CDR string counts and ends with its NUL
            if n < 1 or name.find(0) != n - 1:
                return None
            name = name[:-1]
        elif 0 in name:
            return None
        try:
            names.append(name.decode("utf-8"))
        except UnicodeDecodeError:
            return None
        p += n
    for _ in range(3):  # position, velocity, effort: float64[]
        p = aligned(p, 4)
        if p + 4 > end:
            return None
        m = u32(p)
        p = aligned(p + 4, 8) if m else p + 4
        p += 8 * m
        if p > end:
            return None
    return names if end - p <= (3 if align else 0) else None


@kernel
def field_stats(values, has_value, has_nonzero, has_nan, has_inf, max_abs):
    """Per column of values (n, K): any non-NaN, any non-NaN non-zero, any NaN, any inf, largest finite |v|."""
    n, k = values.shape
    for i in range(n):
        for j in range(k):
            v = values[i, j]
            if np.isnan(v):
                has_nan[j] = True
                continue
            has_value[j] = True
            if v != 0:
                has_nonzero[j] = True
            if np.isinf(v):
                has_inf[j] = True
            elif abs(v) > max_abs[j]:
                max_abs[j] = abs(v)


POW2 = np.int64(1) << np.arange(63, dtype=np.int64)


#: Buckets of the step histograms (:func:`step_buckets`): 1024 exact ones below 1024 ns, then 512 per octave.
STEP_BUCKETS = 28160


def step_buckets(steps: np.ndarray) -> np.ndarray:
    """Histogram bucket of each positive int64 step: the step itself below 1024, else 512 buckets per octave
    (relative width <= 1/512); buckets are ordered like the steps they hold."""
    length = np.searchsorted(POW2, steps, side="right")  # bit length, exactly
    shift = np.maximum(length - 10, 0)
    return shift * 512 + (steps >> shift)


def bucket_range(bucket: int) -> tuple[int, int]:
    """The steps (lowest, highest, both included) that fall into ``bucket`` of :func:`step_buckets`."""
    if bucket < 1024:
        return bucket, bucket
    shift = bucket // 512 - 1
    mantissa = bucket - shift * 512
    return mantissa << shift, min(((mantissa + 1) << shift) - 1, 2**63 - 1)


def time_span(start_ns: int, end_ns: int) -> str:
    """A chunk's message log-time range for a note: 's1-s2 s' (in seconds of log time)."""
    return f"{start_ns / 1e9:.9g}-{end_ns / 1e9:.9g} s of log time"


def decompress(name: str, compression: str, data: bytes, size: int) -> bytes:
    """A chunk's records: ``data`` decompressed, never more than ``size`` + 1 bytes (its declared size, already
    within the budget), so a chunk that lies about its size cannot make wmrid allocate more."""
    if compression == "":
        return bytes(data)
    if compression == "zstd":
        import zstandard  # zstandard: only a zstd chunk

        with zstandard.ZstdDecompressor().stream_reader(io.BytesIO(data)) as reader:
            return reader.read(size + 1)
    if compression == "lz4":
        import lz4.frame  # lz4: only an lz4 chunk

        return lz4.frame.LZ4FrameDecompressor().decompress(data, max_length=size + 1)
    raise LogFormatError(
        f"{name}: a chunk uses compression {compression!r}, which wmrid cannot read (zstd, lz4 or none); "
        "recompress the file with `mcap convert`"
    )


#: The standard sensor_msgs/msg/JointState fields, in order: the layout the compiled reader decodes.
_JOINT_STATE_FIELDS = (("header", "std_msgs/Header"), ("name", "string[]"), ("position", "float64[]"),
                       ("velocity", "float64[]"), ("effort", "float64[]"))  # fmt: skip


def standard_joint_state(encoding: str, data: bytes) -> bool:
    """Whether a JointState schema (``encoding``, its text ``data``) lists exactly the standard fields in the standard
    order, so the compiled reader may decode it; an IDL or other schema, or other fields, go to the generic one."""
    if encoding != "ros2msg":
        return False
    try:
        text = bytes(data).decode("utf-8")
    except UnicodeDecodeError:
        return False
    fields = []
    for line in text.splitlines():
        if line.startswith("=" * 10):
            break  # the definitions of the types it uses follow
        line = line.split("#", 1)[0].strip()
        parts = line.split()
        if len(parts) < 2 or "=" in line:
            continue  # blank, a comment, or a constant
        kind = {"Header": "std_msgs/Header", "std_msgs/msg/Header": "std_msgs/Header"}.get(parts[0], parts[0])
        fields.append((parts[1], kind))
    return tuple(fields) == _JOINT_STATE_FIELDS
