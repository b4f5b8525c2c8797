"""A reference drive given as samples (t, v, omega), turned into the compiled loop's table (trajectory kind 2).

The closed loop (:mod:`wmrid.sim.closed_loop`) asks the reference, at every control period, for the state
(x_r, y_r, phi_r, v_r, w_r, v_r', w_r').  The built-in trajectories give it in closed form; a reference read from
a file (:func:`wmrid.io.reference_files.read_reference`, e.g. a plan of ``wmrid plan``) gives only samples of v and
omega.  :func:`reference_table` precomputes that state on the control grid t_k = k T, k = 0 .. n_ctrl - 1:

* v_r, w_r and their derivatives: a cubic spline through the samples (``scipy.interpolate.CubicSpline``,
  not-a-knot ends), evaluated with its first derivative.  On samples of a smooth signal taken every h seconds
  the spline errs by O(h^4 |v''''|) in value and O(h^3 |v''''|) in slope, most in the last samples at either end
  (not-a-knot guesses the end slopes): on the 50 Hz samples of the built-in ``reversing`` over 20 s, v_r within
  2e-9 m/s, w_r 1.3e-8 rad/s, v_r' 6e-7 m/s^2, w_r' 4.2e-6 rad/s^2 (away from the ends 2e-10, 1.5e-9, 3e-8 and
  2.3e-7; tests/unit/sim/test_simulate_reference.py).  Between the samples the spline is the reference: it is C2, so
  v_r' is continuous, as the controller's feed-forward needs.
* phi_r = the integral of the omega spline from the first sample (its exact antiderivative), so phi_r(0) = 0.
* x_r, y_r: the integrals of v_r cos phi_r, v_r sin phi_r, by Simpson's rule on each control period (the integrand
  at both ends and the middle).  The composite rule errs by at most T^4 / 2880 max|f''''| per unit time: at
  T = 1 ms and |f''''| < 1e4 m/s^5 (a speed of 1 m/s turning at up to 10 rad/s), below 4e-12 m per second of
  reference.  A knot of the spline (where f''' jumps) inside a control period adds an error of order
  T^4 |jump of f'''|; with sample times on the control grid (a 50 Hz plan at 1 ms) no period holds one.

The reference starts at the origin facing +x (x_r = y_r = phi_r = 0 at t = 0), its time counted from its first
sample.  The kernel gets the table flattened into its ``traj`` vector (:func:`pack_table`): [T, n_rows,
then n_rows x 7 values row by row]; between rows (a log time off the control grid) it interpolates linearly.
"""

from __future__ import annotations

import hashlib
import math
from dataclasses import dataclass, field

import numpy as np

from wmrid.core.errors import UsageError

__all__ = ["TABLE_COLUMNS", "Reference", "pack_table", "reference_table"]

#: The columns of a reference table, in the kernel's order (m, m, rad, m/s, rad/s, m/s^2, rad/s^2).
TABLE_COLUMNS = ("x_r", "y_r", "phi_r", "v_r", "w_r", "v_r_dot", "w_r_dot")
#: Values of the kernel's ``traj`` vector before the table: control period T (s), number of rows.
TABLE_HEADER = 2
#: Bytes a reference run holds per control period beyond a built-in trajectory's: the table (7 float64), its packed
#: copy and the temporaries of its construction (the grid, its midpoints, the spline's values there).
TABLE_BYTES_PER_CONTROL_STEP = 256


