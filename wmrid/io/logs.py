"""Reading and writing wheel logs (CSV and Parquet) as one log type, :class:`WheelLog`.

Canonical columns: ``t`` (s), ``eta_r``, ``eta_l`` (rad/s; right wheel = eta_1, left = eta_2),
``tau_r``, ``tau_l`` (N m); optional pose ``x``, ``y`` (m), ``phi`` (rad).  Other columns are ignored.
``--columns t=time,eta_r=vel_right`` maps canonical names to the names in a file.

Format: by suffix (``.csv .txt .tsv`` -> CSV, ``.parquet .pq`` -> Parquet, ``.mcap`` -> MCAP); any other
suffix, and standard input (``-``), by the first bytes (:func:`detect_format`).

CSV delimiter (:func:`sniff_delimiter`): among the first 20 non-blank lines, the first of tab, ``;``, ``,``
that occurs equally often (at least once) on every line; else the first that occurs in the header;
else runs of whitespace when the header splits into several words.  A ``;``-delimited file whose data
rows hold ``digit,digit`` is read with decimal commas (and a note says so).  Comma/tab/semicolon files
are parsed by the multithreaded pyarrow engine; whitespace, decimal-comma and ``", "``-spaced files, and
any file pyarrow refuses, by pandas' C engine with round-trip-exact float parsing.

Time (:func:`seconds_from_stamps`): ``time_unit="auto"`` reads a floating-point column as seconds and an
INTEGER column as integer nanoseconds (the ROS convention), with a note; a floating-point column
reaching 1e16 (1e13) is read as nanoseconds (microseconds) since the epoch, since as seconds it would
span 300,000 years, with a note. Rows stamped 0 among epoch times (a clock not yet set) are dropped,
with a note. Stamps are converted to float64 seconds once, here. They keep their absolute value (as in
the file) while float64 resolves them to 1 ns or better, i.e. while the largest |t| < 2**23 s (about 97
days; float64 spacing there is 2**-30 s < 1 ns). Converted stamps beyond that (epoch stamps such as
1.7e18 ns) are stored relative to the first stamp — subtracted in exact integer arithmetic for integer
columns, before any rounding — and a note gives the first stamp. A float column already in seconds is
kept exactly as in the file whatever its size: converting it loses nothing.

Row numbers in messages: for CSV the line of the file as an editor counts it (header = line 1); for
Parquet the 1-based data row.

Pieces (:func:`open_log`, :class:`LogStream`): CSV and Parquet logs are read CHUNK_ROWS rows at a time
(Parquet one row group at a time), so ``wmrid identify`` needs the same memory for a 4 h log as for a
1 h one.  Every row is checked as when the log is read whole; the log-wide choices (time unit, offset,
epoch-like stamps) are made on the first piece with rows.  MCAP recordings of more than a million
JointState messages are summarised in a first pass (topics, joints, time sources) and then decoded chunk
by chunk, split topics aligned across pieces; the few layouts that cannot stream exactly (speeds derived
from positions, messages out of time order, ...) are decoded whole, with a note saying why.
"""

from __future__ import annotations

import difflib
import errno
import io
import os
import re
import sys
from collections.abc import Callable, Generator, Iterable, Iterator, Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

import numpy as np

from wmrid.core.errors import LogFormatError, UsageError
from wmrid.core.limits import memory_budget, read_limited
from wmrid.io.mcap.joints import TopicSelection
from wmrid.io.signals import SignalOptions, convert

if TYPE_CHECKING:
    import pandas

__all__ = [
    "CANONICAL",
    "MIN_SAMPLES",
    "REQUIRED",
    "LogStream",
    "WheelLog",
    "detect_format",
    "open_log",
    "parse_column_mapping",
    "read_log",
    "read_metadata",
    "seconds_from_stamps",
    "sniff_delimiter",
    "stream_arrays",
    "write_log",
]

REQUIRED = ("t", "eta_r", "eta_l", "tau_r", "tau_l")
POSE = ("x", "y", "phi")
#: Optional wheel-speed reference (set-points, rad/s): the instruments of ``--method iv`` (:mod:`wmrid.estimators.iv`).
REFERENCE = ("eta_ref_r", "eta_ref_l")
CANONICAL = REQUIRED + POSE + REFERENCE
TIME_UNITS = ("auto", "s", "ms", "us", "ns")
MIN_SAMPLES = 10
_NS_PER_UNIT = {"s": 1_000_000_000, "ms": 1_000_000, "us": 1_000, "ns": 1}
_PER_SECOND = {"s": 1.0, "ms": 1e3, "us": 1e6, "ns": 1e9}
ABSOLUTE_LIMIT_S = float(2**23)  # float64 spacing below this is <= 2**-30 s < 1 ns
_CSV_SUFFIXES = (".csv", ".txt", ".tsv")
_PARQUET_SUFFIXES = (".parquet", ".pq")
_MCAP_SUFFIXES = (".mcap",)
_PARQUET_MAGIC = b"PAR1"
_MCAP_MAGIC = b"\x89MCAP"
_SNIFF_BYTES = 65536
_COMMENT_MARKS = ("%", "#")
_EPOCH_LIKE_S = 1e9  # stamps beyond this (2001 in s since the epoch; any ms/us/ns epoch time) are clock times
_STDIN_NAME = "<stdin>"


@dataclass(frozen=True)
class WheelLog:
    """One wheel log in SI units.

    t : (n,) float64, s, strictly increasing (as in the file; relative to the first stamp only when
        the notes say so).
    eta : (n, 2) float64, rad/s, columns [right, left].
    tau : (n, 2) float64, N m, columns [right, left].
    source : the file name as the user gave it (``"<stdin>"`` for ``-``).
    notes : plain-English statements of what was assumed while reading.
    pose : (n, 3) float64 [x m, y m, phi rad] when the log has x, y, phi; else None.
    reference : (n, 2) float64 rad/s, the wheel-speed reference (set-points) [right, left] when the log has
        eta_ref_r, eta_ref_l; else None.
    effort_unit : "N m" for a torque; else the unit of a PWM or voltage effort that could not be
        converted (tau then holds that effort, and the parameters come out in its units).
    """

    t: np.ndarray
    eta: np.ndarray
    tau: np.ndarray
    source: str
    notes: tuple[str, ...] = ()
    pose: np.ndarray | None = None
    effort_unit: str = "N m"
    reference: np.ndarray | None = None

    def __post_init__(self) -> None:
        n = np.shape(self.t)[0] if np.ndim(self.t) == 1 else -1
        if n < 0:
            raise ValueError(f"WheelLog.t must be 1-D, got shape {np.shape(self.t)}")
        for name, arr, width in (
            ("eta", self.eta, 2), ("tau", self.tau, 2), ("pose", self.pose, 3), ("reference", self.reference, 2)
        ):  # fmt: skip
            if arr is not None and np.shape(arr) != (n, width):
                raise ValueError(f"WheelLog.{name} must have shape ({n}, {width}), got {np.shape(arr)}")

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @property
    def duration(self) -> float:
        """Time from the first to the last sample, s."""
        return float(self.t[-1] - self.t[0]) if len(self) else 0.0


# --------------------------------------------------------------------------------------------------
# Streams: a log read piece by piece


#: Rows per piece when a log is read in pieces (about 10 MB of t, eta, tau).
CHUNK_ROWS = 262_144
#: A stream keeps its pieces after the first pass when the log has at most this many samples (160 MB;
#: about 70 min at 1 kHz), so that a second pass (identify's replay) does not read the file again; longer
#: logs are re-read, so memory never exceeds this cache plus one piece.
CACHE_ROWS = 4_194_304


class LogStream:
    """A wheel log that yields :class:`WheelLog` pieces in time order and can be iterated again.

    source : the file name for messages.  effort_unit : as in :class:`WheelLog`.
    Iterating reads the file (or, for a log of at most CACHE_ROWS samples, the pieces kept from the first
    pass).  A pass raises :class:`LogFormatError` at the first unusable row, as :func:`read_log` does, and
    checks across pieces what :func:`read_log` checks across rows (time strictly increasing, one time
    unit).  ``notes`` (what was assumed while reading) and ``samples`` are set when a pass ends.
    Memory: one piece (at most CHUNK_ROWS samples) at a time, whatever the log's length.
    """

    def __init__(self, source: str, effort_unit: str, pieces: Callable[[], Generator[WheelLog, None, tuple[str, ...]]]):
        self.source = source
        self.effort_unit = effort_unit
        self._pieces = pieces
        self._cache: list[WheelLog] | None = None
        self.notes: tuple[str, ...] = ()
        self.samples: int | None = None

    def __iter__(self) -> Iterator[WheelLog]:
        if self._cache is not None:
            yield from self._cache
            return
        kept: list[WheelLog] | None = []
        count = 0
        gen = self._pieces()
        while True:
            try:
                piece = next(gen)
            except StopIteration as stop:
                notes = tuple(stop.value or ())
                break
            count += len(piece)
            if kept is not None:
                kept.append(piece)
                if count > CACHE_ROWS:
                    kept = None
            yield piece
        if self.samples is not None and count != self.samples:
            raise LogFormatError(
                f"{self.source}: the file changed while it was read ({self.samples} samples, then {count}); "
                "identify a copy that is not being written"
            )
        self.samples, self.notes, self._cache = count, notes, kept

    def read(self) -> WheelLog:
        """The whole log as one :class:`WheelLog` (memory: the whole log)."""
        pieces = list(self)
        poses = [p.pose for p in pieces]
        pose = np.concatenate(poses) if all(p is not None for p in poses) else None
        refs = [p.reference for p in pieces]
        reference = np.concatenate(refs) if refs and all(r is not None for r in refs) else None
        return WheelLog(
            t=np.concatenate([p.t for p in pieces]), eta=np.concatenate([p.eta for p in pieces]),
            tau=np.concatenate([p.tau for p in pieces]), source=self.source, notes=self.notes, pose=pose,
            effort_unit=self.effort_unit, reference=reference,
        )  # fmt: skip


