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

import warnings
from collections.abc import Callable
from typing import Any, overload

from wmrid.core.extras import install_hint


class PerformanceWarning(UserWarning):
    """A run that will take much longer than it would with an optional part installed (the command line shows it as
    one line on stderr, "wmrid: note: ..."; a library user can filter it as any warning)."""


numba: Any
try:
    import numba  # numba (~0.3 s): imported by the modules that define kernels, when they are first needed
except ImportError:
    numba = None

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
            return f
        options: dict[str, Any] = {"cache": True, "nogil": True}
        if inline:
            options["inline"] = "always"
        return numba.njit(**options)(f)

    return wrap if fn is None else wrap(fn)


def slow_note(samples: int) -> str | None:
    """One line for a user whose log of ``samples`` samples will be identified without numba, or None (numba is
    installed, or the log is short enough not to matter)."""
    if COMPILED or samples < SLOW_FROM_SAMPLES:
        return None
    seconds = samples * PYTHON_SECONDS_PER_SAMPLE
    took = f"about {seconds / 60.0:.0f} min" if seconds >= 90.0 else f"about {seconds:.0f} s"
    return (
        f"numba is not installed, so the estimator runs as plain Python: {took} for these {samples:,} samples, "
        f"seconds with it ({install_hint('fast')})"
    )


def warn_if_slow(samples: int) -> None:
    """A :class:`PerformanceWarning` with :func:`slow_note`'s line, when there is one."""
    note = slow_note(samples)
    if note is not None:
        warnings.warn(note, PerformanceWarning, stacklevel=3)
