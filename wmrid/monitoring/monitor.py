"""``wmrid monitor``: replay a log against an identified model and report when the dynamics change.

The paper motivates identification with fault detection and unknown payloads; this is that use.  Given
base parameters identified earlier (``wmrid identify LOG0 -o RESULT.json``) and a new log, find the times
at which the robot stopped obeying the model (a payload loaded or dropped, a wheel whose friction rose),
with a test whose false-alarm rate is stated, and identify the robot again after each change.

Residual.  Every signal the inverse model needs is smoothed by a zero-phase Savitzky-Golay cubic over
``accel_window_s`` = 0.1 s (the wheel accelerations are its derivative, never a raw difference of noise;
see :mod:`wmrid.reporting.report`), and the torque residual of the model is taken at ``rate_hz`` = 50 Hz::

    r = tau - M eta_dot - V(eta) - F_v eta - F_d sgn(eta) = tau - Phi(eta, eta_dot) p,
    p = [M11, M12, M22, Vc, Fv1, Fv2, Fd1, Fd2]                                     (2 rows, 8 columns)

A change of the dynamics by dp adds Phi dp to r: a change has the regressor's structure.  The regressor
the test uses is smoothed over ``regressor_window_s`` = 0.5 s: its accelerations carry the derivative
noise of the speeds, which the residual carries too (times M), and with the residual's smoothing the two
would correlate and inflate the statistic (errors in variables; measured: a mean of about 100 instead
of 8 on unchanged logs).

Noise model.  The residual's noise is coloured (the smoothing, a caster disturbance lasting tenths of a
second, the closed loop), so a vector autoregression with q = ``noise_memory_s`` x rate lags (0.3 s: 15)
is fitted by least squares on the CALIBRATION SPAN, the first ``calibration_s`` = 10 s of the log, which is
ASSUMED UNCHANGED.  Residual and regressor columns pass through its whitening filter,
z_k = L^-1 (r_k - sum_i A_i r_k-i) with L L' the innovation covariance, so that without a change z is
white with unit covariance.  The calibration then grows: each time the tested span doubles (at 20, 40,
80 s ...) the noise model is fitted again on all of the log before that point.

Test.  On a window of whitened data the generalised likelihood ratio for "the parameters changed by an
unknown dp at the window's start" is S = c' (G + G P G)^-1 c, c = b - G dp0, G = sum X'X, b = sum X'z
(X the whitened regressor): an estimated model leaves a residual Phi dp of its own, which grows with the
window and is no change, so its error dp, normal with mean dp0 and covariance P, is part of the null
hypothesis.  For the given model, dp starts as normal(0, (2 x its reported standard errors)^2) (twice:
they leave out the closed-loop bias, and the JSON holds no correlations) and is updated (Bayes) with the
calibration span, which fixes the combinations the log's motion excites; for a model identified after a
change, dp is normal(0, 4 x its full covariance).  With P = 0 and dp0 = 0, S is the explained sum of
squares of a least-squares fit of z on X, chi-square with 8 degrees of freedom when nothing changed.  The
noise power at low frequency is itself estimated, from about dof = samples / lags degrees of freedom (an
autoregression's spectrum at frequency 0 has a relative variance of 4 q / n per wheel, Berk 1974), so
S / 8 is taken as F(8, dof).  Windows of 0.5, 1, 2, 4, 8 and 16 s (short ones see a large change at once,
long ones a small one), each tested every quarter of its length: 58,900 tests per hour of log at 50 Hz.
The threshold h is ``margin`` x 8 x the F(8, dof) quantile at p = ``false_alarm_rate`` / tests per hour:
the Bonferroni bound then keeps the expected number of false alarms per hour of log at most
``false_alarm_rate`` (default 0.1 per hour); h falls as the calibration grows (80 after the first 10 s,
60 after 20 s, towards 46 after minutes).  The law is approximate (the closed loop moves the regressor
with the disturbance; the tail is a little heavier than F in the first doublings), so ``margin`` = 1.1,
chosen by measurement: on 6.4 h of unchanged noisy closed-loop simulated logs, each monitored against a
model identified on another log, margin 1 gave 4.2, 0.78 and 0.31 false alarms per hour at stated rates of
10, 1 and 0.3 per hour, margin 1.1 gave 1.7, 0.16 and 0.  bench/bench_monitor.py measures the defaults
(300 logs, 9.2 h: no false alarm; 1.2 per hour at a stated 10 per hour).

After an alarm.  The change time is the maximum-likelihood one, the start j maximising S(j, k) with k one
second (``locate_s``) past the alarm.  A new segment starts there: its model is identified
(:func:`wmrid.estimators.identify.identify`, without a robot file) on its first ``calibration_s`` (again each time its
span doubles), its noise model is fitted on the same span from cross-fitted residuals (each half's
residual from the model identified on the other half, so that the noise model sees a model's estimation
error and not an in-sample fit), and the test restarts, so that a second change (the payload dropped
again) is found too.  When every change is found, each segment is identified on all of it, from its
change to the next change or the end of the log (time re-based to 0): those are the parameters reported.

Caster drag.  A model identified with ``--friction wheel+caster`` (its JSON ``theta.form``, read by
:meth:`wmrid.model.dynamics.RegressorForm.from_dict`) adds its caster columns to Phi: column j of ``form.caster_map``
adds theta0[param_j] col_j [1, pattern_j] to the wheel torques (:func:`wmrid.model.dynamics.friction_torque`),
smoothed as the other speed columns; p's drag entries are theta0's (as in
:func:`wmrid.estimators.idim.rows_from_features`), with their reported standard errors.  The test then has len(p)
degrees of freedom, S / len(p) ~ F(len(p), dof).  After a change the segment is identified with
``friction="wheel+caster"`` and the model's caster positions (its ``form.geometry``) when it has them, else with the
two-term drag (Cv, Cw) (where the wheels never reverse, with wheel friction only; a warning says so).

Times: ``t`` of a change is s from the log's first sample; ``t_alarm`` is the time of the last log sample
the alarming test used (its window's end plus the smoothing's half-width, 0.25 s), when a monitor
running along the log would have raised the alarm.

Limits (stated, not hidden): changes inside a calibration span are not tested for (the first
``calibration_s`` of the log, and of each segment after a change), and two changes closer than that are not
told apart; the log must be evenly sampled (uneven logs are resampled linearly on their median step,
holes are refused); a change that does not show in the torque residual on the log's motion (friction of
a wheel that never turns) cannot be seen.
"""

