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

from wmrid.model.robot import BaseSet, PhysicalParameters

THETA0_NAMES = ("m11", "m12", "m22", "Vc", "Fv1", "Fv2", "Fd1", "Fd2")
#: The caster-drag base parameters of the ``wheel+caster`` friction model, appended to theta0.
CASTER_NAMES = ("Cv", "Cw")
#: The platform motions a caster's normal load follows (:func:`caster_columns`), in their order everywhere:
#: v' (m/s^2) and w^2 (rad^2/s^2) move load fore and aft (pitch), v w (m rad/s^2) and w' (rad/s^2) side to side.
LOAD_SIGNALS = ("dv", "w2", "vw", "dw")
#: The load signals that are time derivatives, of v and of w (the observer's filters carry them, see
#: :func:`filter_regressor`).
DERIVATIVE_SIGNALS = ("dv", "dw")
THETA0_UNITS = {
    "m11": "1/(kg m^2)", "m12": "1/(kg m^2)", "m22": "1/(kg m^2)", "Vc": "kg m^2",
    "Fv1": "N m s/rad", "Fv2": "N m s/rad", "Fd1": "N m", "Fd2": "N m",
    "M11": "kg m^2", "M12": "kg m^2", "M22": "kg m^2", "Cv": "N m", "Cw": "N m",
    **{f"D{k}": "N" for k in range(1, 9)},
    **{f"D{k}{sig}": unit for k in range(1, 9) for sig, unit in (
        ("dv", "N s^2/m"), ("w2", "N s^2/rad^2"), ("vw", "N s^2/(m rad)"), ("dw", "N s^2/rad"))},
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
        **{f"D{k}{sig}": f"{u} {unit}" for k in range(1, 9) for sig, unit in (
            ("dv", "s^2/m^2"), ("w2", "s^2/(m rad^2)"), ("vw", "s^2/(m^2 rad)"), ("dw", "s^2/(m rad)"))},
    }  # fmt: skip


_COMMON_COLUMNS = ("tau_1", "tau_2", "eta_2^2-eta_1*eta_2", "eta_1^2-eta_1*eta_2", "-eta_1", "-eta_2")


