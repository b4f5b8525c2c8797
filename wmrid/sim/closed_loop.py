"""The compiled closed loop: reference trajectories, the plant's right-hand side (Eqs. 9-14), backstepping +
computed-torque control on the nominal parameters, and the RK4 loop that logs it (:func:`closed_loop_kernel`)."""

from __future__ import annotations

import math

import numpy as np

from wmrid.core.errors import UsageError
from wmrid.core.jit import kernel
from wmrid.model.kernels import sign

#: Trajectory kinds of the kernels: the built-ins in closed form, and a table (:mod:`wmrid.sim.reference`).
KIND = {"sinusoid": 0, "reversing": 1, "reference": 2}


@kernel
def table_state(traj, t):
    """The state of a tabulated reference (kind 2) at time t s: its row when t is on the table's grid (within 1e-6
    of a step), else the linear interpolation of the two rows around t; before the first row the first, after the
    last the last.  traj = [step T s, n_rows, n_rows x 7 values row by row] (:func:`wmrid.sim.reference.pack_table`).
    """
    step = traj[0]
    n_rows = int(traj[1])
    u = t / step
    k = math.floor(u + 0.5)
    if abs(u - k) <= 1e-6:  # on the grid (the control times k T)
        i = min(max(int(k), 0), n_rows - 1)
        frac = 0.0
    elif u <= 0.0:
        i, frac = 0, 0.0
    elif u >= n_rows - 1:
        i, frac = n_rows - 1, 0.0
    else:
        i = math.floor(u)
        frac = u - i
    a = 2 + 7 * i
    if frac == 0.0:
        return traj[a], traj[a + 1], traj[a + 2], traj[a + 3], traj[a + 4], traj[a + 5], traj[a + 6]
    g = 1.0 - frac
    return (g * traj[a] + frac * traj[a + 7], g * traj[a + 1] + frac * traj[a + 8],
            g * traj[a + 2] + frac * traj[a + 9], g * traj[a + 3] + frac * traj[a + 10],
            g * traj[a + 4] + frac * traj[a + 11], g * traj[a + 5] + frac * traj[a + 12],
            g * traj[a + 6] + frac * traj[a + 13])  # fmt: skip


@kernel
def reference_state(kind, traj, t, xr_int, yr_int):
    """Reference at time t: (x_r m, y_r m, phi_r rad, v_r m/s, w_r rad/s, v_r' m/s^2, w_r' rad/s^2).

    kind 0 sinusoid, 1 reversing, 2 a table (:func:`table_state`).  For ``reversing`` x_r, y_r are the kernel's
    integrated values, passed in as xr_int, yr_int (the other kinds ignore them).
    """
    if kind == 2:
        return table_state(traj, t)
    if kind == 0:
        amp, lam, v0, dv, period = traj[0], traj[1], traj[2], traj[3], traj[4]
        kx = 2.0 * math.pi / lam
        om = 2.0 * math.pi / period
        s, c = math.sin(om * t), math.cos(om * t)
        x = v0 * t + dv / om * (1.0 - c)
        xd = v0 + dv * s
        xdd = dv * om * c
        xddd = -dv * om * om * s
        sk, ck = math.sin(kx * x), math.cos(kx * x)
        y = amp * sk
        yd = amp * kx * ck * xd
        ydd = -amp * kx * kx * sk * xd * xd + amp * kx * ck * xdd
        yddd = -amp * kx**3 * ck * xd**3 - 3.0 * amp * kx * kx * sk * xd * xdd + amp * kx * ck * xddd
        v2 = xd * xd + yd * yd
        v = math.sqrt(v2)
        phi = math.atan2(yd, xd)
        w = (xd * ydd - yd * xdd) / v2
        vdot = (xd * xdd + yd * ydd) / v
        wdot = (xd * yddd - yd * xddd) / v2 - 2.0 * w * vdot / v
        return x, y, phi, v, w, vdot, wdot
    vamp, vper, wamp, wper = traj[0], traj[1], traj[2], traj[3]
    ov = 2.0 * math.pi / vper
    ow = 2.0 * math.pi / wper
    v = vamp * math.sin(ov * t)
    vdot = vamp * ov * math.cos(ov * t)
    w = wamp * math.sin(ow * t)
    wdot = wamp * ow * math.cos(ow * t)
    phi = wamp / ow * (1.0 - math.cos(ow * t))
    return xr_int, yr_int, phi, v, w, vdot, wdot