from __future__ import annotations

import json
import math
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from wmrid.core.errors import NotIdentifiableError, UsageError
from wmrid.model import dynamics as model
from wmrid.model.dynamics import THETA0_NAMES, RegressorForm

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


#: The false-alarm rate measured at the default settings by bench/bench_monitor.py (reported with every result).
MEASURED = {
    "logs": "300 unchanged noisy closed-loop simulated logs of 120 s (paper robot on the sinusoid at 1 kHz; noise "
    "0.01 rad/s, 0.02 N m, caster 0.05 N m with 0.3 s correlation), each against a model identified on another log",
    "hours": 9.17,
    "false_alarms": 0,
    "per_hour_at_stated": {"10": 1.2, "1": 0.0, "0.3": 0.0, "0.1": 0.0},
    "by": "bench/bench_monitor.py",
}


#: Rows of the Savitzky-Golay evaluation done at once (bounds the memory of long logs).
_CHUNK = 4096


#: Command-line names of the settings a user sets, for error messages.
_OPTION_NAMES = {"calibration_s": "--calibration", "false_alarm_rate": "--false-alarm-rate"}


@dataclass(frozen=True)
class MonitorSettings:
    """The detector's settings (see the module docstring for each one's role).

    calibration_s : s, span at the start of the log (and after each change) assumed unchanged, on which the
        noise model (and, after a change, the model) is first fitted.
    false_alarm_rate : stated false alarms per hour of log (> 0): the Bonferroni bound the threshold keeps.
    windows_s : s, lengths of the test windows; each is tested every 1/steps_per_window of its length.
    rate_hz : Hz, rate of the residual (the log's rate when lower).
    accel_window_s, regressor_window_s : s, Savitzky-Golay windows of the residual and of the regressor.
    noise_memory_s : s, span of the lags of the noise model's autoregression.
    locate_s : s, data past an alarm used to locate the change.
    margin : factor on the threshold for what the F law leaves out (chosen in bench/bench_monitor.py).
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
                label = _OPTION_NAMES.get(name, f"monitor setting {name}")
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
    wheel friction (n = 8)."""

    theta0: np.ndarray
    parameters: dict[str, dict[str, Any]]
    effort_unit: str
    source: str
    std: np.ndarray  # standard errors of p = [M11 M12 M22 Vc Fv1 Fv2 Fd1 Fd2, drag] (undetermined: 10 x the value)
    form: RegressorForm | None = None


def _caster_form(form: RegressorForm | None) -> RegressorForm | None:
    """``form`` when it models caster drag, else None (the eight wheel columns)."""
    return form if form is not None and form.caster else None


def _p_names(form: RegressorForm | None) -> tuple[str, ...]:
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


def _inertia_ok(theta0: np.ndarray) -> bool:
    m11, m12, m22 = theta0[:3]
    return bool(m11 > 0 and m22 > 0 and m11 * m22 - m12 * m12 > 0)


def model_from_dict(data: Any, source: str) -> MonitoredModel:
    """The model of an ``identify`` JSON result (its "parameters" and "effort_unit"); UsageError naming
    ``source`` when it is not one."""
    hint = "give the JSON that `wmrid identify LOG -o RESULT.json` writes"
    if not isinstance(data, dict) or not isinstance(data.get("parameters"), dict):
        raise UsageError(f'--model {source}: not a wmrid identify result (no "parameters" object); {hint}')
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
                f'--model {source}: not a wmrid identify result (parameter {name} has no finite "value"); {hint}'
            )
        values.append(float(value))
    unit = data.get("effort_unit", "N m")
    if not isinstance(unit, str):
        raise UsageError(f'--model {source}: "effort_unit" must be a string, got {unit!r}')
    theta0 = np.array(values)
    if not _inertia_ok(theta0):
        raise UsageError(
            f"--model {source}: its inverse inertia [m11 m12; m12 m22] is not positive definite, so it is no "
            "robot's model; identify the robot again"
        )
    reported = {name: dict(entry) for name, entry in params.items() if isinstance(entry, dict)}
    p_names = _p_names(form)
    named = model.named_base(theta0, names)
    stds = {name: (reported.get(name) or {}).get("std") for name in p_names}
    return MonitoredModel(theta0=theta0, parameters=reported, effort_unit=unit, source=source,
                          std=_std_vector(named, stds, p_names), form=form)  # fmt: skip


def _form_of(form_d: Any, source: str, hint: str) -> RegressorForm | None:
    """The caster model of a result's ``theta.form`` (:meth:`wmrid.model.dynamics.RegressorForm.from_dict`), None for
    wheel friction (or no form recorded)."""
    if not isinstance(form_d, dict) or form_d.get("friction") != "wheel+caster":
        return None
    try:
        form = RegressorForm.from_dict(form_d)
    except (KeyError, TypeError, ValueError, IndexError) as err:
        raise UsageError(
            f"--model {source}: its caster-drag form (theta.form) is malformed ({err.__class__.__name__}: {err}); "
            f"{hint}"
        ) from None
    return _caster_form(form)


def load_model(path: str | Path) -> MonitoredModel:
    """The model in an ``identify`` JSON result file; UsageError (one line, naming the file) otherwise."""
    from wmrid.core.atomic import register_input

    register_input(path)
    from wmrid.core.limits import memory_budget, read_limited

    try:
        text = read_limited(
            path, memory_budget(), f"--model {path}: holds more than {{size}} (WMRID_MEMORY_BUDGET); is it a result?",
            UsageError,
        ).decode("utf-8")  # fmt: skip
    except (OSError, UnicodeDecodeError) as err:
        raise UsageError(f"--model {path}: cannot read it ({err.__class__.__name__}: {err})") from None
    try:
        data = json.loads(text)
    except RecursionError:
        raise UsageError(f"--model {path}: nested too deeply to be an identify result") from None
    except ValueError as err:
        raise UsageError(f"--model {path}: not a wmrid identify result (not JSON: {err})") from None
    return model_from_dict(data, str(path))