@dataclass(frozen=True, eq=False)
class Reference:
    """A reference drive: samples of the forward speed and the turn rate, with where they came from.

    t : (n,) float64 s, finite, strictly increasing, n >= 2; ``t - t[0]`` is the time of the run.
    v : (n,) float64 m/s; omega : (n,) float64 rad/s; finite.
    source : the file they were read from (None: arrays given).  sha256 : of the file, or of the three arrays'
    float64 bytes (t, v, omega, back to back) when given as arrays.
    """

    t: np.ndarray
    v: np.ndarray
    omega: np.ndarray
    source: str | None = None
    sha256: str = field(default="")

    @classmethod
    def from_arrays(
        cls, t: object, v: object, omega: object, *, source: str | None = None, sha256: str | None = None
    ) -> Reference:
        """Check and copy the samples (UsageError naming the bad one); ``sha256`` None: that of the arrays."""
        arrays = []
        for name, values in (("t", t), ("v", v), ("omega", omega)):
            arr = np.array(values, dtype=np.float64) if _numeric(values) else None
            if arr is None or arr.ndim != 1:
                raise UsageError(f"reference {name} must be a 1-D array of numbers")
            bad = np.flatnonzero(~np.isfinite(arr))
            if bad.size:
                raise UsageError(f"reference {name} is NaN or infinite at sample {int(bad[0]) + 1} (1-based)")
            arrays.append(arr)
        t_, v_, w_ = arrays
        if not t_.shape == v_.shape == w_.shape:
            raise UsageError(f"reference t, v, omega must have one length, got {t_.size}, {v_.size}, {w_.size}")
        if t_.size < 2:
            raise UsageError(f"reference has {t_.size} samples; it needs at least 2")
        back = np.flatnonzero(np.diff(t_) <= 0)
        if back.size:
            raise UsageError(f"reference t does not increase at sample {int(back[0]) + 2} (1-based)")
        if sha256 is None:
            sha256 = hashlib.sha256(t_.tobytes() + v_.tobytes() + w_.tobytes()).hexdigest()
        for a in arrays:
            a.setflags(write=False)
        return cls(t=t_, v=v_, omega=w_, source=source, sha256=sha256)

    @property
    def duration(self) -> float:
        """s from the first sample to the last."""
        return float(self.t[-1] - self.t[0])

    def describe(self) -> dict:
        """What a run's settings record of it (JSON-ready)."""
        return {
            "file": self.source, "sha256": self.sha256, "samples": int(self.t.size), "duration": self.duration,
            "interpolation": "cubic spline (not-a-knot) of v and omega; x, y by Simpson's rule per control period",
        }  # fmt: skip


def _numeric(values: object) -> bool:
    try:
        return np.asarray(values).dtype.kind in "fiu"
    except (TypeError, ValueError):
        return False


def reference_table(ref: Reference, period: float, n_rows: int) -> np.ndarray:
    """(n_rows, 7) float64: the reference state at t_k = k ``period`` s, k = 0 .. n_rows - 1, in the columns of
    :data:`TABLE_COLUMNS` (see the module docstring).  Times past the last sample (at most rounding) extrapolate
    the last spline piece."""
    from scipy.interpolate import CubicSpline  # scipy.interpolate (~0.3 s): only a reference drive

    t0 = ref.t - ref.t[0]
    v_spline = CubicSpline(t0, ref.v)
    w_spline = CubicSpline(t0, ref.omega)
    phi_spline = w_spline.antiderivative()
    dv_spline = v_spline.derivative()
    dw_spline = w_spline.derivative()
    grid = np.arange(n_rows) * period
    table = np.empty((n_rows, 7))
    phi = phi_spline(grid)
    table[:, 2] = phi - phi_spline(0.0)
    v = v_spline(grid)
    table[:, 3] = v
    table[:, 4] = w_spline(grid)
    table[:, 5] = dv_spline(grid)
    table[:, 6] = dw_spline(grid)
    if n_rows > 1:
        mid = grid[:-1] + 0.5 * period
        v_mid = v_spline(mid)
        phi_mid = phi_spline(mid) - phi_spline(0.0)
        fx = v * np.cos(table[:, 2])
        fy = v * np.sin(table[:, 2])
        step_x = period / 6.0 * (fx[:-1] + 4.0 * v_mid * np.cos(phi_mid) + fx[1:])
        step_y = period / 6.0 * (fy[:-1] + 4.0 * v_mid * np.sin(phi_mid) + fy[1:])
        table[0, :2] = 0.0
        table[1:, 0] = np.cumsum(step_x)
        table[1:, 1] = np.cumsum(step_y)
    else:
        table[0, :2] = 0.0
    return table


def pack_table(table: np.ndarray, period: float) -> np.ndarray:
    """The kernel's ``traj`` vector of trajectory kind 2: [period, n_rows, table row by row] (float64)."""
    table = np.ascontiguousarray(table, dtype=np.float64)
    if table.ndim != 2 or table.shape[1] != 7 or table.shape[0] < 1:
        raise ValueError(f"a reference table is (n, 7), got {table.shape}")
    if not (math.isfinite(period) and period > 0):
        raise ValueError(f"period must be a positive number of seconds, got {period!r}")
    return np.concatenate(([float(period), float(table.shape[0])], table.ravel()))
