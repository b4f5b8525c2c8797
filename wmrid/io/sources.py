"""Where a log comes from and what format it is: a file, a FIFO or standard input, recognised by suffix or magic bytes.

Format: by suffix (``.csv .txt .tsv`` -> CSV, ``.parquet .pq`` -> Parquet, ``.mcap`` -> MCAP); any other suffix,
and standard input (``-``), by the first bytes (:func:`detect_format`), which also names the formats wmrid does not
read (ROS 1 bags, SQLite, compressed files) instead of failing on them as text.
"""

from __future__ import annotations

import errno
import io
import os
import sys
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from wmrid.core.errors import LogFormatError, UsageError
from wmrid.core.limits import memory_budget, read_limited

if TYPE_CHECKING:
    pass
from wmrid.io.columns import suggest

CSV_SUFFIXES = (".csv", ".txt", ".tsv")


PARQUET_SUFFIXES = (".parquet", ".pq")


_MCAP_SUFFIXES = (".mcap",)


PARQUET_MAGIC = b"PAR1"


MCAP_MAGIC = b"\x89MCAP"


SNIFF_BYTES = 65536


STDIN_NAME = "<stdin>"


#: (magic bytes, what the file is, the fix) of formats wmrid recognises but does not read.
_OTHER_FORMATS = (
    (b"\x1f\x8b", "a gzip-compressed file", "decompress it first (gunzip -k FILE) and give the log inside"),
    (b"\x28\xb5\x2f\xfd", "a zstd-compressed file", "decompress it first (zstd -d FILE) and give the log inside"),
    (b"BZh", "a bzip2-compressed file", "decompress it first (bunzip2 -k FILE) and give the log inside"),
    (b"\xfd7zXZ\x00", "an xz-compressed file", "decompress it first (unxz -k FILE) and give the log inside"),
    (b"PK\x03\x04", "a zip archive", "unpack it first and give the log inside"),
    (b"#ROSBAG", "a ROS 1 bag", "convert it to MCAP first (mcap convert FILE out.mcap)"),
    (b"SQLite f", "an SQLite database (a ROS 2 .db3 bag?)", "convert it to MCAP first (ros2 bag convert)"),
)


def detect_format(path: str, head_bytes: bytes) -> str:
    """``"csv"``, ``"parquet"`` or ``"mcap"``: from the suffix of ``path``, else from the magic bytes.

    ``path`` ``"-"`` (standard input) or an unknown suffix: ``PAR1`` -> parquet, ``\\x89MCAP`` -> mcap,
    anything else -> csv.  A compressed file, an archive, a ROS 1 bag or an SQLite database (whatever its suffix)
    is refused with LogFormatError naming what it is and how to get a log out of it.
    """
    suffix = os.path.splitext(path)[1].lower() if path != "-" else ""
    for magic, what, fix in _OTHER_FORMATS:
        if head_bytes.startswith(magic):
            name = STDIN_NAME if path == "-" else path
            raise LogFormatError(f"{name}: {what}, not a CSV, Parquet or MCAP log; {fix}")
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
    """Where the log's bytes are: a regular file (``path``) or bytes already read (``data``)."""

    name: str  # for messages
    path: str | None
    data: bytes | None

    def head(self, size: int = SNIFF_BYTES) -> bytes:
        if self.data is not None:
            return self.data[:size]
        with open(self.path, "rb") as fh:  # type: ignore[arg-type]
            return fh.read(size)

    def opener(self) -> Any:
        """What pandas/pyarrow read from: the path, or a fresh in-memory stream."""
        return self.path if self.data is None else io.BytesIO(self.data)


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


def one_line(err: BaseException | str) -> str:
    return " ".join(str(err).split())[:300]
