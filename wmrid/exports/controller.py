"""The identified reduced model for a controller: a YAML file and a dependency-free Python function.

Both hold the model the result identified, in the paper's form (Eq. 9 without the disturbance)

    tau = M eta_dot + V(eta) + F_v eta + F_d sgn(eta) [+ the casters' drag],
    V(eta) = V_c [eta_1 eta_2 - eta_2^2, eta_1 eta_2 - eta_1^2],

eta = [right, left] wheel speeds (rad/s), tau the wheel torques (N m, or the log's effort unit); the caster drag as
:func:`wmrid.model.torques.friction_torque` computes it (the two-term model, or each caster's drag force D_k against
its contact's velocity).  Every value carries its std (a field in YAML, a comment in Python) and both name the
result, the log and the robot they came from.  :func:`wheel_torques` is what the Python file defines; the tests
check both files against :func:`wmrid.model.torques.wheel_torque` to 1e-12.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from wmrid.model import dynamics as model
from wmrid.model.dynamics import DRAG_SPEED, RegressorForm


@dataclass(frozen=True)
class ControllerModel:
    """The parts of a result a controller needs (SI or the log's effort unit).

    theta0 (n0,), cov (n0, n0): the base parameters and their covariance (NaN/inf: undetermined); names (n0,);
    form: the identified regressor form (its caster model); units: name -> unit; provenance: name -> text (result,
    log, robot, method, wmrid version).
    """

    theta0: np.ndarray
    cov: np.ndarray
    names: tuple[str, ...]
    form: RegressorForm
    units: dict[str, str]
    provenance: dict[str, str]

    @property
    def big_m(self) -> np.ndarray:
        return np.linalg.inv(model.inverse_inertia(self.theta0))

    def std(self) -> dict[str, float]:
        """name -> std of every base parameter and of M11, M12, M22 (inf: undetermined)."""
        diag = np.diag(self.cov)
        out = {
            n: float(math.sqrt(v)) if np.isfinite(v) and v >= 0 else math.inf
            for n, v in zip(self.names, diag, strict=True)
        }
        cov3 = self.cov[:3, :3]
        if np.all(np.isfinite(cov3)):
            jac = model.invert_inertia_jacobian(np.concatenate([self.theta0[:3], [0.0]]))[:3, :3]
            big = np.sqrt(np.clip(np.diag(jac @ cov3 @ jac.T), 0.0, None))
        else:
            big = np.full(3, math.inf)
        out.update(M11=float(big[0]), M12=float(big[1]), M22=float(big[2]))
        return out

    def casters(self) -> list[dict[str, Any]]:
        """The geometric caster model's casters: [{"x", "y", "D", "D_std", "load": {signal: (value, std)}}] (m, m, N;
        the load terms of ``wheel+caster+load`` in their units, :data:`wmrid.model.dynamics.LOAD_SIGNALS`); []
        otherwise."""
        if not self.form.caster or not self.form.geometry:
            return []
        std = self.std()
        out = []
        big_k, signals = self.form.n_casters, tuple(self.form.load)
        for k in range(big_k):
            name = f"D{k + 1}"
            x, y = self.form.geometry[2 + 2 * k], self.form.geometry[3 + 2 * k]
            load = {
                sig: (float(self.theta0[8 + big_k + k * len(signals) + j]), std[f"{name}{sig}"])
                for j, sig in enumerate(signals)
            }
            out.append({"x": x, "y": y, "D": float(self.theta0[8 + k]), "D_std": std[name], "load": load})
        return out


def _num(value: float) -> str:
    """A float as YAML and Python read it back exactly (repr), inf/nan spelled for YAML."""
    if math.isnan(value):
        return ".nan"
    if math.isinf(value):
        return ".inf" if value > 0 else "-.inf"
    return repr(float(value))


def _py(value: float) -> str:
    """A float as Python reads it back exactly; inf and nan as float("inf") / float("nan")."""
    return repr(float(value)) if math.isfinite(value) else f'float("{value}")'


def _std_text(value: float) -> str:
    return "undetermined" if not math.isfinite(value) else f"{value:.3g}"


def yaml_text(cm: ControllerModel) -> str:
    """The YAML document (module docstring); read back by any YAML 1.2 reader (tests use ruamel.yaml)."""
    std = cm.std()
    big_m = cm.big_m
    unit = cm.units
    th = cm.theta0
    lines = [
        "# wmrid export: the identified reduced wheel-space model (Hoang & Kang 2015, Eq. 9)",
        "#   tau = M eta_dot + V(eta) + F_v eta + F_d sgn(eta) [+ caster drag]",
        "#   V(eta) = Vc [eta_1 eta_2 - eta_2^2, eta_1 eta_2 - eta_1^2]; eta = [right, left] wheel speeds, rad/s",
        "# every value has its standard error beside it (std; .inf: the log does not determine it)",
        "schema: 1",
        "kind: wmrid-reduced-model",
        "provenance:",
        *[f"  {k}: {json.dumps(v)}" for k, v in cm.provenance.items()],
        "units:",
        *[f"  {k}: {json.dumps(unit.get(k, ''))}" for k in ("M11", "m11", "Vc", "Fv1", "Fd1")],
        "wheels: [right, left]",
        "M:  # inertia matrix",
        f"  value: [[{_num(big_m[0, 0])}, {_num(big_m[0, 1])}], [{_num(big_m[0, 1])}, {_num(big_m[1, 1])}]]",
        f"  std: [[{_num(std['M11'])}, {_num(std['M12'])}], [{_num(std['M12'])}, {_num(std['M22'])}]]",
        "M_inverse:  # m = M^-1, the base parameters m11, m12, m22",
        f"  value: [[{_num(th[0])}, {_num(th[1])}], [{_num(th[1])}, {_num(th[2])}]]",
        f"  std: [[{_num(std['m11'])}, {_num(std['m12'])}], [{_num(std['m12'])}, {_num(std['m22'])}]]",
        "Vc:  # Coriolis coefficient",
        f"  value: {_num(th[3])}",
        f"  std: {_num(std['Vc'])}",
        "Fv:  # viscous friction per wheel",
        f"  value: [{_num(th[4])}, {_num(th[5])}]",
        f"  std: [{_num(std['Fv1'])}, {_num(std['Fv2'])}]",
        "Fd:  # Coulomb friction per wheel",
        f"  value: [{_num(th[6])}, {_num(th[7])}]",
        f"  std: [{_num(std['Fd1'])}, {_num(std['Fd2'])}]",
    ]
    if cm.form.caster and cm.form.geometry:
        r, b = cm.form.geometry[:2]
        lines += [
            "caster_drag:  # each caster's drag force D (N) against the velocity of its contact point (x, y), m;",
            "  # with load terms the force is D + sum(load[s] * s) over s in dv = v', w2 = w^2, vw = v w, dw = w'",
            "  # (v = r (eta_1 + eta_2) / 2, w = r (eta_1 - eta_2) / (2 b)): the drag follows the caster's load",
            "  model: geometric",
            f"  r: {_num(r)}",
            f"  b: {_num(b)}",
            f"  regularisation_speed: {_num(DRAG_SPEED)}  # m/s: |u| -> sqrt(|u|^2 + this^2)",
            "  casters:",
            *[f"    - {{x: {_num(c['x'])}, y: {_num(c['y'])}, D: {_num(c['D'])}, D_std: {_num(c['D_std'])}, load: "
              + "{" + ", ".join(f"{sig}: {_num(v)}" for sig, (v, _) in c["load"].items()) + "}, load_std: {"
              + ", ".join(f"{sig}: {_num(e)}" for sig, (_, e) in c["load"].items()) + "}}"
              for c in cm.casters()],
        ]  # fmt: skip
    elif cm.form.caster:
        lines += [
            "caster_drag:  # Cv sgn(eta_1 + eta_2) [1, 1] + Cw sgn(eta_1 - eta_2) [1, -1], N m at the wheels",
            "  model: two-term",
            f"  Cv: {{value: {_num(th[8])}, std: {_num(std['Cv'])}}}",
            f"  Cw: {{value: {_num(th[9])}, std: {_num(std['Cw'])}}}",
        ]
    lines += [
        "base_parameters:  # theta0 and its covariance (the identified estimate)",
        f"  names: [{', '.join(cm.names)}]",
        f"  value: [{', '.join(_num(v) for v in th)}]",
        "  covariance:",
        *[f"    - [{', '.join(_num(v) for v in row)}]" for row in np.asarray(cm.cov)],
    ]
    return "\n".join(lines) + "\n"


def python_text(cm: ControllerModel) -> str:
    """A dependency-free Python module defining ``wheel_torques(eta, eta_dot) -> tau`` (module docstring)."""
    std = cm.std()
    big_m = cm.big_m
    th = cm.theta0
    unit = cm.units
    prov = "\n".join(f"#   {k}: {json.dumps(v)}" for k, v in cm.provenance.items())  # escaped: one line each
    m_std = ", ".join(_std_text(std[n]) for n in ("M11", "M12", "M22"))
    caster = "CASTERS = ()  # no caster drag in this model"
    two_term = "TWO_TERM = None"
    geometry = f"R, B = {_py(0.0)}, {_py(0.0)}"
    if cm.form.caster and cm.form.geometry:
        r, b = cm.form.geometry[:2]
        geometry = f"R, B = {_py(r)}, {_py(b)}  # m: wheel radius, half track"
        rows = "".join(
            f"    ({_py(c['x'])}, {_py(c['y'])}, {_py(c['D'])}, ("
            + "".join(f"({sig!r}, {_py(v)}), " for sig, (v, _) in c["load"].items())
            + f")),  # D std {_std_text(c['D_std'])} N"
            + "".join(f"; {sig} std {_std_text(e)}" for sig, (_, e) in c["load"].items())
            + "\n"
            for c in cm.casters()
        )
        caster = (
            "CASTERS = (  # (x m, y m, drag force D N, load terms ((signal, coefficient), ...)) of each caster\n"
            f"{rows})"
        )
    elif cm.form.caster:
        two_term = (
            f"TWO_TERM = ({_py(th[8])}, {_py(th[9])})  # (Cv, Cw) N m, std {_std_text(std['Cv'])}, "
            f"{_std_text(std['Cw'])}"
        )
    return f'''"""The reduced wheel-space model of a robot identified by wmrid (Hoang & Kang 2015, Eq. 9).

    tau = M eta_dot + V(eta) + F_v eta + F_d sgn(eta) [+ caster drag]

