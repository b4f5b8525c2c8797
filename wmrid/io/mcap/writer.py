"""Writing wheel logs and estimates as MCAP files that Foxglove and ROS 2 tools open.

:func:`write_joint_state_mcap` writes a wheel log (the columns of :mod:`wmrid.io.logs`, plus optional wheel
angles ``theta_r``, ``theta_l``) as a ROS 2 MCAP (profile ``ros2``): one ``sensor_msgs/msg/JointState``
per row and, when the log has a pose, one ``nav_msgs/msg/Odometry`` per row.  :func:`write_series_mcap`
writes named time series (e.g. the estimates over time) as a JSON channel, to plot next to the log.

Time: a row at ``t`` seconds is stamped ``t0_ns + round(t * 1e9)`` integer nanoseconds, by default from
:data:`EPOCH_NS` (2023-11-14 22:13:20 UTC), so that stamps look like ROS times and the two writers'
files line up in one Foxglove session.  The same value is the message's header stamp (sec, nanosec),
its MCAP log time and its publish time.

CDR: the ``mcap_ros2`` writer serialises each message in Python (about 55k messages/s), so the
messages are laid out here instead: within one log every string and sequence length is the same, so
every message has the same byte layout.  :class:`_CdrLayout` builds that layout once, with the
alignment rules of a CDR writer (XCDR1, little endian, encapsulation header ``00 01 00 00``, each
primitive aligned to its size relative to the payload after that header, an empty sequence not
aligned at all), and numpy fills the per-row fields of a block of rows at once.

Every file is written atomically (:mod:`wmrid.runtime.atomic`); an existing file is replaced only with ``force``.
"""

from __future__ import annotations

import struct
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
from mcap.well_known import MessageEncoding, Profile, SchemaEncoding
from mcap.writer import LIBRARY_IDENTIFIER, CompressionType, Writer

from wmrid import __version__
from wmrid.core.errors import UsageError
from wmrid.runtime.atomic import atomic_output

if TYPE_CHECKING:
    import pandas

__all__ = [
    "EPOCH_NS",
    "JOINT_STATE_MSGDEF",
    "ODOMETRY_MSGDEF",
    "write_joint_state_mcap",
]

EPOCH_NS = 1_700_000_000 * 1_000_000_000  # t = 0 s, ns since the Unix epoch (2023-11-14 22:13:20 UTC)
CHUNK_SIZE = 1 << 20  # bytes of uncompressed messages per chunk
COMPRESSIONS = ("zstd", "lz4", "")
JOINT_FRAME_ID = "base_link"
ODOM_FRAME_ID = "odom"
ODOM_CHILD_FRAME_ID = "base_link"
_BLOCK_ROWS = 8192  # rows laid out per numpy pass: bounds memory (an Odometry message is 724 bytes)
_SERIES_BLOCK_ROWS = 65536  # rows formatted as JSON per pyarrow pass
_MAX_STAMP_NS = (2**31) * 1_000_000_000  # header.stamp.sec is an int32

_SEPARATOR = "=" * 80

# ROS 2 Humble definitions (field for field; comments left out), concatenated with their dependencies in
# the format rosbag2 writes into MCAP schemas and mcap_ros2 / Foxglove parse.
_TIME = "int32 sec\nuint32 nanosec\n"
_HEADER = "builtin_interfaces/Time stamp\nstring frame_id\n"
_POINT = "float64 x\nfloat64 y\nfloat64 z\n"
_QUATERNION = "float64 x 0\nfloat64 y 0\nfloat64 z 0\nfloat64 w 1\n"
_POSE = "Point position\nQuaternion orientation\n"
_POSE_WITH_COVARIANCE = "Pose pose\nfloat64[36] covariance\n"
_VECTOR3 = "float64 x\nfloat64 y\nfloat64 z\n"
_TWIST = "Vector3 linear\nVector3 angular\n"
_TWIST_WITH_COVARIANCE = "Twist twist\nfloat64[36] covariance\n"


def _msgdef(main: str, dependencies: Iterable[tuple[str, str]]) -> str:
    """A main definition followed by its dependencies, each after a separator line and ``MSG: pkg/Name``."""
    parts = [main]
    for name, text in dependencies:
        parts.append(f"{_SEPARATOR}\nMSG: {name}\n{text}")
    return "".join(parts)


