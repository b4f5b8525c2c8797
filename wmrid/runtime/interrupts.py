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

An exception raised where Python cannot pass it on (a weakref callback, ``__del__``: measured, a SIGTERM that arrived
while the import system's module-lock callback ran) is printed as "Exception ignored" and dropped, and the run went on
to exit 0 with its outputs written.  :func:`install` therefore also hooks ``sys.unraisablehook``: the dropped stop is
raised again 1 ms later, from wherever the program then is.
"""

from __future__ import annotations

import contextlib
import os
import select
import signal
import sys
import threading
import time
from collections.abc import Callable, Iterator
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
#: The timer's signal that retries a deferred or dropped stop (where the platform has it).
RETRIES = tuple(getattr(signal, n) for n in ("SIGALRM",) if hasattr(signal, n))
#: The first stopping signal received (the exit code is 128 + it), or None.
received: int | None = None
_pending = signal.SIGINT


_holding = 0  # > 0 inside held(): a stopping signal waits until it ends
_deferred = False


def _interrupt(signum: int, frame: FrameType | None) -> None:
    global received, _pending, _deferred
    if signum != getattr(signal, "SIGALRM", None):
        _pending = signum
        if received is None:
            received = signum
    if _holding:
        _deferred = True  # raised when held() ends
        return
    if in_compiler(frame) and hasattr(signal, "setitimer"):
        signal.setitimer(signal.ITIMER_REAL, RETRY_S)  # try again once numba has finished
        return
    _raise()


def _raise() -> None:
    if _pending == signal.SIGINT:
        raise KeyboardInterrupt
    raise Terminated(_pending)


@contextlib.contextmanager
def held() -> Iterator[None]:
    """Inside, a stopping signal is recorded and raised only at the end (a result group's renames run here).
    Blocking the signals (``pthread_sigmask``) holds them back from the main thread only: a signal delivered to
    another thread (OpenBLAS's workers) still ran the handler between two renames and split a log from its truth
    file."""
    global _holding, _deferred
    _holding += 1
    try:
        yield
    finally:
        _holding -= 1
    if not _holding and _deferred:
        _deferred = False
        _raise()


#: s: how soon a stop that was dropped (raised inside a weakref callback or ``__del__``) is raised again.
REPEAT_S = 0.001
#: Whether a stopping signal's exception was dropped since :func:`install` (raised again later, or, when the command
#: ended first, turned into its exit code by the CLI: :func:`disarm`).
dropped = False
_previous_hook: Callable[[object], object] | None = None
_in_hook = threading.local()  # .active: this thread is inside the previous hook (it must not call this one again)


def _unraisable(info: object) -> None:
    """``sys.unraisablehook``: a stopping signal's exception dropped where it was raised is raised again (by SIGALRM,
    :data:`REPEAT_S` later) instead of printed; anything else goes to the previous hook (never back to this one: a
    hook that wrapped this one and stayed installed would otherwise call it in a loop)."""
    global _deferred, dropped
    if isinstance(getattr(info, "exc_value", None), KeyboardInterrupt) and received is not None:
        dropped = True
        if _holding:
            _deferred = True
        elif hasattr(signal, "setitimer"):
            signal.setitimer(signal.ITIMER_REAL, REPEAT_S)
        return
    inside = getattr(_in_hook, "active", False)
    previous = _previous_hook if not inside else None
    _in_hook.active = True
    try:
        (previous or sys.__unraisablehook__)(info)  # type: ignore[arg-type]
    finally:
        _in_hook.active = inside


def disarm() -> bool:
    """Cancel a pending retry (the outcome is being decided); returns whether a stop is owed since :func:`install`:
    one dropped, one held back by :func:`held` whose block raised, or one deferred while numba compiled whose retry
    was still pending; the caller ends the run as stopped.  (Any timer still pending is wmrid's: :func:`install`
    saved and cleared the caller's.)"""
    pending = False
    if hasattr(signal, "setitimer"):
        pending = signal.setitimer(signal.ITIMER_REAL, 0)[0] > 0
    return dropped or _deferred or (pending and received is not None)


def exit_code() -> int:
    """128 + the stopping signal received (130 for Ctrl-C, 143 for SIGTERM, 129 for SIGHUP)."""
    return 128 + int(received if received is not None else signal.SIGINT)


def install() -> dict[int, object]:
    """Use the deferring handler for SIGINT, SIGTERM and SIGHUP (and SIGALRM, its retry); call from the main
    thread.  Returns the handlers it replaced, for :func:`restore`.
    """
    global received, _pending, _previous_hook, dropped, _deferred
    received, _pending, dropped, _deferred = None, signal.SIGINT, False, False
    if sys.unraisablehook is not _unraisable:
        _previous_hook = sys.unraisablehook
        sys.unraisablehook = _unraisable
    previous = {
        signum: signal.signal(signum, _interrupt)
        for signum in STOPPING
        if signum == signal.SIGINT or signal.getsignal(signum) is not signal.SIG_IGN  # nohup's SIGHUP stays ignored
    }
    if hasattr(signal, "SIGALRM"):
        if hasattr(signal, "setitimer"):  # the caller's alarm (a test's timeout, say) waits while wmrid runs
            previous[_CALLER_TIMER] = (*signal.setitimer(signal.ITIMER_REAL, 0), time.monotonic())
        previous[signal.SIGALRM] = signal.signal(signal.SIGALRM, _interrupt)
    return previous


#: The key under which :func:`install` keeps the caller's real-time timer: (delay s, interval s, when).
_CALLER_TIMER = -1


def restore(previous: dict[int, object]) -> None:
    """Put back the handlers :func:`install` replaced, cancel a pending retry, and re-arm the caller's alarm for
    the time it had left (at once if that has passed)."""
    global _previous_hook
    if hasattr(signal, "setitimer"):
        signal.setitimer(signal.ITIMER_REAL, 0)
    if sys.unraisablehook is _unraisable:
        sys.unraisablehook = _previous_hook or sys.__unraisablehook__
        _previous_hook = None
    for signum, handler in previous.items():
        if signum != _CALLER_TIMER:
            signal.signal(signum, handler)  # type: ignore[arg-type]
    timer = previous.get(_CALLER_TIMER)
    if timer is not None:
        delay, interval, since = timer  # type: ignore[misc]
        if delay > 0:
            signal.setitimer(signal.ITIMER_REAL, max(delay - (time.monotonic() - since), 1e-6), interval)


#: s: how long a stopping signal may wait for the program to return to Python (a compiled kernel, a BLAS call)
#: before the watchdog removes the temporary files itself and exits.
GRACE_S = 5.0
#: Called by the watchdog before it exits: each removes what it owns (wmrid.runtime.atomic registers its temporary
# files).
forced_exit_cleanups: list[Callable[[], None]] = []
#: Monotonic time before which the watchdog leaves the process alone (:func:`extend_grace`).
_grace_until = 0.0


def extend_grace(seconds: float) -> None:
    """Let the process run up to ``seconds`` more after a stopping signal before the watchdog ends it: for a command
    that answers the stop itself with work that takes longer than GRACE_S (``wmrid live`` identifying what it has
    received, to write it); a second signal still stops it at once."""
    global _grace_until
    _grace_until = max(_grace_until, time.monotonic() + seconds)


def start_watchdog() -> None:
    """For the command-line process only (never in-process: it would end the caller): a thread that wakes on any
    stopping signal (``signal.set_wakeup_fd``) and, if the process is still running GRACE_S later, runs
    :data:`forced_exit_cleanups` and exits 128 + the signal.  Python runs a signal's handler only between bytecodes,
    so SIGTERM used not to end a process stuck inside a compiled loop at all (``timeout`` then waited forever)."""
    if not hasattr(signal, "set_wakeup_fd") or not hasattr(signal, "pthread_sigmask"):
        return
    import socket  # socket (~5 ms): only the command line's watchdog (wmrid --help never starts it)

    reader, writer = socket.socketpair()
    writer.setblocking(False)
    try:
        signal.set_wakeup_fd(writer.fileno(), warn_on_full_buffer=False)
    except (ValueError, OSError):  # not the main thread, or no such support: no watchdog
        reader.close()
        writer.close()
        return

    def watch() -> None:
        # Signals go to the main thread only (this thread starts with them blocked): while the main thread holds
        # them back (a result group's renames), they wait.
        while True:
            data = reader.recv(64)
            if not data:
                return
            stopping = [s for s in data if s in STOPPING]
            if not stopping:
                continue  # SIGALRM, the compile retry
            time.sleep(GRACE_S)
            while time.monotonic() < _grace_until:
                time.sleep(0.1)
            for cleanup in forced_exit_cleanups:
                with contextlib.suppress(Exception):
                    cleanup()
            signum = stopping[0]
            name = "interrupted" if signum == signal.SIGINT else f"terminated by {signal.Signals(signum).name}"
            note = f"wmrid: {name} (the program did not return to Python within {GRACE_S:g} s)\n"
            with contextlib.suppress(Exception):
                if select.select([], [2], [], 0.2)[1]:  # never block on a full stderr pipe
                    os.write(2, note.encode())
            os._exit(128 + stopping[0])

    held = signal.pthread_sigmask(signal.SIG_BLOCK, set(STOPPING))  # the thread starts with them blocked
    try:
        threading.Thread(target=watch, name="wmrid-signal-watchdog", daemon=True).start()
    finally:
        signal.pthread_sigmask(signal.SIG_SETMASK, held)
    _keep.append((reader, writer))


_keep: list[object] = []  # the watchdog's socket pair lives as long as the process
