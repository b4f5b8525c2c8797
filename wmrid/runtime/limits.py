"""The memory budget: how much one input may make wmrid allocate (issue 13: bounded memory on any input).

A small file can declare a huge size: a zstd chunk that decompresses to gigabytes, a Parquet row group of 100 M
rows, a CSV header of 10 M columns.  Every size an input declares is checked against the budget before it is
allocated; beyond it the input is refused (or the part skipped) with a message naming the budget.

The budget is ``WMRID_MEMORY_BUDGET`` in bytes, with an optional K, M or G suffix (powers of 1024); default 4 GiB,
or half the machine's memory when that is less, and under an address-space cap (``ulimit -v``, ``prlimit --as``)
at most half the cap: a budget above the cap let an endless source (``/dev/zero``, ``yes |``) grow until a
MemoryError instead of stopping at the budget with a line that names it.
"""

from __future__ import annotations

import os
from typing import Any

from wmrid.core.errors import LogFormatError, UsageError

#: bytes: the default budget (at most half the machine's memory, :func:`memory_budget`).
DEFAULT_BUDGET = 4 << 30
ENV = "WMRID_MEMORY_BUDGET"
_SUFFIX = {"": 1, "K": 1 << 10, "M": 1 << 20, "G": 1 << 30, "T": 1 << 40}


def address_space_cap() -> int | None:
    """The soft RLIMIT_AS in bytes (``ulimit -v``), None when there is none."""
    try:
        import resource  # Unix only: the ImportError is caught (no cap)

        soft = resource.getrlimit(resource.RLIMIT_AS)[0]
    except (ImportError, OSError, ValueError, AttributeError):
        return None
    return None if soft == resource.RLIM_INFINITY else int(soft)


