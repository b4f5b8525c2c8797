"""The validation predictor: the model's wheel speeds simulated from the measured torques.

Given the logged torques tau (n, 2) N m and base parameters theta0 (see :mod:`wmrid.model.dynamics`), integrate
the direct model (Eq. 20, no disturbance)::

    eta_dot = m (tau - V(eta) - F_v eta - F_d sgn(eta)),   m = M^-1

from the log's first measured speed, open loop: the simulated speed never sees the measured one again.
Comparing it with the measured speed (:func:`fit_percent`, MATLAB ``compare``'s NRMSE fit) is the usual
validation of an identified model, and minimising the difference is the output-error method
(:mod:`wmrid.estimators.output_error`).

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

Caster drag (``form``, the identified :class:`wmrid.model.dynamics.RegressorForm`): with the geometric model (the
casters' positions known) theta0 has form.n_base entries, the drag forces D_k last, and the drag's wheel
torques (:func:`wmrid.model.dynamics.friction_torque`) join V and F_v eta in the integrated field.  The drag is smooth
in eta (its direction regularised by :data:`wmrid.model.dynamics.DRAG_SPEED`, 0 at eta = 0), so it adds no event: at
zero speed it is part of the known torque F the Coulomb friction must hold (F = tau - V - F_v eta - drag).
Without caster drag the kernel does exactly the arithmetic it did before (bit for bit).  The two-term model
(Cv sgn(eta_1 + eta_2), Cw sgn(eta_1 - eta_2), no positions) has switches of its own at eta_1 = +-eta_2 that
would need the same exact event treatment: it is refused (:class:`UsageError`) rather than smoothed silently.

Pure functions on numpy arrays; the loop is a numba kernel: 0.43 s (zoh) / 0.54 s (foh) for 3.6 M
samples, one hour at 1 kHz, after compilation (one core; 2 substeps per sample: 0.76 s).
"""

from __future__ import annotations

import math

import numba
import numpy as np

from wmrid.core.choices import TorqueHold, values
from wmrid.core.errors import UsageError
from wmrid.model.dynamics import DRAG_SPEED as DRAG_SPEED_MODEL, RegressorForm
from wmrid.model.kernels import plain

#: Default longest RK4 substep, s (one substep per sample at 1 kHz; see the module docstring).
MAX_STEP = 1e-3
#: Zero crossings / mode changes handled within one substep before the rest of it is taken as is.
_MAX_EVENTS = 8
#: Regularisation of the casters' drag direction, m/s (the model's, :data:`wmrid.model.dynamics.DRAG_SPEED`).
DRAG_SPEED = DRAG_SPEED_MODEL
#: The kernel's caster argument when the model has no caster drag.
NO_CASTERS = np.zeros(0)

PREDICTOR = (
    "wheel speeds simulated open loop from the measured torques ({hold}) by the identified model "
    "(Eq. 20, RK4, Coulomb friction holding a wheel at rest), starting at the log's first measured speed"
)


# --------------------------------------------------------------------------------------------------
# Compiled kernel.  th (8,) = theta0 = [m11, m12, m22, Vc, Fv1, Fv2, Fd1, Fd2]; a mode s_j is +1 / -1
# (wheel turning that way, friction Fd_j s_j) or 0 (wheel at rest, eta_j' = 0).