JOINT_STATE_MSGDEF = _msgdef(
    "std_msgs/Header header\nstring[] name\nfloat64[] position\nfloat64[] velocity\nfloat64[] effort\n",
    [("std_msgs/Header", _HEADER), ("builtin_interfaces/Time", _TIME)],
)
ODOMETRY_MSGDEF = _msgdef(
    "std_msgs/Header header\nstring child_frame_id\n"
    "geometry_msgs/PoseWithCovariance pose\ngeometry_msgs/TwistWithCovariance twist\n",
    [
        ("std_msgs/Header", _HEADER),
        ("builtin_interfaces/Time", _TIME),
        ("geometry_msgs/PoseWithCovariance", _POSE_WITH_COVARIANCE),
        ("geometry_msgs/Pose", _POSE),
        ("geometry_msgs/Point", _POINT),
        ("geometry_msgs/Quaternion", _QUATERNION),
        ("geometry_msgs/TwistWithCovariance", _TWIST_WITH_COVARIANCE),
        ("geometry_msgs/Twist", _TWIST),
        ("geometry_msgs/Vector3", _VECTOR3),
    ],
)


# --------------------------------------------------------------------------------------------------
# CDR layout


class _CdrLayout:
    """The byte layout of a CDR message whose strings and sequence lengths are fixed.

    Built in field order, as a CDR writer would write it: constants (strings, sequence lengths, fixed
    values) go into the template; per-message fields are named slots (offset, little-endian dtype) that
    :meth:`fill` writes for a block of messages at once.  Offsets count from the start of the message,
    encapsulation header included; alignment counts from the end of that 4-byte header.
    """

    def __init__(self) -> None:
        self._buf = bytearray(b"\x00\x01\x00\x00")  # CDR_LE, options 0
        self.slots: dict[str, tuple[int, np.dtype]] = {}

    def _align(self, size: int) -> None:
        self._buf += bytes(-(len(self._buf) - 4) % size)

    def uint32(self, value: int) -> None:
        self._align(4)
        self._buf += struct.pack("<I", value)

    def float64(self, value: float) -> None:
        self._align(8)
        self._buf += struct.pack("<d", value)

    def string(self, text: str) -> None:
        """uint32 length (bytes including the terminating NUL), the UTF-8 bytes, NUL."""
        data = text.encode("utf-8") + b"\x00"
        self.uint32(len(data))
        self._buf += data

    def slot(self, name: str, dtype: str) -> None:
        """A per-message field of type ``dtype`` (``"<i4"``, ``"<u4"`` or ``"<f8"``), aligned to its size."""
        if name in self.slots:
            raise ValueError(f"CDR slot {name!r} defined twice")
        kind = np.dtype(dtype)
        self._align(kind.itemsize)
        self.slots[name] = (len(self._buf), kind)
        self._buf += bytes(kind.itemsize)

    def stamp(self) -> None:
        """builtin_interfaces/Time: slots ``sec`` (int32) and ``nanosec`` (uint32)."""
        self.slot("sec", "<i4")
        self.slot("nanosec", "<u4")

    @property
    def size(self) -> int:
        """Bytes per message, encapsulation header included."""
        return len(self._buf)

    def fill(self, values: Mapping[str, np.ndarray]) -> bytes:
        """``n`` messages back to back (n * :attr:`size` bytes), slot ``k`` of message ``i`` = ``values[k][i]``.

        values : {slot name: (n,) array}, one entry for every slot (converted exactly to the slot's type).
        """
        missing = set(self.slots) - set(values)
        if missing:
            raise ValueError(f"no values for CDR slots {sorted(missing)}")
        n = len(next(iter(values.values()))) if values else 0
        out = np.empty((n, self.size), dtype=np.uint8)
        out[:] = np.frombuffer(bytes(self._buf), dtype=np.uint8)
        for name, (offset, kind) in self.slots.items():
            column = np.ascontiguousarray(values[name], dtype=kind)
            if column.shape != (n,):
                raise ValueError(f"CDR slot {name!r}: expected shape ({n},), got {column.shape}")
            out[:, offset : offset + kind.itemsize] = column.view(np.uint8).reshape(n, kind.itemsize)
        return out.tobytes()


