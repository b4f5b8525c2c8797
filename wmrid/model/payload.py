"""The payload a robot carries, from its identified base parameters and its unloaded description.

A rigid payload of mass m_L at (x, y) in the platform frame, with yaw inertia I_L about its own centre
of mass, changes Eqs. (10)-(14) only through the platform (:meth:`PhysicalParameters.with_payload`):

* the total mass m grows by m_L;
* the yaw inertia about the axle midpoint O, I, grows by I_L + m_L (x^2 + y^2);
* the first moments grow: m_p d_x by m_L x, m_p d_y by m_L y;
* the wheels' spin inertia I_w + k_r^2 I_r does not change.

With s = r^2 / (4 b^2), Eqs. (10)-(14) read M11 + M22 = 2 spin + 2 s (m b^2 + I), M12 = s (m b^2 - I),
M11 - M22 = -4 s b (m_p d_y) and V_c = (r^3 / 4 b^2)(m_p d_x + 2 m_r c_x).  So the changes from the
unloaded robot give, one after the other,

    m_L      = (d(M11 + M22)/2 + dM12) / (2 s b^2)
    I_L + m_L (x^2 + y^2) = (d(M11 + M22)/2 - dM12) / (2 s)
    m_L y    = -d(M11 - M22) / (4 s b)
    m_L x    = dV_c 4 b^2 / r^3

four equations in the four unknowns (m_L, x, y, I_L), solvable whenever m_L != 0: all four are
identifiable (tests/unit/model/test_payload.py checks the round trip and the Jacobian's rank).  Standard errors
follow by the delta method from the covariance of (m11, m12, m22, V_c) (M = m^-1 inside).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from wmrid.model import dynamics as model
from wmrid.model.robot import PhysicalParameters

PAYLOAD_NAMES = ("mass", "x", "y", "inertia")
PAYLOAD_UNITS = {"mass": "kg", "x": "m", "y": "m", "inertia": "kg m^2"}


@dataclass(frozen=True)
class PayloadEstimate:
    """A payload estimated from a log (a result's ``payload``, ``--payload``).

    Each quantity is (value, std), std +inf when the log does not bound it.

    Attributes
    ----------
    mass
        kg, the payload's mass.
    x
        m, its centre of mass in the platform frame.
    y
        m, its centre of mass in the platform frame.
    inertia
        kg m^2, its yaw inertia about its own centre of mass.
    """

    mass: tuple[float, float]
    x: tuple[float, float]
    y: tuple[float, float]
    inertia: tuple[float, float]

    def items(self) -> tuple[tuple[str, tuple[float, float]], ...]:
        """(name, (value, std)) in :data:`PAYLOAD_NAMES` order."""
        return tuple((name, getattr(self, name)) for name in PAYLOAD_NAMES)

    def to_dict(self) -> dict[str, dict[str, Any]]:
        """{name: {"value", "std", "unit"}} (std None when not finite), the result JSON's ``payload``."""
        return {
            name: {"value": v, "std": e if math.isfinite(e) else None, "unit": PAYLOAD_UNITS[name]}
            for name, (v, e) in self.items()
        }

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> PayloadEstimate:
        """The estimate :meth:`to_dict` wrote (value null read as NaN, std null as +inf)."""

        def pair(name: str) -> tuple[float, float]:
            entry = data[name]
            value, std = entry["value"], entry["std"]
            return (math.nan if value is None else float(value), math.inf if std is None else float(std))

        return cls(*(pair(name) for name in PAYLOAD_NAMES))


def payload_from_base(theta0: np.ndarray, unloaded: PhysicalParameters) -> np.ndarray:
    """(m_L kg, x m, y m, I_L kg m^2) from base parameters theta0 (8,) [m11 m12 m22 Vc ...] of the loaded robot."""
    big_m = np.linalg.inv(model.inverse_inertia(theta0))
    big_m0 = model.inertia_matrix(unloaded)
    before = (big_m0[0, 0], big_m0[0, 1], big_m0[1, 1], model.coriolis_coefficient(unloaded))
    after = (big_m[0, 0], big_m[0, 1], big_m[1, 1], theta0[3])
    return payload_from_change(before, after, unloaded.r, unloaded.b)


def payload_from_change(before: Any, after: Any, r: float, b: float) -> np.ndarray:
    """(m_L kg, x m, y m, I_L kg m^2) of the payload that changed (M11, M12, M22 kg m^2, V_c kg m) from ``before``
    to ``after`` on a robot of wheel radius r and half-track b (m): the module's four equations.  ``before`` may be
    the robot's own identified values without its payload (a fleet's baseline), not only its model."""
    m11_0, m12_0, m22_0, vc0 = (float(v) for v in before)
    m11, m12, m22, vc = (float(v) for v in after)
    s = r**2 / (4.0 * b**2)
    d_sum = 0.5 * ((m11 + m22) - (m11_0 + m22_0))
    d_12 = m12 - m12_0
    d_diff = (m11 - m22) - (m11_0 - m22_0)
    mass = (d_sum + d_12) / (2.0 * s * b**2)
    inertia_about_o = (d_sum - d_12) / (2.0 * s)
    moment_y = -d_diff / (4.0 * s * b)
    moment_x = (vc - vc0) * 4.0 * b**2 / r**3
    x, y = moment_x / mass, moment_y / mass
    return np.array([mass, x, y, inertia_about_o - mass * (x**2 + y**2)])


def payload_with_std(theta0: np.ndarray, cov0: np.ndarray, unloaded: PhysicalParameters) -> PayloadEstimate:
    """The payload's mass, x, y and inertia with their std, by the delta method (central differences) from theta0
    (8,) and its covariance cov0 (n0, n0) (only m11, m12, m22, Vc enter)."""
    value = payload_from_base(theta0, unloaded)
    jac = np.zeros((4, 4))
    for j in range(4):  # only m11, m12, m22, Vc enter
        step = 1e-6 * max(abs(theta0[j]), 1e-3)
        up, down = theta0.copy(), theta0.copy()
        up[j] += step
        down[j] -= step
        jac[:, j] = (payload_from_base(up, unloaded) - payload_from_base(down, unloaded)) / (2 * step)
    sub = cov0[:4, :4]
    finite = np.all(np.isfinite(sub))
    std = np.sqrt(np.clip(np.diag(jac @ sub @ jac.T), 0.0, None)) if finite else np.full(4, np.inf)
    return PayloadEstimate(*((float(v), float(e)) for v, e in zip(value, std, strict=True)))


#: The smallest payload mass reported as a payload, kg (below it a wheeled robot's load is noise or model error).
MIN_PAYLOAD_KG = 0.05


def payload_statement(payload: PayloadEstimate) -> str:
    """One sentence on a payload estimate: detected when its mass exceeds both 3 std and
    :data:`MIN_PAYLOAD_KG`, else "no payload detected" (and then its position and inertia mean nothing)."""
    mass, std = payload.mass
    if math.isfinite(std) and mass > 3 * std and mass > MIN_PAYLOAD_KG:
        x, y = payload.x[0], payload.y[0]
        return f"payload detected: {mass:.4g} ± {std:.2g} kg at x = {x:.3g} m, y = {y:.3g} m (platform frame)"
    if mass <= 0:
        why = "not positive"
    elif mass <= MIN_PAYLOAD_KG:
        why = f"below {MIN_PAYLOAD_KG:g} kg"
    else:
        why = "within 3 std of 0"
    return (
        f"no payload detected: the mass estimate {mass:.3g} ± {std:.2g} kg is {why} (the log shows the unloaded "
        "robot; the position and inertia columns mean nothing then)"
    )
