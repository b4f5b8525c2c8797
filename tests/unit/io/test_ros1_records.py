"""The compiled ROS 1 JointState reader (wmrid.io.bag.ros1_records) against rosbags' own ROS 1 deserialiser, field for
field: messages serialised by rosbags' typestore, and the same written into ROS 1 bags (plain, bz2 and lz4 chunks)
and read back; then every truncation and random corruption of valid messages, decoded by a copy of the kernel
compiled with bounds checking (a read outside the payload raises) and by the real one inside sentinel bytes.

rosbags' ROS 1 serialiser packs Header.stamp.sec as int32 (a sec of 2**31 or more raises) and its deserialiser reads it
back signed, while ROS 1 time is unsigned: such stamps are written by patching the bytes and compared modulo 2**32.
"""

from __future__ import annotations

import struct
import types

import numba
import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from rosbags.rosbag1 import Reader, Writer
from rosbags.serde import SerdeError
from rosbags.typesys import Stores, get_typestore

from wmrid.io.bag.ros1_records import ros1_joint_states
from wmrid.io.mcap.records import STATUS_MALFORMED, STATUS_OK, _f64, _u32

TS = get_typestore(Stores.ROS1_NOETIC)
JS = "sensor_msgs/msg/JointState"
JointState = TS.types[JS]
Header = TS.types["std_msgs/msg/Header"]
Time = TS.types["builtin_interfaces/msg/Time"]
NS = 1_000_000_000
SENTINEL = 0x7F  # 8 of them read as a float64 are 1.38e306, 4 as a count are 2.1e9
# prefixes of one another, non-ASCII, the empty name: matching goes by the bytes, length included
POOL = ("left_wheel_joint", "right_wheel_joint", "left_wheel", "left_wheel_joint2", "caster_ø", "ведущее_колесо",
        "轮子", "", "a")  # fmt: skip
REF = ("left_wheel_joint", "right_wheel_joint", "ведущее_колесо", "轮子", "", "left_wheel", "absent_joint")


def _ref(names=REF):
    encoded = [n.encode() for n in names]
    ref = np.frombuffer(b"".join(encoded) or b"\0", dtype=np.uint8).copy()
    return ref, np.cumsum([0, *[len(e) for e in encoded]]).astype(np.int64)


def _checked_kernel():
    """The kernel's own code compiled with bounds checking, helpers included: any read outside buf raises."""
    f = ros1_joint_states.py_func
    scope = dict(f.__globals__)
    scope["_u32"] = numba.njit(boundscheck=True)(_u32.py_func)
    scope["_f64"] = numba.njit(boundscheck=True)(_f64.py_func)
    clone = types.FunctionType(f.__code__, scope, f.__name__, f.__defaults__, f.__closure__)
    return numba.njit(boundscheck=True)(clone)


CHECKED = _checked_kernel()


def _run(kernel, buf, starts, lengths, k):
    n = len(starts)
    out = (np.zeros(n, np.int64), np.full((n, k), 1.5), np.full((n, k), 1.5), np.full((n, k), 1.5))
    status = np.full(n, 99, np.int8)
    ref, ref_off = _ref()
    kernel(buf, np.asarray(starts, np.int64), np.asarray(lengths, np.int64), ref, ref_off, *out, status)
    return (*out, status)


def decode(payloads, seed=0):
    """The real kernel on all payloads at once, each between runs of sentinel bytes (a copy of the payload's own
    continuation would be as hostile; :func:`test_truncation_followed_by_the_rest` does that)."""
    rng = np.random.default_rng(seed)
    parts, starts, lengths, at = [], [], [], 0
    for raw in payloads:
        gap = bytes([SENTINEL]) * int(rng.integers(1, 24))
        parts += [gap, bytes(raw)]
        starts.append(at + len(gap))
        lengths.append(len(raw))
        at += len(gap) + len(raw)
    parts.append(bytes([SENTINEL]) * 16)
    buf = np.frombuffer(b"".join(parts), dtype=np.uint8).copy()
    return _run(ros1_joint_states, buf, starts, lengths, len(REF))


def decode_checked(raw):
    """The bounds-checked kernel on one payload that fills its whole buffer."""
    buf = np.frombuffer(bytes(raw), dtype=np.uint8).copy()
    return _run(CHECKED, buf, [0], [len(buf)], len(REF))


def expected(msg):
    """What the kernel must give for a message rosbags decoded: stamp (sec unsigned) and the (3, K) values."""
    names = list(msg.name)
    stamp = (msg.header.stamp.sec % 2**32) * NS + msg.header.stamp.nanosec
    values = np.full((3, len(REF)), np.nan)
    for f, field in enumerate((msg.position, msg.velocity, msg.effort)):
        for k, joint in enumerate(REF):
            if joint in names and names.index(joint) < len(field):
                values[f, k] = field[names.index(joint)]
    return stamp, values


