"""Where a log comes from and what format it is: a file, a FIFO or standard input, recognised by suffix or magic bytes.

Format: by suffix (``.csv .txt .tsv`` -> CSV, ``.parquet .pq`` -> Parquet, ``.mcap`` -> MCAP); any other suffix,
and standard input (``-``), by the first bytes (:func:`detect_format`), which also names the formats wmrid does not
read (ROS 1 bags, SQLite, zip archives) instead of failing on them as text.

Compression: a gzip, bzip2, xz or zstd stream (recognised by its magic bytes, whatever the suffix) is decompressed
as it is read (:attr:`Source.compression`, :meth:`Source.open`); a CSV log inside is read as any CSV log, in
pieces (memory does not grow with the file).  Another format inside a compressed file is refused with the command
that decompresses it.
"""

from __future__ import annotations

import errno
import io
import os
import sys
from dataclasses import dataclass, field
from typing import Any, BinaryIO

from wmrid.core.errors import LogFormatError, UsageError
from wmrid.io.table.columns import suggest
from wmrid.runtime.limits import memory_budget, read_limited

CSV_SUFFIXES = (".csv", ".txt", ".tsv")


PARQUET_SUFFIXES = (".parquet", ".pq")


_MCAP_SUFFIXES = (".mcap",)


PARQUET_MAGIC = b"PAR1"


MCAP_MAGIC = b"\x89MCAP"


SNIFF_BYTES = 65536


STDIN_NAME = "<stdin>"


#: (magic bytes, what the file is, the fix) of formats wmrid recognises but does not read.
_OTHER_FORMATS = (
    (b"PK\x03\x04", "a zip archive", "unpack it first and give the log inside"),
    (b"#ROSBAG", "a ROS 1 bag", "wmrid reads bags from files: save it to a file (decompressed) and give its path"),
    (b"SQLite f", "an SQLite database (a ROS 2 .db3 bag?)", "wmrid reads bags from files: give the .db3 file's path"),
)


_COMPRESSION_SUFFIXES = (".gz", ".gzip", ".bz2", ".xz", ".zst", ".zstd")


#: (magic bytes, name, the command that decompresses a file) of the compressed streams read transparently.
COMPRESSIONS = (
    (b"\x1f\x8b", "gzip", "gunzip -k FILE"),
    (b"BZh", "bzip2", "bunzip2 -k FILE"),
    (b"\xfd7zXZ\x00", "xz", "unxz -k FILE"),
    (b"\x28\xb5\x2f\xfd", "zstd", "zstd -d FILE"),
)


def compression_of(head_bytes: bytes) -> str | None:
    """The name of the compression (see COMPRESSIONS) the bytes start with, else None (a zstd stream may also
    start with a skippable frame, magic 0x184D2A50-5F)."""
    skippable = len(head_bytes) >= 4 and 0x50 <= head_bytes[0] <= 0x5F and head_bytes[1:4] == b"\x2a\x4d\x18"
    if skippable:
        return "zstd"
    return next((name for magic, name, _ in COMPRESSIONS if head_bytes.startswith(magic)), None)


def decompress_command(compression: str) -> str:
    return next(fix for _, name, fix in COMPRESSIONS if name == compression)


def detect_format(path: str, head_bytes: bytes, compression: str | None = None) -> str:
    """``"csv"``, ``"parquet"`` or ``"mcap"``: from the suffix of ``path``, else from the magic bytes.

    ``path`` ``"-"`` (standard input) or an unknown suffix: ``PAR1`` -> parquet, ``\\x89MCAP`` -> mcap,
    anything else -> csv.  An archive, a ROS 1 bag or an SQLite database (whatever its suffix)
    is refused with LogFormatError naming what it is and how to get a log out of it.  compression : the
    compression of the file (``head_bytes`` are then the decompressed ones, and a compression suffix such as
    ``.gz`` is looked through); only a CSV log is read compressed, anything else inside is refused.
    """
    name = STDIN_NAME if path == "-" else path
    stem = path
    if compression is not None and os.path.splitext(path)[1].lower() in _COMPRESSION_SUFFIXES:
        stem = os.path.splitext(path)[0]
    suffix = os.path.splitext(stem)[1].lower() if path != "-" else ""
    for magic, what, fix in _OTHER_FORMATS:
        if head_bytes.startswith(magic):
            inside = f"a {compression}-compressed file holding {what}" if compression else what
            raise LogFormatError(f"{name}: {inside}, not a CSV, Parquet or MCAP log; {fix}")
    if compression is not None:
        for magic, kind, suffixes in (
            (PARQUET_MAGIC, "Parquet", PARQUET_SUFFIXES),
            (MCAP_MAGIC, "MCAP", _MCAP_SUFFIXES),
        ):
            if head_bytes.startswith(magic) or suffix in suffixes:
                raise LogFormatError(
                    f"{name}: a {compression}-compressed {kind} file, which wmrid reads uncompressed only; decompress "
                    f"it first ({decompress_command(compression)}) and give the log inside"
                )
        return "csv"
    if suffix in CSV_SUFFIXES:
        return "csv"
    if suffix in PARQUET_SUFFIXES:
        return "parquet"
    if suffix in _MCAP_SUFFIXES:
        return "mcap"
    if head_bytes.startswith(PARQUET_MAGIC):
        return "parquet"
    if head_bytes.startswith(MCAP_MAGIC):
        return "mcap"
    return "csv"


