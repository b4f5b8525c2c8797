"""What a report records of its inputs: each file's size and SHA-256, so that a colleague can check that the
report was made from the log they have.  A folder (a rosbag2 recording) is every file in it, in name order."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path
from typing import Any


def file_digests(paths: str | os.PathLike[str] | list[Any], data: bytes | None = None) -> list[dict[str, Any]]:
    """[{"path", "bytes", "sha256"}] of ``paths`` (a file, a folder, several; "-" standard input, whose bytes
    ``data`` are then hashed, or an empty list when they were not kept)."""
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
            with open(f, "rb") as fh:
                digest = hashlib.file_digest(fh, "sha256")  # reads in blocks: memory stays bounded
            out.append({"path": str(f), "bytes": f.stat().st_size, "sha256": digest.hexdigest()})
    return out
