"""Outputs are written atomically: a reader sees the old file or the complete new one, never half of it.

Every file wmrid writes goes through :func:`atomic_output`: the data go to a hidden temporary file in the
target's own folder (``.<name>.<random suffix>.tmp``), are flushed and fsynced, and only then take the target's
name with :func:`os.replace` (one rename on the same file system).  Any exception before that point —
including ``KeyboardInterrupt`` — removes the temporary file and leaves the target as it was.

Without ``force`` an existing target is never overwritten; the final step then uses :func:`os.link`,
which refuses to clobber a file that appeared while we were writing.
"""

from __future__ import annotations

import json
import math
import os
import signal
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import IO, Any

from wmrid.errors import OutputExistsError, UsageError

__all__ = ["atomic_output", "atomic_write_bytes", "atomic_write_text", "output_group", "to_json_text", "write_json"]


def _exists_error(path: Path) -> OutputExistsError:
    return OutputExistsError(f"{path} exists; use --force to overwrite it")


def _check_target(path: Path, force: bool) -> Path:
    """The folder the output goes to, after checking that the output may be written there."""
    folder = path.parent
    if str(path) in ("", ".", "-") or path.name in ("", ".", ".."):
        raise UsageError(f"cannot write to {str(path)!r}: give a file name")
    if not folder.is_dir():
        raise UsageError(f"cannot write {path}: folder {folder} does not exist; create it first")
    if path.is_dir():
        raise UsageError(f"cannot write {path}: it is a folder; give a file name")
    if not force and os.path.lexists(path):
        raise _exists_error(path)
    return folder


def _new_file_mode(path: Path) -> int:
    """Permissions for the output: those of the file it replaces, else 0o666 less the umask."""
    try:
        return os.stat(path).st_mode & 0o7777
    except OSError:
        umask = os.umask(0o022)  # there is no os.getumask before Python 3.13; read it and put it back
        os.umask(umask)
        return 0o666 & ~umask


