"""The write-ahead log (``run.db3-wal``) of a ROS 2 sqlite3 recording that was not closed, read without touching it.

rosbag2's "resilient" storage preset records in SQLite's WAL mode, so that a crash loses little: committed messages
sit in the ``-wal`` file beside the ``.db3`` until a checkpoint copies them in, which a crash prevents.  A reader that
opens the database as immutable -- rosbags does, and wmrid does so as not to write beside its inputs (SQLite would
create the ``-shm`` index and, on close, checkpoint into the ``.db3``) -- sees only the pages checkpointed so far:
on a recording cut by a power loss that can be most of it, with no error.

Here the log is read as SQLite itself recovers it (https://www.sqlite.org/fileformat2.html#the_write_ahead_log):
a 32-byte header (magic 0x377f0682 or 0x377f0683, the byte order of the checksums' words; version 3007000; page
size; two salts; a checksum), then frames of a 24-byte header (page number, the database's size in pages after a
commit frame, else 0; the salts; a cumulative checksum) and one page.  Frames count while their salts match and
their checksums hold; those up to the last commit frame are the committed ones, and the newest committed copy of a
page is the page.  The database is then opened through an apsw VFS (:func:`_vfs_classes`) that serves the main file's
reads from those pages over the ``.db3`` (page 1's in-header size set to the committed size), still immutable:
the ``.db3`` and ``-wal`` files are only read, the ``-shm`` not even opened.
"""

from __future__ import annotations

import errno
import os
from dataclasses import dataclass
from typing import Any

import numpy as np

from wmrid.core.jit import kernel
from wmrid.runtime.side_files import NotRegularFile, open_regular

WAL_MAGIC = (0x377F0682, 0x377F0683)
WAL_VERSION = 3007000
_HEADER = 32
_FRAME_HEADER = 24
#: The apsw VFS name wmrid registers (once per process).
VFS_NAME = "wmrid-wal"


@dataclass(frozen=True)
class WalView:
    """The committed state of a database and its write-ahead log: ``path`` the database's real path; ``pages`` maps
    a page number (from 1) to the offset of its newest committed copy in the ``-wal`` file; ``size`` is the
    database's size in pages after the last commit; ``frames`` the committed frames and ``torn`` this generation's
    frames after them (a transaction the stop cut, or a torn write), which are not read."""

    path: str
    page_size: int
    pages: dict[int, int]
    size: int
    frames: int
    torn: int

    def note(self, shown: str | None = None) -> str:
        """What was read, for the log's notes (``shown``: the database's path as the user gave it)."""
        torn = (
            f"; {self.torn} page write(s) after its last commit (a transaction the stop cut) were left out"
            if self.torn
            else ""
        )
        return (
            f"{shown or self.path}: the recording was not closed: its write-ahead log "
            f"({os.path.basename(self.path)}-wal) was read as SQLite recovers it, {self.frames} committed page "
            f"write(s) over the database (those a checkpoint had already copied read the same){torn}"
        )


@kernel
def _u32(buf, p, big):
    if big:
        return (np.int64(buf[p]) << 24) | (np.int64(buf[p + 1]) << 16) | (np.int64(buf[p + 2]) << 8) | buf[p + 3]
    return (np.int64(buf[p + 3]) << 24) | (np.int64(buf[p + 2]) << 16) | (np.int64(buf[p + 1]) << 8) | buf[p]


@kernel
def _checksum(buf, start, n, big, s0, s1):
    """SQLite's WAL checksum over buf[start : start + n] (n a multiple of 8), from (s0, s1)."""
    mask = np.int64(0xFFFFFFFF)
    for q in range(start, start + n, 8):
        s0 = (s0 + _u32(buf, q, big) + s1) & mask
        s1 = (s1 + _u32(buf, q + 4, big) + s0) & mask
    return s0, s1


