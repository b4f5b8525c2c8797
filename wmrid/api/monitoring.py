"""Change detection as one call: :func:`monitor` replays a log against an identified model (``wmrid monitor``).

Imports inside functions: start-up time (a front door: ``import wmrid`` and each function load only what that
function uses).
"""

from __future__ import annotations

import os
from dataclasses import replace
from typing import Any

import numpy as np

from wmrid.api.inputs import LogOptions, read_log
from wmrid.core.errors import UsageError, option
from wmrid.core.wheel_log import LogStream, WheelLog
from wmrid.estimators.options import ObserverOptions
from wmrid.estimators.result import IdentificationResult
from wmrid.monitoring.monitor import monitor as run_monitor
from wmrid.monitoring.monitor_result import MonitorResult
from wmrid.monitoring.settings import MonitoredModel, MonitorSettings, load_model, model_from_dict

__all__ = ["monitor"]


def monitored_model(
    model: str | os.PathLike[str] | IdentificationResult | dict[str, Any] | MonitoredModel,
) -> MonitoredModel:
    """The model to monitor against: a saved ``identify`` result (path or its JSON as a dict), a result, or a
    :class:`MonitoredModel`."""
    if isinstance(model, MonitoredModel):
        return model
    if isinstance(model, IdentificationResult):
        return model_from_dict(model.to_dict(), model.source)
    if isinstance(model, dict):
        return model_from_dict(model, str(model.get("source", "model")))
    return load_model(os.fspath(model))


def monitor(
    log: str | os.PathLike[str] | WheelLog | LogStream,
    model: str | os.PathLike[str] | IdentificationResult | dict[str, Any] | MonitoredModel,
    *,
    options: LogOptions | None = None,
    calibration: float = 10.0,
    false_alarm_rate: float = 0.1,
    settings: MonitorSettings | None = None,
    observer: ObserverOptions | None = None,
) -> MonitorResult:
    """Replay ``log`` against ``model`` and report when the dynamics change, and the parameters after each change.

    Parameters
    ----------
    log
        The log: a path, read with ``options``, or a log already read.
    model
        The identified model to monitor against: a saved ``identify`` result (its path, or its JSON as a dict), an
        :class:`IdentificationResult`, or a :class:`~wmrid.monitoring.settings.MonitoredModel`.
    options
        How to read ``log`` when it is a path (:class:`~wmrid.api.inputs.LogOptions`).
    calibration
        s at the start of the log (and after each change) assumed unchanged, to calibrate the test.
    false_alarm_rate
        False alarms per hour the test's threshold allows.
    settings
        All the detector's settings (:class:`MonitorSettings`); when given, they override ``calibration`` and
        ``false_alarm_rate``.
    observer
        The observer's settings for the identifications after a change (as :func:`identify`'s).  Its friction model
        is the model's (``auto`` or that one); a ``delay`` shifts the efforts of the whole log before the test
        ("auto": estimated on the calibration span, which is assumed unchanged; recorded in the JSON's
        ``log.delay``); ``payload`` is refused: a change is identified without a robot file.

    Returns
    -------
    MonitorResult
        The changes found, with the parameters identified after each; ``to_dict`` gives the JSON form.

    Raises
    ------
    UsageError
        ``observer`` asks for a payload, or for a friction model other than the model's.
    """
    settings = settings or MonitorSettings(calibration_s=calibration, false_alarm_rate=false_alarm_rate)
    model_obj = monitored_model(model)
    if observer is not None:
        _check_observer(observer, model_obj)
    if isinstance(log, (str, os.PathLike)):
        log = read_log(log, options)
    elif isinstance(log, LogStream):
        log = log.read()
    delay = None
    if observer is not None and observer.delay is not None:
        log, delay = _delayed(log, observer, settings.calibration_s)
    result = run_monitor(log, model_obj, settings, observer)
    if delay is not None:  # recorded with the log; what the estimate said is a warning of the run
        record, said = delay
        result = replace(result, log_info=replace(result.log_info, delay=record), warnings=[*said, *result.warnings])
    return result


def _check_observer(observer: ObserverOptions, model: MonitoredModel) -> None:
    """Refuse what the monitor cannot honour: a payload (no robot file) and a friction model not the model's."""
    if observer.payload:
        raise UsageError(
            f"{option('payload')} is not available in wmrid monitor: the segments after a change are identified "
            "without a robot file; identify one segment with wmrid identify --payload --robot ROBOT"
        )
    friction = model.friction
    if observer.friction not in ("auto", friction):
        raise UsageError(
            f"{option('friction')} {observer.friction}: the monitor identifies with the model's friction model "
            f"({friction}); identify the model with {option('friction')} {observer.friction} to monitor with it"
        )


def _delayed(
    log: WheelLog, observer: ObserverOptions, calibration_s: float
) -> tuple[WheelLog, tuple[dict[str, Any], list[str]]]:
    """``log`` with its efforts read ``observer.delay`` s earlier ("auto": the delay estimated on the first
    ``calibration_s`` s), and (the record of what was applied, the estimate's warnings)."""
    from wmrid.estimators.timing_check import apply_delay

    delay = observer.delay
    record: dict[str, Any] = {}
    warnings: list[str] = []
    if delay == "auto":
        t = np.asarray(log.t, dtype=np.float64)
        n = int(np.searchsorted(t, t[0] + calibration_s, side="right"))
        reference = None if log.reference is None else log.reference[:n]
        span = WheelLog(t=t[:n], eta=np.asarray(log.eta)[:n], tau=np.asarray(log.tau)[:n], source=log.source,
                        effort_unit=log.effort_unit, reference=reference)  # fmt: skip
        _, estimated, warnings = apply_delay(span, "auto", observer.torque_hold, observer.control_rate)
        record = {**estimated.to_dict(), "estimated_on_s": calibration_s}
        delay = record["applied_s"]
    if not isinstance(delay, (int, float)):  # given seconds, or the estimate's applied_s
        raise TypeError(f"delay {delay!r}")
    shifted, applied, _ = apply_delay(log, float(delay), observer.torque_hold, observer.control_rate)
    return shifted, ({**applied.to_dict(), **record}, warnings)
