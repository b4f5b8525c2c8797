"""Parquet logs read a row group (or a slice of one) at a time through pyarrow, in bounded memory.

Row numbers in messages are the 1-based data row.
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from typing import Any

import numpy as np

from wmrid.core.errors import LogFormatError
from wmrid.core.extras import require
from wmrid.core.wheel_log import MIN_SAMPLES
from wmrid.io.sources import Source, one_line
from wmrid.io.table.columns import select


def parquet_chunks(
    source: Source, mapping: dict[str, str], explicit: set[str], rows: int, velocity_from: str = "velocity"
) -> tuple[Callable[[], Iterator[tuple[int, dict[str, Any]]]], Callable[[int], str], list[str], str | None]:
    """(chunks, where, notes, time unit hint) of a Parquet log; ``chunks()`` yields (first row, columns)."""
    name = source.name
    require("pyarrow.parquet", "parquet", f"{name}: reading a Parquet log")
    import pyarrow as pa  # pyarrow (~40 ms, extra [parquet]): only a Parquet log
    import pyarrow.parquet as pq  # pyarrow: only a Parquet log

    def opened() -> Any:
        try:
            return pa.OSFile(source.path, "r") if source.path is not None else pa.BufferReader(source.data)
        except (pa.ArrowException, OSError) as err:
            raise LogFormatError(f"{name}: cannot be opened ({one_line(err)})") from err

    def broken(err: BaseException) -> LogFormatError:
        return LogFormatError(
            f"{name}: not a readable Parquet file ({one_line(err)}); it may be truncated or corrupt — "
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
    notes: list[str] = []
    chosen = select(present, mapping, explicit, name, notes, velocity_from)
    twice = sorted({c for c in chosen.values() if present.count(c) > 1})
    if twice:
        raise LogFormatError(
            f"{name}: the Parquet file has {len(twice)} column name(s) used twice ({', '.join(map(repr, twice))}), so "
            "wmrid cannot tell which to read; rename one of each pair when writing the file"
        )
    wanted = list(dict.fromkeys(chosen.values()))
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
                        values = {key: arrow_values(batch.column(col), key == "t") for key, col in chosen.items()}
                        yield base, values
                        base += batch.num_rows
                    del table, batches
            except (pa.ArrowException, OSError) as err:
                raise broken(err) from err

    return chunks, lambda i: f"row {i + 1}", notes, hint


def arrow_values(arr: Any, is_time: bool = False) -> Any:
    """A column of an Arrow batch as numpy (numbers; nulls -> NaN) or, for anything else, a pandas Series."""
    import pyarrow as pa  # pyarrow (~30 ms, extra [parquet]): only a Parquet or pyarrow-read log

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
    import pyarrow as pa  # pyarrow (~30 ms, extra [parquet]): only a Parquet or pyarrow-read log

    kind = "f" if pa.types.is_floating(arr.type) else "i" if pa.types.is_signed_integer(arr.type) else "u"
    dtype = np.dtype(f"{kind}{arr.type.bit_width // 8}")
    return np.frombuffer(arr.buffers()[1], dtype=dtype, count=len(arr), offset=arr.offset * dtype.itemsize)


#: bytes: a Parquet row group larger than this decoded (rows x columns read x 8) is read in slices.
ROW_GROUP_SLICE_BYTES = 64 << 20
