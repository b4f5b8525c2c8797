"""CSV (and other delimited text) logs read piece by piece: delimiter, decimal comma, header, parsing engine.

CSV delimiter (:func:`sniff_delimiter`): among the first 20 non-blank lines, the first of tab, ``;``, ``,``
that occurs equally often (at least once) on every line; else the first that occurs in the header;
else runs of whitespace when the header splits into several words.  A ``;``-delimited file whose data
rows hold ``digit,digit`` is read with decimal commas (and a note says so).  Comma/tab/semicolon files
are parsed by the pyarrow engine (on one thread) when pyarrow is installed (the parquet extra); whitespace,
decimal-comma and ``", "``-spaced files, any file pyarrow refuses, and every file without pyarrow, by pandas' C
engine with round-trip-exact float parsing (the same values).  Row numbers in messages are
the line of the file as an editor counts it (header = line 1).
"""

from __future__ import annotations

import io
import re
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, BinaryIO

import numpy as np

from wmrid.core.errors import LogFormatError
from wmrid.core.extras import available

if TYPE_CHECKING:
    import pandas
from wmrid.io.sources import MCAP_MAGIC, PARQUET_MAGIC, SNIFF_BYTES, DamagedStream, Source, one_line
from wmrid.io.table.columns import select
from wmrid.io.table.parquet_log import arrow_values

_COMMENT_MARKS = ("%", "#")

#: What an unrecognised file is told wmrid reads (by magic bytes, whatever the suffix).
SUPPORTED = (
    "another format wmrid reads: CSV text (also gzip, bzip2, xz or zstd compressed), Parquet, MCAP, a ROS 1 bag, a "
    "ROS 2 .db3 bag or a rosbag2 folder"
)


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


def _text_head(source: Source) -> tuple[str, str, list[str]]:
    """The first bytes decoded; (text, encoding, notes).  Raises for binary or undecodable input."""
    head = source.head()
    name = source.name
    for magic, kind in ((PARQUET_MAGIC, "parquet"), (MCAP_MAGIC, "mcap")):
        if head.startswith(magic):
            raise LogFormatError(f"{name}: holds {kind.upper()} data, not CSV text; rename it with a .{kind} suffix")
    nul = head.find(b"\0")
    if nul >= 0:
        raise LogFormatError(f"{name}: not a CSV text file (byte {nul} is a NUL byte) nor {SUPPORTED}")
    try:
        return head.decode("utf-8-sig"), "utf-8", []
    except UnicodeDecodeError as err:
        if len(head) == SNIFF_BYTES and err.start >= len(head) - 3 and "end of data" in err.reason:
            return head[: err.start].decode("utf-8-sig"), "utf-8", []  # a character cut by the sniff window
        text = head.decode("latin-1")
        if any((ord(ch) < 32 and ch not in "\t\r\n\f") or 0x7F <= ord(ch) < 0xA0 for ch in text):
            raise LogFormatError(
                f"{name}: not a CSV text file (byte {err.start} is not UTF-8 text) nor {SUPPORTED}"
            ) from err
        return text, "latin-1", [f"{name} is not UTF-8; read as Latin-1 text"]


def _csv_line_finder(source: Source, skip: int = 0, has_header: bool = True) -> Callable[[int], str]:
    """Data index (0-based) -> ``"line N"``, counting every line of the file (line 1 is the first).

    skip : leading comment lines; has_header : whether a header line follows them.
    """

    def where(index: int) -> str:
        with csv_stream(source, lines=True) as fh:
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
class CsvLayout:
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


def csv_layout(source: Source) -> CsvLayout:
    """Comments, delimiter, decimal mark, header (or positional names) of a CSV file; see the module docstring."""
    import pandas as pd  # pandas (~0.2 s): only the CSV reader's fallback from pyarrow

    name = source.name
    text, encoding, notes = _text_head(source)
    if source.compression:
        notes.append(f"{source.compression}-compressed: decompressed as it was read")
    if "\n" not in text and "\r" not in text and len(source.head(SNIFF_BYTES + 1)) > SNIFF_BYTES:
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
        msg = one_line(err).replace("Error tokenizing data. C error: ", "")
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
        with csv_stream(source) as fh:
            header = pd.read_csv(fh, nrows=0 if has_header else 1, **c_options)
    except LogFormatError:
        raise
    except (ValueError, UnicodeDecodeError) as err:
        raise fail(err) from err
    except DamagedStream as err:
        raise source.damaged(err) from err
    if not has_header:
        c_options["names"] = [str(i + 1) for i in range(len(header.columns))]
        header = header.set_axis(c_options["names"], axis=1)
    present = [str(c).strip() for c in header.columns]
    if spaced:
        notes.append("spaces around column names and values ignored")
    comments = lines[:skip]
    return CsvLayout(c_options, list(header.columns), present, notes, skip, has_header, spaced, fail, comments)


