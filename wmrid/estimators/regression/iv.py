"""Instrumental variables (IDIM-IV): an estimate the feedback of a closed loop does not bias.

Why least squares is biased in closed loop.  Every method of wmrid fits a model that is linear in its
parameters, X phi = y, and least squares is consistent only when the regressor X is uncorrelated with what
the model leaves out (the residual e: a caster's drag, the floor, the torque noise).  On a robot under
feedback it is not:

* the observer (the paper's direct model, :mod:`wmrid.estimators.observer.step`) regresses the acceleration on the
effort
  tau; a controller answers a disturbance d within its bandwidth, so tau carries -d and the regressor is
  correlated with the residual (Sec. 1 of Hoang & Kang leaves this open).  Measured on the light AMR with a
  0.02 N m coloured disturbance: m11 1.5 % low on average over 40 s logs (up to 4.8 std on one seed), which
  no std covers;
* IDIM (:mod:`wmrid.estimators.regression.idim`) regresses the effort on the speeds and accelerations.  The feedback
reaches its
  regressor only through the tracking error the controller lets through, a smaller correlation (on the same
  logs its mean error was 0.1 %), but not zero.

Instruments.  An instrument matrix Z (same shape as X) correlated with X and not with e gives the consistent
estimate phi_IV = (Z^T X)^-1 Z^T y: Z^T e averages to zero, while Z^T X stays invertible.  Janot, Vandanjon &
Gautier (IEEE TCST 2014) take Z = X evaluated on a simulation of the closed loop on the previous estimate
(their IDIM-IV), which needs the controller's law.  wmrid takes what a log carries without it: the wheel-speed
REFERENCE (set-point) the controller tracks -- a planner's command, a ``cmd_vel`` turned into wheel speeds,
ros2_control's command interface.  The reference is decided before the disturbance acts, so Z, the IDIM
regressor rebuilt from the reference speeds (accelerations, Coriolis, speed, sign and caster columns, through
the same zero-phase filter, edges and decimation as X, :func:`instrument_regression`), is uncorrelated with e,
and it follows X as closely as the robot tracks its reference.  When the reference itself reacts to the
disturbance (an outer loop on the pose, slower than the speed loop) the correlation left is that of the outer
loop, which is far smaller than that of the effort in the observer's regressor.

Relevance.  Weak instruments make phi_IV noisy and its std unreliable.  For each regressor column (after the
per-wheel weights) wmrid reports the first-stage R^2 of the column on Z (:func:`first_stage_r2`), and refuses
an instrument set with an R^2 below MIN_R2 (the reference does not describe how the robot moved: a wrong
column, another unit, or a robot that does not track it).

Standard errors: the delete-a-segment jackknife over the same contiguous segments as IDIM (the residual is
coloured), from per-segment moments A_g = Z_g^T X_g and b_g = Z_g^T y_g, phi_(g) = (A - A_g)^-1 (b - b_g) with
no refit, averaged over the segment grid moved by fractions of a segment as for IDIM
(:data:`wmrid.estimators.regression.idim.GRID_SHIFTS`); theta0 = [m11 m12 m22 Vc ...] and its covariance by the delta
method as for IDIM.  ``weighted``: the
rows of wheel j scaled by 1 / s_j, s_j the rms IV residual of its equation in the unweighted fit.
"""

from __future__ import annotations

import time
from typing import Any

import numpy as np

from wmrid.core.errors import NotIdentifiableError, UsageError, option
from wmrid.estimators.estimate import BaseEstimate, SegmentEstimates
from wmrid.estimators.regression.idim import (
    GRID_SHIFTS,
    JACKKNIFE_TEXT,
    averaged_covariance,
    inertia_warnings,
    jackknife_segments,
    phi_to_theta0,
    shifted_groups,
    sub_segments,
    theta0_covariance,
)
from wmrid.estimators.regression.idim_rows import IdimRegression, effort_delay, idim_regression
from wmrid.model.dynamics import RegressorForm

#: A regressor column whose first-stage R^2 on the instruments is below this is not described by the reference.
MIN_R2 = 0.5
#: Below this first-stage R^2 the instruments are weak: the estimate stands, with a warning.
WEAK_R2 = 0.9


