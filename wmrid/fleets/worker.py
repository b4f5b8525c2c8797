"""What a fleet's worker runs for each log (:func:`identify_entry`, in batches :func:`identify_batch`): the log read and
identified with its row's options, its table row (estimates, std, flags, first stamp, fit), a failure kept as a row; and
a worker's set-up (:func:`prepare_worker`, :func:`warm_up`)."""

from __future__ import annotations

import contextlib
import datetime as dt
import math
import os
import socket
import time
import warnings
from collections.abc import Generator
from dataclasses import dataclass, field
from typing import Any

import numpy as np

import wmrid
from wmrid.core.errors import WmridError
from wmrid.core.wheel_log import LogStream, WheelLog
from wmrid.fleets.table import PARAMETERS, canonical_options, content_digest, empty_row
from wmrid.runtime.limits import tune_malloc

__all__ = ["identify_batch", "identify_entry", "prepare_worker", "warm_up"]

#: A first stamp at least this far past the Unix epoch (2001-09-09) is taken as the log's start time.
EPOCH_START_S = 1e9


#: The fit column is computed (the log read whole once more) for logs of at most this many samples (80 MB).
FIT_MAX_SAMPLES = 2_000_000


@dataclass
class _Seen:
    """What a log's pieces showed as they went by: its first time stamp (s) and each wheel's sum of |speed|
    (rad/s) over its samples."""

    first: float | None = None
    abs_speed: np.ndarray = field(default_factory=lambda: np.zeros(2))
    samples: int = 0

    def mean_speed(self) -> tuple[float | None, float | None]:
        """(right, left) mean absolute wheel speed, rad/s (None for an empty log)."""
        if not self.samples:
            return None, None
        right, left = (self.abs_speed / self.samples).tolist()
        return right, left


def _watched_stream(stream: LogStream, seen: _Seen) -> LogStream:
    """``stream`` as a new LogStream whose pieces are noted in ``seen`` as they pass."""

    def pieces() -> Generator[WheelLog, None, tuple[str, ...]]:
        for piece in stream:
            if len(piece):
                if seen.first is None:
                    seen.first = float(piece.t[0])
                seen.abs_speed += np.abs(piece.eta).sum(axis=0)
                seen.samples += len(piece)
            yield piece
        return stream.notes

    return LogStream(stream.source, stream.effort_unit, pieces)


def friction_correlations(result: Any) -> tuple[float | None, float | None]:
    """The correlation of each wheel's viscous and Coulomb friction estimates (Fv1 with Fd1, Fv2 with Fd2) in an
    identification's covariance of theta0 = [m11 m12 m22 Vc Fv1 Fv2 Fd1 Fd2 ...]; None where one of them is
    undetermined."""
    est = getattr(result, "estimate", None)
    cov = np.asarray(est.cov if est is not None else result.theta0_cov, dtype=float)
    out = []
    for v, d in ((4, 6), (5, 7)):
        denom = math.sqrt(cov[v, v] * cov[d, d]) if cov[v, v] > 0 and cov[d, d] > 0 else math.nan
        rho = cov[v, d] / denom if math.isfinite(denom) and denom > 0 else math.nan
        out.append(float(np.clip(rho, -1.0, 1.0)) if math.isfinite(rho) else None)
    return out[0], out[1]


def _one_line(err: BaseException) -> str:
    text = " ".join(str(err).split())
    return text if len(text) <= 500 else text[:499] + "…"


def _result_columns(result: Any) -> dict[str, Any]:
    params = result.parameters
    out: dict[str, Any] = {}
    for name in PARAMETERS:
        value, std = params.get(name, (None, None))
        out[name], out[f"{name}_std"] = value, std
    info = result.log_info
    flagged = list(result.diagnostics.flagged or ())
    out.update(
        duration_s=info.duration_s, samples=info.samples, rate_hz=info.rate_hz,
        method=result.method, form=getattr(result.form, "kind", None), effort_unit=info.effort_unit,
        flags=flagged, warnings=[" ".join(w.split()) for w in result.warnings],
    )  # fmt: skip
    out["Fv1_Fd1_corr"], out["Fv2_Fd2_corr"] = friction_correlations(result)
    for name, (value, std) in (
        result.payload.items() if result.payload is not None else ()
    ):  # --payload: mass, x, y, inertia
        out[f"payload_{name}"], out[f"payload_{name}_std"] = value, std
    return out


