"""Output-error (OE) refinement: the base parameters whose simulated wheel speeds best match the log.

The paper (Sec. 1) sets the output-error method against IDIM: OE minimises the quadratic error between
the measured output and the output simulated from the same input, needs no differentiated signals, but
"the difficulties in this method arise from the choice of initial conditions, resulting in multiple or
local solutions".  In wmrid OE is a refinement, started from an estimate that is already close (the
observer's), which removes that difficulty::

    theta0_hat = argmin  sum_k || eta_k - eta_hat_k(theta0) ||^2

with eta_hat the validation predictor of :mod:`wmrid.model.predict` (RK4, measured torques held as
``torque_hold`` says, Coulomb friction holding a wheel at rest), solved by ``scipy.optimize.least_squares``
with method "lm" (MINPACK's Levenberg-Marquardt, a trust-region method; no bounds): on a 40 s log it
took 0.7 s where "trf" took 2.5 s to the same point, most of it in an SVD of the 80 000 x 8 Jacobian at
every iteration.

What was observed about the initial-guess problem, on the noisy 40 s closed-loop paper log (seed 1):

* one free-running simulation (``segment_seconds=None``, classic OE) started from the truth with Vc of
  the wrong sign converges (xtol) to a poor local minimum: at twice its size cost 143 125 against 57.4,
  fit 3 % / 8 %, m 25x too small and Vc = -2.8; at its own size cost 644 529 with M absurd.  From the
  nominal parameters, all of theta0 or nominal x2 or x0.5, m x3 or /3, Vc x5, m12 of the wrong sign,
  friction x10 and log-normal draws it reached the right minimum.  (Which starts fail depends on details:
  with a forward-difference Jacobian, Vc of the wrong sign at its own size had succeeded);
* the segmented fit (the default) reached the right minimum from every one of these starts, including
  Vc of the wrong sign at 1x, 2x, 3x, 5x and 10x;
* a start with m far from positive definite (m12 x5) makes the free-running simulation diverge, which
  raises :class:`wmrid.core.errors.NotIdentifiableError`; the segmented fit from it reaches the right
  minimum.  One log-normal draw diverged even over 0.5 s segments.

Choices:

* Scaling: each parameter is scaled by |theta0_start| (``x_scale``), with a floor from the data for
  entries that start at or near 0 (the paper's nominal friction is 0): 10 % of max(|m11|, |m22|) for the
  entries of m, and 1 % of the torque a typical speed produces through that parameter for Vc, F_v and F_d
  (RMS torque / RMS speed^2, / RMS speed, 1).
* Multiple shooting, lite: the simulation restarts from the measured speed every ``segment_seconds``
  (default :data:`SHOOTING_SECONDS` = 0.5 s); the segments' initial speeds are the measured ones, not
  extra unknowns.  The wheel dynamics are nearly integrators (m F_v is about 0.01 1/s for the paper's
  robot), so an unmodelled disturbance (a caster, slip; in closed loop the controller's answer to it is
  in the measured torque but the disturbance is not) makes a free-running simulation drift like a
  random walk, and the fit bends the parameters to absorb the drift; restarts bound it.  Shorter
  segments bound it more but carry less of the slow dynamics (friction) and put the speed noise of more
  restarts into the residuals.  Measured on 10 noisy 40 s closed-loop paper logs (seeds 1-10, caster
  correlation time 0.3 s), RMS error (%) of M11, M12, M22, Vc and the fraction of the 80 parameter
  estimates within 2 reported std of the truth:

      segment   0.1 s               0.25 s              0.5 s               1 s
      errors    0.36 0.96 0.45 0.46  0.31 0.65 0.26 0.35  0.28 0.49 0.23 0.41  0.39 0.61 0.30 0.40
      |z| < 2   94 %                95 %                95 %                92 %
      segment   2 s                 5 s                 one (free run)
      errors    0.53 0.73 0.35 0.38  0.49 0.94 0.46 0.48  0.56 0.69 0.58 0.48
      |z| < 2   92 %                75 %                75 %

  so 0.5 s (several hundred samples at 1 kHz, a couple of the disturbance's correlation times) is the
  default; friction is weakly determined on that trajectory at any length (RMS errors 20-50 %, with
  std of the same size).  ``segment_seconds=None`` fits one free-running simulation (classic OE).
* Caster drag: with the observer's geometric ``wheel+caster`` form (``form``), the drag forces D_k are fitted
  with the rest (n_base parameters) and simulated as :mod:`wmrid.model.predict` does; the two-term caster model is
  refused there, so here too.  On a noise-free 30 s log with two casters' drag, from 10 % off: every entry
  within 0.0014 %; on the MuJoCo AMR from the observer: M within 0.52 %, Vc 0.47 %, D 1.6 %.
* Jacobian: central differences, step eps^(1/3) max(|theta_j|, scale_j), the 2 n_base perturbed simulations
  run in threads (the compiled kernel releases the GIL).  Forward differences with step sqrt(eps) were
  tried first: for the small friction parameters their effect on the speed is only ~1e4 times the
  simulation's round-off, and the Jacobian's relative error of ~1e-5 hid an exact null direction (a
  constant-torque log) behind an eigenvalue ratio of 1e-10.
* Standard errors: the residuals are coloured (the disturbance, the restarts), so the covariance is the
  cluster-robust sandwich over G contiguous time segments (the project's rule,
  :func:`wmrid.estimators.uncertainty.segment_count`: 2 s each, 10 to 40 of them)::

      H = J^T J,  s_g = J_g^T r_g,  Cov = H^-1 (G / (G - 1)) sum_g s_g s_g^T H^-1,   dof = G - 1

* Failure: a simulation that diverges at the start or at the result, an optimiser error (status -1 or
  an exception), or a final Jacobian whose column-normalised information has an eigenvalue below
  :data:`UNEXCITED` of the largest (observed: 1e-16 for a constant-torque log, whose parameters are
  exactly not identifiable, against 1.5e-6 and more on the open- and closed-loop logs of the tests) raise
  :class:`wmrid.core.errors.NotIdentifiableError` with a one-line message.  Running out of ``max_nfev``
  does not: the estimate (which only ever lowered the cost) is returned with a warning and
  ``diagnostics["converged"] = False``.
"""