@dataclass
class Source:
    """Where the log's bytes are: a regular file (``path``) or bytes already read (``data``).

    compression : "gzip", "bzip2", "xz" or "zstd" when those bytes are a compressed stream (found from its magic
    bytes when not given); :meth:`head` and :meth:`open` then give the decompressed bytes.
    """

    name: str  # for messages
    path: str | None
    data: bytes | None
    compression: str | None = field(default=None)

    def __post_init__(self) -> None:
        if self.compression is None:
            self.compression = compression_of(self._raw_head(8))

    def _raw_head(self, size: int) -> bytes:
        if self.data is not None:
            return self.data[:size]
        with open(self.path, "rb") as fh:  # type: ignore[arg-type]
            return fh.read(size)

    def head(self, size: int = SNIFF_BYTES) -> bytes:
        """The first ``size`` bytes of the log (decompressed)."""
        if self.compression is None:
            return self._raw_head(size)
        with self.open() as fh:
            return self._read(fh, size)

    def open(self) -> BinaryIO:
        """A binary stream of the log's bytes (decompressed), to be closed by the caller."""
        raw: BinaryIO = open(self.path, "rb") if self.data is None else io.BytesIO(self.data)  # type: ignore[arg-type]  # noqa: SIM115
        if self.compression is None:
            return raw
        import bz2  # stdlib codecs: only a compressed log (bz2, lzma: optional in a Python build)
        import gzip  # stdlib codecs: only a compressed log
        import lzma  # stdlib codecs: only a compressed log (bz2, lzma: optional in a Python build)

        if self.compression == "gzip":
            reader: Any = gzip.GzipFile(fileobj=raw, mode="rb")
        elif self.compression == "bzip2":
            reader = bz2.BZ2File(raw, mode="rb")
        elif self.compression == "xz":
            reader = lzma.LZMAFile(raw, mode="rb")  # noqa: SIM115 - closed by _Closing
        else:
            reader = _ZstdReader(raw)
        return io.BufferedReader(_Closing(reader, raw), 1 << 16)  # type: ignore[return-value]

    def _read(self, fh: BinaryIO, size: int) -> bytes:
        """Up to ``size`` bytes from ``fh``; a damaged compressed stream is a LogFormatError."""
        try:
            out = bytearray()
            while len(out) < size:
                block = fh.read(size - len(out))
                if not block:
                    break
                out += block
            return bytes(out)
        except OSError as err:
            raise self.damaged(err) from err

    def damaged(self, err: BaseException) -> LogFormatError:
        """The error for a compressed stream that cannot be decompressed."""
        return LogFormatError(
            f"{self.name}: its {self.compression} stream is damaged or cut short ({one_line(err)}); check it with "
            f"{decompress_command(self.compression or '')} and give the log inside"
        )


class DamagedStream(OSError):
    """A compressed stream that cannot be decompressed (damaged, cut short): what :meth:`Source.open`'s stream
    raises instead of the decompressor's own error (EOFError, lzma.LZMAError, zstandard.ZstdError, ...), so that
    readers catch one kind; :meth:`Source.damaged` words it."""


