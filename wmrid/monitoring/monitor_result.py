"""What ``wmrid monitor`` found (:class:`MonitorResult`): the changes of the robot's dynamics along a log
(:class:`Change`: when, which parameters moved and by how much, for a payload its mass), JSON-ready."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from wmrid.estimators.parameter import Parameter
from wmrid.estimators.records import LogInfo
from wmrid.monitoring.glr import WindowGrid
from wmrid.monitoring.residuals import tidy
from wmrid.monitoring.settings import (
    DOF,
    MEASURED,
    MonitoredModel,
    MonitorSettings,
    caster_form,
    p_names,
)


@dataclass
class Change:
    """One detected change: times in s from the log's start (``t`` the located change, ``t_alarm`` the end of the
    alarming window, ``window_s`` its length); ``statistic`` the window's test statistic over ``threshold``.
    ``parameters``: name -> :class:`Parameter` identified on ``segment`` (t_start, t_end) s after the change, as
    ``identify`` reports them (None: not identified; ``warnings`` says why); ``relative_change``: name ->
    (after - before) / |before| against the model or the previous segment; ``theta0``: (n,) the base parameters
    identified after it."""

    t: float
    t_alarm: float
    statistic: float
    threshold: float
    window_s: float
    parameters: dict[str, Parameter] | None = None
    segment: tuple[float, float] | None = None
    warnings: list[str] = field(default_factory=list)
    relative_change: dict[str, float | None] | None = None
    theta0: np.ndarray | None = None

    def to_dict(self) -> dict[str, Any]:
        return {
            "t": self.t,
            "t_alarm": self.t_alarm,
            "delay_s": self.t_alarm - self.t,
            "statistic": self.statistic,
            "threshold": self.threshold,
            "window_s": tidy(self.window_s),
            "parameters": None if self.parameters is None else {n: p.to_dict() for n, p in self.parameters.items()},
            "relative_change": self.relative_change,
            "identified_on": None if self.segment is None else {"t_start": self.segment[0], "t_end": self.segment[1]},
            "warnings": list(self.warnings),
        }


@dataclass
class MonitorResult:
    """What :func:`wmrid.monitor` found; ``to_dict`` gives the JSON form.

    Attributes
    ----------
    source
        The log.
    model
        The model monitored against (:class:`~wmrid.monitoring.settings.MonitoredModel`).
    settings
        The detector's settings (:class:`MonitorSettings`).
    grid
        The tests: windows and steps, per-test false-alarm probability, margin
        (:class:`~wmrid.monitoring.glr.WindowGrid`).
    noise_lags
        Lags of the noise model's autoregression.
    calibration_samples
        Samples of the first calibration span.
    changes
        The changes detected, in time order (:class:`wmrid.monitoring.monitor_result.Change`: when, which
        parameters moved and by how much).
    segments
        Each segment between changes as the JSON records it (t_start, t_end, its model, its calibrations).
    log_info
        What the log was (:class:`~wmrid.estimators.records.LogInfo`).
    warnings
        Said to the user.
    seconds
        s, the run's wall time.
    identification
        The observer's settings of the identifications after a change (form, k, alpha, box_width, torque_hold,
        control_rate), as the JSON's "identification".
    """

    source: str
    model: MonitoredModel
    settings: MonitorSettings
    grid: WindowGrid
    noise_lags: int
    calibration_samples: int
    changes: list[Change]
    segments: list[dict[str, Any]]
    log_info: LogInfo
    warnings: list[str]
    seconds: float
    #: the observer's settings of the identifications after a change (form, k, alpha, box_width, torque_hold,
    #: control_rate), as the JSON's "identification"
    identification: dict[str, Any] | None = None

    @property
    def thresholds(self) -> tuple[float, float]:
        """The GLR statistic's threshold after the first calibration span, and its limit as the calibration grows."""
        dim = len(p_names(caster_form(self.model.form)))
        first_dof = (self.calibration_samples - self.noise_lags) / self.noise_lags
        return self.grid.threshold(first_dof, dim), self.grid.threshold(math.inf, dim)

    def detector_dict(self) -> dict[str, Any]:
        g, st, order = self.grid, self.settings, self.noise_lags
        first, limit = self.thresholds
        form = caster_form(self.model.form)
        names, dim = p_names(form), len(p_names(form))
        drag = "" if form is None else f" + the caster drag of {form.friction} ({', '.join(names[DOF:])})"
        return {
            "method": "windowed generalised likelihood ratio (GLR) test on whitened torque residuals",
            "residual": f"r = tau - M eta_dot - V(eta) - F_v eta - F_d sgn(eta){drag} of the model, every signal "
            f"smoothed by a Savitzky-Golay cubic over {st.accel_window_s:g} s (eta_dot its derivative), at "
            f"{tidy(g.rate):g} Hz",
            "statistic": "S = c' (G + G P G)^-1 c over a window, c = b - G dp0, G = sum X'X, b = sum X'z, z the "
            f"whitened residual, X the whitened regressor Phi (columns {', '.join(names)}, smoothed over "
            f"{st.regressor_window_s:g} s), dp0 and P the mean and covariance of the model's own error (from its "
            "standard errors x 2, updated on the calibration span); with P = 0 the explained sum of squares of a "
            f"least-squares fit of z on X: chi-square with {dim} degrees of freedom when nothing changed",
            "settings": {**st.to_dict(), **g.to_dict(), "noise_lags": order},
            "threshold": {
                "first_calibration": first,
                "limit": limit,
                "rule": f"margin x {dim} x the F({dim}, dof) quantile at p_per_test, dof = the noise model's degrees "
                "of freedom (samples / lags); it falls from 'first_calibration' towards 'limit' as the calibration "
                "grows (each segment's thresholds are in segments[].calibrations)",
            },
            "dof": dim,
            "false_alarm_rate_per_hour": st.false_alarm_rate,
            "measured": MEASURED,
            "calibration": (
                f"noise model: a vector autoregression with {order} lags, fitted on the first {st.calibration_s:g} s "
                "of the log (assumed unchanged) and refitted on all the log seen so far each time that doubles; after "
                "a change the same on the new segment, whose model is identified again on the same span (its noise "
                "model from residuals of models identified on the other half, cross-fitted); threshold: Bonferroni "
                "bound over all tests (p_per_test = false_alarm_rate_per_hour / tests_per_hour) on the F law of S, "
                f"times margin {st.margin:g}; the false alarms per hour measured on many seeds of unchanged noisy "
                "closed-loop simulated logs are printed by bench/accuracy/bench_monitor.py"
            ),
            "not_tested": "the first calibration_s of the log and of each segment after a change (assumed unchanged); "
            "two changes closer than calibration_s are not told apart",
        }

    def to_dict(self) -> dict[str, Any]:
        return {
            "source": self.source,
            "model": {
                "source": self.model.source,
                "effort_unit": self.model.effort_unit,
                "parameters": {name: p.to_dict() for name, p in self.model.parameters.items()},
                **({} if self.model.form is None else {"form": self.model.form.to_dict()}),
            },
            "changes": [c.to_dict() for c in self.changes],
            "detector": self.detector_dict(),
            "segments": self.segments,
            **({} if self.identification is None else {"identification": self.identification}),
            "log": self.log_info.to_dict(),
            "warnings": list(self.warnings),
            "seconds": self.seconds,
        }