from __future__ import annotations

import math
import os
import time
from concurrent.futures import ThreadPoolExecutor

import numpy as np
from scipy.optimize import least_squares

from wmrid.core.choices import TorqueHold, values
from wmrid.core.errors import NotIdentifiableError, UsageError
from wmrid.estimators.estimate import BaseEstimate
from wmrid.estimators.uncertainty import segment_count
from wmrid.model.dynamics import RegressorForm
from wmrid.model.kernels import plain
from wmrid.model.predict import MAX_STEP, caster_array, fit_percent, predictor_text
from wmrid.model.predict_kernel import simulate_kernel

#: Default length (s) of the multiple-shooting segments (see the module docstring).
SHOOTING_SECONDS = 0.5
#: A direction of the column-normalised information J^T J whose eigenvalue is below this fraction of the
#: largest is not determined by the log (as :data:`wmrid.estimators.diagnostics.UNEXCITED`).
UNEXCITED = 1e-12
#: Relative step of the central differences: eps^(1/3), balancing truncation (~step^2) against round-off.
FD_STEP = float(np.finfo(float).eps ** (1.0 / 3.0))
#: Default budget of residual evaluations (the Jacobian's own simulations are not counted).
MAX_NFEV = 200
#: Residual (rad/s) standing for a simulated speed that diverged to inf / NaN.
DIVERGED = 1e50


def shooting_starts(t: np.ndarray, segment_seconds: float | None) -> np.ndarray:
    """Sample indices (G,) at which the simulation restarts from the measured speed; starts[0] = 0.

    t (n,) s increasing.  Segments of ``segment_seconds`` from t[0]; a last piece shorter than half a
    segment is joined to the one before.  None: one segment.
    """
    n = t.size
    if segment_seconds is None or n < 2:
        return np.zeros(1, dtype=np.int64)
    duration = float(t[-1] - t[0])
    n_seg = max(1, math.floor(duration / segment_seconds))
    if duration - n_seg * segment_seconds >= 0.5 * segment_seconds:
        n_seg += 1
    bounds = t[0] + segment_seconds * np.arange(n_seg)
    starts = np.unique(np.searchsorted(t, bounds, side="left"))
    starts = starts[starts < n - 1]
    return starts.astype(np.int64)