def _physical_vector(theta0: np.ndarray) -> np.ndarray:
    """p = [M11, M12, M22, Vc, Fv1, Fv2, Fd1, Fd2, then theta0's caster drag parameters unchanged]: what the
    regressor Phi multiplies."""
    big_m = np.linalg.inv(model.inverse_inertia(theta0))
    return np.array([big_m[0, 0], big_m[0, 1], big_m[1, 1], *theta0[3:]])


@dataclass(frozen=True)
class Signals:
    """What the test needs, at the test rate, independent of the model.

    t : (m,) s from the log's first sample.  tau : (m, 2) smoothed efforts.  phi : (m, 2, 8) regressor of
    the residual (same smoothing), so that r = tau - phi @ p.  phi_test : (m, 2, 8) the test's smoother
    regressor.  rate : Hz.  notes : what was done to the log.  smooth : (raw columns (n, q) at the log's
    rate, which) -> (m, q), the same smoothing as phi's (which "res") or phi_test's ("test") columns: makes the
    caster columns of a ``wheel+caster`` form (:meth:`phi_for`).
    """

    t: np.ndarray
    tau: np.ndarray
    phi: np.ndarray
    phi_test: np.ndarray
    rate: float
    log_rate: float
    lookahead: float
    notes: tuple[str, ...]
    eta: np.ndarray | None = field(default=None, repr=False, compare=False)  # (n, 2) the log's speeds (even grid)
    smooth: Any = field(default=None, repr=False, compare=False)
    _cache: dict = field(default_factory=dict, repr=False, compare=False)

    def phi_for(self, form: RegressorForm | None, which: str = "res") -> np.ndarray:
        """The regressor (m, 2, len(p)) of ``form``: phi (``which`` "res") or phi_test ("test"), with a
        ``wheel+caster`` form's drag columns appended: column j of ``form.caster_map`` adds
        col_j x [1, pattern_j] to the wheel torques, so it goes to p's entry of its parameter (as
        :func:`wmrid.estimators.idim.rows_from_features` maps them), smoothed as the other speed columns."""
        base = self.phi if which == "res" else self.phi_test
        form = _caster_form(form)
        if form is None:
            return base
        key = (form, which)
        if key not in self._cache:
            if self.eta is None or self.smooth is None:
                raise ValueError("these signals were made without the log's speeds: no caster columns")
            cols = self.smooth(model.caster_columns(self.eta, form), which)  # (m, q)
            extra = np.zeros((len(base), 2, form.n_base - 8))
            for j, (_, param, pattern) in enumerate(form.caster_map):
                extra[:, 0, param - 8] += cols[:, j]
                extra[:, 1, param - 8] += pattern * cols[:, j]
            self._cache[key] = np.concatenate([base, extra], axis=2)
        return self._cache[key]

    def residual(
        self, theta0: np.ndarray, a: int = 0, b: int | None = None, form: RegressorForm | None = None
    ) -> np.ndarray:
        """r (b - a, 2): torque residual of the model theta0 (of regressor form ``form``: its caster drag, if
        any) at samples [a, b)."""
        return self.tau[a:b] - self.phi_for(form)[a:b] @ _physical_vector(theta0)


def _tidy(x: float) -> float:
    """x to 9 significant digits (a rate from a median time step is 49.99999999999 Hz, not 50)."""
    return float(f"{x:.9g}")


def _odd_window(seconds: float, step: float) -> int:
    return max(5, round(seconds / step) | 1)


def _savgol_at(x: np.ndarray, window: int, deriv: int, delta: float, centres: np.ndarray) -> np.ndarray:
    """The Savitzky-Golay cubic (``window`` samples, derivative ``deriv``) of x (n,) at the given centres."""
    from scipy.signal import savgol_coeffs

    coeffs = savgol_coeffs(window, 3, deriv=deriv, delta=delta, use="dot")
    half = window // 2
    out = np.empty(len(centres))
    offsets = np.arange(-half, half + 1)
    for start in range(0, len(centres), _CHUNK):
        idx = centres[start : start + _CHUNK, None] + offsets
        out[start : start + _CHUNK] = x[idx] @ coeffs
    return out


def _uniform(t: np.ndarray, eta: np.ndarray, tau: np.ndarray, source: str):
    """(t, eta, tau, step, note): the log on an even grid (resampled linearly when its steps are uneven)."""
    dt = np.diff(t)
    step = float(np.median(dt))
    if not (step > 0 and math.isfinite(step)):
        raise NotIdentifiableError(f"{source}: its time stamps do not increase; monitor needs an evenly sampled log")
    big = float(dt.max())
    if big > HOLE_FACTOR * step:
        after = float(t[int(np.argmax(dt))] - t[0])
        raise NotIdentifiableError(
            f"{source}: the log has a hole: time jumps by {big:.6g} s after t = {after:.6g} s (the median step is "
            f"{step:.3g} s); cut the log into its continuous parts and monitor each"
        )
    if np.all(np.abs(dt - step) <= 0.01 * step):
        return t, eta, tau, step, None
    grid = t[0] + step * np.arange(math.floor((t[-1] - t[0]) / step + 1e-9) + 1)
    eta_u = np.column_stack([np.interp(grid, t, eta[:, j]) for j in range(2)])
    tau_u = np.column_stack([np.interp(grid, t, tau[:, j]) for j in range(2)])
    note = f"uneven time steps: resampled linearly on the median step {step:.4g} s for the residual test"
    return grid, eta_u, tau_u, step, note


