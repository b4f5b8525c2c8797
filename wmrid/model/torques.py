"""The model's torques from a base-parameter estimate: Coriolis, friction and caster drag, the inertia's load, the wheel
torque a motion needs and the acceleration an effort gives (Eqs. 9-18 evaluated, for residuals, plans and
prediction)."""

from __future__ import annotations

import numpy as np

from wmrid.model.dynamics import RegressorForm, caster_columns, inverse_inertia


def coriolis_torque(eta: np.ndarray, vc: float) -> np.ndarray:
    """V(eta) (n, 2), N m, Eqs. (13)-(14)."""
    e1, e2 = eta[..., 0], eta[..., 1]
    return vc * np.stack([e1 * e2 - e2 * e2, e1 * e2 - e1 * e1], axis=-1)


def friction_torque(
    eta: np.ndarray, theta0: np.ndarray, form: RegressorForm | None = None, eta_dot: np.ndarray | None = None
) -> np.ndarray:
    """F_v eta + F_d sgn(eta) (n, 2), N m, Eqs. (15)-(17), plus the caster drag when theta0 has more than 8
    entries (``form`` says which caster model; None: the two-term one).  A drag that follows v' or w' (the load
    terms of ``form``) needs eta_dot (n, 2) rad/s^2."""
    fv = theta0[4:6]
    fd = theta0[6:8]
    out = fv * eta + fd * np.sign(eta)
    if len(theta0) > 8:
        form = form if form is not None else RegressorForm("general", caster=True)
        e2d = np.atleast_2d(eta)
        cols = caster_columns(e2d, form, None if eta_dot is None else np.atleast_2d(eta_dot))  # (n, q)
        drag = np.zeros(e2d.shape)
        for j, (_, param, pattern) in enumerate(form.caster_map):
            drag += theta0[param] * cols[:, j : j + 1] * np.array([1.0, float(pattern)])
        out = out + drag.reshape(np.shape(out))
    return out


def load_inertia(eta: np.ndarray, theta0: np.ndarray, form: RegressorForm) -> np.ndarray:
    """A(eta) (n, 2, 2), kg m^2: the part of the caster drag's wheel torques that is linear in eta' (its v' and w'
    load terms), so that the drag is friction_torque(eta, theta0, form, eta_dot) = (its value at eta_dot = 0)
    + A(eta) eta_dot.  Zero without such terms."""
    eta = np.atleast_2d(eta)
    out = np.zeros((len(eta), 2, 2))
    derivative = dict(form.derivative_columns)
    if not derivative:
        return out
    r, b = form.geometry[0], form.geometry[1]
    grads = (np.array([0.5 * r, 0.5 * r]), np.array([r / (2.0 * b), -r / (2.0 * b)]))  # d v / d eta, d w / d eta
    mult = caster_columns(eta, form, multiplier=True)
    for j, (col, param, pattern) in enumerate(form.caster_map):
        if col in derivative:
            out += theta0[param] * mult[:, j, None, None] * np.outer([1.0, float(pattern)], grads[derivative[col]])
    return out


def wheel_acceleration(
    eta: np.ndarray, tau: np.ndarray, theta0: np.ndarray, form: RegressorForm | None = None
) -> np.ndarray:
    """The direct model eta_dot (n, 2), rad/s^2, Eq. (20) without disturbance (``form``: the caster model of a
    theta0 longer than 8, see :func:`friction_torque`).  A drag that follows v' or w' adds A(eta) eta_dot
    (:func:`load_inertia`) to the inertia's torque: then (M + A(eta)) eta_dot = tau - V - F is solved per sample."""
    if form is None or not form.derivative_columns or len(theta0) <= 8:
        rhs = tau - coriolis_torque(eta, theta0[3]) - friction_torque(eta, theta0, form)
        return rhs @ inverse_inertia(theta0).T
    eta2 = np.atleast_2d(eta)
    still = friction_torque(eta2, theta0, form, np.zeros_like(eta2))  # the drag at eta_dot = 0
    rhs = np.atleast_2d(tau) - coriolis_torque(eta2, theta0[3]) - still
    big_m = np.linalg.inv(inverse_inertia(theta0)) + load_inertia(eta2, theta0, form)
    return np.linalg.solve(big_m, rhs[..., None])[..., 0].reshape(np.shape(tau))


def wheel_torque(
    eta: np.ndarray, eta_dot: np.ndarray, theta0: np.ndarray, form: RegressorForm | None = None
) -> np.ndarray:
    """The inverse model tau (n, 2), N m, Eq. (9) without disturbance (``form`` as :func:`wheel_acceleration`)."""
    big_m = np.linalg.inv(inverse_inertia(theta0))
    friction = friction_torque(eta, theta0, form, eta_dot if form is not None and form.load else None)
    return eta_dot @ big_m.T + coriolis_torque(eta, theta0[3]) + friction
