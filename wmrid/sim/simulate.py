"""The paper's virtual prototype (Sec. 4-5) as a fast, seeded closed-loop simulator.

A differential-drive robot with the TRUE parameters tracks a reference trajectory under a
Fierro & Lewis (1995) backstepping controller that only knows the NOMINAL parameters; the log it
produces is what the identification in the rest of wmrid consumes, and ``SimulatedLog.truth()``
is what it should find.

Conventions (the paper's, SI units): eta = [eta_1, eta_2] = [right, left] wheel angular velocity
(rad/s), tau = [tau_1, tau_2] wheel torque (N m), pose (x m, y m, phi rad) of the axle midpoint O.

Plant (true parameters, Eqs. 7, 9)::

    x' = r/2 (eta_1 + eta_2) cos phi,  y' = r/2 (eta_1 + eta_2) sin phi,  phi' = r/(2b) (eta_1 - eta_2)
    theta' = eta
    M eta' + V(eta) + F_v eta + F_d sgn(eta) + tau_d = tau          (sgn(0) = 0)

integrated with classical RK4, ``substeps`` steps per control period, torque tau and caster
disturbance tau_d held constant over each control period (zero-order hold).

Controller, every control period T (1 ms, the paper's sampling time; 1/rate when rate > 1 kHz), on the
TRUE state (measurement noise only enters the log):

* tracking error in the robot frame, e = R(phi)^T (q_r - q), e3 = wrap(phi_r - phi) in [-pi, pi);
* kinematic control (Fierro & Lewis 1995, Eq. 12)::

      v_c = v_r cos e3 + k1 e1
      w_c = w_r + k2 v_r e2 + k3 |v_r| sin e3

  With v_r >= 0 (the ``sinusoid``) this is exactly Fierro & Lewis' law; ``|v_r|`` in the last term keeps
  the Lyapunov derivative -k1 e1^2 - (k3/k2) |v_r| sin^2 e3 non-positive when the reference drives
  backwards (``reversing``), where the textbook law would be unstable in e3.
* wheel-speed references with the NOMINAL r, b: eta_c = [(v_c + b w_c)/r, (v_c - b w_c)/r];
* eta_c' ANALYTICALLY: v_c', w_c' by the chain rule with the reference's v_r', w_r' and the error
  dynamics e1' = w e2 - v + v_r cos e3, e2' = -w e1 + v_r sin e3, e3' = w_r - w, where (v, w) are computed
  from the measured eta with the nominal r, b (no backward difference, so no start-up transient);
* computed torque with the NOMINAL parameters (including the nominal friction, 0 for the paper robot)::

      tau = M_nom (eta_c' + K (eta_c - eta)) + V_nom(eta) + F_v,nom eta + F_d,nom sgn(eta)

Gains (:data:`GAINS`): k1 = 3 1/s, k2 = 25 1/m^2, k3 = 10 1/m (linearised lateral error dynamics
s^2 + k3 v_r s + k2 v_r^2: critically damped, natural frequency 5 v_r rad/s), K = 50 1/s (wheel-speed
loop, a 20 ms time constant, well above the kinematic loop and well below the 1 kHz control rate).

Trajectories (:data:`TRAJECTORY_PARAMETERS`), both start at the origin with the robot ON the
reference and its wheel speeds equal to the reference's (computed with the TRUE r, b):

* ``sinusoid`` (the paper's Fig. 5): the path y = A sin(2 pi x / lambda) travelled with a forward speed
  x'(t) = v0 + dv sin(2 pi t / P), i.e. x_r(t) = v0 t + dv P / (2 pi) (1 - cos(2 pi t / P)); with
  A = 0.5 m, lambda = 3 m, v0 = 0.5 m/s, dv = 0.3 m/s, P = 7 s the curvature reaches 2.19 1/m
  (b kappa = 0.50) so the wheels differ by up to a factor 3, both stay strictly positive (about
  0.8 rad/s at the slowest, on the default paper robot), and speed, turning rate and both
  accelerations vary on two incommensurate periods (P and lambda / v0 = 6 s): all 7 columns of Eq. (25)
  are excited.  phi_r = atan2(y_r', x_r'); v_r, w_r and their derivatives are closed-form.
* ``reversing``: v_r(t) = V sin(2 pi t / P_v), w_r(t) = W sin(2 pi t / P_w) with V = 0.4 m/s,
  P_v = 6 s, W = 0.8 rad/s, P_w = 4.3 s; |b w_r| <= 0.18 m/s < V, so both wheels reverse near every zero
  of v_r (twice per 6 s).  phi_r(t) = W P_w / (2 pi) (1 - cos(2 pi t / P_w)) is closed-form; x_r, y_r
  are the integrals of v_r cos phi_r, v_r sin phi_r, integrated in the kernel by RK4 (Simpson's rule,
  since the integrand depends on t only) on the plant's substep grid (error far below 1e-9 m).

Noise (:class:`NoiseSettings`): a ``numpy.random.Generator(PCG64(seed))`` draws, in this order and
always (so each stream depends on the seed and sizes only), standard normals for the velocity noise
(n, 2), the torque noise (n, 2) and the caster innovations (n_ctrl, 2).  The caster disturbance tau_d
is an Ornstein-Uhlenbeck process per wheel, sampled exactly on the control grid
(d_{k+1} = a d_k + sigma sqrt(1 - a^2) z_{k+1}, a = exp(-T / caster_time), d_0 = sigma z_0, so it is
stationary from t = 0) and held over each control period; it enters the plant only.

Plant change (:class:`PlantChange`, optional): the plant's parameters switch once during the run, from
``change.before`` (= ``true``) to ``change.after`` -- a payload loaded or dropped, a wheel's friction
multiplied by a factor.  Rule: the switch happens at the start of control period k_s, the first one whose
start time k T is >= the requested time t_c, i.e. k_s = ceil(t_c / T) (t_c / T within 1e-9 of a whole
number counts as that number, so a t_c on the control grid switches exactly there); the plant integrates
[k T, (k + 1) T] with ``before`` for k < k_s and with ``after`` for k >= k_s.  The state (and so every
logged value) at t <= k_s T is bit for bit that of the run without the change; the controller keeps its
NOMINAL parameters throughout, and the random streams are drawn as without a change.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numba
import numpy as np

from wmrid.core.errors import UsageError
from wmrid.model import dynamics as model
from wmrid.model.robot import Payload, PhysicalParameters

if TYPE_CHECKING:
    import pandas

#: Control period used whenever the log rate is at most 1 kHz (the paper's sampling time), s.
CONTROL_PERIOD = 1e-3

#: Names of the built-in reference trajectories.
TRAJECTORIES = ("sinusoid", "reversing")

#: Parameters of each trajectory (SI units); see the module docstring for the formulas.
TRAJECTORY_PARAMETERS: dict[str, dict[str, float]] = {
    "sinusoid": {"A": 0.5, "wavelength": 3.0, "v0": 0.5, "dv": 0.3, "speed_period": 7.0},
    "reversing": {"V": 0.4, "v_period": 6.0, "W": 0.8, "w_period": 4.3},
}

#: Controller gains: k1 (1/s), k2 (1/m^2), k3 (1/m) kinematic; K (1/s) wheel-speed loop.
GAINS: dict[str, float] = {"k1": 3.0, "k2": 25.0, "k3": 10.0, "K": 50.0}

_KIND = {"sinusoid": 0, "reversing": 1}

#: Kinds of :class:`PlantChange` (``settings["change"]["kind"]``).
CHANGE_KINDS = ("payload-load", "payload-drop", "friction-fault", "custom")

#: Wheel name -> index of its friction parameters (F_v1, F_d1: right; F_v2, F_d2: left).
WHEELS = {"right": 1, "left": 2}

#: Which friction terms a friction fault multiplies.
FRICTION_TERMS = {"both": ("F_v", "F_d"), "viscous": ("F_v",), "coulomb": ("F_d",)}

#: Keys of ``settings["change"]`` that a change's ``detail`` may not use.
_CHANGE_KEYS = ("kind", "t", "t_switch", "switch_period", "before", "after", "physical_before", "physical_after")


@dataclass(frozen=True)
class NoiseSettings:
    """Measurement noise, encoder quantisation and the unmodelled caster disturbance.

    eta_std : rad/s, std of white Gaussian noise added to the logged wheel velocities.
    tau_std : N m, std of white Gaussian noise added to the logged torques.
    caster_std : N m, stationary std of the coloured disturbance torque tau_d on each wheel (the paper's
        ball caster): an Ornstein-Uhlenbeck process per wheel, exactly discretised on the control grid.
    caster_time : s, correlation time of that process.
    encoder_cpr : counts per wheel revolution; when > 0 the logged velocity is the finite difference of
        the quantised wheel angle over one log period (then eta_std, if any, is added on top); 0: off.
    """

    eta_std: float = 0.0
    tau_std: float = 0.0
    caster_std: float = 0.0
    caster_time: float = 0.3
    encoder_cpr: int = 0

    def __post_init__(self) -> None:
        for name in ("eta_std", "tau_std", "caster_std", "caster_time"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise UsageError(f"noise {name} must be a finite number, got {value!r}")
            if value < 0:
                raise UsageError(f"noise {name} must be >= 0, got {value}")
            object.__setattr__(self, name, float(value))
        if self.caster_time <= 0:
            raise UsageError(f"noise caster_time must be > 0 s, got {self.caster_time}")
        cpr = self.encoder_cpr
        if isinstance(cpr, bool) or not isinstance(cpr, (int, np.integer)) or cpr < 0:
            raise UsageError(f"noise encoder_cpr must be a whole number >= 0, got {cpr!r}")
        object.__setattr__(self, "encoder_cpr", int(cpr))

    def to_dict(self) -> dict[str, float | int]:
        return dataclasses.asdict(self)


def _time(name: str, value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise UsageError(f"{name} must be a number of seconds, got {value!r}")
    value = float(value)
    if not math.isfinite(value) or value <= 0:
        raise UsageError(f"{name} must be a finite time > 0 s, got {value}")
    return value


@dataclass(frozen=True, eq=False)
class PlantChange:
    """One change of the plant during a run: ``before`` until time t (s), ``after`` from then on.

    The switch happens at the first control period starting at or after t (see the module docstring and
    :meth:`switch_period`).  kind : one of :data:`CHANGE_KINDS`; detail : a JSON-serialisable description
    (the payload, or the wheel and factor of a friction fault), copied into ``settings["change"]``.
    Build one with :meth:`payload_load`, :meth:`payload_drop` or :meth:`friction_fault`, or directly
    (kind ``custom``).
    """

    t: float
    before: PhysicalParameters
    after: PhysicalParameters
    kind: str = "custom"
    detail: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "t", _time("change time", self.t))
        if not isinstance(self.before, PhysicalParameters) or not isinstance(self.after, PhysicalParameters):
            raise UsageError("a plant change needs PhysicalParameters before and after")
        if self.kind not in CHANGE_KINDS:
            raise UsageError(f"unknown plant change kind {self.kind!r}; choose one of {', '.join(CHANGE_KINDS)}")
        if not isinstance(self.detail, dict) or set(self.detail) & set(_CHANGE_KEYS):
            raise UsageError(f"plant change detail must be a dict without the keys {', '.join(_CHANGE_KEYS)}")
        if self.before == self.after:
            raise UsageError("the plant change changes nothing: before and after are the same parameters")

    @classmethod
    def payload_load(cls, t: float, robot: PhysicalParameters, payload: Payload) -> PlantChange:
        """``robot`` until t, then ``robot`` carrying ``payload``."""
        if not isinstance(payload, Payload):
            raise UsageError(f"payload must be a Payload, got {type(payload).__name__}")
        return cls(t, robot, robot.with_payload(payload), "payload-load", {"payload": dataclasses.asdict(payload)})

    @classmethod
    def payload_drop(cls, t: float, robot: PhysicalParameters, payload: Payload) -> PlantChange:
        """``robot`` carrying ``payload`` until t, then ``robot`` alone."""
        if not isinstance(payload, Payload):
            raise UsageError(f"payload must be a Payload, got {type(payload).__name__}")
        return cls(t, robot.with_payload(payload), robot, "payload-drop", {"payload": dataclasses.asdict(payload)})

    @classmethod
    def friction_fault(
        cls, t: float, robot: PhysicalParameters, wheel: str, factor: float, terms: str = "both"
    ) -> PlantChange:
        """``robot`` until t, then with one wheel's friction multiplied by ``factor`` (>= 0, != 1).

        wheel : ``right`` (F_v1, F_d1) or ``left`` (F_v2, F_d2); terms : ``both``, ``viscous`` (F_v only)
        or ``coulomb`` (F_d only).
        """
        if wheel not in WHEELS:
            raise UsageError(f"friction fault: unknown wheel {wheel!r}; choose one of {', '.join(WHEELS)}")
        if terms not in FRICTION_TERMS:
            raise UsageError(f"friction fault: unknown terms {terms!r}; choose one of {', '.join(FRICTION_TERMS)}")
        if isinstance(factor, bool) or not isinstance(factor, (int, float, np.integer, np.floating)):
            raise UsageError(f"friction fault factor must be a number, got {factor!r}")
        factor = float(factor)
        if not math.isfinite(factor) or factor < 0 or factor == 1:
            raise UsageError(f"friction fault factor must be a finite number >= 0 other than 1, got {factor}")
        names = [f"{term}{WHEELS[wheel]}" for term in FRICTION_TERMS[terms]]
        if all(getattr(robot, name) == 0 for name in names):
            raise UsageError(
                f"friction fault: {' and '.join(names)} of the {wheel} wheel are 0 in the plant, so a factor changes "
                "nothing"
            )
        after = robot.replace(**{name: getattr(robot, name) * factor for name in names})
        detail = {"wheel": wheel, "factor": factor, "terms": terms, "parameters": names}
        return cls(t, robot, after, "friction-fault", detail)

    def switch_period(self, period: float) -> int:
        """k_s: the first control period whose start k_s T is >= t, i.e. ceil(t / T), with t / T within 1e-9
        (relative) of a whole number taken as that number."""
        ratio = self.t / period
        near = round(ratio)
        if abs(ratio - near) <= 1e-9 * max(1.0, ratio):
            return int(near)
        return math.ceil(ratio)

    def to_dict(self, period: float) -> dict:
        """The change as recorded in ``settings["change"]`` for control period T = ``period`` (s)."""
        k = self.switch_period(period)
        return {
            "kind": self.kind,
            "t": self.t,
            "t_switch": k * period,
            "switch_period": k,
            "before": model.named_base(model.base_parameters(self.before)),
            "after": model.named_base(model.base_parameters(self.after)),
            "physical_before": self.before.to_dict(),
            "physical_after": self.after.to_dict(),
            **self.detail,
        }

    @classmethod
    def from_dict(cls, data: dict) -> PlantChange:
        """The change back from ``settings["change"]`` (to reproduce a run)."""
        detail = {key: value for key, value in data.items() if key not in _CHANGE_KEYS}
        return cls(
            data["t"], PhysicalParameters(**data["physical_before"]), PhysicalParameters(**data["physical_after"]),
            data["kind"], detail,
        )  # fmt: skip


@dataclass(frozen=True, eq=False)
class SimulatedLog:
    """A simulated log (read-only arrays) with the truth it was generated from.

    t : (n,) s, starting at 0, spacing 1/rate.
    eta : (n, 2) rad/s, logged wheel velocities [right, left] (with noise / quantisation).
    tau : (n, 2) N m, logged torques: the torque applied over the control period starting at t (with noise).
    pose : (n, 3) true x (m), y (m), phi (rad, unwrapped) of the axle midpoint.
    wheel_angle : (n, 2) rad, true wheel angles theta [right, left], 0 at t = 0.
    true, nominal : the plant's parameters (at t = 0, before any change) and the controller's.
    settings : everything needed to reproduce the run (JSON-serialisable); with a plant change, its
        ``"change"`` entry holds kind, requested time t, actual switch time t_switch (s) and control period
        switch_period, the base parameters ``before`` and ``after`` (as ``truth()["parameters"]``), the
        physical sets ``physical_before`` and ``physical_after``, and the change's detail (payload, or
        wheel, factor, terms, parameters).
    reference : (n, 3) reference pose x_r (m), y_r (m), phi_r (rad) at t.
    eta_ref : (n, 2) rad/s, the reference's wheel speeds [right, left] at t: (v_r +/- b w_r) / r with the
        NOMINAL r, b -- the wheel-speed set-points a planner would send (uncorrelated with the disturbance),
        logged as eta_ref_r, eta_ref_l (the instruments of ``identify --method iv``, :mod:`wmrid.estimators.iv`).
    disturbance : (n, 2) N m, caster torque tau_d applied over the control period starting at t (unlogged
        in a real log; kept for tests and diagnostics).
    eta_true : (n, 2) rad/s, true wheel velocities at t (the clean counterpart of ``eta``).
    change : the plant change of the run, or None.
    """

    t: np.ndarray
    eta: np.ndarray
    tau: np.ndarray
    pose: np.ndarray
    wheel_angle: np.ndarray
    true: PhysicalParameters
    nominal: PhysicalParameters
    settings: dict
    reference: np.ndarray = field(repr=False, default=None)  # type: ignore[assignment]
    disturbance: np.ndarray = field(repr=False, default=None)  # type: ignore[assignment]
    eta_true: np.ndarray = field(repr=False, default=None)  # type: ignore[assignment]
    change: PlantChange | None = field(repr=False, default=None)
    eta_ref: np.ndarray = field(repr=False, default=None)  # type: ignore[assignment]

    def plant_at(self, t: float) -> PhysicalParameters:
        """The plant's parameters over the control period starting at t (s): ``true`` before the switch time,
        the change's ``after`` from it on."""
        if self.change is None:
            return self.true
        t_switch = self.settings["change"]["t_switch"]
        return self.change.after if t >= t_switch - 1e-9 * self.settings["control_period"] else self.true

    def to_frame(self) -> pandas.DataFrame:
        """Columns t, eta_r, eta_l, tau_r, tau_l, x, y, phi, theta_r, theta_l, eta_ref_r, eta_ref_l (SI units;
        r = right; the last two: the reference's wheel speeds, :attr:`eta_ref`)."""
        import pandas as pd

        return pd.DataFrame(
            {
                "t": self.t,
                "eta_r": self.eta[:, 0],
                "eta_l": self.eta[:, 1],
                "tau_r": self.tau[:, 0],
                "tau_l": self.tau[:, 1],
                "x": self.pose[:, 0],
                "y": self.pose[:, 1],
                "phi": self.pose[:, 2],
                "theta_r": self.wheel_angle[:, 0],
                "theta_l": self.wheel_angle[:, 1],
                "eta_ref_r": self.eta_ref[:, 0],
                "eta_ref_l": self.eta_ref[:, 1],
            }
        )

    def truth(self) -> dict:
        """The true base parameters (m11, m12, m22, Vc, Fv1, Fv2, Fd1, Fd2, M11, M12, M22), inputs, settings."""
        return {
            "parameters": model.named_base(model.base_parameters(self.true)),
            "physical": self.true.to_dict(),
            "nominal_physical": self.nominal.to_dict(),
            "settings": self.settings,
        }