@dataclass(frozen=True)
class RegressorForm:
    """Which regressor g(eta, tau) is used: the paper's 7 columns or the general 8, and whether caster drag
    adds columns (general form only; see :func:`caster_columns`).

    caster : the ``wheel+caster`` friction model.  geometry : () for the two-term model (Cv, Cw: the drag's
    limits driving straight and turning on the spot), or (r, b, x_1, y_1, ..., x_K, y_K) in m: the wheel
    radius, half track and each caster's ground contact in the platform frame, for the exact drag direction
    of each caster (one parameter per caster, its drag force D_k in N).  load : geometric model only, the
    signals of :data:`LOAD_SIGNALS` the casters' drag follows as their normal load moves with the platform's
    accelerations (see :func:`caster_columns`): one more parameter per caster and signal, D{k}{signal}.
    """

    kind: Literal["paper", "general"] = "paper"
    signs: tuple[int, int] = (1, 1)  # paper form only: the constant sign of eta_1 and eta_2
    caster: bool = False  # the wheel+caster friction model
    geometry: tuple[float, ...] = ()
    load: tuple[str, ...] = ()

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
        object.__setattr__(self, "load", tuple(self.load))
        if self.load and (not self.geometry or any(x not in LOAD_SIGNALS for x in self.load)
                          or self.load != tuple(x for x in LOAD_SIGNALS if x in self.load)):  # fmt: skip
            raise ValueError(
                f"caster load signals are an ordered subset of {LOAD_SIGNALS} with a caster geometry, got {self.load}"
            )

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
        big_k = self.n_casters
        drag = tuple(item for k in range(big_k) for item in ((8 + 2 * k, 8 + k, 1), (9 + 2 * k, 8 + k, -1)))
        n_load = big_k * len(self.load)  # caster k, signal l: parameter 8 + K + k L + l, columns after the drag's
        load = tuple(item for j in range(n_load) for item in (
            (8 + 2 * big_k + 2 * j, 8 + big_k + j, 1), (9 + 2 * big_k + 2 * j, 8 + big_k + j, -1)))  # fmt: skip
        return drag + load

    @property
    def derivative_columns(self) -> tuple[tuple[int, int], ...]:
        """(regressor column, signal) of the columns c(eta) x phi' whose phi' is a derivative: signal 0 for
        phi = v (``dv``), 1 for phi = w (``dw``).  The observer carries them through its filters without
        differentiating (:func:`filter_regressor`)."""
        if not self.load:
            return ()
        out = []
        for col, param, _ in self.caster_map:
            if param >= 8 + self.n_casters:
                signal = self.load[(param - 8 - self.n_casters) % len(self.load)]
                if signal in DERIVATIVE_SIGNALS:
                    out.append((col, DERIVATIVE_SIGNALS.index(signal)))
        return tuple(out)

    @property
    def n_columns(self) -> int:
        return (7 if self.kind == "paper" else 8) + len(self.caster_map)

    @property
    def n_base(self) -> int:
        """Number of base parameters: 8, plus Cv, Cw (two-term caster model) or D_1..D_K (geometric)."""
        if not self.caster:
            return 8
        return 8 + (self.n_casters * (1 + len(self.load)) if self.geometry else 2)

    @property
    def base_names(self) -> tuple[str, ...]:
        if not self.caster:
            return THETA0_NAMES
        if not self.geometry:
            return THETA0_NAMES + CASTER_NAMES
        drag = tuple(f"D{k + 1}" for k in range(self.n_casters))
        return THETA0_NAMES + drag + tuple(f"D{k + 1}{x}" for k in range(self.n_casters) for x in self.load)

    @property
    def column_names(self) -> tuple[str, ...]:
        if self.kind == "paper":
            return (*_COMMON_COLUMNS, "-1")
        if self.caster and not self.geometry:
            caster: tuple[str, ...] = ("-sgn(eta_1+eta_2)", "-sgn(eta_1-eta_2)")
        else:
            caster = tuple(f"-drag{k + 1}_{part}" for k in range(self.n_casters) for part in ("v", "w"))
            caster += tuple(f"-drag{k + 1}_{part}*{x}" for k in range(self.n_casters) for x in self.load
                            for part in ("v", "w"))  # fmt: skip
        return (*_COMMON_COLUMNS, "-sgn(eta_1)", "-sgn(eta_2)", *caster)

    def theta_names(self) -> list[str]:
        """Names theta_1k, theta_2k (k from 1) in row-major order, as in Table 2."""
        return [f"theta{i}{k}" for i in (1, 2) for k in range(1, self.n_columns + 1)]

    @property
    def friction(self) -> str:
        """The friction model: ``wheel``, ``wheel+caster``, or ``wheel+caster+load`` (a drag that follows the load)."""
        if not self.caster:
            return "wheel"
        return "wheel+caster+load" if self.load else "wheel+caster"

    def to_dict(self) -> dict[str, object]:
        out: dict[str, object] = {
            "kind": self.kind, "signs": list(self.signs), "columns": list(self.column_names), "friction": self.friction,
        }  # fmt: skip
        if self.geometry:
            out["caster_geometry"] = {"r": self.geometry[0], "b": self.geometry[1], "casters": [
                list(self.geometry[2 + 2 * k : 4 + 2 * k]) for k in range(self.n_casters)]}  # fmt: skip
        if self.load:
            out["caster_load"] = list(self.load)
        return out

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> RegressorForm:
        """The form recorded by :meth:`to_dict` (an identify result's ``theta.form``), friction model included."""
        caster = data.get("friction") in ("wheel+caster", "wheel+caster+load")
        geometry: tuple[float, ...] = ()
        if caster and data.get("caster_geometry"):
            g = data["caster_geometry"]
            geometry = (g["r"], g["b"], *[v for xy in g["casters"] for v in xy])
        load = tuple(data.get("caster_load", ())) if geometry else ()
        return cls(data["kind"], tuple(data.get("signs", (1, 1))), caster=caster, geometry=geometry, load=load)

    def without_load(self) -> RegressorForm:
        """The same form without the load-transfer terms (its first :attr:`n_base` - K L base parameters)."""
        return RegressorForm(self.kind, self.signs, caster=self.caster, geometry=self.geometry)


