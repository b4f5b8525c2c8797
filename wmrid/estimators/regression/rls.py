"""Recursive least squares (RLS) with exponential forgetting on the IDIM regression.

The regression is the one of :mod:`wmrid.estimators.regression.idim`
(:func:`wmrid.estimators.regression.idim_rows.idim_regression`: zero-phase
parallel
filtering, accelerations from the filtered velocities, edges dropped), two rows per sample,
X_k phi = y_k with phi = [M11 M12 M22 Vc Fv1 Fv2 Fd1 Fd2] (then the caster parameters with a ``form`` that
has caster drag, :func:`wmrid.estimators.regression.idim_rows.phi_names`: the caster columns are filtered and mapped
exactly as IDIM
does, so p = 8 + their number of parameters).  By default it is NOT decimated, so the
forgetting factor lambda acts per log sample.  (The filter is zero-phase, hence non-causal: this is an
offline analysis of how the parameters drift, not an online estimator.)

The compiled kernel (:func:`rls_kernel`) runs the classical covariance-form update with a vector
measurement (2 equations, p parameters) at each sample::

    e = y_k - X_k phi                         (a priori prediction error, N m)
    K = P X_k^T (lambda I_2 + X_k P X_k^T)^-1
    phi <- phi + K e
    P <- (P - K X_k P) / lambda

so the estimate minimises sum_k lambda^(n-k) |y_k - X_k phi|^2.  Implementation choices:

* Columns are scaled by their rms over the log, phi_s = d * phi, so P and the tests below are unit-free.
* Exact initialisation instead of a large prior P_0 = delta I (whose cancellations cost digits): until
  the forgetting-weighted information R = sum lambda^(n-k) X_k^T X_k is well conditioned (the Cholesky
  pivots of the diagonally equilibrated R all above :data:`INIT_PIVOT`), the kernel accumulates R and r
  and the estimate is undefined (NaN in the history); then P = R^-1, phi = P r and the recursion takes
  over.  With lambda = 1 the final estimate equals batch least squares on the same rows, whatever the
  start.
* Anti-windup: with lambda < 1 a log that stops exciting some direction (standing still) would make P
  grow as lambda^-n without bound; P is not divided by lambda on a step where that would take its
  trace beyond its trace at initialisation (the estimate never gets less certain than when it was
  first defined).  ``diagnostics["forgetting_capped"]`` counts such steps.

Standard errors:

* lambda = 1: the final estimate is the least-squares one, so the delete-a-segment jackknife of
  :mod:`wmrid.estimators.regression.idim` applies unchanged (from per-sub-segment sums of X^T X and X^T y the kernel
  keeps, averaged over the shifted grids as there), dof = G - 1.
* lambda < 1: a LOCAL statement about the estimate at the end of the log, made from the data in its
  effective window of 1 / (1 - lambda) samples (weights w_k = lambda^(n-k); their effective count
  (sum w)^2 / sum w^2 is (1 + lambda) / (1 - lambda) on a long log).  phi - phi_true ~ P sum_k w_k z_k
  with z_k = X_k^T e_k the scores, so Cov phi = (sum_k w_k^2) P S P, S the long-run covariance per sample
  of the scores: the sandwich of exponentially weighted least squares.  S is estimated by batch means of
  the scores of the a priori prediction errors over the whole log (batches of
  :data:`wmrid.estimators.uncertainty.SEGMENT_SECONDS`, at least :data:`MIN_BATCHES` of them), which accounts for
  their colour (the filter alone makes neighbouring residuals nearly equal; plain s^2 P would be about
  sqrt(rate / (2 f_c)) times too small) but assumes the residuals' level and colour are the same over
  the log, and ignores the lag of tracking a drifting parameter.  dof = B - 1 with B the number of
  batches (that of the estimate of S).  Measured on 12 seeds of the noisy closed-loop simulation
  (40 s, 1 kHz, windows of 1-10 s): rms t-statistics of 0.6-1.9 per parameter (0.5-1.6 for lambda = 1
  with the jackknife), i.e. the local std can understate the spread up to about twice.

The history (:class:`RlsHistory`, from :func:`rls_history` or :func:`rls_run`) samples the estimate at
most ``history_points`` times (evenly in samples, the last sample included): t, phi, theta0 and the
std of theta0 by the same sandwich (each point's P and sum w^2, the log-wide S).
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from wmrid.core.errors import NotIdentifiableError, UsageError
from wmrid.estimators.estimate import BaseEstimate
from wmrid.estimators.regression.idim import (
    GRID_SHIFTS,
    JACKKNIFE_TEXT,
    averaged_covariance,
    inertia_warnings,
    not_identifiable_message,
    phi_to_theta0,
    segment_index,
    sub_segments,
    theta0_covariance,
)
from wmrid.estimators.regression.idim_rows import IdimRegression, effort_delay, idim_regression
from wmrid.estimators.regression.rls_kernel import INIT_PIVOT, rls_kernel
from wmrid.estimators.uncertainty import SEGMENT_SECONDS
from wmrid.model.dynamics import RegressorForm

#: Default number of history points.
HISTORY_POINTS = 2000
#: Fewest batches for the batch-means long-run covariance of the scores.
MIN_BATCHES = 10


@dataclass(frozen=True, eq=False)
class RlsHistory:
    """The RLS estimate over time (at most ``history_points`` samples of the regression).

    t : (m,) s.  phi : (m, p) [M11 M12 M22 Vc Fv1 Fv2 Fd1 Fd2, caster...]; theta0 : (m, p) [m11 m12 m22 Vc Fv1
    Fv2 Fd1 Fd2, caster...] (p = 8, plus the caster parameters of the form,
    :func:`wmrid.estimators.regression.idim_rows.phi_names`);
    both NaN before the estimate is defined (see the module docstring, exact initialisation).
    std : (m, p) standard errors of theta0 (local sandwich; NaN before initialisation).
    forgetting : lambda.
    """

    t: np.ndarray
    phi: np.ndarray
    theta0: np.ndarray
    std: np.ndarray
    forgetting: float


def long_run_scores(scores: np.ndarray, n_batches: int, block_len: int) -> np.ndarray:
    """Long-run covariance (p, p) per sample of the scores x_k^T e_k, by batch means (NaN under 2 batches).

    scores (p + 1, p) as :func:`rls_kernel` fills it: S = (sum z_b z_b^T - zbar zbar^T n_b) / (n_b - 1) / block_len.
    """
    p = scores.shape[1]
    if n_batches < 2:
        return np.full((p, p), np.nan)
    mean = scores[p] / n_batches
    cov = (scores[:p] - n_batches * np.outer(mean, mean)) / (n_batches - 1) / block_len
    return 0.5 * (cov + cov.T)


def _check_forgetting(forgetting: float) -> float:
    if isinstance(forgetting, bool) or not isinstance(forgetting, (int, float, np.integer, np.floating)):
        raise UsageError(f"forgetting must be a number in (0, 1], got {forgetting!r}")
    lam = float(forgetting)
    if not (math.isfinite(lam) and 0.0 < lam <= 1.0):
        raise UsageError(f"forgetting must be in (0, 1], got {forgetting!r}")
    return lam


def _jackknife(fine_a: np.ndarray, fine_c: np.ndarray, scale: np.ndarray, g: int) -> tuple[np.ndarray, int]:
    """Jackknife covariance (p, p) of phi over G segments, averaged over the grid's shifts
    (:func:`wmrid.estimators.regression.idim.averaged_covariance`), from per-sub-segment scaled sums (G K, p, p) and (G
    K, p) (:func:`wmrid.estimators.regression.idim.sub_segments`), and its dof G - 1."""

    def one(groups: np.ndarray) -> np.ndarray:
        return _jackknife_grid(fine_a[groups].sum(axis=1), fine_c[groups].sum(axis=1), scale)

    return averaged_covariance(one, g), g - 1


def _jackknife_grid(blk_a: np.ndarray, blk_c: np.ndarray, scale: np.ndarray) -> np.ndarray:
    """Jackknife covariance (p, p) of phi from per-segment scaled sums (G, p, p) and (G, p)."""
    g = blk_a.shape[0]
    a = blk_a.sum(axis=0)
    c = blk_c.sum(axis=0)
    loo = np.empty((g, blk_c.shape[1]))
    for i in range(g):
        try:
            loo[i] = np.linalg.solve(a - blk_a[i], c - blk_c[i]) / scale
        except np.linalg.LinAlgError:
            loo[i] = np.nan
    centred = loo - loo.mean(axis=0)
    cov = (g - 1) / g * (centred.T @ centred)
    return 0.5 * (cov + cov.T)


def _residual_rms(reg: IdimRegression, phi: np.ndarray, chunk: int = 1 << 16) -> np.ndarray:
    """rms (2,) N m of each wheel's residual y - X phi over the regression, in chunks."""
    n = len(reg.t)
    ssq = np.zeros(2)
    for lo in range(0, n, chunk):
        sl = slice(lo, min(n, lo + chunk))
        ssq += np.sum((reg.tau[sl] - reg.rows(sl) @ phi) ** 2, axis=0)
    return np.sqrt(ssq / n)