# --------------------------------------------------------------------------------------------------
# Compiled kernel.  Parameter vectors (float64):
#   traj   sinusoid: [A, wavelength, v0, dv, speed_period]; reversing: [V, v_period, W, w_period]
#   plant  [m11, m12, m22, Vc, Fv1, Fv2, Fd1, Fd2, r, b]   (m = M^-1 of the TRUE robot; plant_after alike)
#   ctrl   [M11, M12, M22, Vc, Fv1, Fv2, Fd1, Fd2, r, b]   (NOMINAL robot, M itself)
#   gains  [k1, k2, k3, K]
# State s (7,): x, y, phi, theta_1, theta_2, eta_1, eta_2.


@numba.njit(cache=True, nogil=True)
def _sgn(x):
    if x > 0.0:
        return 1.0
    if x < 0.0:
        return -1.0
    return 0.0


@numba.njit(cache=True, nogil=True)
def _reference(kind, traj, t, xr_int, yr_int):
    """Reference at time t: (x_r m, y_r m, phi_r rad, v_r m/s, w_r rad/s, v_r' m/s^2, w_r' rad/s^2).

    For ``reversing`` x_r, y_r are the kernel's integrated values, passed in as xr_int, yr_int.
    """
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


@numba.njit(cache=True, nogil=True)
def reference_wheel_speeds(kind, traj, t, r, b):
    """(n, 2) rad/s: the reference's wheel speeds [(v_r + b w_r) / r, (v_r - b w_r) / r] at times t (n,) s."""
    out = np.empty((t.shape[0], 2))
    for i in range(t.shape[0]):
        ref = _reference(kind, traj, t[i], 0.0, 0.0)
        out[i, 0] = (ref[3] + b * ref[4]) / r
        out[i, 1] = (ref[3] - b * ref[4]) / r
    return out