def stream_arrays(log: Any, rows: int = CHUNK_ROWS) -> LogStream:
    """A :class:`LogStream` over a log already in memory (t, eta, tau arrays; source, notes, effort_unit; pose and
    reference when it has them)."""
    t, eta, tau = log.t, log.eta, log.tau
    pose, reference = getattr(log, "pose", None), getattr(log, "reference", None)
    source = getattr(log, "source", "log")
    unit = getattr(log, "effort_unit", "N m")
    notes = tuple(getattr(log, "notes", ()))

    def pieces() -> Generator[WheelLog, None, tuple[str, ...]]:
        for start in range(0, len(t), rows):
            stop = start + rows
            yield WheelLog(
                t=t[start:stop], eta=eta[start:stop], tau=tau[start:stop], source=source, effort_unit=unit,
                pose=None if pose is None else pose[start:stop],
                reference=None if reference is None else reference[start:stop],
            )  # fmt: skip
        return notes

    return LogStream(source, unit, pieces)


# --------------------------------------------------------------------------------------------------
# Column mapping


def _suggest(name: str, candidates: list[str] | tuple[str, ...], cutoff: float = 0.6) -> str | None:
    """The closest candidate to ``name`` (case-insensitive difflib match), if any is close."""
    lowered = {c.lower(): c for c in candidates}
    hit = difflib.get_close_matches(name.lower(), list(lowered), n=1, cutoff=cutoff)
    return lowered[hit[0]] if hit else None


def parse_column_mapping(text: str) -> dict[str, str]:
    """Parse the ``--columns`` option: ``"t=time,eta_r=vel_right,tau_l=effort_left"``.

    Keys are canonical names (t, eta_r, eta_l, tau_r, tau_l, x, y, phi); values are column names in the
    log.  Returns {canonical: source name}.  Raises :class:`UsageError` on anything else.
    """
    mapping: dict[str, str] = {}
    example = "t=time,eta_r=vel_right,tau_l=effort_left"
    for item in text.split(","):
        item = item.strip()
        if not item:
            continue
        key, sep, value = item.partition("=")
        key, value = key.strip(), value.strip()
        if not sep or not key or not value:
            raise UsageError(f"--columns: {item!r} is not NAME=COLUMN; write e.g. --columns {example}")
        _check_key(key, "--columns")
        if key in mapping:
            raise UsageError(f"--columns: {key!r} is given twice ({mapping[key]!r} and {value!r})")
        mapping[key] = value
    if not mapping:
        raise UsageError(f"--columns is empty; write e.g. --columns {example}")
    seen: dict[str, str] = {}
    for key, value in mapping.items():
        if value in seen:
            raise UsageError(
                f"--columns maps both {seen[value]} and {key} to the column {value!r}; each needs its own column"
            )
        seen[value] = key
    return mapping


def _check_key(key: str, what: str) -> None:
    if key not in CANONICAL:
        close = _suggest(key, CANONICAL)
        hint = f" (did you mean {close!r}?)" if close else ""
        raise UsageError(f"{what}: {key!r} is not a column wmrid knows{hint}; use one of {', '.join(CANONICAL)}")


# --------------------------------------------------------------------------------------------------
# Format detection


#: (magic bytes, what the file is, the fix) of formats wmrid recognises but does not read.
_OTHER_FORMATS = (
    (b"\x1f\x8b", "a gzip-compressed file", "decompress it first (gunzip -k FILE) and give the log inside"),
    (b"\x28\xb5\x2f\xfd", "a zstd-compressed file", "decompress it first (zstd -d FILE) and give the log inside"),
    (b"BZh", "a bzip2-compressed file", "decompress it first (bunzip2 -k FILE) and give the log inside"),
    (b"\xfd7zXZ\x00", "an xz-compressed file", "decompress it first (unxz -k FILE) and give the log inside"),
    (b"PK\x03\x04", "a zip archive", "unpack it first and give the log inside"),
    (b"#ROSBAG", "a ROS 1 bag", "convert it to MCAP first (mcap convert FILE out.mcap)"),
    (b"SQLite f", "an SQLite database (a ROS 2 .db3 bag?)", "convert it to MCAP first (ros2 bag convert)"),
)


def detect_format(path: str, head_bytes: bytes) -> str:
    """``"csv"``, ``"parquet"`` or ``"mcap"``: from the suffix of ``path``, else from the magic bytes.

    ``path`` ``"-"`` (standard input) or an unknown suffix: ``PAR1`` -> parquet, ``\\x89MCAP`` -> mcap,
    anything else -> csv.  A compressed file, an archive, a ROS 1 bag or an SQLite database (whatever its suffix)
    is refused with LogFormatError naming what it is and how to get a log out of it.
    """
    suffix = os.path.splitext(path)[1].lower() if path != "-" else ""
    for magic, what, fix in _OTHER_FORMATS:
        if head_bytes.startswith(magic):
            name = _STDIN_NAME if path == "-" else path
            raise LogFormatError(f"{name}: {what}, not a CSV, Parquet or MCAP log; {fix}")
    if suffix in _CSV_SUFFIXES:
        return "csv"
    if suffix in _PARQUET_SUFFIXES:
        return "parquet"
    if suffix in _MCAP_SUFFIXES:
        return "mcap"
    if head_bytes.startswith(_PARQUET_MAGIC):
        return "parquet"
    if head_bytes.startswith(_MCAP_MAGIC):
        return "mcap"
    return "csv"


# --------------------------------------------------------------------------------------------------
# Reading


@dataclass
class _Source:
    """Where the log's bytes are: a regular file (``path``) or bytes already read (``data``)."""

    name: str  # for messages
    path: str | None
    data: bytes | None

    def head(self, size: int = _SNIFF_BYTES) -> bytes:
        if self.data is not None:
            return self.data[:size]
        with open(self.path, "rb") as fh:  # type: ignore[arg-type]
            return fh.read(size)

    def opener(self) -> Any:
        """What pandas/pyarrow read from: the path, or a fresh in-memory stream."""
        return self.path if self.data is None else io.BytesIO(self.data)


#: The message for a pipe, a device or standard input that holds more than the memory budget ({size}: the budget).
_ENDLESS = (
    "{name}: {what} holds more than {{size}}, the memory budget (WMRID_MEMORY_BUDGET); an endless source? save the "
    "log to a file, which wmrid reads piece by piece"
)


def _open_source(path: str) -> _Source:
    if path == "-":
        if sys.stdin is None or sys.stdin.isatty():
            raise UsageError("log '-' means standard input, but nothing is piped in; give a file or pipe one in")
        data = read_limited(sys.stdin.buffer, memory_budget(), _ENDLESS.format(name=_STDIN_NAME, what="standard input"))
        if not data:
            raise LogFormatError(f"{_STDIN_NAME}: standard input is empty; pipe a CSV or Parquet log into it")
        return _Source(_STDIN_NAME, None, data)
    if os.path.islink(path) and not os.path.exists(path):
        try:
            os.stat(path)
        except OSError as err:
            if err.errno == errno.ELOOP:
                raise LogFormatError(f"{path}: a symbolic link that loops back on itself; give the log file") from None
        raise LogFormatError(
            f"{path}: a symbolic link to {os.readlink(path)!r}, which does not exist; fix the link or give the log file"
        )
    if not os.path.exists(path):
        folder = os.path.dirname(path) or "."
        hint = ""
        if os.path.isdir(folder):
            close = _suggest(os.path.basename(path), sorted(os.listdir(folder)), cutoff=0.8)
            hint = f" (did you mean {os.path.join(os.path.dirname(path), close)!r}?)" if close else ""
        raise LogFormatError(f"{path}: no such file{hint}; check the path")
    if os.path.isdir(path):
        raise LogFormatError(f"{path}: is a folder, not a log file; give the CSV or Parquet file inside it")
    try:
        if not os.path.isfile(path):  # a pipe such as <(command), or a device: read it once, within the budget
            data = read_limited(path, memory_budget(), _ENDLESS.format(name=path, what="it is not a regular file and"))
            source = _Source(path, None, data)
            size = len(data)
        else:
            with open(path, "rb"):
                pass  # fail here, with a clear message, if it cannot be read
            source = _Source(path, path, None)
            size = os.path.getsize(path)
    except OSError as err:
        raise LogFormatError(f"{path}: cannot be read ({err.strerror or err}); check its permissions") from err
    if size == 0:
        raise LogFormatError(f"{path}: the file is empty (0 bytes); give a log with a header and data rows")
    return source


