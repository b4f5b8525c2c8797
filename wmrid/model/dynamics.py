"""The paper's reduced wheel-space dynamics and its linear parameterisation (Eqs. 9-25).

Conventions (the paper's): eta = [eta_1, eta_2] = [right, left] wheel angular velocity (rad/s),
tau = [tau_1, tau_2] the wheel torques (N m).  Pure functions on numpy arrays; no I/O.

    M eta_dot + V(eta) + F_v eta + F_d sgn(eta) + tau_d = tau                        (9)
    V = V_c [eta_1 eta_2 - eta_2^2, eta_1 eta_2 - eta_1^2]                           (13-14)
    eta_dot = m (tau - V - F_v eta - F_d sgn(eta)),  m = M^-1                        (19-20)
    eta_dot_i = g(eta, tau) theta_i                                                  (22)

Base parameters (Eq. 21), in this order everywhere: ``theta0 = [m11, m12, m22, Vc, Fv1, Fv2, Fd1, Fd2]``.

Two regressor forms:

* ``paper`` (7 columns, Eq. 25): valid while each wheel keeps one sign s_j; the last column is -1 and
  theta_i7 = m_i1 F_d1 s_1 + m_i2 F_d2 s_2 (the paper has s = (+1, +1)).
* ``general`` (8 columns): one Coulomb column per wheel, -sgn(eta_1), -sgn(eta_2), with
  theta_i = [..., m_i1 F_d1, m_i2 F_d2]; needed when a wheel reverses.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Literal

import numpy as np

from wmrid.model.robot import PhysicalParameters

THETA0_NAMES = ("m11", "m12", "m22", "Vc", "Fv1", "Fv2", "Fd1", "Fd2")
#: The caster-drag base parameters of the ``wheel+caster`` friction model, appended to theta0.
CASTER_NAMES = ("Cv", "Cw")
THETA0_UNITS = {
    "m11": "1/(kg m^2)", "m12": "1/(kg m^2)", "m22": "1/(kg m^2)", "Vc": "kg m^2",
    "Fv1": "N m s/rad", "Fv2": "N m s/rad", "Fd1": "N m", "Fd2": "N m",
    "M11": "kg m^2", "M12": "kg m^2", "M22": "kg m^2", "Cv": "N m", "Cw": "N m",
    **{f"D{k}": "N" for k in range(1, 9)},
}  # fmt: skip


def base_units(effort_unit: str = "N m") -> dict[str, str]:
    """Units of the base parameters and M when the effort is in ``effort_unit`` (SI for "N m").

    With a PWM or voltage effort the model keeps its form, M eta' + ... = u, so each parameter is in
    units of u: m = M^-1 in (rad/s^2)/u, Vc in u s^2/rad^2, F_v in u s/rad, F_d in u.
    """
    if effort_unit == "N m":
        return dict(THETA0_UNITS)
    u = effort_unit
    inv, big = f"(rad/s^2)/{u}", f"{u} s^2/rad"
    return {
        "m11": inv, "m12": inv, "m22": inv, "Vc": f"{u} s^2/rad^2", "Fv1": f"{u} s/rad", "Fv2": f"{u} s/rad",
        "Fd1": u, "Fd2": u, "M11": big, "M12": big, "M22": big, "Cv": u, "Cw": u,
        **{f"D{k}": f"{u}/m" for k in range(1, 9)},
    }  # fmt: skip


_COMMON_COLUMNS = ("tau_1", "tau_2", "eta_2^2-eta_1*eta_2", "eta_1^2-eta_1*eta_2", "-eta_1", "-eta_2")


@dataclass(frozen=True)
class RegressorForm:
    """Which regressor g(eta, tau) is used: the paper's 7 columns or the general 8, and whether caster drag
    adds columns (general form only; see :func:`caster_columns`).

    caster : the ``wheel+caster`` friction model.  geometry : () for the two-term model (Cv, Cw: the drag's
    limits driving straight and turning on the spot), or (r, b, x_1, y_1, ..., x_K, y_K) in m: the wheel
    radius, half track and each caster's ground contact in the platform frame, for the exact drag direction
    of each caster (one parameter per caster, its drag force D_k in N).
    """

    kind: Literal["paper", "general"] = "paper"
    signs: tuple[int, int] = (1, 1)  # paper form only: the constant sign of eta_1 and eta_2
    caster: bool = False  # the wheel+caster friction model
    geometry: tuple[float, ...] = ()

    def __post_init__(self) -> None:
        if self.kind not in ("paper", "general"):
            raise ValueError(f"unknown regressor form {self.kind!r}")
        if any(s not in (1, -1) for s in self.signs):
            raise ValueError(f"wheel signs must be +1 or -1, got {self.signs}")
        if self.caster and self.kind != "general":
            raise ValueError("caster drag needs the general form")
        if self.geometry and (not self.caster or len(self.geometry) < 4 or len(self.geometry) % 2):
            raise ValueError("caster geometry is (r, b, x_1, y_1, ...) with at least one caster, caster form only")
        object.__setattr__(self, "geometry", tuple(float(v) for v in self.geometry))

    @property
    def n_casters(self) -> int:
        """K, the casters of the geometric model (0 otherwise)."""
        return (len(self.geometry) - 2) // 2 if self.geometry else 0

    @property
    def caster_map(self) -> tuple[tuple[int, int, int], ...]:
        """(regressor column, base parameter, pattern) of each caster column: theta_i,column =
        (m_i1 + pattern m_i2) theta0[parameter]."""
        if not self.caster:
            return ()
        if not self.geometry:
            return ((8, 8, 1), (9, 9, -1))
        return tuple(item for k in range(self.n_casters) for item in ((8 + 2 * k, 8 + k, 1), (9 + 2 * k, 8 + k, -1)))

    @property
    def n_columns(self) -> int:
        return (7 if self.kind == "paper" else 8) + len(self.caster_map)

    @property
    def n_base(self) -> int:
        """Number of base parameters: 8, plus Cv, Cw (two-term caster model) or D_1..D_K (geometric)."""
        if not self.caster:
            return 8
        return 8 + (self.n_casters if self.geometry else 2)

    @property
    def base_names(self) -> tuple[str, ...]:
        if not self.caster:
            return THETA0_NAMES
        if not self.geometry:
            return THETA0_NAMES + CASTER_NAMES
        return THETA0_NAMES + tuple(f"D{k + 1}" for k in range(self.n_casters))

    @property
    def column_names(self) -> tuple[str, ...]:
        if self.kind == "paper":
            return (*_COMMON_COLUMNS, "-1")
        if self.caster and not self.geometry:
            caster: tuple[str, ...] = ("-sgn(eta_1+eta_2)", "-sgn(eta_1-eta_2)")
        else:
            caster = tuple(f"-drag{k + 1}_{part}" for k in range(self.n_casters) for part in ("v", "w"))
        return (*_COMMON_COLUMNS, "-sgn(eta_1)", "-sgn(eta_2)", *caster)

    def theta_names(self) -> list[str]:
        """Names theta_1k, theta_2k (k from 1) in row-major order, as in Table 2."""
        return [f"theta{i}{k}" for i in (1, 2) for k in range(1, self.n_columns + 1)]

    @property
    def friction(self) -> str:
        return "wheel+caster" if self.caster else "wheel"

    def to_dict(self) -> dict[str, object]:
        out: dict[str, object] = {
            "kind": self.kind, "signs": list(self.signs), "columns": list(self.column_names), "friction": self.friction,
        }  # fmt: skip
        if self.geometry:
            out["caster_geometry"] = {"r": self.geometry[0], "b": self.geometry[1], "casters": [
                list(self.geometry[2 + 2 * k : 4 + 2 * k]) for k in range(self.n_casters)]}  # fmt: skip
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> RegressorForm:
        """The form recorded by :meth:`to_dict` (an identify result's ``theta.form``), friction model included."""
        caster = data.get("friction") == "wheel+caster"
        geometry: tuple[float, ...] = ()
        if caster and data.get("caster_geometry"):
            g = data["caster_geometry"]
            geometry = (g["r"], g["b"], *[v for xy in g["casters"] for v in xy])
        return cls(data["kind"], tuple(data.get("signs", (1, 1))), caster=caster, geometry=geometry)


def choose_form(eta: np.ndarray) -> RegressorForm:
    """The paper's 7-column form when each wheel keeps one strict sign over the log, else general.

    eta : (n, 2) float, rad/s.  A wheel that is ever exactly 0 or changes sign needs the general form
    (sgn(0) = 0 would break the paper form's constant column).
    """
    signs = []
    for j in range(2):
        col = eta[:, j]
        if np.all(col > 0):
            signs.append(1)
        elif np.all(col < 0):
            signs.append(-1)
        else:
            return RegressorForm("general")
    return RegressorForm("paper", (signs[0], signs[1]))


def inertia_matrix(p: PhysicalParameters) -> np.ndarray:
    """M (2, 2), kg m^2, Eqs. (10)-(12)."""
    inertia = (
        p.I_p
        + p.m_p * (p.d_x**2 + p.d_y**2)
        + 2.0 * (p.I_wm + p.m_w * p.a**2)
        + 2.0 * (p.I_rm + p.m_r * (p.c_x**2 + p.c_y**2))
    )
    mass = p.m_p + 2.0 * p.m_w + 2.0 * p.m_r
    scale = p.r**2 / (4.0 * p.b**2)
    spin = p.I_w + p.k_r**2 * p.I_r
    m11 = spin + (mass * p.b**2 + inertia - 2.0 * p.m_p * p.b * p.d_y) * scale
    m22 = spin + (mass * p.b**2 + inertia + 2.0 * p.m_p * p.b * p.d_y) * scale
    m12 = (mass * p.b**2 - inertia) * scale
    return np.array([[m11, m12], [m12, m22]])


def coriolis_coefficient(p: PhysicalParameters) -> float:
    """V_c (kg m^2) = (m_p d_x + 2 m_r c_x) r^3 / (4 b^2), below Eq. (14)."""
    return (p.m_p * p.d_x + 2.0 * p.m_r * p.c_x) * p.r**3 / (4.0 * p.b**2)


def base_parameters(p: PhysicalParameters) -> np.ndarray:
    """theta0 (8,) = [m11, m12, m22, Vc, Fv1, Fv2, Fd1, Fd2] of Eq. (21), with m = M^-1 (a robot file's base set,
    :class:`wmrid.model.robot.BaseSet`, gives them directly)."""
    given = getattr(p, "theta0", None)
    if given is not None:
        return np.array(given, dtype=np.float64)
    m = np.linalg.inv(inertia_matrix(p))
    return np.array([m[0, 0], m[0, 1], m[1, 1], coriolis_coefficient(p), p.F_v1, p.F_v2, p.F_d1, p.F_d2])


def inverse_inertia(theta0: np.ndarray) -> np.ndarray:
    """m = M^-1 (2, 2) from theta0."""
    return np.array([[theta0[0], theta0[1]], [theta0[1], theta0[2]]])


def invert_inertia_entries(x: np.ndarray) -> np.ndarray:
    """x (..., n) = [a11, a12, a22, rest...] -> the same with the entries of [[a11, a12], [a12, a22]]^-1 first.

    The one conversion between theta0 = [m11 m12 m22 Vc ...] and the physical vector phi = [M11 M12 M22 Vc ...]
    (Vc, friction and caster drag are the same in both), in either direction: the 2x2 inverse is its own inverse.
    Closed form (M11 = m22 / det, M12 = -m12 / det, M22 = m11 / det); a singular block gives inf/nan, not an error.
    """
    x = np.asarray(x, dtype=np.float64)
    a11, a12, a22 = x[..., 0], x[..., 1], x[..., 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        det = a11 * a22 - a12 * a12
        out = x.copy()
        out[..., 0] = a22 / det
        out[..., 1] = -a12 / det
        out[..., 2] = a11 / det
    return out


def invert_inertia_jacobian(x: np.ndarray) -> np.ndarray:
    """d y / d x (n, n) of y = :func:`invert_inertia_entries` (x): the 2x2 inverse's derivative dY = -Y dX Y in the
    top-left 3x3 block (entries 11, 12, 22; dX's 12 entry stands on both sides of the diagonal), identity elsewhere.
    """
    y = invert_inertia_entries(x)
    y11, y12, y22 = y[0], y[1], y[2]
    jac = np.eye(len(y))
    jac[:3, :3] = -np.array(
        [
            [y11 * y11, 2.0 * y11 * y12, y12 * y12],
            [y11 * y12, y11 * y22 + y12 * y12, y12 * y22],
            [y12 * y12, 2.0 * y12 * y22, y22 * y22],
        ]
    )
    return jac


def default_base_names(n0: int) -> tuple[str, ...]:
    """Names of a theta0 of n0 entries when its form is not at hand: the eight base parameters, then the two-term
    caster drag Cv, Cw (a geometric caster model's D_k need ``RegressorForm.base_names``)."""
    return (THETA0_NAMES + CASTER_NAMES)[:n0]


def named_base(theta0: np.ndarray, names: tuple[str, ...] | None = None) -> dict[str, float]:
    """theta0 plus M = m^-1 as a name -> value map (M11, M12, M22 in kg m^2); ``names`` default: the eight
    base parameters, and Cv, Cw for ten."""
    if names is None:
        names = default_base_names(len(theta0))
    out = {name: float(v) for name, v in zip(names, theta0, strict=True)}
    big_m = np.linalg.inv(inverse_inertia(theta0))
    out.update(M11=float(big_m[0, 0]), M12=float(big_m[0, 1]), M22=float(big_m[1, 1]))
    return out


def intermediate_parameters(theta0: np.ndarray, form: RegressorForm) -> np.ndarray:
    """theta (2, p): rows theta_1, theta_2 of Eqs. (23)-(24) (paper form) or the general form."""
    m = inverse_inertia(theta0)
    vc, fv1, fv2, fd1, fd2 = theta0[3:8]
    rows = []
    for i in range(2):
        mi1, mi2 = m[i]
        common = [mi1, mi2, mi1 * vc, mi2 * vc, mi1 * fv1, mi2 * fv2]
        if form.kind == "paper":
            s1, s2 = form.signs
            rows.append([*common, mi1 * fd1 * s1 + mi2 * fd2 * s2])
        elif form.caster:
            extra = [(mi1 + pattern * mi2) * theta0[param] for _, param, pattern in form.caster_map]
            rows.append([*common, mi1 * fd1, mi2 * fd2, *extra])
        else:
            rows.append([*common, mi1 * fd1, mi2 * fd2])
    return np.array(rows)


def regressor(eta: np.ndarray, tau: np.ndarray, form: RegressorForm) -> np.ndarray:
    """g(eta, tau) (n, p) of Eq. (25) for eta (n, 2) rad/s and tau (n, 2) N m."""
    e1, e2 = eta[:, 0], eta[:, 1]
    cols = [tau[:, 0], tau[:, 1], e2 * e2 - e1 * e2, e1 * e1 - e1 * e2, -e1, -e2]
    if form.kind == "paper":
        cols.append(-np.ones_like(e1))
    else:
        cols += [-np.sign(e1), -np.sign(e2)]
        if form.caster:
            cols += list(-caster_columns(eta, form).T)
    return np.stack(cols, axis=1)


def coriolis_torque(eta: np.ndarray, vc: float) -> np.ndarray:
    """V(eta) (n, 2), N m, Eqs. (13)-(14)."""
    e1, e2 = eta[..., 0], eta[..., 1]
    return vc * np.stack([e1 * e2 - e2 * e2, e1 * e2 - e1 * e1], axis=-1)


def friction_torque(eta: np.ndarray, theta0: np.ndarray, form: RegressorForm | None = None) -> np.ndarray:
    """F_v eta + F_d sgn(eta) (n, 2), N m, Eqs. (15)-(17), plus the caster drag when theta0 has more than 8
    entries (``form`` says which caster model; None: the two-term one)."""
    fv = theta0[4:6]
    fd = theta0[6:8]
    out = fv * eta + fd * np.sign(eta)
    if len(theta0) > 8:
        form = form if form is not None else RegressorForm("general", caster=True)
        cols = caster_columns(np.atleast_2d(eta), form)  # (n, q)
        drag = np.zeros(np.atleast_2d(eta).shape)
        for j, (_, param, pattern) in enumerate(form.caster_map):
            drag += theta0[param] * cols[:, j : j + 1] * np.array([1.0, float(pattern)])
        out = out + drag.reshape(np.shape(out))
    return out


#: Below this speed (m/s) of a caster's contact, its drag direction is regularised (smooth through a stop).
DRAG_SPEED = 1e-3


def caster_columns(eta: np.ndarray, form: RegressorForm) -> np.ndarray:
    """The caster drag's columns (n, q) for eta (n, 2) rad/s, in the order of ``form.caster_map``.

    A caster's rolling drag is a force D against the velocity of its contact with the ground.  Mapped to the
    wheels through the kinematics (v = r (eta_1 + eta_2) / 2, w = r (eta_1 - eta_2) / (2 b), tau = J^T Q), a
    drag needs the wheel torques a [1, 1] + c [1, -1], a the part against the platform's speed, c against its
    turning.  Column j holds a (pattern +1) or c (pattern -1) per unit parameter; the wheels see
    theta0[param] x column x [1, pattern].

    * Two-term model (no geometry): driving straight the drag is a Coulomb force against v, turning on the spot
      a Coulomb moment against w: a = sgn(eta_1 + eta_2), c = sgn(eta_1 - eta_2), with parameters Cv = (r/2) x
      the force and Cw = (r/(2b)) x the moment, N m at each wheel (r and b need not be known).  In between,
      the true drag turns smoothly with each caster's velocity, which this model leaves to the residual.
    * Geometric model (r, b and each caster's contact (x_k, y_k) known): its contact moves at
      u = (v - w y_k, w x_k), the drag is -D_k u/|u| (|u| regularised by DRAG_SPEED), so per newton of drag
      a = (r/2) u_x/|u| and c = (r/(2b)) (x_k u_y - y_k u_x)/|u|: exact for a ball caster of constant load.
    """
    e1, e2 = eta[:, 0], eta[:, 1]
    if not form.geometry:
        return np.stack([np.sign(e1 + e2), np.sign(e1 - e2)], axis=1)
    r, b = form.geometry[0], form.geometry[1]
    v = 0.5 * r * (e1 + e2)
    w = r / (2.0 * b) * (e1 - e2)
    cols = []
    for k in range(form.n_casters):
        x, y = form.geometry[2 + 2 * k], form.geometry[3 + 2 * k]
        ux, uy = v - w * y, w * x
        norm = np.sqrt(ux * ux + uy * uy + DRAG_SPEED**2)
        cols += [0.5 * r * ux / norm, r / (2.0 * b) * (x * uy - y * ux) / norm]
    return np.stack(cols, axis=1)


def wheel_acceleration(
    eta: np.ndarray, tau: np.ndarray, theta0: np.ndarray, form: RegressorForm | None = None
) -> np.ndarray:
    """The direct model eta_dot (n, 2), rad/s^2, Eq. (20) without disturbance (``form``: the caster model of a
    theta0 longer than 8, see :func:`friction_torque`)."""
    rhs = tau - coriolis_torque(eta, theta0[3]) - friction_torque(eta, theta0, form)
    return rhs @ inverse_inertia(theta0).T


def wheel_torque(
    eta: np.ndarray, eta_dot: np.ndarray, theta0: np.ndarray, form: RegressorForm | None = None
) -> np.ndarray:
    """The inverse model tau (n, 2), N m, Eq. (9) without disturbance (``form`` as :func:`wheel_acceleration`)."""
    big_m = np.linalg.inv(inverse_inertia(theta0))
    return eta_dot @ big_m.T + coriolis_torque(eta, theta0[3]) + friction_torque(eta, theta0, form)
