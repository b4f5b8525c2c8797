"""A log with a known truth, made here: the CAD robot driven open loop, integrated to 1e-11 (a helper module for the
tests, importable from any of them as ``tests.open_loop``)."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
from scipy.integrate import solve_ivp

from wmrid.model import dynamics as model, torques
from wmrid.model.robot import PAPER_CAD


def open_loop_log(
    duration: float = 5.0,
    dt: float = 1e-3,
    reversing: bool = False,
    uneven: bool = False,
    torque=None,
    eta0=None,
    feedback: bool = False,
):
    """The CAD robot driven open-loop by smooth torques, integrated by DOP853 at rtol 1e-11.

    ``torque(t) -> (2,)`` N m and ``eta0`` (2,) rad/s override the built-in excitation; a ``torque``
    taking ``(t, eta)`` (flagged by ``feedback=True``) closes a loop on the wheel speeds.
    Returns an object with t (n,) s, eta (n, 2) rad/s, tau (n, 2) N m, source, notes, theta0 (8,).
    """
    theta0 = model.base_parameters(PAPER_CAD)
    if torque is not None:
        pass
    elif reversing:

        def torque(t):
            return np.array(
                [2.0 * np.sin(1.3 * t) + 0.5 * np.sin(3.1 * t), 2.0 * np.sin(0.9 * t + 1) + 0.4 * np.sin(2.3 * t)]
            )

        eta0 = [0.5, -0.3] if eta0 is None else eta0
    else:

        def torque(t):
            return np.array(
                [
                    1.2 + 0.8 * np.sin(1.3 * t) + 0.3 * np.sin(3.1 * t),
                    1.0 + 0.7 * np.sin(0.9 * t + 1) + 0.3 * np.sin(2.3 * t),
                ]
            )

        eta0 = [3.0, 3.0] if eta0 is None else eta0

    def applied(t, eta):
        return torque(t, eta) if feedback else torque(t)

    def rhs(t, y):
        return torques.wheel_acceleration(y[None, :], applied(t, y)[None, :], theta0)[0]

    if uneven:
        rng = np.random.default_rng(5)
        t = np.concatenate([[0.0], np.cumsum(rng.uniform(0.5 * dt, 1.5 * dt, int(duration / dt)))])
    else:
        t = np.arange(round(duration / dt) + 1) * dt
    sol = solve_ivp(rhs, (t[0], t[-1]), eta0, t_eval=t, rtol=1e-11, atol=1e-12, method="DOP853")
    tau = np.array([applied(x, y) for x, y in zip(t, sol.y.T, strict=True)])
    return SimpleNamespace(t=t, eta=sol.y.T.copy(), tau=tau, source="open-loop", notes=(), theta0=theta0)