def residual_signals(t: np.ndarray, eta: np.ndarray, tau: np.ndarray, settings: MonitorSettings,
                     source: str = "log") -> Signals:  # fmt: skip
    """Smoothed efforts and regressors at the test rate (see the module docstring)."""
    t = np.asarray(t, dtype=float)
    eta = np.asarray(eta, dtype=float)
    tau = np.asarray(tau, dtype=float)
    if len(t) < 10:
        raise NotIdentifiableError(f"{source}: only {len(t)} samples; monitoring needs a log of many seconds")
    t, eta, tau, step, note = _uniform(t, eta, tau, source)
    log_rate = 1.0 / step
    dec = max(1, round(log_rate / settings.rate_hz))
    w_res = _odd_window(settings.accel_window_s, step)
    w_reg = _odd_window(settings.regressor_window_s, step)
    half = max(w_res, w_reg) // 2
    if len(t) < 2 * half + 2:
        raise NotIdentifiableError(f"{source}: the log is shorter than the smoothing windows; record a longer log")
    centres = np.arange(half, len(t) - half, dec)
    e1, e2 = eta[:, 0], eta[:, 1]
    columns = {  # made one at a time: a long log's full-rate columns are large
        "e1": lambda: e1, "e2": lambda: e2, "v1": lambda: e1 * e2 - e2 * e2, "v2": lambda: e1 * e2 - e1 * e1,
        "s1": lambda: np.sign(e1), "s2": lambda: np.sign(e2),
    }  # fmt: skip

    def regressor(window: int) -> np.ndarray:
        f = {name: _savgol_at(make(), window, 0, step, centres) for name, make in columns.items()}
        a1 = _savgol_at(e1, window, 1, step, centres)
        a2 = _savgol_at(e2, window, 1, step, centres)
        phi = np.zeros((len(centres), 2, DOF))
        phi[:, 0, 0], phi[:, 0, 1], phi[:, 1, 1], phi[:, 1, 2] = a1, a2, a1, a2
        phi[:, 0, 3], phi[:, 1, 3] = f["v1"], f["v2"]
        phi[:, 0, 4], phi[:, 1, 5] = f["e1"], f["e2"]
        phi[:, 0, 6], phi[:, 1, 7] = f["s1"], f["s2"]
        return phi

    def smooth(raw: np.ndarray, which: str) -> np.ndarray:
        window = w_res if which == "res" else w_reg
        return np.column_stack([_savgol_at(raw[:, j], window, 0, step, centres) for j in range(raw.shape[1])])

    tau_f = np.column_stack([_savgol_at(tau[:, j], w_res, 0, step, centres) for j in range(2)])
    notes = (note,) if note else ()
    return Signals(
        t=t[centres] - t[0], tau=tau_f, phi=regressor(w_res), phi_test=regressor(w_reg), rate=log_rate / dec,
        log_rate=log_rate, lookahead=half * step, notes=notes, eta=eta, smooth=smooth,
    )  # fmt: skip


@dataclass(frozen=True)
class NoiseModel:
    """r_k = sum_i A_i r_k-i + e_k, e_k ~ N(0, cov): a vector autoregression of the residual (2 wheels).

    coeffs : (q, 2, 2) A_1 .. A_q.  cov : (2, 2) innovation covariance.  rows : equations it was fitted on.
    dof : degrees of freedom of its estimate of the low-frequency noise power, rows / q (an autoregression
    of order q on n samples estimates the spectrum at frequency 0 with a relative variance of 4 q / n per
    wheel, Berk 1974; two wheels halve it).
    """

    coeffs: np.ndarray
    cov: np.ndarray
    rows: int

    @property
    def order(self) -> int:
        return len(self.coeffs)

    @property
    def dof(self) -> float:
        return self.rows / self.order

    @classmethod
    def fit(cls, spans: list[np.ndarray], order: int) -> NoiseModel:
        """Least squares on the residual spans (each (n_i, 2); lags never cross from one span to another)."""
        lagged, target = [], []
        for r in spans:
            n = len(r)
            if n <= order:
                continue
            target.append(r[order:])
            lagged.append(np.hstack([r[order - i : n - i] for i in range(1, order + 1)]))  # (n - q, 2q)
        rows = sum(len(t) for t in target)
        if rows < MIN_ROWS_PER_COEFFICIENT * 2 * order:
            raise NotIdentifiableError(
                f"the calibration span holds {rows + order} residual samples, too few for a noise model with {order} "
                "lags"
            )
        z = np.concatenate(lagged)
        y = np.concatenate(target)
        coef, *_ = np.linalg.lstsq(z, y, rcond=None)  # (2q, 2): y = z @ coef
        innov = y - z @ coef
        cov = innov.T @ innov / (rows - 2 * order)
        coeffs = np.stack([coef[2 * i : 2 * i + 2].T for i in range(order)])
        return cls(coeffs=coeffs, cov=cov, rows=rows)

    def whiten(self, x: np.ndarray) -> np.ndarray:
        """L^-1 (x_k - sum_i A_i x_k-i) for k >= q: (m - q, 2, ...) from x (m, 2, ...), cov = L L'."""
        q = self.order
        m = len(x)
        out = x[q:].copy()
        for i in range(1, q + 1):
            out -= np.einsum("jl,kl...->kj...", self.coeffs[i - 1], x[q - i : m - i])
        inv_l = np.linalg.inv(np.linalg.cholesky(self.cov))
        return np.einsum("jl,kl...->kj...", inv_l, out)


@dataclass(frozen=True)
class WindowGrid:
    """The tests: windows and steps in blocks of ``block`` samples (at ``rate`` Hz), per-test false-alarm
    probability p_test = false_alarm_rate / tests_per_hour, and the margin on the threshold."""

    block: int
    windows: tuple[int, ...]
    steps: tuple[int, ...]
    rate: float
    p_test: float
    tests_per_hour: float
    margin: float

    def threshold(self, dof: float, n_params: int = DOF) -> float:
        """h with P(S > h / margin) = p_test for S / n ~ F(n, dof), n = ``n_params`` = len(p) (8 without caster
        drag): the chi2_n law of S with a noise power estimated on ``dof`` degrees of freedom (chi2_n itself for
        dof = inf)."""
        from scipy.stats import chi2, f

        if not math.isfinite(dof):
            return self.margin * float(chi2.isf(self.p_test, n_params))
        return self.margin * n_params * float(f.isf(self.p_test, n_params, dof))

    def to_dict(self) -> dict[str, Any]:
        return {
            "windows_s": [_tidy(w * self.block / self.rate) for w in self.windows],
            "steps_s": [_tidy(s * self.block / self.rate) for s in self.steps],
            "tests_per_hour": self.tests_per_hour,
            "p_per_test": self.p_test,
        }