class _Closing(io.RawIOBase):
    """A decompressing reader that also closes the raw stream under it; its errors are DamagedStream."""

    def __init__(self, reader: Any, raw: BinaryIO):
        self._reader, self._raw = reader, raw

    def readable(self) -> bool:
        return True

    def readinto(self, buffer: Any) -> int:
        data = self.read(len(buffer))
        buffer[: len(data)] = data
        return len(data)

    def read(self, size: int = -1) -> bytes:
        try:
            return self._reader.read(size) if size is not None and size >= 0 else self._reader.read()
        except DamagedStream:
            raise
        except Exception as err:  # EOFError, OSError, lzma.LZMAError, zstandard.ZstdError
            raise DamagedStream(one_line(err) or type(err).__name__) from err

    def close(self) -> None:
        if not self.closed:
            try:
                self._reader.close()
            finally:
                self._raw.close()
                super().close()


#: The message for a pipe, a device or standard input that holds more than the memory budget ({size}: the budget).
_ENDLESS = (
    "{name}: {what} holds more than {{size}}, the memory budget (WMRID_MEMORY_BUDGET); an endless source? save the "
    "log to a file, which wmrid reads piece by piece"
)


def open_source(path: str) -> Source:
    if path == "-":
        if sys.stdin is None or sys.stdin.isatty():
            raise UsageError("log '-' means standard input, but nothing is piped in; give a file or pipe one in")
        data = read_limited(sys.stdin.buffer, memory_budget(), _ENDLESS.format(name=STDIN_NAME, what="standard input"))
        if not data:
            raise LogFormatError(f"{STDIN_NAME}: standard input is empty; pipe a CSV or Parquet log into it")
        return Source(STDIN_NAME, None, data)
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
            close = suggest(os.path.basename(path), sorted(os.listdir(folder)), cutoff=0.8)
            hint = f" (did you mean {os.path.join(os.path.dirname(path), close)!r}?)" if close else ""
        raise LogFormatError(f"{path}: no such file{hint}; check the path")
    if os.path.isdir(path):
        raise LogFormatError(f"{path}: is a folder, not a log file; give the CSV or Parquet file inside it")
    try:
        if not os.path.isfile(path):  # a pipe such as <(command), or a device: read it once, within the budget
            data = read_limited(path, memory_budget(), _ENDLESS.format(name=path, what="it is not a regular file and"))
            source = Source(path, None, data)
            size = len(data)
        else:
            with open(path, "rb"):
                pass  # fail here, with a clear message, if it cannot be read
            source = Source(path, path, None)
            size = os.path.getsize(path)
    except OSError as err:
        raise LogFormatError(f"{path}: cannot be read ({err.strerror or err}); check its permissions") from err
    if size == 0:
        raise LogFormatError(f"{path}: the file is empty (0 bytes); give a log with a header and data rows")
    return source


class _ZstdReader:
    """A zstd stream's bytes, frame after frame, that raises at the end when the last frame is incomplete
    (zstandard's stream reader then just stops: a file cut short would read as a shorter log).  The compressed
    input is fed 1 KiB at a time, so one step's output stays bounded (a zstd block of 128 KiB takes a few bytes:
    at most ~40 MB out of 1 KiB in), and ``read(size)`` holds little more than ``size`` bytes."""

    _IN = 1024

    def __init__(self, raw: BinaryIO):
        import zstandard  # zstandard: only a .zst log

        self._zstd, self._raw = zstandard, raw
        self._dobj = zstandard.ZstdDecompressor().decompressobj()
        self._buf = bytearray()
        self._off = 0
        self._in = b""
        self._in_off = 0
        self._started = False
        self._done = False

    def read(self, size: int = -1) -> bytes:
        if size is None or size < 0:
            parts = []
            while block := self.read(1 << 20):
                parts.append(block)
            return b"".join(parts)
        while len(self._buf) - self._off < size and not self._done:
            self._step()
        end = min(self._off + size, len(self._buf))
        out = bytes(self._buf[self._off : end])
        self._off = end
        if self._off >= 1 << 16:
            del self._buf[: self._off]
            self._off = 0
        return out

    def _step(self) -> None:
        if self._in_off >= len(self._in):
            self._in, self._in_off = self._raw.read(1 << 16), 0
            if not self._in:
                self._done = True
                if self._started and not self._dobj.eof:
                    raise EOFError("the last zstd frame is incomplete")
                return
        piece = self._in[self._in_off : self._in_off + self._IN]
        self._in_off += len(piece)
        while piece:
            if self._dobj.eof:  # the next frame
                self._dobj = self._zstd.ZstdDecompressor().decompressobj()
            self._started = True
            self._buf += self._dobj.decompress(piece)
            piece = self._dobj.unused_data if self._dobj.eof else b""

    def close(self) -> None:
        pass


def one_line(err: BaseException | str) -> str:
    return " ".join(str(err).split())[:300]
