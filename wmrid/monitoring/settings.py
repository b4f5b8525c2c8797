"""The monitor's settings and the model it monitors against: :class:`MonitorSettings`, and :class:`MonitoredModel` read
from an ``identify`` JSON result (:func:`model_from_dict`, :func:`load_model`)."""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from wmrid.core.errors import LogFormatError, UsageError, cannot_read, option
from wmrid.estimators.parameter import Parameter
from wmrid.estimators.result import from_dict
from wmrid.model import dynamics as model
from wmrid.model.dynamics import THETA0_NAMES, RegressorForm
from wmrid.runtime.atomic import register_input
from wmrid.runtime.limits import memory_budget, read_limited

#: Names of the columns of the inverse-dynamics regressor Phi (the parameters p it multiplies).
REGRESSOR_NAMES = ("M11", "M12", "M22", "Vc", "Fv1", "Fv2", "Fd1", "Fd2")


#: Degrees of freedom of the test without caster drag: the number of regressor columns (a ``wheel+caster`` model
#: adds its drag parameters: len(p)).
DOF = len(REGRESSOR_NAMES)


#: Shortest span after a change that is identified at all, s (shorter: the change is reported without
#: parameters).
MIN_IDENTIFY_S = 3.0


#: The model's error is taken as normal with this many times its reported standard errors (they leave out the
#: closed-loop bias, and a given model's correlations are not in its JSON).
PRIOR_STD_FACTOR = 2.0


#: Equations per coefficient of each noise-model equation (2 q of them) at least.
MIN_ROWS_PER_COEFFICIENT = 5


#: A time step longer than this many median steps is a hole the monitor refuses.
HOLE_FACTOR = 10.0


#: The false-alarm rate measured at the default settings by bench/accuracy/bench_monitor.py (reported with every
#: result).
MEASURED = {
    "logs": "300 unchanged noisy closed-loop simulated logs of 120 s (paper robot on the sinusoid at 1 kHz; noise "
    "0.01 rad/s, 0.02 N m, caster 0.05 N m with 0.3 s correlation), each against a model identified on another log",
    "hours": 9.17,
    "false_alarms": 0,
    "per_hour_at_stated": {"10": 1.2, "1": 0.0, "0.3": 0.0, "0.1": 0.0},
    "by": "bench/accuracy/bench_monitor.py",
}


#: Rows of the Savitzky-Golay evaluation done at once (bounds the memory of long logs).
CHUNK = 4096


#: The settings that are options of ``wmrid monitor`` (--calibration, --false-alarm-rate), named as such in messages.
_OPTIONS = ("calibration_s", "false_alarm_rate")


@dataclass(frozen=True)
class MonitorSettings:
    """The change detector's settings (``wmrid monitor``), checked when made.

    :mod:`wmrid.monitoring.monitor` explains each one's role.

    Attributes
    ----------
    calibration_s
        s, span at the start of the log (and after each change) assumed unchanged, on which the noise model (and,
        after a change, the model) is first fitted.
    false_alarm_rate
        Stated false alarms per hour of log (> 0): the Bonferroni bound the threshold keeps.
    windows_s
        s, lengths of the test windows.
    steps_per_window
        Each window is tested every 1/steps_per_window of its length.
    rate_hz
        Hz, rate of the residual (the log's rate when lower).
    accel_window_s
        s, the Savitzky-Golay window of the residual.
    regressor_window_s
        s, the Savitzky-Golay window of the regressor.
    noise_memory_s
        s, span of the lags of the noise model's autoregression.
    locate_s
        s, data past an alarm used to locate the change.
    margin
        Factor on the threshold for what the F law leaves out (chosen in bench/accuracy/bench_monitor.py).
    """

    calibration_s: float = 10.0
    false_alarm_rate: float = 0.1
    windows_s: tuple[float, ...] = (0.5, 1.0, 2.0, 4.0, 8.0, 16.0)
    steps_per_window: int = 4
    rate_hz: float = 50.0
    accel_window_s: float = 0.1
    regressor_window_s: float = 0.5
    noise_memory_s: float = 0.3
    locate_s: float = 1.0
    margin: float = 1.1

    def __post_init__(self) -> None:
        for name in ("calibration_s", "false_alarm_rate", "rate_hz", "accel_window_s", "regressor_window_s",
                     "noise_memory_s", "margin"):  # fmt: skip
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
                label = option(name) if name in _OPTIONS else f"monitor setting {name}"
                raise UsageError(f"{label} must be a finite number > 0, got {value!r}")
        if (
            isinstance(self.locate_s, bool)
            or not isinstance(self.locate_s, (int, float))
            or not (math.isfinite(self.locate_s) and self.locate_s >= 0)
        ):
            raise UsageError(f"monitor setting locate_s must be a finite number >= 0, got {self.locate_s!r}")
        if not self.windows_s or any(not (math.isfinite(w) and w > 0) for w in self.windows_s):
            raise UsageError(f"monitor windows must be finite lengths > 0 s, got {self.windows_s!r}")
        if (
            isinstance(self.steps_per_window, bool)
            or not isinstance(self.steps_per_window, int)
            or (self.steps_per_window < 1)
        ):
            raise UsageError(f"monitor steps_per_window must be a whole number >= 1, got {self.steps_per_window!r}")

    def to_dict(self) -> dict[str, Any]:
        return {
            "calibration_s": self.calibration_s, "windows_s": list(self.windows_s),
            "steps_per_window": self.steps_per_window, "rate_hz": self.rate_hz, "accel_window_s": self.accel_window_s,
            "regressor_window_s": self.regressor_window_s, "noise_memory_s": self.noise_memory_s,
            "locate_s": self.locate_s, "margin": self.margin,
        }  # fmt: skip


