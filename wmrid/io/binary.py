"""Byte helpers both containers (MCAP, ROS 1 bags) use: a file mapped read-only with its pages given back as the reader
passes them (:func:`map_file`, :func:`page_releaser`), little-endian integers at offsets (:func:`u64s_at`), the note of
a file cut short (:func:`cut_short_note`)."""

from __future__ import annotations

import mmap
import os
from collections.abc import Callable

import numpy as np

from wmrid.core.errors import LogFormatError


def map_file(path: str, data: bytes | None) -> tuple[np.ndarray, Callable[[int], None] | None]:
    """(the bytes as uint8, a function that hands the mapped pages below an offset back to the kernel)."""
    if data is not None:
        return np.frombuffer(data, dtype=np.uint8), None
    try:
        with open(path, "rb") as fh:
            size = os.fstat(fh.fileno()).st_size
            if size == 0:
                raise LogFormatError(f"{path}: the file is empty (0 bytes)")
            # Not closed explicitly: numpy views of it may live on in a traceback; the map is released
            # when the last view goes (the file descriptor closes here, the map keeps its own).
            mapped = mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)
    except OSError as err:
        raise LogFormatError(f"{path}: cannot be read ({err.strerror or err})") from err
    return np.frombuffer(mapped, dtype=np.uint8), page_releaser(mapped)


def read_only(buf: np.ndarray) -> np.ndarray:
    """``buf`` as a read-only view (no copy).  The record kernels are compiled per array type, and numba types a
    read-only array apart from a writable one: a file's map and a decompressed chunk are read-only, bytes given as a
    bytearray are not; one type for all is one compilation instead of two."""
    if not buf.flags.writeable:
        return buf
    view = buf.view()
    view.flags.writeable = False
    return view


def page_releaser(mapped: mmap.mmap) -> Callable[[int], None] | None:
    """A function that hands the pages of a read-only file mapping below an offset back to the kernel, in runs of
    at least :data:`_RELEASE_BYTES` (None where the platform cannot).  Dropping them loses nothing (they come back
    from the page cache if touched again); without this a long file's pages all count in the resident memory."""
    if not hasattr(mapped, "madvise") or not hasattr(mmap, "MADV_DONTNEED"):
        return None
    done = [0]

    def release(offset: int) -> None:
        upto = offset // mmap.PAGESIZE * mmap.PAGESIZE
        if upto - done[0] >= _RELEASE_BYTES:
            mapped.madvise(mmap.MADV_DONTNEED, done[0], upto - done[0])
            done[0] = upto

    return release


#: Mapped pages are handed back in runs of at least this many bytes.
_RELEASE_BYTES = 1 << 22


def cut_short_note(reached: int, size: int) -> str:
    """Said of a file (MCAP or ROS 1) whose last record stops at byte ``size``, after ``reached``."""
    return (
        f"the file ends inside a record (byte {reached} of {size}): it was cut short, e.g. by a crash; read "
        f"everything up to there, {size - reached} bytes at the end are lost"
    )


def u64s_at(buf: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """The little-endian uint64 at each of ``offsets`` (n,) in ``buf`` (uint8), as int64 (n,)."""
    return np.ascontiguousarray(buf[offsets[:, None] + np.arange(8)]).view("<i8").ravel()
