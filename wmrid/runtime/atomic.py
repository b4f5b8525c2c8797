"""Outputs are written atomically: a reader sees the old file or the complete new one, never half of it.

Every file wmrid writes goes through :func:`atomic_output`: the data go to a hidden temporary file in the
target's own folder (``.<name>.<random suffix>.tmp``), are flushed and fsynced, and only then take the target's
name with :func:`os.replace` (one rename on the same file system).  Any exception before that point —
including ``KeyboardInterrupt`` — removes the temporary file and leaves the target as it was.

Without ``force`` an existing target is never overwritten; the final step then uses :func:`os.link`,
which refuses to clobber a file that appeared while we were writing.

What is never replaced (issue 13):

* a target that is not a regular file: a character device (``/dev/null``), a FIFO, ``-``, ``/dev/stdout`` or
  ``/dev/fd/N`` is written in place, as a stream (not atomic: a stream cannot be); a block device, a socket or
  anything else is refused;
* a symbolic link: the file it points to is written (atomically, in that file's folder), the link stays;
* an input: a target that is the same file as one registered with :func:`register_input` is refused.

Every error while writing becomes :class:`wmrid.core.errors.OutputWriteError` (exit 1) naming the target, with the
temporary file removed.  Temporary names keep within NAME_MAX (255 bytes) whatever the target's name.
"""

from __future__ import annotations

import errno
import json
import math
import os
import signal
import stat
import sys
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager, suppress
from pathlib import Path
from typing import IO, Any

from wmrid.core.errors import OutputExistsError, OutputWriteError, ReaderGone, UsageError, option
from wmrid.runtime import interrupts

__all__ = [
    "atomic_output", "atomic_write_bytes", "atomic_write_text", "check_output", "clear_inputs", "output_group",
    "register_input", "to_json_text", "track_inputs", "write_json",
]  # fmt: skip

#: (st_dev, st_ino) of the files this run reads: an output that is one of them is refused.  None: not tracked
#: (a library caller may well rewrite a file it read); the CLI tracks them for the length of a command.
_INPUTS: dict[tuple[int, int], str] | None = None
#: Bytes of the target's name kept in a temporary name: "." + 200 + "." + 8 random + ".tmp" < 255 (NAME_MAX).
_TMP_NAME_BYTES = 200


def _short(name: str) -> str:
    """``name`` cut to _TMP_NAME_BYTES bytes of its file-system encoding (never mid-character)."""
    return os.fsencode(name)[:_TMP_NAME_BYTES].decode(sys.getfilesystemencoding(), errors="ignore")


#: Paths written in place as the process's own streams.
_STREAM_PATHS = {"-": 1, "/dev/stdout": 1, "/dev/stderr": 2, "/proc/self/fd/1": 1, "/proc/self/fd/2": 2}
#: Signals held back while a group's renames run (Ctrl-C, kill, a closed terminal).
_HELD = tuple(getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, n))


#: Temporary files being written: what the signal watchdog removes if it has to end the process itself.
_LIVE: set[str] = set()


def _remove_live() -> None:
    for name in list(_LIVE):
        with suppress(OSError):
            os.unlink(name)
    _LIVE.clear()


interrupts.forced_exit_cleanups.append(_remove_live)


def register_input(path: str | Path) -> None:
    """Note ``path`` as an input of this run: an output that is the same file is refused (:func:`atomic_output`).
    A path that does not exist (yet) or is not a file is ignored, and so is every path unless inputs are tracked
    (:func:`track_inputs`)."""
    if _INPUTS is None:
        return
    try:
        st = os.stat(path)
    except (OSError, ValueError):
        return
    if stat.S_ISREG(st.st_mode):
        _INPUTS[(st.st_dev, st.st_ino)] = str(path)


def track_inputs() -> None:
    """Start noting inputs (:func:`register_input`) and outputs written (:func:`written`); the CLI calls this when a
    command starts."""
    global _INPUTS
    _INPUTS = {}
    _WRITTEN.clear()


def clear_inputs() -> None:
    """Stop noting inputs and forget them (the CLI calls this when a command ends)."""
    global _INPUTS
    _INPUTS = None


def stream_fd(path: str | Path) -> int | None:
    """The file descriptor a path names as one of this process's streams (``-``, /dev/stdout, /dev/fd/N), else None."""
    text = str(path)
    if text in _STREAM_PATHS:
        return _STREAM_PATHS[text]
    for prefix in ("/dev/fd/", "/proc/self/fd/"):
        if text.startswith(prefix) and text[len(prefix) :].isdigit():
            return int(text[len(prefix) :])
    return None


