"""The estimator's loops compiled when numba is installed (the ``fast`` extra), the same Python functions otherwise.

Every per-sample recursion in wmrid (the observer, the least-squares and filter recursions, the simulators, the
binary log scanners) is written once, as a plain Python function on numpy arrays and scalars, and decorated with
:func:`kernel`.  With numba (``pip install 'wmrid[fast]'``, 217 MB: numba and its LLVM) the decorator compiles it to
machine code on first use and caches that on disk; without numba the function runs as written.  The results are the
same to rounding (tests/unit/api/test_without_numba.py runs logs, every method and the simulator both ways); only
the time differs, about 10x on the bundled sample and 50-100x on the inner loops, which :func:`warn_if_slow` tells
a user of a long log.
"""

from __future__ import annotations

import functools
import warnings
from collections.abc import Callable
from typing import Any, overload

import numpy as np

from wmrid.core.extras import install_hint, installed


class PerformanceWarning(UserWarning):
    """A run that will take much longer than it would with an optional part installed (the command line shows it as
    one line on stderr, "wmrid: note: ..."; a library user can filter it as any warning)."""


numba: Any
#: Why numba is installed but cannot be imported (its ImportError: e.g. a NumPy newer than it supports), or None.
BROKEN: str | None = None
try:
    import numba  # numba (~0.3 s): imported by the modules that define kernels, when they are first needed
except ImportError as _err:
    numba = None
    if installed("numba"):
        BROKEN = " ".join(str(_err).split()) or type(_err).__name__

#: Whether the kernels are compiled (numba importable).  Decided once, when wmrid first needs a kernel.
COMPILED: bool = numba is not None

#: Samples of a log from which :func:`slow_note` speaks: below it the plain-Python kernels take a few seconds.
SLOW_FROM_SAMPLES = 100_000

#: Plain-Python time per sample of one identification (s), measured on the 2-core machine on the bundled sample
#: (12 s for 40,001 samples, every check included): for the estimate :func:`slow_note` gives.
PYTHON_SECONDS_PER_SAMPLE = 3e-4


@overload
def kernel(fn: Callable[..., Any]) -> Any: ...


@overload
def kernel(*, inline: bool = False) -> Callable[[Callable[..., Any]], Any]: ...


def kernel(fn: Any = None, *, inline: bool = False) -> Any:
    """``fn`` compiled by numba (``njit``, cached on disk, the GIL released; ``inline``: inlined where it is called),
    or ``fn`` itself when numba is not installed.

    Use as ``@kernel`` or ``@kernel(inline=True)``; typed ``Any``, as numba's dispatchers are.  A kernel must run the
    same as plain Python: numpy arrays and scalars, loops, no Python objects numba cannot type."""

    def wrap(f: Callable[..., Any]) -> Any:
        if numba is None:
            return _as_compiled(f)
        options: dict[str, Any] = {"cache": True, "nogil": True}
        if inline:
            options["inline"] = "always"
        return numba.njit(**options)(f)

    return wrap if fn is None else wrap(fn)


def _as_compiled(f: Callable[..., Any]) -> Callable[..., Any]:
    """``f`` run as plain Python with numba's arithmetic as far as numpy can give it: a division by zero raises
    ZeroDivisionError (numba's error model, where numpy's scalars would give inf and a warning); an overflow, an
    invalid operation (inf - inf) or an underflow gives inf, NaN or 0 silently, as compiled code does (numpy would
    print a RuntimeWarning per code line)."""

    @functools.wraps(f)
    def run(*args: Any) -> Any:
        with np.errstate(divide="raise", over="ignore", under="ignore", invalid="ignore"):
            try:
                return f(*args)
            except FloatingPointError as err:  # numpy's "divide by zero encountered in scalar divide"
                raise ZeroDivisionError(str(err)) from None

    return run


def slow_note(samples: int) -> str | None:
    """One line for a user whose log of ``samples`` samples will be identified without numba, or None (numba is
    installed, or the log is short enough not to matter)."""
    if COMPILED or samples < SLOW_FROM_SAMPLES:
        return None
    seconds = samples * PYTHON_SECONDS_PER_SAMPLE
    took = f"about {seconds / 60.0:.0f} min" if seconds >= 90.0 else f"about {seconds:.0f} s"
    plain = f"{_why_plain()}, so the estimator runs as plain Python"
    return f"{plain}: {took} for these {samples:,} samples, {_remedy('seconds')}"


def _why_plain() -> str:
    return "numba is not installed" if BROKEN is None else f"numba is installed but cannot be imported ({BROKEN})"


def _remedy(fast: str) -> str:
    """``fast`` ("seconds"), said of the compiled kernels: with the extra to install, or once the numba that is there
    imports."""
    return f"{fast} with it ({install_hint('fast')})" if BROKEN is None else f"{fast} once numba imports"


def warn_if_slow(samples: int) -> None:
    """A :class:`PerformanceWarning` with :func:`slow_note`'s line, when there is one."""
    note = slow_note(samples)
    if note is not None:
        warnings.warn(note, PerformanceWarning, stacklevel=3)


def warn_plain_python(what: str) -> None:
    """A :class:`PerformanceWarning` that ``what`` ("every log is identified") runs as plain Python, when numba is not
    installed: for a command of many logs, whose lengths are not known at its start."""
    if not COMPILED:
        warnings.warn(
            f"{_why_plain()}, so {what} as plain Python, {_remedy('about ten times faster')}",
            PerformanceWarning,
            stacklevel=2,
        )