def csv_chunks(
    source: Source, mapping: dict[str, str], explicit: set[str], rows: int, velocity_from: str = "velocity"
) -> tuple[Callable[[], Iterator[tuple[int, dict[str, Any]]]], Callable[[int], str], list[str], None]:
    """(chunks, where, notes, None) of a CSV log; ``chunks()`` yields (first data row, columns) of ``rows`` rows.

    Plain files (comma, tab or semicolon, no comments, a header) are parsed by pyarrow's streaming CSV
    reader; anything it refuses, from the row it refused on, and all other files by pandas' C engine.
    """
    import pandas as pd  # pandas (~0.2 s): only the CSV reader's fallback from pyarrow

    name = source.name
    layout = csv_layout(source)
    c_options, present, notes = layout.c_options, layout.present, layout.notes
    header = pd.DataFrame(columns=layout.header_columns)
    chosen = select(present, mapping, explicit, name, notes, velocity_from)
    actual = {str(c).strip(): c for c in header.columns}
    usecols = list(dict.fromkeys(actual[c] for c in chosen.values()))
    plain = (
        available("pyarrow.csv")  # the parquet extra
        and c_options["sep"] in (",", "\t", ";")
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
            with csv_stream(source) as fh, pd.read_csv(fh, chunksize=rows, **c_options) as reader:
                for frame in reader:
                    n = len(frame)
                    if base + n > skip_rows:
                        start = max(skip_rows - base, 0)
                        frame = frame.iloc[start:]
                        frame.columns = [str(c).strip() for c in frame.columns]
                        yield base + start, {key: _series_values(frame[col]) for key, col in chosen.items()}
                    base += n
        except LogFormatError:
            raise
        except (ValueError, UnicodeDecodeError) as err:
            raise layout.fail(err) from err
        except DamagedStream as err:
            raise source.damaged(err) from err

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
    source: Source, sep: str, usecols: list[Any], chosen: dict[str, str], actual: dict[str, Any], rows: int
) -> Iterator[dict[str, Any]]:
    """Column values of ``rows``-row pieces read by pyarrow's streaming CSV reader (raises _ArrowCsvRefused)."""
    import pyarrow as pa  # pyarrow (~30 ms, extra [parquet]): the fast CSV path, when installed
    import pyarrow.csv as pcsv  # pyarrow: the fast CSV path, when installed

    fh = csv_stream(source)
    fh.defer_errors()  # type: ignore[attr-defined]  # (a _LineGuard) pyarrow reads on its own threads
    # pyarrow reads through a buffered native stream, which copies each block out of the bytes object read() returns
    # while it holds the GIL: handed the Python file itself, its reader kept those bytes objects, and one released on
    # one of its I/O threads after the interpreter began to exit made that thread take the GIL and die inside C++
    # ("terminate called without an active exception", exit 134, after the right message: 2-3 runs in 96 under
    # load, a 300 MB line in an xz file; gdb: arrow::py::PyBuffer::~PyBuffer -> PyGILState_Ensure ->
    # pthread_exit).  Closing the stream (``release``) closes the Python file on this thread and drops it, so nothing
    # pyarrow keeps holds a Python object.
    stream = pa.BufferedInputStream(pa.PythonFile(fh, mode="r"), buffer_size=1 << 24)
    release = stream.close

    try:
        reader = pcsv.open_csv(
            stream,
            # One parsing thread (the stream is read on pyarrow's I/O thread all the same: see above).
            read_options=pcsv.ReadOptions(block_size=1 << 24, use_threads=False),
            parse_options=pcsv.ParseOptions(delimiter=sep),
            convert_options=pcsv.ConvertOptions(include_columns=usecols),
        )
    except LogFormatError:
        release()
        raise
    except (pa.ArrowException, OSError, ValueError) as err:
        release()
        fh.raise_deferred()  # type: ignore[attr-defined]
        raise _ArrowCsvRefused from err
    pending: list[Any] = []
    count = 0

    def values(table: Any) -> dict[str, Any]:
        return {key: arrow_values(table.column(actual[col]).combine_chunks()) for key, col in chosen.items()}

    try:
        with fh, reader:
            for batch in reader:
                fh.raise_deferred()  # type: ignore[attr-defined]
                pending.append(batch)
                count += batch.num_rows
                while count >= rows:  # pieces of exactly ``rows`` rows, whatever pyarrow's block size
                    table = pa.Table.from_batches(pending)
                    yield values(table.slice(0, rows))
                    rest = table.slice(rows)
                    pending, count = rest.to_batches(), rest.num_rows
    except LogFormatError:
        raise
    except (pa.ArrowException, OSError, ValueError) as err:
        fh.raise_deferred()  # type: ignore[attr-defined]
        raise _ArrowCsvRefused from err
    finally:
        release()
    fh.raise_deferred()  # type: ignore[attr-defined]
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


#: bytes: the longest first line (header) of a CSV log; a 10 M-column header took 3.4 GB and 75 s to refuse.
MAX_HEADER_BYTES = 1 << 20