def window_grid(settings: MonitorSettings, rate: float) -> WindowGrid:
    """The windows on the residual's sample grid, each tested every 1/steps_per_window of its length."""
    shortest = min(settings.windows_s)
    block = max(1, round(shortest * rate / settings.steps_per_window))
    windows = tuple(sorted({max(1, round(w * rate / block)) for w in settings.windows_s}))
    steps = tuple(max(1, round(w / settings.steps_per_window)) for w in windows)
    tests_per_hour = sum(3600.0 * rate / (s * block) for s in steps)
    p_test = settings.false_alarm_rate / tests_per_hour
    return WindowGrid(block, windows, steps, rate, p_test, tests_per_hour, settings.margin)


@dataclass(frozen=True)
class ModelError:
    """What is known of the model's own error dp (p = [M11 M12 M22 Vc Fv1 Fv2 Fd1 Fd2, caster drag]) on a segment:
    normal with mean ``mean`` (n,) and covariance ``cov`` (n, n); the residual holds Phi dp even without a change."""

    mean: np.ndarray
    cov: np.ndarray


def _glr(gram: np.ndarray, proj: np.ndarray, err: ModelError) -> np.ndarray:
    """S = c' (G + G P G)^-1 c, c = b - G dp_mean, for stacks G (k, n, n), b (k, n): the GLR statistic when the
    model's own error, normal (dp_mean, P), is part of the null hypothesis (c = X'e + G (dp - dp_mean) then has
    covariance G + G P G); a relative ridge of 1e-10 for directions a window does not excite."""
    n = gram.shape[-1]
    ridge = 1e-10 * np.trace(gram, axis1=1, axis2=2)[:, None, None] * np.eye(n) + 1e-300 * np.eye(n)
    cov = gram + ridge + gram @ err.cov @ gram
    centred = proj - gram @ err.mean
    sol = np.linalg.solve(cov, centred[..., None])[..., 0]
    return np.einsum("kp,kp->k", centred, sol)


def window_statistics(z: np.ndarray, x: np.ndarray, err: ModelError, lo: int, grid: WindowGrid, after: int,
                      upto: int):  # fmt: skip
    """The tests whose window lies in the whitened data z (m, 2), x (m, 2, n) -- z[0] being sample ``lo`` of the
    segment, a whole number of blocks -- and ends in (after, upto]: per window length, (width in samples,
    window ends (exclusive, segment samples), statistics S)."""
    first_block = lo // grid.block
    usable = (lo + len(z)) // grid.block - first_block
    out = []
    if usable < min(grid.windows):
        return out
    n = usable * grid.block
    dim = x.shape[-1]
    xb = x[:n].reshape(usable, grid.block, 2, dim)
    zb = z[:n].reshape(usable, grid.block, 2)
    gram = np.concatenate([np.zeros((1, dim, dim)), np.cumsum(np.einsum("nbip,nbiq->npq", xb, xb), axis=0)])
    proj = np.concatenate([np.zeros((1, dim)), np.cumsum(np.einsum("nbip,nbi->np", xb, zb), axis=0)])
    for width, step in zip(grid.windows, grid.steps, strict=True):
        ends = np.arange(width, usable + 1)  # in blocks from first_block
        absolute = (first_block + ends) * grid.block
        keep = ((first_block + ends) % step == 0) & (absolute > after) & (absolute <= upto)
        ends = ends[keep]
        if len(ends) == 0:
            continue
        s = _glr(gram[ends] - gram[ends - width], proj[ends] - proj[ends - width], err)
        out.append((width * grid.block, (first_block + ends) * grid.block, s))
    return out


def locate(z: np.ndarray, x: np.ndarray, err: ModelError, upto: int) -> int:
    """The maximum-likelihood change sample: the j < ``upto`` maximising S(j, len(z)), the GLR statistic of the
    whitened data from j to the end (indices into z)."""
    gram_rev = np.cumsum(np.einsum("kip,kiq->kpq", x, x)[::-1], axis=0)[::-1]  # sums from j to the end
    proj_rev = np.cumsum(np.einsum("kip,ki->kp", x, z)[::-1], axis=0)[::-1]
    upto = max(1, min(upto, len(z)))
    return int(np.argmax(_glr(gram_rev[:upto], proj_rev[:upto], err)))


@dataclass
class Change:
    """One detected change: times in s from the log's start."""

    t: float
    t_alarm: float
    statistic: float
    threshold: float
    window_s: float
    parameters: dict[str, dict[str, Any]] | None = None
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
            "window_s": _tidy(self.window_s),
            "parameters": self.parameters,
            "relative_change": self.relative_change,
            "identified_on": None if self.segment is None else {"t_start": self.segment[0], "t_end": self.segment[1]},
            "warnings": list(self.warnings),
        }