def instrument_regression(reg: IdimRegression, t: np.ndarray, reference: np.ndarray, tau: np.ndarray) -> np.ndarray:
    """Instruments Z (N, 2, p) for the regression ``reg`` of a log: its regressor rebuilt from the reference.

    t (n,) s, reference (n, 2) rad/s wheel-speed set-points [right, left], tau (n, 2) N m: the log ``reg`` was
    built from (tau only fixes the shapes).  The reference goes through
    :func:`wmrid.estimators.regression.idim_rows.idim_regression`
    with
    reg's cutoff, order, decimation and caster form, so its rows are those of ``reg`` sample for sample.
    """
    ref = idim_regression(
        t, reference, tau, reg.cutoff_hz, reg.decimation > 1, order=reg.order, form=reg.form
    )  # fmt: skip
    if ref.features.shape != reg.features.shape or not np.array_equal(ref.t, reg.t):
        raise UsageError("the reference's regression does not line up with the log's (same time stamps needed)")
    return ref.rows()


def segment_moments(
    z: np.ndarray, x: np.ndarray, y: np.ndarray, weights: np.ndarray, seg: np.ndarray, g: int
) -> tuple[np.ndarray, np.ndarray]:
    """Per-segment moments A_g = Z_g^T W X_g (g, p, p) and b_g = Z_g^T W y_g (g, p).

    z, x (N, 2, p) instruments and regressor, y (N, 2) N m, weights (2,) per wheel (applied to both sides: the
    weighted rows), seg (N,) segment of each sample in [0, g).
    """
    p = x.shape[2]
    w2 = weights**2
    big_a = np.zeros((g, p, p))
    big_b = np.zeros((g, p))
    for i in range(g):
        sel = seg == i
        for row in range(2):
            zi, xi = z[sel, row, :], x[sel, row, :]
            big_a[i] += w2[row] * (zi.T @ xi)
            big_b[i] += w2[row] * (zi.T @ y[sel, row])
    return big_a, big_b