@numba.njit(cache=True, nogil=True)
def _reversing_velocity(traj, t):
    """(x_r', y_r') m/s of the reversing reference at time t."""
    vamp, vper, wamp, wper = traj[0], traj[1], traj[2], traj[3]
    ow = 2.0 * math.pi / wper
    v = vamp * math.sin(2.0 * math.pi / vper * t)
    phi = wamp / ow * (1.0 - math.cos(ow * t))
    return v * math.cos(phi), v * math.sin(phi)


@numba.njit(cache=True, nogil=True)
def reversing_advance(traj, t, h):
    """(dx_r, dy_r) m: the reversing reference's advance from t to t + h s, by Simpson's rule (RK4 on x_r' = f(t))."""
    fa = _reversing_velocity(traj, t)
    fm = _reversing_velocity(traj, t + 0.5 * h)
    fb = _reversing_velocity(traj, t + h)
    return h / 6.0 * (fa[0] + 4.0 * fm[0] + fb[0]), h / 6.0 * (fa[1] + 4.0 * fm[1] + fb[1])


@numba.njit(cache=True, nogil=True)
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
    f1 = tau1 - d1 - vc * (e1 * e2 - e2 * e2) - fv1 * e1 - fd1 * _sgn(e1)
    f2 = tau2 - d2 - vc * (e1 * e2 - e1 * e1) - fv2 * e2 - fd2 * _sgn(e2)
    out[5] = m11 * f1 + m12 * f2
    out[6] = m12 * f1 + m22 * f2