#: bytes: the longest line of a CSV log, and the longest run of line ends in a row (blank lines: a million of
#: them).  The parsers skip blank lines and hold a line whole: a header and 2 GB of blank lines took 41 s and
#: 1.18 GB, one line of gigabytes would fill memory.  A log past either is refused as it is read: a line over
#: twice MAX_LINE_BYTES always, one within it never (likewise blank lines and MAX_BLANK_RUN).
MAX_LINE_BYTES = 16 << 20
MAX_BLANK_RUN = 1 << 20

_CR_TO_LF = bytes.maketrans(b"\r", b"\n")
_BLANK_RUN = b"\n" * MAX_BLANK_RUN


class _LineGuard(io.RawIOBase):
    """A CSV log's byte stream that raises LogFormatError (naming the log and the byte reached) once a line passes
    :data:`MAX_LINE_BYTES` or a run of blank lines :data:`MAX_BLANK_RUN` line ends (each within a factor of two: see
    there); otherwise the bytes as they are, uncopied.  Each block read costs a few C-speed look-ups: a long line or
    run holds a whole segment of the limit's length, aligned in the block, that has no line end (or only line ends),
    and a segment is tested by its first bytes, which differ at once in a log's ordinary text."""

    def __init__(self, raw: BinaryIO, name: str):
        self._raw, self._name = raw, name
        self._line = 0  # bytes of the line not yet ended, carried from the blocks before
        self._run = 0  # line-end bytes in a row at the end of the blocks before
        self._offset = 0  # bytes read before this block (for the message)
        self._defer = False  # keep a refusal for raise_deferred() and read as at the end instead of raising
        self.deferred: LogFormatError | None = None

    def defer_errors(self) -> None:
        """Keep a refusal instead of raising it, and read as at the end from then on; the reader's own thread then
        raises it with :meth:`raise_deferred`.  For pyarrow's CSV reader, which reads on its I/O threads: an exception
        raised there while the process exits left a thread behind, and the process aborted ("terminate called
        without an active exception", exit 134, after the right message; seen once under load)."""
        self._defer = True

    def raise_deferred(self) -> None:
        """Raise the refusal kept by :meth:`defer_errors`, if any."""
        if self.deferred is not None:
            raise self.deferred

    def readable(self) -> bool:
        return True

    def read(self, size: int = -1) -> bytes:
        if self.deferred is not None:
            return b""
        data = self._raw.read(size)
        if data:
            self._check(data)
            if self.deferred is not None:
                return b""
            self._offset += len(data)
        return data

    def readinto(self, buffer: Any) -> int:
        data = self.read(len(buffer))
        buffer[: len(data)] = data
        return len(data)

    def _check(self, block: bytes) -> None:
        try:
            self._check_block(block)
        except LogFormatError as err:
            if not self._defer:
                raise
            self.deferred = err

    def _check_block(self, block: bytes) -> None:
        if b"\r" in block:
            block = block.translate(_CR_TO_LF)
        first = block.find(b"\n")
        if first < 0:
            first = len(block)
        if self._line + first > MAX_LINE_BYTES:
            self._refuse(f"a line longer than {MAX_LINE_BYTES >> 20} MiB", self._offset - self._line)
        for start in range(first, len(block) - MAX_LINE_BYTES + 1, MAX_LINE_BYTES):
            if block.find(b"\n", start, start + MAX_LINE_BYTES) < 0:
                self._refuse(f"a line longer than {MAX_LINE_BYTES >> 20} MiB", self._offset + start)
        if first == len(block):
            self._line += len(block)
            self._run = 0
            return
        lead = len(block) - len(block.lstrip(b"\n"))
        if self._run + lead > MAX_BLANK_RUN:
            self._refuse(f"more than {MAX_BLANK_RUN:,} blank lines in a row", self._offset - self._run)
        for start in range(lead, len(block) - MAX_BLANK_RUN + 1, MAX_BLANK_RUN):
            if block.startswith(_BLANK_RUN, start):
                self._refuse(f"more than {MAX_BLANK_RUN:,} blank lines in a row", self._offset + start)
        tail = len(block) - len(block.rstrip(b"\n"))
        self._run = self._run + len(block) if tail == len(block) else tail
        self._line = len(block) - block.rfind(b"\n") - 1

    def _refuse(self, what: str, where: int) -> None:
        raise LogFormatError(
            f"{self._name}: {what} (from byte {max(where, 0):,}), which no "
            f"wheel log has: wmrid reads lines of at most {MAX_LINE_BYTES >> 20} MiB and at most {MAX_BLANK_RUN:,} "
            "blank lines in a row; check the file, or remove them (grep -v '^$')"
        )

    def close(self) -> None:
        if not self.closed:
            try:
                self._raw.close()
            finally:
                super().close()


def csv_stream(source: Source, lines: bool = False) -> BinaryIO:
    """The (decompressed) bytes of the CSV log ``source``, its lines and runs of blank lines bounded
    (:class:`_LineGuard`), to be closed by the caller; ``lines``: buffered, to be read line by line."""
    guard = _LineGuard(source.open(), source.name)
    return io.BufferedReader(guard, 1 << 16) if lines else guard  # type: ignore[return-value]
