"""The validation predictor: the model's wheel speeds simulated from the measured torques.

Given the logged torques tau (n, 2) N m and base parameters theta0 (see :mod:`wmrid.model`), integrate
the direct model (Eq. 20, no disturbance)::

    eta_dot = m (tau - V(eta) - F_v eta - F_d sgn(eta)),   m = M^-1

from the log's first measured speed, open loop: the simulated speed never sees the measured one again.
Comparing it with the measured speed (:func:`fit_percent`, MATLAB ``compare``'s NRMSE fit) is the usual
validation of an identified model, and minimising the difference is the output-error method
(:mod:`wmrid.output_error`).

Torque between samples (``torque_hold``): ``"zoh"`` holds tau[k] over [t_k, t_k+1) (a digital
controller's command; the simulator's convention), ``"foh"`` interpolates linearly from tau[k] to
tau[k+1] (a measured, continuous effort).  Same meaning as the observer's option.

Integration: classical RK4 with a fixed step, each sample interval split into
ceil((t_k+1 - t_k) / max_step) equal substeps (default max_step = 1 ms: one substep at 1 kHz, ten at
100 Hz; uneven logs are fine).  Sample times are substep boundaries, so the torque is smooth within
every step and RK4 keeps its fourth order.  The wheel dynamics are slow against 1 ms (rates m F_v and
m V_c eta of 0.01-1 1/s for the paper's robot; the local error goes as (rate h)^5): on the paper
robot over 5 s the speeds at h = 1 ms differ from those at h = 0.01 ms by 2e-13 rad/s, and by 5e-11
rad/s at h = 10 ms.  A robot with much faster wheel dynamics (rate h > 0.1) wants a smaller max_step.

Coulomb friction at zero speed (the one discontinuity): the friction is set-valued at eta_j = 0, as
in the standard (stiction-free) Coulomb model: a wheel at rest stays at rest while the friction torque
needed to hold it, |f_j| <= F_dj, and otherwise starts to turn in the direction of the net torque.
Concretely:

* within a step each wheel has a fixed mode, s_j = +1 or -1 (turning; friction F_dj s_j) or 0 (at
  rest; eta_j' = 0 and f_j whatever holds it), so RK4 integrates a smooth vector field;
* a turning wheel whose speed would cross zero within a step: the crossing instant is located (regula
  falsi on the RK4 step length, to ~1e-12 of the step), the step is cut there, the speed set to exactly
  0, and the rest of the step continues in the mode chosen below;
* at zero speed the mode is the (unique, for positive definite M and F_d >= 0) consistent one of
  {rest, +1, -1} per wheel: rest if the holding friction f = F - M eta' (F = tau - V - F_v eta) is within
  [-F_d, F_d], else the direction of the resulting acceleration.  Breakaway is checked at step starts,
  so it can be late by at most one substep (where the excess torque is still ~0).

So a wheel that brakes through zero with |net torque| < F_d stops and stays stopped, and one pushed
harder reverses: neither smoothing of sgn nor chattering around zero.  For a log whose wheels never
reach zero (the paper's sinusoid) this is exactly Eq. (20).  With non-physical parameters (F_d < 0, or
m not positive definite) a consistent mode may not exist; the wheel then leaves zero with sgn(0) = 0.

Pure functions on numpy arrays; the loop is a numba kernel: 0.43 s (zoh) / 0.54 s (foh) for 3.6 M
samples, one hour at 1 kHz, after compilation (one core; 2 substeps per sample: 0.76 s).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from wmrid.errors import UsageError

#: Default longest RK4 substep, s (one substep per sample at 1 kHz; see the module docstring).
MAX_STEP = 1e-3
#: Zero crossings / mode changes handled within one substep before the rest of it is taken as is.
_MAX_EVENTS = 8

PREDICTOR = (
    "wheel speeds simulated open loop from the measured torques ({hold}) by the identified model "
    "(Eq. 20, RK4, Coulomb friction holding a wheel at rest), starting at the log's first measured speed"
)


# --------------------------------------------------------------------------------------------------
# Compiled kernel.  th (8,) = theta0 = [m11, m12, m22, Vc, Fv1, Fv2, Fd1, Fd2]; a mode s_j is +1 / -1
# (wheel turning that way, friction Fd_j s_j) or 0 (wheel at rest, eta_j' = 0).


@numba.njit(cache=True, nogil=True)
def _accel(e1, e2, t1, t2, th, s1, s2):
    """(eta_1', eta_2') rad/s^2 at speeds e, torques t, in mode (s1, s2)."""
    m11, m12, m22, vc = th[0], th[1], th[2], th[3]
    g1 = t1 - vc * (e1 * e2 - e2 * e2) - th[4] * e1 - th[6] * s1
    g2 = t2 - vc * (e1 * e2 - e1 * e1) - th[5] * e2 - th[7] * s2
    if s1 != 0.0 and s2 != 0.0:
        return m11 * g1 + m12 * g2, m12 * g1 + m22 * g2
    if s1 == 0.0 and s2 == 0.0:
        return 0.0, 0.0
    if s1 == 0.0:  # wheel 1 held: row 2 of M eta' = g with eta_1' = 0 gives eta_2' = g2 / M22, 1/M22 = det m / m11
        return 0.0, (m22 - m12 * m12 / m11) * g2
    return (m11 - m12 * m12 / m22) * g1, 0.0


@numba.njit(cache=True, nogil=True)
def _mode(e1, e2, t1, t2, th):
    """The consistent mode (s1, s2) at speeds e and torques t (see the module docstring)."""
    s1 = 1.0 if e1 > 0.0 else (-1.0 if e1 < 0.0 else 0.0)
    s2 = 1.0 if e2 > 0.0 else (-1.0 if e2 < 0.0 else 0.0)
    if s1 != 0.0 and s2 != 0.0:
        return s1, s2
    m11, m12, m22, vc = th[0], th[1], th[2], th[3]
    fd1, fd2 = th[6], th[7]
    det = m11 * m22 - m12 * m12
    f1 = t1 - vc * (e1 * e2 - e2 * e2) - th[4] * e1  # F = tau - V - Fv eta (friction excluded)
    f2 = t2 - vc * (e1 * e2 - e1 * e1) - th[5] * e2
    if det > 0.0 and m11 > 0.0 and fd1 >= 0.0 and fd2 >= 0.0:
        big11, big12, big22 = m22 / det, -m12 / det, m11 / det
        cand1 = (0.0, 1.0, -1.0) if s1 == 0.0 else (s1, s1, s1)
        cand2 = (0.0, 1.0, -1.0) if s2 == 0.0 else (s2, s2, s2)
        n1 = 3 if s1 == 0.0 else 1
        n2 = 3 if s2 == 0.0 else 1
        for i in range(n1):
            for j in range(n2):
                c1, c2 = cand1[i], cand2[j]
                a1, a2 = _accel(e1, e2, t1, t2, th, c1, c2)
                ok = True
                if c1 == 0.0:  # holding torque of wheel 1 from row 1 of M eta' = F - f
                    ok = ok and abs(f1 - big11 * a1 - big12 * a2) <= fd1
                elif s1 == 0.0:
                    ok = ok and c1 * a1 > 0.0
                if c2 == 0.0:
                    ok = ok and abs(f2 - big12 * a1 - big22 * a2) <= fd2
                elif s2 == 0.0:
                    ok = ok and c2 * a2 > 0.0
                if ok:
                    return c1, c2
    # No consistent mode (non-physical parameters): leave zero with sgn(0) = 0, as Eq. (20) reads.
    a1 = m11 * f1 + m12 * f2
    a2 = m12 * f1 + m22 * f2
    if s1 == 0.0:
        s1 = 1.0 if a1 > 0.0 else (-1.0 if a1 < 0.0 else 0.0)
    if s2 == 0.0:
        s2 = 1.0 if a2 > 0.0 else (-1.0 if a2 < 0.0 else 0.0)
    return s1, s2


@numba.njit(cache=True, nogil=True)
def _rk4(e1, e2, s1, s2, ta1, ta2, tm1, tm2, tb1, tb2, h, th):
    """One RK4 step of length h in mode (s1, s2); torques at the start (ta), middle (tm) and end (tb)."""
    k11, k12 = _accel(e1, e2, ta1, ta2, th, s1, s2)
    k21, k22 = _accel(e1 + 0.5 * h * k11, e2 + 0.5 * h * k12, tm1, tm2, th, s1, s2)
    k31, k32 = _accel(e1 + 0.5 * h * k21, e2 + 0.5 * h * k22, tm1, tm2, th, s1, s2)
    k41, k42 = _accel(e1 + h * k31, e2 + h * k32, tb1, tb2, th, s1, s2)
    return (
        e1 + h / 6.0 * (k11 + 2.0 * k21 + 2.0 * k31 + k41),
        e2 + h / 6.0 * (k12 + 2.0 * k22 + 2.0 * k32 + k42),
    )


@numba.njit(cache=True, nogil=True)
def _crossing(e1, e2, s1, s2, x0, x1, slope1, slope2, u1, u2, w0, dw, th, wheel):
    """Fraction in (0, 1] of a step at which wheel ``wheel`` (0/1) reaches zero speed (regula falsi, Illinois).

    The step starts at speeds e, spans the interval fraction [w0, w0 + dw] of a sample interval whose
    torque is u + w * slope, and is taken in mode (s1, s2).  x0 (at fraction 0) and x1 (at 1) are the
    wheel's speeds, of opposite signs.
    """
    lo, hi = 0.0, 1.0
    glo, ghi = x0, x1
    side = 0
    alpha = 1.0
    for _ in range(60):
        alpha = (lo * ghi - hi * glo) / (ghi - glo)
        if not (lo < alpha < hi):
            alpha = 0.5 * (lo + hi)
        part = alpha * dw
        wm = w0 + 0.5 * part
        wb = w0 + part
        n1, n2 = _rk4(e1, e2, s1, s2, u1 + w0 * slope1, u2 + w0 * slope2, u1 + wm * slope1, u2 + wm * slope2,
                      u1 + wb * slope1, u2 + wb * slope2, part * th[8], th)  # fmt: skip
        g = n1 if wheel == 0 else n2
        if g == 0.0 or hi - lo < 1e-13:
            break
        if (g > 0.0) == (glo > 0.0):
            lo, glo = alpha, g
            if side == -1:
                ghi *= 0.5
            side = -1
        else:
            hi, ghi = alpha, g
            if side == 1:
                glo *= 0.5
            side = 1
    return alpha


@numba.njit(cache=True, nogil=True)
def _advance(e1, e2, u1, u2, slope1, slope2, w0, dw, th):
    """Speeds after one substep covering the fraction [w0, w0 + dw] of a sample interval.

    The torque over the interval is u + w slope (w the fraction, slope = 0 for zero-order hold); th (9,)
    is theta0 followed by the interval's length in s.  Zero crossings and mode changes as documented.
    """
    for ev in range(_MAX_EVENTS):
        ta1, ta2 = u1 + w0 * slope1, u2 + w0 * slope2
        s1, s2 = _mode(e1, e2, ta1, ta2, th)
        wm, wb = w0 + 0.5 * dw, w0 + dw
        n1, n2 = _rk4(e1, e2, s1, s2, ta1, ta2, u1 + wm * slope1, u2 + wm * slope2, u1 + wb * slope1,
                      u2 + wb * slope2, dw * th[8], th)  # fmt: skip
        # A turning wheel crosses zero when its new speed is of the other sign (a wheel leaving zero is
        # not tracked within its first step: if it came back, it is put at rest below).
        c1 = e1 * s1 > 0.0 and n1 * s1 < 0.0
        c2 = e2 * s2 > 0.0 and n2 * s2 < 0.0
        if not (c1 or c2) or ev == _MAX_EVENTS - 1:
            if n1 * s1 < 0.0 or (s1 == 0.0 and n1 != 0.0):
                n1 = 0.0
            if n2 * s2 < 0.0 or (s2 == 0.0 and n2 != 0.0):
                n2 = 0.0
            return n1, n2
        alpha = 1.0
        if c1:
            alpha = _crossing(e1, e2, s1, s2, e1, n1, slope1, slope2, u1, u2, w0, dw, th, 0)
        if c2:
            alpha = min(alpha, _crossing(e1, e2, s1, s2, e2, n2, slope1, slope2, u1, u2, w0, dw, th, 1))
        part = alpha * dw  # fraction of the sample interval up to the crossing
        wm, wb = w0 + 0.5 * part, w0 + part
        n1, n2 = _rk4(e1, e2, s1, s2, ta1, ta2, u1 + wm * slope1, u2 + wm * slope2, u1 + wb * slope1,
                      u2 + wb * slope2, part * th[8], th)  # fmt: skip
        # Snap the wheel that crossed (and one that crossed within the root tolerance) to rest.
        if c1 and (n1 * s1 <= 0.0 or abs(n1) <= 1e-12 * abs(e1)):
            n1 = 0.0
        if c2 and (n2 * s2 <= 0.0 or abs(n2) <= 1e-12 * abs(e2)):
            n2 = 0.0
        if n1 * s1 < 0.0:
            n1 = 0.0
        if n2 * s2 < 0.0:
            n2 = 0.0
        e1, e2 = n1, n2
        w0 += part
        dw -= part
        if dw <= 0.0:
            break
    return e1, e2


@numba.njit(cache=True, nogil=True)
def simulate_kernel(t, tau, theta0, starts, eta_start, foh, max_step):
    """Simulated speeds (n, 2) rad/s; the state is reset to eta_start[g] at sample starts[g].

    t (n,) s increasing, tau (n, 2) N m, theta0 (8,), starts (G,) int64 increasing with starts[0] = 0,
    eta_start (G, 2) rad/s, foh: bool (linear torque between samples, else hold), max_step: s.
    """
    n = t.shape[0]
    out = np.empty((n, 2))
    th = np.empty(9)
    th[:8] = theta0
    g = 0
    e1, e2 = 0.0, 0.0
    for k in range(n):
        if g < starts.shape[0] and k == starts[g]:
            e1, e2 = eta_start[g, 0], eta_start[g, 1]
            g += 1
        out[k, 0] = e1
        out[k, 1] = e2
        if k == n - 1:
            break
        dt = t[k + 1] - t[k]
        th[8] = dt
        u1, u2 = tau[k, 0], tau[k, 1]
        slope1, slope2 = 0.0, 0.0
        if foh:
            slope1, slope2 = tau[k + 1, 0] - u1, tau[k + 1, 1] - u2
        ns = max(1, math.ceil(dt / max_step))
        dw = 1.0 / ns
        for j in range(ns):
            e1, e2 = _advance(e1, e2, u1, u2, slope1, slope2, j * dw, dw, th)
    return out


# --------------------------------------------------------------------------------------------------


def _check_hold(torque_hold: str) -> bool:
    if torque_hold not in ("zoh", "foh"):
        raise UsageError(f"torque_hold must be zoh or foh, got {torque_hold!r}")
    return torque_hold == "foh"


def _check_inputs(t: np.ndarray, tau: np.ndarray, theta0: np.ndarray, max_step: float) -> tuple[np.ndarray, ...]:
    t = np.ascontiguousarray(t, dtype=float)
    tau = np.ascontiguousarray(tau, dtype=float)
    theta0 = np.ascontiguousarray(theta0, dtype=float)
    if t.ndim != 1 or t.size < 1:
        raise UsageError(f"t must be a non-empty 1-D array, got shape {t.shape}")
    if tau.shape != (t.size, 2):
        raise UsageError(f"tau must have shape ({t.size}, 2), got {tau.shape}")
    if theta0.shape != (8,):
        raise UsageError(f"theta0 must have shape (8,), got {theta0.shape}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(tau)) and np.all(np.isfinite(theta0))):
        raise UsageError("t, tau and theta0 must be finite")
    if t.size > 1 and not np.all(np.diff(t) > 0):
        raise UsageError("t must be strictly increasing")
    if not (math.isfinite(max_step) and max_step > 0):
        raise UsageError(f"max_step must be a finite number > 0 (s), got {max_step}")
    return t, tau, theta0


def simulate_segments(
    t: np.ndarray,
    tau: np.ndarray,
    theta0: np.ndarray,
    eta: np.ndarray,
    starts: np.ndarray,
    *,
    torque_hold: str = "zoh",
    max_step: float = MAX_STEP,
) -> np.ndarray:
    """Simulated speeds (n, 2) rad/s, restarted from the measured speed eta[s] at each index s of ``starts``.

    t (n,) s strictly increasing, tau (n, 2) N m, theta0 (8,), eta (n, 2) rad/s measured speeds (only the
    rows in ``starts`` are read), starts (G,) increasing sample indices with starts[0] = 0.  Each segment
    [starts[g], starts[g+1]) is an independent open-loop simulation (the output-error method's multiple
    shooting); see :func:`simulate_speeds` for the integration.
    """
    t, tau, theta0 = _check_inputs(t, tau, theta0, max_step)
    foh = _check_hold(torque_hold)
    starts = np.ascontiguousarray(starts, dtype=np.int64)
    if starts.ndim != 1 or starts.size < 1 or starts[0] != 0 or np.any(np.diff(starts) <= 0) or starts[-1] >= t.size:
        raise UsageError("starts must be increasing sample indices beginning at 0")
    eta = np.asarray(eta, dtype=float)
    if eta.shape != (t.size, 2):
        raise UsageError(f"eta must have shape ({t.size}, 2), got {eta.shape}")
    eta_start = np.ascontiguousarray(eta[starts])
    if not np.all(np.isfinite(eta_start)):
        raise UsageError("the measured speeds at the segment starts must be finite")
    return simulate_kernel(t, tau, theta0, starts, eta_start, foh, float(max_step))


def simulate_speeds(
    t: np.ndarray,
    tau: np.ndarray,
    theta0: np.ndarray,
    eta0: np.ndarray,
    *,
    torque_hold: str = "zoh",
    max_step: float = MAX_STEP,
) -> np.ndarray:
    """The model's wheel speeds eta_hat (n, 2) rad/s, simulated open loop from the measured torques.

    t (n,) s strictly increasing (uneven steps allowed), tau (n, 2) N m, theta0 (8,) base parameters,
    eta0 (2,) rad/s the speed at t[0] (the log's first measured speed), torque_hold "zoh" (tau[k] held
    over [t_k, t_k+1)) or "foh" (linear between samples), max_step: longest RK4 substep (s).
    eta_hat[0] = eta0.  Integration and the treatment of zero speed: see the module docstring.
    """
    t, tau, theta0 = _check_inputs(t, tau, theta0, max_step)
    foh = _check_hold(torque_hold)
    eta0 = np.asarray(eta0, dtype=float)
    if eta0.shape != (2,) or not np.all(np.isfinite(eta0)):
        raise UsageError(f"eta0 must be 2 finite speeds (rad/s), got {eta0!r}")
    starts = np.zeros(1, dtype=np.int64)
    return simulate_kernel(t, tau, theta0, starts, eta0.reshape(1, 2).copy(), foh, float(max_step))


def fit_percent(y: np.ndarray, y_hat: np.ndarray) -> np.ndarray:
    """NRMSE fit (k,) in %, per column: 100 (1 - ||y - y_hat|| / ||y - mean(y)||), as MATLAB's ``compare``.

    y, y_hat (n, k) (or (n,), giving shape ()).  100 is a perfect fit, 0 no better than the mean, and it
    can be negative.  A constant column of y gives NaN (the fit is undefined).
    """
    y = np.asarray(y, dtype=float)
    y_hat = np.asarray(y_hat, dtype=float)
    if y.shape != y_hat.shape:
        raise UsageError(f"y and y_hat must have the same shape, got {y.shape} and {y_hat.shape}")
    num = np.linalg.norm(y - y_hat, axis=0)
    den = np.linalg.norm(y - y.mean(axis=0), axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den > 0, 100.0 * (1.0 - num / np.where(den > 0, den, 1.0)), np.nan)


def validation_fit(
    t: np.ndarray, eta: np.ndarray, tau: np.ndarray, theta0: np.ndarray, torque_hold: str = "zoh"
) -> dict[str, object]:
    """Fit (%) of the simulated wheel speeds to the measured ones, per wheel, with the predictor's definition.

    t (n,) s, eta (n, 2) rad/s measured, tau (n, 2) N m, theta0 (8,).  Returns {"eta_r": fit %, "eta_l":
    fit %, "predictor": one sentence}; the simulation starts at eta[0] (:func:`simulate_speeds`).
    """
    eta = np.asarray(eta, dtype=float)
    if eta.ndim != 2 or eta.shape[1] != 2 or eta.shape[0] < 1:
        raise UsageError(f"eta must have shape (n, 2), got {eta.shape}")
    eta_hat = simulate_speeds(t, tau, theta0, eta[0], torque_hold=torque_hold)
    fit = fit_percent(eta, eta_hat)
    return {"eta_r": float(fit[0]), "eta_l": float(fit[1]), "predictor": PREDICTOR.format(hold=torque_hold)}
