"""Ctrl-C that never lands inside numba's compiler.

A KeyboardInterrupt raised while numba compiles a kernel or loads it from its on-disk cache (Python code
that llvmlite calls back into through ctypes) leaves LLVM in a broken state: the process then dies of a
segmentation fault instead of exiting 130 (seen: `wmrid simulate` interrupted about a second in).
:func:`install` replaces Python's SIGINT handler with one that raises KeyboardInterrupt at once unless
the interrupted code is numba's or llvmlite's; there it re-checks every 50 ms (SIGALRM) and raises as
soon as the program is back in its own code.  Compiled kernels themselves never see the signal (it is
handled when they return), so this only defers Ctrl-C by the length of a compilation.

SIGTERM (``timeout``, ``docker stop``, systemd) and SIGHUP (a closed terminal) are handled the same way: they
raise :class:`Terminated`, a KeyboardInterrupt, so every temporary file is removed and a result group is complete
or absent, exactly as for Ctrl-C; the CLI then exits 128 + the signal's number (143, 129).
"""

from __future__ import annotations

import os
import signal
from types import FrameType

RETRY_S = 0.05
_GUARDED = (f"{os.sep}numba{os.sep}", f"{os.sep}llvmlite{os.sep}")


def in_compiler(frame: FrameType | None) -> bool:
    """True when ``frame`` or one of its callers runs numba's or llvmlite's Python code."""
    while frame is not None:
        if any(part in frame.f_code.co_filename for part in _GUARDED):
            return True
        frame = frame.f_back
    return False


class Terminated(KeyboardInterrupt):
    """SIGTERM or SIGHUP, raised where Ctrl-C would be; ``signum`` says which."""

    def __init__(self, signum: int) -> None:
        super().__init__(signal.Signals(signum).name)
        self.signum = signum


#: The signals that stop a run: Ctrl-C, and where the platform has them, kill and a closed terminal.
STOPPING = tuple(getattr(signal, n) for n in ("SIGINT", "SIGTERM", "SIGHUP") if hasattr(signal, n))
#: The first stopping signal received (the exit code is 128 + it), or None.
received: int | None = None
_pending = signal.SIGINT


def _interrupt(signum: int, frame: FrameType | None) -> None:
    global received, _pending
    if signum != getattr(signal, "SIGALRM", None):
        _pending = signum
        if received is None:
            received = signum
    if in_compiler(frame) and hasattr(signal, "setitimer"):
        signal.setitimer(signal.ITIMER_REAL, RETRY_S)  # try again once numba has finished
        return
    if _pending == signal.SIGINT:
        raise KeyboardInterrupt
    raise Terminated(_pending)


def exit_code() -> int:
    """128 + the stopping signal received (130 for Ctrl-C, 143 for SIGTERM, 129 for SIGHUP)."""
    return 128 + int(received if received is not None else signal.SIGINT)


def install() -> dict[int, object]:
    """Use the deferring handler for SIGINT, SIGTERM and SIGHUP (and SIGALRM, its retry); call from the main
    thread.  Returns the handlers it replaced, for :func:`restore`.
    """
    global received, _pending
    received, _pending = None, signal.SIGINT
    previous = {
        signum: signal.signal(signum, _interrupt)
        for signum in STOPPING
        if signum == signal.SIGINT or signal.getsignal(signum) is not signal.SIG_IGN  # nohup's SIGHUP stays ignored
    }
    if hasattr(signal, "SIGALRM"):
        previous[signal.SIGALRM] = signal.signal(signal.SIGALRM, _interrupt)
    return previous


def restore(previous: dict[int, object]) -> None:
    """Put back the handlers :func:`install` replaced, and cancel a pending retry."""
    if hasattr(signal, "setitimer"):
        signal.setitimer(signal.ITIMER_REAL, 0)
    for signum, handler in previous.items():
        signal.signal(signum, handler)  # type: ignore[arg-type]
