"""Reading and writing wheel logs, whatever their format, as one log type (:class:`wmrid.core.wheel_log.WheelLog`).

:func:`read_log` reads a log whole; :func:`open_log` returns a :class:`wmrid.core.wheel_log.LogStream` that reads it
piece by piece.  The format is recognised in :mod:`wmrid.io.sources`; the pieces come from :mod:`wmrid.io.csv_log`,
:mod:`wmrid.io.parquet_log` or :mod:`wmrid.io.mcap.log`; this module turns the columns into checked SI arrays
(:class:`_Assembler`: time stamps through :mod:`wmrid.io.stamps`, signals through :mod:`wmrid.io.signals`).
``--columns t=time,eta_r=vel_right`` maps canonical names to the names in a file (:mod:`wmrid.io.columns`); other
columns are ignored.  Rows stamped 0 among epoch times (a clock not yet set) are dropped, with a note.

Pieces: CSV and Parquet logs are read CHUNK_ROWS rows at a time (Parquet one row group at a time), so ``wmrid
identify`` needs the same memory for a 4 h log as for a 1 h one.  Every row is checked as when the log is read whole;
the log-wide choices (time unit, offset, epoch-like stamps) are made on the first piece with rows.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable, Generator, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from wmrid.core.errors import LogFormatError, UsageError, option
from wmrid.core.extras import available, require
from wmrid.io.mcap.joints import TopicSelection
from wmrid.io.signals import SignalOptions, convert, position_to_rad, speed_from_position

if TYPE_CHECKING:
    import pandas
from wmrid.core.wheel_log import (
    CANONICAL,
    CHUNK_ROWS,
    MIN_SAMPLES,
    POSE,
    POSITION,
    REFERENCE,
    REQUIRED,
    LogStream,
    WheelLog,
)
from wmrid.io.bag.log import recording_paths
from wmrid.io.columns import check_key
from wmrid.io.csv_log import csv_chunks
from wmrid.io.field_paths import field_signals
from wmrid.io.mcap.log import read_mcap_log
from wmrid.io.parquet_log import parquet_chunks
from wmrid.io.sources import CSV_SUFFIXES, PARQUET_SUFFIXES, STDIN_NAME, Source, detect_format, one_line, open_source
from wmrid.io.stamps import (
    ABSOLUTE_LIMIT_S,
    EPOCH_LIKE_S,
    MIN_PLAUSIBLE_STEP_S,
    PER_SECOND,
    TIME_UNITS,
    implausible_step,
    seconds,
)

#: The time column of PlotJuggler's CSV export, which merges every topic's samples into one table.
MERGED_TIME = "__time"


def read_log(
    path: str | Sequence[str],
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
    path: str | Sequence[str],
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
    are read.  ``path`` may also be a ROS 1 bag, a ROS 2 ``.db3`` bag, a rosbag2 folder, or several bag files
    of one recording (read in time order: :func:`wmrid.io.bag.log.recording_paths`).
    """
    if time_unit not in TIME_UNITS:
        raise UsageError(f"{option('time_unit')} {time_unit!r} is not one of {', '.join(TIME_UNITS)}")
    paths = [os.fspath(path)] if isinstance(path, (str, os.PathLike)) else [os.fspath(p) for p in path]
    if not paths:
        raise UsageError("no log given; give a log file")
    bag = recording_paths(paths) if data is None else None
    if bag is not None:
        return _bag_log(bag, columns, selection, signals or SignalOptions(), gear_ratio, rows)
    path = paths[0]
    mapping = {key: key for key in CANONICAL}
    for key, value in (columns or {}).items():
        check_key(key, "--columns")
        mapping[key] = value
    explicit = set(columns or ())

    if data is None and path != "-":
        from wmrid.core.atomic import register_input

        register_input(path)  # an output of this command may not be this file
    source = open_source(path) if data is None else Source(STDIN_NAME if path == "-" else path, None, data)
    kind = detect_format(path, source.head(8), source.compression)
    signals = signals or SignalOptions()
    if kind == "mcap":
        if explicit & set(REFERENCE):
            named = ", ".join(sorted(explicit & set(REFERENCE)))
            raise UsageError(
                f"{source.name}: {option('columns')} {named}: the wheel-speed reference is read from CSV and Parquet "
                "logs only "
                "so far; export the set-points as columns of one"
            )
        return read_mcap_log(source, columns or {}, selection or TopicSelection(), signals, gear_ratio, rows)
    velocity_from = (selection or TopicSelection()).velocity_from
    if kind == "parquet":
        chunks, where, notes, hint = parquet_chunks(source, mapping, explicit, rows, velocity_from)
    else:
        chunks, where, notes, hint = csv_chunks(source, mapping, explicit, rows, velocity_from)
    effort_unit = "N m" if signals == SignalOptions() else signals.effort_label

    def pieces() -> Generator[WheelLog, None, tuple[str, ...]]:
        assembler = _Assembler(
            source.name, mapping, time_unit, hint, where, bool(explicit & set(REFERENCE)),
            merged=mapping["t"].lower() == MERGED_TIME,
        )  # fmt: skip
        signal_notes: list[str] = []
        held: list[WheelLog] = []  # positions: the whole log, for the derivative's window
        for base, values in chunks():
            piece = assembler.add(values, base)
            if piece is None:
                continue
            if assembler.positions:
                held.append(piece)
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
        finished = assembler.finish()
        if held:
            signal_notes = yield from _speeds_from_positions(held, mapping, velocity_from, signals, gear_ratio, rows)
        return (*notes, *finished, *signal_notes)

    return LogStream(source.name, effort_unit, pieces)


