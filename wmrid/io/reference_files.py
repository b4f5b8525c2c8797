"""Reference drives on file: a planned forward speed v (m/s) and turn rate omega (rad/s) over time t (s).

:func:`write_reference` writes one for the robot to replay, :func:`read_reference` reads one back (for
``wmrid simulate --reference``, or to check what was written).  The format follows the suffix:

* ``.csv`` (also ``.tsv``, ``.txt``) and ``.parquet`` (``.pq``): a table of the columns given, in their order --
  at least ``t`` (s), ``v`` (m/s) and ``omega`` (rad/s); a plan adds ``eta_r``, ``eta_l`` (rad/s), ``x``, ``y`` (m)
  and ``phi`` (rad).  CSV floats are written in shortest round-trip form, so they read back bit for bit.
* ``.mcap``: a ROS 2 recording (profile ``ros2``, message encoding ``cdr``, schema encoding ``ros2msg``, zstd
  chunks) of one ``geometry_msgs/msg/Twist`` per row on one topic (``linear.x = v``, ``angular.z = omega``, every
  other field 0), or ``geometry_msgs/msg/TwistStamped`` (the same twist under a header).  Row i is logged and
  published at ``start_ns + round(t[i] * 1e9)`` integer nanoseconds; the other columns are not written.

Replaying an MCAP file on a robot: ``ros2 bag play`` publishes each message at its log time (its "receive"
time), relative to the first message, so the robot gets the rows at their pace whatever ``start_ns`` is.
The file is a bare rosbag2 storage file, no ``metadata.yaml`` beside it: ROS 2 Iron and later (rosbag2 with
storage-id detection, ros2/rosbag2 PR #1072) play it as ``ros2 bag play plan.mcap``; Humble needs the storage
named, ``ros2 bag play -s mcap plan.mcap`` (with ``ros-humble-rosbag2-storage-mcap`` installed), and reads the
topics from the file itself when ``metadata.yaml`` is missing.  (Stated from the rosbag2 sources; no ROS
installation was run to check it.)  rosbags (>= 0.11) reads the bare file too: ``rosbags.highlevel.AnyReader
([Path("plan.mcap")])``.  ``ros2 bag play`` does not rewrite header stamps: a TwistStamped keeps the stamp
written here.  ros2_control's ``diff_drive_controller`` ignores a TwistStamped older than its ``cmd_vel_timeout``
(0.5 s by default) but stamps an all-zero stamp with its own clock on receipt, so write ``zero_stamps=True`` for
it (or ``start_ns`` near the time of the replay).

Times read from an MCAP file are the log times, in seconds after the first message, converted once here.
"""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from pathlib import Path
from typing import Any

import numpy as np

from wmrid.core.errors import LogFormatError, UsageError, cannot_read
from wmrid.core.extras import require
from wmrid.runtime.atomic import atomic_output, register_input

__all__ = [
    "REFERENCE_COLUMNS",
    "TWIST_MSGDEF",
    "TWIST_STAMPED_MSGDEF",
    "TWIST_TYPES",
    "read_reference",
    "write_reference",
]

#: The columns every reference has: time (s), forward speed (m/s), turn rate (rad/s).
REFERENCE_COLUMNS = ("t", "v", "omega")
#: The ROS 2 message types a reference is written as and read from.
TWIST_TYPES = ("geometry_msgs/msg/Twist", "geometry_msgs/msg/TwistStamped")

_SEPARATOR = "=" * 80
_VECTOR3 = "float64 x\nfloat64 y\nfloat64 z\n"
_TIME = "int32 sec\nuint32 nanosec\n"
_HEADER = "builtin_interfaces/Time stamp\nstring frame_id\n"
_TWIST = "Vector3 linear\nVector3 angular\n"
_MAX_STAMP_NS = (2**31) * 1_000_000_000  # header.stamp.sec is an int32
_MCAP_SUFFIXES = (".mcap",)
_CSV_SUFFIXES = (".csv", ".tsv", ".txt")
_PARQUET_SUFFIXES = (".parquet", ".pq")