def identify_entry(spec: dict[str, Any]) -> dict[str, Any]:
    """Identify one log of the fleet and return its table row (never raises for a bad log: the row's ``error``
    says what went wrong).  The Dask task; importable, so that it travels to the workers by name.

    spec : {"log", "robot_id", "robot", "time" (aware datetime or None), "time_source", "options" (identify's
        keywords and LogOptions fields), "options_key", "fit" (bool), "known_sha256" (a resumed row's hash or
        None)}.  When the log's content hash equals ``known_sha256`` the log is not identified and
        {"skipped": True, "sha256": ...} is returned.
    """
    start = time.perf_counter()
    row = empty_row(
        robot_id=spec["robot_id"], log=spec["log"], robot=spec.get("robot"), start_time=spec.get("time"),
        time_source=spec.get("time_source"), options=canonical_options(spec["options"]),
        options_key=spec["options_key"], worker=f"{socket.gethostname()}:{os.getpid()}",
        wmrid_version=wmrid.__version__,
    )  # fmt: skip
    try:
        sha, size = content_digest(spec["log"])
    except OSError as err:
        row["error"] = f"{spec['log']}: cannot be read ({err.strerror or _one_line(err)})"
        row["run_time_s"] = time.perf_counter() - start
        return row
    if spec.get("known_sha256") == sha:
        return {"skipped": True, "sha256": sha}
    row.update(sha256=sha, bytes=size)
    try:
        result, seen, robot, log = _identify(spec)
        row.update(_result_columns(result))
        row["speed_r"], row["speed_l"] = seen.mean_speed()
        first = seen.first
        if spec.get("fit", True):
            row.update(_fit(result, log, robot))
        if row["start_time"] is None and first is not None and first >= EPOCH_START_S:
            row["start_time"] = dt.datetime.fromtimestamp(first, tz=dt.timezone.utc)
            row["time_source"] = "log"
    except WmridError as err:
        row["error"] = _one_line(err)
    except MemoryError:
        row["error"] = f"{spec['log']}: out of memory on the worker"
    except Exception as err:  # a bug must not end a fleet run: the row says it, with the type
        row["error"] = f"internal error: {type(err).__name__}: {_one_line(err)}"
    row["run_time_s"] = time.perf_counter() - start
    return row


_worker_prepared = False


_malloc_tuned = False


def prepare_worker() -> bool:
    """Set this process up as one fleet worker among one per core (once): each identify on one thread
    (:func:`wmrid.estimators.observer.replay.one_thread`), and malloc tuned (:func:`wmrid.runtime.limits.tune_malloc`,
    over the MALLOC_TRIM_THRESHOLD_ Dask's nanny sets: +70 % on a 60 s log without it).  Returns whether malloc was
    tuned."""
    global _worker_prepared, _malloc_tuned
    if not _worker_prepared:
        from wmrid.core.jit import PerformanceWarning  # numba with it (~0.3 s): only a worker's set-up
        from wmrid.estimators.observer.replay import one_thread  # the observer's kernels: not wmrid.fleets.run

        warnings.filterwarnings("ignore", category=PerformanceWarning)  # `wmrid fleet` says it once, not per log

        one_thread()
        _worker_prepared = True
        _malloc_tuned = tune_malloc(override_environment=True)
    return _malloc_tuned