def read_log(
    path: str,
    *,
    columns: Mapping[str, str] | None = None,
    time_unit: str = "auto",
    selection: TopicSelection | None = None,
    signals: SignalOptions | None = None,
    gear_ratio: float | None = None,
    data: bytes | None = None,
) -> WheelLog:
    """Read a wheel log from a CSV, Parquet or MCAP file, or from standard input for ``"-"``.

    columns : {canonical name: name in the file} for columns not named canonically (for a JSON topic
        of an MCAP: {key: dotted field path}).
    time_unit : ``"auto"`` (float -> s, integer -> ns), ``"s"``, ``"ms"``, ``"us"`` or ``"ns"``.
    data : the log's bytes when the caller has already read them (e.g. standard input it had to peek
        at); ``path`` then only names the log.
    selection : MCAP topics, joints, time source and alignment (:mod:`wmrid.io.mcap.joints`).
    signals : what the speed and effort columns hold (:mod:`wmrid.io.signals`); gear_ratio : the robot's
        k_r, used to turn a motor current into a wheel torque when --gear-ratio is not given.

    The file is opened read-only.  Raises :class:`LogFormatError` (one line naming the file, the row or
    column at fault and the fix) for anything that is not a usable log.  :func:`open_log` reads the same
    log piece by piece.
    """
    return open_log(
        path, columns=columns, time_unit=time_unit, selection=selection, signals=signals, gear_ratio=gear_ratio,
        data=data,
    ).read()  # fmt: skip


def open_log(
    path: str,
    *,
    columns: Mapping[str, str] | None = None,
    time_unit: str = "auto",
    selection: TopicSelection | None = None,
    signals: SignalOptions | None = None,
    gear_ratio: float | None = None,
    data: bytes | None = None,
    rows: int = CHUNK_ROWS,
) -> LogStream:
    """The log of :func:`read_log` (same arguments) as a :class:`LogStream` of pieces of ``rows`` samples.

    CSV and Parquet logs are read piece by piece (bounded memory); so are MCAP recordings, except the
    layouts listed in the module docstring, which are decoded whole and then handed out in pieces.
    The file's layout (format, columns, delimiter) is checked here; the rows are checked as the pieces
    are read.
    """
    if time_unit not in TIME_UNITS:
        raise UsageError(f"--time-unit {time_unit!r} is not one of {', '.join(TIME_UNITS)}")
    mapping = {key: key for key in CANONICAL}
    for key, value in (columns or {}).items():
        _check_key(key, "--columns")
        mapping[key] = value
    explicit = set(columns or ())

    if data is None and path != "-":
        from wmrid.core.atomic import register_input

        register_input(path)  # an output of this command may not be this file
    source = _open_source(path) if data is None else _Source(_STDIN_NAME if path == "-" else path, None, data)
    kind = detect_format(path, source.head(8))
    signals = signals or SignalOptions()
    if kind == "mcap":
        if explicit & set(REFERENCE):
            named = ", ".join(sorted(explicit & set(REFERENCE)))
            raise UsageError(
                f"{source.name}: --columns {named}: the wheel-speed reference is read from CSV and Parquet logs only "
                "so far; export the set-points as columns of one"
            )
        return _read_mcap_log(source, columns or {}, selection or TopicSelection(), signals, gear_ratio, rows)
    if kind == "parquet":
        chunks, where, notes, hint = _parquet_chunks(source, mapping, explicit, rows)
    else:
        chunks, where, notes, hint = _csv_chunks(source, mapping, explicit, rows)
    effort_unit = "N m" if signals == SignalOptions() else signals.effort_label

    def pieces() -> Generator[WheelLog, None, tuple[str, ...]]:
        assembler = _Assembler(source.name, mapping, time_unit, hint, where, bool(explicit & set(REFERENCE)))
        signal_notes: list[str] = []
        for base, values in chunks():
            piece = assembler.add(values, base)
            if piece is None:
                continue
            if signals != SignalOptions():
                eta, tau, signal_notes = convert(piece.eta, piece.tau, signals, gear_ratio)
                reference = piece.reference
                if reference is not None:  # set-points in the speeds' unit and sense
                    reference = convert(reference, piece.tau, signals, gear_ratio)[0]
                piece = WheelLog(
                    t=piece.t, eta=eta, tau=tau, source=piece.source, pose=piece.pose, effort_unit=effort_unit,
                    reference=reference,
                )  # fmt: skip
            yield piece
        return (*notes, *assembler.finish(), *signal_notes)

    return LogStream(source.name, effort_unit, pieces)


#: An MCAP whose JointState topics hold at most this many pieces' worth of messages is decoded whole, in one
#: pass (a stream of that length keeps its samples in memory anyway); a longer one is streamed.
_MCAP_WHOLE_PIECES = 4  # pieces of CHUNK_ROWS: bags of up to ~1 M messages are decoded in one pass


def _read_mcap_log(
    source: _Source,
    columns: Mapping[str, str],
    selection: TopicSelection,
    signals: SignalOptions,
    gear_ratio: float | None,
    rows: int = CHUNK_ROWS,
) -> LogStream:
    """An MCAP recording as a LogStream: JointState topics (or a JSON topic with field paths).

    A first pass (:func:`wmrid.io.mcap.reader.scan_mcap`) reads the file record by record.  When its JointState
    topics hold at most ``_MCAP_WHOLE_PIECES * rows`` messages, that pass keeps them and the log is assembled
    whole (:func:`_mcap_whole_log`).  A longer recording keeps only a summary per topic; the topic, joint and
    time choices are made from it and each pass over the stream decodes the file again, a batch of records
    at a time (:func:`_mcap_pieces`): memory does not grow with the recording, and the samples and notes are
    those of the whole decode.  Read whole all the same, with a note saying why: speeds derived from
    positions, messages out of time order in the file, and the other cases :func:`wmrid.io.mcap.joints.stream_plan`
    lists; a JSON topic is always read whole.
    """
    from wmrid.io.mcap.joints import stream_plan
    from wmrid.io.mcap.reader import read_mcap, scan_mcap

    path = source.path or source.name
    if columns and selection.topic:
        missing = [k for k in REQUIRED[1:] if k not in columns]
        if missing:
            raise UsageError(f"a JSON topic needs field paths for {', '.join(missing)} in --columns")
        contents = read_mcap(path, data=source.data, json_fields={selection.topic: dict(columns)})
        return stream_arrays(_mcap_whole_log(source, contents, selection, signals, gear_ratio), rows)
    contents = scan_mcap(path, source.data, keep=_MCAP_WHOLE_PIECES * rows)
    if contents.complete:
        return stream_arrays(_mcap_whole_log(source, contents, selection, signals, gear_ratio), rows)
    plan, why = stream_plan(contents, selection, signals, gear_ratio)
    relative = False
    if why is None:  # seconds_from_stamps' choice, from the range of the stamps that can come out
        times = plan.vel.times[plan.vel_time]
        limit = ABSOLUTE_LIMIT_S * _NS_PER_UNIT["s"]
        relative = times.low >= limit
        if not relative and not (times.high < limit and times.low > -limit):
            why = "its stamps cross the limit of absolute float64 times"
    if why is not None:
        from dataclasses import replace

        whole = _mcap_whole_log(source, read_mcap(path, data=source.data), selection, signals, gear_ratio)
        note = f"the recording was decoded whole (memory grows with its length): {why}"
        return stream_arrays(replace(whole, notes=(*whole.notes, note)), rows)
    return _mcap_pieces(source, contents, plan, selection, signals, gear_ratio, rows, relative)


def _mcap_whole_log(
    source: _Source, contents: Any, selection: TopicSelection, signals: SignalOptions, gear_ratio: float | None
) -> WheelLog:
    """The WheelLog of a recording read whole (:class:`wmrid.io.mcap.reader.McapContents` with its arrays)."""
    from wmrid.io.mcap.joints import signals_from_json, signals_from_mcap

    if selection.topic in contents.json:
        sig = signals_from_json(contents, selection.topic, signals, gear_ratio)
    else:
        sig = signals_from_mcap(contents, selection, signals, gear_ratio)
    notes = list(contents.notes) + list(sig.notes)
    _mcap_check_count(source, len(sig.t_ns))
    t, offset = seconds_from_stamps(sig.t_ns, "ns")
    if offset is not None:
        notes.append(f"time relative to the first stamp, {offset} ns")
    _mcap_check_finite(source, t, sig.speed, sig.effort)
    eta = np.ascontiguousarray(sig.speed, dtype=np.float64)
    tau = np.ascontiguousarray(sig.effort, dtype=np.float64)
    return WheelLog(t=t, eta=eta, tau=tau, source=source.name, notes=tuple(notes), effort_unit=sig.effort_unit)