def _special(path: Path) -> str | None:
    """How a target that is not a regular file is written: "stream" (a character device or FIFO, in place), or
    None for a regular file or a new path.  Refuses a block device, a socket or any other kind of file."""
    try:
        st = os.stat(path)  # follows links: what the path names is what would be written
    except (OSError, ValueError):
        return None
    mode = st.st_mode
    if stat.S_ISREG(mode) or stat.S_ISDIR(mode):
        return None
    if stat.S_ISCHR(mode) or stat.S_ISFIFO(mode):
        return "stream"
    kind = "a block device" if stat.S_ISBLK(mode) else "a socket" if stat.S_ISSOCK(mode) else "not a regular file"
    raise UsageError(f"cannot write {path}: it is {kind}, which wmrid never writes; give a file name")


def _refuse_input(path: Path) -> None:
    try:
        st = os.stat(path)
    except (OSError, ValueError):
        return
    source = (_INPUTS or {}).get((st.st_dev, st.st_ino))
    if source is not None:
        raise UsageError(f"cannot write {path}: it is the input {source}; give another output file")


def _write_error(path: Path | str, err: OSError) -> OutputWriteError:
    """The error to raise for ``err`` while writing ``path`` (callers let a BrokenPipeError through: a reader that
    has seen enough, e.g. ``| head``)."""
    where = "standard output" if str(path) in ("-", "/dev/stdout") else str(path)
    return OutputWriteError(f"cannot write {where}: {err.strerror or err}; nothing was written there in full")


def _unwritable(folder: Path, err: OSError) -> str:
    """Why nothing can be created in ``folder`` (the output's), with the fix."""
    where = str(folder) if str(folder) not in ("", ".") else "the current folder"
    if err.errno == errno.EROFS:
        return f"{where} is on a read-only file system; write the output to another folder"
    if err.errno in (errno.EACCES, errno.EPERM):
        return (f"{where} is not writable ({err.strerror}); write the output to another folder, or change the "
                "folder's permissions")  # fmt: skip
    return f"{err.strerror or err} (creating a file in {where})"


def _exists_error(path: Path) -> OutputExistsError:
    return OutputExistsError(f"{path} exists; use {option('force', True)} to overwrite it")


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


def _target(path: Path, force: bool) -> tuple[Path, Path] | None:
    """(the file :func:`atomic_output` replaces, its folder) after every check made before writing, or None for a
    stream (written in place)."""
    if stream_fd(path) is not None or _special(path) == "stream":
        return None
    if path.is_symlink():
        path = Path(os.path.realpath(path))
    _refuse_input(path)
    return path, _check_target(path, force)


def check_output(path: str | Path, *, force: bool = False) -> None:
    """Refuse now what :func:`atomic_output` would refuse when it comes to write ``path``, with the same error: an
    existing file without ``force``, a missing folder, a folder, a block device or socket, an input of this run
    (registered so far).  A command calls it before its work, so that a refusal costs nothing; a stream passes."""
    _target(Path(path), force)


