"""What a report records of its inputs: each file's size and SHA-256, so that a colleague can check that the
report was made from the log they have.  A folder (a rosbag2 recording) is every file in it, in name order."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path
from typing import Any

from wmrid.runtime.side_files import open_regular

#: bytes read at a time when hashing.
_BLOCK = 1 << 20


def regular_digest(path: str | os.PathLike[str]) -> tuple[str, int]:
    """(SHA-256 hex, bytes) of the regular file ``path``: its bytes up to the size it had when opened (a file that
    grows meanwhile is not chased), in blocks.  A device, a FIFO or a folder is refused unread
    (:class:`wmrid.runtime.side_files.NotRegularFile`, an OSError: ``/dev/zero`` would never end, a FIFO never start);
    other OSErrors pass through."""
    h = hashlib.sha256()
    with open_regular(path) as fh:
        left = size = os.fstat(fh.fileno()).st_size
        while left > 0:
            block = fh.read(min(_BLOCK, left))
            if not block:  # shorter than its size a moment ago: what was there
                break
            h.update(block)
            left -= len(block)
    return h.hexdigest(), size - left


def file_digests(
    paths: str | os.PathLike[str] | list[Any], data: bytes | None = None, *, regular_only: bool = False
) -> list[dict[str, Any]]:
    """[{"path", "bytes", "sha256"}] of ``paths`` (a file, a folder, several; "-" standard input, whose bytes
    ``data`` are then hashed, or an empty list when they were not kept).  ``regular_only``: every file is hashed by
    :func:`regular_digest` (for files the user did not name: a fleet manifest's logs), so that a device or a FIFO
    is refused unread."""
    items = [paths] if isinstance(paths, (str, os.PathLike)) else list(paths)
    out = []
    for item in items:
        name = os.fspath(item)
        if name == "-":
            if data is not None:
                out.append({"path": "-", "bytes": len(data), "sha256": hashlib.sha256(data).hexdigest()})
            continue
        path = Path(name)
        files = sorted(p for p in path.rglob("*") if p.is_file()) if path.is_dir() else [path]
        for f in files:
            if regular_only:
                sha, size = regular_digest(f)
                out.append({"path": str(f), "bytes": size, "sha256": sha})
                continue
            with open(f, "rb") as fh:
                digest = hashlib.file_digest(fh, "sha256")  # reads in blocks: memory stays bounded
            out.append({"path": str(f), "bytes": f.stat().st_size, "sha256": digest.hexdigest()})
    return out
