"""Series of JSON messages written as MCAP (:func:`write_series_mcap`): the estimates over time and the prediction
errors (``wmrid identify --mcap-out``), to plot in Foxglove beside the log."""

from __future__ import annotations

import json
import math
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import Any

import numpy as np
from mcap.well_known import MessageEncoding, SchemaEncoding

from wmrid.core.errors import UsageError
from wmrid.core.extras import available
from wmrid.io.mcap.writer import (
    _SERIES_BLOCK_ROWS,
    CHUNK_SIZE,
    EPOCH_NS,
    _check_chunk_size,
    _check_metadata,
    _check_topic,
    _compression,
    _open_writer,
    _stamps_ns,
)
from wmrid.runtime.atomic import atomic_output


def series_json_schema(names: Iterable[str]) -> dict:
    """The JSON Schema of a :func:`write_series_mcap` message: an object with number ``t`` and ``names``."""
    properties: dict[str, Any] = {"t": {"type": "number", "description": "time since the start of the log, s"}}
    for name in names:
        properties[name] = {"type": "number", "description": "null when not finite"}
    return {
        "title": "wmrid series",
        "type": "object",
        "properties": properties,
        "required": list(properties),
    }


def _json_numbers(values: np.ndarray) -> Any:
    """(n,) float64 -> pyarrow strings: the shortest text that reads back bit for bit, ``null`` if not finite.

    Arrow's float formatter writes an integral value without a fraction (``-0``, ``3``); ``.0`` is appended
    so that it reads back as a float, with its sign (``-0.0``).
    """
    import pyarrow as pa  # pyarrow (extra [parquet]): the fast path, when installed
    import pyarrow.compute as pc  # pyarrow.compute (~60 ms): the fast path, when installed

    arr = pa.array(values, type=pa.float64())
    text = pc.cast(arr, pa.string())
    integral = pc.match_substring_regex(text, r"^-?[0-9]+$")
    text = pc.if_else(integral, pc.binary_join_element_wise(text, pa.scalar(".0"), ""), text)
    return pc.if_else(pc.is_finite(arr), text, pa.scalar("null"))


def _json_objects(columns: Mapping[str, np.ndarray]) -> tuple[bytes, list[int]]:
    """One JSON object per row, ``{"name": value, ...}`` in the order of ``columns``, back to back.

    columns : {name: (n,) float64}.  Returns the UTF-8 bytes of the n objects and their n + 1 offsets
    (object i is ``data[offsets[i]:offsets[i + 1]]``).  Formatted by Arrow when pyarrow is installed (the parquet
    extra; about 10x faster), else by :func:`_json_objects_python`: the same numbers, bit for bit (the texts may
    differ: Arrow writes ``0.00001`` where ``repr`` writes ``1e-05``).
    """
    if not available("pyarrow.compute"):
        return _json_objects_python(columns)
    import pyarrow as pa  # pyarrow (extra [parquet]): the fast path, when installed
    import pyarrow.compute as pc  # pyarrow.compute (~60 ms): the fast path, when installed

    parts: list[Any] = []
    for k, (name, values) in enumerate(columns.items()):
        parts.append(pa.scalar(("{" if k == 0 else ",") + json.dumps(name) + ":"))
        parts.append(_json_numbers(values))
    parts.append(pa.scalar("}"))
    joined = pc.binary_join_element_wise(*parts, "")
    n = len(joined)
    offsets = np.frombuffer(joined.buffers()[1], dtype=np.int32, count=n + 1, offset=4 * joined.offset)
    return joined.buffers()[2].to_pybytes(), offsets.tolist()