def load_signals(geometry: tuple[float, ...]) -> tuple[str, ...]:
    """The load signals (:data:`LOAD_SIGNALS`) of the ``wheel+caster+load`` model for casters at ``geometry``
    (r, b, x_1, y_1, ...): the pitch's v' and w^2 when every caster is on the centre line (|y_k| < 1 mm: a roll
    moment is taken by the wheels, whose contacts are the only supports off the line, and w' enters only through
    the centre of mass's small d_y), all four otherwise."""
    if all(abs(y) < 1e-3 for y in geometry[3::2]):
        return ("dv", "w2")
    return LOAD_SIGNALS


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


def base_parameters(p: PhysicalParameters | BaseSet) -> np.ndarray:
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


def regressor(eta: np.ndarray, tau: np.ndarray, form: RegressorForm, eta_dot: np.ndarray | None = None) -> np.ndarray:
    """g(eta, tau) (n, p) of Eq. (25) for eta (n, 2) rad/s and tau (n, 2) N m.

    A form whose caster drag follows v' or w' (``form.derivative_columns``) needs eta_dot (n, 2) rad/s^2; the
    observer, which does not differentiate, uses :func:`filter_regressor` instead."""
    return _regressor(eta, tau, form, eta_dot, multiplier=False)


#: Samples by which the observer's derivative columns (c(eta) v', c(eta) w') take phi' late: the change of the speeds
#: over the previous step, not the current one, whose noise the prediction error carries too (see
#: :mod:`wmrid.estimators.observer.step`).  A lag of one step errs by about h phi'' / phi' of the column (1 ms at 1
# kHz).
DERIVATIVE_LAG = 1


def filter_regressor(
    eta: np.ndarray, tau: np.ndarray, form: RegressorForm, eta_sign: np.ndarray | None = None
) -> np.ndarray:
    """What the observer's filters take per sample (n, p): g(eta, tau) of :func:`regressor`, except that a column
    c(eta) phi' of ``form.derivative_columns`` holds its multiplier c(eta).

    The filters then take that column's input over a step from t_a to t_b as phi's rate of change over the step
    before it times the first-order-hold weights of c (:data:`DERIVATIVE_LAG`;
    :func:`wmrid.estimators.observer.step.observer_step`).  No derivative is formed: summed over
    steps the phi differences telescope, so a noisy phi enters the filtered column once, not divided by the step
    (with c constant, filtered phi' = phi - k filtered phi, exactly).

    eta_sign (n, 2) rad/s: the speeds the sign columns and the casters' drag directions are taken from (the
    observer's short centred mean, :mod:`wmrid.estimators.sign_speed`); None: eta."""
    return _regressor(eta, tau, form, None, multiplier=True, eta_sign=eta_sign)


def _regressor(eta, tau, form, eta_dot, multiplier, eta_sign=None):
    e1, e2 = eta[:, 0], eta[:, 1]
    sgn = eta if eta_sign is None else eta_sign
    cols = [tau[:, 0], tau[:, 1], e2 * e2 - e1 * e2, e1 * e1 - e1 * e2, -e1, -e2]
    if form.kind == "paper":
        cols.append(-np.ones_like(e1))
    else:
        cols += [-np.sign(sgn[:, 0]), -np.sign(sgn[:, 1])]
        if form.caster:
            cols += list(-caster_columns(eta, form, eta_dot, multiplier=multiplier, eta_sign=eta_sign).T)
    return np.stack(cols, axis=1)