@kernel
def wal_frames(buf, page_size, big, salt1, salt2, s0, s1, pages, sizes):
    """Walk the frames of a WAL file (uint8 ``buf``): fills ``pages[i]`` (page number) and ``sizes[i]`` (database
    size after a commit frame, else 0).  Returns (valid, current): the frames that are valid (salts, page number and
    checksums, in order), and those of this generation (the header's salts), valid or not, before the first frame of
    an older one (left by a checkpoint that restarted the log: already in the database)."""
    frame = _FRAME_HEADER + page_size
    n = (buf.shape[0] - _HEADER) // frame
    valid = -1
    for i in range(n):
        p = _HEADER + i * frame
        if _u32(buf, p + 8, True) != salt1 or _u32(buf, p + 12, True) != salt2:
            return (i if valid < 0 else valid), i
        if valid >= 0:
            continue  # past a broken frame: only counting this generation's frames
        s0, s1 = _checksum(buf, p, 8, big, s0, s1)
        s0, s1 = _checksum(buf, p + _FRAME_HEADER, page_size, big, s0, s1)
        if _u32(buf, p, True) == 0 or s0 != _u32(buf, p + 16, True) or s1 != _u32(buf, p + 20, True):
            valid = i
            continue
        pages[i] = _u32(buf, p, True)
        sizes[i] = _u32(buf, p + 4, True)
    return (n if valid < 0 else valid), n


def wal_state(db_path: str) -> tuple[WalView | None, str | None]:
    """(:func:`wal_view` of ``db_path``, None) -- or (None, a note) when its write-ahead log exists but cannot be
    read, or is not a regular file (a FIFO would block its reader, a device never end: neither is opened).  Costs
    one stat when there is no log."""

    if not os.path.exists(db_path + "-wal"):
        return None, None
    try:
        return wal_view(db_path), None
    except NotRegularFile as err:
        return None, (
            f"{db_path}: the file beside it named as its write-ahead log ({os.path.basename(db_path)}-wal) is "
            f"{err.kind}, not a regular file: ignored, never opened; the database was read as it is (messages "
            "recorded after its last checkpoint, if any, are missing)"
        )
    except OSError as err:
        return None, (
            f"{db_path}: its write-ahead log could not be read ({err.strerror or err}): the messages recorded after "
            "its last checkpoint may be missing"
        )


#: Views read, by the database's real path: (the log's identity, the view); at most _CACHED of them.
_cache: dict[str, tuple[tuple[Any, ...], WalView | None]] = {}
_CACHED = 64


def wal_view(db_path: str) -> WalView | None:
    """The committed pages of ``db_path``'s write-ahead log, None when there is none with a committed frame (no
    ``-wal`` file, an empty one, another format).  Read once per process while the file is unchanged (its inode,
    size, times and header: a restarted log has new salts).  OSError when the log exists but cannot be read."""
    real = os.path.realpath(db_path)
    wal = real + "-wal"
    try:
        fh = open_regular(wal)  # a FIFO or a device is never opened for reading (NotRegularFile, an OSError)
    except FileNotFoundError:
        return None
    with fh:
        st = os.fstat(fh.fileno())
        head = fh.read(_HEADER)
        key = (st.st_ino, st.st_size, st.st_mtime_ns, st.st_ctime_ns, head)
        known = _cache.get(real)
        if known is None or known[0] != key:
            if len(_cache) >= _CACHED:
                _cache.pop(next(iter(_cache)))
            known = (key, _read_view(real, fh, head, st.st_size))
            _cache[real] = known
    return known[1]


def _read_view(db_path: str, wal: Any, head: bytes, size: int) -> WalView | None:
    if size < _HEADER + _FRAME_HEADER or len(head) < _HEADER:
        return None
    magic, version, page_size, _, salt1, salt2, c1, c2 = (
        int.from_bytes(head[i : i + 4], "big") for i in range(0, _HEADER, 4)
    )
    if magic not in WAL_MAGIC or version != WAL_VERSION or not 512 <= page_size <= 65536 or page_size & (page_size - 1):
        return None
    big = magic == WAL_MAGIC[1]
    s0, s1 = _checksum(np.frombuffer(head, dtype=np.uint8), 0, 24, big, 0, 0)
    if (s0, s1) != (c1, c2):
        return None
    count = (size - _HEADER) // (_FRAME_HEADER + page_size)
    if not count:
        return None
    pages = np.zeros(count, dtype=np.int64)
    sizes = np.zeros(count, dtype=np.int64)
    try:  # the pages stay in the file: only the headers are kept
        buf = np.memmap(wal, dtype=np.uint8, mode="r", shape=(size,))
    except ValueError as err:  # shorter than its size a moment ago
        raise OSError(errno.EIO, "it changed while being read") from err
    valid, current = wal_frames(buf, page_size, big, salt1, salt2, s0, s1, pages, sizes)
    del buf
    commits = np.flatnonzero(sizes[:valid])
    if not len(commits):
        return None
    last = int(commits[-1])
    offsets = _HEADER + np.arange(last + 1, dtype=np.int64) * (_FRAME_HEADER + page_size) + _FRAME_HEADER
    newest = dict(zip(pages[: last + 1].tolist(), offsets.tolist(), strict=True))  # later frames overwrite earlier
    return WalView(db_path, page_size, newest, int(sizes[last]), last + 1, int(current) - last - 1)


