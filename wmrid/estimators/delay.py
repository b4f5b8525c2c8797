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
minimised again, for each of G contiguous segments (:func:`wmrid.estimators.uncertainty.segment_count`).

``delay`` > 0: the logged effort is late (stamped after it acted); the correction reads it d earlier than
stamped.  Pure functions on arrays; no I/O.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from wmrid.core.errors import NotIdentifiableError, UsageError, option

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

    @property
    def significant(self) -> bool:
        return abs(self.delay) > max(SIGNIFICANT_Z * self.std, SIGNIFICANT_S)

    def to_dict(self) -> dict[str, Any]:
        return {
            "delay_s": self.delay, "std_s": self.std, "significant": self.significant, "segments": self.segments,
            "at_edge_of_search": self.at_edge,
            "meaning": "> 0: the efforts are stamped later than they acted (read them earlier by this much)",
        }  # fmt: skip


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


def estimate_delay(
    t: np.ndarray,
    eta: np.ndarray,
    tau: np.ndarray,
    *,
    span: float = DEFAULT_SPAN_S,
    torque_hold: str = "zoh",
    control_rate: float | None = None,
    cutoff_hz: float | None = None,
) -> DelayEstimate:
    """The delay of the efforts behind the speeds, with its standard error (see the module docstring).

    t (n,) s, eta (n, 2) rad/s, tau (n, 2); span s: search [-span, span]; torque_hold, control_rate: how the
    effort was held (:func:`wmrid.estimators.idim_regression.effort_delay`, applied on top of each candidate);
    cutoff_hz: the filter's (default: IDIM's, from the log, once: :func:`wmrid.estimators.idim.fit_with_cutoff`).
    Raises NotIdentifiableError when the log is too short.
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
            cutoff_hz = fit_with_cutoff(t, eta, tau, None, delay=hold)[0].cutoff_hz
        except NotIdentifiableError:
            cutoff_hz = default_cutoff(eta, (len(t) - 1) / max(t[-1] - t[0], 1e-300))
    n_steps = round(span / DELAY_STEP_S)
    grid = DELAY_STEP_S * np.arange(-n_steps, n_steps + 1)
    # The regressor does not depend on the candidate; the filtered effort does, by a shift only (the zero-phase
    # filter is time-invariant): the effort read d later than its hold, filtered, is the filtered effort read at
    # t + d.  So: one regression, its QR once, and per candidate the filtered effort interpolated at the kept
    # times (linear, between 1 kHz samples of a signal below 10 Hz: 1e-5 of it at most).
    reg = idim_regression(t, eta, tau, cutoff_hz, True, effort_delay=hold, keep_effort=True)
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
    delay, at_edge = _refine(grid, rss)
    g = per_segment.shape[1]
    loo = np.array([_refine(grid, rss - per_segment[:, i])[0] for i in range(g)])
    std = float(np.sqrt((g - 1) / g * np.sum((loo - loo.mean()) ** 2)))
    # the slope of theta0 in the delay, of the fit on the rows profiled and of the fit on every row (which the
    # observer's estimate, fitted on every sample, follows more closely on a reversing log), the larger of the two
    fast_slope = _theta0_slope(q, r, lambda d: effort(d, times), delay)
    every = reg.rows().reshape(-1, x.shape[2])
    q_all, r_all = np.linalg.qr(every)
    all_slope = _theta0_slope(q_all, r_all, lambda d: effort(d, reg.t), delay)
    slope = None
    if fast_slope is not None and all_slope is not None:
        slope = np.where(np.abs(fast_slope) >= np.abs(all_slope), fast_slope, all_slope)
    return DelayEstimate(
        delay=delay, std=std, grid=grid, rss=rss, segments=g, at_edge=at_edge, theta0_slope=slope
    )  # fmt: skip


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
    log: Any, torque_hold: str, control_rate: float | None, samples: int, median_step: float
) -> dict[str, Any]:
    """The record for ``diagnostics["timing"]``: the efforts' delay estimated from the log (:func:`estimate_delay`,
    searched over +/- max(DEFAULT_SPAN_S, 1.2 logged steps), under the given hold), for identify's default timing.

    Keys: "checked"; the estimate (:meth:`DelayEstimate.to_dict`); "apply": significant and not at the edge of the
    search (identify then identifies with ``delay="auto"``); "slow": the log is slower than SLOW_LOG_HZ;
    "faster_controller": :func:`faster_controller` (the warning of :func:`apply_delay` then names --control-rate).
    Measured on the light AMR (1 kHz controller, noise): 5 ms late or early at 1 kHz found within 0.1 ms on the
    sinusoid; a 100 Hz log 4.5 ms of the 5 ms half step, a 20 Hz log 24.6 of 25 ms.  The profile costs one
    regression (0.03 s for 40 s at 1 kHz) on at most the first TIMING_WINDOW_SAMPLES samples, read piece by piece
    (``samples`` and ``median_step`` s come from the survey).  A log that cannot be profiled (a hole, too short
    for the filter) is not checked, and the record says why."""
    from wmrid.core.errors import WmridError
    from wmrid.core.wheel_log import LogStream

    slow = bool(median_step > 0 and 1.0 / median_step < SLOW_LOG_HZ)
    none = {"checked": False, "apply": False, "slow": slow, "faster_controller": False}
    if samples < 2:
        return {**none, "why": f"{samples} samples"}
    t, eta, tau = _window(log if isinstance(log, LogStream) else None, log, TIMING_WINDOW_SAMPLES)
    try:
        est = estimate_delay(
            t, eta, tau, span=search_span(t), torque_hold=torque_hold, control_rate=control_rate
        )  # fmt: skip
    except WmridError as err:
        return {**none, "why": str(err)}
    apply = bool(est.significant and not est.at_edge)
    faster = bool(apply and faster_controller(est, t, torque_hold, control_rate))
    window = {"samples_profiled": len(t), "of": int(samples)}
    slope = {"theta0_slope_per_s": est.theta0_slope.tolist()} if est.theta0_slope is not None else {}
    record = {"checked": True, **est.to_dict(), "apply": apply, "slow": slow, "faster_controller": faster, **window}
    return {**record, **slope}


#: A delay the timing check could not resolve is carried by the std when it would move some parameter by more
#: than this many of its std (the std then grows by more than 4 %); below, the extra identification is skipped.
MATERIAL_SHIFT = 0.3


def unresolved_delay(record: dict[str, Any], theta0_std: np.ndarray) -> float | None:
    """The delay s whose effect the std must carry when the timing check (``record``, :func:`timing_check`) left the
    efforts as stamped: sign(d) sqrt(d^2 + s^2), the root-mean-square error of taking the delay as 0 when the log
    puts it at d +/- s; None when the check applied its delay, did not run, ended at the edge of its search, when
    the log rules out a significant delay (|d| + SIGNIFICANT_Z s <= SIGNIFICANT_S: what is left is below the
    resolution the check applies, and carrying it grew V_c's std 1.4-1.9 times on every well-specified log of the
    paper's robot, whose delay it pins to 0.03-0.07 ms), or when that delay would move no parameter by
    MATERIAL_SHIFT of its std ``theta0_std`` (n0,) (judged by the profile's slope, ``theta0_slope_per_s``).

    Why: a delay below SIGNIFICANT_Z std is not applied, but on a log that times its efforts poorly (a slow
    reversing motion with torque noise: std 1-1.6 ms) a 5 ms delay can fall below that and bias the friction by 7 %
    at 5 std, with nothing said."""
    if not record.get("checked") or record.get("apply") or record.get("at_edge_of_search"):
        return None
    slope = record.get("theta0_slope_per_s")
    d, s = float(record.get("delay_s", 0.0)), float(record.get("std_s", 0.0))
    if slope is None or not (math.isfinite(d) and math.isfinite(s)):
        return None
    if abs(d) + SIGNIFICANT_Z * s <= SIGNIFICANT_S:
        return None  # the log rules out any delay the check would call significant
    size = math.hypot(d, s)
    slope = np.asarray(slope, dtype=float)
    std = np.asarray(theta0_std, dtype=float)[: len(slope)]
    with np.errstate(divide="ignore", invalid="ignore"):
        shift = np.abs(size * slope[: len(std)]) / std
    if not np.any(np.isfinite(shift) & (shift > MATERIAL_SHIFT)):
        return None
    return math.copysign(size, d) if d else size


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
    if stream is None:
        return tuple(np.asarray(a, dtype=np.float64)[:most] for a in (log.t, log.eta, log.tau))  # type: ignore[return-value]
    parts: list[Any] = []
    count = 0
    for piece in stream:
        parts.append(piece)
        count += len(piece.t)
        if count >= most:
            break
    t = np.concatenate([p.t for p in parts])[:most]
    eta = np.concatenate([p.eta for p in parts])[:most]
    tau = np.concatenate([p.tau for p in parts])[:most]
    return t.astype(np.float64), eta.astype(np.float64), tau.astype(np.float64)


def apply_delay(
    log: Any, delay: float | str, torque_hold: str, control_rate: float | None
) -> tuple[Any, dict[str, Any], list[str]]:
    """(the log in memory with its efforts read ``delay`` s earlier, the record for ``diagnostics["delay"]``,
    warnings) for :func:`wmrid.estimators.identify.identify`.

    ``delay``: seconds, or "auto" (:func:`estimate_delay`; applied only when significant and not at the edge
    of the search).  The warnings name the likely cause: two clocks, or a controller faster than the log."""
    from wmrid.core.wheel_log import LogStream, WheelLog
    from wmrid.estimators.idim_regression import MAX_EFFORT_SHIFT_S, shifted

    whole = log.read() if isinstance(log, LogStream) else log
    t = np.asarray(whole.t, dtype=np.float64)
    eta = np.asarray(whole.eta, dtype=np.float64)
    tau = np.asarray(whole.tau, dtype=np.float64)
    source = getattr(whole, "source", "log")
    warnings: list[str] = []
    if delay == "auto":
        est = estimate_delay(t, eta, tau, span=search_span(t), torque_hold=torque_hold, control_rate=control_rate)
        record = {"chosen_by": "auto", **est.to_dict()}
        applied = est.delay if est.significant and not est.at_edge else 0.0
        if est.at_edge:
            warnings.append(
                f"the delay between efforts and speeds could not be estimated (the fit keeps improving to the edge of "
                f"the searched +/-{abs(est.grid[0]) * 1e3:g} ms): the model does not fit this log well enough to time "
                "it; the efforts are used as stamped"
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