def bits(a):
    return np.asarray(a, np.float64).view(np.uint64)  # compares NaN payloads and the sign of zero too


def assert_row(out, i, msg):
    stamp, pos, vel, eff, status = out
    want_stamp, want = expected(msg)
    assert status[i] == STATUS_OK
    assert stamp[i] == want_stamp
    for f, got in enumerate((pos, vel, eff)):
        np.testing.assert_array_equal(bits(got[i]), bits(want[f]), err_msg=f"message {i}, field {f}")


def assert_decodes_like_rosbags(payloads):
    out = decode(payloads)
    for i, raw in enumerate(payloads):
        assert_row(out, i, TS.deserialize_ros1(raw, JS))
    return out


def make(names, pos=None, vel=None, eff=None, sec=0, nsec=0, frame_id="", seq=0):
    """A serialised JointState; the fields default to as many values as names; sec >= 2**31 is patched in."""
    n = len(names)
    fields = [np.arange(1, n + 1, dtype=np.float64) * s if v is None else np.asarray(v, np.float64)
              for v, s in ((pos, 1.0), (vel, 0.5), (eff, -0.25))]  # fmt: skip
    msg = JointState(header=Header(seq=seq, stamp=Time(sec=sec % 2**31, nanosec=nsec), frame_id=frame_id),
                     name=list(names), position=fields[0], velocity=fields[1], effort=fields[2])  # fmt: skip
    raw = bytearray(TS.serialize_ros1(msg, JS))
    raw[4:8] = struct.pack("<I", sec)
    return bytes(raw)


CASES = {
    "in order": make(["left_wheel_joint", "right_wheel_joint"], sec=1_700_000_000, nsec=123_456_789, frame_id="base"),
    "permuted, extra joints": make(["caster_ø", "right_wheel_joint", "a", "left_wheel_joint"], sec=5, nsec=1),
    "missing joints": make(["right_wheel_joint"], [0.5], [1.5], [2.5]),
    "no joints": make([]),
    "empty velocity and effort": make(["left_wheel_joint", "right_wheel_joint"], [1.0, 2.0], [], []),
    "only effort": make(["left_wheel_joint", "right_wheel_joint"], [], [], [3.0, -4.0]),
    "shorter arrays": make(["left_wheel_joint", "right_wheel_joint", "轮子"], [1.0, 2.0], [7.0], [8.0, 9.0]),
    "longer arrays": make(["right_wheel_joint"], [1.0, 2.0, 3.0], [4.0, 5.0], [6.0, 7.0, 8.0, 9.0]),
    "special values": make(
        ["left_wheel_joint", "right_wheel_joint", "轮子"],
        [np.nan, -0.0, np.inf],
        [-np.inf, 5e-324, 1.7976931348623157e308],
        [float.fromhex("-0x1.8p-1022"), 0.0, -np.nan],
    ),
    "NaN payload": make(["left_wheel_joint"], [np.frombuffer(struct.pack("<Q", 0x7FF0_0000_DEAD_BEEF), np.float64)[0]]),
    "duplicate names: the first wins": make(["left_wheel_joint", "right_wheel_joint", "left_wheel_joint"]),
    "prefixes and the empty name": make(["left_wheel_joint2", "left_wheel", "", "left_wheel_joint"]),
    "non-ASCII names and frame_id": make(["ведущее_колесо", "轮子", "caster_ø"], frame_id="odom_ø_轮"),
    "empty frame_id": make(["left_wheel_joint"], frame_id=""),
    "long frame_id": make(["left_wheel_joint", "轮子"], frame_id="f" * 70_000, sec=3),
    "sec 2**31": make(["left_wheel_joint"], sec=2**31, nsec=0),
    "sec 2**32 - 1": make(["right_wheel_joint"], sec=2**32 - 1, nsec=999_999_999),
    "nsec 2**32 - 1, not normalised": make(["right_wheel_joint"], sec=2**32 - 1, nsec=2**32 - 1, seq=2**32 - 1),
}


