"""What a log holds, before any identification: the first thing to run on an unknown recording.

For an MCAP: every topic with its message type, encoding, message count, rate and time range, and for
each JointState topic its joints and whether position, velocity and effort are populated.  For CSV and
Parquet: the columns, the number of rows, and which canonical columns were found.  The result is a
plain dict (the JSON form); :func:`wmrid.reporting.render.print_inspection` draws it as tables.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from wmrid.core.errors import LogFormatError


def inspect_log(path: str) -> dict[str, Any]:
    """A description of the log at ``path`` (or ``-``): {"source", "format", ...}; see the module docstring."""
    from wmrid.io.sources import detect_format
    from wmrid.io.sources import open_source as _open_source

    source = _open_source(path)
    kind = detect_format(path, source.head(8))
    if kind == "mcap":
        return _inspect_mcap(source)
    return _inspect_table(source, kind)


def _inspect_mcap(source) -> dict[str, Any]:
    from wmrid.io.mcap.reader import read_mcap

    contents = read_mcap(source.path or source.name, data=source.data)
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
            stamps = series.stamp_ns
            entry["header_stamps"] = (
                "all set, in order" if np.all(stamps > 0) and np.all(np.diff(stamps) >= 0)
                else "some zero" if np.any(stamps <= 0) else "out of order"
            )  # fmt: skip
        topics.append(entry)
    return {
        "source": contents.source, "format": "mcap", "profile": contents.profile, "library": contents.library,
        "size_bytes": contents.size_bytes,
        "start_s": min(firsts) * 1e-9 if firsts else None, "end_s": max(lasts) * 1e-9 if lasts else None,
        "duration_s": (max(lasts) - min(firsts)) * 1e-9 if firsts else 0.0,
        "topics": topics, "metadata": sorted(contents.metadata), "notes": list(contents.notes),
    }  # fmt: skip


def _inspect_table(source, kind: str) -> dict[str, Any]:
    from wmrid.core.wheel_log import CANONICAL

    if kind == "parquet":
        import pyarrow as pa
        import pyarrow.parquet as pq

        try:
            with pa.OSFile(source.path, "r") if source.path is not None else pa.BufferReader(source.data) as stream:
                pf = pq.ParquetFile(stream)
                columns = [{"name": f.name, "type": str(f.type)} for f in pf.schema_arrow]
                rows = pf.metadata.num_rows
                notes, comments = [], []
        except (pa.ArrowException, OSError) as err:
            raise LogFormatError(f"{source.name}: not a readable Parquet file ({err})") from err
    else:
        import pandas as pd

        from wmrid.io.csv_log import _csv_layout

        layout = _csv_layout(source)
        try:
            frame = pd.read_csv(source.opener(), nrows=5, **layout.c_options)
        except (ValueError, UnicodeDecodeError) as err:
            raise layout.fail(err) from err
        columns = [{"name": str(c).strip(), "type": str(t)} for c, t in frame.dtypes.items()]
        rows = None
        notes = layout.notes
        comments = layout.comments[:40]
    names = [c["name"] for c in columns]
    return {
        "source": source.name, "format": kind, "rows": rows, "columns": columns,
        "canonical_found": [c for c in CANONICAL if c in names],
        "canonical_missing": [c for c in CANONICAL[:5] if c not in names],
        "notes": notes,
        "comments": comments,
    }  # fmt: skip
