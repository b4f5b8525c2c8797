"""The compiled reader of ROS 1 serialised sensor_msgs/JointState messages: the ROS 1 counterpart of
:func:`wmrid.io.mcap.records.joint_states`, with the same arguments, results and status codes.

ROS 1 wire format: little-endian, no alignment or padding; a string is its uint32 byte length then its bytes (no
terminating NUL); an array is its uint32 count then its elements.  A JointState is the Header (uint32 seq, uint32
stamp.sec, uint32 stamp.nsec, string frame_id), string[] name, float64[] position, velocity and effort.

Stamps come out in ns; values as the message has them (rad, rad/s, N m).  What it cannot decode it reports by a
status code, never by reading outside the message's bytes.  tests/unit/io/test_ros1_records.py checks it field for field
against rosbags' ROS 1 deserialiser, on messages written by rosbags and on truncated and corrupted ones.
"""

from __future__ import annotations

import numpy as np

from wmrid.core.jit import kernel
from wmrid.io.mcap.records import STATUS_MALFORMED, STATUS_OK, _f64, _u32

#: seq, stamp.sec, stamp.nsec and frame_id's length: the bytes every message has.
_FIXED = 16


@kernel
def ros1_joint_states(buf, starts, lengths, ref, ref_off, stamp, pos, vel, eff, status):
    """Decode ROS 1 JointState payloads buf[starts[i] : starts[i] + lengths[i]] into per-joint arrays.

    ref, ref_off: the reference joint names, concatenated bytes and offsets (K + 1,); a message's name matches a
    reference name when their bytes are equal, its first occurrence wins.
    stamp (n,) int64 header stamp in ns (sec unsigned); pos, vel, eff (n, K) float64, NaN where the message lacks
    the joint or the field (an array shorter than the names); status (n,) int8: 0 ok, 1 malformed (a payload
    shorter than the fixed header, or a length or count that runs past its end; bytes after effort are ignored).
    Like the CDR reader, a malformed message keeps the stamp and fields decoded before the fault.
    """
    n = starts.shape[0]
    k_ref = ref_off.shape[0] - 1
    idx = np.empty(k_ref, dtype=np.int64)
    for i in range(n):
        p = starts[i]
        end = p + lengths[i]
        status[i] = STATUS_OK
        for k in range(k_ref):
            pos[i, k] = np.nan
            vel[i, k] = np.nan
            eff[i, k] = np.nan
        if lengths[i] < _FIXED:
            status[i] = STATUS_MALFORMED
            continue
        stamp[i] = _u32(buf, p + 4) * 1_000_000_000 + _u32(buf, p + 8)
        p += _FIXED + _u32(buf, p + 12)  # past frame_id
        if p + 4 > end:
            status[i] = STATUS_MALFORMED
            continue
        count = _u32(buf, p)
        p += 4
        for k in range(k_ref):
            idx[k] = -1
        bad = False
        for j in range(count):  # each name takes at least 4 bytes: a huge count ends at the payload's end
            if p + 4 > end:
                bad = True
                break
            slen = _u32(buf, p)
            p += 4
            if p + slen > end:
                bad = True
                break
            for k in range(k_ref):
                a = ref_off[k]
                if ref_off[k + 1] - a != slen or idx[k] >= 0:
                    continue
                same = True
                for c in range(slen):
                    if buf[p + c] != ref[a + c]:
                        same = False
                        break
                if same:
                    idx[k] = j
            p += slen
        if bad:
            status[i] = STATUS_MALFORMED
            continue
        for which in range(3):
            if p + 4 > end:
                bad = True
                break
            m = _u32(buf, p)
            p += 4
            if p + 8 * m > end:
                bad = True
                break
            for k in range(k_ref):
                j = idx[k]
                if j >= 0 and j < m:
                    value = _f64(buf, p + 8 * j)
                    if which == 0:
                        pos[i, k] = value
                    elif which == 1:
                        vel[i, k] = value
                    else:
                        eff[i, k] = value
            p += 8 * m
        if bad:
            status[i] = STATUS_MALFORMED


#: The record opcodes of a ROS 1 bag (format 2.0).
OP_MESSAGE = 0x02
OP_BAG_HEADER = 0x03
OP_INDEX = 0x04
OP_CHUNK = 0x05
OP_CHUNK_INFO = 0x06
OP_CONNECTION = 0x07


@kernel
def ros1_records(buf, p, end, ops, conns, times, hstart, hlen, dstart, dlen):
    """Walk ROS 1 bag records in buf[p:end] (each: uint32 header length, header fields, uint32 data length, data).

    Per record: ``ops`` the ``op`` field (-1 when absent), ``conns`` the ``conn`` field (-1), ``times`` the
    ``time`` field in ns (sec * 1e9 + nsec, -1 when absent), the header's and the data's offset and length.  A
    header field is uint32 length then ``name=value``; a field that runs past its header ends the header.
    Returns (records read, offset after the last whole record): it stops when the arrays are full or a record runs
    past ``end`` (a file cut short).
    """
    n = 0
    cap = ops.shape[0]
    while n < cap and p + 4 <= end:
        hl = _u32(buf, p)
        h0 = p + 4
        if hl > end - h0 - 4:
            break
        h1 = h0 + hl
        dl = _u32(buf, h1)
        d0 = h1 + 4
        if dl > end - d0:
            break
        op = -1
        conn = -1
        t = -1
        q = h0
        while q + 4 <= h1:
            fl = _u32(buf, q)
            q += 4
            if fl > h1 - q:
                break
            eq = -1
            for k in range(q, q + fl):
                if buf[k] == 61:  # '='
                    eq = k
                    break
            if eq >= 0:
                name_len = eq - q
                v0 = eq + 1
                vlen = q + fl - v0
                if name_len == 2 and vlen == 1 and buf[q] == 111 and buf[q + 1] == 112:  # "op"
                    op = buf[v0]
                elif (
                    name_len == 4 and vlen == 4
                    and buf[q] == 99 and buf[q + 1] == 111 and buf[q + 2] == 110 and buf[q + 3] == 110
                ):  # "conn"  # fmt: skip
                    conn = _u32(buf, v0)
                elif (
                    name_len == 4 and vlen == 8
                    and buf[q] == 116 and buf[q + 1] == 105 and buf[q + 2] == 109 and buf[q + 3] == 101
                ):  # "time"  # fmt: skip
                    t = _u32(buf, v0) * 1_000_000_000 + _u32(buf, v0 + 4)
            q += fl
        ops[n] = op
        conns[n] = conn
        times[n] = t
        hstart[n] = h0
        hlen[n] = hl
        dstart[n] = d0
        dlen[n] = dl
        n += 1
        p = d0 + dl
    return n, p