def _fsync_folder(folder: Path) -> None:
    """Make the rename itself durable (best effort: not every platform can open a folder)."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    except OSError:
        pass
    finally:
        os.close(fd)


@contextmanager
def atomic_output(path: str | Path, *, force: bool = False, mode: str = "wb") -> Iterator[IO]:
    """Open ``path`` for writing so that it appears complete or not at all.

    path : the output file; its folder must exist.  force : replace an existing file.
    mode : ``"wb"`` (bytes) or ``"w"`` (UTF-8 text).

    Raises :class:`OutputExistsError` if ``path`` exists and ``force`` is false, and
    :class:`UsageError` if its folder does not exist or it is a folder; nothing is created then.
    """
    if mode not in ("wb", "w"):
        raise ValueError(f"atomic_output mode must be 'wb' or 'w', not {mode!r}")
    path = Path(path)
    folder = _check_target(path, force)
    file_mode = _new_file_mode(path)
    kwargs: dict[str, Any] = {"encoding": "utf-8"} if mode == "w" else {}
    try:
        handle = tempfile.NamedTemporaryFile(  # noqa: SIM115 - closed below on every path
            mode=mode, dir=folder, delete=False, prefix=f".{path.name}.", suffix=".tmp", **kwargs
        )
    except OSError as err:
        raise UsageError(f"cannot write {path}: {err.strerror or err}") from err
    tmp = Path(handle.name)
    try:
        try:
            yield handle
            handle.flush()
            os.fsync(handle.fileno())
        finally:
            handle.close()
        os.chmod(tmp, file_mode)
        if _GROUP is not None:  # inside output_group(): renamed with the other outputs at its end
            _GROUP.append((tmp, path, force))
            return
        _commit(tmp, path, force)
    except BaseException:
        with suppress(OSError):
            os.unlink(tmp)
        raise
    _fsync_folder(folder)


def _commit(tmp: Path, path: Path, force: bool) -> None:
    if force:
        os.replace(tmp, path)
    else:
        _link_no_clobber(tmp, path)


_GROUP: list[tuple[Path, Path, bool]] | None = None


@contextmanager
def output_group() -> Iterator[None]:
    """Outputs written inside appear together or not at all (e.g. a log and its truth file).

    Each is written to its temporary file as usual; the renames into place all happen at the end, with
    SIGINT held back (so Ctrl-C cannot fall between them); any exception before that (Ctrl-C included)
    removes every temporary file and leaves the targets as they were.
    """
    global _GROUP
    if _GROUP is not None:
        yield
        return
    _GROUP = pending = []
    try:
        yield
    except BaseException:
        for tmp, _, _ in pending:
            with suppress(OSError):
                os.unlink(tmp)
        raise
    finally:
        _GROUP = None
    blocked = hasattr(signal, "pthread_sigmask")
    if blocked:
        signal.pthread_sigmask(signal.SIG_BLOCK, {signal.SIGINT})
    try:
        for i, (tmp, path, force) in enumerate(pending):
            try:
                _commit(tmp, path, force)
            except BaseException:
                for later, _, _ in pending[i:]:
                    with suppress(OSError):
                        os.unlink(later)
                raise
        for folder in {path.parent for _, path, _ in pending}:
            _fsync_folder(folder)
    finally:
        if blocked:
            signal.pthread_sigmask(signal.SIG_UNBLOCK, {signal.SIGINT})


def _link_no_clobber(tmp: Path, path: Path) -> None:
    """Give ``tmp`` the name ``path`` unless a file of that name appeared meanwhile."""
    try:
        os.link(tmp, path)
    except FileExistsError as err:
        raise _exists_error(path) from err
    except OSError:  # a file system without hard links: check, then rename (a small race remains)
        if os.path.lexists(path):
            raise _exists_error(path) from None
        os.replace(tmp, path)
        return
    os.unlink(tmp)


def atomic_write_bytes(path: str | Path, data: bytes, *, force: bool = False) -> None:
    """Write ``data`` to ``path`` atomically (see :func:`atomic_output`)."""
    with atomic_output(path, force=force, mode="wb") as fh:
        fh.write(data)


def atomic_write_text(path: str | Path, text: str, *, force: bool = False) -> None:
    """Write ``text`` as UTF-8 to ``path`` atomically (see :func:`atomic_output`)."""
    atomic_write_bytes(path, text.encode("utf-8"), force=force)


def _jsonable(obj: Any) -> Any:
    """Plain JSON values: numpy scalars and arrays become numbers and lists, NaN/inf become null."""
    if isinstance(obj, bool) or obj is None or isinstance(obj, (int, str)):
        return obj
    if isinstance(obj, float):
        return obj if math.isfinite(obj) else None
    if isinstance(obj, dict):
        return {str(k): _jsonable(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [_jsonable(v) for v in obj]
    if isinstance(obj, Path):
        return str(obj)
    if hasattr(obj, "tolist") and callable(obj.tolist):  # numpy arrays and scalars
        return _jsonable(obj.tolist())
    if hasattr(obj, "to_dict") and callable(obj.to_dict):
        return _jsonable(obj.to_dict())
    raise TypeError(f"cannot write a {type(obj).__name__} as JSON")


def to_json_text(obj: Any) -> str:
    """Strict JSON text (indent 2, NaN/inf as null) ending in a newline."""
    return json.dumps(_jsonable(obj), indent=2, allow_nan=False) + "\n"


def write_json(path_or_dash: str | Path, obj: Any, *, force: bool = False) -> None:
    """Write ``obj`` as strict JSON to a file (atomically) or, for ``"-"``, to standard output."""
    text = to_json_text(obj)
    if str(path_or_dash) == "-":
        sys.stdout.write(text)
        sys.stdout.flush()
        return
    atomic_write_text(path_or_dash, text, force=force)
