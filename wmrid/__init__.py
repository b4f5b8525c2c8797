"""wmrid: identify the dynamic parameters of differential-drive wheeled mobile robots from their logs.

The public API, loaded on first use so that ``import wmrid`` stays fast::

    import wmrid
    log = wmrid.read_log("sample_logs/paper_sinusoid.csv")
    result = wmrid.identify(log, wmrid.load_robot("paper"))
    value, std = result.parameters["m11"]

Layers, lowest first: :mod:`wmrid.core`, :mod:`wmrid.model`, then :mod:`wmrid.io`, :mod:`wmrid.estimators` and
:mod:`wmrid.sim` side by side, :mod:`wmrid.pipeline`, :mod:`wmrid.monitoring` and :mod:`wmrid.design`,
:mod:`wmrid.reporting`, :mod:`wmrid.api` and the command line :mod:`wmrid.cli` on top.

Imports inside functions: start-up time (a front door: ``import wmrid`` and each function load only what that
function uses).
"""

import os as _os
from typing import TYPE_CHECKING as _TYPE_CHECKING

__version__ = "0.1.0"


def _numba_cache_fallback() -> None:
    """Give numba a writable cache when it would have none (issue 13: read-only installs).

    numba caches compiled kernels in the package's ``__pycache__``, else in the user's cache folder; with neither
    writable (installed read-only, run as a service account whose HOME does not exist) every command failed with
    "cannot cache function".  Then NUMBA_CACHE_DIR (read when numba is imported) points to a per-user folder under
    the system's temporary directory.  A NUMBA_CACHE_DIR already set is left alone."""
    from wmrid.core.extras import installed  # the extras' table, light: only this set-up, not the public names

    if _os.environ.get("NUMBA_CACHE_DIR") or not installed("numba"):  # without numba there is nothing to cache
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
    fallback = _private_temp_folder("wmrid-numba-cache")
    if fallback is not None:
        _os.environ["NUMBA_CACHE_DIR"] = fallback


def _private_temp_folder(name: str) -> str | None:
    """A folder under the system's temporary directory that only this user can write: ``NAME-UID`` when it is (or
    can be made) this user's own folder, not writable by others; else a fresh one (``NAME-`` and eight random
    characters).  In a shared /tmp anyone can make ``NAME-UID`` first: a folder someone else owns is never used
    (numba's cache holds pickles it loads: issue 30 found "cannot cache function" as an internal error there).  None
    when there is no writable temporary directory at all."""
    import contextlib
    import stat
    import tempfile

    uid = _os.getuid() if hasattr(_os, "getuid") else None
    try:
        path = _os.path.join(tempfile.gettempdir(), f"{name}-{uid if uid is not None else 'user'}")
        with contextlib.suppress(FileExistsError):  # made before, or by another process just now (fleet workers)
            _os.mkdir(path, 0o700)
        st = _os.lstat(path)
        mine = uid is None or st.st_uid == uid
        if stat.S_ISDIR(st.st_mode) and mine and not st.st_mode & 0o022 and _os.access(path, _os.W_OK | _os.X_OK):
            return path
        return tempfile.mkdtemp(prefix=f"{name}-")
    except OSError:  # FileNotFoundError from gettempdir included: no usable temporary directory
        return None


