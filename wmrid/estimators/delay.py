"""The delay between a log's effort and speed signals, estimated from the log (issue 12, timing).

Efforts and speeds often come from two topics, two clocks, two drivers: a torque stamped 5 ms late makes the
dynamics look like friction (a torque that leads the speed's derivative by d adds about -d M eta'' to the
equation, which a sinusoidal motion turns into viscous friction) and biases F_v by tens of per cent.

The estimate profiles the fit over the shift.  For each candidate delay d on a grid of DELAY_STEP_S over
[-span, span], the efforts are read d later than stamped, tau_log(t + d)
(:func:`wmrid.estimators.idim_regression.shifted`), and
the
inverse-dynamics regression of :mod:`wmrid.estimators.idim` (the same zero-phase filter, cutoff fixed once from the log)
is solved by least squares; its residual sum of squares RSS(d) is smallest at the delay that makes the model
fit best.  A parabola through the three grid points around the minimum refines it below the grid step.
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

from wmrid.core.errors import NotIdentifiableError, UsageError, WmridError, option

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
    from wmrid.estimators.uncertainty import interval_factor

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
    effort was held (:func:`wmrid.estimators.idim_regression.effort_delay`, applied on top of each candidate);
    cutoff_hz: the filter's (default: IDIM's, from the log, once: :func:`wmrid.estimators.idim.fit_with_cutoff`).
    reference (n, 2) rad/s: the logged wheel-speed set-points; given, the delay is the root of an instrumental-variable
    moment (:func:`_iv_profile`), which a disturbance inside the feedback loop does not bias, instead of the
    least-squares minimiser.  form : the friction model profiled (a :class:`wmrid.model.dynamics.RegressorForm` with
    caster drag, :func:`wmrid.estimators.observer_pass.delay_profile_form`; None: the wheels' friction only).  Raises
    NotIdentifiableError when the log is too short.
    """
    from wmrid.estimators.idim import fit_with_cutoff, segment_index
    from wmrid.estimators.idim_checks import slow_rows
    from wmrid.estimators.idim_regression import MAX_EFFORT_SHIFT_S, default_cutoff, effort_delay, idim_regression

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

    def effort(d: float, at: np.ndarray) -> np.ndarray:
        # a candidate delay d: the effort acted d before its stamp, i.e. it is read d later than its hold
        return np.column_stack([np.interp(at + d, reg.t_grid, reg.effort_grid[:, j]) for j in range(2)]).reshape(-1)

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
        delay=delay, std=std, grid=grid, rss=rss, segments=g, at_edge=at_edge, theta0_slope=slope, method=method
    )  # fmt: skip


def _iv_profile(
    reg: Any, fast: np.ndarray, grid: np.ndarray, effort: Any, t: np.ndarray, reference: np.ndarray,
    tau: np.ndarray, seg: np.ndarray, g: int,
) -> tuple[float, float] | None:  # fmt: skip
    """(delay s, its jackknife std s) by instrumental variables, or None when the reference cannot serve (another
    shape, non-finite, or a first-stage R^2 below :data:`wmrid.estimators.iv.MIN_R2`: it does not describe the motion).

    Why not least squares: inside a feedback loop the controller answers a disturbance d with an effort that lags it
    by about the loop's time constant (20 ms on the light AMR), so a shifted effort fits part of d, and the RSS
    profile's minimum moves towards that lag (to the edge of the +/-20 ms search, or -19.6 +/- 2.85 ms applied, on
    a 200 Hz AMR log on one clock).  The reference was set before the disturbance acted, so a moment built from it
    is not moved by d.  Model: the effort read d0 later, y(d0) = X phi + e, e uncorrelated with the instruments Z
    (the IDIM regressor rebuilt from the reference, :func:`wmrid.estimators.iv.instrument_regression`).  For each
    candidate d, phi(d) = (Z^T X)^-1 Z^T y(d) (IDIM-IV) leaves one more instrument free to test the delay: w = dZ/dt
    phi(0), the derivative of the effort the reference predicts (a central difference over one logged step, at
    least 1 ms).  The moment m(d) = w^T (y(d) - X phi(d)) is zero at d0 up to noise and grows through it with slope
    w^T (I - X (Z^T X)^-1 Z^T) dy/dt, about |w|^2 less its part in the instruments' span, > 0: the delay is the grid
    interval where m rises through zero (linear interpolation), the one nearest 0 if several.  Its std: the
    delete-a-segment jackknife of that root (per-segment moments, no refit); infinite when the full log or a
    jackknife replicate has no root in the span, i.e. the log does not pin the delay.  On logs without a
    disturbance it agrees with least squares (5 ms late at 1 kHz: +4.96 +/- 0.07 ms against +4.96 +/- 0.07 ms)."""
    from wmrid.estimators.idim_regression import shifted
    from wmrid.estimators.iv import MIN_R2, first_stage_r2, instrument_regression

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
    from wmrid.estimators.idim import phi_to_theta0, theta0_jacobian

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


