"""Which files make a recording (:func:`recording_paths`): a rosbag2 folder, a folder of bag files, one ROS 1 bag or
``.db3`` file by its magic bytes, several files of one recording.  No reader is loaded here, so that a command
reading a CSV or Parquet log never loads the bag readers."""

from __future__ import annotations

import os
from collections.abc import Sequence

from wmrid.core.errors import LogFormatError, cannot_read

ROS1_MAGIC = b"#ROSBAG V2.0"
SQLITE_MAGIC = b"SQLite format 3\x00"
MCAP_MAGIC = b"\x89MCAP"


#: The suffixes of a recording's files inside a folder without metadata.yaml (``.bag.active``: the file ROS 1's
#: ``rosbag record`` was writing when it stopped, left so by a crash).
BAG_SUFFIXES = (".bag", ".bag.active", ".db3", ".mcap")


def _magic(path: str) -> bytes:
    try:
        with open(path, "rb") as fh:
            return fh.read(16)
    except OSError:
        return b""


#: The magic bytes of the ROS 1 and sqlite files a folder without metadata.yaml may hold, by suffix (an MCAP file that
#: a crash left empty or cut in its header is the MCAP reader's to note and skip).
_SUFFIX_MAGIC = {".bag": ROS1_MAGIC, ".bag.active": ROS1_MAGIC, ".db3": SQLITE_MAGIC}


def _readable_head(path: str) -> bytes:
    """The first 16 bytes of the file ``path`` of a recording, or LogFormatError when it cannot be read (naming the
    file, the reason and the fix)."""
    try:
        with open(path, "rb") as fh:
            return fh.read(16)
    except OSError as err:
        raise LogFormatError(f"{path}: {cannot_read(err)}") from None


def _check_folder_files(files: list[str]) -> None:
    """Each of a folder's recording files (found by suffix) readable, and each ROS 1 or sqlite one not empty and of
    the kind its suffix says: a wrong one is one line naming it (rosbags stopped on it with a message of its own)."""
    for path in files:
        head = _readable_head(path)
        suffix = next((s for s in sorted(_SUFFIX_MAGIC, key=len, reverse=True) if path.lower().endswith(s)), None)
        if suffix is None:
            continue
        if not head:
            raise LogFormatError(f"{path}: the file is empty (0 bytes); remove it, or give the recording's other files")
        if not head.startswith(_SUFFIX_MAGIC[suffix]):
            kind = "a ROS 1 bag" if _SUFFIX_MAGIC[suffix] == ROS1_MAGIC else "an SQLite database"
            raise LogFormatError(
                f"{path}: a {suffix} file that is not {kind} (its first bytes say otherwise); remove it from the "
                "folder, or give the recording's files"
            )


def is_bag_file(path: str) -> bool:
    """Whether ``path`` is a ROS 1 bag or an SQLite database (a ROS 2 .db3 bag), by its magic bytes."""
    head = _magic(path)
    return head.startswith(ROS1_MAGIC) or head.startswith(SQLITE_MAGIC)


def recording_paths(paths: Sequence[str]) -> list[str] | None:
    """The files (or the rosbag2 folder) rosbags reads for the log ``paths`` names, or None when it is not a bag
    recording (one CSV, Parquet or MCAP file, or standard input, which the other readers take).

    A rosbag2 folder (with its ``metadata.yaml``); a folder without one: its ``.bag``, ``.db3`` and ``.mcap`` files
    in name order; one ROS 1 bag or ``.db3`` file (by magic bytes,
    whatever the suffix); several files: all of them, as one recording in time order.
    """
    paths = [os.fspath(p) for p in paths]
    if len(paths) == 1:
        path = paths[0]
        if path == "-" or not os.path.exists(path):
            return None
        if os.path.isdir(path):
            if os.path.lexists(os.path.join(path, "metadata.yaml")):  # a broken link too: the reader refuses it
                return [path]
            inside = sorted(
                os.path.join(path, f) for f in os.listdir(path)
                if f.lower().endswith(BAG_SUFFIXES) and os.path.isfile(os.path.join(path, f))
            )  # fmt: skip
            if not inside:
                raise LogFormatError(
                    f"{path}: a folder with no recording in it (no metadata.yaml, .bag, .db3 or .mcap file); give the "
                    "rosbag2 folder, the bag files, or a CSV, Parquet or MCAP log"
                )
            _check_folder_files(inside)
            return inside
        return [path] if is_bag_file(path) else None
    seen: dict[tuple[int, int], str] = {}
    for path in paths:
        if path == "-":
            raise LogFormatError("standard input cannot be one of several files of a recording; give the files")
        if not os.path.exists(path):
            raise LogFormatError(f"{path}: no such file; check the path")
        st = os.stat(path)
        if (st.st_dev, st.st_ino) in seen:  # the same file by any name: its messages would count twice
            raise LogFormatError(
                f"{path}: the same file as {seen[(st.st_dev, st.st_ino)]}; give each file of the recording once"
            )
        seen[(st.st_dev, st.st_ino)] = path
        head = b"" if os.path.isdir(path) else _readable_head(path)
        if not (os.path.isdir(path) or head.startswith((ROS1_MAGIC, SQLITE_MAGIC, MCAP_MAGIC))):
            raise LogFormatError(
                f"{path}: several files are read as one recording only when they are bags (ROS 1 .bag, ROS 2 .db3 or "
                "MCAP files, or rosbag2 folders); give one CSV or Parquet log at a time"
            )
    return paths