def _mcap_check_count(source: _Source, n: int) -> None:
    if n < MIN_SAMPLES:
        raise LogFormatError(
            f"{source.name}: only {n} usable samples after reading the topics; identification needs "
            f"at least {MIN_SAMPLES}"
        )


def _mcap_check_finite(source: _Source, t: np.ndarray, speed: np.ndarray, effort: np.ndarray) -> None:
    for arr, what in ((speed, "speed"), (effort, "effort")):
        bad = ~np.isfinite(arr)
        if bad.any():
            raise LogFormatError(
                f"{source.name}: a wheel {what} is not a finite number at t = {t[np.argmax(bad.any(axis=1))]:.6g} s"
            )


def _mcap_pieces(
    source: _Source,
    contents: Any,
    plan: Any,
    selection: TopicSelection,
    signals: SignalOptions,
    gear_ratio: float | None,
    rows: int,
    relative: bool,
) -> LogStream:
    """The streamed LogStream of a long recording (see :func:`_read_mcap_log`): pieces of exactly ``rows``
    samples, as :func:`stream_arrays` cuts the whole log.  Its ``_mcap_peak`` is the most JointState samples
    the last pass held at once (decoded, waiting and cut into pieces)."""
    from wmrid.io.mcap.joints import SignalStream
    from wmrid.io.mcap.reader import iter_joint_parts

    path = source.path or source.name
    unit = signals.effort_label
    per_s = float(_NS_PER_UNIT["s"])

    def pieces() -> Generator[WheelLog, None, tuple[str, ...]]:
        signal = SignalStream(plan, selection, signals, gear_ratio, source.name, rows)
        ready: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        state = {"ready": 0, "total": 0, "offset": None, "error": None, "peak": 0}

        def take(batch: list[tuple[np.ndarray, np.ndarray, np.ndarray]]) -> None:
            for t_ns, speed, effort in batch:
                if state["offset"] is None and relative:
                    state["offset"] = int(t_ns[0])
                if relative:
                    t = (t_ns - np.int64(state["offset"])).astype(np.float64) / per_s
                else:
                    t = t_ns.astype(np.float64) / per_s
                if state["error"] is None:
                    try:
                        _mcap_check_finite(source, t, speed, effort)
                    except LogFormatError as err:
                        state["error"] = err  # raised once the log is known to have MIN_SAMPLES samples
                ready.append((t, np.ascontiguousarray(speed, dtype=np.float64),
                              np.ascontiguousarray(effort, dtype=np.float64)))  # fmt: skip
                state["ready"] += len(t)
                state["total"] += len(t)
            if state["error"] is not None and state["total"] >= MIN_SAMPLES:
                raise state["error"]

        def cut(final: bool) -> Iterator[WheelLog]:
            if not ready or (state["ready"] < rows and not final) or state["total"] < MIN_SAMPLES:
                return
            t, eta, tau = (np.concatenate([r[i] for r in ready]) for i in range(3))
            ready.clear()
            start = 0
            while len(t) - start >= rows or (final and start < len(t)):
                stop = min(start + rows, len(t))
                yield WheelLog(t=t[start:stop], eta=eta[start:stop], tau=tau[start:stop], source=source.name,
                               effort_unit=unit)  # fmt: skip
                start = stop
            if start < len(t):
                ready.append((t[start:], eta[start:], tau[start:]))
            state["ready"] = len(t) - start

        for parts in iter_joint_parts(path, source.data, signal.channels):
            decoded = sum(len(p[0]) for got in parts.values() for p in got)
            take(signal.feed(parts))
            state["peak"] = max(state["peak"], decoded + signal.held + state["ready"])
            stream._mcap_peak = state["peak"]  # type: ignore[attr-defined]
            yield from cut(final=False)
        take(signal.finish())
        _mcap_check_count(source, state["total"])
        if state["error"] is not None:
            raise state["error"]
        yield from cut(final=True)
        notes = [*contents.notes, *signal.notes()]
        if relative:
            notes.append(f"time relative to the first stamp, {state['offset']} ns")
        return tuple(notes)

    stream = LogStream(source.name, unit, pieces)
    stream._mcap_peak = 0  # type: ignore[attr-defined]
    return stream


def _select(present: list[str], mapping: dict[str, str], explicit: set[str], name: str) -> dict[str, str]:
    """{canonical: column in the file} for the required columns and, when all three exist, the pose.

    Raises one :class:`LogFormatError` naming every missing column, the columns there are, close
    matches, and the ``--columns`` option that would fix it.
    """
    needed = list(REQUIRED) + [k for k in POSE if k in explicit]
    if explicit & set(REFERENCE):  # one reference column named: both are needed
        needed += list(REFERENCE)
    missing = [k for k in needed if mapping[k] not in present]
    if missing:
        parts, fixes = [], []
        taken = {mapping[k] for k in needed if k not in missing}
        free = [c for c in present if c not in taken]
        for key in missing:
            col = mapping[key]
            close = _suggest(col, free, cutoff=0.7)
            if close:
                free.remove(close)
            origin = f" (given for {key} by --columns)" if key in explicit else ""
            parts.append(f"{col!r}{origin}" + (f" (did you mean {close!r}?)" if close else ""))
            fixes.append(f"{key}={close or '...'}")
        shown = ", ".join(repr(c) for c in present[:20])
        if len(present) > 20:
            shown += f", ... ({len(present)} in all)"
        label = "column" if len(missing) == 1 else "columns"
        raise LogFormatError(
            f"{name}: no {label} {', '.join(parts)}; the columns are {shown or 'none'}; "
            f"name the log's columns with --columns {','.join(fixes)}"
        )
    chosen = {key: mapping[key] for key in REQUIRED}
    for optional in (POSE, REFERENCE):
        if all(mapping[k] in present for k in optional):
            chosen.update({key: mapping[key] for key in optional})
    return chosen


# ---- Parquet