def _json_objects_python(columns: Mapping[str, np.ndarray]) -> tuple[bytes, list[int]]:
    """:func:`_json_objects` without pyarrow: each float as ``repr`` writes it (the shortest text that reads back bit
    for bit, ``3.0`` for an integral one), ``null`` when not finite."""
    keys = [("{" if k == 0 else ",") + json.dumps(name) + ":" for k, name in enumerate(columns)]
    texts = [
        [repr(v) if math.isfinite(v) else "null" for v in np.asarray(values, dtype=np.float64).tolist()]
        for values in columns.values()
    ]
    rows = [
        "".join(part for pair in zip(keys, row, strict=True) for part in pair) + "}" for row in zip(*texts, strict=True)
    ]
    encoded = [row.encode("utf-8") for row in rows]
    offsets = np.concatenate([[0], np.cumsum([len(b) for b in encoded], dtype=np.int64)]).tolist()
    return b"".join(encoded), offsets


def write_series_mcap(
    path: str | Path,
    t: np.ndarray,
    series: Mapping[str, np.ndarray],
    *,
    topic: str = "/wmrid/estimates",
    force: bool = False,
    metadata: Mapping[str, str] | None = None,
    t0_ns: int = EPOCH_NS,
    compression: str = "zstd",
    chunk_size: int = CHUNK_SIZE,
) -> None:
    """Write named time series as an MCAP JSON channel, one message per time step.

    t : (n,) float seconds, non-decreasing, on the same clock as the log (0 = its start).
    series : {name: (n,) array}, e.g. ``theta11``, ``e_r``, ``lambda_min``; converted to float64.
    path : the ``.mcap`` file; written atomically, replaced only with ``force``.

    Message i on ``topic`` (message encoding ``json``, schema encoding ``jsonschema``, schema
    :func:`series_json_schema`) is the object ``{"t": t[i], name: series[name][i], ...}`` with the names in
    the order given, every number written with ``repr`` (reads back bit for bit) and NaN or infinite
    values as ``null``.  Its log and publish time are ``t0_ns + round(t[i] * 1e9)`` ns, as in
    :func:`write_joint_state_mcap` with the same ``t0_ns``, so both files line up in Foxglove.
    metadata : one MCAP metadata record named ``"wmrid"``.  compression, chunk_size : as in
    :func:`write_joint_state_mcap`.

    Raises :class:`UsageError` for malformed input and :class:`~wmrid.core.errors.OutputExistsError` if
    ``path`` exists and ``force`` is false.
    """
    topic = _check_topic(topic, "topic")
    chunk_size = _check_chunk_size(chunk_size)
    _compression(compression)
    metadata = _check_metadata(metadata)
    stamps = _stamps_ns(t, t0_ns, "t")
    n = len(stamps)
    columns: dict[str, np.ndarray] = {"t": np.asarray(t, dtype=np.float64)}
    for name, values in series.items():
        if not isinstance(name, str) or not name or name == "t":
            raise UsageError(f"series names must be non-empty strings other than 't', got {name!r}")
        arr = np.asarray(values)
        if arr.shape != (n,) or arr.dtype.kind not in "fiub":
            raise UsageError(f"series {name!r} must be a numeric array of shape ({n},), got {arr.dtype} {arr.shape}")
        columns[name] = arr.astype(np.float64, copy=False)
    schema_text = json.dumps(series_json_schema([name for name in columns if name != "t"]), indent=2)

    with atomic_output(path, force=force, mode="wb") as fh:
        writer = _open_writer(fh, compression, chunk_size, "")
        if metadata is not None:
            writer.add_metadata("wmrid", metadata)
        schema = writer.register_schema("wmrid.Series", SchemaEncoding.JSONSchema, schema_text.encode("utf-8"))
        channel = writer.register_channel(topic, MessageEncoding.JSON, schema)
        add = writer.add_message
        for start in range(0, n, _SERIES_BLOCK_ROWS):
            block = slice(start, start + _SERIES_BLOCK_ROWS)
            data, offsets = _json_objects({name: values[block] for name, values in columns.items()})
            for i, stamp in enumerate(stamps[block].tolist()):
                add(channel, stamp, data[offsets[i] : offsets[i + 1]], stamp, (start + i) & 0xFFFFFFFF)
        writer.finish()
