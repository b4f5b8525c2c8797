"""The delay between a log's effort and speed signals, estimated from the log (issue 12, timing).

Efforts and speeds often come from two topics, two clocks, two drivers: a torque stamped 5 ms late makes the
dynamics look like friction (a torque that leads the speed's derivative by d adds about -d M eta'' to the
equation, which a sinusoidal motion turns into viscous friction) and biases F_v by tens of per cent.

The estimate profiles the fit over the shift.  For each candidate delay d on a grid of DELAY_STEP_S over
[-span, span], the efforts are read d later than stamped, tau_log(t + d)
(:func:`wmrid.estimators.regression.idim_rows.shifted`), and
the
inverse-dynamics regression of :mod:`wmrid.estimators.regression.idim` (the same zero-phase filter, cutoff fixed once
from the log) is solved by least squares; its residual sum of squares RSS(d) is smallest at the delay that makes the
model fit best.  A parabola through the three grid points around the minimum refines it below the grid step.
Its standard error is the delete-a-segment jackknife of that minimiser: RSS(d) minus one segment's share,
minimised again, for each of G contiguous segments (:func:`wmrid.estimators.uncertainty.segment_count`); infinite
(the log does not pin the delay) when a replicate's minimum is at the edge of the search (:func:`_jackknife_std`).

``delay`` > 0: the logged effort is late (stamped after it acted); the correction reads it d earlier than
stamped.  Pure functions on arrays; no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from wmrid.core.errors import NotIdentifiableError, UsageError, WmridError
from wmrid.core.jit import kernel
from wmrid.estimators.findings import EstimatedDelay
from wmrid.estimators.uncertainty import interval_factor

#: Grid step of the profile, s (a fifth of a 1 kHz step would be finer than the refinement needs).
DELAY_STEP_S = 0.0005
#: Default half-width of the searched range, s.
DEFAULT_SPAN_S = 0.02
#: A delay is reported as significant beyond this many of its standard errors and beyond SIGNIFICANT_S.
SIGNIFICANT_Z = 3.0
SIGNIFICANT_S = 5e-4
#: The slow rows are left out of the profile unless fewer than this fraction of the rows would remain.
MIN_FAST = 0.3


@dataclass(frozen=True)
class DelayEstimate:
    """delay s (> 0: the effort is late), its jackknife std s, the profile (grid (m,) s, rss (m,)), G segments,
    and whether it is significant (|delay| > SIGNIFICANT_Z std and > SIGNIFICANT_S).  ``theta0_slope`` (8,):
    d theta0 / d delay (units of theta0 per s) at the estimate, how much a delay left in moves the parameters
    (:func:`unresolved_delay`): of the least-squares fits on the rows profiled and on every row, entry by entry the
    larger (against the observer's own slope on the light AMR: 0.8-2.4 times it on sinusoids, 0.8-1.9 reversing)."""

    delay: float
    std: float
    grid: np.ndarray
    rss: np.ndarray
    segments: int
    at_edge: bool
    theta0_slope: np.ndarray | None = None
    method: str = "least squares"
    #: Hz, the zero-phase filter's cutoff the profile used (IDIM's, chosen from the log unless given)
    cutoff_hz: float | None = None

    @property
    def determined(self) -> bool:
        """Whether the profile pins the delay: a finite std (every jackknife replicate's minimum, or by instrumental
        variables its root, inside the span) and, by instrumental variables, a root in the span."""
        return bool(math.isfinite(self.std) and math.isfinite(self.delay))

    @property
    def significant(self) -> bool:
        """|delay| beyond SIGNIFICANT_S and beyond the 99.73 % quantile of Student's t with G - 1 dof times its
        std (3.0 for a long log; 4.1 for a 4 s log of 10 segments, whose jackknife std is itself uncertain)."""
        return self.determined and abs(self.delay) > max(significance_factor(self.segments) * self.std, SIGNIFICANT_S)

    def record(self) -> EstimatedDelay:
        """The estimate as a result records it (:meth:`to_dict`'s figures)."""
        return EstimatedDelay.from_dict(self.to_dict())

    def to_dict(self) -> dict[str, Any]:
        return {
            "delay_s": self.delay if math.isfinite(self.delay) else None,
            "std_s": self.std if math.isfinite(self.std) else None, "significant": self.significant,
            "segments": self.segments, "at_edge_of_search": self.at_edge, "estimator": self.method,
            "meaning": "> 0: the efforts are stamped later than they acted (read them earlier by this much)",
        }  # fmt: skip


def significance_factor(segments: int, coverage: float = 0.9973) -> float:
    """Standard errors a delay must exceed: Student's t quantile at ``coverage`` with ``segments`` - 1 dof (the
    jackknife's), at least SIGNIFICANT_Z (the normal's 3)."""
    return max(SIGNIFICANT_Z, interval_factor(coverage, max(int(segments) - 1, 1)))


def _refine(grid: np.ndarray, rss: np.ndarray) -> tuple[float, bool]:
    """The minimiser of rss (m,) over grid (m,), refined by a parabola through its neighbours; and whether the
    minimum lies on the edge of the grid (then it is the edge, unrefined)."""
    i = int(np.argmin(rss))
    if i == 0 or i == len(grid) - 1:
        return float(grid[i]), True
    y0, y1, y2 = rss[i - 1], rss[i], rss[i + 1]
    den = y0 - 2.0 * y1 + y2
    step = grid[i + 1] - grid[i]
    offset = 0.5 * (y0 - y2) / den if den > 0 else 0.0
    return float(grid[i] + np.clip(offset, -1.0, 1.0) * step), False


def _jackknife_std(grid: np.ndarray, rss: np.ndarray, per_segment: np.ndarray) -> float:
    """s: the delete-a-segment jackknife std of the least-squares minimiser (:func:`_refine`) of ``rss`` (m,) over
    ``grid`` (m,), per_segment (m, G) its segments' shares; infinite when a replicate's minimum lies at the edge of
    the grid, as :func:`_iv_profile` makes it when a replicate has no root in the span.

    Why: a replicate at the edge is the edge, not its minimiser (the fit keeps improving beyond it), so the jackknife
    of clipped replicates understates the spread, and |d| / s is no evidence.  Measured on a 200 Hz reversing log of
    the light AMR on one clock (0.005 N m caster disturbance inside the loop, no reference, seed 7): +19.52 +/- 6.07
    ms profiled over +/-20 ms with 8 of 18 replicates at +20 ms (3.2 std: the unresolved-delay term carried 18.6 ms
    and grew F_v2's std 7.3 times), +20.81 +/- 10.86 ms over +/-40 ms, where none is (1.9 std: no evidence)."""
    g = per_segment.shape[1]
    loo = [_refine(grid, rss - per_segment[:, i]) for i in range(g)]
    if any(edge for _, edge in loo):
        return math.inf
    values = np.array([d for d, _ in loo])
    return float(np.sqrt((g - 1) / g * np.sum((values - values.mean()) ** 2)))


def estimate_delay(
    t: np.ndarray,
    eta: np.ndarray,
    tau: np.ndarray,
    *,
    span: float = DEFAULT_SPAN_S,
    torque_hold: str = "zoh",
    control_rate: float | None = None,
    cutoff_hz: float | None = None,
    reference: np.ndarray | None = None,
    form: Any = None,
) -> DelayEstimate:
    """The delay of the efforts behind the speeds, with its standard error (see the module docstring).

    t (n,) s, eta (n, 2) rad/s, tau (n, 2); span s: search [-span, span]; torque_hold, control_rate: how the
    effort was held (:func:`wmrid.estimators.regression.idim_rows.effort_delay`, applied on top of each candidate);
    cutoff_hz: the filter's (default: IDIM's, from the log, once:
    :func:`wmrid.estimators.regression.idim.fit_with_cutoff`). reference (n, 2) rad/s: the logged wheel-speed
    set-points; given, the delay is the root of an instrumental-variable moment (:func:`_iv_profile`), which a
    disturbance inside the feedback loop does not bias, instead of the least-squares minimiser.  form : the friction
    model profiled (a :class:`wmrid.model.dynamics.RegressorForm` with caster drag,
    :func:`wmrid.estimators.observer.observe.delay_profile_form`; None: the wheels' friction only).  Raises
    NotIdentifiableError when the log is too short.
    """
    # IDIM (~20 ms with its rows and checks): only a delay estimate
    from wmrid.estimators.regression.idim import fit_with_cutoff, segment_index
    from wmrid.estimators.regression.idim_checks import slow_rows  # IDIM's checks: only a delay estimate

    # IDIM's rows: only a delay estimate
    from wmrid.estimators.regression.idim_rows import MAX_EFFORT_SHIFT_S, default_cutoff, effort_delay, idim_regression

    if not (math.isfinite(span) and 0 < span <= MAX_EFFORT_SHIFT_S / 2):
        raise UsageError(f"the delay search span must be in (0, {MAX_EFFORT_SHIFT_S / 2:g}] s, got {span!r}")
    t = np.asarray(t, dtype=np.float64)
    eta = np.asarray(eta, dtype=np.float64)
    tau = np.asarray(tau, dtype=np.float64)
    hold = effort_delay(t, torque_hold, control_rate)
    if cutoff_hz is None:  # IDIM's: the default, lowered while the estimate moves with it (errors in variables)
        try:
            cutoff_hz = fit_with_cutoff(t, eta, tau, None, delay=hold, covariance=False)[0].cutoff_hz
        except NotIdentifiableError:
            cutoff_hz = default_cutoff(eta, (len(t) - 1) / max(t[-1] - t[0], 1e-300))
    n_steps = round(span / DELAY_STEP_S)
    grid = DELAY_STEP_S * np.arange(-n_steps, n_steps + 1)
    # The regressor does not depend on the candidate; the filtered effort does, by a shift only (the zero-phase
    # filter is time-invariant): the effort read d later than its hold, filtered, is the filtered effort read at
    # t + d.  So: one regression, its QR once, and per candidate the filtered effort interpolated at the kept
    # times (linear, between 1 kHz samples of a signal below 10 Hz: 1e-5 of it at most).
    reg = idim_regression(t, eta, tau, cutoff_hz, True, form=form, effort_delay=hold, keep_effort=True)
    assert reg.effort_grid is not None
    assert reg.t_grid is not None
    seg, g = segment_index(reg.t)
    # Near a stop the measured sgn(eta) flips with the noise and friction is least like the model: a shift of the
    # effort fits that error too (1.4 ms on a noisy reversing log), so those rows stay out.
    fast = ~slow_rows(reg, eta)
    if fast.sum() < MIN_FAST * len(fast):
        fast = np.ones(len(fast), dtype=bool)
    x = reg.rows()[fast]
    rows = x.reshape(-1, x.shape[2])
    q, r = np.linalg.qr(rows)
    times = reg.t[fast]
    if times[0] + grid[0] < reg.t_grid[0] or times[-1] + grid[-1] > reg.t_grid[-1]:
        raise NotIdentifiableError("the log is too short to profile the delay over the searched span")
    per_segment = np.zeros((len(grid), g))

    t_grid = np.ascontiguousarray(reg.t_grid, dtype=np.float64)
    effort_grid = np.ascontiguousarray(reg.effort_grid, dtype=np.float64)

    def effort(d: float, at: np.ndarray) -> np.ndarray:
        # a candidate delay d: the effort acted d before its stamp, i.e. it is read d later than its hold
        return interp_columns(np.ascontiguousarray(at, dtype=np.float64), float(d), t_grid, effort_grid).reshape(-1)

    for k, d in enumerate(grid):
        y = effort(d, times)
        resid = y - q @ (q.T @ y)
        r2 = (resid**2).reshape(-1, 2).sum(axis=1)  # per sample
        per_segment[k] = np.bincount(seg[fast], weights=r2, minlength=g)
    rss = per_segment.sum(axis=1)
    method = "least squares"
    iv = None
    if reference is not None:
        iv = _iv_profile(reg, fast, grid, lambda d: effort(d, times), t, reference, tau, seg[fast], g)
    if iv is not None:
        delay, std = iv
        at_edge = False
        method = "instrumental variables"
    else:
        delay, at_edge = _refine(grid, rss)
        std = _jackknife_std(grid, rss, per_segment)
    # the slope of theta0 in the delay, of the fit on the rows profiled and of the fit on every row (which the
    # observer's estimate, fitted on every sample, follows more closely on a reversing log), the larger of the two
    at = delay if math.isfinite(delay) else 0.0
    fast_slope = _theta0_slope(q, r, lambda d: effort(d, times), at)
    every = reg.rows().reshape(-1, x.shape[2])
    q_all, r_all = np.linalg.qr(every)
    all_slope = _theta0_slope(q_all, r_all, lambda d: effort(d, reg.t), at)
    slope = None
    if fast_slope is not None and all_slope is not None:
        slope = np.where(np.abs(fast_slope) >= np.abs(all_slope), fast_slope, all_slope)
    return DelayEstimate(
        delay=delay, std=std, grid=grid, rss=rss, segments=g, at_edge=at_edge, theta0_slope=slope, method=method,
        cutoff_hz=cutoff_hz,
    )  # fmt: skip


def _iv_profile(
    reg: Any, fast: np.ndarray, grid: np.ndarray, effort: Any, t: np.ndarray, reference: np.ndarray,
    tau: np.ndarray, seg: np.ndarray, g: int,
) -> tuple[float, float] | None:  # fmt: skip
    """(delay s, its jackknife std s) by instrumental variables, or None when the reference cannot serve (another
    shape, non-finite, or a first-stage R^2 below :data:`wmrid.estimators.regression.iv.MIN_R2`: it does not describe
    the motion).

    Why not least squares: inside a feedback loop the controller answers a disturbance d with an effort that lags it
    by about the loop's time constant (20 ms on the light AMR), so a shifted effort fits part of d, and the RSS
    profile's minimum moves towards that lag (to the edge of the +/-20 ms search, or -19.6 +/- 2.85 ms applied, on
    a 200 Hz AMR log on one clock).  The reference was set before the disturbance acted, so a moment built from it
    is not moved by d.  Model: the effort read d0 later, y(d0) = X phi + e, e uncorrelated with the instruments Z
    (the IDIM regressor rebuilt from the reference, :func:`wmrid.estimators.regression.iv.instrument_regression`).  For
    each candidate d, phi(d) = (Z^T X)^-1 Z^T y(d) (IDIM-IV) leaves one more instrument free to test the delay: w =
    dZ/dt phi(0), the derivative of the effort the reference predicts (a central difference over one logged step, at
    least 1 ms).  The moment m(d) = w^T (y(d) - X phi(d)) is zero at d0 up to noise and grows through it with slope
    w^T (I - X (Z^T X)^-1 Z^T) dy/dt, about |w|^2 less its part in the instruments' span, > 0: the delay is the grid
    interval where m rises through zero (linear interpolation), the one nearest 0 if several.  Its std: the
    delete-a-segment jackknife of that root (per-segment moments, no refit); infinite when the full log or a
    jackknife replicate has no root in the span, i.e. the log does not pin the delay.  On logs without a
    disturbance it agrees with least squares (5 ms late at 1 kHz: +4.96 +/- 0.07 ms against +4.96 +/- 0.07 ms)."""
    from wmrid.estimators.regression.idim_rows import shifted  # IDIM's rows: only a delay estimate

    # IDIM-IV: only a log with the wheel-speed reference
    from wmrid.estimators.regression.iv import MIN_R2, first_stage_r2, instrument_regression

    reference = np.asarray(reference, dtype=np.float64)
    if reference.shape != (len(t), 2) or not np.all(np.isfinite(reference)):
        return None
    try:
        z = instrument_regression(reg, t, reference, tau)
        h = max(1e-3, float(np.median(np.diff(t))))
        z_dot = (
            instrument_regression(reg, t, shifted(t, reference, -h), tau)
            - instrument_regression(reg, t, shifted(t, reference, h), tau)
        ) / (2 * h)
    except WmridError:
        return None
    x = reg.rows()
    if np.min(first_stage_r2(z, x, np.ones(2))) < MIN_R2:
        return None
    p = x.shape[2]
    xs, zs, zds = (a[fast].reshape(-1, p) for a in (x, z, z_dot))
    rows_seg = np.repeat(seg, 2)

    def per_segment(col: np.ndarray) -> np.ndarray:
        return np.bincount(rows_seg, weights=col, minlength=g)

    big_a = np.stack([np.stack([per_segment(zs[:, i] * xs[:, j]) for j in range(p)], axis=1) for i in range(p)], 1)
    try:
        phi0 = np.linalg.solve(big_a.sum(axis=0), zs.T @ effort(0.0))
    except np.linalg.LinAlgError:
        return None
    w = zds @ phi0
    small_a = np.stack([per_segment(w * xs[:, j]) for j in range(p)], axis=1)  # (g, p)
    big_b = np.empty((len(grid), g, p))
    small_c = np.empty((len(grid), g))
    for k, d in enumerate(grid):
        y = effort(d)
        big_b[k] = np.stack([per_segment(zs[:, j] * y) for j in range(p)], axis=1)
        small_c[k] = per_segment(w * y)

    def root(keep: np.ndarray) -> float:
        try:
            phi = np.linalg.solve(big_a[keep].sum(axis=0), big_b[:, keep].sum(axis=1).T).T  # (m, p)
        except np.linalg.LinAlgError:
            return math.nan
        m = small_c[:, keep].sum(axis=1) - phi @ small_a[keep].sum(axis=0)
        up = np.flatnonzero((m[:-1] < 0) & (m[1:] >= 0))
        if len(up) == 0:
            return math.nan
        k = int(up[np.argmin(np.abs(grid[up] + grid[up + 1]))])
        return float(grid[k] - m[k] * (grid[k + 1] - grid[k]) / (m[k + 1] - m[k]))

    every = np.ones(g, dtype=bool)
    delay = root(every)
    loo = np.empty(g)
    for i in range(g):
        keep = every.copy()
        keep[i] = False
        loo[i] = root(keep)
    if not (math.isfinite(delay) and np.all(np.isfinite(loo))):
        return delay, math.inf
    return delay, float(np.sqrt((g - 1) / g * np.sum((loo - loo.mean()) ** 2)))


def _theta0_slope(q: np.ndarray, r: np.ndarray, effort: Any, delay: float) -> np.ndarray | None:
    """d theta0 / d delay (8,) per s of the least-squares fit (rows = q r, efforts ``effort(d)``) at ``delay``, by a
    central difference over DELAY_STEP_S; None when R is singular or the slope is not finite."""
    from wmrid.estimators.regression.idim import phi_to_theta0, theta0_jacobian  # IDIM: only a delay estimate

    try:
        phi = np.linalg.solve(r, q.T @ effort(delay))
        dphi = np.linalg.solve(r, q.T @ (effort(delay + DELAY_STEP_S) - effort(delay - DELAY_STEP_S)))
    except np.linalg.LinAlgError:
        return None
    slope = theta0_jacobian(phi) @ (dphi / (2 * DELAY_STEP_S))
    return slope if np.all(np.isfinite(slope)) and np.all(np.isfinite(phi_to_theta0(phi))) else None


#: s: the resolution of an estimated delay that the std must carry at least (the multibody prototype's
#: contacts and load transfer put the delay of an on-time log at -0.39 ms, against a jackknife std of 0.07 ms).
DELAY_RESOLUTION_S = 5e-4


def combine(estimates: list[DelayEstimate]) -> DelayEstimate:
    """One estimate from those of consecutive windows of a log (the same delay all along it): the inverse-variance
    weighted mean and its std (1 / sqrt(sum 1/s_i^2)), the segments summed, at the edge when any window is, and
    undetermined (infinite std) when any window is; the first window's profile and slope."""
    first = estimates[0]
    if len(estimates) == 1:
        return first
    stds = np.array([e.std for e in estimates])
    delays = np.array([e.delay for e in estimates])
    segments = sum(e.segments for e in estimates)
    at_edge = any(e.at_edge for e in estimates)
    if not (np.all(np.isfinite(stds)) and np.all(np.isfinite(delays)) and np.all(stds > 0)):
        delay, std = float(np.mean(delays)), math.inf
    else:
        weights = 1.0 / stds**2
        delay, std = float(np.sum(weights * delays) / np.sum(weights)), float(1.0 / np.sqrt(np.sum(weights)))
    return DelayEstimate(
        delay=delay, std=std, grid=first.grid, rss=first.rss, segments=segments, at_edge=at_edge,
        theta0_slope=first.theta0_slope, method=first.method,
    )  # fmt: skip


@kernel
def interp_columns(at: np.ndarray, d: float, xp: np.ndarray, fp: np.ndarray) -> np.ndarray:  # pragma: no cover
    """The columns of fp (m, 2), sampled at xp (m,) increasing, read at at + d (at (n,) increasing): numpy.interp's
    value bit for bit (its slope times the step from the knot below, the end values outside, the knot's own value on
    a knot; tested against it), each point's knot found from where evenly spaced knots would put it, then walked to.
    The delay's profile reads the efforts so at each of its candidates (half its time on an hour's log with numpy)."""
    n = at.shape[0]
    m = xp.shape[0]
    out = np.empty((n, 2))
    per_span = (m - 1) / (xp[m - 1] - xp[0]) if m > 1 and xp[m - 1] > xp[0] else 0.0
    for i in range(n):
        x = at[i] + d
        if np.isnan(x):
            out[i, 0] = x
            out[i, 1] = x
            continue
        if x < xp[0]:
            out[i, 0] = fp[0, 0]
            out[i, 1] = fp[0, 1]
            continue
        if x > xp[m - 1]:
            out[i, 0] = fp[m - 1, 0]
            out[i, 1] = fp[m - 1, 1]
            continue
        # the last knot at or below x, walked to from where evenly spaced knots would put it (the profile's knots
        # are: one step or none, however far apart the points of ``at``)
        j = min(max(int((x - xp[0]) * per_span), 0), m - 1)
        while j + 1 < m and xp[j + 1] <= x:
            j += 1
        while j > 0 and xp[j] > x:
            j -= 1
        for c in range(2):
            if j == m - 1 or xp[j] == x:
                out[i, c] = fp[j, c]
                continue
            slope = (fp[j + 1, c] - fp[j, c]) / (xp[j + 1] - xp[j])
            value = slope * (x - xp[j]) + fp[j, c]
            if np.isnan(value):
                value = slope * (x - xp[j + 1]) + fp[j + 1, c]
                if np.isnan(value) and fp[j, c] == fp[j + 1, c]:
                    value = fp[j, c]
            out[i, c] = value
    return out