def identify_batch(specs: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """:func:`identify_entry` of several logs in turn: one Dask task for ``batch`` logs, which divides the
    scheduler's work per log by ``batch``.  The worker's malloc is tuned first (:func:`prepare_worker`)."""
    prepare_worker()
    return [identify_entry(spec) for spec in specs]


def _split_options(options: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    # api.inputs: only on a worker (wmrid.fleets.run, which imports this, stays lazy)
    from wmrid.api.inputs import LOG_OPTION_NAMES

    log_opts = {k: v for k, v in options.items() if k in LOG_OPTION_NAMES}
    run_opts = {k: v for k, v in options.items() if k not in LOG_OPTION_NAMES}
    return log_opts, run_opts


def _identify(spec: dict[str, Any]) -> tuple[Any, _Seen, Any, Any]:
    """(result, what its pieces showed (first stamp, wheel speeds), the prepared robot, the log as read: a stream or
    a whole log)."""
    # the identification (numba, ~0.3 s): only on a worker, not in wmrid.fleets.run
    from wmrid.api.identification import prepare, run_prepared, settings_from
    from wmrid.api.inputs import LogOptions, open_log  # api.inputs: only on a worker (wmrid.fleets.run stays lazy)

    log_opts, run_opts = _split_options(spec["options"])
    options = LogOptions(**log_opts)
    rotor_inertia = run_opts.pop("rotor_inertia", None)
    method, observer, fit = settings_from(run_opts)
    prep = prepare(method, observer, fit, options=options, robot=spec.get("robot"), rotor_inertia=rotor_inertia)
    seen = _Seen()
    stream = _watched_stream(open_log(spec["log"], options, robot=prep.robot), seen)
    wheel_log = stream if prep.method == "observer" else stream.read()
    result = run_prepared(wheel_log, prep)
    return result, seen, prep.robot, wheel_log


def _fit(result: Any, log: Any, robot: Any) -> dict[str, Any]:
    """fit_r, fit_l: % fit of the identified model's simulated wheel speeds on the log it was identified from (None
    above :data:`FIT_MAX_SAMPLES` samples, or where the predictor cannot run the model).  A stream of that size
    kept its pieces from the identification: the file is not read again."""
    # the identification (numba, ~0.3 s): only on a worker, not in wmrid.fleets.run
    from wmrid.api.identification import validate

    samples = result.log_info.samples or 0
    if samples > FIT_MAX_SAMPLES:
        return {}
    try:
        whole = log.read() if hasattr(log, "read") else log
        checked = validate(result, whole, robot=robot)
    except Exception:  # the fit is an extra: its failure never discards the identification
        return {}
    assert checked.validation is not None  # validate always records one
    fit = checked.validation.fit_percent
    return {"fit_r": fit["eta_r"], "fit_l": fit["eta_l"]}


def warm_up() -> float:
    """Load wmrid's compiled kernels in this process (numba's cache: about a second once per process), so that a
    worker's first log does not pay for it; returns the seconds it took.  Run on every worker at the start."""
    from wmrid.api.identification import identify  # the identification (numba, ~0.3 s): warm_up loads it on a worker
    from wmrid.core.jit import COMPILED  # numba with it (~0.3 s): warm_up loads it on a worker
    from wmrid.model.predict import validation_fit  # the predictor's numba kernel: warm_up loads it on a worker

    start = time.perf_counter()
    prepare_worker()
    if not COMPILED:  # no kernels to load: a warm-up identify would only cost a second of plain Python
        return time.perf_counter() - start
    t = np.arange(2001) * 1e-3
    eta = np.column_stack([2 + np.sin(3 * t), 2 + np.cos(2 * t)])
    tau = np.column_stack([np.cos(3 * t), -np.sin(2 * t)]) + 0.1
    with contextlib.suppress(WmridError):
        result = identify(WheelLog(t=t, eta=eta, tau=tau, source="warm-up"), "paper")
        assert result.estimate is not None  # identify's result always carries its estimate
        validation_fit(t, eta, tau, result.estimate.theta0)
    return time.perf_counter() - start
