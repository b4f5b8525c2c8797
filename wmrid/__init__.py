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


_numba_cache_fallback()