def _cluster_index(t: np.ndarray, n_clusters: int) -> np.ndarray:
    """Cluster (0 .. G-1) of each sample: G equal time slices of the log."""
    span = t[-1] - t[0]
    frac = (t - t[0]) / span if span > 0 else np.zeros_like(t)
    return np.minimum((frac * n_clusters).astype(np.int64), n_clusters - 1)


def _scales(
    theta0_start: np.ndarray, eta: np.ndarray, tau: np.ndarray, form: RegressorForm | None = None
) -> np.ndarray:
    """x_scale (n0,): |theta0_start| with data-based floors (see the module docstring); a caster's drag force
    D_k (N, the entries beyond 8) gets 1 % of the RMS torque as a force at the wheel's rim (/ (r/2))."""
    tau_rms = float(np.sqrt(np.mean(tau**2)))
    eta_rms = float(np.sqrt(np.mean(eta**2)))
    tau_rms = tau_rms if tau_rms > 0 else 1.0
    eta_rms = eta_rms if eta_rms > 0 else 1.0
    m_big = max(abs(theta0_start[0]), abs(theta0_start[2]))
    m_big = m_big if m_big > 0 else 1.0
    floor = np.array(
        [0.1 * m_big] * 3
        + [0.01 * tau_rms / eta_rms**2, 0.01 * tau_rms / eta_rms, 0.01 * tau_rms / eta_rms]
        + [0.01 * tau_rms] * 2
        + [0.01 * tau_rms / (0.5 * form.geometry[0]) if form is not None and form.geometry else 0.0]
        * (theta0_start.size - 8)
    )
    return np.maximum(np.abs(theta0_start), floor)


def cluster_sandwich(jac: np.ndarray, resid: np.ndarray, cluster: np.ndarray, n_clusters: int) -> np.ndarray:
    """Cluster-robust covariance (p, p): H^-1 (G/(G-1)) sum_g s_g s_g^T H^-1, H = J^T J, s_g = J_g^T r_g.

    jac (N, p), resid (N,), cluster (N,) in [0, n_clusters).
    """
    p = jac.shape[1]
    scores = np.zeros((n_clusters, p))
    np.add.at(scores, cluster, jac * resid[:, None])
    h_inv = np.linalg.inv(jac.T @ jac)
    meat = n_clusters / (n_clusters - 1) * (scores.T @ scores)
    cov = h_inv @ meat @ h_inv
    return 0.5 * (cov + cov.T)


