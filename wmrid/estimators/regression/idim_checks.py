"""IDIM under alternative admissible choices: what its jackknife cannot see (docs/explanation/uncertainty.md).

The jackknife measures how IDIM's estimate varies along a log; an error that is the same all along it is
invisible to it, as for the observer (:mod:`wmrid.estimators.model_error`).  Two such errors have their own signature in
IDIM, and each is measured by refitting the same regression another admissible way:

* the filter: the regression is exact whatever the cutoff only while the model holds and the speeds are
  noise-free; a model error or the noise's errors in variables make the estimate depend on the band the
  filter keeps.  Refit at the cutoff divided by CUTOFF_RATIO (:func:`cutoff_check`);
* friction at low speed: near a stop the measured sgn(eta) and the real friction differ most (noise flips the
  sign, friction is smooth through zero); refit without the rows where a wheel is slow (:func:`slow_speed_check`).

Each difference delta (in theta0) gets a delete-a-segment jackknife of its own (the two fits share the
segments), and is added to the covariance, as delta delta^T, only where some |delta_j| exceeds its gate in
units of that jackknife std -- noise alone rarely does.  Pure functions on arrays.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from wmrid.core.errors import NotIdentifiableError, UsageError
from wmrid.estimators.regression.idim_rows import idim_regression, phi_to_theta0, segment_factors, solve_r

#: The second fit's cutoff is the first's divided by this.
CUTOFF_RATIO = math.sqrt(2.0)
#: The cutoff difference is added beyond this many of its std (as the observer's discretisation term).
CUTOFF_GATE = 4.0
#: The low-speed difference is added beyond this many of its std (as the observer's, SLOW_SPEED_GATE).
SLOW_GATE = 3.0
#: A row is slow when a wheel's filtered speed is below this fraction of its 90th-percentile |speed| (as the
#: observer's LOW_SPEED_FRACTION); rows within SLOW_MARGIN_PERIODS cutoff periods of a slow row go too (the
#: zero-phase filter smears a sign change over about one period each way).
SLOW_FRACTION = 0.1
SLOW_MARGIN_PERIODS = 0.5
#: The check is skipped when fewer than this fraction of the rows are left.
MIN_KEPT = 0.2


def segments_on(t: np.ndarray, t0: float, duration: float, g: int) -> np.ndarray:
    """Segment index (N,) in [0, g) of times t (N,) s on the grid of g equal segments of [t0, t0 + duration]."""
    pos = (np.asarray(t) - t0) / max(duration, 1e-300)
    return np.clip((pos * g).astype(np.int64), 0, g - 1)


def difference(fac_a: list[np.ndarray], fac_b: list[np.ndarray], gate: float) -> dict[str, Any]:
    """theta0 of fit a minus theta0 of fit b, with the delete-a-segment jackknife std of that difference.

    fac_a, fac_b: the two fits' per-segment factors over the same g segments.  Returns {"applied": some
    |delta_j| > gate sd_j, "delta" (p,) theta0 units, "sd" (p,), "largest_ratio"}.
    """

    g = len(fac_a)
    singular = {"applied": False, "delta": None, "sd": None, "largest_ratio": None, "why": "a refit was singular"}
    try:
        with np.errstate(all="ignore"):
            full_a = phi_to_theta0(solve_r(np.vstack(fac_a)))
            full_b = phi_to_theta0(solve_r(np.vstack(fac_b)))
            loo = np.empty((g, len(full_a)))
            for i in range(g):
                a = phi_to_theta0(solve_r(np.vstack(fac_a[:i] + fac_a[i + 1 :])))
                b = phi_to_theta0(solve_r(np.vstack(fac_b[:i] + fac_b[i + 1 :])))
                loo[i] = a - b
    except np.linalg.LinAlgError:
        return singular
    delta = full_a - full_b
    if not (np.all(np.isfinite(delta)) and np.all(np.isfinite(loo))):
        return singular
    centred = loo - loo.mean(axis=0)
    sd = np.sqrt((g - 1) / g * np.sum(centred**2, axis=0))
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(sd > 0, np.abs(delta) / sd, 0.0)
    largest = float(np.max(ratio))
    return {"applied": bool(largest > gate), "delta": delta.tolist(), "sd": sd.tolist(), "largest_ratio": largest}


def cutoff_check(
    t: np.ndarray, eta: np.ndarray, tau: np.ndarray, reg: Any, fac: list[np.ndarray], weights: np.ndarray,
    seg: np.ndarray, g: int, decimate: bool, delay: float = 0.0, span: tuple[float, float] | None = None,
) -> dict[str, Any]:  # fmt: skip
    """The estimate at the cutoff / CUTOFF_RATIO against that at the cutoff (``reg``, :func:`difference`).

    t, eta, tau: the log as given to :func:`wmrid.estimators.regression.idim_rows.idim_regression`; reg: its regression
    at the cutoff
    used;
    fac: reg's per-segment factors (:func:`wmrid.estimators.regression.idim.segment_factors`); weights (2,): the fit's;
    seg (N,), g:
    reg's jackknife segments, g equal parts of ``span`` (t0 s, duration s; default reg's own times); delay: its
    effort delay, s.  Skipped (not
    applied, with "why") when the log is too short for the lower cutoff's transient.
    """

    low = reg.cutoff_hz / CUTOFF_RATIO
    try:
        other = idim_regression(t, eta, tau, low, decimate, order=reg.order, form=reg.form, effort_delay=delay)
    except (NotIdentifiableError, UsageError) as err:
        return {"applied": False, "delta": None, "sd": None, "largest_ratio": None, "why": str(err)}
    t0, duration = (float(reg.t[0]), float(reg.t[-1] - reg.t[0])) if span is None else span
    seg_b = segments_on(other.t, t0, duration, g)
    fac_b = segment_factors(other.rows(), other.tau, weights, seg_b, g)
    return {**difference(fac, fac_b, CUTOFF_GATE), "cutoff_hz": [reg.cutoff_hz, low]}


def slow_rows(reg: Any, eta: np.ndarray) -> np.ndarray:
    """(N,) bool: the rows of ``reg`` where a wheel's filtered speed is below SLOW_FRACTION of its 90th-percentile
    |speed| (of the log's eta (n, 2)), widened by SLOW_MARGIN_PERIODS cutoff periods each way."""
    low = SLOW_FRACTION * np.percentile(np.abs(eta), 90, axis=0)
    speeds = reg.features[:, 4:6]
    slow = np.any(np.abs(speeds) < low[None, :], axis=1)
    if not slow.any():
        return slow
    margin = SLOW_MARGIN_PERIODS / reg.cutoff_hz
    times = reg.t[slow]
    lo = np.searchsorted(times, reg.t - margin, side="left")
    hi = np.searchsorted(times, reg.t + margin, side="right")
    return hi > lo  # a slow row lies within the margin


def slow_speed_check(
    reg: Any, eta: np.ndarray, fac: list[np.ndarray], weights: np.ndarray, seg: np.ndarray, g: int
) -> dict[str, Any]:
    """The estimate with every row (its per-segment factors ``fac``) against the one without the slow rows
    (:func:`slow_rows`, :func:`difference`); skipped when no row is slow or fewer than MIN_KEPT of them remain, or
    the rest leaves a segment empty."""

    none = {"applied": False, "delta": None, "sd": None, "largest_ratio": None}
    slow = slow_rows(reg, eta)
    kept = float(np.mean(~slow))
    if not slow.any():
        return {**none, "why": "no wheel is slow", "left_out_fraction": 0.0}
    if kept < MIN_KEPT or np.any(np.bincount(seg[~slow], minlength=g) == 0):
        return {**none, "why": "too little of the log is fast", "left_out_fraction": 1.0 - kept}
    fac_fast = segment_factors(reg.rows(), reg.tau, weights, seg, g, keep=~slow)
    return {**difference(fac, fac_fast, SLOW_GATE), "left_out_fraction": 1.0 - kept}
