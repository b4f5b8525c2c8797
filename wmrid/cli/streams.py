"""The process's standard streams, guarded for the CLI (issue 13: output errors).

* Standard output: a write or flush that fails (a full disk, ``/dev/full``, a closed stream) becomes
  :class:`wmrid.core.errors.OutputWriteError` naming standard output, so the run exits 1 with one line instead of 0
  with truncated JSON or "internal error".  A closed pipe (``| head``) becomes :class:`wmrid.core.errors.ReaderGone`:
  a reader that has seen enough, exit 0.
* Unbuffered standard output (``PYTHONUNBUFFERED=1``, ``python -u``): Python writes each string with one write(2)
  and drops what a short write left over (a file on a nearly full filesystem takes the first 64 KB and the run
  ended 0 with truncated JSON, issue 30).  It is written through a buffered writer instead, which writes the rest
  (and so meets the error), flushed after every write so that it stays unbuffered.
* Standard error: carries only notes and messages, so a failure there (closed, full) is ignored and never
  changes the exit code of a run that succeeded.

:func:`guard` installs both and returns what :func:`unguard` puts back.
"""

from __future__ import annotations

import contextlib
import io
import sys
from typing import Any

from wmrid.core.errors import OutputWriteError, ReaderGone


def _failure(err: BaseException | None) -> OutputWriteError:
    why = "it is closed" if err is None else getattr(err, "strerror", None) or str(err)
    return OutputWriteError(f"cannot write standard output: {why}; what was printed is incomplete")


class _GuardedOutput:
    """A stream (text, or binary as ``buffer``) whose write errors are OutputWriteError; None: a closed stream.
    ``autoflush``: flushed after every write (a buffered stream standing in for an unbuffered one)."""

    def __init__(self, stream: Any, autoflush: bool = False) -> None:
        self._stream = stream
        self._autoflush = autoflush

    def write(self, data: Any) -> int:
        if self._stream is None:
            raise _failure(None)
        try:
            n = self._stream.write(data)
            if self._autoflush:
                self._stream.flush()
            return n
        except BrokenPipeError as err:
            raise ReaderGone() from err
        except (OSError, ValueError) as err:  # ValueError: a stream closed under us
            raise _failure(err) from err

    def flush(self) -> None:
        if self._stream is None:
            return
        try:
            self._stream.flush()
        except BrokenPipeError as err:
            raise ReaderGone() from err
        except (OSError, ValueError) as err:
            raise _failure(err) from err

    def isatty(self) -> bool:
        try:
            return bool(self._stream is not None and self._stream.isatty())
        except (OSError, ValueError):
            return False

    @property
    def buffer(self) -> _GuardedOutput:
        if self._stream is None:
            return _GuardedOutput(None)  # closed: writing to it is the error, not asking for it
        inner = getattr(self._stream, "buffer", None)
        if inner is None:  # a text-only stream (StringIO, a test harness): callers fall back to text
            raise AttributeError("buffer")
        return _GuardedOutput(inner, self._autoflush)

    def __getattr__(self, name: str) -> Any:
        if self._stream is None:
            raise AttributeError(name)
        return getattr(self._stream, name)


class _QuietError:
    """Standard error that never fails: what cannot be written there is dropped."""

    def __init__(self, stream: Any) -> None:
        self._stream = stream

    def write(self, data: Any) -> int:
        try:
            if self._stream is not None:
                self._stream.write(data)
        except (OSError, ValueError):
            pass
        return len(data)

    def flush(self) -> None:
        try:
            if self._stream is not None:
                self._stream.flush()
        except (OSError, ValueError):
            pass

    def isatty(self) -> bool:
        try:
            return bool(self._stream is not None and self._stream.isatty())
        except (OSError, ValueError):
            return False

    def __getattr__(self, name: str) -> Any:
        if self._stream is None:
            raise AttributeError(name)
        return getattr(self._stream, name)


def guard() -> tuple[Any, Any]:
    """Replace sys.stdout and sys.stderr by their guarded forms; returns the originals for :func:`unguard`."""
    saved = (sys.stdout, sys.stderr)
    if not isinstance(sys.stdout, _GuardedOutput):
        buffered = _buffered(sys.stdout)
        sys.stdout = _GuardedOutput(buffered or sys.stdout, autoflush=buffered is not None)  # type: ignore[assignment]
    if not isinstance(sys.stderr, _QuietError):
        sys.stderr = _QuietError(sys.stderr)  # type: ignore[assignment]
    return saved


def _buffered(stream: Any) -> Any:
    """A text stream writing ``stream``'s file descriptor through a buffered writer, when ``stream`` writes straight
    to a raw file (unbuffered: a short write would lose the rest); None otherwise (already buffered, no file)."""
    try:
        raw = getattr(stream, "buffer", None)
        if not isinstance(raw, io.RawIOBase):
            return None
        fd = stream.fileno()
        writer = io.BufferedWriter(io.FileIO(fd, "wb", closefd=False))
        return io.TextIOWrapper(
            writer, encoding=stream.encoding, errors=stream.errors, line_buffering=False, write_through=True
        )
    except (OSError, ValueError, AttributeError):
        return None


def unguard(saved: tuple[Any, Any]) -> None:
    """Put back the streams :func:`guard` replaced."""
    current = sys.stdout
    if isinstance(current, _GuardedOutput) and current._autoflush and current._stream is not None:
        with contextlib.suppress(OSError, ValueError):
            current._stream.flush()
    sys.stdout, sys.stderr = saved


def finish_output() -> None:
    """Flush standard output: raises OutputWriteError when what was printed could not all be written."""
    sys.stdout.flush()