def test_cases_decode_like_rosbags():
    payloads = list(CASES.values())
    out = assert_decodes_like_rosbags(payloads)
    stamp, pos, vel, eff, _ = out
    names = list(CASES)
    row = {name: i for i, name in enumerate(names)}
    # spot checks written out, beyond agreeing with rosbags
    assert stamp[row["sec 2**32 - 1"]] == (2**32 - 1) * NS + 999_999_999
    assert stamp[row["nsec 2**32 - 1, not normalised"]] == (2**32 - 1) * NS + 2**32 - 1
    i = row["shorter arrays"]
    np.testing.assert_array_equal(vel[i, :4], [7.0, np.nan, np.nan, np.nan])
    np.testing.assert_array_equal(eff[i, :4], [8.0, 9.0, np.nan, np.nan])
    i = row["duplicate names: the first wins"]
    assert pos[i, 0] == 1.0
    i = row["prefixes and the empty name"]
    np.testing.assert_array_equal(pos[i], [4.0, np.nan, np.nan, np.nan, 3.0, 2.0, np.nan])
    assert np.isnan(pos[:, REF.index("absent_joint")]).all()
    assert TS.deserialize_ros1(CASES["sec 2**32 - 1"], JS).header.stamp.sec == -1  # rosbags reads sec signed


def random_payloads(rng, n):
    out = []
    for _ in range(n):
        k = int(rng.integers(0, 7))
        names = list(rng.choice(POOL, size=k, replace=bool(rng.random() < 0.3)))
        fields = []
        for _ in range(3):
            m = (k, k, 0, int(rng.integers(0, k + 3)))[rng.integers(0, 4)]
            v = rng.normal(scale=10.0 ** rng.integers(-3, 4), size=m)
            v[rng.random(m) < 0.05] = np.nan
            v[rng.random(m) < 0.03] = -np.inf
            fields.append(v)
        sec = int(rng.integers(0, 2**32)) if rng.random() < 0.3 else int(rng.integers(0, 2**31))
        frame = "".join(rng.choice(["b", "a", "s", "e", "_", "ø", "轮"], size=int(rng.integers(0, 40))))
        out.append(make(names, *fields, sec=sec, nsec=int(rng.integers(0, NS)), frame_id=frame,
                        seq=int(rng.integers(0, 2**32))))  # fmt: skip
    return out


def test_random_messages_decode_like_rosbags():
    assert_decodes_like_rosbags(random_payloads(np.random.default_rng(20240611), 400))


@settings(max_examples=150, deadline=None, derandomize=True, database=None)
@given(
    names=st.lists(st.sampled_from(POOL) | st.text(max_size=6), max_size=8),
    values=st.lists(st.floats(allow_nan=True, allow_infinity=True, width=64), max_size=30),
    cuts=st.tuples(st.integers(0, 10), st.integers(0, 10), st.integers(0, 10)),
    sec=st.integers(0, 2**32 - 1),
    nsec=st.integers(0, 2**32 - 1),
    frame_id=st.text(max_size=20),
)
def test_generated_messages_decode_like_rosbags(names, values, cuts, sec, nsec, frame_id):
    a, b = sorted(cuts[:2])
    raw = make(names, values[:a], values[a:b], values[b : b + cuts[2]], sec=sec, nsec=nsec, frame_id=frame_id)
    assert_decodes_like_rosbags([raw])
    np.testing.assert_array_equal(bits(np.stack(decode_checked(raw)[1:4])), bits(np.stack(decode([raw])[1:4])))


@pytest.mark.parametrize("compression", [None, "BZ2", "LZ4"])
def test_bag_messages_decode_like_rosbags(tmp_path, compression):
    payloads = [*CASES.values(), *random_payloads(np.random.default_rng(7), 150)]
    path = tmp_path / "joints.bag"
    writer = Writer(path)
    if compression:
        writer.set_compression(Writer.CompressionFormat[compression])
    writer.chunk_threshold = 8192  # several chunks
    with writer:
        conn = writer.add_connection("/joint_states", JS, typestore=TS)
        for i, raw in enumerate(payloads):
            writer.write(conn, 1_000 + i, raw)
    with Reader(path) as reader:
        assert len(reader.chunk_infos) > 3
        read = [(t, bytes(raw)) for _, t, raw in reader.messages()]
    assert [t for t, _ in read] == [1_000 + i for i in range(len(payloads))]
    assert [raw for _, raw in read] == payloads
    assert_decodes_like_rosbags([raw for _, raw in read])


def rosbags_verdict(raw):
    """rosbags' decode of the message at the start of raw ("utf-8" when a string is not UTF-8, None when none is
    there): the kernel ignores bytes after the effort array, rosbags refuses them, so every prefix is tried."""
    for end in range(len(raw), 15, -1):
        try:
            return TS.deserialize_ros1(raw[:end], JS)
        except SerdeError as exc:
            if isinstance(exc.__cause__, UnicodeDecodeError):
                return "utf-8"
    return None


