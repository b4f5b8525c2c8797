"""The compiled reader of ROS 1 serialised sensor_msgs/JointState messages: the ROS 1 counterpart of
:func:`wmrid.io.mcap.records.joint_states`, with the same arguments, results and status codes.

ROS 1 wire format: little-endian, no alignment or padding; a string is its uint32 byte length then its bytes (no
terminating NUL); an array is its uint32 count then its elements.  A JointState is the Header (uint32 seq, uint32
stamp.sec, uint32 stamp.nsec, string frame_id), string[] name, float64[] position, velocity and effort.

Stamps come out in ns; values as the message has them (rad, rad/s, N m).  What it cannot decode it reports by a
status code, never by reading outside the message's bytes.  tests/test_ros1_records.py checks it field for field
against rosbags' ROS 1 deserialiser, on messages written by rosbags and on truncated and corrupted ones.
"""

from __future__ import annotations

import numba
import numpy as np

from wmrid.io.mcap.records import STATUS_MALFORMED, STATUS_OK, _f64, _u32

#: seq, stamp.sec, stamp.nsec and frame_id's length: the bytes every message has.
_FIXED = 16


@numba.njit(cache=True, nogil=True)
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