def _speeds_from_positions(
    held: list[WheelLog],
    mapping: dict[str, str],
    velocity_from: str,
    signals: SignalOptions,
    gear_ratio: float | None,
    rows: int,
) -> Generator[WheelLog, None, list[str]]:
    """Pieces of ``rows`` samples of a table log read with wheel positions: ``held``, the whole log's pieces with the
    positions in place of the speeds, differentiated as a bag's positions are (:func:`speed_from_position`, in rad
    by :func:`position_to_rad`), the signals then converted as any log's; returns the notes."""
    t = np.concatenate([p.t for p in held])
    tau = np.concatenate([p.tau for p in held])
    pose = np.concatenate([p.pose for p in held]) if all(p.pose is not None for p in held) else None
    reference = np.concatenate([p.reference for p in held]) if all(p.reference is not None for p in held) else None
    position = position_to_rad(np.concatenate([p.eta for p in held]), signals)
    speed, note = speed_from_position(t - t[0], position)
    columns = f"columns {mapping[POSITION[0]]!r} and {mapping[POSITION[1]]!r}"
    notes = [f"{columns}: {note}" + (" (the log has no speed columns)" if velocity_from == "auto" else "")]
    speed, converted, more = convert(speed, tau, signals, gear_ratio, speed_in_rad_s=True)
    if reference is not None and signals != SignalOptions():  # set-points in the speeds' unit and sense
        reference = convert(reference, tau, signals, gear_ratio)[0]
    unit = "N m" if signals == SignalOptions() else signals.effort_label
    for start in range(0, len(t), rows):
        part = slice(start, start + rows)
        yield WheelLog(
            t=t[part], eta=speed[part], tau=converted[part], source=held[0].source, effort_unit=unit,
            pose=None if pose is None else pose[part],
            reference=None if reference is None else reference[part],
        )  # fmt: skip
    return notes + more


def _bag_log(
    paths: list[str],
    columns: Mapping[str, str] | None,
    selection: TopicSelection | None,
    signals: SignalOptions,
    gear_ratio: float | None,
    rows: int,
) -> LogStream:
    from wmrid.core.atomic import register_input
    from wmrid.io.bag.log import read_bag_log

    fs = field_signals(columns) if columns else None
    if columns and fs is None:
        raise UsageError(
            f"{paths[0]}: {option('columns')} names the columns of a CSV or Parquet log; in a bag it takes field "
            "paths (eta_r=/topic:field.path, ...), and JointState topics are chosen with "
            f"{option('velocity_topic')}, {option('effort_topic')} and {option('right_joint')}/{option('left_joint')}"
        )
    for p in paths:
        for root, _, files in os.walk(p) if os.path.isdir(p) else [("", None, [p])]:
            for f in files:
                register_input(os.path.join(root, f))  # an output of this command may not be one of them
    return read_bag_log(paths, selection or TopicSelection(), signals, gear_ratio, rows, fields=fs)


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