@kernel
def reference_wheel_speeds(kind, traj, t, r, b):
    """(n, 2) rad/s: the reference's wheel speeds [(v_r + b w_r) / r, (v_r - b w_r) / r] at times t (n,) s."""
    out = np.empty((t.shape[0], 2))
    for i in range(t.shape[0]):
        ref = reference_state(kind, traj, t[i], 0.0, 0.0)
        out[i, 0] = (ref[3] + b * ref[4]) / r
        out[i, 1] = (ref[3] - b * ref[4]) / r
    return out


@kernel
def reference_signals(kind, traj, t):
    """(n, 4): the reference's v m/s, w rad/s, v' m/s^2, w' rad/s^2 at times t (n,) s (a plan's baselines: a 1 kHz
    minute is 60,000 calls of :func:`reference_state`)."""
    out = np.empty((t.shape[0], 4))
    for i in range(t.shape[0]):
        ref = reference_state(kind, traj, t[i], 0.0, 0.0)
        out[i, 0], out[i, 1], out[i, 2], out[i, 3] = ref[3], ref[4], ref[5], ref[6]
    return out


@kernel
def _reversing_velocity(traj, t):
    """(x_r', y_r') m/s of the reversing reference at time t."""
    vamp, vper, wamp, wper = traj[0], traj[1], traj[2], traj[3]
    ow = 2.0 * math.pi / wper
    v = vamp * math.sin(2.0 * math.pi / vper * t)
    phi = wamp / ow * (1.0 - math.cos(ow * t))
    return v * math.cos(phi), v * math.sin(phi)


@kernel
def reversing_advance(traj, t, h):
    """(dx_r, dy_r) m: the reversing reference's advance from t to t + h s, by Simpson's rule (RK4 on x_r' = f(t))."""
    fa = _reversing_velocity(traj, t)
    fm = _reversing_velocity(traj, t + 0.5 * h)
    fb = _reversing_velocity(traj, t + h)
    return h / 6.0 * (fa[0] + 4.0 * fm[0] + fb[0]), h / 6.0 * (fa[1] + 4.0 * fm[1] + fb[1])


@kernel
def _plant_rhs(s, tau1, tau2, d1, d2, plant, out):
    """out (7,) = s' for state s (7,) under wheel torques tau and caster disturbance d (N m)."""
    m11, m12, m22, vc = plant[0], plant[1], plant[2], plant[3]
    fv1, fv2, fd1, fd2, r, b = plant[4], plant[5], plant[6], plant[7], plant[8], plant[9]
    phi, e1, e2 = s[2], s[5], s[6]
    v = 0.5 * r * (e1 + e2)
    out[0] = v * math.cos(phi)
    out[1] = v * math.sin(phi)
    out[2] = r / (2.0 * b) * (e1 - e2)
    out[3] = e1
    out[4] = e2
    f1 = tau1 - d1 - vc * (e1 * e2 - e2 * e2) - fv1 * e1 - fd1 * sign(e1)
    f2 = tau2 - d2 - vc * (e1 * e2 - e1 * e1) - fv2 * e2 - fd2 * sign(e2)
    out[5] = m11 * f1 + m12 * f2
    out[6] = m12 * f1 + m22 * f2