@contextmanager
def atomic_output(path: str | Path, *, force: bool = False, mode: str = "wb") -> Iterator[IO]:
    """Open ``path`` for writing so that it appears complete or not at all.

    path : the output file; its folder must exist.  force : replace an existing file.
    mode : ``"wb"`` (bytes) or ``"w"`` (UTF-8 text).  A stream target (``-``, /dev/stdout, a character device,
    a FIFO) is written in place, without ``force``; a link is followed (the file it names is replaced).

    Raises :class:`OutputExistsError` if ``path`` exists and ``force`` is false, :class:`UsageError` if its
    folder does not exist, it is a folder, a block device or socket, or an input of this run (nothing is created
    then), and :class:`OutputWriteError` when writing fails (the temporary file is removed).
    """
    if mode not in ("wb", "w"):
        raise ValueError(f"atomic_output mode must be 'wb' or 'w', not {mode!r}")
    path = Path(path)
    target = _target(path, force)
    if target is None:
        with _in_place(path, stream_fd(path), mode) as handle:
            yield handle
        return
    path, folder = target
    file_mode = _new_file_mode(path)
    kwargs: dict[str, Any] = {"encoding": "utf-8"} if mode == "w" else {}
    handle: IO | None = None
    try:  # one try from the creation to the end: a stop anywhere in between removes the temporary file
        # A stop between the file's creation and its registration would leave it behind (seen once in CI: SIGHUP
        # the moment the file appeared): the signal waits until the file is known, then is raised in this try.
        with interrupts.held():
            try:
                handle = tempfile.NamedTemporaryFile(  # noqa: SIM115 - closed below on every path
                    mode=mode, dir=folder, delete=False, prefix=f".{_short(path.name)}.", suffix=".tmp", **kwargs
                )
            except OSError as err:
                raise UsageError(f"cannot write {path}: {_unwritable(folder, err)}") from err
            _LIVE.add(handle.name)
        tmp = Path(handle.name)
        try:
            try:
                yield handle
                handle.flush()
                os.fsync(handle.fileno())
            finally:
                handle.close()
        except BrokenPipeError:
            raise
        except OSError as err:
            raise _write_error(path, err) from err
        os.chmod(tmp, file_mode)
        if _GROUP is not None:  # inside output_group(): renamed with the other outputs at its end
            _GROUP.append((tmp, path, force))
            return
        _commit(tmp, path, force)
        _LIVE.discard(str(tmp))
    except BaseException:
        if handle is not None:
            handle.close()
            with suppress(OSError):
                os.unlink(handle.name)
            _LIVE.discard(handle.name)
        raise
    _fsync_folder(folder)


@contextmanager
def _in_place(path: Path, fd: int | None, mode: str) -> Iterator[IO]:
    """A stream target opened for writing in place: the process's descriptor ``fd`` (duplicated, so closing it
    leaves the stream open), or the device or FIFO at ``path``."""
    try:
        if fd is not None:
            if fd == 1:
                with suppress(Exception):
                    sys.stdout.flush()
            handle = os.fdopen(os.dup(fd), mode, **({"encoding": "utf-8"} if mode == "w" else {}))
        else:
            handle = open(path, mode, **({"encoding": "utf-8"} if mode == "w" else {}))  # noqa: SIM115
    except OSError as err:
        raise _write_error(path, err) from err
    try:
        try:
            yield handle
            handle.flush()
        finally:
            with suppress(BrokenPipeError):
                handle.close()
    except BrokenPipeError as err:
        raise ReaderGone() from err
    except OSError as err:
        raise _write_error(path, err) from err


def _commit(tmp: Path, path: Path, force: bool) -> None:
    if force:
        os.replace(tmp, path)
    else:
        _link_no_clobber(tmp, path)
    if _INPUTS is not None:  # a command runs: what it wrote, for the message when it is stopped
        _WRITTEN.append(str(path))


#: The files the running command has written so far (the CLI's stop message names them).
_WRITTEN: list[str] = []


def written() -> list[str]:
    """The files written (committed) since the command started (:func:`track_inputs`)."""
    return list(dict.fromkeys(_WRITTEN))


_GROUP: list[tuple[Path, Path, bool]] | None = None


@contextmanager
def output_group() -> Iterator[None]:
    """Outputs written inside appear together or not at all (e.g. a log and its truth file).

    Each is written to its temporary file as usual; the renames into place all happen at the end, with
    SIGINT, SIGTERM and SIGHUP held back (so no signal can fall between them); any exception before that (Ctrl-C
    included) removes every temporary file and leaves the targets as they were.
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
            _LIVE.discard(str(tmp))
        raise
    finally:
        _GROUP = None
    blocked = hasattr(signal, "pthread_sigmask")
    if blocked:
        signal.pthread_sigmask(signal.SIG_BLOCK, set(_HELD))
    try:
        with interrupts.held():  # a signal that reaches another thread waits too
            for i, (tmp, path, force) in enumerate(pending):
                try:
                    _commit(tmp, path, force)
                    _LIVE.discard(str(tmp))
                except BaseException:
                    for later, _, _ in pending[i:]:
                        with suppress(OSError):
                            os.unlink(later)
                        _LIVE.discard(str(later))
                    raise
            for folder in {path.parent for _, path, _ in pending}:
                _fsync_folder(folder)
    finally:
        if blocked:
            signal.pthread_sigmask(signal.SIG_UNBLOCK, set(_HELD))


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
        try:
            sys.stdout.write(text)
            sys.stdout.flush()
        except BrokenPipeError:
            raise
        except OSError as err:
            raise _write_error("-", err) from err
        return
    atomic_write_text(path_or_dash, text, force=force)
