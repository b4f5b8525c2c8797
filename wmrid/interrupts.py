"""Ctrl-C that never lands inside numba's compiler.

A KeyboardInterrupt raised while numba compiles a kernel or loads it from its on-disk cache (Python code
that llvmlite calls back into through ctypes) leaves LLVM in a broken state: the process then dies of a
segmentation fault instead of exiting 130 (seen: `wmrid simulate` interrupted about a second in).
:func:`install` replaces Python's SIGINT handler with one that raises KeyboardInterrupt at once unless
the interrupted code is numba's or llvmlite's; there it re-checks every 50 ms (SIGALRM) and raises as
soon as the program is back in its own code.  Compiled kernels themselves never see the signal (it is
handled when they return), so this only defers Ctrl-C by the length of a compilation.
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


def _interrupt(signum: int, frame: FrameType | None) -> None:
    if in_compiler(frame) and hasattr(signal, "setitimer"):
        signal.setitimer(signal.ITIMER_REAL, RETRY_S)  # try again once numba has finished
        return
    raise KeyboardInterrupt


def install() -> dict[int, object]:
    """Use the deferring handler for SIGINT (and SIGALRM, its retry); call from the main thread.

    Returns the handlers it replaced, for :func:`restore`.
    """
    previous = {signal.SIGINT: signal.signal(signal.SIGINT, _interrupt)}
    if hasattr(signal, "SIGALRM"):
        previous[signal.SIGALRM] = signal.signal(signal.SIGALRM, _interrupt)
    return previous


def restore(previous: dict[int, object]) -> None:
    """Put back the handlers :func:`install` replaced, and cancel a pending retry."""
    if hasattr(signal, "setitimer"):
        signal.setitimer(signal.ITIMER_REAL, 0)
    for signum, handler in previous.items():
        signal.signal(signum, handler)  # type: ignore[arg-type]