#: ROS 2 definitions (Humble onwards, comments left out) with their dependencies, as rosbag2 writes them into MCAP.
TWIST_MSGDEF = _TWIST + f"{_SEPARATOR}\nMSG: geometry_msgs/Vector3\n{_VECTOR3}"
TWIST_STAMPED_MSGDEF = (
    "std_msgs/Header header\nTwist twist\n"
    f"{_SEPARATOR}\nMSG: std_msgs/Header\n{_HEADER}"
    f"{_SEPARATOR}\nMSG: builtin_interfaces/Time\n{_TIME}"
    f"{_SEPARATOR}\nMSG: geometry_msgs/Twist\n{_TWIST}"
    f"{_SEPARATOR}\nMSG: geometry_msgs/Vector3\n{_VECTOR3}"
)


def _kind(path: str) -> str:
    suffix = os.path.splitext(path)[1].lower()
    if suffix in _MCAP_SUFFIXES:
        return "mcap"
    if suffix in _CSV_SUFFIXES:
        return "csv"
    if suffix in _PARQUET_SUFFIXES:
        return "parquet"
    raise UsageError(f"cannot tell the reference format from {path!r}; name it .csv, .parquet or .mcap")


# --------------------------------------------------------------------------------------------------
# Checks shared by the writer and the reader


def _data_row(i: int) -> str:
    return f"data row {i}"


def _check_times(t: np.ndarray, where: str, row: Callable[[int], str] = _data_row) -> None:
    """Raise LogFormatError unless t (n,) s is finite and strictly increasing; ``where`` names the file, ``row(i)``
    the i-th row (1-based)."""
    bad = np.flatnonzero(~np.isfinite(t))
    if bad.size:
        raise LogFormatError(f"{where}: t is NaN or infinite at {row(int(bad[0]) + 1)}; drop or fix it")
    back = np.flatnonzero(np.diff(t) <= 0)
    if back.size:
        i = int(back[0])
        raise LogFormatError(
            f"{where}: t does not increase at {row(i + 2)} ({t[i + 1]!r} s after {t[i]!r} s); times must be "
            "strictly increasing (sort the rows, drop repeats)"
        )


def _check_values(name: str, values: np.ndarray, where: str, row: Callable[[int], str] = _data_row) -> None:
    bad = np.flatnonzero(~np.isfinite(values))
    if bad.size:
        raise LogFormatError(f"{where}: {name} is NaN or infinite at {row(int(bad[0]) + 1)}; drop or fix it")


def _check_count(n: int, where: str, what: str) -> None:
    if n < 2:
        raise LogFormatError(f"{where}: {n} {what}; a reference needs at least 2 samples (t, v, omega)")


# --------------------------------------------------------------------------------------------------
# Writing


def _columns(columns: Mapping[str, Any]) -> dict[str, np.ndarray]:
    """The columns as (n,) float64 arrays, checked: t, v, omega present, one length, numeric."""
    if not isinstance(columns, Mapping):
        raise UsageError(f"columns must be a mapping of name to array, got {type(columns).__name__}")
    missing = [c for c in REFERENCE_COLUMNS if c not in columns]
    if missing:
        raise UsageError(f"a reference needs columns t, v and omega; missing {', '.join(map(repr, missing))}")
    out: dict[str, np.ndarray] = {}
    n = None
    for name, values in columns.items():
        if not isinstance(name, str) or not name or name != name.strip() or set(name) & {",", "\t", '"', "\n", "\r"}:
            raise UsageError(f"column names must be plain non-empty strings, got {name!r}")
        arr = np.asarray(values)
        if arr.ndim != 1 or arr.dtype.kind not in "fiu":
            raise UsageError(f"column {name!r} must be a 1-D numeric array, got {arr.dtype} of shape {arr.shape}")
        if n is None:
            n = arr.shape[0]
        elif arr.shape[0] != n:
            raise UsageError(
                f"column {name!r} has {arr.shape[0]} values, column {next(iter(out))!r} {n}; give one length"
            )
        out[name] = arr.astype(np.float64, copy=False)
    return out