def grouped_moments(fine_a: np.ndarray, fine_b: np.ndarray, groups: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Per-segment moments (G, p, p), (G, p) from per-sub-segment ones (G K, p, p), (G K, p): segment i's are the sums
    over its sub-segments groups[i] (groups (G, K), :func:`wmrid.estimators.regression.idim.shifted_groups`)."""
    return fine_a[groups].sum(axis=1), fine_b[groups].sum(axis=1)


def solve_moments(big_a: np.ndarray, big_b: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(phi (p,), leave-one-segment-out solutions (g, p), jackknife covariance (p, p)) from per-segment moments."""
    total_a, total_b = big_a.sum(axis=0), big_b.sum(axis=0)
    phi = np.linalg.solve(total_a, total_b)
    g = big_a.shape[0]
    loo = np.empty((g, len(phi)))
    for i in range(g):
        loo[i] = np.linalg.solve(total_a - big_a[i], total_b - big_b[i])
    centred = loo - loo.mean(axis=0)
    cov = (g - 1) / g * (centred.T @ centred)
    return phi, loo, 0.5 * (cov + cov.T)


def first_stage_r2(z: np.ndarray, x: np.ndarray, weights: np.ndarray) -> np.ndarray:
    """R^2 (p,) of each (weighted, stacked) regressor column of x (N, 2, p) on all instruments z (N, 2, p).

    1 when the instruments reproduce the column exactly; near 0 when they say nothing about it.  A column
    that is identically zero (unexcited) gets 1 (it is not the instruments' fault).
    """
    p = x.shape[2]
    zs = (z * weights[None, :, None]).reshape(-1, p)
    xs = (x * weights[None, :, None]).reshape(-1, p)
    coef, *_ = np.linalg.lstsq(zs, xs, rcond=None)
    resid = xs - zs @ coef
    total = np.sum(xs**2, axis=0)  # uncentred: the model has no intercept
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(total > 0, 1.0 - np.sum(resid**2, axis=0) / total, 1.0)


def identify_iv(
    t: np.ndarray,
    eta: np.ndarray,
    tau: np.ndarray,
    reference: np.ndarray,
    *,
    cutoff_hz: float | None = None,
    weighted: bool = False,
    order: int = 4,
    decimate: bool = True,
    form: RegressorForm | None = None,
    torque_hold: str = "zoh",
    control_rate: float | None = None,
    grid: tuple[float, float, int] | None = None,
) -> BaseEstimate:
    """IDIM-IV estimate of the base parameters, the reference speeds as instruments (see the module docstring).

    t : (n,) s strictly increasing; eta : (n, 2) rad/s [right, left]; tau : (n, 2) N m; reference : (n, 2)
    rad/s, the wheel-speed set-points at the same times.  cutoff_hz, order, decimate, form, torque_hold,
    control_rate, grid : as for :func:`wmrid.estimators.regression.idim.identify_idim` (the same filtered regression and
    segments). weighted : two-step per-wheel weights.  Returns a :class:`BaseEstimate` (method "iv"), dof = G - 1;
    diagnostics hold the first-stage R^2 per parameter, the residual rms per wheel (N m), phi and its std.
    Raises NotIdentifiableError when the reference does not describe the speeds (a first-stage R^2 below MIN_R2)
    or Z^T X is singular.
    """
    start = time.perf_counter()
    reference = np.asarray(reference, dtype=np.float64)
    if reference.shape != np.shape(eta):
        raise UsageError(f"the reference must have the speeds' shape {np.shape(eta)}, got {reference.shape}")
    if not np.all(np.isfinite(reference)):
        raise NotIdentifiableError("the reference speeds hold non-finite values (NaN or inf)")
    delay = effort_delay(t, torque_hold, control_rate)
    reg = idim_regression(t, eta, tau, cutoff_hz, decimate, order=order, form=form, effort_delay=delay)
    x = reg.rows()
    z = instrument_regression(reg, t, reference, tau)
    names = reg.phi_names
    seg, g = jackknife_segments(reg.t, grid)
    sub = sub_segments(reg.t, seg, g, grid)
    ones = np.ones(2)
    r2 = first_stage_r2(z, x, ones)
    weak = [name for name, v in zip(names, r2, strict=True) if v < MIN_R2]
    if weak:
        raise NotIdentifiableError(
            f"the reference speeds do not describe how the wheels moved (first-stage R^2 of {', '.join(weak)} "
            f"below {MIN_R2:g}: {min(r2):.2g}); check that the reference columns are the wheel-speed set-points in "
            f"rad/s, right then left, or leave out {option('method', 'iv')}"
        )

    def fit(weights: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        fine_a, fine_b = segment_moments(z, x, reg.tau, weights, sub, g * GRID_SHIFTS)
        try:
            phi, loo, _ = solve_moments(*grouped_moments(fine_a, fine_b, shifted_groups(g)[0]))
            cov = averaged_covariance(lambda groups: solve_moments(*grouped_moments(fine_a, fine_b, groups))[2], g)
        except np.linalg.LinAlgError as err:
            raise NotIdentifiableError(
                "the instrumental-variable system Z^T X is singular: the log or its reference does not excite "
                "the dynamics; record a log that accelerates, brakes and turns"
            ) from err
        rms = np.sqrt(np.mean((x @ phi - reg.tau) ** 2, axis=0))
        return phi, cov, rms, weights, loo

    phi, cov_phi, rms, weights, loo = fit(ones)
    if weighted:
        if np.any(rms <= 0):
            raise NotIdentifiableError("weighted IV: a wheel equation fits exactly, so its weight is undefined")
        phi, cov_phi, rms, weights, loo = fit(1.0 / rms)
        r2 = first_stage_r2(z, x, weights)
    theta0 = phi_to_theta0(phi)
    cov0 = theta0_covariance(phi, cov_phi)
    std_phi = np.sqrt(np.clip(np.diag(cov_phi), 0.0, None))
    warnings = inertia_warnings(phi)
    weakish = [name for name, v in zip(names, r2, strict=True) if v < WEAK_R2]
    if weakish:
        warnings.append(
            f"the reference describes {', '.join(weakish)} only loosely (first-stage R^2 down to {min(r2):.2f}): the "
            "instrumental-variable estimate is noisier than least squares there"
        )
    diagnostics: dict[str, Any] = {
        **reg.info(),
        "rows": 2 * len(reg.t),
        "weighted": bool(weighted),
        "weights": [float(w) for w in weights],
        "residual_rms": [float(v) for v in rms],
        "segments": int(g),
        "effort_delay_s": delay,
        "instruments": "the IDIM regressor rebuilt from the logged wheel-speed reference",
        "first_stage_r2": {name: float(v) for name, v in zip(names, r2, strict=True)},
        "grid_shifts": GRID_SHIFTS,
        "uncertainty": JACKKNIFE_TEXT,
        "phi": {name: float(v) for name, v in zip(names, phi, strict=True)},
        "phi_std": {name: float(v) for name, v in zip(names, std_phi, strict=True)},
    }
    t0, span = (float(reg.t[0]), float(reg.t[-1] - reg.t[0])) if grid is None else (grid[0], grid[1])
    return BaseEstimate(
        method="iv", theta0=theta0, cov=cov0, dof=g - 1, seconds=time.perf_counter() - start,
        diagnostics=diagnostics, warnings=tuple(warnings), segments=SegmentEstimates(t0, span, phi_to_theta0(loo)),
    )  # fmt: skip