def check_hostile(raw):
    """The bounds-checked kernel on raw alone, the real one on raw between sentinels: the same outputs, bit for
    bit, and the ones rosbags gives (status malformed exactly when rosbags finds no message)."""
    checked = decode_checked(raw)
    real = decode([raw])
    for a, b in zip(checked, real, strict=True):
        np.testing.assert_array_equal(np.asarray(a).view(np.uint8), np.asarray(b).view(np.uint8))
    assert not (bits(np.stack(real[1:4])) == np.uint64(0x7F7F7F7F7F7F7F7F)).any()
    verdict = rosbags_verdict(raw)
    if verdict == "utf-8":
        assert real[4][0] in (STATUS_OK, STATUS_MALFORMED)
    elif verdict is None:
        assert real[4][0] == STATUS_MALFORMED
    else:
        assert_row(real, 0, verdict)
    return verdict


def test_every_truncation_is_malformed():
    for name in ("permuted, extra joints", "special values", "shorter arrays", "no joints", "sec 2**32 - 1"):
        raw = CASES[name]
        for end in range(len(raw)):
            assert decode_checked(raw[:end])[4][0] == STATUS_MALFORMED, (name, end)
            assert check_hostile(raw[:end]) is None
        assert decode_checked(raw)[4][0] == STATUS_OK


def test_truncation_followed_by_the_rest():
    """A payload cut short inside a buffer that goes on with the rest of the message: never read past the cut."""
    raw = CASES["permuted, extra joints"]
    buf = np.frombuffer(raw, dtype=np.uint8).copy()
    n = len(raw)
    out = _run(ros1_joint_states, buf, np.zeros(n, np.int64), np.arange(n), len(REF))
    assert (out[4] == STATUS_MALFORMED).all()
    whole = _run(ros1_joint_states, buf, [0], [n], len(REF))
    assert_row(whole, 0, TS.deserialize_ros1(raw, JS))


def length_fields(raw):
    """Offsets of every length or count in a valid payload: frame_id, name count, each name, the three arrays."""
    (flen,) = struct.unpack_from("<I", raw, 12)
    p = 16 + flen
    out = [12, p]
    (count,) = struct.unpack_from("<I", raw, p)
    p += 4
    for _ in range(count):
        out.append(p)
        p += 4 + struct.unpack_from("<I", raw, p)[0]
    for _ in range(3):
        out.append(p)
        p += 4 + 8 * struct.unpack_from("<I", raw, p)[0]
    assert p == len(raw)
    return out


EDGES = (0, 1, 2, 3, 4, 7, 8, 2**31 - 1, 2**31, 2**32 - 8, 2**32 - 1)


def test_hostile_lengths():
    """Each length or count set to edge values or nudged by one: huge counts must not read beyond the payload."""
    compared = 0
    for name in ("permuted, extra joints", "shorter arrays", "non-ASCII names and frame_id", "no joints"):
        raw = CASES[name]
        for at in length_fields(raw):
            (value,) = struct.unpack_from("<I", raw, at)
            for new in {*EDGES, value - 1, value + 1, value + 2, (value + 8) % 2**32}:
                bad = bytearray(raw)
                struct.pack_into("<I", bad, at, new % 2**32)
                compared += check_hostile(bytes(bad)) not in (None, "utf-8")
    assert compared > 20


def test_random_corruption():
    rng = np.random.default_rng(1234)
    payloads = [*CASES.values(), *random_payloads(rng, 40)]
    payloads = [raw for raw in payloads if len(raw) < 2000]
    verdicts = {"decoded": 0, "none": 0, "utf-8": 0}
    for raw in payloads:
        for _ in range(12):
            bad = bytearray(raw)
            for at in rng.integers(0, len(bad), size=int(rng.integers(1, 4))):
                bad[at] = int(rng.integers(0, 256)) if rng.random() < 0.7 else bad[at] ^ (1 << int(rng.integers(0, 8)))
            if rng.random() < 0.2:
                bad += bytes(rng.integers(0, 256, size=int(rng.integers(1, 12)), dtype=np.uint8))
            verdict = check_hostile(bytes(bad))
            verdicts["none" if verdict is None else "utf-8" if verdict == "utf-8" else "decoded"] += 1
    assert verdicts["decoded"] > 100, verdicts
    assert verdicts["none"] > 50, verdicts


@settings(max_examples=300, deadline=None, derandomize=True, database=None)
@given(st.binary(max_size=120))
def test_arbitrary_bytes(raw):
    check_hostile(raw)


def test_bounds_checking_is_on():
    """The checked kernel really checks: its helper raises where the real one would read past the end."""
    with pytest.raises(IndexError):
        CHECKED.py_func.__globals__["_u32"](np.zeros(4, np.uint8), 1)