def write_reference(
    path: str | os.PathLike[str],
    columns: Mapping[str, np.ndarray],
    *,
    topic: str = "/cmd_vel",
    stamped: bool = False,
    frame_id: str = "base_link",
    start_ns: int = 0,
    zero_stamps: bool = False,
    force: bool = False,
) -> None:
    """Write a reference drive to ``path``, format by suffix (module docstring).

    columns : {name: (n,) array}, n >= 2, holding at least ``t`` (s, finite, strictly increasing), ``v`` (m/s) and
        ``omega`` (rad/s) (both finite).  CSV and Parquet get every column, in the order given; MCAP only t, v, omega.
    topic : MCAP topic of the messages.  stamped : ``geometry_msgs/msg/TwistStamped`` instead of ``Twist``, with
        ``header.frame_id = frame_id`` and ``header.stamp`` the message's time (``zero_stamps``: 0 s, 0 ns instead).
    start_ns : integer nanoseconds of t = 0 on the MCAP clock; message i is logged and published at
        ``start_ns + round(t[i] * 1e9)`` ns (which must lie in [0, 2**31) s), its sequence number i.
    force : replace an existing file.  The file is written atomically (:mod:`wmrid.runtime.atomic`): it appears complete
        or not at all; an input of the running command is never overwritten.

    Raises :class:`UsageError` for malformed columns or options, :class:`LogFormatError` for times that are not
    finite and strictly increasing or values that are not finite (naming the row, 1-based), and
    :class:`~wmrid.core.errors.OutputExistsError` if ``path`` exists and ``force`` is false.
    """
    name = os.fspath(path)
    kind = _kind(name)
    data = _columns(columns)
    where = f"reference for {name}"
    n = data["t"].shape[0]
    _check_count(n, where, "data rows")
    _check_times(data["t"], where)
    for col in ("v", "omega"):
        _check_values(col, data[col], where)
    if kind == "mcap":
        _write_mcap(name, data, topic=topic, stamped=stamped, frame_id=frame_id, start_ns=start_ns,
                    zero_stamps=zero_stamps, force=force)  # fmt: skip
        return
    import pandas as pd  # pandas (~0.2 s): only a CSV or Parquet reference

    from wmrid.io.logs import write_log  # the log writer (~20 ms): only a CSV or Parquet reference

    write_log(pd.DataFrame(data), name, force=force)


def _stamps(t: np.ndarray, start_ns: Any, where: str) -> np.ndarray:
    """(n,) int64 ns ``start_ns + round(t * 1e9)``, checked: inside a ROS stamp's range, strictly increasing."""
    if isinstance(start_ns, bool) or not isinstance(start_ns, (int, np.integer)):
        raise UsageError(f"start_ns must be a whole number of nanoseconds, got {start_ns!r}")
    start_ns = int(start_ns)
    first, last = start_ns + round(float(t[0]) * 1e9), start_ns + round(float(t[-1]) * 1e9)
    if first < 0 or last >= _MAX_STAMP_NS:
        raise UsageError(
            f"{where}: t spans {t[0]:g} s to {t[-1]:g} s; from start_ns = {start_ns} that leaves the range of a ROS "
            "stamp (0 to 2**31 s after 1970)"
        )
    ns = np.rint(t * 1e9).astype(np.int64) + np.int64(start_ns)
    same = np.flatnonzero(np.diff(ns) <= 0)
    if same.size:
        raise LogFormatError(
            f"{where}: t at data rows {int(same[0]) + 1} and {int(same[0]) + 2} falls on the same nanosecond; "
            "an MCAP reference needs times at least 1 ns apart"
        )
    return ns


def _write_mcap(
    path: str, data: dict[str, np.ndarray], *, topic: str, stamped: bool, frame_id: str, start_ns: int,
    zero_stamps: bool, force: bool,
) -> None:  # fmt: skip
    from mcap_ros2.writer import Writer  # mcap_ros2's writer (~40 ms): only an MCAP reference

    if not isinstance(topic, str) or not topic:
        raise UsageError(f"topic must be a non-empty string, got {topic!r}")
    if not isinstance(frame_id, str):
        raise UsageError(f"frame_id must be a string, got {frame_id!r}")
    ns = _stamps(data["t"], start_ns, f"reference for {path}")
    v, omega = data["v"].tolist(), data["omega"].tolist()
    with atomic_output(path, force=force, mode="wb") as fh:
        writer = Writer(fh)
        if stamped:
            schema = writer.register_msgdef(TWIST_TYPES[1], TWIST_STAMPED_MSGDEF)
        else:
            schema = writer.register_msgdef(TWIST_TYPES[0], TWIST_MSGDEF)
        for i, stamp in enumerate(ns.tolist()):
            twist = {"linear": {"x": v[i], "y": 0.0, "z": 0.0}, "angular": {"x": 0.0, "y": 0.0, "z": omega[i]}}
            if stamped:
                sec, nanosec = divmod(0 if zero_stamps else stamp, 1_000_000_000)
                message = {"header": {"stamp": {"sec": sec, "nanosec": nanosec}, "frame_id": frame_id}, "twist": twist}
            else:
                message = twist
            writer.write_message(topic, schema, message, log_time=stamp, publish_time=stamp, sequence=i & 0xFFFFFFFF)
        writer.finish()


