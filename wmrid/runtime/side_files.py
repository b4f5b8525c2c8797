"""Files the user did not name, read with care (issue 30): a rosbag2 folder's ``metadata.yaml``, a ``.db3``'s
``-wal``, the logs a fleet manifest lists, the files a glob finds.

Such a file is opened only when it is a regular file: a FIFO blocks its reader until a writer comes (forever when
none does), a device such as ``/dev/zero`` or ``/dev/urandom`` never ends, and a symbolic link may name either.
:func:`open_regular` looks before it opens (``stat``), opens without waiting (``O_NONBLOCK``: opening a FIFO returns
at once) and looks again at what it opened (``fstat``), so that a file swapped in between is refused too.
:func:`read_regular` then reads it up to a limit.
"""

from __future__ import annotations

import errno
import os
import stat
from typing import BinaryIO

from wmrid.runtime.limits import describe, read_limited


class NotRegularFile(OSError):
    """A path that names something other than a regular file (or a folder where a file is wanted); ``kind`` says
    what ("a FIFO", "a character device", ...)."""

    def __init__(self, path: str, kind: str):
        super().__init__(errno.EINVAL, f"it is {kind}, not a regular file", path)
        self.kind = kind


def file_kind(mode: int) -> str:
    """What a stat mode names, for a message: "a regular file", "a folder", "a FIFO", "a character device", ..."""
    for test, kind in (
        (stat.S_ISREG, "a regular file"), (stat.S_ISDIR, "a folder"), (stat.S_ISFIFO, "a FIFO (named pipe)"),
        (stat.S_ISCHR, "a character device"), (stat.S_ISBLK, "a block device"), (stat.S_ISSOCK, "a socket"),
    ):  # fmt: skip
        if test(mode):
            return kind
    return "not a regular file"


def not_regular(path: str | os.PathLike) -> str | None:
    """What ``path`` names when it exists and is not a regular file ("a FIFO (named pipe)", ...), else None (a
    regular file, or nothing: a missing path is the caller's to report).  Follows symbolic links; opens nothing."""
    try:
        st = os.stat(path)
    except (OSError, ValueError):
        return None
    return None if stat.S_ISREG(st.st_mode) else file_kind(st.st_mode)


#: What :func:`broken_link` says of a loop of symbolic links.
LOOP = "a loop of symbolic links"


def broken_link(path: str | os.PathLike) -> str | None:
    """What ``path`` is when it is a symbolic link that leads to no file: "a loop of symbolic links", or "a symbolic
    link to TARGET, which does not exist"; None otherwise (no link, a link that leads somewhere, or nothing there).
    Opens nothing; a loop is found by the system's own limit on links followed (ELOOP), never walked here."""
    name = os.fspath(path)
    try:
        os.stat(name)
        return None
    except OSError as err:
        if err.errno == errno.ELOOP:
            return LOOP
        if not os.path.islink(name):
            return None
        try:
            target = os.readlink(name)
        except OSError:
            target = "?"
        return f"a symbolic link to {target}, which does not exist"
    except ValueError:  # a NUL in the name
        return None


def open_regular(path: str | os.PathLike) -> BinaryIO:
    """``path`` opened for reading in binary, only if it is a regular file: :class:`NotRegularFile` otherwise (before
    anything is read, and without waiting on a FIFO).  Other OSErrors (missing, no permission) pass through."""
    name = os.fspath(path)
    kind = not_regular(name)
    if kind is not None:
        raise NotRegularFile(str(name), kind)
    fd = os.open(name, os.O_RDONLY | os.O_NONBLOCK | os.O_NOCTTY | getattr(os, "O_CLOEXEC", 0))
    try:
        mode = os.fstat(fd).st_mode
        if not stat.S_ISREG(mode):  # swapped between the look and the open
            raise NotRegularFile(str(name), file_kind(mode))
        os.set_blocking(fd, True)
        return os.fdopen(fd, "rb")
    except BaseException:
        os.close(fd)
        raise


def read_regular(path: str | os.PathLike, limit: int, message: str, error: type[Exception]) -> bytes:
    """The bytes of the regular file ``path`` (:func:`open_regular`), refused with ``error`` (``message`` formatted
    with ``size``, the limit described) when its size is over ``limit`` -- by its size before a byte is read, and
    again while reading (a file that grows).  NotRegularFile and other OSErrors pass through."""
    with open_regular(path) as fh:
        if os.fstat(fh.fileno()).st_size > limit:
            raise error(message.format(size=describe(limit)))
        return read_limited(fh, limit, message, error)