def _parquet_chunks(
    source: _Source, mapping: dict[str, str], explicit: set[str], rows: int
) -> tuple[Callable[[], Iterator[tuple[int, dict[str, Any]]]], Callable[[int], str], list[str], str | None]:
    """(chunks, where, notes, time unit hint) of a Parquet log; ``chunks()`` yields (first row, columns)."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    name = source.name

    def opened() -> Any:
        try:
            return pa.OSFile(source.path, "r") if source.path is not None else pa.BufferReader(source.data)
        except (pa.ArrowException, OSError) as err:
            raise LogFormatError(f"{name}: cannot be opened ({_one_line(err)})") from err

    def broken(err: BaseException) -> LogFormatError:
        return LogFormatError(
            f"{name}: not a readable Parquet file ({_one_line(err)}); it may be truncated or corrupt — "
            "write it again or export the log as CSV"
        )

    with opened() as stream:
        try:
            pf = pq.ParquetFile(stream)
            present = list(pf.schema_arrow.names)
            if pf.metadata.num_rows == 0:
                raise LogFormatError(f"{name}: the Parquet file has no rows; give a log with {MIN_SAMPLES}+ samples")
            schema = pf.schema_arrow
        except (pa.ArrowException, OSError) as err:
            raise broken(err) from err
    chosen = _select(present, mapping, explicit, name)
    twice = sorted({c for c in chosen.values() if present.count(c) > 1})
    if twice:
        raise LogFormatError(
            f"{name}: the Parquet file has {len(twice)} column name(s) used twice ({', '.join(map(repr, twice))}), so "
            "wmrid cannot tell which to read; rename one of each pair when writing the file"
        )
    wanted = list(dict.fromkeys(chosen.values()))
    notes: list[str] = []
    hint = None
    typ = schema.field(chosen["t"]).type
    if pa.types.is_timestamp(typ) or pa.types.is_duration(typ):
        hint = typ.unit
        notes.append(f"time column {chosen['t']!r} is a Parquet {typ} column; read in its own unit, {typ.unit}")

    def chunks() -> Iterator[tuple[int, dict[str, Any]]]:
        base = 0
        with opened() as stream:
            try:
                pf = pq.ParquetFile(stream)
                # One row group at a time: iter_batches over the whole file reads ahead and held ~40 % of a 4 h
                # log at once.  A row group too large to hold decoded (a 2 MB file can hold 100 M rows of zeros
                # in one) is read in slices of ``rows`` instead: 35 MB of Arrow memory for 20 M rows, not 1.2 GB.
                for group in range(pf.num_row_groups):
                    decoded = pf.metadata.row_group(group).num_rows * len(wanted) * 8
                    if decoded > ROW_GROUP_SLICE_BYTES:
                        batches: Iterable[Any] = pf.iter_batches(
                            batch_size=rows, row_groups=[group], columns=wanted, use_threads=False
                        )
                        table = None
                    else:
                        table = pf.read_row_group(group, columns=wanted, use_threads=True)
                        batches = table.to_batches(max_chunksize=rows)
                    for batch in batches:
                        values = {key: _arrow_values(batch.column(col), key == "t") for key, col in chosen.items()}
                        yield base, values
                        base += batch.num_rows
                    del table, batches
            except (pa.ArrowException, OSError) as err:
                raise broken(err) from err

    return chunks, lambda i: f"row {i + 1}", notes, hint


def _arrow_values(arr: Any, is_time: bool = False) -> Any:
    """A column of an Arrow batch as numpy (numbers; nulls -> NaN) or, for anything else, a pandas Series."""
    import pyarrow as pa

    if is_time and (pa.types.is_timestamp(arr.type) or pa.types.is_duration(arr.type)):
        arr = arr.cast(pa.int64())
    if pa.types.is_integer(arr.type) or pa.types.is_floating(arr.type):
        if arr.null_count:
            return arr.to_numpy(zero_copy_only=False).astype(np.float64)  # nulls -> NaN
        return _primitive_to_numpy(arr)
    return arr.to_pandas()  # strings, bools, decimals...: checked cell by cell


def _primitive_to_numpy(arr: Any) -> np.ndarray:
    """A numeric Arrow array without nulls as a numpy view of its data buffer.

    ``pyarrow.Array.to_numpy`` imports pandas (a third of a second); the data buffer of a primitive
    array is already the numpy layout.
    """
    import pyarrow as pa

    kind = "f" if pa.types.is_floating(arr.type) else "i" if pa.types.is_signed_integer(arr.type) else "u"
    dtype = np.dtype(f"{kind}{arr.type.bit_width // 8}")
    return np.frombuffer(arr.buffers()[1], dtype=dtype, count=len(arr), offset=arr.offset * dtype.itemsize)


# ---- CSV


def sniff_delimiter(text: str) -> tuple[str, str]:
    """(delimiter, decimal) for CSV text; delimiter ``"\\s+"`` means runs of whitespace.

    See the module docstring for the rule.
    """
    lines = [ln for ln in text.splitlines() if ln.strip()][:20]
    if not lines:
        return ",", "."
    header, data = lines[0], lines[1:]
    chosen = None
    for cand in ("\t", ";", ","):
        counts = {ln.count(cand) for ln in lines}
        if len(counts) == 1 and counts.pop() > 0:
            chosen = cand
            break
    if chosen is None:
        chosen = next((c for c in ("\t", ";", ",") if c in header), None)
    if chosen is None:
        chosen = r"\s+" if len(header.split()) > 1 else ","
    decimal = "."
    if chosen == ";" and any(re.search(r"\d,\d", ln) for ln in data):
        decimal = ","
    return chosen, decimal


def _text_head(source: _Source) -> tuple[str, str, list[str]]:
    """The first bytes decoded; (text, encoding, notes).  Raises for binary or undecodable input."""
    head = source.head()
    name = source.name
    for magic, kind in ((_PARQUET_MAGIC, "parquet"), (_MCAP_MAGIC, "mcap")):
        if head.startswith(magic):
            raise LogFormatError(f"{name}: holds {kind.upper()} data, not CSV text; rename it with a .{kind} suffix")
    nul = head.find(b"\0")
    if nul >= 0:
        raise LogFormatError(f"{name}: not a CSV text file (byte {nul} is a NUL byte); give a CSV or Parquet log")
    try:
        return head.decode("utf-8-sig"), "utf-8", []
    except UnicodeDecodeError as err:
        if len(head) == _SNIFF_BYTES and err.start >= len(head) - 3 and "end of data" in err.reason:
            return head[: err.start].decode("utf-8-sig"), "utf-8", []  # a character cut by the sniff window
        text = head.decode("latin-1")
        if any((ord(ch) < 32 and ch not in "\t\r\n\f") or 0x7F <= ord(ch) < 0xA0 for ch in text):
            raise LogFormatError(
                f"{name}: not a CSV text file (byte {err.start} is not UTF-8 text); give a CSV or Parquet log"
            ) from err
        return text, "latin-1", [f"{name} is not UTF-8; read as Latin-1 text"]


def _csv_line_finder(source: _Source, skip: int = 0, has_header: bool = True) -> Callable[[int], str]:
    """Data index (0-based) -> ``"line N"``, counting every line of the file (line 1 is the first).

    skip : leading comment lines; has_header : whether a header line follows them.
    """

    def where(index: int) -> str:
        fh = open(source.path, "rb") if source.data is None else io.BytesIO(source.data)  # noqa: SIM115
        with fh:
            seen_header = not has_header
            count = -1
            for lineno, raw in enumerate(fh, start=1):
                if lineno <= skip or not raw.strip():
                    continue  # comments, and blank lines (skipped by both parsers)
                if not seen_header:
                    seen_header = True
                    continue
                count += 1
                if count == index:
                    return f"line {lineno}"
        return f"data row {index + 1}"

    return where


@dataclass
class _CsvLayout:
    """How a CSV file is laid out: options for pandas, its columns, notes, and a parse-error mapper."""

    c_options: dict[str, Any]
    header_columns: list[Any]
    present: list[str]
    notes: list[str]
    skip: int
    has_header: bool
    spaced: bool
    fail: Callable[[BaseException], LogFormatError]
    comments: list[str]


def _csv_layout(source: _Source) -> _CsvLayout:
    """Comments, delimiter, decimal mark, header (or positional names) of a CSV file; see the module docstring."""
    import pandas as pd

    name = source.name
    text, encoding, notes = _text_head(source)
    if "\n" not in text and "\r" not in text and len(source.head(_SNIFF_BYTES + 1)) > _SNIFF_BYTES:
        longer = source.head(MAX_HEADER_BYTES + 1)
        if not any(mark in longer for mark in (b"\n", b"\r")) and len(longer) > MAX_HEADER_BYTES:
            raise LogFormatError(
                f"{name}: its first line is longer than {MAX_HEADER_BYTES >> 20} MiB (a header of "
                f"{longer.count(b',') + 1:,}+ columns?); a wheel log has a handful of columns: give a CSV log"
            )
    lines = text.splitlines()
    skip = 0
    while skip < len(lines) and lines[skip].lstrip().startswith(_COMMENT_MARKS):
        skip += 1
    if skip:
        notes.append(f"the first {skip} lines are comments (starting with % or #) and were skipped")
        text = "\n".join(lines[skip:])
    if not text.strip():
        raise LogFormatError(f"{name}: the file holds only blank lines; give a log with a header and data rows")
    sep, decimal = sniff_delimiter(text)
    header_line = next(ln for ln in text.splitlines() if ln.strip())
    has_header = not _all_numbers(header_line, sep, decimal)
    if not has_header:
        n_fields = len(header_line.split() if sep == r"\s+" else header_line.split(sep))
        notes.append(
            f"no header row: the {n_fields} columns are named by position, 1 to {n_fields}; map them with "
            "--columns, e.g. t=1,eta_r=3"
        )
    spaced = sep != r"\s+" and any(f != f.strip() for f in header_line.split(sep))
    if sep == "\t":
        notes.append("columns separated by tabs")
    elif sep == ";":
        notes.append("columns separated by ';'")
    elif sep == r"\s+":
        notes.append("columns separated by whitespace")
    if decimal == ",":
        notes.append("decimal commas (e.g. 1,5) read as decimal points")

    def fail(err: BaseException) -> LogFormatError:
        if isinstance(err, UnicodeDecodeError):
            return LogFormatError(
                f"{name}: not a CSV text file (byte {err.start} of a block is not {encoding} text); "
                "give a CSV or Parquet log"
            )
        if isinstance(err, pd.errors.EmptyDataError):
            return LogFormatError(f"{name}: the file holds no header or data; give a log with a header and data rows")
        msg = _one_line(err).replace("Error tokenizing data. C error: ", "")
        return LogFormatError(f"{name}: cannot be parsed as CSV ({msg}); every row needs one value per header column")

    c_options: dict[str, Any] = {
        "sep": sep,
        "decimal": decimal,
        "encoding": encoding,
        "skipinitialspace": spaced,
        "engine": "c",
        "skiprows": skip,
    }
    if not has_header:
        c_options["header"] = None
    if int(pd.__version__.split(".")[0]) < 3:  # pandas 3 parses floats exactly by default (and warns on this)
        c_options["float_precision"] = "round_trip"
    try:
        header = pd.read_csv(source.opener(), nrows=0 if has_header else 1, **c_options)
    except (ValueError, UnicodeDecodeError) as err:
        raise fail(err) from err
    if not has_header:
        c_options["names"] = [str(i + 1) for i in range(len(header.columns))]
        header = header.set_axis(c_options["names"], axis=1)
    present = [str(c).strip() for c in header.columns]
    if spaced:
        notes.append("spaces around column names and values ignored")
    comments = lines[:skip]
    return _CsvLayout(c_options, list(header.columns), present, notes, skip, has_header, spaced, fail, comments)


def _csv_chunks(
    source: _Source, mapping: dict[str, str], explicit: set[str], rows: int
) -> tuple[Callable[[], Iterator[tuple[int, dict[str, Any]]]], Callable[[int], str], list[str], None]:
    """(chunks, where, notes, None) of a CSV log; ``chunks()`` yields (first data row, columns) of ``rows`` rows.

    Plain files (comma, tab or semicolon, no comments, a header) are parsed by pyarrow's streaming CSV
    reader; anything it refuses, from the row it refused on, and all other files by pandas' C engine.
    """
    import pandas as pd

    name = source.name
    layout = _csv_layout(source)
    c_options, present, notes = layout.c_options, layout.present, layout.notes
    header = pd.DataFrame(columns=layout.header_columns)
    chosen = _select(present, mapping, explicit, name)
    actual = {str(c).strip(): c for c in header.columns}
    usecols = list(dict.fromkeys(actual[c] for c in chosen.values()))
    plain = (
        c_options["sep"] in (",", "\t", ";")
        and c_options["decimal"] == "."
        and c_options["encoding"] == "utf-8"
        and not layout.spaced
        and not layout.skip
        and layout.has_header
        and len(set(layout.header_columns)) == len(layout.header_columns)
    )

    def c_engine(skip_rows: int) -> Iterator[tuple[int, dict[str, Any]]]:
        base = 0
        try:  # all columns: usecols would hide ragged rows
            with pd.read_csv(source.opener(), chunksize=rows, **c_options) as reader:
                for frame in reader:
                    n = len(frame)
                    if base + n > skip_rows:
                        start = max(skip_rows - base, 0)
                        frame = frame.iloc[start:]
                        frame.columns = [str(c).strip() for c in frame.columns]
                        yield base + start, {key: _series_values(frame[col]) for key, col in chosen.items()}
                    base += n
        except (ValueError, UnicodeDecodeError) as err:
            raise layout.fail(err) from err

    def chunks() -> Iterator[tuple[int, dict[str, Any]]]:
        done = 0
        if plain:
            try:
                for values in _arrow_csv(source, c_options["sep"], usecols, chosen, actual, rows):
                    n = len(values["t"])
                    yield done, values
                    done += n
                return
            except _ArrowCsvRefused:
                pass  # the C engine decides, and explains, from the first row not yet handed out
        yield from c_engine(done)

    return chunks, _csv_line_finder(source, layout.skip, layout.has_header), notes, None


class _ArrowCsvRefused(Exception):
    """pyarrow's CSV reader cannot read (the rest of) a file the C engine may still read or explain."""