def faster_controller(est: Any, t: np.ndarray, torque_hold: str, control_rate: float | None) -> bool:
    """Whether a significant delay estimate ``est`` (:class:`wmrid.estimators.delay.DelayEstimate`) is the signature
    of a
    controller faster than the log rather than of two clocks: under the default hold over each logged step (zoh,
    no --control-rate) the efforts act half a step after their stamps, while a faster controller's act after
    half of its own, shorter period; the estimate then lies between 0 and half a logged step (within 2 std).
    Measured on multibody logs of a 1 kHz controller at 100 Hz: 3.9-5.8 ms, half a step being 5 ms."""
    if torque_hold != "zoh" or control_rate is not None or len(t) < 2:
        return False
    half = 0.5 * float(np.median(np.diff(np.asarray(t, dtype=np.float64))))
    return -2 * est.std < est.delay <= half + 2 * est.std


#: Hz: a log slower than this whose controller rate is unknown has its hold uncertain (:func:`timing_check`): its
#: half step is more than 1.25 ms, beyond DELAY_RESOLUTION_S even against a 1 kHz controller's half period.
SLOW_LOG_HZ = 400.0
#: The timing check profiles at most this many samples from the start of a log (200 s at 1 kHz): a clock offset or a
#: controller's hold is the same all along a log, and 40 s already pin it to 0.07 ms; memory and time stay bounded.
TIMING_WINDOW_SAMPLES = 200_000


def search_span(t: np.ndarray) -> float:
    """s: the delay search's half-width for a log with times t (n,) s: DEFAULT_SPAN_S, or 1.2 logged steps when
    longer (a slow log's held effort can lag its stamp by half a step: 25 ms at 20 Hz)."""
    step = float(np.median(np.diff(t))) if len(t) > 1 else 0.0
    return max(DEFAULT_SPAN_S, 1.2 * step)


def faster_controller_text(est: Any, t: np.ndarray) -> str:
    """The warning for a faster controller found by ``est`` on a log with times t (n,) s."""
    half = 0.5 * float(np.median(np.diff(t)))
    return (
        f"the efforts act {max(half - est.delay, 0.0) * 1e3:.2f} +/- {est.std * 1e3:.2f} ms after their "
        f"stamps, not half a logged step ({half * 1e3:.3g} ms) as an effort held over each step would: a "
        "controller faster than the log set them (the log holds one of its updates per step); give "
        "--control-rate HZ (e.g. 1000 for a 1 kHz loop) or --torque-hold foh"
    )


