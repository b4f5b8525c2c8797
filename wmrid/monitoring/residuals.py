"""The torque residual's signals on a uniform grid: smoothed speeds, accelerations and torques, and the regressor
the residual is linear in (:func:`residual_signals`)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from wmrid.core.errors import NotIdentifiableError
from wmrid.model import dynamics as model
from wmrid.model.dynamics import RegressorForm
from wmrid.monitoring.settings import CHUNK, DOF, HOLE_FACTOR, MonitorSettings, caster_form, physical_vector


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
        :func:`wmrid.estimators.regression.idim_rows.rows_from_features` maps them), smoothed as the other speed
        columns."""
        base = self.phi if which == "res" else self.phi_test
        form = caster_form(form)
        if form is None:
            return base
        key = (form, which)
        if key not in self._cache:
            if self.eta is None or self.smooth is None:
                raise ValueError("these signals were made without the log's speeds: no caster columns")
            eta_dot = None  # a drag that follows v' or w': the speeds' central difference, smoothed with the rest
            if form.derivative_columns:
                eta_dot = np.gradient(self.eta, 1.0 / self.log_rate, axis=0)
            cols = self.smooth(model.caster_columns(self.eta, form, eta_dot), which)  # (m, q)
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
        return self.tau[a:b] - self.phi_for(form)[a:b] @ physical_vector(theta0)


def tidy(x: float) -> float:
    """x to 9 significant digits (a rate from a median time step is 49.99999999999 Hz, not 50)."""
    return float(f"{x:.9g}")


def _odd_window(seconds: float, step: float) -> int:
    return max(5, round(seconds / step) | 1)


def _savgol_at(x: np.ndarray, window: int, deriv: int, delta: float, centres: np.ndarray) -> np.ndarray:
    """The Savitzky-Golay cubic (``window`` samples, derivative ``deriv``) of x (n,) at the given centres."""
    from scipy.signal import savgol_coeffs  # scipy.signal (~0.6 s): only the residuals' derivatives

    coeffs = savgol_coeffs(window, 3, deriv=deriv, delta=delta, use="dot")
    half = window // 2
    out = np.empty(len(centres))
    offsets = np.arange(-half, half + 1)
    for start in range(0, len(centres), CHUNK):
        idx = centres[start : start + CHUNK, None] + offsets
        out[start : start + CHUNK] = x[idx] @ coeffs
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
