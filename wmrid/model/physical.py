"""The robot's physical quantities from its identified base parameters: what a log determines, what the robot file
gives, and what stays undetermined (``wmrid export``).

With the geometry of the robot file taken as known -- the wheel radius r, the half track b and the spin inertia of a
wheel with its rotor, spin = I_w + k_r^2 I_r -- Eqs. (10)-(14) are linear in four combinations of the platform's
mass distribution (s = r^2 / (4 b^2)):

    M11 + M22 = 2 spin + 2 s (m b^2 + I)        m   = m_p + 2 m_w + 2 m_r, the total mass (kg)
    M12       = s (m b^2 - I)                   I   = the yaw inertia about the axle midpoint O (kg m^2)
    M11 - M22 = -4 s b (m_p d_y)                m_p d_y: the platform's first moment across (kg m)
    V_c       = (r^3 / (4 b^2)) (m_p d_x + 2 m_r c_x)   its first moment along, with the rotors' (kg m)

so the log determines exactly these four (and the friction of each wheel, and a caster's drag): nothing else about
the mass distribution reaches the wheels.  The platform's own values follow only with more of the robot file: the
wheels' and rotors' masses and inertias (m_w, I_wm, a, m_r, I_rm, c_x, c_y) give

    m_p = m - 2 m_w - 2 m_r,   d_y = (m_p d_y) / m_p,   d_x = ((m_p d_x + 2 m_r c_x) - 2 m_r c_x) / m_p,
    I_p = I - m_p (d_x^2 + d_y^2) - 2 (I_wm + m_w a^2) - 2 (I_rm + m_r (c_x^2 + c_y^2)).

The covariance of theta0 = [m11 m12 m22 Vc ...] is carried through M = m^-1 (:func:`wmrid.model.dynamics.
invert_inertia_jacobian`) and the equations above by their exact Jacobians (the delta method; tests check it against
sampling).  The robot file's values carry no uncertainty here: they are what the user measured or took from CAD,
and an error in them moves the physical values, not the base parameters.  Undetermined by any wheel log: the
height of the centre of mass, roll and pitch inertias, and how I divides among bodies beyond what the file says.

Pure functions on arrays; no I/O.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from wmrid.core.errors import UsageError
from wmrid.model import dynamics as model
from wmrid.model.robot import PARAMETER_UNITS, PhysicalParameters

#: Where a quantity comes from.
FROM_LOG = "log"
FROM_LOG_AND_FILE = "log + robot file"
FROM_FILE = "robot file"
#: The four mass-distribution quantities the log determines (with r, b, spin from the file), then the platform's
#: own values (with more of the file).  name -> (unit, meaning).
DETERMINED = {
    "m": ("kg", "total mass (platform, wheels and rotors)"),
    "I": ("kg m^2", "yaw inertia of the whole robot about the axle midpoint O"),
    "mp_dy": ("kg m", "platform's first moment across, m_p d_y"),
    "mp_dx": ("kg m", "first moment along, m_p d_x + 2 m_r c_x (platform and rotors)"),
}
PLATFORM = {
    "m_p": ("kg", "platform mass (without wheels and rotors)"),
    "d_x": ("m", "x of the platform's centre of mass (forward from O)"),
    "d_y": ("m", "y of the platform's centre of mass (towards the left wheel)"),
    "I_p": ("kg m^2", "platform's yaw inertia about its own centre of mass"),
}
FRICTION = {
    "F_v1": ("N m s/rad", "viscous friction, right wheel"),
    "F_v2": ("N m s/rad", "viscous friction, left wheel"),
    "F_d1": ("N m", "Coulomb friction, right wheel"),
    "F_d2": ("N m", "Coulomb friction, left wheel"),
}
#: The robot file's values the physical quantities rest on (taken as known).
FROM_FILE_NAMES = ("r", "b", "I_w", "k_r", "I_r", "m_w", "a", "I_wm", "m_r", "I_rm", "c_x", "c_y")
#: What no wheel log determines.
UNDETERMINED = (
    "the height of the centre of mass",
    "the platform's roll and pitch inertias",
    "how the yaw inertia divides among the bodies beyond the robot file's wheels and rotors",
)


@dataclass(frozen=True)
class Quantity:
    """One physical value: value and std (SI; std inf when the log leaves it undetermined), unit, meaning, and
    where it comes from (:data:`FROM_LOG`, :data:`FROM_LOG_AND_FILE`, :data:`FROM_FILE`)."""

    value: float
    std: float
    unit: str
    meaning: str
    source: str

    def to_dict(self) -> dict[str, Any]:
        return {"value": self.value, "std": self.std if math.isfinite(self.std) else None, "unit": self.unit,
                "meaning": self.meaning, "source": self.source}  # fmt: skip

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> Quantity:
        std = data.get("std")
        return cls(float(data["value"]), math.inf if std is None else float(std), str(data["unit"]),
                   str(data["meaning"]), str(data["source"]))  # fmt: skip


@dataclass(frozen=True)
class PhysicalEstimate:
    """The physical quantities of an identified robot.

    What the log determines, what the robot file gives and what stays undetermined (:mod:`wmrid.model.physical`
    derives them).

    Attributes
    ----------
    quantities
        Name -> :class:`Quantity`, in the order m, I, mp_dy, mp_dx, m_p, d_x, d_y, I_p, F_v1, F_v2, F_d1, F_d2, the
        caster drags D_k (N) when the result has them, then the robot file's values.
    names
        The log-determined quantities' names (the four mass-distribution ones, the platform's four, the friction and
        the drags).
    cov
        (n, n) their covariance, SI.
    parameters
        The identified robot as Table 1 (the platform's values and friction identified, the rest from the file),
        what a simulator is built from.
    undetermined
        What no wheel log determines, a phrase each.
    clipped
        Friction entries identified below 0 and written as 0 in ``parameters`` (a simulator's friction is >= 0).
    """

    quantities: dict[str, Quantity]
    names: tuple[str, ...]
    cov: np.ndarray
    parameters: PhysicalParameters
    undetermined: tuple[str, ...] = UNDETERMINED
    #: Friction entries identified below 0 and written as 0 in ``parameters`` (a simulator's friction is >= 0).
    clipped: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        cov = [[float(v) if math.isfinite(v) else None for v in row] for row in np.asarray(self.cov)]
        return {
            "quantities": {k: q.to_dict() for k, q in self.quantities.items()}, "names": list(self.names),
            "cov": cov, "parameters": self.parameters.to_dict(), "undetermined": list(self.undetermined),
            "clipped": list(self.clipped),
        }  # fmt: skip

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> PhysicalEstimate:
        cov = np.array([[math.nan if v is None else float(v) for v in row] for row in data["cov"]], dtype=float)
        return cls(
            quantities={k: Quantity.from_dict(v) for k, v in data["quantities"].items()},
            names=tuple(data["names"]), cov=cov.reshape(len(data["names"]), len(data["names"])),
            parameters=PhysicalParameters(**data["parameters"]), undetermined=tuple(data["undetermined"]),
            clipped=tuple(data.get("clipped", ())),
        )  # fmt: skip


def mass_distribution(big_m: np.ndarray, vc: float, p: PhysicalParameters) -> np.ndarray:
    """(m kg, I kg m^2, m_p d_y kg m, m_p d_x + 2 m_r c_x kg m) from M (2, 2) kg m^2 and V_c kg m^2, with r, b and
    spin = I_w + k_r^2 I_r of ``p`` (module docstring); linear in (M11, M12, M22, V_c)."""
    return _linear_map(p) @ np.array([big_m[0, 0], big_m[0, 1], big_m[1, 1], vc]) + _offset(p)


def _linear_map(p: PhysicalParameters) -> np.ndarray:
    """L (4, 4) with mass_distribution = L [M11 M12 M22 Vc] + offset."""
    s = p.r**2 / (4.0 * p.b**2)
    half = 0.5 / (2.0 * s * p.b**2)
    return np.array(
        [
            [half, 1.0 / (2.0 * s * p.b**2), half, 0.0],  # m = ((M11 + M22)/2 - spin + M12) / (2 s b^2)
            [0.25 / s, -0.5 / s, 0.25 / s, 0.0],  # I = ((M11 + M22)/2 - spin - M12) / (2 s)
            [-1.0 / (4.0 * s * p.b), 0.0, 1.0 / (4.0 * s * p.b), 0.0],  # m_p d_y = -(M11 - M22) / (4 s b)
            [0.0, 0.0, 0.0, 4.0 * p.b**2 / p.r**3],  # m_p d_x + 2 m_r c_x = V_c 4 b^2 / r^3
        ]
    )


def _offset(p: PhysicalParameters) -> np.ndarray:
    s = p.r**2 / (4.0 * p.b**2)
    spin = p.I_w + p.k_r**2 * p.I_r
    return np.array([-spin / (2.0 * s * p.b**2), -spin / (2.0 * s), 0.0, 0.0])


def platform_values(dist: np.ndarray, p: PhysicalParameters) -> np.ndarray:
    """(m_p kg, d_x m, d_y m, I_p kg m^2) from the mass distribution (m, I, m_p d_y, m_p d_x + 2 m_r c_x) and the
    robot file's wheels and rotors (module docstring)."""
    m, inertia, my, mx = (float(v) for v in dist)
    m_p = m - 2.0 * p.m_w - 2.0 * p.m_r
    d_x = (mx - 2.0 * p.m_r * p.c_x) / m_p
    d_y = my / m_p
    rest = 2.0 * (p.I_wm + p.m_w * p.a**2) + 2.0 * (p.I_rm + p.m_r * (p.c_x**2 + p.c_y**2))
    return np.array([m_p, d_x, d_y, inertia - m_p * (d_x**2 + d_y**2) - rest])


def _platform_jacobian(dist: np.ndarray, p: PhysicalParameters) -> np.ndarray:
    """d platform_values / d dist (4, 4), exact."""
    m_p, d_x, d_y, _ = platform_values(dist, p)
    jac = np.zeros((4, 4))
    jac[0, 0] = 1.0  # m_p = m - const
    jac[1, 0], jac[1, 3] = -d_x / m_p, 1.0 / m_p  # d_x = (mx - c) / m_p
    jac[2, 0], jac[2, 2] = -d_y / m_p, 1.0 / m_p  # d_y = my / m_p
    # I_p = I - m_p (d_x^2 + d_y^2) - rest = I - ((mx - c)^2 + my^2) / m_p - rest
    jac[3, 1] = 1.0
    jac[3, 0] = d_x**2 + d_y**2
    jac[3, 3] = -2.0 * d_x
    jac[3, 2] = -2.0 * d_y
    return jac


def physical_from_base(
    theta0: np.ndarray,
    cov0: np.ndarray,
    p: PhysicalParameters,
    base_names: tuple[str, ...] | None = None,
    caster_meanings: dict[str, str] | None = None,
) -> PhysicalEstimate:
    """The physical quantities (:class:`PhysicalEstimate`) of base parameters theta0 (n0,) with covariance cov0
    (n0, n0) (a row of NaN with inf on the diagonal: undetermined), on the robot file's geometry ``p``.

    caster_meanings: name -> meaning of each caster-drag parameter (the casters it stands for).  A friction entry
    below 0 is kept in ``quantities`` and written as 0 in ``parameters`` (listed in ``clipped``).
    Raises :class:`~wmrid.core.errors.UsageError` (one sentence, naming the quantity and why) when the implied
    robot is not physical: M not positive definite, a total mass or yaw inertia not positive, a platform lighter
    than nothing once the file's wheels and rotors are taken off, or a platform yaw inertia below zero.
    """
    theta0 = np.asarray(theta0, dtype=float)
    cov0 = np.asarray(cov0, dtype=float)
    n0 = len(theta0)
    names0 = base_names or model.default_base_names(n0)
    big_m = np.linalg.inv(model.inverse_inertia(theta0))
    if not np.all(np.isfinite(big_m)) or np.any(np.linalg.eigvalsh(big_m) <= 0):
        raise UsageError(
            f"the identified inertia matrix M = [[{big_m[0, 0]:.4g}, {big_m[0, 1]:.4g}], [{big_m[0, 1]:.4g}, "
            f"{big_m[1, 1]:.4g}]] kg m^2 is not positive definite, which no robot has: the result does not describe "
            "a physical robot"
        )
    dist = mass_distribution(big_m, theta0[3], p)
    _check(dist[0] > 0, f"the implied total mass m = {dist[0]:.4g} kg is not positive")
    _check(dist[1] > 0, f"the implied yaw inertia about the axle midpoint I = {dist[1]:.4g} kg m^2 is not positive")
    wheels = 2.0 * p.m_w + 2.0 * p.m_r
    _check(dist[0] > wheels, f"the implied total mass m = {dist[0]:.4g} kg is not more than the robot file's wheels "
           f"and rotors alone ({wheels:.4g} kg): check m_w and m_r in the robot file, or the log's units")  # fmt: skip
    plat = platform_values(dist, p)
    _check(plat[3] >= 0, f"the implied platform yaw inertia I_p = {plat[3]:.4g} kg m^2 is negative: the yaw inertia "
           f"I = {dist[1]:.4g} kg m^2 is less than the robot file's wheels, rotors and the platform's offset centre of "
           "mass alone need (check the robot file's a, I_wm, m_w, or the log's units)")  # fmt: skip
    # Jacobian of [m, I, mp_dy, mp_dx, m_p, d_x, d_y, I_p, friction..., drags...] w.r.t. theta0
    j_phys = model.invert_inertia_jacobian(np.concatenate([theta0[:3], [0.0]]))[:3, :3]  # dM / dm (3, 3)
    lin = _linear_map(p)
    j_dist = np.zeros((4, n0))
    j_dist[:, :3] = lin[:, :3] @ j_phys
    j_dist[:, 3] = lin[:, 3]
    j_plat = _platform_jacobian(dist, p) @ j_dist
    extra = list(range(4, n0))  # friction, then caster drags
    j_rest = np.zeros((len(extra), n0))
    for row, j in enumerate(extra):
        j_rest[row, j] = 1.0
    jac = np.vstack([j_dist, j_plat, j_rest])
    names = (*DETERMINED, *PLATFORM, *FRICTION, *names0[8:])
    cov = _propagate(jac, cov0)
    values = np.concatenate([dist, plat, theta0[4:]])
    std = np.sqrt(np.where(np.isfinite(np.diag(cov)), np.clip(np.diag(cov), 0.0, None), np.inf))
    quantities: dict[str, Quantity] = {}
    units = model.THETA0_UNITS
    for i, name in enumerate(names):
        if name in DETERMINED:
            unit, meaning = DETERMINED[name]
            source = FROM_LOG_AND_FILE  # r, b (and spin for m, I) from the file
        elif name in PLATFORM:
            unit, meaning, source = *PLATFORM[name], FROM_LOG_AND_FILE
        elif name in FRICTION:
            unit, meaning, source = *FRICTION[name], FROM_LOG
        elif name in ("Cv", "Cw"):
            unit = units.get(name, "N m")
            meaning = f"two-term caster drag against {'driving' if name == 'Cv' else 'turning'}, at each wheel"
            source = FROM_LOG
        else:
            unit, source = units.get(name, "N"), FROM_LOG
            meaning = (caster_meanings or {}).get(name, f"caster drag force {name}")
        quantities[name] = Quantity(float(values[i]), float(std[i]), unit, meaning, source)
    for name in FROM_FILE_NAMES:
        unit, meaning = PARAMETER_UNITS[name]
        quantities[name] = Quantity(float(getattr(p, name)), 0.0, unit, meaning, FROM_FILE)
    friction = dict(zip(FRICTION, (float(v) for v in theta0[4:8]), strict=True))
    clipped = tuple(k for k, v in friction.items() if v < 0)
    identified = dataclasses.replace(
        p, m_p=float(plat[0]), d_x=float(plat[1]), d_y=float(plat[2]), I_p=float(plat[3]),
        **{k: max(v, 0.0) for k, v in friction.items()},
    )  # fmt: skip
    return PhysicalEstimate(quantities=quantities, names=names, cov=cov, parameters=identified, clipped=clipped)


def _propagate(jac: np.ndarray, cov0: np.ndarray) -> np.ndarray:
    """J cov0 J^T, with a quantity that depends on an undetermined base parameter (NaN/inf in cov0) undetermined:
    its row and column NaN, inf on the diagonal."""
    bad = ~np.isfinite(np.diag(cov0))
    clean = np.where(np.isfinite(cov0), cov0, 0.0)
    cov = jac @ clean @ jac.T
    touched = np.any(np.abs(jac[:, bad]) > 0, axis=1) if bad.any() else np.zeros(len(jac), dtype=bool)
    cov[touched, :] = np.nan
    cov[:, touched] = np.nan
    cov[touched, touched] = np.inf
    return cov


def _check(ok: bool, why: str) -> None:
    if not ok:
        raise UsageError(f"{why}; the result does not describe a physical robot, so it is not exported")