class _Assembler:
    """Turns the columns of successive pieces of a table log into :class:`WheelLog` pieces.

    Checks each piece as :func:`read_log` checks a whole log (numbers, finite, time strictly increasing,
    also across pieces) and makes the log-wide decisions (time unit, offset, epoch-like stamps) on the
    first piece that has rows.  ``finish()`` returns the notes and raises for a log too short to use.
    """

    def __init__(
        self, name: str, mapping: dict[str, str], time_unit: str, hint: str | None, where: Callable[[int], str],
        reference_required: bool = False, merged: bool = False,
    ):  # fmt: skip
        self.name, self.mapping, self.time_unit, self.hint, self.where = name, mapping, time_unit, hint, where
        self.merged = merged  # a merged export (PlotJuggler): rows without any wheel value are other topics'
        self.empty_rows = 0
        self.empty_first: str | None = None
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
        self.positions = False  # the wheel columns are positions (pos_r, pos_l), not speeds
        self.required = REQUIRED

    def add(self, values: dict[str, Any], base: int) -> WheelLog | None:
        """The piece whose first row is data row ``base`` (0-based) of the file, or None if it has no rows left.

        ``values`` holds the columns :func:`wmrid.io.columns.select` chose: with wheel positions (pos_r, pos_l) in
        place of the speeds, the piece's ``eta`` holds those positions, as read, for the caller to differentiate.
        """
        name, mapping = self.name, self.mapping
        self.positions = POSITION[0] in values
        self.required = REQUIRED if not self.positions else ("t", *POSITION, "tau_r", "tau_l")
        required = self.required
        kept = None

        def where(i: int) -> str:
            return self.where(base + (int(kept[i]) if kept is not None else i))

        arrays = {key: _numeric(values[key], key, mapping[key], name, where) for key in required}
        if self.merged:
            arrays, values, kept = self._other_topics(arrays, values, where)
            if not len(arrays["t"]):
                return None
        bad = [(i, key) for key in required if (i := _first_nonfinite(arrays[key])) is not None]
        if bad:  # the first non-finite cell in file order among the required columns
            i, key = min(bad, key=lambda b: (b[0], required.index(b[1])))
            raise LogFormatError(_nonfinite_message(arrays[key], i, mapping[key], name, where))
        stamps = self._stamps(arrays["t"], where)

        zero = stamps == 0
        if self.epoch is None and self.n == 0 and len(zero) > 1 and zero.all():
            # undecided: hold the zero rows back until a stamp says whether they are a clock not yet set
            self.held_zeros += len(zero)
            self.held_first = self.held_first or where(0)
            return None
        if self.epoch is None and not zero.all():  # decided by the first piece with a non-zero stamp
            self.epoch = bool(np.min(np.abs(stamps[~zero])) > EPOCH_LIKE_S)
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
            rows_kept = np.flatnonzero(~zero)
            arrays = {key: arr[rows_kept] for key, arr in arrays.items()}
            values = {key: _take(val, rows_kept) for key, val in values.items()}
            kept = rows_kept if kept is None else kept[rows_kept]  # row numbers in the piece as read
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
        t = seconds(stamps, self.unit, self.offset)  # type: ignore[arg-type]
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

        eta = np.column_stack([arrays[required[1]], arrays[required[2]]]).astype(np.float64, copy=False)
        tau = np.column_stack([arrays["tau_r"], arrays["tau_l"]]).astype(np.float64, copy=False)
        pose = self._optional("pose", POSE, values, where, required=False)
        reference = self._optional("reference", REFERENCE, values, where, required=self.reference_required)
        return WheelLog(t=t, eta=eta, tau=tau, source=name, pose=pose, reference=reference)

    def _other_topics(
        self, arrays: dict[str, np.ndarray], values: dict[str, Any], where: Callable[[int], str]
    ) -> tuple[dict[str, np.ndarray], dict[str, Any], np.ndarray | None]:
        """A merged export's piece without the rows where every wheel speed and effort is empty (rows of other
        topics, which such an export interleaves); (arrays, values, the kept rows' indices or None)."""
        empty = np.ones(len(arrays["t"]), dtype=bool)
        for key in self.required[1:]:
            arr = arrays[key]
            empty &= np.isnan(arr) if arr.dtype.kind == "f" else np.zeros(len(arr), dtype=bool)
        if not empty.any():
            return arrays, values, None
        self.empty_rows += int(empty.sum())
        self.empty_first = self.empty_first or where(int(np.argmax(empty)))
        kept = np.flatnonzero(~empty)
        return {k: a[kept] for k, a in arrays.items()}, {k: _take(v, kept) for k, v in values.items()}, kept

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
                    f"hold whole numbers; give the time column one kind of number (or {option('time_unit', 's')} with "
                    "decimals)"
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
            per_s = PER_SECOND[unit]
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
        if self.empty_rows:
            notes.insert(
                0,
                f"{self.empty_rows} rows without any wheel speed or effort (other topics' samples, which a "
                f"{MERGED_TIME!r} export interleaves) were dropped (first: {self.empty_first})",
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
                raise LogFormatError(implausible_step(name, tcol, mean_step, self.first_stamp))
        if any(self.mapping[k] != k for k in self.required):
            notes.append(
                "columns read as "
                + ", ".join(f"{k} = {self.mapping[k]!r}" for k in self.required if self.mapping[k] != k)
            )
        return notes


def _take(values: Any, rows: np.ndarray) -> Any:
    """Rows of a column as read (a numpy array or a pandas Series), renumbered from 0."""
    if isinstance(values, np.ndarray):
        return values[rows]
    return values.iloc[rows].reset_index(drop=True)


def read_metadata(path: str) -> dict[str, str]:
    """The key/value metadata of a Parquet log's schema (without pandas' own), {} for other formats."""
    source = open_source(path)
    if detect_format(path, source.head(8), source.compression) != "parquet":
        return {}
    require("pyarrow.parquet", "parquet", f"{source.name}: reading a Parquet log")
    import pyarrow as pa
    import pyarrow.parquet as pq

    try:
        with pa.OSFile(source.path, "r") if source.path is not None else pa.BufferReader(source.data) as stream:
            meta = pq.ParquetFile(stream).schema_arrow.metadata or {}
    except (pa.ArrowException, OSError) as err:
        raise LogFormatError(f"{source.name}: not a readable Parquet file ({one_line(err)})") from err
    return {k.decode(): v.decode() for k, v in meta.items() if k != b"pandas"}


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
    if suffix in CSV_SUFFIXES:
        with atomic_output(path, force=force, mode="wb") as fh:
            _write_csv(frame, fh, "\t" if suffix == ".tsv" else ",")
    elif suffix in PARQUET_SUFFIXES:
        require("pyarrow.parquet", "parquet", f"{path}: writing a Parquet log")
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

    All-numeric frames go through pyarrow when it is installed (the parquet extra; about 15x faster than
    ``DataFrame.to_csv``): floats are formatted by Arrow's shortest round-trip formatter and integral ones get ``.0``
    appended, so a float column never reads back as integers (which would change the meaning of a time column).
    Anything else (strings, awkward names), and everything without pyarrow, goes through pandas with
    ``float_format=None`` (repr precision: the same values, ``3.0`` for an integral float).
    """
    names = [str(c) for c in frame.columns]
    plain = all(isinstance(dt, np.dtype) and dt.kind in ("i", "u", "f") for dt in frame.dtypes) and not any(
        set(n) & {sep, '"', "\n", "\r"} or n != n.strip() for n in names
    )
    if not plain or len(set(names)) != len(names) or not available("pyarrow.csv"):
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