def _under_an_address_space_cap() -> None:
    """Keep the address space small when the process runs under a cap (``ulimit -v``, ``prlimit --as``).

    Libraries reserve address space they rarely touch: OpenBLAS a buffer per thread, Arrow's default allocator
    about 1 GB, glibc a 64 MB arena per thread.  An identify of a 2 s log reached 2.15 GB of address space, so
    under a 2 GB cap an allocation failed deep inside OpenBLAS and the run hung in ``lstsq``.  Under a cap (and
    unless set already): one BLAS thread, Arrow's system allocator, at most two malloc arenas -- 0.77 GB.  wmrid's
    heavy loops are compiled (numba), so none of this costs measurable time."""
    try:
        import resource

        soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    except (ImportError, OSError, ValueError, AttributeError):
        return
    if soft == resource.RLIM_INFINITY:
        return
    if not any(_os.environ.get(v) for v in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")):
        _os.environ["OPENBLAS_NUM_THREADS"] = "1"
        _os.environ["OMP_NUM_THREADS"] = "1"
    _os.environ.setdefault("ARROW_DEFAULT_MEMORY_POOL", "system")
    if "MALLOC_ARENA_MAX" not in _os.environ:
        try:
            import ctypes

            ctypes.CDLL(None).mallopt(-8, 2)  # M_ARENA_MAX (glibc); elsewhere there is no such call
        except (OSError, AttributeError):
            pass


_numba_cache_fallback()
_under_an_address_space_cap()


#: Public name -> module that defines it (imported on first access: numpy, numba and pandas load only when used).
_EXPORTS = {
    "LogOptions": "wmrid.api.inputs",
    "load_robot": "wmrid.api.inputs",
    "open_log": "wmrid.api.inputs",
    "read_log": "wmrid.api.inputs",
    "identify": "wmrid.api.identification",
    "compare": "wmrid.api.identification",
    "validate": "wmrid.api.identification",
    "ObserverOptions": "wmrid.estimators.options",
    "MethodOptions": "wmrid.estimators.methods",
    "Identification": "wmrid.api.reporting",
    "inspect": "wmrid.api.inputs",
    "Comparison": "wmrid.estimators.methods",
    "ValidationLog": "wmrid.estimators.methods",
    "simulate": "wmrid.api.simulation",
    "monitor": "wmrid.api.monitoring",
    "report": "wmrid.api.reporting",
    "write_report": "wmrid.api.reporting",
    "write_simulation": "wmrid.api.simulation",
    "load_reference": "wmrid.api.simulation",
    "NoiseSettings": "wmrid.sim.scenario",
    "Change": "wmrid.sim.scenario",
    "PlantChange": "wmrid.sim.scenario",
    "Payload": "wmrid.model.robot",
    "MultibodySettings": "wmrid.sim.multibody_model",
    "IdentificationResult": "wmrid.estimators.result",
    "ObserverRun": "wmrid.estimators.result",
    "Parameter": "wmrid.estimators.parameter",
    "Verdict": "wmrid.estimators.records",
    "GroupVerdict": "wmrid.estimators.records",
    "LogInfo": "wmrid.estimators.records",
    "Validation": "wmrid.estimators.records",
    "PayloadEstimate": "wmrid.model.payload",
    "Diagnostics": "wmrid.estimators.findings",
    "BaseEstimate": "wmrid.estimators.estimate",
    "WheelLog": "wmrid.core.wheel_log",
    "LogStream": "wmrid.core.wheel_log",
    "Robot": "wmrid.model.robot",
    "MonitorResult": "wmrid.monitoring.monitor_result",
    "MonitorSettings": "wmrid.monitoring.settings",
    "Report": "wmrid.reporting.report",
    "SimulationRun": "wmrid.api.simulation",
    "WmridError": "wmrid.core.errors",
    "fleet": "wmrid.fleets.run",
    "FleetRun": "wmrid.fleets.run",
    "fleet_report": "wmrid.fleets.report",
    "write_fleet_report": "wmrid.fleets.report",
    "FleetReport": "wmrid.fleets.rendering",
    "plan": "wmrid.api.planning",
    "predict_plan": "wmrid.api.planning",
    "write_plan": "wmrid.api.planning",
    "read_plan": "wmrid.api.planning",
    "Plan": "wmrid.design.plan",
    "export": "wmrid.api.exporting",
    "ExportResult": "wmrid.model.export_result",
    "ExportCheck": "wmrid.model.export_result",
    "PhysicalEstimate": "wmrid.model.physical",
    "live": "wmrid.api.live",
    "LiveRun": "wmrid.api.live",
    "LiveChange": "wmrid.monitoring.live_change",
    "PayloadMass": "wmrid.monitoring.live_change",
    "LiveUpdate": "wmrid.estimators.observer.live_update",
    "LiveResult": "wmrid.api.live",
}

if _TYPE_CHECKING:  # what the lazy exports are, for editors and type checkers (the same names as _EXPORTS)
    from wmrid.api.exporting import (
        export as export,
    )
    from wmrid.api.identification import compare as compare, identify as identify, validate as validate
    from wmrid.api.inputs import (
        LogOptions as LogOptions,
        inspect as inspect,
        load_robot as load_robot,
        open_log as open_log,
        read_log as read_log,
    )
    from wmrid.api.live import (
        LiveResult as LiveResult,
        LiveRun as LiveRun,
        live as live,
    )
    from wmrid.api.monitoring import (
        monitor as monitor,
    )
    from wmrid.api.planning import (
        plan as plan,
        predict_plan as predict_plan,
        read_plan as read_plan,
        write_plan as write_plan,
    )
    from wmrid.api.reporting import (
        Identification as Identification,
        report as report,
        write_report as write_report,
    )
    from wmrid.api.simulation import (
        SimulationRun as SimulationRun,
        load_reference as load_reference,
        simulate as simulate,
        write_simulation as write_simulation,
    )
    from wmrid.core.errors import (
        WmridError as WmridError,
    )
    from wmrid.core.wheel_log import (
        LogStream as LogStream,
        WheelLog as WheelLog,
    )
    from wmrid.design.plan import (
        Plan as Plan,
    )
    from wmrid.estimators.estimate import (
        BaseEstimate as BaseEstimate,
    )
    from wmrid.estimators.findings import Diagnostics as Diagnostics
    from wmrid.estimators.methods import Comparison as Comparison, ValidationLog as ValidationLog
    from wmrid.estimators.observer.live_update import LiveUpdate as LiveUpdate
    from wmrid.estimators.options import (
        MethodOptions as MethodOptions,
        ObserverOptions as ObserverOptions,
    )
    from wmrid.estimators.parameter import Parameter as Parameter
    from wmrid.estimators.records import (
        GroupVerdict as GroupVerdict,
        LogInfo as LogInfo,
        Validation as Validation,
        Verdict as Verdict,
    )
    from wmrid.estimators.result import (
        IdentificationResult as IdentificationResult,
        ObserverRun as ObserverRun,
    )
    from wmrid.fleets.rendering import (
        FleetReport as FleetReport,
    )
    from wmrid.fleets.report import (
        fleet_report as fleet_report,
        write_fleet_report as write_fleet_report,
    )
    from wmrid.fleets.run import FleetRun as FleetRun, fleet as fleet
    from wmrid.model.export_result import ExportCheck as ExportCheck, ExportResult as ExportResult
    from wmrid.model.payload import PayloadEstimate as PayloadEstimate
    from wmrid.model.physical import (
        PhysicalEstimate as PhysicalEstimate,
    )
    from wmrid.model.robot import Payload as Payload, Robot as Robot
    from wmrid.monitoring.live_change import LiveChange as LiveChange, PayloadMass as PayloadMass
    from wmrid.monitoring.monitor_result import MonitorResult as MonitorResult
    from wmrid.monitoring.settings import (
        MonitorSettings as MonitorSettings,
    )
    from wmrid.reporting.report import Report as Report
    from wmrid.sim.multibody_model import MultibodySettings as MultibodySettings
    from wmrid.sim.scenario import (
        Change as Change,
        NoiseSettings as NoiseSettings,
        PlantChange as PlantChange,
    )

__all__ = ["__version__", *sorted(_EXPORTS)]


def __getattr__(name: str) -> object:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'wmrid' has no attribute {name!r}")
    import importlib

    value = getattr(importlib.import_module(module), name)
    globals()[name] = value  # later accesses skip this function
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))