def _arrow_csv(
    source: _Source, sep: str, usecols: list[Any], chosen: dict[str, str], actual: dict[str, Any], rows: int
) -> Iterator[dict[str, Any]]:
    """Column values of ``rows``-row pieces read by pyarrow's streaming CSV reader (raises _ArrowCsvRefused)."""
    import pyarrow as pa
    import pyarrow.csv as pcsv

    try:
        reader = pcsv.open_csv(
            source.opener(),
            read_options=pcsv.ReadOptions(block_size=1 << 24, use_threads=True),
            parse_options=pcsv.ParseOptions(delimiter=sep),
            convert_options=pcsv.ConvertOptions(include_columns=usecols),
        )
    except (pa.ArrowException, OSError, ValueError) as err:
        raise _ArrowCsvRefused from err
    pending: list[Any] = []
    count = 0

    def values(table: Any) -> dict[str, Any]:
        return {key: _arrow_values(table.column(actual[col]).combine_chunks()) for key, col in chosen.items()}

    try:
        with reader:
            for batch in reader:
                pending.append(batch)
                count += batch.num_rows
                while count >= rows:  # pieces of exactly ``rows`` rows, whatever pyarrow's block size
                    table = pa.Table.from_batches(pending)
                    yield values(table.slice(0, rows))
                    rest = table.slice(rows)
                    pending, count = rest.to_batches(), rest.num_rows
    except (pa.ArrowException, OSError, ValueError) as err:
        raise _ArrowCsvRefused from err
    if count:
        yield values(pa.Table.from_batches(pending))


def _all_numbers(line: str, sep: str, decimal: str) -> bool:
    """True when every field of ``line`` reads as a number (a data row, not a header)."""
    fields = line.split() if sep == r"\s+" else line.split(sep)
    try:
        for f in fields:
            if f.strip():
                float(f.strip().replace(decimal, ".") if decimal != "." else f.strip())
    except ValueError:
        return False
    return any(f.strip() for f in fields)


def _series_values(series: pandas.Series) -> Any:
    """A numeric numpy array when pandas parsed the column as numbers, else the Series itself."""
    numeric = isinstance(series.dtype, np.dtype) and series.dtype.kind in ("i", "u", "f")
    return series.to_numpy() if numeric else series


# ---- Validation and assembly


def _numeric(values: Any, key: str, col: str, name: str, where: Callable[[int], str]) -> np.ndarray:
    """A numeric numpy array (int or float) or a LogFormatError naming the first non-numeric cell."""
    if isinstance(values, np.ndarray) and values.dtype.kind in "iuf":
        return values
    import pandas as pd  # only for non-numeric columns: keeps a numeric Parquet read free of pandas

    series = pd.Series(values)
    if series.dtype.kind == "b":
        raise LogFormatError(f"{name}: column {col!r} holds true/false values; map {key} to a numeric column")
    coerced = pd.to_numeric(series, errors="coerce")
    bad = coerced.isna().to_numpy() & series.notna().to_numpy()
    if bad.any():
        i = int(np.argmax(bad))
        raise LogFormatError(
            f"{name}: {where(i)}, column {col!r}: {str(series.iloc[i])[:40]!r} is not a number; fix or delete that row"
        )
    out = coerced.to_numpy()
    return out if out.dtype.kind in "iuf" else out.astype(np.float64)


def _first_nonfinite(arr: np.ndarray) -> int | None:
    """Index of the first NaN/inf in ``arr`` (None if all finite or not floating point)."""
    if arr.dtype.kind != "f":
        return None
    ok = np.isfinite(arr)
    return None if ok.all() else int(np.argmin(ok))


def _nonfinite_message(arr: np.ndarray, i: int, col: str, name: str, where: Callable[[int], str]) -> str:
    what = "empty or NaN" if np.isnan(arr[i]) else f"{float(arr[i])}"
    return f"{name}: {where(i)}, column {col!r} is {what}; fill or delete that row"


def seconds_from_stamps(stamps: np.ndarray, unit: str) -> tuple[np.ndarray, int | float | None]:
    """(t float64 s, offset) from stamps in ``unit`` ("s", "ms", "us", "ns"); offset is the stamp subtracted.

    Integer stamps are converted exactly relative to their first value when the absolute seconds would
    reach 2**23 s (float64 spacing > 1 ns), else absolutely; the division by 10**k is correctly rounded
    because the integer fits in 53 bits.  Float stamps in seconds are returned unchanged; other float
    stamps follow the same relative rule (the subtraction of nearby floats is exact).
    """
    if stamps.dtype.kind in "iu":
        ints = stamps.astype(np.int64) if stamps.dtype.kind == "u" else stamps
        per_s = _NS_PER_UNIT["s"] // _NS_PER_UNIT[unit]  # stamps per second
        largest = max(abs(int(ints[0])), abs(int(ints[-1])))
        if largest >= ABSOLUTE_LIMIT_S * per_s:
            offset = int(ints[0])
            return (ints - ints[0]).astype(np.float64) / float(per_s), offset
        return ints.astype(np.float64) / float(per_s), None
    floats = stamps.astype(np.float64, copy=False)
    if unit == "s":
        return floats, None
    per_s = _PER_SECOND[unit]
    if max(abs(floats[0]), abs(floats[-1])) >= ABSOLUTE_LIMIT_S * per_s:
        return (floats - floats[0]) / per_s, float(floats[0])
    return floats / per_s, None