def _joint_state_layout(names: tuple[str, str], with_position: bool) -> _CdrLayout:
    """sensor_msgs/msg/JointState with the two joints ``names``; slots p0 p1 (if with_position), v0 v1, e0 e1."""
    layout = _CdrLayout()
    layout.stamp()
    layout.string(JOINT_FRAME_ID)
    layout.uint32(len(names))
    for name in names:
        layout.string(name)
    for prefix, present in (("p", with_position), ("v", True), ("e", True)):
        layout.uint32(len(names) if present else 0)
        if present:
            for k in range(len(names)):
                layout.slot(f"{prefix}{k}", "<f8")
    return layout


def _odometry_layout() -> _CdrLayout:
    """nav_msgs/msg/Odometry: slots x, y (m), qz, qw (orientation about z); all else constant (z = 0, twist
    and both covariances 0)."""
    layout = _CdrLayout()
    layout.stamp()
    layout.string(ODOM_FRAME_ID)
    layout.string(ODOM_CHILD_FRAME_ID)
    layout.slot("x", "<f8")
    layout.slot("y", "<f8")
    layout.float64(0.0)  # position.z
    layout.float64(0.0)  # orientation.x
    layout.float64(0.0)  # orientation.y
    layout.slot("qz", "<f8")
    layout.slot("qw", "<f8")
    for _ in range(36):  # pose.covariance: unknown
        layout.float64(0.0)
    for _ in range(6):  # twist.twist linear xyz, angular xyz
        layout.float64(0.0)
    for _ in range(36):  # twist.covariance
        layout.float64(0.0)
    return layout


# --------------------------------------------------------------------------------------------------
# Checks


def _compression(name: str) -> Any:
    kinds = {"zstd": CompressionType.ZSTD, "lz4": CompressionType.LZ4, "": CompressionType.NONE}
    if name not in kinds:
        raise UsageError(f"MCAP compression {name!r} is not one of 'zstd', 'lz4' or '' (none)")
    return kinds[name]


def _check_chunk_size(chunk_size: int) -> int:
    if isinstance(chunk_size, bool) or not isinstance(chunk_size, (int, np.integer)) or chunk_size < 1:
        raise UsageError(f"MCAP chunk size must be a whole number of bytes >= 1, got {chunk_size!r}")
    return int(chunk_size)


def _check_metadata(metadata: Mapping[str, str] | None) -> dict[str, str] | None:
    if metadata is None:
        return None
    bad = [k for k, v in metadata.items() if not isinstance(k, str) or not isinstance(v, str)]
    if bad:
        raise UsageError(f"MCAP metadata keys and values must be strings; not so for {bad!r} (JSON-encode them)")
    return dict(metadata)


def _check_topic(topic: str, what: str) -> str:
    if not isinstance(topic, str) or not topic:
        raise UsageError(f"{what} must be a non-empty string, got {topic!r}")
    return topic


def _stamps_ns(t: Any, t0_ns: int, what: str) -> np.ndarray:
    """(n,) int64 ns: ``t0_ns + round(t * 1e9)`` for (n,) float seconds ``t``, checked.

    Raises :class:`UsageError` unless ``t`` is a 1-D float array, finite, non-decreasing once rounded,
    and every stamp lies in [0, 2**31) s (the range of a ROS header stamp).
    """
    if isinstance(t0_ns, bool) or not isinstance(t0_ns, (int, np.integer)):
        raise UsageError(f"t0_ns must be a whole number of nanoseconds, got {t0_ns!r}")
    t0_ns = int(t0_ns)
    arr = np.asarray(t)
    if arr.ndim != 1:
        raise UsageError(f"{what} must be one-dimensional, got shape {arr.shape}")
    if arr.dtype.kind in "iu":
        raise UsageError(f"{what} is an integer column (nanoseconds in a wmrid log); give float seconds")
    if arr.dtype.kind != "f":
        raise UsageError(f"{what} must hold float seconds, got dtype {arr.dtype}")
    arr = arr.astype(np.float64, copy=False)
    if not np.all(np.isfinite(arr)):
        bad = int(np.argmin(np.isfinite(arr))) + 1
        raise UsageError(f"{what} holds a NaN or infinite value at data row {bad} (1-based); drop or fix it")
    if arr.size == 0:
        return np.zeros(0, dtype=np.int64)
    lo, hi = float(arr.min()), float(arr.max())
    first, last = t0_ns + round(lo * 1e9), t0_ns + round(hi * 1e9)
    if first < 0 or last >= _MAX_STAMP_NS:
        raise UsageError(
            f"{what} spans {lo:g} s to {hi:g} s; from t0_ns = {t0_ns} that leaves the range of a ROS stamp "
            f"(0 to 2**31 s after 1970)"
        )
    ns = np.rint(arr * 1e9).astype(np.int64) + np.int64(t0_ns)
    back = np.flatnonzero(np.diff(ns) < 0)
    if back.size:
        raise UsageError(f"{what} decreases at data row {int(back[0]) + 2} (1-based); sort the rows by time")
    return ns