def memory_budget() -> int:
    """The budget in bytes (``WMRID_MEMORY_BUDGET``; default DEFAULT_BUDGET, or half the machine's memory when less,
    but at least 1 GiB; under an address-space cap at most half of it, at least 64 MiB); UsageError for a
    malformed value."""
    text = os.environ.get(ENV, "").strip()
    if not text:
        try:
            half = os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") // 2
        except (ValueError, OSError, AttributeError):
            half = DEFAULT_BUDGET
        budget = min(DEFAULT_BUDGET, max(half, 1 << 30))
        cap = address_space_cap()
        return budget if cap is None else min(budget, max(cap // 2, 64 << 20))
    number, suffix = text.rstrip("KMGTkmgtBb"), text[len(text.rstrip("KMGTkmgtBb")) :].upper().rstrip("B")
    try:
        value = int(float(number) * _SUFFIX[suffix])
    except (ValueError, KeyError, OverflowError):
        value = -1
    if value <= 0:
        raise UsageError(f"{ENV}={text!r}: give a size in bytes, e.g. 512M or 4G")
    return value


def describe(size: int) -> str:
    """A byte count for a message: '3.2 GiB', '512 MiB', '12 KiB', '100 B'."""
    for unit, scale in (("TiB", 1 << 40), ("GiB", 1 << 30), ("MiB", 1 << 20), ("KiB", 1 << 10)):
        if size >= scale:
            return f"{size / scale:.3g} {unit}"
    return f"{size} B"


#: bytes: the most a robot description (TOML, URDF) may hold; a real one is a few kilobytes.
ROBOT_FILE_LIMIT = 16 << 20


def read_limited(source: Any, limit: int, message: str, error: type[Exception] | None = None) -> bytes:
    """The bytes of ``source`` (a path, or a binary file object such as standard input), read in 1 MiB blocks and
    refused with :class:`wmrid.core.errors.LogFormatError` (``message``, formatted with ``size``, the limit described)
    once they pass ``limit`` (or ``error``, another WmridError class): an endless source (``/dev/zero``, ``yes |``)
    stops there instead of filling memory.  OSError passes through."""

    error = error or LogFormatError

    def read(fh: Any) -> bytes:
        data = bytearray()  # grown in place: no second copy of everything read at the end
        while True:
            block = fh.read(1 << 20)
            if not block:
                return data  # type: ignore[return-value]  # a bytearray reads like bytes everywhere it goes
            data += block
            if len(data) > limit:
                raise error(message.format(size=describe(limit)))

    if isinstance(source, (str, os.PathLike)):
        with open(source, "rb") as fh:
            return read(fh)
    return read(source)


#: glibc's malloc settings for one identification at a time (mallopt parameter -> value): blocks up to 32 MiB from
#: the heap (M_MMAP_THRESHOLD, -3) and up to 64 MiB of freed heap kept (M_TRIM_THRESHOLD, -1).  With glibc's
#: defaults every array of a long log (600,000 samples: ~10 MB each) is mapped and unmapped afresh, its pages
#: faulted in each time: the in-process identify of a 10-minute 1 kHz bag took 0.96 s instead of 0.90 s (db3) and
#: 0.67 s instead of 0.63 s (ROS 1), for 20 MB more peak memory (bench/speed/bench_bags.py).  Dask's nanny even sets
#: MALLOC_TRIM_THRESHOLD_=65536, which pins the mmap threshold at 128 KiB: +70 % on a fleet worker.
MALLOC_SETTINGS = {-3: 32 << 20, -1: 64 << 20}


def tune_malloc(override_environment: bool = False) -> bool:
    """Apply :data:`MALLOC_SETTINGS` to this process (glibc only); whether they were applied.  Left alone under an
    address-space cap (``ulimit -v``: the heap's larger footprint would count against it) and, unless
    ``override_environment``, when MALLOC_MMAP_THRESHOLD_ or MALLOC_TRIM_THRESHOLD_ says what the user wants."""
    global _tuned
    try:
        import ctypes  # only to call glibc's mallopt; a platform without it: the ImportError is caught below
        import resource  # Unix only: the ImportError is caught below

        if resource.getrlimit(resource.RLIMIT_AS)[0] != resource.RLIM_INFINITY:
            return False
        if not override_environment and any(
            os.environ.get(v) for v in ("MALLOC_MMAP_THRESHOLD_", "MALLOC_TRIM_THRESHOLD_")
        ):
            return False
        libc = ctypes.CDLL(None)
        _tuned = all(libc.mallopt(param, value) == 1 for param, value in MALLOC_SETTINGS.items())
        return _tuned
    except (ImportError, OSError, AttributeError, ValueError):
        return False


#: Whether :func:`tune_malloc` tuned this process's malloc.
_tuned = False


#: glibc's own thresholds, fixed (mallopt parameter -> value): every block over 128 KiB mapped and given back when
#: freed, freed heap over 128 KiB given back (:func:`lean_malloc`).
LEAN_MALLOC_SETTINGS = {-3: 128 << 10, -1: 128 << 10}


def lean_malloc() -> bool:
    """Give memory back as soon as it is freed (:data:`LEAN_MALLOC_SETTINGS`, then ``malloc_trim``; glibc only), in a
    process whose malloc :func:`tune_malloc` tuned (the command line's): for its last stage when it is held to a
    memory budget (``wmrid live``'s final identify after a long stream), where the tuned heap's kept memory would add
    to the peak (an hour's identify: 336 MB against 415 MB tuned).  A process that did not tune malloc (a library
    caller's) is left as it is.  Whether it was applied."""
    if not _tuned:
        return False
    try:
        import ctypes  # only to call glibc's mallopt; a platform without it: the error is caught below

        libc = ctypes.CDLL(None)
        done = all(libc.mallopt(param, value) == 1 for param, value in LEAN_MALLOC_SETTINGS.items())
        libc.malloc_trim(0)
        return done
    except Exception:
        return False


#: The thread counts of the BLAS libraries numpy and scipy load (OpenBLAS, an OpenMP build, MKL).
BLAS_THREAD_VARIABLES = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")


def one_blas_thread() -> bool:
    """One BLAS thread for this process, unless the user set a count (:data:`BLAS_THREAD_VARIABLES`); whether it was
    set.  Effective only before numpy and scipy load their BLAS (each reads the count then).

    Why, for a process of one command: wmrid's BLAS calls are small (the delay profile's QR of a few thousand rows,
    p x p solves), too small to gain from threads, while OpenBLAS's workers spin after each call and take the cores
    from wmrid's own second thread (the timing check alongside the observer, the half-rate replay): the 1 h Parquet
    identify took 8.2 s instead of 4.8 s on a busy 2-core machine.  One thread also makes the last bits the same on
    every machine: with more, a few results depend on the core count (the friction test's statistic on the MuJoCo
    log, by 3e-11 relative), and the golden files are one thread's."""
    if any(os.environ.get(v) for v in BLAS_THREAD_VARIABLES):
        return False
    os.environ["OPENBLAS_NUM_THREADS"] = "1"
    return True