@numba.njit(cache=True, nogil=True)
def _drag(e1, e2, cas):
    """The casters' drag torques (d_1, d_2) N m at the wheels (in the model as friction: subtracted from tau).

    cas = [r, b, x_1, y_1, D_1, ..., x_K, y_K, D_K] (see :func:`caster_array`); as
    :func:`wmrid.model.dynamics.friction_torque`'s caster part: caster k's contact moves at u = (v - w y_k, w x_k), and
    its drag D_k needs the wheel torques D_k (a_k [1, 1] + c_k [1, -1]), a_k = (r/2) u_x/|u|, c_k = (r/(2b))
    (x_k u_y - y_k u_x)/|u|, |u| regularised by DRAG_SPEED (smooth in eta, 0 at eta = 0).
    """
    r, b = cas[0], cas[1]
    v = 0.5 * r * (e1 + e2)
    w = r / (2.0 * b) * (e1 - e2)
    d1, d2 = 0.0, 0.0
    for k in range((cas.shape[0] - 2) // 3):
        x, y, force = cas[2 + 3 * k], cas[3 + 3 * k], cas[4 + 3 * k]
        ux = v - w * y
        uy = w * x
        norm = math.sqrt(ux * ux + uy * uy + DRAG_SPEED * DRAG_SPEED)
        a = 0.5 * r * ux / norm
        c = r / (2.0 * b) * (x * uy - y * ux) / norm
        d1 += force * (a + c)
        d2 += force * (a - c)
    return d1, d2


@numba.njit(cache=True, nogil=True)
def _accel(e1, e2, t1, t2, th, s1, s2, cas):
    """(eta_1', eta_2') rad/s^2 at speeds e, torques t, in mode (s1, s2); cas: caster drag (empty: none)."""
    m11, m12, m22, vc = th[0], th[1], th[2], th[3]
    g1 = t1 - vc * (e1 * e2 - e2 * e2) - th[4] * e1 - th[6] * s1
    g2 = t2 - vc * (e1 * e2 - e1 * e1) - th[5] * e2 - th[7] * s2
    if cas.shape[0] > 0:
        d1, d2 = _drag(e1, e2, cas)
        g1 -= d1
        g2 -= d2
    if s1 != 0.0 and s2 != 0.0:
        return m11 * g1 + m12 * g2, m12 * g1 + m22 * g2
    if s1 == 0.0 and s2 == 0.0:
        return 0.0, 0.0
    if s1 == 0.0:  # wheel 1 held: row 2 of M eta' = g with eta_1' = 0 gives eta_2' = g2 / M22, 1/M22 = det m / m11
        return 0.0, (m22 - m12 * m12 / m11) * g2
    return (m11 - m12 * m12 / m22) * g1, 0.0


@numba.njit(cache=True, nogil=True)
def _mode(e1, e2, t1, t2, th, cas):
    """The consistent mode (s1, s2) at speeds e and torques t (see the module docstring)."""
    s1 = 1.0 if e1 > 0.0 else (-1.0 if e1 < 0.0 else 0.0)
    s2 = 1.0 if e2 > 0.0 else (-1.0 if e2 < 0.0 else 0.0)
    if s1 != 0.0 and s2 != 0.0:
        return s1, s2
    m11, m12, m22, vc = th[0], th[1], th[2], th[3]
    fd1, fd2 = th[6], th[7]
    det = m11 * m22 - m12 * m12
    f1 = t1 - vc * (e1 * e2 - e2 * e2) - th[4] * e1  # F = tau - V - Fv eta (Coulomb friction excluded)
    f2 = t2 - vc * (e1 * e2 - e1 * e1) - th[5] * e2
    if cas.shape[0] > 0:  # the casters' drag: smooth in eta, a known torque at this state like V and Fv eta
        d1, d2 = _drag(e1, e2, cas)
        f1 -= d1
        f2 -= d2
    if det > 0.0 and m11 > 0.0 and fd1 >= 0.0 and fd2 >= 0.0:
        big11, big12, big22 = m22 / det, -m12 / det, m11 / det
        cand1 = (0.0, 1.0, -1.0) if s1 == 0.0 else (s1, s1, s1)
        cand2 = (0.0, 1.0, -1.0) if s2 == 0.0 else (s2, s2, s2)
        n1 = 3 if s1 == 0.0 else 1
        n2 = 3 if s2 == 0.0 else 1
        for i in range(n1):
            for j in range(n2):
                c1, c2 = cand1[i], cand2[j]
                a1, a2 = _accel(e1, e2, t1, t2, th, c1, c2, cas)
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
def _rk4(e1, e2, s1, s2, ta1, ta2, tm1, tm2, tb1, tb2, h, th, cas):
    """One RK4 step of length h in mode (s1, s2); torques at the start (ta), middle (tm) and end (tb)."""
    k11, k12 = _accel(e1, e2, ta1, ta2, th, s1, s2, cas)
    k21, k22 = _accel(e1 + 0.5 * h * k11, e2 + 0.5 * h * k12, tm1, tm2, th, s1, s2, cas)
    k31, k32 = _accel(e1 + 0.5 * h * k21, e2 + 0.5 * h * k22, tm1, tm2, th, s1, s2, cas)
    k41, k42 = _accel(e1 + h * k31, e2 + h * k32, tb1, tb2, th, s1, s2, cas)
    return (
        e1 + h / 6.0 * (k11 + 2.0 * k21 + 2.0 * k31 + k41),
        e2 + h / 6.0 * (k12 + 2.0 * k22 + 2.0 * k32 + k42),
    )


@numba.njit(cache=True, nogil=True)
def _crossing(e1, e2, s1, s2, x0, x1, slope1, slope2, u1, u2, w0, dw, th, cas, wheel):
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
                      u1 + wb * slope1, u2 + wb * slope2, part * th[8], th, cas)  # fmt: skip
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
def _advance(e1, e2, u1, u2, slope1, slope2, w0, dw, th, cas):
    """Speeds after one substep covering the fraction [w0, w0 + dw] of a sample interval.

    The torque over the interval is u + w slope (w the fraction, slope = 0 for zero-order hold); th (9,)
    is theta0 followed by the interval's length in s, cas the caster drag (:func:`caster_array`; empty: none).
    Zero crossings and mode changes as documented.
    """
    for ev in range(_MAX_EVENTS):
        ta1, ta2 = u1 + w0 * slope1, u2 + w0 * slope2
        s1, s2 = _mode(e1, e2, ta1, ta2, th, cas)
        wm, wb = w0 + 0.5 * dw, w0 + dw
        n1, n2 = _rk4(e1, e2, s1, s2, ta1, ta2, u1 + wm * slope1, u2 + wm * slope2, u1 + wb * slope1,
                      u2 + wb * slope2, dw * th[8], th, cas)  # fmt: skip
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
            alpha = _crossing(e1, e2, s1, s2, e1, n1, slope1, slope2, u1, u2, w0, dw, th, cas, 0)
        if c2:
            alpha = min(alpha, _crossing(e1, e2, s1, s2, e2, n2, slope1, slope2, u1, u2, w0, dw, th, cas, 1))
        part = alpha * dw  # fraction of the sample interval up to the crossing
        wm, wb = w0 + 0.5 * part, w0 + part
        n1, n2 = _rk4(e1, e2, s1, s2, ta1, ta2, u1 + wm * slope1, u2 + wm * slope2, u1 + wb * slope1,
                      u2 + wb * slope2, part * th[8], th, cas)  # fmt: skip
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
def simulate_kernel(t, tau, theta0, starts, eta_start, foh, max_step, cas):
    """Simulated speeds (n, 2) rad/s; the state is reset to eta_start[g] at sample starts[g].

    t (n,) s increasing, tau (n, 2) N m, theta0 (8,) (the wheel part), starts (G,) int64 increasing with
    starts[0] = 0, eta_start (G, 2) rad/s, foh: bool (linear torque between samples, else hold), max_step: s,
    cas: the casters' drag (:func:`caster_array`; an empty array for none).
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
            e1, e2 = _advance(e1, e2, u1, u2, slope1, slope2, j * dw, dw, th, cas)
    return out


# --------------------------------------------------------------------------------------------------


def _check_hold(torque_hold: str) -> bool:
    if torque_hold not in values(TorqueHold):
        raise UsageError(f"torque_hold must be zoh or foh, got {torque_hold!r}")
    return torque_hold == "foh"


#: Refusal of the two-term caster model (no positions): its sgn(eta_1 +- eta_2) switches are not handled.
TWO_TERM_REFUSAL = (
    "--validate/oe model the caster drag only with the casters' positions ([[caster]] in the robot file); "
    "the two-term model (Cv, Cw) switches at eta_1 = -eta_2 and eta_1 = eta_2, which the predictor does not "
    "handle as events"
)


def unsimulated(form: RegressorForm | None) -> str | None:
    """Why the validation predictor cannot simulate a model of ``form`` (the two-term caster drag: see
    :func:`caster_array`), said in one sentence, or None when it can."""
    if form is not None and form.caster and not form.geometry:
        return (
            "no fit: the identified caster drag (Cv, Cw) cannot be simulated without the casters' positions; give "
            "a robot file with [[caster]] tables to validate it"
        )
    if form is not None and form.load:
        return LOAD_REFUSAL
    return None


#: Why the predictor does not simulate the ``wheel+caster+load`` model.
LOAD_REFUSAL = (
    "no fit: the predictor does not simulate a caster drag that follows the load (friction wheel+caster+load); "
    "identify with --friction wheel+caster to validate"
)


def caster_array(theta0: np.ndarray, form: RegressorForm | None) -> np.ndarray:
    """The kernel's caster argument for base parameters theta0 of model ``form``.

    [r, b, x_1, y_1, D_1, ..., x_K, y_K, D_K] for the geometric caster model (form.geometry and
    theta0[8:] = D_1..D_K); :data:`NO_CASTERS` (empty) without caster drag (form None or form.caster
    False).  The two-term model (caster drag without positions) raises :class:`UsageError`: its Coulomb-like
    switches at eta_1 = +-eta_2 would need exact event handling the predictor does not do, and smoothing them
    would be a silent approximation.
    """
    if form is None or not form.caster:
        return NO_CASTERS
    if not form.geometry:
        raise UsageError(TWO_TERM_REFUSAL)
    if form.load:
        raise UsageError(LOAD_REFUSAL)
    geo = form.geometry
    cas = [geo[0], geo[1]]
    for k in range(form.n_casters):
        cas += [geo[2 + 2 * k], geo[3 + 2 * k], float(theta0[8 + k])]
    return np.array(cas, dtype=float)


def predictor_text(torque_hold: str, form: RegressorForm | None = None) -> str:
    """One sentence naming the predictor (:data:`PREDICTOR`, plus the casters' drag when the model has it)."""
    text = PREDICTOR.format(hold=torque_hold)
    if form is not None and form.caster:
        text = text.replace("holding a wheel at rest)", "holding a wheel at rest, the casters' rolling drag)")
    return text


def _check_inputs(
    t: np.ndarray, tau: np.ndarray, theta0: np.ndarray, max_step: float, form: RegressorForm | None = None
) -> tuple[np.ndarray, ...]:
    """Checked (t, tau, theta0[:8], cas): the wheel part of theta0 and the kernel's caster argument."""
    t = plain(t)
    tau = plain(tau)
    theta0 = plain(theta0)
    if t.ndim != 1 or t.size < 1:
        raise UsageError(f"t must be a non-empty 1-D array, got shape {t.shape}")
    if tau.shape != (t.size, 2):
        raise UsageError(f"tau must have shape ({t.size}, 2), got {tau.shape}")
    n_base = 8 if form is None else form.n_base
    if theta0.shape != (n_base,):
        raise UsageError(f"theta0 must have shape ({n_base},), got {theta0.shape}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(tau)) and np.all(np.isfinite(theta0))):
        raise UsageError("t, tau and theta0 must be finite")
    if t.size > 1 and not np.all(np.diff(t) > 0):
        raise UsageError("t must be strictly increasing")
    if not (math.isfinite(max_step) and max_step > 0):
        raise UsageError(f"max_step must be a finite number > 0 (s), got {max_step}")
    cas = caster_array(theta0, form)
    return t, tau, np.ascontiguousarray(theta0[:8]), cas


def simulate_segments(
    t: np.ndarray,
    tau: np.ndarray,
    theta0: np.ndarray,
    eta: np.ndarray,
    starts: np.ndarray,
    *,
    torque_hold: str = "zoh",
    max_step: float = MAX_STEP,
    form: RegressorForm | None = None,
) -> np.ndarray:
    """Simulated speeds (n, 2) rad/s, restarted from the measured speed eta[s] at each index s of ``starts``.

    t (n,) s strictly increasing, tau (n, 2) N m, theta0 (form.n_base,) (8 without a form), eta (n, 2) rad/s
    measured speeds (only the rows in ``starts`` are read), starts (G,) increasing sample indices with
    starts[0] = 0.  Each segment [starts[g], starts[g+1]) is an independent open-loop simulation (the
    output-error method's multiple shooting); see :func:`simulate_speeds` for the integration and ``form``.
    """
    t, tau, theta0, cas = _check_inputs(t, tau, theta0, max_step, form)
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
    return simulate_kernel(t, tau, theta0, starts, eta_start, foh, float(max_step), cas)


def simulate_speeds(
    t: np.ndarray,
    tau: np.ndarray,
    theta0: np.ndarray,
    eta0: np.ndarray,
    *,
    torque_hold: str = "zoh",
    max_step: float = MAX_STEP,
    form: RegressorForm | None = None,
) -> np.ndarray:
    """The model's wheel speeds eta_hat (n, 2) rad/s, simulated open loop from the measured torques.

    t (n,) s strictly increasing (uneven steps allowed), tau (n, 2) N m, theta0 (8,) base parameters,
    eta0 (2,) rad/s the speed at t[0] (the log's first measured speed), torque_hold "zoh" (tau[k] held
    over [t_k, t_k+1)) or "foh" (linear between samples), max_step: longest RK4 substep (s).
    eta_hat[0] = eta0.  Integration and the treatment of zero speed: see the module docstring.

    form: the identified model's :class:`wmrid.model.dynamics.RegressorForm` (None: the eight wheel parameters).  With
    the geometric caster model theta0 has form.n_base entries, the last ones the drag forces D_k, and the drag
    (smooth in eta) is part of the simulated dynamics; a form without caster drag changes nothing; the
    two-term caster model (no positions) is refused with :class:`UsageError`.
    """
    t, tau, theta0, cas = _check_inputs(t, tau, theta0, max_step, form)
    foh = _check_hold(torque_hold)
    eta0 = np.asarray(eta0, dtype=float)
    if eta0.shape != (2,) or not np.all(np.isfinite(eta0)):
        raise UsageError(f"eta0 must be 2 finite speeds (rad/s), got {eta0!r}")
    starts = np.zeros(1, dtype=np.int64)
    return simulate_kernel(t, tau, theta0, starts, eta0.reshape(1, 2).copy(), foh, float(max_step), cas)


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
    t: np.ndarray,
    eta: np.ndarray,
    tau: np.ndarray,
    theta0: np.ndarray,
    torque_hold: str = "zoh",
    form: RegressorForm | None = None,
) -> dict[str, object]:
    """Fit (%) of the simulated wheel speeds to the measured ones, per wheel, with the predictor's definition.

    t (n,) s, eta (n, 2) rad/s measured, tau (n, 2) N m, theta0 (8,) or (form.n_base,) with ``form`` (the
    identified model's; caster drag as :func:`simulate_speeds`).  Returns {"eta_r": fit %, "eta_l": fit %,
    "predictor": one sentence}; the simulation starts at eta[0] (:func:`simulate_speeds`).
    """
    eta = np.asarray(eta, dtype=float)
    if eta.ndim != 2 or eta.shape[1] != 2 or eta.shape[0] < 1:
        raise UsageError(f"eta must have shape (n, 2), got {eta.shape}")
    eta_hat = simulate_speeds(t, tau, theta0, eta[0], torque_hold=torque_hold, form=form)
    fit = fit_percent(eta, eta_hat)
    return {"eta_r": float(fit[0]), "eta_l": float(fit[1]), "predictor": predictor_text(torque_hold, form)}