@dataclass(frozen=True)
class MonitoredModel:
    """Base parameters theta0 (n,) [m11 m12 m22 Vc Fv1 Fv2 Fd1 Fd2, then the caster drag's] with their reported
    form, effort unit; ``form``: the regressor form of a ``wheel+caster`` model (its caster columns), None for
    wheel friction (n = 8).  ``parameters``: the result's reported parameters, name -> :class:`Parameter` (value and
    std in ``unit``, std inf when not determined; flags), in the result's order."""

    theta0: np.ndarray
    parameters: dict[str, Parameter]
    effort_unit: str
    source: str
    std: np.ndarray  # standard errors of p = [M11 M12 M22 Vc Fv1 Fv2 Fd1 Fd2, drag] (undetermined: 10 x the value)
    form: RegressorForm | None = None
    #: what the saved result says against its own use (its verdict or flags), a warning of every monitor run
    doubt: str | None = None

    @property
    def friction(self) -> str:
        """The model's friction model ("wheel" without a caster form): the one its re-identifications use."""
        return "wheel" if self.form is None else self.form.friction


def caster_form(form: RegressorForm | None) -> RegressorForm | None:
    """``form`` when it models caster drag, else None (the eight wheel columns)."""
    return form if form is not None and form.caster else None


def p_names(form: RegressorForm | None) -> tuple[str, ...]:
    """Names of p: REGRESSOR_NAMES, then the caster drag's parameters of ``form`` (identical in theta0 and p)."""
    return REGRESSOR_NAMES if form is None else REGRESSOR_NAMES + form.base_names[8:]


def _std_vector(
    values: dict[str, float], stds: dict[str, float | None], names: tuple[str, ...] = REGRESSOR_NAMES
) -> np.ndarray:
    """Standard errors of p = [M11 M12 M22 Vc Fv1 Fv2 Fd1 Fd2] (``names``: then the caster drag's); an undetermined
    one (null or infinite std) counts as ten times its value (1 when 0): the test gives that direction no weight."""
    out = []
    for name in names:
        std = stds.get(name)
        ok = isinstance(std, (int, float)) and not isinstance(std, bool) and math.isfinite(std) and std >= 0
        floor = 1e-9 * max(abs(values[name]), 1e-12)  # a std of 0 would make the prior singular
        out.append(max(float(std), floor) if ok else 10.0 * (abs(values[name]) or 0.1))
    return np.array(out)


def inertia_ok(theta0: np.ndarray) -> bool:
    m11, m12, m22 = theta0[:3]
    return bool(m11 > 0 and m22 > 0 and m11 * m22 - m12 * m12 > 0)


def model_from_dict(data: Any, source: str) -> MonitoredModel:
    """The model of an ``identify`` JSON result (its "parameters" and "effort_unit"); UsageError naming
    ``source`` when it is not one.

    A saved result (with "settings" and a "theta.form") is also read through
    :func:`wmrid.estimators.result.from_dict`, after the checks here, so that what identify wrote is checked
    as ``report`` checks it; a shorter document (one from before the form was recorded, or a model written by
    hand: "parameters", "effort_unit" and optionally "theta.form") is read for what the monitor needs.
    """
    hint = "give the JSON that `wmrid identify LOG -o RESULT.json` writes"
    if not isinstance(data, dict) or not isinstance(data.get("parameters"), dict):
        raise UsageError(f'{option("model")} {source}: not a wmrid identify result (no "parameters" object); {hint}')
    params = data["parameters"]
    form_d = data.get("theta", {}).get("form", {}) if isinstance(data.get("theta"), dict) else {}
    form = _form_of(form_d, source, hint)
    names = THETA0_NAMES if form is None else form.base_names
    values = []
    for name in names:
        entry = params.get(name)
        value = entry.get("value") if isinstance(entry, dict) else None
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
            raise UsageError(
                f'{option("model")} {source}: not a wmrid identify result (parameter {name} has no finite "value"); '
                f"{hint}"
            )
        values.append(float(value))
    unit = data.get("effort_unit", "N m")
    if not isinstance(unit, str):
        raise UsageError(f'{option("model")} {source}: "effort_unit" must be a string, got {unit!r}')
    theta0 = np.array(values)
    if not inertia_ok(theta0):
        raise UsageError(
            f"{option('model')} {source}: its inverse inertia [m11 m12; m12 m22] is not positive definite, so it is no "
            "robot's model; identify the robot again"
        )
    reported = _reported(params, unit, source)
    columns = p_names(form)
    by_name = model.named_base(theta0, names)
    stds = {name: reported[name].std if name in reported else None for name in columns}
    theta_d = data.get("theta")
    if isinstance(theta_d, dict) and "form" in theta_d and "settings" in data:  # a saved result: as report checks
        try:
            from_dict(data, source)
        except LogFormatError as err:
            raise UsageError(f"{option('model')} {err}") from None
    return MonitoredModel(theta0=theta0, parameters=reported, effort_unit=unit, source=source,
                          std=_std_vector(by_name, stds, columns), form=form, doubt=_doubt(data, source))  # fmt: skip