@kernel
def control_torque(s, ref, ctrl, gains):
    """Computed-torque backstepping law: (tau_1, tau_2) N m from the state s (7,) and reference tuple."""
    xr, yr, phir, vr, wr, vrd, wrd = ref
    big11, big12, big22, vc = ctrl[0], ctrl[1], ctrl[2], ctrl[3]
    fv1, fv2, fd1, fd2, r, b = ctrl[4], ctrl[5], ctrl[6], ctrl[7], ctrl[8], ctrl[9]
    k1, k2, k3, kw = gains[0], gains[1], gains[2], gains[3]
    x, y, phi, eta1, eta2 = s[0], s[1], s[2], s[5], s[6]
    cp, sp = math.cos(phi), math.sin(phi)
    dx, dy = xr - x, yr - y
    err1 = cp * dx + sp * dy
    err2 = -sp * dx + cp * dy
    err3 = phir - phi
    if math.isfinite(err3):  # a diverged state stays NaN (math.floor of NaN raises in Python; numba's is undefined)
        err3 -= 2.0 * math.pi * math.floor((err3 + math.pi) / (2.0 * math.pi))  # wrap to [-pi, pi)
    v = 0.5 * r * (eta1 + eta2)
    w = r / (2.0 * b) * (eta1 - eta2)
    c3, s3 = math.cos(err3), math.sin(err3)
    err1d = w * err2 - v + vr * c3
    err2d = -w * err1 + vr * s3
    err3d = wr - w
    avr = abs(vr)
    avrd = vrd * sign(vr)
    vc_ = vr * c3 + k1 * err1
    wc_ = wr + k2 * vr * err2 + k3 * avr * s3
    vcd = vrd * c3 - vr * s3 * err3d + k1 * err1d
    wcd = wrd + k2 * (vrd * err2 + vr * err2d) + k3 * (avrd * s3 + avr * c3 * err3d)
    ec1 = (vc_ + b * wc_) / r
    ec2 = (vc_ - b * wc_) / r
    ecd1 = (vcd + b * wcd) / r
    ecd2 = (vcd - b * wcd) / r
    a1 = ecd1 + kw * (ec1 - eta1)
    a2 = ecd2 + kw * (ec2 - eta2)
    tau1 = big11 * a1 + big12 * a2 + vc * (eta1 * eta2 - eta2 * eta2) + fv1 * eta1 + fd1 * sign(eta1)
    tau2 = big12 * a1 + big22 * a2 + vc * (eta1 * eta2 - eta1 * eta1) + fv2 * eta2 + fd2 * sign(eta2)
    return tau1, tau2


