"""What a log holds, before any identification: the first thing to run on an unknown recording.

For an MCAP: every topic with its message type, encoding, message count, rate and time range, and for
each JointState topic its joints and whether position, velocity and effort are populated.  For CSV and
Parquet: the columns, the number of rows, and which canonical columns were found.  The result is a
:class:`McapInventory` or a :class:`TableInventory`; ``to_dict`` is the JSON form, which
:func:`wmrid.reporting.render.print_inspection` draws as tables.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from wmrid.core.errors import LogFormatError
from wmrid.core.extras import require
from wmrid.core.json_record import JsonRecord, kept, names, other_keys
from wmrid.core.wheel_log import CANONICAL, CHUNK_ROWS
from wmrid.io.bag.paths import recording_paths
from wmrid.io.sources import detect_format, open_source


@dataclass(frozen=True, kw_only=True)
class TopicSummary(JsonRecord):
    """A topic of a recording: its message ``type`` and ``encoding``, ``messages`` (None: not counted), ``rate_hz``,
    ``start_s`` and ``end_s`` (None: not read); a JointState topic's ``joints``, which of position, velocity and
    effort are populated (``fields``) and its ``header_stamps``; another topic's numeric ``field_paths``
    (``TOPIC:PATH``, as ``--columns`` takes them)."""

    topic: str | None = None
    type: str | None = None
    encoding: str | None = None
    messages: int | None = kept()
    rate_hz: float | None = kept()
    start_s: float | None = kept()
    end_s: float | None = kept()
    joints: tuple[str, ...] | None = names()
    fields: dict[str, Any] | None = None
    header_stamps: str | None = None
    field_paths: tuple[str, ...] | None = names()
    other: dict[str, Any] = other_keys()


@dataclass(frozen=True, kw_only=True)
class ColumnSummary(JsonRecord):
    """A column of a CSV or Parquet log: its ``name`` and its ``type`` as the reader sees it."""

    name: str | None = None
    type: str | None = None
    other: dict[str, Any] = other_keys()


@dataclass(frozen=True)
class McapInventory:
    """What an MCAP or a bag (``format``) holds: its topics (:class:`TopicSummary`), time range (s), metadata names
    and notes."""

    source: str
    profile: str
    library: str
    size_bytes: int
    start_s: float | None
    end_s: float | None
    duration_s: float
    topics: tuple[TopicSummary, ...]
    metadata: list[str]
    notes: list[str]
    format: str = "mcap"  # or "ros1 bag", "ros2 bag"

    def to_dict(self) -> dict[str, Any]:
        return {
            "source": self.source, "format": self.format, "profile": self.profile, "library": self.library,
            "size_bytes": self.size_bytes, "start_s": self.start_s, "end_s": self.end_s, "duration_s": self.duration_s,
            "topics": [t.to_dict() for t in self.topics], "metadata": self.metadata, "notes": self.notes,
        }  # fmt: skip


@dataclass(frozen=True)
class TableInventory:
    """What a CSV or Parquet log holds: its columns (:class:`ColumnSummary`), rows (None for CSV: not counted), which
    canonical columns it has and which required ones it lacks, reading notes and comment lines."""

    source: str
    format: str
    rows: int | None
    columns: tuple[ColumnSummary, ...]
    canonical_found: list[str]
    canonical_missing: list[str]
    notes: list[str]
    comments: list[str]

    def to_dict(self) -> dict[str, Any]:
        return {
            "source": self.source, "format": self.format, "rows": self.rows,
            "columns": [c.to_dict() for c in self.columns],
            "canonical_found": self.canonical_found, "canonical_missing": self.canonical_missing, "notes": self.notes,
            "comments": self.comments,
        }  # fmt: skip


def inspect_log(path: str | list[str]) -> McapInventory | TableInventory:
    """A description of the log at ``path`` (or ``-``; or the files of one recording); see the module docstring."""
    paths = [path] if isinstance(path, str) else list(path)
    bag = recording_paths(paths)
    if bag is not None:
        from wmrid.io.bag.reader import read_bag  # the bag reader (numba, ~0.3 s): only a bag

        contents = read_bag(bag, keep=4 * CHUNK_ROWS)  # summaries past ~1 M messages: memory stays bounded
        return _inventory(contents, contents.format)
    path = paths[0]
    source = open_source(path)
    kind = detect_format(path, source.head(8), source.compression)
    if kind == "mcap":
        from wmrid.io.mcap.reader import read_mcap  # the MCAP reader (numba, ~0.3 s): only an MCAP file

        return _inventory(read_mcap(source.path or source.name, data=source.data), "mcap")
    return _inspect_table(source, kind)


def _field_paths(contents: Any, kind: str) -> dict[str, list[str]]:
    """topic -> its numeric field paths as ``--columns`` takes them (``TOPIC:PATH``), from the message definitions
    in the recording (the distribution's own for a bag without them); a type that cannot be parsed has none."""
    # rosbags' type system (~15 ms): only a bag or MCAP's field paths
    from rosbags.typesys import Stores, get_types_from_msg, get_typestore

    from wmrid.io.ros.field_paths import numeric_paths  # ROS field paths (~8 ms): only a bag or MCAP's topics

    store = get_typestore(Stores.ROS1_NOETIC if kind == "ros1 bag" else Stores.ROS2_HUMBLE)
    for msgtype, text in contents.definitions.values():
        if text:
            try:  # one type at a time: a definition rosbags cannot use loses only its own paths
                store.register(get_types_from_msg(text, _rosbags_name(msgtype)))
            except Exception:
                continue
    return {
        topic: [f"{topic}:{p}" for p in numeric_paths(store.fielddefs, _rosbags_name(msgtype))]
        for topic, (msgtype, _) in contents.definitions.items()
    }


def _rosbags_name(msgtype: str) -> str:
    pkg, _, rest = msgtype.partition("/")
    return msgtype if not rest or rest.startswith("msg/") else f"{pkg}/msg/{rest}"


def _inventory(contents: Any, kind: str) -> McapInventory:
    """The inventory of a recording's contents (an MCAP read, or a bag's through rosbags)."""
    paths = _field_paths(contents, kind)
    firsts = [c.first_ns for c in contents.channels if c.first_ns is not None]
    lasts = [c.last_ns for c in contents.channels if c.last_ns is not None]
    topics = []
    for c in contents.channels:
        entry: dict[str, Any] = {
            "topic": c.topic, "type": c.schema_name, "encoding": c.message_encoding, "messages": c.count,
            "rate_hz": c.rate_hz,
            "start_s": None if c.first_ns is None else c.first_ns * 1e-9,
            "end_s": None if c.last_ns is None else c.last_ns * 1e-9,
        }  # fmt: skip
        series = contents.joints.get(c.topic)
        if series is not None:
            entry["joints"] = list(series.names)
            entry["fields"] = {f: series.populated(f) for f in ("position", "velocity", "effort")}
            if hasattr(series, "stamp_ns"):
                stamps = series.stamp_ns
                positive, ordered = bool(np.all(stamps > 0)), bool(np.all(np.diff(stamps) >= 0))
            else:  # a summary of a long recording
                header = series.times["header"]
                positive, ordered = header.all_positive, header.ordered
            entry["header_stamps"] = (
                "all set, in order" if positive and ordered else "some zero" if not positive else "out of order"
            )
        elif c.topic in paths:
            entry["field_paths"] = paths[c.topic]
        topics.append(TopicSummary.from_dict(entry))
    return McapInventory(
        source=contents.source, profile=contents.profile, library=contents.library, size_bytes=contents.size_bytes,
        start_s=min(firsts) * 1e-9 if firsts else None, end_s=max(lasts) * 1e-9 if lasts else None,
        duration_s=(max(lasts) - min(firsts)) * 1e-9 if firsts else 0.0,
        topics=tuple(topics), metadata=sorted(contents.metadata), notes=list(contents.notes), format=kind,
    )  # fmt: skip


def _inspect_table(source, kind: str) -> TableInventory:
    if kind == "parquet":
        require("pyarrow.parquet", "parquet", f"{source.name}: reading a Parquet log")
        import pyarrow as pa  # pyarrow (~40 ms, extra [parquet]): only a Parquet log
        import pyarrow.parquet as pq  # pyarrow: only a Parquet log

        try:
            with pa.OSFile(source.path, "r") if source.path is not None else pa.BufferReader(source.data) as stream:
                pf = pq.ParquetFile(stream)
                columns = [ColumnSummary(name=f.name, type=str(f.type)) for f in pf.schema_arrow]
                rows = pf.metadata.num_rows
                notes, comments = [], []
        except (pa.ArrowException, OSError) as err:
            raise LogFormatError(f"{source.name}: not a readable Parquet file ({err})") from err
    else:
        import pandas as pd  # pandas (~0.2 s): only a CSV log

        from wmrid.io.table.csv_log import csv_layout, csv_stream  # the CSV reader (~10 ms): only a CSV log

        layout = csv_layout(source)
        try:
            with csv_stream(source) as fh:
                frame = pd.read_csv(fh, nrows=5, **layout.c_options)
        except LogFormatError:
            raise
        except (ValueError, UnicodeDecodeError) as err:
            raise layout.fail(err) from err
        columns = [ColumnSummary(name=str(c).strip(), type=str(t)) for c, t in frame.dtypes.items()]
        rows = None
        notes = layout.notes
        comments = layout.comments[:40]
    found = [c.name for c in columns]
    return TableInventory(
        source=source.name, format=kind, rows=rows, columns=tuple(columns),
        canonical_found=[c for c in CANONICAL if c in found],
        canonical_missing=[c for c in CANONICAL[:5] if c not in found],
        notes=notes, comments=comments,
    )  # fmt: skip