def timing_check(
    log: Any, torque_hold: str, control_rate: float | None, samples: int, median_step: float, form: Any = None
) -> dict[str, Any]:
    """The record for ``diagnostics["timing"]``: the efforts' delay estimated from the log (:func:`estimate_delay`,
    searched over +/- max(DEFAULT_SPAN_S, 1.2 logged steps), under the given hold), for identify's default timing.

    Keys: "checked"; the estimate (:meth:`DelayEstimate.to_dict`; by instrumental variables when the log carries the
    wheel-speed reference, else least squares); "apply": significant and not at the edge of the search (identify
    then identifies with ``delay="auto"``); "slow": the log is slower than SLOW_LOG_HZ; "faster_controller":
    :func:`faster_controller` (the warning of :func:`apply_delay` then names --control-rate).
    Measured on the light AMR (1 kHz controller, noise): 5 ms late or early at 1 kHz found within 0.1 ms on the
    sinusoid; a 100 Hz log 4.5 ms of the 5 ms half step, a 20 Hz log 24.6 of 25 ms.  The profile costs one
    regression (0.03 s for 40 s at 1 kHz) per window of at most TIMING_WINDOW_SAMPLES samples, read piece by piece
    (``samples`` and ``median_step`` s come from the survey); a longer log is profiled window by window and the
    windows' estimates combined by their inverse variances (:func:`combine`), so the delay's std keeps shrinking
    as 1/sqrt(T) with the log's length.  A log that cannot be profiled (a hole, too short for the filter) is not
    checked, and the record says why.  ``form``: the friction model profiled (:func:`estimate_delay`)."""
    from wmrid.core.errors import WmridError
    from wmrid.core.wheel_log import LogStream

    slow = bool(median_step > 0 and 1.0 / median_step < SLOW_LOG_HZ)
    none = {"checked": False, "apply": False, "slow": slow, "faster_controller": False}
    if samples < 2:
        return {**none, "why": f"{samples} samples"}
    count = math.ceil(samples / TIMING_WINDOW_SAMPLES)
    size = math.ceil(samples / count)

    def profile(with_form: Any) -> tuple[DelayEstimate, int, int, np.ndarray]:
        estimates: list[DelayEstimate] = []
        profiled = 0
        first_t = None
        for t, eta, tau, reference in _windows(log if isinstance(log, LogStream) else None, log, size):
            if estimates and len(t) < size // 2:  # a short tail adds little and may not fit the filter
                break
            try:
                est = estimate_delay(
                    t, eta, tau, span=search_span(t), torque_hold=torque_hold, control_rate=control_rate,
                    reference=reference, form=with_form,
                )  # fmt: skip
            except WmridError:
                if not estimates:
                    raise
                break
            estimates.append(est)
            profiled += len(t)
            first_t = t if first_t is None else first_t
        assert first_t is not None
        return combine(estimates), profiled, len(estimates), first_t

    try:
        wheel, profiled, windows, first_t = profile(None)
    except WmridError as err:
        return {**none, "why": str(err)}
    drag = None
    if form is not None and consults_drag(wheel):
        try:
            drag = profile(form)[0]
        except WmridError:
            drag = None
    est, note = with_drag(wheel, drag, form)
    apply = bool(est.significant and not est.at_edge)
    faster = bool(apply and faster_controller(est, first_t, torque_hold, control_rate))
    window = {"samples_profiled": profiled, "of": int(samples), "windows": windows}
    # the eight base parameters' slope (a caster model profiled has its drag after them, named by its own form)
    slope = {"theta0_slope_per_s": est.theta0_slope[:8].tolist()} if est.theta0_slope is not None else {}
    record = {"checked": True, **est.to_dict(), "apply": apply, "slow": slow, "faster_controller": faster, **window}
    if drag is not None:
        record["profiled_with"] = form.friction if est is drag else "wheel"
        record["wheel_model"] = wheel.to_dict()
    if note:
        record["note"] = note
    return {**record, **slope}


def consults_drag(wheel: DelayEstimate) -> bool:
    """Whether the timing needs the profile with the casters' drag too (:func:`with_drag`): the wheels' friction alone
    found a significant delay, which an undescribed drag can fake."""
    return bool(wheel.significant and not wheel.at_edge)


