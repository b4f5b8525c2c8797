"""Reading and writing wheel logs, whatever their format, as one log type (:class:`wmrid.core.wheel_log.WheelLog`).

:func:`read_log` reads a log whole; :func:`open_log` returns a :class:`wmrid.core.wheel_log.LogStream` that reads it
piece by piece.  The format is recognised in :mod:`wmrid.io.sources`; the pieces come from
:mod:`wmrid.io.table.csv_log`, :mod:`wmrid.io.table.parquet_log` or :mod:`wmrid.io.mcap.log`; this module turns the
columns into checked SI arrays (:class:`Assembler`: time stamps through :mod:`wmrid.io.stamps`, signals through
:mod:`wmrid.io.signals`). ``--columns t=time,eta_r=vel_right`` maps canonical names to the names in a file
(:mod:`wmrid.io.table.columns`); other columns are ignored.  Rows stamped 0 among epoch times (a clock not yet set) are
dropped, with a note.

Pieces: CSV and Parquet logs are read CHUNK_ROWS rows at a time (Parquet one row group at a time), so ``wmrid
identify`` needs the same memory for a 4 h log as for a 1 h one.  Every row is checked as when the log is read whole;
the log-wide choices (time unit, offset, epoch-like stamps) are made on the first piece with rows.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Generator, Mapping, Sequence
from typing import TYPE_CHECKING, Any

import numpy as np

from wmrid.core.errors import LogFormatError, UsageError, option
from wmrid.core.extras import available, require
from wmrid.io.ros.selection import TopicSelection
from wmrid.io.signals import SignalOptions, convert, position_to_rad, speed_from_position

if TYPE_CHECKING:
    import pandas
from wmrid.core.wheel_log import (
    CANONICAL,
    POSITION,
    REFERENCE,
    LogStream,
    WheelLog,
    piece_rows,
)
from wmrid.io.assembler import MERGED_TIME, Assembler
from wmrid.io.bag.paths import recording_paths
from wmrid.io.ros.field_paths import field_signals
from wmrid.io.sources import CSV_SUFFIXES, PARQUET_SUFFIXES, STDIN_NAME, Source, detect_format, one_line, open_source
from wmrid.io.stamps import (
    TIME_UNITS,
)
from wmrid.io.table.columns import check_key
from wmrid.io.table.csv_log import csv_chunks
from wmrid.io.table.parquet_log import parquet_chunks
from wmrid.runtime.atomic import atomic_output, register_input


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
    selection : MCAP topics, joints, time source and alignment (:mod:`wmrid.io.ros.joints`).
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
    rows: int | None = None,
) -> LogStream:
    """The log of :func:`read_log` (same arguments) as a :class:`LogStream` of pieces of ``rows`` samples (None:
    :func:`wmrid.core.wheel_log.piece_rows`, CHUNK_ROWS unless limited).

    CSV and Parquet logs are read piece by piece (bounded memory); so are MCAP recordings, except the
    layouts listed in the module docstring, which are decoded whole and then handed out in pieces.
    The file's layout (format, columns, delimiter) is checked here; the rows are checked as the pieces
    are read.  ``path`` may also be a ROS 1 bag, a ROS 2 ``.db3`` bag, a rosbag2 folder, or several bag files
    of one recording (read in time order: :func:`wmrid.io.bag.paths.recording_paths`).
    """
    if time_unit not in TIME_UNITS:
        raise UsageError(f"{option('time_unit')} {time_unit!r} is not one of {', '.join(TIME_UNITS)}")
    rows = piece_rows() if rows is None else rows
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
        from wmrid.io.mcap.log import read_mcap_log  # the MCAP reader and its compiled decoders: MCAP logs only

        return read_mcap_log(source, columns or {}, selection or TopicSelection(), signals, gear_ratio, rows)
    velocity_from = (selection or TopicSelection()).velocity_from
    if kind == "parquet":
        chunks, where, notes, hint = parquet_chunks(source, mapping, explicit, rows, velocity_from)
    else:
        chunks, where, notes, hint = csv_chunks(source, mapping, explicit, rows, velocity_from)
    effort_unit = "N m" if signals == SignalOptions() else signals.effort_label

    def pieces() -> Generator[WheelLog, None, tuple[str, ...]]:
        assembler = Assembler(
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
    from wmrid.io.bag.log import read_bag_log  # rosbags and the compiled decoders: bag logs only

    return read_bag_log(paths, selection or TopicSelection(), signals, gear_ratio, rows, fields=fs)


def read_metadata(path: str) -> dict[str, str]:
    """The key/value metadata of a Parquet log's schema (without pandas' own), {} for other formats."""
    source = open_source(path)
    if detect_format(path, source.head(8), source.compression) != "parquet":
        return {}
    require("pyarrow.parquet", "parquet", f"{source.name}: reading a Parquet log")
    import pyarrow as pa  # pyarrow (~40 ms, extra [parquet]): only a Parquet log
    import pyarrow.parquet as pq  # pyarrow: only a Parquet log

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
    written atomically (:mod:`wmrid.runtime.atomic`); an existing file is replaced only with ``force``.
    """
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
        import pyarrow as pa  # pyarrow (~40 ms, extra [parquet]): only a Parquet log
        import pyarrow.parquet as pq  # pyarrow: only a Parquet log

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
    import pyarrow as pa  # pyarrow (~0.1 s with compute and csv): only a CSV written
    import pyarrow.compute as pc  # pyarrow: only a CSV written
    import pyarrow.csv as pcsv  # pyarrow: only a CSV written

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
