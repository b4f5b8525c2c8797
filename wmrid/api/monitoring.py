"""Change detection as one call: :func:`monitor` replays a log against an identified model (``wmrid monitor``)."""

from __future__ import annotations

import os
from typing import Any

from wmrid.api.inputs import LogOptions, read_log
from wmrid.core.wheel_log import LogStream, WheelLog
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
) -> MonitorResult:
    """Replay ``log`` against ``model`` and report when the dynamics change, and the parameters after each change.

    calibration : s at the start of the log (and after each change) assumed unchanged, to calibrate the test.
    false_alarm_rate : false alarms per hour the test's threshold allows.  ``settings`` (all of them) overrides both.
    """
    settings = settings or MonitorSettings(calibration_s=calibration, false_alarm_rate=false_alarm_rate)
    model_obj = monitored_model(model)
    if isinstance(log, (str, os.PathLike)):
        log = read_log(log, options)
    elif isinstance(log, LogStream):
        log = log.read()
    return run_monitor(log, model_obj, settings)