@dataclass
class MonitorResult:
    """What :func:`monitor` found; ``to_dict`` gives the JSON form."""

    source: str
    model: MonitoredModel
    settings: MonitorSettings
    grid: WindowGrid
    noise_lags: int
    calibration_samples: int
    changes: list[Change]
    segments: list[dict[str, Any]]
    log_info: dict[str, Any]
    warnings: list[str]
    seconds: float

    def detector_dict(self) -> dict[str, Any]:
        g, st, order = self.grid, self.settings, self.noise_lags
        first_dof = (self.calibration_samples - order) / order
        form = _caster_form(self.model.form)
        names, dim = _p_names(form), len(_p_names(form))
        drag = "" if form is None else f" + the caster drag of {form.friction} ({', '.join(names[DOF:])})"
        return {
            "method": "windowed generalised likelihood ratio (GLR) test on whitened torque residuals",
            "residual": f"r = tau - M eta_dot - V(eta) - F_v eta - F_d sgn(eta){drag} of the model, every signal "
            f"smoothed by a Savitzky-Golay cubic over {st.accel_window_s:g} s (eta_dot its derivative), at "
            f"{_tidy(g.rate):g} Hz",
            "statistic": "S = c' (G + G P G)^-1 c over a window, c = b - G dp0, G = sum X'X, b = sum X'z, z the "
            f"whitened residual, X the whitened regressor Phi (columns {', '.join(names)}, smoothed over "
            f"{st.regressor_window_s:g} s), dp0 and P the mean and covariance of the model's own error (from its "
            "standard errors x 2, updated on the calibration span); with P = 0 the explained sum of squares of a "
            f"least-squares fit of z on X: chi-square with {dim} degrees of freedom when nothing changed",
            "settings": {**st.to_dict(), **g.to_dict(), "noise_lags": order},
            "threshold": {
                "first_calibration": g.threshold(first_dof, dim),
                "limit": g.threshold(math.inf, dim),
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
                "closed-loop simulated logs are printed by bench/bench_monitor.py"
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
                "parameters": self.model.parameters,
                **({} if self.model.form is None else {"form": self.model.form.to_dict()}),
            },
            "changes": [c.to_dict() for c in self.changes],
            "detector": self.detector_dict(),
            "segments": self.segments,
            "log": self.log_info,
            "warnings": list(self.warnings),
            "seconds": self.seconds,
        }


@dataclass(frozen=True)
class _Log:
    t: np.ndarray
    eta: np.ndarray
    tau: np.ndarray
    source: str
    notes: tuple[str, ...] = ()
    effort_unit: str = "N m"


def _segment_log(log: Any, t_start: float, t_end: float, unit: str) -> _Log:
    t = np.asarray(log.t) - log.t[0]
    keep = (t >= t_start - 1e-9) & (t <= t_end + 1e-9)
    t_seg = t[keep]
    return _Log(
        t=t_seg - t_seg[0] if len(t_seg) else t_seg, eta=np.asarray(log.eta)[keep], tau=np.asarray(log.tau)[keep],
        source=f"{log.source} [{t_start:.3f} s, {t_end:.3f} s]", effort_unit=unit,
    )  # fmt: skip


def _identify_span(log: Any, t_start: float, t_end: float, unit: str, friction: str = "wheel",
                   notes: list[str] | None = None, geometry: tuple[float, ...] = ()):  # fmt: skip
    """(identification of log[t_start, t_end] (s from the log's start), None) or (None, why not).

    ``friction``: the given model's friction model.  ``wheel+caster`` is identified with the given model's caster
    positions ``geometry`` ((r, b, x_1, y_1, ...), its ``form.geometry``), else with the two-term caster model
    (Cv, Cw); where that is not identifiable (the wheels never stop or reverse: the drag then adds to the
    Coulomb friction) the wheel friction model is used instead, and why is appended to ``notes``."""
    from wmrid.estimators.identify import identify

    seg = _segment_log(log, t_start, t_end, unit)
    span = float(seg.t[-1]) if len(seg.t) else 0.0
    if len(seg.t) < 10 or span < MIN_IDENTIFY_S - 1e-9:
        return None, (
            f"only {span:.3g} s of log from {t_start:.3f} s: too little to identify (at least {MIN_IDENTIFY_S:g} s)"
        )
    try:
        try:
            result = identify(seg, None, friction=friction, geometry=geometry, feedback=False, timing=False)
        except NotIdentifiableError as err:
            if friction == "wheel":
                raise
            result = identify(seg, None, friction="wheel", feedback=False, timing=False)
            if notes is not None:
                notes.append(
                    f"the log from {t_start:.3f} s to {t_end:.3f} s was identified with wheel friction only: the "
                    f"caster model was not identifiable there ({err})"
                )
    except NotIdentifiableError as err:
        return None, f"the log from {t_start:.3f} s to {t_end:.3f} s could not be identified: {err}"
    theta0 = result.estimate.theta0
    if not (np.all(np.isfinite(theta0)) and _inertia_ok(theta0)):
        return None, f"the model identified from {t_start:.3f} s to {t_end:.3f} s is not physical"
    return result, None


@dataclass(frozen=True)
class _Model:
    """Base parameters theta0 (n,) and the prior covariance (n, n) of the error of p = [M11 M12 M22 Vc Fv1 Fv2 Fd1
    Fd2, caster drag]; ``update``: refine it with the calibration span (a given model, from another log), or not
    (a model identified on the calibration span itself, whose covariance already holds that data); ``form``: its
    caster model (None: wheel friction, n = 8)."""

    theta0: np.ndarray
    cov: np.ndarray
    update: bool
    form: RegressorForm | None = None


def _physical_jacobian(theta0: np.ndarray) -> np.ndarray:
    """d p / d theta0 (n, n): M = m^-1 gives dM = -M dm M; the others (Vc, friction, caster drag) are the same in
    both."""
    n = len(theta0)
    big_m = np.linalg.inv(model.inverse_inertia(theta0))
    jac = np.zeros((n, n))
    basis = (np.array([[1.0, 0.0], [0.0, 0.0]]), np.array([[0.0, 1.0], [1.0, 0.0]]), np.array([[0.0, 0.0], [0.0, 1.0]]))
    for j, dm in enumerate(basis):
        d_big = -big_m @ dm @ big_m
        jac[:3, j] = [d_big[0, 0], d_big[0, 1], d_big[1, 1]]
    jac[3:, 3:] = np.eye(n - 3)
    return jac


def _model_of_result(result: Any) -> _Model:
    """The model an identification found, with its full covariance (undetermined parameters: ten times their
    value as standard error, uncorrelated), times PRIOR_STD_FACTOR^2."""
    theta0 = np.asarray(result.estimate.theta0, dtype=float)
    cov0 = np.array(result.estimate.cov, dtype=float)
    bad = ~np.isfinite(np.diag(cov0))
    cov0[bad, :] = cov0[:, bad] = 0.0
    cov0[bad, bad] = (10.0 * np.maximum(np.abs(theta0[bad]), 1e-3)) ** 2
    cov0 = np.where(np.isfinite(cov0), cov0, 0.0)
    jac = _physical_jacobian(theta0)
    return _Model(theta0, PRIOR_STD_FACTOR**2 * (jac @ cov0 @ jac.T), update=False, form=_caster_form(result.form))