def rls_on_regression(
    reg: IdimRegression, *, forgetting: float = 1.0, history_points: int = HISTORY_POINTS
) -> tuple[BaseEstimate, RlsHistory]:
    """Run RLS over a prepared regression: (the final estimate, its history).  See :func:`rls_run`."""
    start = time.perf_counter()
    lam = _check_forgetting(forgetting)
    if isinstance(history_points, bool) or not isinstance(history_points, (int, np.integer)) or history_points < 1:
        raise UsageError(f"history_points must be a whole number >= 1, got {history_points!r}")
    feats = np.ascontiguousarray(reg.features, dtype=np.float64)
    tau = np.ascontiguousarray(reg.tau, dtype=np.float64)
    n = len(reg.t)
    # rms of each phi column over both rows of every sample (a_1 and a_2 each enter two columns)
    col_feats = ([0], [1, 0], [1], [2, 3], [4], [5], [6], [7])
    ms = np.array([np.sum(feats[:, f] ** 2) / (2 * n) for f in col_feats])
    # (feature index, phi index, pattern) of each caster feature, for the kernel
    cmap = reg.caster_map
    caster = np.array([(8 + j, param, pat) for j, (_, param, pat) in enumerate(cmap)], dtype=np.int64).reshape(-1, 3)
    names = reg.phi_names
    p = len(names)
    if p > 8:  # a caster parameter's column: its features summed in row 1, with their patterns in row 2
        row1 = np.zeros((n, p - 8))
        row2 = np.zeros((n, p - 8))
        for j, (_, param, pattern) in enumerate(cmap):
            row1[:, param - 8] += feats[:, 8 + j]
            row2[:, param - 8] += pattern * feats[:, 8 + j]
        ms = np.concatenate([ms, (np.sum(row1**2, axis=0) + np.sum(row2**2, axis=0)) / (2 * n)])
    scale = np.where(ms > 0, np.sqrt(ms), 1.0)
    seg, g = segment_index(reg.t)
    segment = sub_segments(reg.t, seg, g)  # the kernel's sums per sub-segment: the jackknife averages shifted grids
    blk_a = np.zeros((g * GRID_SHIFTS, p, p))
    blk_c = np.zeros((g * GRID_SHIFTS, p))
    stride = max(1, math.ceil(n / history_points))
    m = math.ceil(n / stride)
    hist_idx = np.zeros(m, dtype=np.int64)
    hist_phi = np.zeros((m, p))
    hist_p = np.zeros((m, p, p))
    hist_w2 = np.zeros(m)
    stats = np.zeros(6)
    scores = np.zeros((p + 1, p))
    duration = float(reg.t[-1] - reg.t[0])
    dt = duration / max(n - 1, 1)
    block_len = max(1, round(min(SEGMENT_SECONDS, duration / MIN_BATCHES) / max(dt, 1e-300)))
    kernel_start = time.perf_counter()
    phi_s, pm = rls_kernel(
        feats, tau, scale, caster, lam, INIT_PIVOT, segment, blk_a, blk_c, stride, block_len,
        hist_idx, hist_phi, hist_p, hist_w2, stats, scores,
    )  # fmt: skip
    kernel_seconds = time.perf_counter() - kernel_start

    phys = reg.scales()
    reason = not_identifiable_message(blk_a.sum(axis=0) * np.outer(scale / phys, scale / phys), names)
    if reason is not None:
        raise NotIdentifiableError(reason)
    init = int(stats[0])
    if init < 0 or not np.all(np.isfinite(phi_s)):
        raise NotIdentifiableError(
            "the log does not excite the dynamics well enough for the recursion to start (its information "
            "stays ill-conditioned); record a log that accelerates, brakes and turns"
        )
    phi = phi_s / scale
    unscale = np.outer(scale, scale)
    n_batches = int(stats[5])
    s_lr = long_run_scores(scores, n_batches, block_len)
    warnings = inertia_warnings(phi)
    n_after = n - init
    if lam == 1.0:
        cov_phi, dof = _jackknife(blk_a, blk_c, scale, g)
        std_method = JACKKNIFE_TEXT
        n_weighted = float(n_after)
    else:
        w2 = float(hist_w2[-1])
        cov_phi = w2 * (pm @ s_lr @ pm) / unscale
        dof = max(1, n_batches - 1)
        std_method = (
            "local: w2 P S P over the forgetting window, S the long-run covariance of the scores x_k^T e_k "
            "(batch means over the log)"
        )
        sw = (1.0 - lam**n_after) / (1.0 - lam)
        sw2 = (1.0 - lam ** (2 * n_after)) / (1.0 - lam * lam)
        n_weighted = sw * sw / sw2
        if n_weighted < 10 * p:
            window = 1 / (1 - lam)
            short = f"the forgetting window ({window:.3g} samples) is short for {p} parameters"
            warnings.append(f"{short}; the estimate is noisy")
    theta0 = phi_to_theta0(phi)
    cov0 = theta0_covariance(phi, cov_phi)
    if not np.all(np.isfinite(cov0)):
        cov0 = np.full((p, p), np.nan)
        np.fill_diagonal(cov0, np.inf)
        warnings.append(
            "the standard errors could not be computed (the log is too short, or one segment holds all the excitation)"
        )
    std_phi = np.sqrt(np.clip(np.diag(cov_phi), 0.0, None))
    diagnostics: dict[str, Any] = {
        **reg.info(),
        "forgetting": lam,
        "window_samples": None if lam == 1.0 else 1.0 / (1.0 - lam),
        "window_seconds": None if lam == 1.0 else dt / (1.0 - lam),
        "effective_samples": float(n_weighted),
        "init_samples": init + 1,
        "init_seconds": float(reg.t[init] - reg.t[0]),
        "forgetting_capped": int(stats[2]),
        "residual_rms": [float(v) for v in _residual_rms(reg, phi)],
        "local_prediction_rms": [float(v) for v in np.sqrt(stats[3:5])],
        "segments": int(g),
        "grid_shifts": GRID_SHIFTS,
        "batches": n_batches,
        "batch_seconds": float(block_len * dt),
        "uncertainty": std_method,
        "kernel_seconds": float(kernel_seconds),
        "history_points": int(m),
        "phi": {name: float(v) for name, v in zip(names, phi, strict=True)},
        "phi_std": {name: float(v) for name, v in zip(names, std_phi, strict=True)},
    }
    estimate = BaseEstimate(
        method="rls", theta0=theta0, cov=cov0, dof=dof, seconds=time.perf_counter() - start,
        diagnostics=diagnostics, warnings=tuple(warnings),
    )  # fmt: skip

    h_phi = hist_phi / scale
    h_theta = phi_to_theta0(h_phi)
    h_std = np.full_like(h_theta, np.nan)
    for i in np.flatnonzero(np.all(np.isfinite(h_phi), axis=1)):
        cov_i = hist_w2[i] * (hist_p[i] @ s_lr @ hist_p[i]) / unscale
        h_std[i] = np.sqrt(np.clip(np.diag(theta0_covariance(h_phi[i], cov_i)), 0.0, None))
    history = RlsHistory(t=reg.t[hist_idx], phi=h_phi, theta0=h_theta, std=h_std, forgetting=lam)
    return estimate, history