_VIEWS: dict[str, WalView] = {}
_registered: list[Any] = []


def connect(db_path: str, view: WalView) -> Any:
    """An immutable, read-only apsw connection to ``db_path`` as committed in its write-ahead log ``view``."""
    import urllib.request  # urllib.request (~25 ms, http and ssl): only a .db3 with a write-ahead log

    import apsw  # apsw: only a .db3 with a write-ahead log

    if not _registered:
        _registered.append(_make_vfs())
    _VIEWS[view.path] = view  # view.path is the real path (no symbolic link), as xFullPathname gives it
    uri = "file:" + urllib.request.pathname2url(view.path) + "?immutable=1"
    try:
        return apsw.Connection(uri, flags=apsw.SQLITE_OPEN_READONLY | apsw.SQLITE_OPEN_URI, vfs=VFS_NAME)
    finally:
        _VIEWS.pop(view.path, None)  # the main file is open (or failed): the view lives on in its WalFile


def _vfs_classes() -> tuple[type, type]:
    import apsw  # apsw: only a .db3 with a write-ahead log

    class WalVFS(apsw.VFS):
        """The default VFS, but a main database with a registered :class:`WalView` is opened as :class:`WalFile`."""

        def __init__(self) -> None:
            super().__init__(VFS_NAME, "")

        def xFullPathname(self, name: str) -> str:
            # the default VFS resolves a symbolic link with SQLITE_OK_SYMLINK, which apsw takes for an error
            return os.path.realpath(name)

        def xOpen(self, name: Any, flags: list[int]) -> Any:
            path = name.filename() if isinstance(name, apsw.URIFilename) else name
            view = _VIEWS.get(os.path.realpath(path)) if path else None
            if view is not None and flags[0] & apsw.SQLITE_OPEN_MAIN_DB:
                return WalFile(view, name, flags)
            return apsw.VFSFile("", name, flags)

    class WalFile(apsw.VFSFile):
        """The main database file seen through its write-ahead log: committed pages from the log, the rest from the
        file, page 1's in-header size set to the committed size, beyond the file's end zeros (never written)."""

        def __init__(self, view: WalView, name: Any, flags: list[int]):
            super().__init__("", name, flags)
            self.view = view
            self.wal = open_regular(view.path + "-wal")  # closed in xClose
            self.base = os.path.getsize(view.path)

        def _page(self, number: int) -> bytes:
            ps = self.view.page_size
            where = self.view.pages.get(number)
            if where is not None:
                self.wal.seek(where)
                data = self.wal.read(ps)
            elif (number - 1) * ps < self.base:
                data = super().xRead(ps, (number - 1) * ps)
            else:
                data = bytes(ps)
            if number == 1:
                data = data[:28] + self.view.size.to_bytes(4, "big") + data[32:]
            return data

        def xRead(self, amount: int, offset: int) -> bytes:
            ps = self.view.page_size
            out = bytearray()
            pos, end = offset, offset + amount
            while pos < end:
                number, within = pos // ps + 1, pos % ps
                take = min(ps - within, end - pos)
                out += self._page(number)[within : within + take]
                pos += take
            return bytes(out)

        def xFileSize(self) -> int:
            return self.view.size * self.view.page_size

        def xClose(self) -> None:
            self.wal.close()
            super().xClose()

    return WalVFS, WalFile


def _make_vfs() -> Any:
    """The VFS, registered with apsw (made on first use: apsw is imported only when a recording needs it)."""
    vfs_class, _ = _vfs_classes()
    return vfs_class()