@numba.njit(cache=True, nogil=True)
def _control(s, ref, ctrl, gains):
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
    err3 -= 2.0 * math.pi * math.floor((err3 + math.pi) / (2.0 * math.pi))  # wrap to [-pi, pi)
    v = 0.5 * r * (eta1 + eta2)
    w = r / (2.0 * b) * (eta1 - eta2)
    c3, s3 = math.cos(err3), math.sin(err3)
    err1d = w * err2 - v + vr * c3
    err2d = -w * err1 + vr * s3
    err3d = wr - w
    avr = abs(vr)
    avrd = vrd * _sgn(vr)
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
    tau1 = big11 * a1 + big12 * a2 + vc * (eta1 * eta2 - eta2 * eta2) + fv1 * eta1 + fd1 * _sgn(eta1)
    tau2 = big12 * a1 + big22 * a2 + vc * (eta1 * eta2 - eta1 * eta1) + fv2 * eta2 + fd2 * _sgn(eta2)
    return tau1, tau2


@numba.njit(cache=True, nogil=True)
def closed_loop_kernel(kind, traj, plant, ctrl, gains, period, substeps, n_log, every, caster_z, caster_std,
                       caster_time, plant_after=None, switch=-1):  # fmt: skip
    """Run the closed loop; all arguments plain scalars / float64 arrays.

    kind 0 sinusoid / 1 reversing; traj, plant (10,), ctrl (10,), gains (4,) as documented above;
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
    ref0 = _reference(kind, traj, 0.0, xr_int, yr_int)
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
        ref = _reference(kind, traj, t, xr_int, yr_int)
        tau1, tau2 = _control(s, ref, ctrl, gains)
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


# --------------------------------------------------------------------------------------------------


def _positive_number(name: str, value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise UsageError(f"{name} must be a number, got {value!r}")
    value = float(value)
    if not math.isfinite(value) or value <= 0:
        raise UsageError(f"{name} must be a finite number > 0, got {value}")
    return value


def timing(rate: float) -> tuple[float, int]:
    """(control period T in s, control periods per log period N) for a log rate in Hz.

    T = 1 ms (the paper's sampling time) for rate <= 1 kHz, else 1/rate.  Raises UsageError unless
    N = (1/rate)/T is a whole number.
    """
    rate = _positive_number("rate", rate)
    if rate > 1.0 / CONTROL_PERIOD:
        return 1.0 / rate, 1
    ratio = (1.0 / rate) / CONTROL_PERIOD
    every = round(ratio)
    if every < 1 or abs(ratio - every) > 1e-9 * ratio:
        raise UsageError(
            f"rate {rate:g} Hz: the log period 1/rate must be a whole number of {CONTROL_PERIOD * 1e3:g} ms "
            f"control periods (e.g. 1000, 500, 250, 200, 100 Hz), or the rate must exceed 1000 Hz"
        )
    return CONTROL_PERIOD, int(every)


def parse_time(text: str, option: str) -> float:
    """A time in seconds (> 0, finite) from an option's text; UsageError naming ``option`` otherwise."""
    try:
        value = float(text)
    except ValueError:
        raise UsageError(f"{option} {text!r}: expected a time in seconds, e.g. 30") from None
    if not math.isfinite(value) or value <= 0:
        raise UsageError(f"{option} {text!r}: the time must be a finite number of seconds > 0")
    return value


def parse_friction_fault(text: str) -> tuple[str, float, str]:
    """(wheel, factor, terms) from ``WHEEL:FACTOR[:TERMS]``, e.g. ``right:3`` or ``left:0.5:coulomb``.

    WHEEL is right or left, FACTOR a number, TERMS one of :data:`FRICTION_TERMS` (default both); the
    factor's range is checked by :meth:`PlantChange.friction_fault`.
    """
    parts = [part.strip() for part in text.split(":")]
    usage = (
        f"--friction-fault {text!r}: expected WHEEL:FACTOR[:TERMS] with WHEEL right or left and TERMS both, "
        "viscous or coulomb, e.g. right:3"
    )
    if len(parts) not in (2, 3) or parts[0].lower() not in WHEELS:
        raise UsageError(usage)
    terms = parts[2].lower() if len(parts) == 3 else "both"
    if terms not in FRICTION_TERMS:
        raise UsageError(usage)
    try:
        factor = float(parts[1])
    except ValueError:
        raise UsageError(usage) from None
    return parts[0].lower(), factor, terms


def _plant_vector(p: PhysicalParameters) -> np.ndarray:
    """The kernel's plant vector [m11, m12, m22, Vc, Fv1, Fv2, Fd1, Fd2, r, b] of parameters p."""
    theta = model.base_parameters(p)
    m = model.inverse_inertia(theta)
    return np.array([m[0, 0], m[0, 1], m[1, 1], *theta[3:8], p.r, p.b])


def _encoder_velocity(theta: np.ndarray, eta: np.ndarray, cpr: int, dt: float) -> np.ndarray:
    """Velocity (n, 2) rad/s an encoder driver reports: difference of quantised angles over one log period.

    theta (n, 2) rad, eta (n, 2) rad/s true; the count is floor(theta / (2 pi / cpr)).  Before t = 0
    the wheel is taken to turn at its initial speed, so theta(-dt) = theta(0) - dt eta(0).
    """
    step = 2.0 * math.pi / cpr
    counts = np.floor(theta / step)
    before = np.floor((theta[0] - dt * eta[0]) / step)
    diff = np.diff(counts, axis=0, prepend=before[None, :])
    return diff * (step / dt)


def simulate(
    true: PhysicalParameters,
    nominal: PhysicalParameters,
    *,
    trajectory: str = "sinusoid",
    duration: float = 40.0,
    rate: float = 1000.0,
    noise: NoiseSettings = NoiseSettings(),
    seed: int = 0,
    substeps: int = 4,
    change: PlantChange | None = None,
) -> SimulatedLog:
    """Simulate the closed loop and return its log.

    true : plant parameters (at t = 0); nominal : what the controller believes.
    trajectory : one of :data:`TRAJECTORIES`.  duration : s (> 0); the log has n = floor(duration * rate) + 1
    samples at t = 0, 1/rate, ...  rate : log rate in Hz (see :func:`timing`).  noise : see
    :class:`NoiseSettings`.  seed : non-negative int for ``numpy.random.PCG64``; same seed, same output
    bit for bit.  substeps : RK4 steps per control period (>= 1).  change : a :class:`PlantChange` whose
    ``before`` is ``true``, switching the plant to ``change.after`` at the first control period starting
    at or after ``change.t``, which must come before the last sample; None (default): no change, and the
    output is exactly that of a simulator without this option.
    """
    if not isinstance(true, PhysicalParameters):
        raise UsageError("true and nominal must be PhysicalParameters")
    if isinstance(substeps, bool) or not isinstance(substeps, (int, np.integer)) or substeps < 1:
        raise UsageError(f"substeps must be a whole number >= 1, got {substeps!r}")
    run = plan_run(nominal, trajectory=trajectory, duration=duration, rate=rate, noise=noise, seed=seed)
    period, every, n, n_ctrl = run.period, run.every, run.n, run.n_ctrl
    switch = -1
    if change is not None:
        if not isinstance(change, PlantChange):
            raise UsageError(f"change must be a PlantChange, got {type(change).__name__}")
        if change.before != true:
            raise UsageError("change.before must be the plant's parameters at t = 0 (the argument true)")
        switch = change.switch_period(period)
        if switch < 1 or switch >= n_ctrl - 1:
            raise UsageError(
                f"change time {change.t:g} s: the plant would switch at {switch * period:g} s (the first control "
                f"period starting at or after it), which must come after 0 and before the last sample at "
                f"{(n_ctrl - 1) * period:g} s"
            )
    plant = _plant_vector(true)
    traj, ctrl, gains, caster_z = run.traj, run.ctrl, run.gains, run.caster_z

    args = (_KIND[trajectory], traj, plant, ctrl, gains, period, int(substeps), n, every, caster_z,
            noise.caster_std, noise.caster_time)  # fmt: skip
    if change is None:
        pose, angle, eta_true, tau_applied, refpose, dist = closed_loop_kernel(*args)
    else:
        pose, angle, eta_true, tau_applied, refpose, dist = closed_loop_kernel(
            *args, _plant_vector(change.after), switch
        )

    settings = {"substeps": int(substeps)}
    return run.log(true, pose, angle, eta_true, tau_applied, refpose, dist, settings, change)


@dataclass(frozen=True, eq=False)
class RunPlan:
    """What every closed-loop simulator of wmrid shares: the checked run settings, the random streams and the
    controller's vectors (see :func:`plan_run`), and the assembly of the log (:meth:`log`).

    period : control period T, s; every : control periods per log period; n : log samples; n_ctrl : control
    periods; eta_z, tau_z (n, 2) and caster_z (n_ctrl, 2): standard normals, drawn in that order from
    PCG64(seed); traj, ctrl (10,), gains (4,): the kernel's reference, NOMINAL controller and gain vectors.
    """

    nominal: PhysicalParameters
    trajectory: str
    duration: float
    rate: float
    noise: NoiseSettings
    seed: int
    period: float
    every: int
    n: int
    n_ctrl: int
    eta_z: np.ndarray
    tau_z: np.ndarray
    caster_z: np.ndarray
    traj: np.ndarray
    ctrl: np.ndarray
    gains: np.ndarray

    def log(
        self, true: PhysicalParameters, pose: np.ndarray, angle: np.ndarray, eta_true: np.ndarray,
        tau_applied: np.ndarray, refpose: np.ndarray, dist: np.ndarray, extra: dict, change: PlantChange | None,
    ) -> SimulatedLog:  # fmt: skip
        """The SimulatedLog of a run: encoder quantisation and noise on the logged speeds and torques, the
        settings (``extra`` merged in), read-only arrays."""
        noise = self.noise
        dt = self.every * self.period
        cpr = noise.encoder_cpr
        eta_meas = _encoder_velocity(angle, eta_true, cpr, dt) if cpr > 0 else eta_true.copy()
        eta_log = eta_meas + noise.eta_std * self.eta_z
        tau_log = tau_applied + noise.tau_std * self.tau_z
        t = np.arange(self.n) * dt
        settings = {
            "trajectory": self.trajectory,
            "trajectory_parameters": dict(TRAJECTORY_PARAMETERS[self.trajectory]),
            "duration": self.duration,
            "rate": self.rate,
            "control_period": self.period,
            "substeps": None,
            "n_samples": self.n,
            "seed": self.seed,
            "generator": "numpy PCG64",
            "noise": noise.to_dict(),
            "gains": dict(GAINS),
            **extra,
        }
        if change is not None:
            settings["change"] = change.to_dict(self.period)
        eta_ref = reference_wheel_speeds(_KIND[self.trajectory], self.traj, t, self.nominal.r, self.nominal.b)
        for a in (t, eta_log, tau_log, pose, angle, refpose, dist, eta_true, eta_ref):
            a.setflags(write=False)
        return SimulatedLog(
            t=t, eta=eta_log, tau=tau_log, pose=pose, wheel_angle=angle, true=true, nominal=self.nominal,
            settings=settings, reference=refpose, disturbance=dist, eta_true=eta_true, change=change, eta_ref=eta_ref,
        )  # fmt: skip


#: Bytes a simulated run holds per logged sample (the log's 12 columns, the noise draws, the controller's state and
#: the writer's copies; measured for `simulate --duration 600`: 820 B written as CSV, 600 B as Parquet) and per
#: control step (the caster draws).
BYTES_PER_SAMPLE = 900
BYTES_PER_CONTROL_STEP = 32


def check_run_memory(n: int, n_ctrl: int, duration: float, rate: float) -> None:
    """UsageError before anything is allocated when a run of n samples (n_ctrl control steps) would need more than
    the memory budget (:mod:`wmrid.core.limits`): ``simulate --duration 1e9`` used to die of "Unable to allocate 14.6
    TiB"."""
    from wmrid.core.limits import ENV, describe, memory_budget

    need = n * BYTES_PER_SAMPLE + n_ctrl * BYTES_PER_CONTROL_STEP
    budget = memory_budget()
    if need > budget:
        longest = budget / (BYTES_PER_SAMPLE + BYTES_PER_CONTROL_STEP * n_ctrl / max(n, 1)) / rate
        raise UsageError(
            f"--duration {duration:g} s at {rate:g} Hz is {n:,} samples, about {describe(need)} of memory, beyond the "
            f"budget of {describe(budget)} ({ENV}); simulate at most {longest:,.0f} s at this rate, in several runs"
        )


def plan_run(
    nominal: PhysicalParameters, *, trajectory: str, duration: float, rate: float, noise: NoiseSettings, seed: int
) -> RunPlan:
    """Check a run's settings (UsageError naming the bad one) and draw its random streams; see :class:`RunPlan`."""
    if trajectory not in TRAJECTORIES:
        raise UsageError(f"unknown trajectory {trajectory!r}; choose one of {', '.join(TRAJECTORIES)}")
    if not isinstance(nominal, PhysicalParameters):
        raise UsageError("true and nominal must be PhysicalParameters")
    if not isinstance(noise, NoiseSettings):
        raise UsageError(f"noise must be a NoiseSettings, got {type(noise).__name__}")
    duration = _positive_number("duration", duration)
    period, every = timing(rate)
    rate = float(rate)
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise UsageError(f"seed must be a whole number >= 0, got {seed!r}")
    n = math.floor(duration * rate + 1e-9) + 1
    if n < 2:
        raise UsageError(f"duration {duration:g} s at {rate:g} Hz gives fewer than 2 samples")
    n_ctrl = (n - 1) * every + 1
    check_run_memory(n, n_ctrl, duration, rate)
    rng = np.random.Generator(np.random.PCG64(int(seed)))
    eta_z = rng.standard_normal((n, 2))
    tau_z = rng.standard_normal((n, 2))
    caster_z = rng.standard_normal((n_ctrl, 2))
    traj = np.array(list(TRAJECTORY_PARAMETERS[trajectory].values()), dtype=np.float64)
    big_nom = model.inertia_matrix(nominal)
    ctrl = np.array(
        [big_nom[0, 0], big_nom[0, 1], big_nom[1, 1], model.coriolis_coefficient(nominal),
         nominal.F_v1, nominal.F_v2, nominal.F_d1, nominal.F_d2, nominal.r, nominal.b]
    )  # fmt: skip
    gains = np.array([GAINS["k1"], GAINS["k2"], GAINS["k3"], GAINS["K"]])
    return RunPlan(
        nominal=nominal, trajectory=trajectory, duration=duration, rate=rate, noise=noise, seed=int(seed),
        period=period, every=every, n=n, n_ctrl=n_ctrl, eta_z=eta_z, tau_z=tau_z, caster_z=caster_z, traj=traj,
        ctrl=ctrl, gains=gains,
    )  # fmt: skip