def rls_run(
    t: np.ndarray,
    eta: np.ndarray,
    tau: np.ndarray,
    *,
    forgetting: float = 1.0,
    cutoff_hz: float | None = None,
    order: int = 4,
    decimate: bool = False,
    history_points: int = HISTORY_POINTS,
    form: RegressorForm | None = None,
    torque_hold: str = "zoh",
    control_rate: float | None = None,
) -> tuple[BaseEstimate, RlsHistory]:
    """RLS over a log: (final estimate, history of the estimate).

    t : (n,) s strictly increasing; eta : (n, 2) rad/s [right, left]; tau : (n, 2) N m.
    forgetting : lambda in (0, 1], per regression sample (per log sample unless ``decimate``); the
    effective window is 1 / (1 - lambda) samples; 1 is plain RLS (= batch least squares).
    cutoff_hz, order, decimate : the preprocessing of :func:`wmrid.estimators.regression.idim_rows.idim_regression`.
    history_points : at most this many points in the history.
    form : the observer's regressor form; with caster drag (``form.caster``) the regression gains its caster
    columns and phi, theta0 its caster parameters (``form.base_names[8:]``), as in
    :mod:`wmrid.estimators.regression.idim`; otherwise
    (or None) it is ignored.  torque_hold, control_rate : how the effort was held
    (:func:`wmrid.estimators.regression.idim_rows.effort_delay`).
    The estimate (method "rls") is the one at the end of the log; see the module docstring for what its
    standard errors mean.  Raises NotIdentifiableError when the log does not excite the dynamics.
    """
    start = time.perf_counter()
    lam = _check_forgetting(forgetting)
    delay = effort_delay(t, torque_hold, control_rate)
    reg = idim_regression(t, eta, tau, cutoff_hz, decimate, order=order, form=form, effort_delay=delay)
    estimate, history = rls_on_regression(reg, forgetting=lam, history_points=history_points)
    estimate = dataclasses.replace(estimate, seconds=time.perf_counter() - start)
    return estimate, history


