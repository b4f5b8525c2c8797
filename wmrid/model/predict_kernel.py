"""The compiled kernel of the speed predictor (:func:`simulate_kernel`, numba): the reduced dynamics integrated over a
log's efforts by RK4 with the Coulomb friction's stick-slip events located, one segment at a time
(:mod:`wmrid.model.predict`)."""

from __future__ import annotations

import math

import numpy as np

from wmrid.core.jit import kernel
from wmrid.model.dynamics import DRAG_SPEED as DRAG_SPEED_MODEL

#: Zero crossings / mode changes handled within one substep before the rest of it is taken as is.
_MAX_EVENTS = 8


#: Regularisation of the casters' drag direction, m/s (the model's, :data:`wmrid.model.dynamics.DRAG_SPEED`).
DRAG_SPEED = DRAG_SPEED_MODEL


@kernel
def _drag(e1, e2, cas):
    """The casters' drag torques (d_1, d_2) N m at the wheels (in the model as friction: subtracted from tau).

    cas = [r, b, x_1, y_1, D_1, ..., x_K, y_K, D_K] (see :func:`caster_array`); as
    :func:`wmrid.model.torques.friction_torque`'s caster part: caster k's contact moves at u = (v - w y_k, w x_k), and
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


#: Inlined where it is called (numba's own inlining: the 16 % of a simulation that the calls cost, for 0.4 s more of
#: compiling once; inlining the RK4 step as well doubled the compile for 5 % more, everything made it 22 s).  The same
#: arithmetic: the simulated speeds are bit-identical.
@kernel(inline=True)
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


@kernel
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


@kernel
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


@kernel
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


@kernel
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


@kernel
def simulate_kernel(t, tau, theta0, starts, eta_start, foh, max_step, cas):
    """Simulated speeds (n, 2) rad/s; the state is reset to eta_start[g] at sample starts[g].

    t (n,) s increasing, tau (n, 2) N m, theta0 (8,) (the wheel part), starts (G,) int64 increasing with
    starts[0] = 0, eta_start (G, 2) rad/s, foh: bool (linear torque between samples, else hold), max_step: s,
    cas: the casters' drag (:func:`caster_array`; an empty array for none).
    """
    n = t.shape[0]
    out = np.empty((n, 2))
    th = np.empty(9)
    for j in range(8):  # element by element: a slice assignment compiled numba's shape-mismatch message, 1.3 s
        th[j] = theta0[j]
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