def _float_column(frame: pandas.DataFrame, name: str) -> np.ndarray:
    values = np.asarray(frame[name])
    if values.dtype.kind not in "fiu":
        raise UsageError(f"column {name!r} must be numeric, got dtype {values.dtype}")
    return values.astype(np.float64, copy=False)


def _open_writer(fh: Any, compression: str, chunk_size: int, profile: str) -> Any:
    writer = Writer(fh, chunk_size=chunk_size, compression=_compression(compression))
    writer.start(profile=profile, library=f"wmrid/{__version__}; {LIBRARY_IDENTIFIER}")
    return writer


# --------------------------------------------------------------------------------------------------
# Writers


def write_joint_state_mcap(
    path: str | Path,
    frame: pandas.DataFrame,
    *,
    force: bool = False,
    metadata: Mapping[str, str] | None = None,
    right_joint: str = "right_wheel_joint",
    left_joint: str = "left_wheel_joint",
    topic: str = "/joint_states",
    odom_topic: str | None = "/odom",
    compression: str = "zstd",
    chunk_size: int = CHUNK_SIZE,
    t0_ns: int = EPOCH_NS,
) -> None:
    """Write a wheel log as a ROS 2 MCAP file: one ``sensor_msgs/msg/JointState`` per row.

    frame : columns ``t`` (s, float, non-decreasing), ``eta_r``, ``eta_l`` (rad/s), ``tau_r``, ``tau_l``
        (N m); optionally ``theta_r``, ``theta_l`` (wheel angles, rad; both or neither) and ``x``, ``y``
        (m), ``phi`` (rad) (all three or none).  Other columns are ignored.  Values are written bit for
        bit (NaN included).
    path : the ``.mcap`` file; written atomically, replaced only with ``force``.
    metadata : written as one MCAP metadata record named ``"wmrid"`` (e.g. ``{"truth": json_text}``).
    right_joint, left_joint : joint names.  Each message lists them LEFT FIRST, ``[left_joint, right_joint]``,
        with position (wheel angles, or an empty sequence without ``theta_*``), velocity (eta) and effort
        (tau) in that order; readers must match joints by name.
    topic : JointState topic; header.frame_id ``"base_link"``.
    odom_topic : with a pose, a ``nav_msgs/msg/Odometry`` per row here (None: none): header.frame_id
        ``"odom"``, child_frame_id ``"base_link"``, pose.pose.position (x, y, 0), orientation the yaw
        quaternion (0, 0, sin(phi/2), cos(phi/2)).  The twist is left ZERO: the body speeds
        v = r (eta_r + eta_l) / 2 and w = r (eta_r - eta_l) / (2 b) need the wheel radius r and half
        track b, which a log does not carry.  Both covariances are zero (unknown).
    compression : ``"zstd"`` (default), ``"lz4"`` or ``""`` (none), per chunk.
    chunk_size : uncompressed bytes per chunk (default 1 MiB).
    t0_ns : ns since the Unix epoch of t = 0 (default :data:`EPOCH_NS`).  A row's stamp is
        ``t0_ns + round(t * 1e9)`` ns: header.stamp (sec, nanosec), log time and publish time alike; the
        MCAP sequence number is the row index.

    Raises :class:`UsageError` for a missing or malformed column or option, and
    :class:`~wmrid.core.errors.OutputExistsError` if ``path`` exists and ``force`` is false.
    """
    missing = [c for c in ("t", "eta_r", "eta_l", "tau_r", "tau_l") if c not in frame.columns]
    if missing:
        raise UsageError(f"cannot write JointState messages: no column {', '.join(map(repr, missing))}")
    angles = [c for c in ("theta_r", "theta_l") if c in frame.columns]
    pose = [c for c in ("x", "y", "phi") if c in frame.columns]
    if len(angles) == 1:
        raise UsageError(f"the log has {angles[0]!r} but not the other wheel angle; give theta_r and theta_l")
    if pose and len(pose) != 3:
        raise UsageError(f"the log has pose columns {pose} but not all of x, y, phi")
    for name, what in ((right_joint, "right_joint"), (left_joint, "left_joint")):
        if not isinstance(name, str) or not name:
            raise UsageError(f"{what} must be a non-empty string, got {name!r}")
    if right_joint == left_joint:
        raise UsageError(f"right_joint and left_joint are both {right_joint!r}; give two names")
    topic = _check_topic(topic, "topic")
    with_odom = bool(pose) and odom_topic is not None
    if with_odom:
        odom_topic = _check_topic(odom_topic, "odom_topic")
        if odom_topic == topic:
            raise UsageError(f"topic and odom_topic are both {topic!r}")
    chunk_size = _check_chunk_size(chunk_size)
    _compression(compression)
    metadata = _check_metadata(metadata)

    stamps = _stamps_ns(frame["t"].to_numpy(), t0_ns, "column 't'")
    # Joint k of each message: k = 0 left, k = 1 right.
    columns = {"v0": "eta_l", "v1": "eta_r", "e0": "tau_l", "e1": "tau_r"}
    if angles:
        columns.update({"p0": "theta_l", "p1": "theta_r"})
    data = {slot: _float_column(frame, col) for slot, col in columns.items()}
    joint = _joint_state_layout((left_joint, right_joint), with_position=bool(angles))
    if with_odom:
        phi = _float_column(frame, "phi")
        odom_data = {"x": _float_column(frame, "x"), "y": _float_column(frame, "y")}
        with np.errstate(invalid="ignore"):  # an infinite phi gives a NaN quaternion, as it should
            odom_data.update({"qz": np.sin(0.5 * phi), "qw": np.cos(0.5 * phi)})
        odom = _odometry_layout()

    with atomic_output(path, force=force, mode="wb") as fh:
        writer = _open_writer(fh, compression, chunk_size, Profile.ROS2)
        if metadata is not None:
            writer.add_metadata("wmrid", metadata)
        joint_schema = writer.register_schema(
            "sensor_msgs/msg/JointState", SchemaEncoding.ROS2, JOINT_STATE_MSGDEF.encode("utf-8")
        )
        joint_channel = writer.register_channel(topic, MessageEncoding.CDR, joint_schema)
        if with_odom:
            odom_schema = writer.register_schema(
                "nav_msgs/msg/Odometry", SchemaEncoding.ROS2, ODOMETRY_MSGDEF.encode("utf-8")
            )
            odom_channel = writer.register_channel(odom_topic, MessageEncoding.CDR, odom_schema)
        add = writer.add_message
        for start in range(0, len(stamps), _BLOCK_ROWS):
            block = slice(start, start + _BLOCK_ROWS)
            ns = stamps[block]
            sec, nanosec = np.divmod(ns, 1_000_000_000)
            joint_bytes = joint.fill({"sec": sec, "nanosec": nanosec, **{k: v[block] for k, v in data.items()}})
            size = joint.size
            if with_odom:
                odom_bytes = odom.fill({"sec": sec, "nanosec": nanosec, **{k: v[block] for k, v in odom_data.items()}})
                odom_size = odom.size
                for i, stamp in enumerate(ns.tolist()):
                    row = (start + i) & 0xFFFFFFFF
                    add(joint_channel, stamp, joint_bytes[i * size : (i + 1) * size], stamp, row)
                    add(odom_channel, stamp, odom_bytes[i * odom_size : (i + 1) * odom_size], stamp, row)
            else:
                for i, stamp in enumerate(ns.tolist()):
                    add(joint_channel, stamp, joint_bytes[i * size : (i + 1) * size], stamp, (start + i) & 0xFFFFFFFF)
        writer.finish()