class _Assembler:
    """Turns the columns of successive pieces of a table log into :class:`WheelLog` pieces.

    Checks each piece as :func:`read_log` checks a whole log (numbers, finite, time strictly increasing,
    also across pieces) and makes the log-wide decisions (time unit, offset, epoch-like stamps) on the
    first piece that has rows.  ``finish()`` returns the notes and raises for a log too short to use.
    """

    def __init__(
        self, name: str, mapping: dict[str, str], time_unit: str, hint: str | None, where: Callable[[int], str],
        reference_required: bool = False,
    ):  # fmt: skip
        self.name, self.mapping, self.time_unit, self.hint, self.where = name, mapping, time_unit, hint, where
        self.reference_required = reference_required  # named by --columns: a bad cell is an error, not a note
        self.notes: list[str] = []
        self.unit: str | None = None
        self.kind: str | None = None  # "i" or "f": the time column's kind in the first piece
        self.offset: int | float | None = None
        self.epoch: bool | None = None  # whether stamps are epoch times (zero stamps are then dropped)
        self.zero_rows = 0
        self.zero_first: str | None = None
        self.held_zeros = 0  # leading all-zero rows not yet known to be bad epoch stamps
        self.held_first: str | None = None
        self.prev_stamp: Any = None
        self.prev_t: float | None = None
        self.first_step: float | None = None
        self.first_stamp = 0.0  # the first stamp as stored (for the message about an implausible unit)
        self.first_t = 0.0
        self.n = 0
        self.dropped: set[str] = set()  # optional column groups dropped for the rest of the log (_optional)
        self.last_t = 0.0

    def add(self, values: dict[str, Any], base: int) -> WheelLog | None:
        """The piece whose first row is data row ``base`` (0-based) of the file, or None if it has no rows left."""
        name, mapping = self.name, self.mapping
        kept = None

        def where(i: int) -> str:
            return self.where(base + (int(kept[i]) if kept is not None else i))

        arrays = {key: _numeric(values[key], key, mapping[key], name, where) for key in REQUIRED}
        bad = [(i, key) for key in REQUIRED if (i := _first_nonfinite(arrays[key])) is not None]
        if bad:  # the first non-finite cell in file order among the required columns
            i, key = min(bad, key=lambda b: (b[0], REQUIRED.index(b[1])))
            raise LogFormatError(_nonfinite_message(arrays[key], i, mapping[key], name, where))
        stamps = self._stamps(arrays["t"], where)

        zero = stamps == 0
        if self.epoch is None and self.n == 0 and len(zero) > 1 and zero.all():
            # undecided: hold the zero rows back until a stamp says whether they are a clock not yet set
            self.held_zeros += len(zero)
            self.held_first = self.held_first or where(0)
            return None
        if self.epoch is None and not zero.all():  # decided by the first piece with a non-zero stamp
            self.epoch = bool(np.min(np.abs(stamps[~zero])) > _EPOCH_LIKE_S)
            if self.held_zeros and self.epoch:
                self.zero_rows += self.held_zeros
                self.zero_first = self.held_first
                self.held_zeros = 0
            elif self.held_zeros:  # zeros, then times that are not epoch times: time stood still
                raise LogFormatError(
                    f"{name}: time is not strictly increasing at {self.held_first}: the log starts with "
                    f"{self.held_zeros} rows stamped 0; sort the log by time and drop repeated stamps"
                )
        if self.epoch and zero.any():
            rows = np.flatnonzero(zero)
            self.zero_rows += len(rows)
            self.zero_first = self.zero_first or where(int(rows[0]))
            kept = np.flatnonzero(~zero)
            arrays = {key: arr[kept] for key, arr in arrays.items()}
            values = {key: _take(val, kept) for key, val in values.items()}
            stamps = arrays["t"]
        if len(stamps) == 0:
            return None
        if self.unit is None:
            self._decide_unit(stamps)

        steps = np.diff(stamps, prepend=stamps[:1] if self.prev_stamp is None else [self.prev_stamp])
        check = steps[1:] if self.prev_stamp is None else steps
        if not (check > 0).all():
            i = int(np.argmin(check > 0)) + (1 if self.prev_stamp is None else 0)
            before = stamps[i - 1].item() if i > 0 else self.prev_stamp.item()
            raise LogFormatError(
                f"{name}: time is not strictly increasing at {where(i)}: {mapping['t']!r} = {stamps[i].item()!r} "
                f"follows {before!r} on the row before; sort the log by time and drop repeated stamps"
            )
        t = _seconds(stamps, self.unit, self.offset)  # type: ignore[arg-type]
        t_steps = np.diff(t, prepend=t[:1] if self.prev_t is None else [self.prev_t])
        t_check = t_steps[1:] if self.prev_t is None else t_steps
        if not (t_check > 0).all():  # distinct stamps that float64 cannot tell apart
            i = int(np.argmin(t_check > 0)) + (1 if self.prev_t is None else 0)
            before = stamps[i - 1].item() if i > 0 else self.prev_stamp.item()
            raise LogFormatError(
                f"{name}: {where(i)}: stamps {before!r} and {stamps[i].item()!r} are equal "
                "in float64 seconds; give the time column in a coarser unit"
            )
        if self.first_step is None and len(t) > 1:
            self.first_step = float(np.median(np.diff(t)))
        if self.n == 0 and len(t):
            self.first_stamp, self.first_t = float(stamps[0]), float(t[0])
        self.prev_stamp, self.prev_t, self.last_t = stamps[-1], float(t[-1]), float(t[-1])
        self.n += len(t)

        eta = np.column_stack([arrays["eta_r"], arrays["eta_l"]]).astype(np.float64, copy=False)
        tau = np.column_stack([arrays["tau_r"], arrays["tau_l"]]).astype(np.float64, copy=False)
        pose = self._optional("pose", POSE, values, where, required=False)
        reference = self._optional("reference", REFERENCE, values, where, required=self.reference_required)
        return WheelLog(t=t, eta=eta, tau=tau, source=name, pose=pose, reference=reference)

    def _stamps(self, stamps: np.ndarray, where: Callable[[int], str]) -> np.ndarray:
        """The time column in the kind (integer or float) of the first piece's."""
        kind = "i" if stamps.dtype.kind in "iu" else "f"
        if self.kind is None:
            self.kind = kind
        elif kind != self.kind:
            if self.kind == "f":
                return stamps.astype(np.float64)
            whole = stamps == np.round(stamps)
            if not whole.all():
                i = int(np.argmin(whole))
                raise LogFormatError(
                    f"{self.name}: {where(i)}: time stamp {stamps[i].item()!r} has decimals where the rows before "
                    "hold whole numbers; give the time column one kind of number (or --time-unit s with decimals)"
                )
            return stamps.astype(np.int64)
        return stamps.astype(np.int64) if stamps.dtype.kind == "u" else stamps

    def _decide_unit(self, stamps: np.ndarray) -> None:
        tcol = self.mapping["t"]
        unit = self.time_unit
        if self.hint is not None:
            if self.time_unit not in ("auto", self.hint):
                self.notes.append(f"--time-unit {self.time_unit} ignored: the column's type says {self.hint}")
            unit = self.hint
        elif self.time_unit == "auto":
            if stamps.dtype.kind in "iu":
                unit = "ns"
                self.notes.append(
                    f"time column {tcol!r} holds integers: read as integer nanoseconds "
                    "(use --time-unit s, ms or us if it counts other units)"
                )
            else:
                unit = "s"
                largest = float(np.max(np.abs(stamps)))
                for candidate, low in (("ns", 1e16), ("us", 1e13)):
                    if largest >= low:  # as seconds: over 300,000 years; as ns or us since the epoch: today
                        unit = candidate
                        self.notes.append(
                            f"time column {tcol!r} holds floats up to {largest:.4g}: too large for seconds, read "
                            f"as {candidate} since the Unix epoch (use --time-unit to say otherwise)"
                        )
                        break
        self.unit = unit
        # Decided on the first piece, before the log's last stamp is known: relative already from
        # ABSOLUTE_LIMIT_S / 2 (48 days) on, so that a log may run 48 more days and keep 1 ns resolution.
        self.offset = None
        if stamps.dtype.kind in "iu" or unit != "s":
            per_s = _PER_SECOND[unit]
            largest = max(abs(float(stamps[0])), abs(float(stamps[-1]))) / per_s
            if largest >= ABSOLUTE_LIMIT_S / 2:
                self.offset = int(stamps[0]) if stamps.dtype.kind in "iu" else float(stamps[0])

    def _optional(
        self, label: str, keys: tuple[str, ...], values: dict[str, Any], where: Callable[[int], str], required: bool
    ) -> np.ndarray | None:
        """The optional columns ``keys`` (the pose, the reference) as (n, len(keys)), or None: when one is absent, or,
        unless ``required`` (named by --columns), with a note when a cell is unusable; they are then dropped for the
        rest of the log (``self.dropped``)."""
        if label in self.dropped:
            return None
        if not all(k in values for k in keys):
            self.dropped.add(label)
            return None
        cols = []
        for key in keys:
            try:
                arr = _numeric(values[key], key, self.mapping[key], self.name, where).astype(np.float64, copy=False)
                i = _first_nonfinite(arr)
                problem = None if i is None else _nonfinite_message(arr, i, self.mapping[key], self.name, where)
                short = None if problem is None else problem.split(";")[0]  # the cell, without the fix
            except LogFormatError as err:
                problem = short = str(err)
            if problem is not None:
                if required:
                    raise LogFormatError(problem)
                self.notes.append(f"{label} columns ignored: {short.removeprefix(self.name + ': ')}")
                self.dropped.add(label)
                return None
            cols.append(arr)
        return np.column_stack(cols)

    def finish(self) -> list[str]:
        """The notes of the whole log; raises LogFormatError for a log with fewer than MIN_SAMPLES samples."""
        name, tcol, notes = self.name, self.mapping["t"], list(self.notes)
        if self.held_zeros > 1:  # only zeros: time stood still
            raise LogFormatError(
                f"{name}: time is not strictly increasing: all {self.held_zeros} rows are stamped 0; give the log "
                "its time stamps"
            )
        if self.n == 0 and self.zero_rows == 0 and self.held_zeros == 0:
            raise LogFormatError(
                f"{name}: has a header but no data rows; give a log with at least {MIN_SAMPLES} samples"
            )
        if self.n < MIN_SAMPLES:
            raise LogFormatError(
                f"{name}: only {self.n} samples; identification needs at least {MIN_SAMPLES}, so record a longer log"
            )
        if self.zero_rows:
            notes.insert(
                0,
                f"{self.zero_rows} rows with time stamp 0 among epoch times were dropped as bad stamps "
                f"(first: {self.zero_first})",
            )
        if self.offset is not None:
            notes.append(
                f"time stored relative to the first stamp {self.offset!r} {self.unit} (t = 0 there) so that float64 "
                "seconds keep 1 ns resolution"
            )
        if self.unit == "s" and self.kind == "f" and abs(self.last_t) >= 1e11:
            notes.append(
                f"time column {tcol!r} reaches {self.last_t:.3g} s (over 3000 years): if it counts ms, us or ns, "
                "say so with --time-unit"
            )
        elif self.unit == "ns" and self.time_unit == "auto" and self.hint is None and self.n > 1:
            mean_step = (self.last_t - self.first_t) / (self.n - 1)  # the whole log's, not its first piece's
            if mean_step < MIN_PLAUSIBLE_STEP_S:
                raise LogFormatError(_implausible_step(name, tcol, mean_step, self.first_stamp))
        if any(self.mapping[k] != k for k in REQUIRED):
            notes.append(
                "columns read as " + ", ".join(f"{k} = {self.mapping[k]!r}" for k in REQUIRED if self.mapping[k] != k)
            )
        return notes


