"""wmrid: identify the dynamic parameters of differential-drive wheeled mobile robots from their logs."""

import os as _os

__version__ = "0.1.0"


def _numba_cache_fallback() -> None:
    """Give numba a writable cache when it would have none (issue 13: read-only installs).

    numba caches compiled kernels in the package's ``__pycache__``, else in the user's cache folder; with neither
    writable (installed read-only, run as a service account whose HOME does not exist) every command failed with
    "cannot cache function".  Then NUMBA_CACHE_DIR (read when numba is imported) points to a per-user folder under
    the system's temporary directory.  A NUMBA_CACHE_DIR already set is left alone."""
    if _os.environ.get("NUMBA_CACHE_DIR"):
        return
    here = _os.path.dirname(_os.path.abspath(__file__))
    candidates = [_os.path.join(here, "__pycache__")]
    home = _os.environ.get("XDG_CACHE_HOME") or _os.path.join(_os.path.expanduser("~"), ".cache")
    if _os.path.isabs(home):  # no HOME and no passwd entry leaves "~": never a folder made in the working directory
        candidates.append(_os.path.join(home, "numba"))
    for folder in candidates:
        try:
            _os.makedirs(folder, exist_ok=True)
        except OSError:
            continue
        if _os.access(folder, _os.W_OK | _os.X_OK):  # also false on a read-only file system, root or not
            return  # numba can cache here
    import tempfile

    uid = _os.getuid() if hasattr(_os, "getuid") else "user"
    _os.environ["NUMBA_CACHE_DIR"] = _os.path.join(tempfile.gettempdir(), f"wmrid-numba-cache-{uid}")


def _blas_threads_under_a_cap() -> None:
    """One BLAS thread when the process runs under an address-space cap (``ulimit -v``, ``prlimit --as``) and no
    thread count is set: OpenBLAS reserves a buffer per thread when numpy loads, and under a 2 GB cap a 3 s log
    hung inside ``eigvalsh`` (or printed OpenBLAS's own allocation errors) with its default of one per core.
    wmrid's heavy loops are compiled (numba), so a single BLAS thread costs nothing measurable there."""
    if any(_os.environ.get(v) for v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")):
        return
    try:
        import resource

        soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    except (ImportError, OSError, ValueError, AttributeError):
        return
    if soft != resource.RLIM_INFINITY:
        _os.environ["OPENBLAS_NUM_THREADS"] = "1"
        _os.environ["OMP_NUM_THREADS"] = "1"


_numba_cache_fallback()
_blas_threads_under_a_cap()