def identify_rls(
    t: np.ndarray,
    eta: np.ndarray,
    tau: np.ndarray,
    *,
    forgetting: float = 1.0,
    cutoff_hz: float | None = None,
    order: int = 4,
    decimate: bool = False,
    form: RegressorForm | None = None,
    torque_hold: str = "zoh",
    control_rate: float | None = None,
) -> BaseEstimate:
    """The RLS estimate at the end of the log (see :func:`rls_run` for the arguments)."""
    estimate, _ = rls_run(
        t, eta, tau, forgetting=forgetting, cutoff_hz=cutoff_hz, order=order, decimate=decimate, form=form,
        torque_hold=torque_hold, control_rate=control_rate,
    )  # fmt: skip
    return estimate


def rls_history(
    t: np.ndarray,
    eta: np.ndarray,
    tau: np.ndarray,
    *,
    forgetting: float = 1.0,
    cutoff_hz: float | None = None,
    order: int = 4,
    decimate: bool = False,
    history_points: int = HISTORY_POINTS,
    form: RegressorForm | None = None,
    torque_hold: str = "zoh",
    control_rate: float | None = None,
) -> RlsHistory:
    """theta0 over time: the tracking RLS estimate, at most ``history_points`` points (see :func:`rls_run`)."""
    return rls_run(
        t, eta, tau, forgetting=forgetting, cutoff_hz=cutoff_hz, order=order, decimate=decimate,
        history_points=history_points, form=form, torque_hold=torque_hold, control_rate=control_rate,
    )[1]  # fmt: skip