# --------------------------------------------------------------------------------------------------
# Reading


def read_reference(
    path: str | os.PathLike[str], *, topic: str | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t, v, omega): a reference drive read from ``path``, format by suffix (module docstring).

    t : (n,) float64 s, finite and strictly increasing -- the file's ``t`` column, or for MCAP each message's log time
    in seconds after the first message's; v : (n,) m/s; omega : (n,) rad/s; n >= 2.
    CSV and Parquet: the columns ``t``, ``v``, ``omega`` (others are ignored).  MCAP: the ``geometry_msgs/msg/Twist``
    or ``TwistStamped`` messages (CDR) on ``topic`` -- by default the only topic that has them -- with
    v = ``linear.x``, omega = ``angular.z``; the other fields are ignored.

    Raises :class:`LogFormatError` (one line naming the file and the row, 1-based, or the message, or what is
    missing) for an unreadable file, a missing column or topic, a value that is not a finite number, times that
    do not strictly increase, fewer than 2 samples; :class:`UsageError` for a path that cannot be read.
    """
    name = os.fspath(path)
    p = Path(name)
    if not p.exists():
        raise UsageError(f"reference {name} does not exist; check the path")
    if p.is_dir():
        raise UsageError(f"reference {name} is a folder; give the .csv, .parquet or .mcap file itself")
    kind = _kind(name)
    register_input(name)  # an output of this command may not be this file
    if kind == "mcap":
        t, v, omega, chosen = _read_mcap(name, topic)

        def row(i: int) -> str:
            return f"message {i} on {chosen}"

        _check_count(t.shape[0], name, f"messages on {chosen}")
    else:
        if topic is not None:
            raise UsageError(f"{name}: a topic applies to an MCAP reference only; a {kind.upper()} file has columns")
        t, v, omega = _read_table(name, kind)
        row = _data_row
        _check_count(t.shape[0], name, "data rows")
    _check_times(t, name, row)
    _check_values("v", v, name, row)
    _check_values("omega", omega, name, row)
    return t, v, omega


def _read_table(name: str, kind: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    import pandas as pd  # pandas (~0.2 s): only a CSV or Parquet reference

    try:
        if kind == "parquet":
            require("pyarrow.parquet", "parquet", f"{name}: reading a Parquet reference")
            import pyarrow as pa  # pyarrow (~40 ms, extra [parquet]): only a Parquet reference
            import pyarrow.parquet as pq  # pyarrow: only a Parquet reference

            try:
                frame = pq.read_table(name).to_pandas()
            except (pa.ArrowException, OSError) as err:
                raise LogFormatError(f"{name}: not a readable Parquet file ({_one_line(err)})") from err
        else:
            sep = "\t" if name.lower().endswith(".tsv") else ","
            frame = pd.read_csv(name, sep=sep, skipinitialspace=True)
    except pd.errors.EmptyDataError as err:
        raise LogFormatError(f"{name}: the file is empty; a reference needs a header t,v,omega and data rows") from err
    except (pd.errors.ParserError, UnicodeDecodeError, ValueError) as err:
        raise LogFormatError(f"{name}: cannot be parsed as CSV ({_one_line(err)})") from err
    except OSError as err:
        raise UsageError(f"reference {name}: {cannot_read(err)}") from err
    frame.columns = [str(c).strip() for c in frame.columns]
    missing = [c for c in REFERENCE_COLUMNS if c not in frame.columns]
    if missing:
        have = ", ".join(map(str, frame.columns[:8])) or "none"
        raise LogFormatError(
            f"{name}: no column {', '.join(map(repr, missing))} (columns: {have}); a reference needs t (s), v (m/s) "
            "and omega (rad/s)"
        )
    out = []
    for col in REFERENCE_COLUMNS:
        raw = frame[col]
        values = pd.to_numeric(raw, errors="coerce").to_numpy(dtype=np.float64, na_value=np.nan)
        bad = np.flatnonzero(np.isnan(values) & raw.notna().to_numpy())
        if bad.size:
            i = int(bad[0])
            raise LogFormatError(f"{name}: column {col!r} holds {raw.iloc[i]!r} at data row {i + 1}, not a number")
        out.append(values)
    return out[0], out[1], out[2]


def _one_line(err: BaseException) -> str:
    return " ".join(str(err).split())[:300]


def _read_mcap(name: str, topic: str | None) -> tuple[np.ndarray, np.ndarray, np.ndarray, str]:
    """(t s, v, omega, the topic read) of the Twist-like messages of one topic of an MCAP file."""
    from mcap.reader import make_reader  # mcap's reader (~20 ms): only an MCAP reference
    from mcap_ros2.decoder import DecoderFactory  # mcap_ros2's decoder (~25 ms): only an MCAP reference

    found: dict[str, list[tuple[int, Any, Any, bytes]]] = {}  # topic -> [(log time, schema, channel, payload)]
    other: set[str] = set()
    try:
        fh = open(name, "rb")  # noqa: SIM115 - closed below
    except OSError as err:
        raise UsageError(f"reference {name}: {cannot_read(err)}") from err
    try:
        with fh:
            reader = make_reader(fh)
            for schema, channel, message in reader.iter_messages(log_time_order=True):
                if schema is not None and schema.name in TWIST_TYPES:
                    if topic is None or channel.topic == topic:
                        found.setdefault(channel.topic, []).append((message.log_time, schema, channel, message.data))
                else:
                    other.add(channel.topic)
    except Exception as err:  # a damaged file: mcap's own errors, struct and seek errors on a file cut short, the
        # decompressors' (zstandard.ZstdError derives from Exception only): each is this file's fault, not ours
        raise LogFormatError(f"{name}: not a readable MCAP file ({_one_line(err) or type(err).__name__})") from err
    if not found:
        if topic is not None:
            raise LogFormatError(f"{name}: no Twist or TwistStamped messages on topic {topic!r}")
        listed = ", ".join(sorted(other)) or "no messages at all"
        raise LogFormatError(
            f"{name}: no geometry_msgs/msg/Twist or TwistStamped messages (topics: {listed}); a reference MCAP holds "
            "the speeds to drive as Twist messages"
        )
    if len(found) > 1:
        raise LogFormatError(
            f"{name}: Twist messages on {len(found)} topics ({', '.join(sorted(found))}); name the one to read"
        )
    ((chosen, rows),) = found.items()
    factory = DecoderFactory()
    decoders: dict[int, Any] = {}
    n = len(rows)
    ns = np.empty(n, dtype=np.int64)
    v = np.empty(n)
    omega = np.empty(n)
    for i, (log_time, schema, channel, payload) in enumerate(rows):
        decoder = decoders.get(schema.id)
        if decoder is None:
            if channel.message_encoding != "cdr":
                raise LogFormatError(
                    f"{name}: topic {chosen} is encoded as {channel.message_encoding!r}; a reference is read from CDR "
                    "(ROS 2) messages"
                )
            decoder = factory.decoder_for(channel.message_encoding, schema)
            if decoder is None:
                raise LogFormatError(f"{name}: cannot decode {schema.name} with schema encoding {schema.encoding!r}")
            decoders[schema.id] = decoder
        try:
            msg = decoder(payload)
            twist = msg.twist if schema.name == TWIST_TYPES[1] else msg
            v[i], omega[i] = float(twist.linear.x), float(twist.angular.z)
        except Exception as err:  # a damaged payload: mcap_ros2 raises several kinds of error
            raise LogFormatError(
                f"{name}: message {i + 1} on {chosen} cannot be decoded as {schema.name} ({_one_line(err)})"
            ) from err
        ns[i] = log_time
    t = (ns - ns[0]) / 1e9
    return t, v, omega, chosen