def with_drag(wheel: DelayEstimate, drag: DelayEstimate | None, form: Any) -> tuple[DelayEstimate, str | None]:
    """The estimate the timing rests on, from the profile with the wheels' friction alone (``wheel``) and, when
    :func:`consults_drag`, the profile with the casters' drag too (``drag``, of friction model ``form``; None: not run
    or failed).  A drag the profile leaves out is fitted by shifting the efforts, so a significant delay stands only
    when the drag's profile finds it too (its figure is then the one applied); otherwise the drag's profile is the
    record, nothing is applied, and the note says why.  The check only ever vetoes: a wheels' profile that is not
    significant, or runs to the edge of its search, is kept as it is, because a delay only the drag's profile shows
    can be its own misfit (the light AMR reversing on MuJoCo, on time, came out 5.6 ms late with the casters'
    two-term model).  Returns (estimate, note or None).

    Measured (MuJoCo, the paper robot with its two ball casters, whose drag is about five times the wheels' Coulomb
    friction; speed noise 0.02 rad/s, no delay): on its 60 s plan the wheels' profile put the efforts 18.5 +/- 2.4 ms
    late, "significant" (identify applied it: S 132, every parameter poorly determined); with the casters' load model
    0.04 +/- 0.11 ms.  REGBOT's wheels' profile is determined and not significant (+6.62 +/- 1.64 ms): timed as
    before."""
    if drag is None or not consults_drag(wheel):
        return wheel, None
    if drag.significant and not drag.at_edge:
        return drag, None
    found = f"{drag.delay * 1e3:+.2f} +/- {drag.std * 1e3:.2f} ms" if drag.determined else "not pinned"
    return drag, (
        f"with the wheels' friction alone the efforts appear {wheel.delay * 1e3:+.2f} +/- {wheel.std * 1e3:.2f} ms "
        f"late, but with the casters' drag modelled ({form.friction}) the delay is {found}: the undescribed drag, "
        "not a delay, so the efforts are used as stamped"
    )


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


#: A delay the timing check could not resolve is carried by the std when it would move some parameter by more
#: than this many of its std (the std then grows by more than 4 %); below, the extra identification is skipped.
MATERIAL_SHIFT = 0.3
#: Coverage of the evidence a delay left unapplied needs before the std carries it (Student's t with the profile's
#: G - 1 dof: |d| beyond about 2 std).
CARRY_COVERAGE = 0.95


def unresolved_delay(record: dict[str, Any], theta0_std: np.ndarray) -> float | None:
    """The delay s whose effect the std must carry when the timing check (``record``, :func:`timing_check`) left the
    efforts as stamped: sign(d) sqrt(d^2 - s^2), the unbiased estimate of the delay's size when the log puts it at
    d +/- s (E[d^2] = delta^2 + s^2), when the log gives evidence of a delay: |d| beyond the t quantile at
    CARRY_COVERAGE (about 2 std) but not significant.  None when the check applied its delay, did not run, ended at
    the edge of its search or did not pin the delay (an infinite std), when the log shows no such evidence, when it
    rules out a significant delay (|d| + SIGNIFICANT_Z s <= SIGNIFICANT_S: below the resolution the check applies),
    or when that delay would move no parameter by MATERIAL_SHIFT of its std ``theta0_std`` (n0,) (judged by the
    profile's slope, ``theta0_slope_per_s``).

    Why: a delay below significance is not applied, but on a log that times its efforts poorly (a slow reversing
    motion with torque noise: std 1-1.6 ms) a 5 ms delay can fall below it and bias the friction by 7 % at 5 std,
    with nothing said.  Why not sqrt(d^2 + s^2), what this carried before issue 28: on a log on one clock it
    carried a delay of the size of its std on every log, so the std of a log that pins its delay poorly (a 200 Hz
    reversing log with a disturbance inside the loop: s of 5-45 ms) grew 4-5 times against --delay 0; on a log
    with no delay the term now comes in 5 % of logs, and where it does its size, like s, shrinks as 1/sqrt(T)."""
    from wmrid.estimators.uncertainty import interval_factor

    if not record.get("checked") or record.get("apply") or record.get("at_edge_of_search"):
        return None
    slope = record.get("theta0_slope_per_s")
    d, s = record.get("delay_s"), record.get("std_s")
    if slope is None or d is None or s is None or not (math.isfinite(d) and math.isfinite(s)):
        return None
    d, s = float(d), float(s)
    if abs(d) + SIGNIFICANT_Z * s <= SIGNIFICANT_S:
        return None  # the log rules out any delay the check would call significant
    if abs(d) <= interval_factor(CARRY_COVERAGE, max(int(record.get("segments", 2)) - 1, 1)) * s:
        return None  # no evidence of a delay
    size = math.sqrt(d * d - s * s)
    slope = np.asarray(slope, dtype=float)
    std = np.asarray(theta0_std, dtype=float)[: len(slope)]
    with np.errstate(divide="ignore", invalid="ignore"):
        shift = np.abs(size * slope[: len(std)]) / std
    if not np.any(np.isfinite(shift) & (shift > MATERIAL_SHIFT)):
        return None
    return math.copysign(size, d)