eta = [right, left] wheel speeds (rad/s), eta_dot their accelerations (rad/s^2), tau the wheel torques
({unit.get("Fd1", "N m")}).  Paste wheel_torques into a controller as a feedforward or computed-torque term.  Pure
Python, no imports beyond math.
"""
# Provenance:
{prov}

import math

#: Inertia matrix M ({unit.get("M11", "kg m^2")}); std M11, M12, M22: {m_std}
M = (({_py(big_m[0, 0])}, {_py(big_m[0, 1])}), ({_py(big_m[0, 1])}, {_py(big_m[1, 1])}))
#: Coriolis coefficient Vc ({unit.get("Vc", "kg m^2")}); std {_std_text(std["Vc"])}
VC = {_py(th[3])}
#: Viscous friction (right, left) ({unit.get("Fv1", "N m s/rad")}); std {_std_text(std["Fv1"])}, {_std_text(std["Fv2"])}
FV = ({_py(th[4])}, {_py(th[5])})
#: Coulomb friction (right, left) ({unit.get("Fd1", "N m")}); std {_std_text(std["Fd1"])}, {_std_text(std["Fd2"])}
FD = ({_py(th[6])}, {_py(th[7])})
{geometry}
{caster}
{two_term}
DRAG_SPEED = {_py(DRAG_SPEED)}  # m/s: a caster's contact speed is regularised as sqrt(|u|^2 + DRAG_SPEED^2)


def _sgn(x):
    return (x > 0) - (x < 0)


def wheel_torques(eta, eta_dot):
    """(tau_right, tau_left) for wheel speeds eta = (right, left) rad/s and accelerations eta_dot rad/s^2."""
    e1, e2 = float(eta[0]), float(eta[1])
    a1, a2 = float(eta_dot[0]), float(eta_dot[1])
    t1 = M[0][0] * a1 + M[0][1] * a2 + VC * (e1 * e2 - e2 * e2) + FV[0] * e1 + FD[0] * _sgn(e1)
    t2 = M[0][1] * a1 + M[1][1] * a2 + VC * (e1 * e2 - e1 * e1) + FV[1] * e2 + FD[1] * _sgn(e2)
    if TWO_TERM is not None:
        cv, cw = TWO_TERM
        t1 += cv * _sgn(e1 + e2) + cw * _sgn(e1 - e2)
        t2 += cv * _sgn(e1 + e2) - cw * _sgn(e1 - e2)
    v = 0.5 * R * (e1 + e2)
    w = R / (2.0 * B) * (e1 - e2) if B else 0.0
    # the signals a caster's load (and so its drag) follows: v', w^2, v w, w'
    signals = {{"dv": 0.5 * R * (a1 + a2), "w2": w * w, "vw": v * w, "dw": R / (2.0 * B) * (a1 - a2) if B else 0.0}}
    for x, y, force, load in CASTERS:
        force = force + sum(coefficient * signals[name] for name, coefficient in load)
        ux, uy = v - w * y, w * x
        norm = math.sqrt(ux * ux + uy * uy + DRAG_SPEED * DRAG_SPEED)
        a = 0.5 * R * ux / norm
        c = R / (2.0 * B) * (x * uy - y * ux) / norm
        t1 += force * (a + c)
        t2 += force * (a - c)
    return (t1, t2)
'''


def controller_model(result: Any, provenance: dict[str, str]) -> ControllerModel:
    """The :class:`ControllerModel` of an identification result (its reported estimate)."""
    est = result.estimate
    theta0 = np.asarray(est.theta0, dtype=float)
    n0 = len(theta0)
    names = tuple(result.form.base_names) if n0 == result.form.n_base else model.default_base_names(n0)
    return ControllerModel(theta0=theta0, cov=np.asarray(est.cov, dtype=float), names=names, form=result.form,
                           units=dict(result.units), provenance=provenance)  # fmt: skip
