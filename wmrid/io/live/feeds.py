"""Bytes as they arrive: a regular file that grows (read from a remembered offset) and a pipe (standard input).

Neither blocks for longer than the timeout it is given, so the caller can refresh a display, notice that no data
came for ``--idle`` seconds, and take Ctrl-C between two reads.
"""

from __future__ import annotations

import io
import os
import select
import time
from typing import BinaryIO

#: Bytes read at most at once (a file that is already long is then followed piece by piece: ``--until`` stops
#: within one such read of the log time asked for).
READ_BYTES = 1 << 16


class FileFeed:
    """The bytes appended to the regular file ``path`` since the last read.

    The file is opened once; a file that is replaced (a new inode under the name) is not followed to its new self.
    """

    def __init__(self, path: str) -> None:
        self.path = path
        self.fd = os.open(path, os.O_RDONLY)
        self.offset = 0  # bytes handed out so far

    def read(self, limit: int = READ_BYTES) -> bytes:
        """Up to ``limit`` new bytes, b"" when the file has not grown (never blocks)."""
        data = os.pread(self.fd, limit, self.offset)
        self.offset += len(data)
        return data

    def size(self) -> int:
        """The file's current size in bytes."""
        return os.fstat(self.fd).st_size

    def close(self) -> None:
        if self.fd >= 0:
            os.close(self.fd)
            self.fd = -1


class PipeFeed:
    """The bytes that arrive on ``stream`` (standard input's binary stream, a pipe); ``ended`` once it is closed.

    A stream with a file descriptor is waited on with select; one without (bytes in memory, as an in-process test
    gives) is read as it is."""

    def __init__(self, stream: BinaryIO) -> None:
        self.stream = stream
        try:
            self.fd: int | None = stream.fileno()
        except (OSError, AttributeError, ValueError, io.UnsupportedOperation):
            self.fd = None
        self.ended = False

    def read(self, timeout: float, limit: int = READ_BYTES) -> bytes:
        """Up to ``limit`` bytes, waiting at most ``timeout`` s for the first; b"" when none came (or the end)."""
        if self.ended:
            return b""
        if self.fd is None:
            data = self.stream.read(limit)
            self.ended = not data
            return data or b""
        deadline = time.monotonic() + max(timeout, 0.0)
        while True:
            left = max(deadline - time.monotonic(), 0.0)
            ready, _, _ = select.select([self.fd], [], [], left)
            if ready:
                data = os.read(self.fd, limit)
                if not data:
                    self.ended = True
                return data
            if left <= 0.0:
                return b""

    def close(self) -> None:
        self.ended = True