def _number(value: Any, missing: float) -> float:
    """``value`` as a float; ``missing`` when it is null or not a number (a model written by hand)."""
    ok = isinstance(value, (int, float)) and not isinstance(value, bool)
    return float(value) if ok else missing


def _reported(params: dict[str, Any], effort_unit: str, source: str) -> dict[str, Parameter]:
    """The result's "parameters" entries as :class:`Parameter` (as :meth:`Parameter.from_dict` reads them); what a
    model written by hand leaves out is filled in: the std as not determined, the unit its name has, no flags."""
    units = model.base_units(effort_unit)
    out = {}
    for name, entry in params.items():
        if not isinstance(entry, dict):
            continue
        try:
            out[name] = Parameter(
                name, _number(entry.get("value"), math.nan), _number(entry.get("std"), math.inf),
                entry["unit"] if isinstance(entry.get("unit"), str) else units.get(name, ""),
                tuple(entry.get("flags") or ()),
            )  # fmt: skip
        except ValueError as err:  # an unknown flag
            raise UsageError(f"{option('model')} {source}: {err}") from None
    return out


def _doubt(data: dict[str, Any], source: str) -> str | None:
    """What the saved result itself says against being used as a model (its verdict: the numbers are not to be
    used; its flags: stds not to be trusted), as one warning for the monitor, or None."""
    verdict = data.get("verdict") if isinstance(data.get("verdict"), dict) else {}
    summary = verdict.get("summary") if isinstance(verdict.get("summary"), str) else ""
    if summary.startswith("Do not use"):
        return f"the model {source} says of itself: {summary} Changes judged against it mean little"
    diagnostics = data.get("diagnostics") if isinstance(data.get("diagnostics"), dict) else {}
    flagged = [n for n in diagnostics.get("flagged") or [] if isinstance(n, str)]
    if flagged:
        return (
            f"the model {source} flags {', '.join(flagged)}: their std is not to be trusted, so the test's tolerance "
            "for them is a guess"
        )
    return None


def _form_of(form_d: Any, source: str, hint: str) -> RegressorForm | None:
    """The caster model of a result's ``theta.form`` (:meth:`wmrid.model.dynamics.RegressorForm.from_dict`), None for
    wheel friction (or no form recorded)."""
    if not isinstance(form_d, dict) or form_d.get("friction") != "wheel+caster":
        return None
    try:
        form = RegressorForm.from_dict(form_d)
    except (KeyError, TypeError, ValueError, IndexError) as err:
        raise UsageError(
            f"{option('model')} {source}: its caster-drag form (theta.form) is malformed ({err.__class__.__name__}: "
            f"{err}); "
            f"{hint}"
        ) from None
    return caster_form(form)


def load_model(path: str | Path) -> MonitoredModel:
    """The model in an ``identify`` JSON result file; UsageError (one line, naming the file) otherwise."""
    register_input(path)
    try:
        text = read_limited(
            path, memory_budget(), f"--model {path}: holds more than {{size}} (WMRID_MEMORY_BUDGET); is it a result?",
            UsageError,
        ).decode("utf-8")  # fmt: skip
    except OSError as err:
        raise UsageError(f"{option('model')} {path}: {cannot_read(err)}") from None
    except UnicodeDecodeError as err:
        raise UsageError(f"{option('model')} {path}: not an identify result (byte {err.start} is not UTF-8)") from None
    try:
        data = json.loads(text)
    except RecursionError:
        raise UsageError(f"{option('model')} {path}: nested too deeply to be an identify result") from None
    except ValueError as err:
        raise UsageError(f"{option('model')} {path}: not a wmrid identify result (not JSON: {err})") from None
    return model_from_dict(data, str(path))


def physical_vector(theta0: np.ndarray) -> np.ndarray:
    """p = [M11, M12, M22, Vc, Fv1, Fv2, Fd1, Fd2, then theta0's caster drag parameters unchanged]: what the
    regressor Phi multiplies (:func:`wmrid.model.dynamics.invert_inertia_entries`)."""
    return model.invert_inertia_entries(theta0)


def named(theta0: np.ndarray, form: RegressorForm | None) -> dict[str, float]:
    """theta0 and M by name (:func:`wmrid.model.dynamics.named_base`), the caster drag's named by ``form``."""
    return model.named_base(theta0) if form is None else model.named_base(theta0, form.base_names)