def identify_oe(
    t: np.ndarray,
    eta: np.ndarray,
    tau: np.ndarray,
    theta0_start: np.ndarray,
    *,
    torque_hold: str = "zoh",
    max_nfev: int = MAX_NFEV,
    segment_seconds: float | None = SHOOTING_SECONDS,
    max_step: float = MAX_STEP,
    form: RegressorForm | None = None,
) -> BaseEstimate:
    """Output-error estimate of theta0 (8,) = [m11 m12 m22 Vc Fv1 Fv2 Fd1 Fd2], started from theta0_start.

    With ``form`` (the observer's :class:`wmrid.model.dynamics.RegressorForm`) of the geometric caster model theta0 has
    form.n_base entries, the drag forces D_1..D_K last (form.base_names), and the simulation includes their drag
    (:func:`wmrid.model.predict.simulate_speeds`); a form without caster drag is the same as None; the two-term caster
    model (no positions) is refused with UsageError.

    t (n,) s strictly increasing, eta (n, 2) rad/s measured wheel speeds [right, left], tau (n, 2) N m
    (or any effort unit: the parameters follow it), theta0_start (8,) the starting point (the observer's
    estimate in wmrid; OE alone has a local-minimum problem far from the truth).  torque_hold "zoh" / "foh"
    (:mod:`wmrid.model.predict`), max_nfev: budget of cost evaluations, segment_seconds: multiple-shooting
    segment length in s (None: one free-running simulation), max_step: longest RK4 substep, s.
    theta0_start has form.n_base entries (8 without a form).

    Returns a :class:`BaseEstimate` with method "oe", the cluster-robust covariance with dof = G - 1 and
    diagnostics (iterations, cost and fit % at the start and the end, segments).  Raises UsageError for
    bad input and NotIdentifiableError when the optimiser fails or the log does not determine theta0.
    """
    started = time.perf_counter()
    t = plain(t)
    eta = np.ascontiguousarray(eta, dtype=float)
    tau = plain(tau)
    x0 = np.array(theta0_start, dtype=float)
    n = t.size
    if t.ndim != 1 or n < 3:
        raise UsageError(f"t must be a 1-D array of at least 3 samples, got shape {t.shape}")
    if eta.shape != (n, 2) or tau.shape != (n, 2):
        raise UsageError(f"eta and tau must have shape ({n}, 2), got {eta.shape} and {tau.shape}")
    n_base = 8 if form is None else form.n_base
    if x0.shape != (n_base,):
        raise UsageError(f"theta0_start must have shape ({n_base},), got {x0.shape}")
    if not all(np.all(np.isfinite(a)) for a in (t, eta, tau, x0)):
        raise UsageError("t, eta, tau and theta0_start must be finite")
    if not np.all(np.diff(t) > 0):
        raise UsageError("t must be strictly increasing")
    if torque_hold not in values(TorqueHold):
        raise UsageError(f"torque_hold must be zoh or foh, got {torque_hold!r}")
    if segment_seconds is not None and not (math.isfinite(segment_seconds) and segment_seconds > 0):
        raise UsageError(f"segment_seconds must be a finite number > 0 (s) or None, got {segment_seconds}")
    if not (isinstance(max_nfev, int) and max_nfev >= 1):
        raise UsageError(f"max_nfev must be an integer >= 1, got {max_nfev!r}")
    if not (math.isfinite(max_step) and max_step > 0):
        raise UsageError(f"max_step must be a finite number > 0 (s), got {max_step}")
    foh = torque_hold == "foh"
    caster_array(x0, form)  # refuses the two-term caster model before any work

    starts = shooting_starts(t, segment_seconds)
    eta_start = np.ascontiguousarray(eta[starts])
    keep = np.ones(n, dtype=bool)
    keep[starts] = False  # residuals there are 0 whatever theta0
    target = eta[keep].ravel()
    if target.size < n_base:
        raise NotIdentifiableError(f"output error: {target.size} residuals cannot determine {n_base} parameters")

    def simulate(theta: np.ndarray, st: np.ndarray = starts, e0: np.ndarray = eta_start) -> np.ndarray:
        cas = caster_array(theta, form)
        return simulate_kernel(t, tau, np.ascontiguousarray(theta[:8]), st, e0, foh, float(max_step), cas)

    def residual(theta: np.ndarray) -> np.ndarray:
        r = simulate(theta)[keep].ravel() - target
        # A diverging trial simulation (e.g. Vc far off: the V(eta) term is quadratic) gets a huge but finite
        # residual, so the optimiser rejects the step instead of computing with NaN.
        return np.clip(np.nan_to_num(r, nan=DIVERGED), -DIVERGED, DIVERGED)

    scale = _scales(x0, eta, tau, form)
    steps = FD_STEP * np.maximum(np.abs(x0), scale)
    workers = max(1, min(8, os.cpu_count() or 1))

    with ThreadPoolExecutor(max_workers=workers) as pool:

        def jacobian(theta: np.ndarray) -> np.ndarray:
            def column(j: int) -> np.ndarray:
                up, down = theta.copy(), theta.copy()
                up[j] += steps[j]
                down[j] -= steps[j]
                return (residual(up) - residual(down)) / (up[j] - down[j])

            return np.stack(list(pool.map(column, range(n_base))), axis=1)

        r_start = residual(x0)
        if np.any(np.abs(r_start) >= DIVERGED):
            raise NotIdentifiableError(
                "output error: the simulation from the starting parameters diverges; start closer to the truth"
            )
        try:
            res = least_squares(residual, x0, jac=jacobian, method="lm", x_scale=scale, max_nfev=max_nfev)
        except (ValueError, np.linalg.LinAlgError) as exc:
            raise NotIdentifiableError(f"output error: the optimiser failed ({exc})") from exc
        if res.status < 0 or not (np.all(np.isfinite(res.x)) and np.all(np.isfinite(res.fun))):
            raise NotIdentifiableError(f"output error: the optimiser failed ({res.message})")
        theta = res.x
        jac = jacobian(theta)
    r_end = residual(theta)

    if np.any(np.abs(r_end) >= DIVERGED) or not np.all(np.isfinite(jac)):
        raise NotIdentifiableError("output error: the simulation diverges at the optimiser's result")
    norms = np.linalg.norm(jac, axis=0)
    if not np.all(norms > 0):
        raise NotIdentifiableError("output error: the log does not determine every base parameter (zero sensitivity)")
    info = np.linalg.eigvalsh((jac / norms).T @ (jac / norms))
    if not info[0] > UNEXCITED * info[-1]:
        raise NotIdentifiableError(
            f"output error: the log does not determine all base parameters (information ratio {info[0] / info[-1]:.0e})"
        )

    kept_t = t[keep]
    n_clusters = segment_count(float(t[-1] - t[0]), kept_t.size)
    cluster = np.repeat(_cluster_index(kept_t, n_clusters), 2)
    cov = cluster_sandwich(jac, r_end, cluster, n_clusters)

    def fits(theta_: np.ndarray, st: np.ndarray, e0: np.ndarray) -> list[float | None]:
        """Fit % per wheel, None where undefined (a constant speed) or the simulation diverged."""
        with np.errstate(all="ignore"):
            values = fit_percent(eta, simulate(theta_, st, e0))
        return [float(v) if math.isfinite(v) else None for v in values]

    one = np.zeros(1, dtype=np.int64)
    e_first = eta[:1].copy()  # writable, as eta_start: a read-only view (of a read-only log) compiled the kernel again
    cost_start = 0.5 * float(r_start @ r_start)
    cost_end = 0.5 * float(r_end @ r_end)
    warnings: list[str] = []
    if res.status == 0:
        warnings.append(
            f"output error did not converge within {max_nfev} evaluations; the estimate is the best point found"
        )
    diagnostics = {
        "converged": bool(res.status > 0),
        "status": int(res.status),
        "message": str(res.message),
        "iterations": int(res.njev) if res.njev is not None else None,
        "evaluations": int(res.nfev),
        "cost_start": cost_start,
        "cost_end": cost_end,
        "rms_start": math.sqrt(2.0 * cost_start / r_start.size),
        "rms_end": math.sqrt(2.0 * cost_end / r_end.size),
        "fit_percent_start": fits(x0, starts, eta_start),
        "fit_percent_end": fits(theta, starts, eta_start),
        "free_run_fit_percent_start": fits(x0, one, e_first),
        "free_run_fit_percent_end": fits(theta, one, e_first),
        "shooting_segments": int(starts.size),
        "segment_seconds": segment_seconds,
        "clusters": int(n_clusters),
        "information_ratio": float(info[0] / info[-1]),
        "torque_hold": torque_hold,
        "predictor": predictor_text(torque_hold, form)
        + (f", restarted from the measured speed every {segment_seconds:g} s" if segment_seconds is not None else ""),
        "theta0_start": [float(v) for v in x0],
    }
    if n_base > 8:  # names only with the caster drag: the wheel-only diagnostics stay as they were
        diagnostics["parameter_names"] = list(form.base_names)
    return BaseEstimate(
        method="oe",
        theta0=theta.copy(),
        cov=cov,
        dof=n_clusters - 1,
        seconds=time.perf_counter() - started,
        diagnostics=diagnostics,
        warnings=tuple(warnings),
    )
