"""Whole units out of bytes that arrive in pieces: CSV lines, JSON lines (turned into CSV lines) and MCAP records.

A unit cut by the end of what has arrived so far (a torn last line or record) is held back until its remainder
arrives; :attr:`consumed` counts the bytes of the whole units handed on, so a copy of the first ``consumed`` bytes
is exactly what was read.  Memory: the units not yet taken, and one torn unit (a line up to 1 MiB, a record up to
the memory budget).
"""

from __future__ import annotations

import csv
import io
import json
import math
from collections.abc import Callable

from wmrid.core.errors import LogFormatError
from wmrid.io.mcap.records import (
    MAGIC,
    OP_CHANNEL,
    OP_CHUNK,
    OP_DATA_END,
    OP_FOOTER,
    OP_HEADER,
    OP_MESSAGE,
    OP_SCHEMA,
    decompress,
)

#: bytes: the longest line a followed CSV may have (a wheel log's row is well under 1 KiB)
MAX_LINE = 1 << 20

#: The comment marks of CSV logs (wmrid.io.table.csv_log skips such leading lines).
COMMENT_MARKS = ("#", "%")


class LineFramer:
    """Bytes to whole lines (each ending in a newline); the torn last line is held back."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.tail = b""
        self.consumed = 0  # bytes of the whole lines handed out

    def push(self, data: bytes) -> bytes:
        """The whole lines completed by ``data`` (b"" when none)."""
        buf = self.tail + data
        cut = buf.rfind(b"\n") + 1
        self.tail = buf[cut:]
        if len(self.tail) > MAX_LINE:
            raise LogFormatError(f"{self.name}: a line longer than {MAX_LINE >> 20} MiB; a wheel log's rows are short")
        self.consumed += cut
        return buf[:cut]

    def flush(self) -> bytes:
        """The last line when the stream has ended without a newline after it (b"" when none)."""
        rest, self.tail = self.tail, b""
        self.consumed += len(rest)
        return rest + b"\n" if rest.strip() else b""


class CsvBatcher:
    """Whole CSV lines to batches that read as CSV files of their own: the prelude (leading comment lines and the
    header line), then the data lines that arrived since the last batch.

    A file without a header (its first line all numbers) has no header in its prelude: its columns are named by
    position in every batch, as the CSV reader names them in the whole file.
    """

    def __init__(self, name: str) -> None:
        self.name = name
        self.prelude: bytes | None = None
        self._head = b""  # the lines before the header is known
        self._rows: list[bytes] = []
        self.rows = 0  # data lines handed out in batches so far

    def push(self, lines: bytes) -> None:
        """Add whole lines (``lines`` ends in a newline or is empty)."""
        if not lines:
            return
        if self.prelude is None:
            self._head += lines
            prelude, rest = _prelude(self._head)
            if prelude is None:
                return
            self.prelude, self._head = prelude, b""
            lines = rest
        if lines:
            self._rows.append(lines)

    def take(self) -> tuple[bytes, int] | None:
        """(a batch: the prelude and the new data lines, the data lines before them), or None when none arrived."""
        if self.prelude is None or not self._rows:
            return None
        body = b"".join(self._rows)
        self._rows = []
        before = self.rows
        self.rows += body.count(b"\n")
        return self.prelude + body, before


def _prelude(text: bytes) -> tuple[bytes | None, bytes]:
    """(comment lines and the header line, the lines after them) once a line that is neither blank nor a comment
    has arrived, else (None, text).  A first such line that holds only numbers is data: the prelude is then the
    comments alone."""
    from wmrid.io.table.csv_log import _all_numbers, sniff_delimiter  # the CSV reader (~10 ms): only a CSV stream

    pos = 0
    while True:
        end = text.find(b"\n", pos)
        if end < 0:
            return None, text
        line = text[pos:end].decode("utf-8", "replace").lstrip("\ufeff")
        if line.strip() and not line.lstrip().startswith(COMMENT_MARKS):
            sep, decimal = sniff_delimiter(text[pos:].decode("utf-8", "replace"))
            if _all_numbers(line.strip(), sep, decimal):
                return text[:pos], text[pos:]
            return text[: end + 1], text[end + 1 :]
        pos = end + 1


class JsonLines:
    """JSON lines (one flat object per line: ``{"t": 0.001, "eta_r": 1.2, ...}``) to CSV lines whose header is the
    keys of the first object, so the CSV reader (and ``--columns``) reads them as it reads a CSV log.  A key missing
    from a later line is an empty cell (the reader names its row); keys the first line did not have are ignored."""

    def __init__(self, name: str) -> None:
        self.name = name
        self.keys: list[str] | None = None
        self.line = 0

    def convert(self, lines: bytes) -> bytes:
        """CSV lines (the header first, on the first call) for whole JSON lines."""
        out = io.StringIO()
        writer = csv.writer(out, lineterminator="\n")
        for raw in lines.splitlines():
            self.line += 1
            if not raw.strip():
                continue
            try:
                obj = json.loads(raw)
            except (ValueError, RecursionError) as err:
                raise LogFormatError(
                    f"{self.name}: line {self.line} is not JSON ({err}); give one object per line"
                ) from err
            if not isinstance(obj, dict):
                raise LogFormatError(
                    f"{self.name}: line {self.line} is {type(obj).__name__}, not an object; give one object per line, "
                    'e.g. {"t": 0.001, "eta_r": 1.2, "eta_l": 1.1, "tau_r": 0.3, "tau_l": 0.2}'
                )
            if self.keys is None:
                self.keys = [str(k) for k in obj]
                writer.writerow(self.keys)
            writer.writerow([_cell(obj.get(k), k, self.name, self.line) for k in self.keys])
        return out.getvalue().encode("utf-8")


def _cell(value: object, key: str, name: str, line: int) -> str:
    if value is None:
        return ""
    if isinstance(value, (bool, dict, list)):
        raise LogFormatError(
            f"{name}: line {line}, key {key!r}: {json.dumps(value)[:40]} is not a number; give flat objects of numbers"
        )
    if isinstance(value, float):
        return repr(value) if math.isfinite(value) else ""
    return str(value)


#: The opcode and body of MCAP's DataEnd (CRC 0: not computed) and Footer (no summary) records.
_DATA_END = bytes([OP_DATA_END]) + (4).to_bytes(8, "little") + bytes(4)
_FOOTER = bytes([OP_FOOTER]) + (20).to_bytes(8, "little") + bytes(20)


def _string(body: bytes, p: int) -> tuple[str, int]:
    n = int.from_bytes(body[p : p + 4], "little")
    return body[p + 4 : p + 4 + n].decode("utf-8", "replace"), p + 4 + n


class McapFramer:
    """MCAP records out of bytes that arrive in pieces (an MCAP file being written, a pipe), record by record.

    Schemas and channels are kept (small); the messages of the channels ``keep(topic, schema_name)`` accepts are
    kept raw until :meth:`take` puts them in a batch: a small MCAP file of their own (the header, the kept schemas
    and channels, the messages, a footer) that wmrid's MCAP reader decodes as it decodes any file.  A chunk is
    decompressed once it is whole (wmrid's own decompression, bounded by the size the chunk declares).  ``finished``
    once the footer is read; a torn last record waits for its remainder.
    """

    def __init__(self, name: str, keep: Callable[[str, str], bool], max_record: int) -> None:
        self.name = name
        self.keep = keep
        self.max_record = max_record
        self.buf = b""
        self.consumed = 0  # bytes of the whole records read (the magic included)
        self.started = False
        self.finished = False
        self.header = b""
        self.schemas: dict[int, tuple[str, bytes]] = {}
        self.channels: dict[int, bytes] = {}
        self.kept: set[int] = set()
        self.messages: list[bytes] = []
        self.message_count = 0  # messages of kept channels read so far

    @property
    def held(self) -> int:
        """Bytes of a torn record waiting for its remainder."""
        return len(self.buf)

    def push(self, data: bytes) -> None:
        """Read the whole records ``data`` completes."""
        buf = self.buf + data
        pos = 0
        if not self.started:
            if len(buf) < len(MAGIC):
                if not MAGIC.startswith(buf):
                    raise LogFormatError(f"{self.name}: not an MCAP file (it does not start with MCAP's magic bytes)")
                self.buf = buf
                return
            if not buf.startswith(MAGIC):
                raise LogFormatError(f"{self.name}: not an MCAP file (it does not start with MCAP's magic bytes)")
            self.started = True
            pos = len(MAGIC)
        while not self.finished and len(buf) - pos >= 9:
            length = int.from_bytes(buf[pos + 1 : pos + 9], "little")
            if length > self.max_record:
                raise LogFormatError(
                    f"{self.name}: a record of {length:,} bytes at byte {self.consumed + pos}, beyond the memory "
                    "budget (WMRID_MEMORY_BUDGET); a damaged file?"
                )
            if len(buf) - pos - 9 < length:
                break  # torn: wait for the remainder
            op = buf[pos]
            self._record(op, buf[pos + 9 : pos + 9 + length], buf[pos : pos + 9 + length])
            pos += 9 + length
        if self.finished and len(buf) - pos >= len(MAGIC) and buf[pos : pos + len(MAGIC)] == MAGIC:
            pos += len(MAGIC)
        self.consumed += pos
        self.buf = buf[pos:]

    def _record(self, op: int, body: bytes, raw: bytes) -> None:
        if op == OP_HEADER:
            self.header = raw
        elif op == OP_SCHEMA:
            sid = int.from_bytes(body[0:2], "little")
            self.schemas[sid] = (_string(body, 2)[0], raw)
        elif op == OP_CHANNEL:
            cid = int.from_bytes(body[0:2], "little")
            sid = int.from_bytes(body[2:4], "little")
            topic = _string(body, 4)[0]
            self.channels[cid] = raw
            schema = self.schemas.get(sid, ("", b""))[0]
            if self.keep(topic, schema):
                self.kept.add(cid)
            else:
                self.kept.discard(cid)
        elif op == OP_MESSAGE:
            if int.from_bytes(body[0:2], "little") in self.kept:
                self.messages.append(raw)
                self.message_count += 1
        elif op == OP_CHUNK:
            size = int.from_bytes(body[16:24], "little")
            if size > self.max_record:
                raise LogFormatError(f"{self.name}: a chunk declaring {size:,} bytes, beyond the memory budget")
            compression, p = _string(body, 28)
            n = int.from_bytes(body[p : p + 8], "little")
            inner = decompress(self.name, compression, body[p + 8 : p + 8 + n], size)
            q = 0
            while len(inner) - q >= 9:
                length = int.from_bytes(inner[q + 1 : q + 9], "little")
                if len(inner) - q - 9 < length:
                    break  # a damaged chunk: what it holds whole was read
                if inner[q] in (OP_SCHEMA, OP_CHANNEL, OP_MESSAGE):
                    self._record(inner[q], inner[q + 9 : q + 9 + length], inner[q : q + 9 + length])
                q += 9 + length
        elif op == OP_FOOTER:
            self.finished = True

    def take(self) -> bytes | None:
        """The kept messages read since the last batch as a small MCAP file of their own, or None when none."""
        if not self.messages:
            return None
        used = {int.from_bytes(self.channels[c][9 + 2 : 9 + 4], "little") for c in self.kept if c in self.channels}
        parts = [MAGIC, self.header]
        parts += [raw for sid, (_, raw) in self.schemas.items() if sid in used]
        parts += [self.channels[c] for c in sorted(self.kept) if c in self.channels]
        parts += self.messages
        parts += [_DATA_END, _FOOTER, MAGIC]
        self.messages = []
        return b"".join(parts)