def unresolved_text(record: dict[str, Any], moved: float) -> str:
    """The warning for an unresolved delay (:func:`unresolved_delay`) ``moved`` s, the timing check's ``record``."""
    return (
        f"the efforts' timing against the speeds is uncertain: the log puts their delay at "
        f"{record['delay_s'] * 1e3:+.2f} +/- {record['std_s'] * 1e3:.2f} ms, not distinguishable from none, so they "
        f"were used as stamped; what a delay of {moved * 1e3:+.2f} ms would change was added to the std. Give "
        "--delay 0 if the two clocks are known to agree (or --delay SECONDS if the offset is known)"
    )


def _window(stream: Any, log: Any, most: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(t (m,), eta (m, 2), tau (m, 2)): the first ``most`` samples of a log, from the stream's pieces when it is a
    :class:`wmrid.core.wheel_log.LogStream` (read no further), else sliced from the log in memory."""
    t, eta, tau, _ = next(_windows(stream, log, most))
    return t, eta, tau


def _reference_of(log: Any, n: int) -> np.ndarray | None:
    """The log's wheel-speed reference (n, 2) when it has one of that shape (a simulator's ``reference`` may be a
    pose), else None."""
    ref = getattr(log, "reference", None)
    if ref is None:
        return None
    ref = np.asarray(ref, dtype=np.float64)
    return ref if ref.shape == (n, 2) else None


def _windows(stream: Any, log: Any, size: int) -> Any:
    """Consecutive windows (t, eta, tau, reference or None) of at most ``size`` samples covering a log, from the
    stream's pieces when it is a :class:`wmrid.core.wheel_log.LogStream` (read piece by piece; one window in
    memory at a time), else sliced from the log in memory."""
    if stream is None:
        arrays = [np.asarray(a, dtype=np.float64) for a in (log.t, log.eta, log.tau)]
        reference = _reference_of(log, len(arrays[0]))
        for start in range(0, len(arrays[0]), size):
            cut = slice(start, start + size)
            yield (*(a[cut] for a in arrays), None if reference is None else reference[cut])
        return
    parts: list[Any] = []
    count = 0

    def window(parts: list[Any]) -> tuple[Any, ...]:
        t = np.concatenate([p.t for p in parts]).astype(np.float64)
        eta = np.concatenate([p.eta for p in parts]).astype(np.float64)
        tau = np.concatenate([p.tau for p in parts]).astype(np.float64)
        refs = [getattr(p, "reference", None) for p in parts]
        reference = None
        if all(r is not None for r in refs):
            reference = np.concatenate(refs).astype(np.float64)
            reference = reference if reference.shape == (len(t), 2) else None
        return t, eta, tau, reference

    for piece in stream:
        parts.append(piece)
        count += len(piece.t)
        while count >= size:
            t, eta, tau, reference = window(parts)
            ref_head = ref_rest = None
            if reference is not None:
                ref_head, ref_rest = reference[:size], reference[size:]
            yield t[:size], eta[:size], tau[:size], ref_head
            rest = t[size:]
            parts = [] if len(rest) == 0 else [_Piece(rest, eta[size:], tau[size:], ref_rest)]
            count = len(rest)
    if count:
        yield window(parts)


@dataclass(frozen=True)
class _Piece:
    """What :func:`_windows` carries over from one window to the next."""

    t: np.ndarray
    eta: np.ndarray
    tau: np.ndarray
    reference: np.ndarray | None


def apply_delay(
    log: Any, delay: float | str, torque_hold: str, control_rate: float | None, form: Any = None
) -> tuple[Any, dict[str, Any], list[str]]:
    """(the log in memory with its efforts read ``delay`` s earlier, the record for ``diagnostics["delay"]``,
    warnings) for :func:`wmrid.pipeline.identify.identify`.

    ``delay``: seconds, or "auto" (:func:`estimate_delay`; applied only when significant and not at the edge
    of the search; ``form`` the friction model profiled).  The warnings name the likely cause: two clocks, or a
    controller faster than the log."""
    from wmrid.core.wheel_log import LogStream, WheelLog
    from wmrid.estimators.idim_regression import MAX_EFFORT_SHIFT_S, shifted

    whole = log.read() if isinstance(log, LogStream) else log
    t = np.asarray(whole.t, dtype=np.float64)
    eta = np.asarray(whole.eta, dtype=np.float64)
    tau = np.asarray(whole.tau, dtype=np.float64)
    source = getattr(whole, "source", "log")
    warnings: list[str] = []
    if delay == "auto":
        common = {
            "span": search_span(t), "torque_hold": torque_hold, "control_rate": control_rate,
            "reference": _reference_of(whole, len(t)),
        }  # fmt: skip
        wheel = estimate_delay(t, eta, tau, **common)
        drag = None
        if form is not None and consults_drag(wheel):
            try:
                drag = estimate_delay(t, eta, tau, form=form, **common)
            except WmridError:
                drag = None
        est, note = with_drag(wheel, drag, form)
        record = {"chosen_by": "auto", **est.to_dict()}
        if drag is not None:
            record["profiled_with"] = form.friction if est is drag else "wheel"
            record["wheel_model"] = wheel.to_dict()
        if note:
            warnings.append(note)
        applied = est.delay if est.significant and not est.at_edge else 0.0
        if est.at_edge:
            warnings.append(
                f"the delay between efforts and speeds could not be estimated (the fit keeps improving to the edge of "
                f"the searched +/-{abs(est.grid[0]) * 1e3:g} ms): the model does not fit this log well enough to time "
                "it; the efforts are used as stamped"
            )
        elif not est.determined:
            why = (
                "the instrumental-variable moment of the logged reference does not cross zero within the searched "
                f"+/-{abs(est.grid[0]) * 1e3:g} ms"
                if est.method == "instrumental variables"
                else "the fit on part of the log keeps improving to the edge of the searched "
                f"+/-{abs(est.grid[0]) * 1e3:g} ms"
            )
            warnings.append(
                f"the delay between efforts and speeds could not be estimated ({why}): this log does not pin it; the "
                "efforts are used as stamped"
            )
        elif est.significant and faster_controller(est, t, torque_hold, control_rate):
            warnings.append(
                f"{faster_controller_text(est, t)}.  This run read them {est.delay * 1e3:.2f} ms later than the hold "
                f"assumes (--delay {est.delay:.5f})"
            )
        elif est.significant:
            half = 0.5 * float(np.median(np.diff(t)))
            cause = "two topics or clocks?"
            if abs(est.delay + half) <= max(2 * est.std, 0.2 * half):
                cause = "half a logged step: speeds computed as backward differences of encoder counts lag by that much"
            warnings.append(
                f"the efforts appear stamped {est.delay * 1e3:+.2f} +/- {est.std * 1e3:.2f} ms late against the "
                f"speeds ({cause}): they were read that much earlier (--delay "
                f"{est.delay:.5f}); a delay left in biases the friction by tens of per cent"
            )
    else:
        applied = float(delay)
        if not (math.isfinite(applied) and abs(applied) <= MAX_EFFORT_SHIFT_S):
            raise UsageError(
                f"{option('delay')} must be auto or seconds within +/-{MAX_EFFORT_SHIFT_S:g}, got {delay!r}"
            )
        record = {"chosen_by": "--delay"}
    record["applied_s"] = applied
    if applied == 0.0:
        return whole, record, warnings
    shifted_log = WheelLog(
        t=t, eta=eta, tau=shifted(t, tau, -applied), source=source, notes=tuple(getattr(whole, "notes", ())),
        effort_unit=getattr(whole, "effort_unit", "N m"), pose=getattr(whole, "pose", None),
        reference=getattr(whole, "reference", None),
    )  # fmt: skip
    return shifted_log, record, warnings
