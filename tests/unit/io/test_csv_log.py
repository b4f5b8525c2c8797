"""wmrid/io/table/csv_log.py: what pyarrow's CSV reader is handed.

pyarrow reads a CSV log on its own I/O threads.  A Python object its pipeline still held when the interpreter began to
exit was released on such a thread, which then had to take the GIL and died inside C++: "terminate called without an
active exception", exit 134, after the right one-line refusal (2-3 runs in 96 under load; gdb showed
``arrow::py::PyBuffer::~PyBuffer`` -> ``PyGILState_Ensure`` -> ``pthread_exit``).  That race cannot be provoked on
demand; what removes it can be checked every time: pyarrow keeps no block the log's stream returned beyond the read
that returned it (each is copied into pyarrow's memory and released while the GIL is held), and once a reading ends,
read to the end or refused part-way, it holds neither a block nor the stream.
"""

from __future__ import annotations

import gc
import io
import weakref

import pytest

from wmrid.core.errors import LogFormatError
from wmrid.io.sources import Source
from wmrid.io.table.csv_log import MAX_LINE_BYTES, _arrow_csv

pytest.importorskip("pyarrow")

NAMES = ["t", "eta_r", "eta_l", "tau_r", "tau_l"]


class _Block(bytearray):
    """A block of the log as its stream returns it: weakly referenceable, unlike bytes."""


class _Fed(io.RawIOBase):
    """A stream of ``data`` whose reads are :class:`_Block` objects, each remembered by a weak reference; each read
    first counts the earlier blocks still alive (``held``: the largest count)."""

    def __init__(self, data: bytes, source: _FedSource) -> None:
        self._data = io.BytesIO(data)
        self._source = source

    def readable(self) -> bool:
        return True

    def read(self, size: int = -1) -> _Block:  # type: ignore[override]
        handed = self._source.handed
        self._source.held = max(self._source.held, sum(ref() is not None for ref in handed))
        block = _Block(self._data.read(size))
        handed.append(weakref.ref(block))
        return block


class _FedSource(Source):
    """A log in memory whose stream is :class:`_Fed`; the streams it opened are remembered by weak references."""

    handed: list[weakref.ref]
    streams: list[weakref.ref]
    held: int

    def open(self) -> _Fed:  # type: ignore[override]
        stream = _Fed(self.data, self)  # type: ignore[arg-type]
        self.streams.append(weakref.ref(stream))
        return stream


def _source(data: bytes) -> _FedSource:
    source = _FedSource("log.csv", None, data)
    source.handed, source.streams, source.held = [], [], 0
    return source


def _read(source: Source) -> int:
    """Rows read through pyarrow's streaming reader, 1000 at a time."""
    columns = {n: n for n in NAMES}
    return sum(len(v["t"]) for v in _arrow_csv(source, ",", list(NAMES), columns, columns, 1000))


def _alive(refs: list[weakref.ref]) -> int:
    gc.collect()
    return sum(ref() is not None for ref in refs)


def test_a_log_read_to_the_end_leaves_pyarrow_holding_nothing_of_python():
    rows = b"".join(b"%d,1,1,1,1\n" % i for i in range(5000))
    source = _source(b",".join(n.encode() for n in NAMES) + b"\n" + rows)
    assert _read(source) == 5000
    assert len(source.handed) > 1
    assert source.streams
    assert source.held == 0
    assert _alive(source.handed) == 0
    assert _alive(source.streams) == 0


def test_a_log_refused_part_way_leaves_pyarrow_holding_nothing_of_python():
    """A line longer than the reader allows (the case that aborted): refused in one line, and nothing of Python left
    in pyarrow's hands."""
    head = b",".join(n.encode() for n in NAMES) + b"\n0,1,1,1,1\n"
    source = _source(head + b"1," * ((MAX_LINE_BYTES + (1 << 20)) // 2))
    with pytest.raises(LogFormatError, match="a line longer than 16 MiB"):
        _read(source)
    assert len(source.handed) > 1
    assert source.streams
    assert source.held == 0
    assert _alive(source.handed) == 0
    assert _alive(source.streams) == 0