#: bytes: the longest first line (header) of a CSV log; a 10 M-column header took 3.4 GB and 75 s to refuse.
MAX_HEADER_BYTES = 1 << 20

#: bytes: a Parquet row group larger than this decoded (rows x columns read x 8) is read in slices.
ROW_GROUP_SLICE_BYTES = 64 << 20

#: s: integer stamps read as nanoseconds whose samples are closer than this (a wheel log above 100 kHz) are refused:
#: they count a coarser unit (epoch milliseconds read as ns gave 1 ns steps and m11 = 0).
MIN_PLAUSIBLE_STEP_S = 1e-5


def _implausible_step(name: str, tcol: str, step_s: float, first: float) -> str:
    """The message for integer stamps whose median step, read as ns, is ``step_s`` (``first``: the first stamp, as
    stored): the unit under which the first stamp is a date of this century (epoch time), else every unit that
    puts the step between 0.1 ms and 1 s (10 Hz to 10 kHz)."""
    count = step_s * 1e9
    scales = {"ms": 1e-3, "us": 1e-6, "s": 1.0}
    epoch = [u for u in scales if 9.46e8 <= first * scales[u] <= 4.1e9]  # the first stamp a date, 2000 to 2100
    plausible = [u for u, scale in scales.items() if 1e-4 <= count * scale <= 1.0]
    units = epoch or plausible
    if units:
        fix = " or ".join(f"--time-unit {u} ({1.0 / (count * scales[u]):.3g} Hz)" for u in units)
        fix = f"give {fix}" + (", which makes the first stamp a date since the Unix epoch" if epoch else "")
    else:
        fix = "give --time-unit s, ms or us for the unit it counts"
    return (
        f"{name}: time column {tcol!r} holds integers whose samples are {count:.4g} apart: as nanoseconds (the default "
        f"for integers) that is a {1.0 / max(step_s, 1e-300):.3g} Hz wheel log, which no robot logs; {fix}"
    )


def _seconds(stamps: np.ndarray, unit: str, offset: int | float | None) -> np.ndarray:
    """Stamps in ``unit`` as float64 seconds, less ``offset`` (a stamp) when given; see :func:`seconds_from_stamps`."""
    if stamps.dtype.kind in "iu":
        per_s = _NS_PER_UNIT["s"] // _NS_PER_UNIT[unit]
        if offset is not None:
            return (stamps - int(offset)).astype(np.float64) / float(per_s)
        return stamps.astype(np.float64) / float(per_s)
    floats = stamps.astype(np.float64, copy=False)
    if unit == "s":
        return floats
    if offset is not None:
        return (floats - float(offset)) / _PER_SECOND[unit]
    return floats / _PER_SECOND[unit]


def _take(values: Any, rows: np.ndarray) -> Any:
    """Rows of a column as read (a numpy array or a pandas Series), renumbered from 0."""
    if isinstance(values, np.ndarray):
        return values[rows]
    return values.iloc[rows].reset_index(drop=True)


def _one_line(err: BaseException | str) -> str:
    return " ".join(str(err).split())[:300]


def read_metadata(path: str) -> dict[str, str]:
    """The key/value metadata of a Parquet log's schema (without pandas' own), {} for other formats."""
    import pyarrow as pa
    import pyarrow.parquet as pq

    source = _open_source(path)
    if detect_format(path, source.head(8)) != "parquet":
        return {}
    try:
        with pa.OSFile(source.path, "r") if source.path is not None else pa.BufferReader(source.data) as stream:
            meta = pq.ParquetFile(stream).schema_arrow.metadata or {}
    except (pa.ArrowException, OSError) as err:
        raise LogFormatError(f"{source.name}: not a readable Parquet file ({_one_line(err)})") from err
    return {k.decode(): v.decode() for k, v in meta.items() if k != b"pandas"}


# --------------------------------------------------------------------------------------------------
# Writing


def write_log(
    frame: pandas.DataFrame, path: str, *, force: bool = False, metadata: dict[str, str] | None = None
) -> None:
    """Write ``frame`` as a log: ``.csv`` (or ``-`` for CSV on standard output) or ``.parquet``/``.pq``.

    CSV floats are written with repr precision (read back exactly); CSV has no place for ``metadata``,
    so it is dropped there.  Parquet keeps ``metadata`` in the schema's key/value metadata.  Files are
    written atomically (:mod:`wmrid.core.atomic`); an existing file is replaced only with ``force``.
    """
    from wmrid.core.atomic import atomic_output

    if path == "-":
        out = getattr(sys.stdout, "buffer", None)
        if out is None:  # a text-only stream (e.g. a test harness)
            frame.to_csv(sys.stdout, index=False, float_format=None, lineterminator="\n")
        else:
            sys.stdout.flush()
            _write_csv(frame, out, ",")
            out.flush()
        return
    suffix = os.path.splitext(path)[1].lower()
    if suffix in _CSV_SUFFIXES:
        with atomic_output(path, force=force, mode="wb") as fh:
            _write_csv(frame, fh, "\t" if suffix == ".tsv" else ",")
    elif suffix in _PARQUET_SUFFIXES:
        import pyarrow as pa
        import pyarrow.parquet as pq

        table = pa.Table.from_pandas(frame, preserve_index=False)
        merged = dict(table.schema.metadata or {})
        merged.update({str(k).encode(): str(v).encode() for k, v in (metadata or {}).items()})
        table = table.replace_schema_metadata(merged)
        with atomic_output(path, force=force, mode="wb") as fh:
            pq.write_table(table, fh)
    else:
        raise UsageError(f"cannot tell the log format from {path!r}; name it .csv or .parquet")


def _write_csv(frame: pandas.DataFrame, fh: Any, sep: str) -> None:
    """CSV whose floats read back bit for bit (shortest round-trip repr, as ``repr(float)``).

    All-numeric frames go through pyarrow (about 15x faster than ``DataFrame.to_csv``): floats are
    formatted by Arrow's shortest round-trip formatter and integral ones get ``.0`` appended, so a float
    column never reads back as integers (which would change the meaning of a time column).  Anything
    else (strings, awkward names) goes through pandas with ``float_format=None`` (repr precision).
    """
    names = [str(c) for c in frame.columns]
    plain = all(isinstance(dt, np.dtype) and dt.kind in ("i", "u", "f") for dt in frame.dtypes) and not any(
        set(n) & {sep, '"', "\n", "\r"} or n != n.strip() for n in names
    )
    if not plain or len(set(names)) != len(names):
        frame.to_csv(fh, index=False, sep=sep, float_format=None, lineterminator="\n", encoding="utf-8")
        return
    import pyarrow as pa
    import pyarrow.compute as pc
    import pyarrow.csv as pcsv

    arrays = []
    for col in frame.columns:
        values = frame[col].to_numpy()
        if values.dtype.kind == "f":
            text = pc.cast(pa.array(values.astype(np.float64, copy=False)), pa.string())
            integral = pc.match_substring_regex(text, r"^-?[0-9]+$")
            text = pc.if_else(integral, pc.binary_join_element_wise(text, pa.scalar(".0"), ""), text)
            arrays.append(text)
        else:
            arrays.append(pa.array(values))
    table = pa.Table.from_arrays(arrays, names=names)
    fh.write((sep.join(names) + "\n").encode("utf-8"))  # unquoted, whatever the pyarrow version
    pcsv.write_csv(table, fh, pcsv.WriteOptions(include_header=False, delimiter=sep, quoting_style="none"))