class _Segment:
    """The test on one segment of the signals (from sample ``start`` to the end), its calibrations growing by
    doubling; ``fixed`` None: identify the model on the segment itself."""

    def __init__(self, mon: _Monitor, start: int, fixed: _Model | None) -> None:
        self.m, self.start, self.fixed = mon, start, fixed
        self.n = len(mon.sig.t) - start
        self.calibrations: list[dict[str, Any]] = []

    def _t(self, i: int) -> float:
        return float(self.m.sig.t[self.start + min(i, self.n - 1)])

    def calibrate(self, upto: int) -> tuple[_Model, NoiseModel]:
        """The model and the noise model from the segment's samples [0, upto)."""
        m = self.m
        a = self.start
        if self.fixed is not None:
            return self.fixed, NoiseModel.fit(
                [m.sig.residual(self.fixed.theta0, a, a + upto, self.fixed.form)], m.order
            )
        t0, t1 = self._t(0), self._t(upto - 1)
        result, problem = _identify_span(m.log, t0, t1, m.unit, m.friction, m.notes, m.geometry)
        if result is None:
            raise _Stop(problem)
        fitted = _model_of_result(result)
        # Cross-fitting: each half's residual from the model identified on the other half, so that the noise
        # model sees the model's estimation error as the test will, not an in-sample fit.
        half = upto // 2
        tm = self._t(half)
        first, _ = _identify_span(m.log, t0, tm, m.unit, m.friction, m.notes, m.geometry)
        second, _ = _identify_span(m.log, tm, t1, m.unit, m.friction, m.notes, m.geometry)
        if first is not None and second is not None:
            spans = [m.sig.residual(second.estimate.theta0, a, a + half, _caster_form(second.form)),
                     m.sig.residual(first.estimate.theta0, a + half, a + upto, _caster_form(first.form))]  # fmt: skip
        else:
            spans = [m.sig.residual(fitted.theta0, a, a + upto, fitted.form)]
        try:
            return fitted, NoiseModel.fit(spans, m.order)
        except NotIdentifiableError as err:
            raise _Stop(f"the segment from {t0:.3f} s: {err}") from None

    def run(self):
        """The first alarm (change sample in the segment, Change) or None."""
        m, grid = self.m, self.m.grid
        n_cal = m.n_cal
        if self.n < n_cal + min(grid.windows) * grid.block:
            raise _Stop(
                f"the last {self._t(self.n - 1) - self._t(0):.3g} s from {self._t(0):.3f} s are shorter than the "
                f"calibration span ({m.settings.calibration_s:g} s) and a test window: not tested"
            )
        longest = max(grid.windows) * grid.block
        upto = n_cal
        while upto < self.n:
            nxt = min(2 * upto, self.n)
            fitted, noise = self.calibrate(upto)
            h = grid.threshold(noise.dof, len(fitted.theta0))
            err = ModelError(np.zeros(len(fitted.theta0)), fitted.cov)
            if fitted.update:  # what the calibration span says of the given model's error (Bayes, normal)
                z, x = m.whitened(fitted, noise, self.start + noise.order, self.start + upto)
                gram, proj = np.einsum("kip,kiq->pq", x, x), np.einsum("kip,ki->p", x, z)
                post = np.linalg.inv(np.linalg.inv(fitted.cov) + gram)
                err = ModelError(post @ proj, (post + post.T) / 2)
            lo = max(n_cal, (upto - longest) // grid.block * grid.block)
            z, x = m.whitened(fitted, noise, self.start + lo, self.start + nxt)
            tests = window_statistics(z, x, err, lo, grid, upto, nxt)
            alarm = None
            for width, ends, s in tests:
                over = np.flatnonzero(s > h)
                if len(over):
                    cand = (int(ends[over[0]]), -float(s[over[0]]), width)
                    alarm = cand if alarm is None or cand < alarm else alarm
            largest = max((float(s.max()) for _, _, s in tests), default=0.0)
            if alarm is not None:
                largest = max(float(s[ends <= alarm[0]].max(initial=0.0)) for _, ends, s in tests)
            self.calibrations.append({
                "t_start": self._t(0), "t_end": self._t(upto - 1), "lags": noise.order, "dof": noise.dof,
                "innovation_std": [float(v) for v in np.sqrt(np.diag(noise.cov))], "threshold": h,
                "tests_until": self._t(nxt - 1), "largest_statistic": largest,
            })  # fmt: skip
            if alarm is not None:
                end, neg_s, width = alarm
                lo_loc = max(n_cal, end - longest)
                hi_loc = min(self.n, end + m.after)
                z, x = m.whitened(fitted, noise, self.start + lo_loc, self.start + hi_loc)
                j = lo_loc + locate(z, x, err, end - lo_loc)
                t_alarm = min(self._t(end - 1) + m.sig.lookahead, m.duration)
                change = Change(t=self._t(j), t_alarm=t_alarm, statistic=-neg_s, threshold=h,
                                window_s=width / grid.rate)  # fmt: skip
                return j, change
            upto = nxt
        return None

    def to_dict(self, t_end: float) -> dict[str, Any]:
        return {"t_start": self._t(0), "t_end": t_end, "model": "given" if self.fixed is not None else "identified on "
                "the segment", "calibrations": self.calibrations}  # fmt: skip


class _Stop(Exception):
    """The segment cannot be tested further (why: the message)."""


class _Monitor:
    def __init__(
        self, log: Any, sig: Signals, settings: MonitorSettings, unit: str, friction: str = "wheel",
        geometry: tuple[float, ...] = (),
    ) -> None:  # fmt: skip
        self.log, self.sig, self.settings, self.unit = log, sig, settings, unit
        self.grid = window_grid(settings, sig.rate)
        self.order = max(1, round(settings.noise_memory_s * sig.rate))
        self.n_cal = max(1, math.ceil(round(settings.calibration_s * sig.rate) / self.grid.block)) * self.grid.block
        self.after = round(settings.locate_s * sig.rate)
        self.duration = float(log.t[-1] - log.t[0])
        self.friction = friction
        self.geometry = geometry  # the model's caster positions (r, b, x_1, y_1, ...), () for none
        self.notes: list[str] = []  # fallbacks of re-identification (see _identify_span)

    def whitened(self, fitted: _Model, noise: NoiseModel, a: int, b: int) -> tuple[np.ndarray, np.ndarray]:
        """Whitened residual z (m, 2) and regressor x (m, 2, n) of signal samples [a, b) (from a - q for the
        filter's memory)."""
        q = noise.order
        residual = self.sig.residual(fitted.theta0, a - q, b, fitted.form)
        return noise.whiten(residual), noise.whiten(self.sig.phi_for(fitted.form, "test")[a - q : b])


def monitor(log: Any, model_: MonitoredModel, settings: MonitorSettings | None = None) -> MonitorResult:
    """Replay ``log`` (t (n,) s, eta (n, 2) rad/s, tau (n, 2); source, notes, effort_unit) against ``model_``
    and report the changes of its dynamics (see the module docstring)."""
    started = time.perf_counter()
    settings = settings or MonitorSettings()
    source = getattr(log, "source", "log")
    unit = getattr(log, "effort_unit", "N m")
    if unit != model_.effort_unit:
        raise UsageError(
            f"--model {model_.source}: its parameters are for efforts in {model_.effort_unit}, but the log's effort "
            f"is in {unit}; identify and monitor with the same effort options"
        )
    sig = residual_signals(log.t, log.eta, log.tau, settings, source)
    friction = "wheel" if model_.form is None else model_.form.friction
    geometry = () if model_.form is None else tuple(model_.form.geometry)
    mon = _Monitor(log, sig, settings, unit, friction, geometry)
    duration = float(log.t[-1] - log.t[0])
    need = (MIN_ROWS_PER_COEFFICIENT * 2 + 2) * mon.order  # after a change the halves lose q samples each
    if mon.n_cal < need:
        raise UsageError(
            f"--calibration {settings.calibration_s:g} s: too short for the noise model ({mon.order} lags at "
            f"{sig.rate:.4g} Hz need at least {need / sig.rate:.3g} s)"
        )
    if len(sig.t) < mon.n_cal + min(mon.grid.windows) * mon.grid.block:
        raise NotIdentifiableError(
            f"{source}: the log lasts {duration:.3g} s, but monitoring needs more than the calibration span "
            f"({settings.calibration_s:g} s, assumed unchanged) plus a test window; record a longer log or lower "
            "--calibration"
        )
    warnings: list[str] = []
    changes: list[Change] = []
    segments: list[dict[str, Any]] = []
    prior = np.diag((PRIOR_STD_FACTOR * model_.std) ** 2)
    seg = _Segment(mon, 0, _Model(model_.theta0, prior, update=True, form=_caster_form(model_.form)))
    while True:
        try:
            found = seg.run()
        except _Stop as stop:
            warnings.append(str(stop))
            found = None
        if found is None:
            segments.append(seg.to_dict(float(sig.t[-1])))
            break
        j, change = found
        segments.append(seg.to_dict(change.t))
        changes.append(change)
        seg = _Segment(mon, seg.start + j, None)
    # Each segment after a change, identified on all of it.
    before, before_form = model_.theta0, _caster_form(model_.form)
    for i, change in enumerate(changes):
        t_end = changes[i + 1].t if i + 1 < len(changes) else duration
        notes: list[str] = []
        result, problem = _identify_span(log, change.t, t_end, unit, friction, notes, geometry)
        change.warnings.extend(notes)
        if result is None:
            change.warnings.append(problem)
            continue
        change.parameters = result.to_dict()["parameters"]
        change.segment = (change.t, t_end)
        change.warnings.extend(result.warnings)
        change.theta0 = result.estimate.theta0
        after_form = _caster_form(result.form)
        if after_form != before_form and before_form is not None:
            change.warnings.append(
                f"identified with friction model {'wheel' if after_form is None else after_form.friction} "
                f"({', '.join((after_form.base_names if after_form else THETA0_NAMES)[8:]) or 'no caster drag'}), "
                f"not the model's ({', '.join(before_form.base_names[8:])}; the caster model was not identifiable "
                "on this segment): its friction and drag terms are not comparable"
            )
        after_named, before_named = named(change.theta0, after_form), named(before, before_form)
        # the caster drag's parameters are compared when both models have them (same caster model)
        drag = [name for name in after_named if name not in (*THETA0_NAMES, "M11", "M12", "M22")]
        change.relative_change = {
            name: (after_named[name] - before_named[name]) / abs(before_named[name]) if before_named[name] else None
            for name in (*THETA0_NAMES, "M11", "M12", "M22", *(n for n in drag if n in before_named))
        }
        before, before_form = change.theta0, after_form
    seen = set(warnings)
    for note in mon.notes:  # re-identifications that fell back to wheel friction (once each)
        if note not in seen:
            seen.add(note)
            warnings.append(note)
    log_info = {
        "samples": len(log.t),
        "duration_s": duration,
        "rate_hz": _tidy(sig.log_rate),
        "notes": [*getattr(log, "notes", ()), *sig.notes],
        "effort_unit": unit,
    }
    return MonitorResult(
        source=source, model=model_, settings=settings, grid=mon.grid, noise_lags=mon.order,
        calibration_samples=mon.n_cal, changes=changes, segments=segments,
        log_info=log_info, warnings=warnings, seconds=time.perf_counter() - started,
    )  # fmt: skip


def named(theta0: np.ndarray, form: RegressorForm | None) -> dict[str, float]:
    """theta0 and M by name (:func:`wmrid.model.dynamics.named_base`), the caster drag's named by ``form``."""
    return model.named_base(theta0) if form is None else model.named_base(theta0, form.base_names)