@kernel
def closed_loop_kernel(kind, traj, plant, ctrl, gains, period, substeps, n_log, every, caster_z, caster_std,
                       caster_time, plant_after=None, switch=-1):  # fmt: skip
    """Run the closed loop; all arguments plain scalars / float64 arrays.

    kind 0 sinusoid / 1 reversing / 2 table; traj, plant (10,), ctrl (10,), gains (4,) as documented above;
    period: control period T (s); substeps: RK4 steps per control period; n_log: number of log samples;
    every: control periods per log period; caster_z (n_ctrl, 2) standard normals, n_ctrl = (n_log-1)*every+1;
    caster_std (N m), caster_time (s) of the Ornstein-Uhlenbeck disturbance.
    plant_after (10,), switch: the plant integrates control period k (from k T to (k + 1) T) with ``plant``
    for k < switch and with ``plant_after`` for k >= switch; switch < 0 (the default): ``plant`` throughout.
    The initial state uses ``plant``'s r, b.

    Returns pose (n_log, 3), wheel_angle (n_log, 2), eta (n_log, 2) true, tau (n_log, 2) applied,
    reference (n_log, 3), disturbance (n_log, 2) -- all at the log samples, the torque and disturbance
    being those held over the control period that starts at the sample.
    """
    n_ctrl = (n_log - 1) * every + 1
    after = plant if plant_after is None else plant_after
    pose = np.empty((n_log, 3))
    angle = np.empty((n_log, 2))
    eta = np.empty((n_log, 2))
    tau = np.empty((n_log, 2))
    refpose = np.empty((n_log, 3))
    dist = np.empty((n_log, 2))

    # Initial state: on the reference, wheel speeds matching (v_r, w_r) with the TRUE r, b.
    r, b = plant[8], plant[9]
    s = np.zeros(7)
    xr_int, yr_int = 0.0, 0.0
    ref0 = reference_state(kind, traj, 0.0, xr_int, yr_int)
    s[0], s[1], s[2] = ref0[0], ref0[1], ref0[2]
    s[5] = (ref0[3] + b * ref0[4]) / r
    s[6] = (ref0[3] - b * ref0[4]) / r

    a_ou = math.exp(-period / caster_time)
    q_ou = caster_std * math.sqrt(-math.expm1(-2.0 * period / caster_time))  # sigma sqrt(1 - a^2)
    d1 = caster_std * caster_z[0, 0]
    d2 = caster_std * caster_z[0, 1]

    h = period / substeps
    k1 = np.empty(7)
    k2 = np.empty(7)
    k3 = np.empty(7)
    k4 = np.empty(7)
    tmp = np.empty(7)
    for k in range(n_ctrl):
        t = k * period
        ref = reference_state(kind, traj, t, xr_int, yr_int)
        tau1, tau2 = control_torque(s, ref, ctrl, gains)
        if k % every == 0:
            i = k // every
            pose[i, 0], pose[i, 1], pose[i, 2] = s[0], s[1], s[2]
            angle[i, 0], angle[i, 1] = s[3], s[4]
            eta[i, 0], eta[i, 1] = s[5], s[6]
            tau[i, 0], tau[i, 1] = tau1, tau2
            refpose[i, 0], refpose[i, 1], refpose[i, 2] = ref[0], ref[1], ref[2]
            dist[i, 0], dist[i, 1] = d1, d2
        if k == n_ctrl - 1:
            break
        p = plant if (switch < 0 or k < switch) else after
        for j in range(substeps):
            _plant_rhs(s, tau1, tau2, d1, d2, p, k1)
            for m in range(7):
                tmp[m] = s[m] + 0.5 * h * k1[m]
            _plant_rhs(tmp, tau1, tau2, d1, d2, p, k2)
            for m in range(7):
                tmp[m] = s[m] + 0.5 * h * k2[m]
            _plant_rhs(tmp, tau1, tau2, d1, d2, p, k3)
            for m in range(7):
                tmp[m] = s[m] + h * k3[m]
            _plant_rhs(tmp, tau1, tau2, d1, d2, p, k4)
            for m in range(7):
                s[m] += h / 6.0 * (k1[m] + 2.0 * k2[m] + 2.0 * k3[m] + k4[m])
            if kind == 1:  # RK4 on x_r' = f(t) alone: Simpson's rule over the substep
                dx, dy = reversing_advance(traj, t + j * h, h)
                xr_int += dx
                yr_int += dy
        d1 = a_ou * d1 + q_ou * caster_z[k + 1, 0]
        d2 = a_ou * d2 + q_ou * caster_z[k + 1, 1]
    return pose, angle, eta, tau, refpose, dist


def check_finite(eta: np.ndarray, tau: np.ndarray, step: float) -> None:
    """A :class:`UsageError` when the simulated wheel speeds or torques (n, 2) stop being finite: the parameters,
    the payload, the casters or a fault made the closed loop diverge, and a log of NaNs would be written."""
    bad = ~(np.isfinite(eta).all(axis=1) & np.isfinite(tau).all(axis=1))
    if bad.any():
        first = int(np.argmax(bad))
        raise UsageError(
            f"the simulation diverged at t = {first * step:.4g} s (the wheel speeds or torques are no longer finite): "
            "the robot's parameters, payload, casters or fault make the closed loop unstable; make them smaller"
        )