def platform_speeds(eta: np.ndarray, r: float, b: float) -> tuple[np.ndarray, np.ndarray]:
    """(v, w): the platform's forward speed (m/s) and turn rate (rad/s) from eta (..., 2) rad/s (or their
    derivatives from eta_dot), for wheel radius r and half track b, m."""
    e1, e2 = eta[..., 0], eta[..., 1]
    return 0.5 * r * (e1 + e2), r / (2.0 * b) * (e1 - e2)


#: Below this speed (m/s) of a caster's contact, its drag direction is regularised (smooth through a stop).
DRAG_SPEED = 1e-3


def caster_columns(
    eta: np.ndarray,
    form: RegressorForm,
    eta_dot: np.ndarray | None = None,
    *,
    multiplier: bool = False,
    eta_sign: np.ndarray | None = None,
) -> np.ndarray:
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
      (a and c are r/2 and r/(2b) times d|u|/dv and d|u|/dw: the drag's power is D_k |u|.)
    * Load transfer (``form.load``): a ball caster's drag is its rolling resistance times its normal load N_k,
      and N_k moves with the platform's accelerations.  The supports' normal forces balance gravity and the
      moments of the bodies' inertial forces -m_i a_i, which act at the bodies' heights above the ground; a
      body at (x_i, y_i) in the platform frame accelerates by a_x = v' - x_i w^2 - y_i w', a_y = v w + x_i w' -
      y_i w^2 (plus the wheels' and rotors' gyroscopic moment, in v w, and the motors' reaction, in eta'), so
      with supports whose stiffness does not change with load every caster's load, and its drag, is
      D_k(t) = D_k + D{k}dv v' + D{k}w2 w^2 + D{k}vw v w + D{k}dw w'  (each term a caster's share of a moment
      about the ground; a caster on the centre line takes only the pitch's v', w^2 and, through d_y, w').  The
      drag's columns times each signal are the load term's columns; linear in the new parameters, so the
      estimator stays linear.  The v' and w' columns need eta_dot (n, 2) rad/s^2; ``multiplier`` leaves them
      without the derivative (what the observer's filters take, :func:`filter_regressor`).

    eta_sign (n, 2) rad/s: the speeds the drag's direction (the signs, u/|u|) is taken from; the load signals keep
    eta (None: eta for both).
    """
    s = eta if eta_sign is None else eta_sign
    if not form.geometry:
        return np.stack([np.sign(s[:, 0] + s[:, 1]), np.sign(s[:, 0] - s[:, 1])], axis=1)
    r, b = form.geometry[0], form.geometry[1]
    v, w = platform_speeds(eta, r, b)
    vs, ws = platform_speeds(s, r, b)
    cols = []
    for k in range(form.n_casters):
        x, y = form.geometry[2 + 2 * k], form.geometry[3 + 2 * k]
        ux, uy = vs - ws * y, ws * x
        norm = np.sqrt(ux * ux + uy * uy + DRAG_SPEED**2)
        cols += [0.5 * r * ux / norm, r / (2.0 * b) * (x * uy - y * ux) / norm]
    if form.load:
        signals = {"w2": w * w, "vw": v * w}
        if not multiplier:
            if eta_dot is None:
                raise ValueError("a caster drag that follows v' or w' needs eta_dot")
            # (complex eta_dot kept: the plan's gradient takes the complex step through it)
            signals["dv"], signals["dw"] = platform_speeds(np.asarray(eta_dot) * 1.0, r, b)
        else:
            signals["dv"] = signals["dw"] = np.ones_like(v)
        drag = list(cols)
        for k in range(form.n_casters):
            for x in form.load:
                cols += [drag[2 * k] * signals[x], drag[2 * k + 1] * signals[x]]
    return np.stack(cols, axis=1)
