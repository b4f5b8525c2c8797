"""The optional parts of wmrid and the extras that install them.

``pip install wmrid`` gives identify, simulate, report, compare, monitor, inspect, plan and export on CSV, MCAP and
ROS bag logs.  One extra makes every command faster, three add what only some commands or formats need (the sizes
measured in a fresh Python 3.11 environment; README "Install"):

* ``fast``: numba, which compiles the estimator's loops (:mod:`wmrid.core.jit`; without it they run as plain Python,
  with the same results to rounding, about 10 times slower);
* ``fleet``: ``wmrid fleet`` (dask.distributed, and pyarrow for its Parquet table);
* ``parquet``: Parquet logs, in and out (pyarrow; it also reads plain CSV logs about 3x faster);
* ``physics``: ``wmrid simulate --engine mujoco`` (MuJoCo).

A command that needs a missing part says so in one line, naming the extra (:func:`require`).
"""

from __future__ import annotations

import importlib
import importlib.util
from types import ModuleType

from wmrid.core.errors import WmridError

#: extra -> (what it adds, the modules it installs).
EXTRAS = {
    "fast": ("compiled estimator loops", ("numba",)),
    "fleet": ("wmrid fleet", ("distributed", "pyarrow")),
    "parquet": ("Parquet logs", ("pyarrow",)),
    "physics": ("wmrid simulate --engine mujoco", ("mujoco",)),
}


class MissingExtraError(WmridError, ImportError):
    """A command or a format needs an optional part of wmrid that is not installed (exit 2)."""


def install_hint(extra: str) -> str:
    """The command that installs ``extra``: ``pip install 'wmrid[fleet]'``."""
    if extra not in EXTRAS:
        raise ValueError(f"unknown extra {extra!r}; the extras are {', '.join(EXTRAS)}")
    return f"pip install 'wmrid[{extra}]'"


def require(module: str, extra: str, what: str | None = None) -> ModuleType:
    """``module`` imported, or a :class:`MissingExtraError` in one line: "``what`` needs the ``extra`` extra: pip
    install 'wmrid[extra]'" (``what`` defaults to what the extra adds, :data:`EXTRAS`)."""
    try:
        return importlib.import_module(module)
    except ImportError as err:
        need = what or EXTRAS[extra][0]
        raise MissingExtraError(f"{need} needs the {extra} extra: {install_hint(extra)}") from err


def require_installed(module: str, extra: str, what: str | None = None) -> None:
    """As :func:`require`, without importing ``module`` (distributed takes ~0.5 s): the one-line error when it is not
    installed, checked before a command's work, whose own imports come later."""
    if not installed(module):
        require(module, extra, what)  # the same error, raised by the import


def installed(module: str) -> bool:
    """Whether ``module`` is installed, found without importing it (an installed module may still fail to import)."""
    try:
        return importlib.util.find_spec(module) is not None
    except (ImportError, ValueError):
        return False


def available(module: str) -> bool:
    """Whether ``module`` can be imported (an optional fast path is taken only then)."""
    try:
        importlib.import_module(module)
    except ImportError:
        return False
    return True
