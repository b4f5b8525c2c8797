"""Physical description of a differential-drive robot (the paper's Table 1 plus friction).

A robot file is TOML::

    name = "my-robot"
    [nominal]          # required: what the designer believes; starts the estimator
    I_p = 4.0          # kg m^2  platform inertia about its centre of mass O_p
    ...
    [cad]              # optional: the CAD ("Solidworks") values, taken as the reference truth
    ...
    [motor]            # optional: to turn a logged motor current into a wheel torque
    torque_constant = 0.0105   # N m/A (k_t); the gear ratio is k_r of [nominal]
    efficiency = 0.9           # of the gearbox, in (0, 1]

All values are SI: kg, m, kg m^2, N m s/rad (viscous), N m (Coulomb). Every key of
:data:`PARAMETER_UNITS` must be present in each set.

Table 1 of the paper prints ``d_x`` in "cm", but its values (0.15, 0.1781) only make sense in metres:
with d_x = 0.15 m, Eq. (13)'s V_c and the paper's Table 2 nominal column agree to every printed
digit (theta_13 = m11 V_c = 0.147); with 0.15 cm they would be 100 times smaller. wmrid therefore
reads d_x in metres, like every other length (``tests/unit/model/test_model.py`` checks this).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

from wmrid.core.errors import RobotFileError, UsageError, option

#: Parameter name -> (unit, meaning).  Order is the order used in files and reports.
PARAMETER_UNITS: dict[str, tuple[str, str]] = {
    "I_p": ("kg m^2", "platform (without wheels and rotors) inertia about its centre of mass O_p"),
    "m_p": ("kg", "platform mass (without wheels and rotors)"),
    "d_x": ("m", "x of O_p in the platform frame (forward from the axle midpoint O)"),
    "d_y": ("m", "y of O_p in the platform frame (towards the left wheel)"),
    "I_wm": ("kg m^2", "wheel inertia about its diameter"),
    "I_w": ("kg m^2", "wheel inertia about its axle"),
    "m_w": ("kg", "mass of each wheel"),
    "a": ("m", "distance from O to each wheel's centre of mass"),
    "m_r": ("kg", "mass of each motor rotor"),
    "I_rm": ("kg m^2", "rotor inertia about its diameter"),
    "I_r": ("kg m^2", "rotor inertia about its axle"),
    "c_x": ("m", "x of the rotors' centres of mass"),
    "c_y": ("m", "|y| of the rotors' centres of mass"),
    "k_r": ("1", "gear reduction ratio (rotor speed / wheel speed)"),
    "r": ("m", "wheel radius"),
    "b": ("m", "half track: distance from O to each wheel's ground contact"),
    "F_v1": ("N m s/rad", "viscous friction of the right wheel (eta_1)"),
    "F_v2": ("N m s/rad", "viscous friction of the left wheel (eta_2)"),
    "F_d1": ("N m", "Coulomb (dynamic) friction of the right wheel"),
    "F_d2": ("N m", "Coulomb (dynamic) friction of the left wheel"),
}

_POSITIVE = ("m_p", "m_w", "r", "b", "k_r")
_NON_NEGATIVE = ("I_p", "I_wm", "I_w", "m_r", "I_rm", "I_r", "F_v1", "F_v2", "F_d1", "F_d2")


@dataclass(frozen=True)
class PhysicalParameters:
    """One column of Table 1 plus friction, SI units (see :data:`PARAMETER_UNITS`)."""

    I_p: float
    m_p: float
    d_x: float
    d_y: float
    I_wm: float
    I_w: float
    m_w: float
    a: float
    m_r: float
    I_rm: float
    I_r: float
    c_x: float
    c_y: float
    k_r: float
    r: float
    b: float
    F_v1: float = 0.0
    F_v2: float = 0.0
    F_d1: float = 0.0
    F_d2: float = 0.0

    def __post_init__(self) -> None:
        for name in PARAMETER_UNITS:
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(value):
                raise RobotFileError(f"robot parameter {name} must be a finite number, got {value!r}")
            object.__setattr__(self, name, float(value))
        for name in _POSITIVE:
            if getattr(self, name) <= 0:
                raise RobotFileError(f"robot parameter {name} must be > 0, got {getattr(self, name)}")
        for name in _NON_NEGATIVE:
            if getattr(self, name) < 0:
                raise RobotFileError(f"robot parameter {name} must be >= 0, got {getattr(self, name)}")

    def to_dict(self) -> dict[str, float]:
        return dataclasses.asdict(self)

    def replace(self, **changes: float) -> PhysicalParameters:
        return dataclasses.replace(self, **changes)

    def with_payload(self, payload: Payload) -> PhysicalParameters:
        """The platform carrying a rigid payload (parallel-axis theorem).

        The payload of mass m_L at (x, y) in the platform frame, with inertia I_L about its own
        centre of mass, merges with the platform: m_p' = m_p + m_L,
        d' = (m_p d + m_L p) / m_p',
        I_p' = I_p + m_p |d - d'|^2 + I_L + m_L |p - d'|^2.
        """
        m0, m_l = self.m_p, payload.mass
        m1 = m0 + m_l
        dx1 = (m0 * self.d_x + m_l * payload.x) / m1
        dy1 = (m0 * self.d_y + m_l * payload.y) / m1
        ip1 = (
            self.I_p
            + m0 * ((self.d_x - dx1) ** 2 + (self.d_y - dy1) ** 2)
            + payload.inertia
            + m_l * ((payload.x - dx1) ** 2 + (payload.y - dy1) ** 2)
        )
        return self.replace(m_p=m1, d_x=dx1, d_y=dy1, I_p=ip1)


@dataclass(frozen=True)
class Payload:
    """A rigid payload on the platform.

    Attributes
    ----------
    mass
        kg, > 0.
    x
        m, the position of its centre of mass in the platform frame.
    y
        m, the position of its centre of mass in the platform frame.
    inertia
        kg m^2, its own yaw inertia (about its centre of mass), >= 0.
    """

    mass: float
    x: float = 0.0
    y: float = 0.0
    inertia: float = 0.0

    def __post_init__(self) -> None:
        for name in ("mass", "x", "y"):
            if not math.isfinite(getattr(self, name)):
                raise UsageError(f"payload {name} must be finite")
        if self.mass <= 0:
            raise UsageError(f"payload mass must be > 0 kg, got {self.mass}")
        if not (math.isfinite(self.inertia) and self.inertia >= 0):  # simulate's payload_inertia
            raise UsageError(f"{option('payload_inertia')} must be a finite number >= 0 kg m^2, got {self.inertia}")

    @classmethod
    def parse(cls, text: str, inertia: float = 0.0) -> Payload:
        """Parse the command line's ``MASS[@X,Y]`` (kg, m), e.g. ``25`` or ``25@0.1,-0.05``.

        Parameters
        ----------
        text
            ``MASS[@X,Y]``: the mass in kg, and the position in m (default 0, 0).
        inertia
            kg m^2, the payload's own yaw inertia.

        Returns
        -------
        Payload
            The payload.
        """
        mass_text, at, where = text.partition("@")
        try:
            if at and not where.strip():
                raise ValueError("nothing after @")
            mass = float(mass_text)
            x, y = (float(v) for v in where.split(",")) if where else (0.0, 0.0)
        except ValueError:
            raise UsageError(
                f"{option('payload')} {text!r}: expected MASS[@X,Y] in kg and metres, e.g. 25@0.1,-0.05"
            ) from None
        return cls(mass=mass, x=x, y=y, inertia=inertia)


#: Kinds of caster the multibody prototype builds.
CASTER_KINDS = ("ball", "swivel")
#: Default rolling-resistance coefficient of a caster (force / normal load): polyurethane on a hard floor.
DEFAULT_CASTER_RESISTANCE = 0.015


@dataclass(frozen=True)
class Caster:
    """A passive caster under the platform (only the multibody prototype uses it).

    x, y : m, its ground contact in the platform frame (for a swivel caster: its swivel axis);
    radius : m, of the ball or caster wheel; kind : ``ball`` or ``swivel``;
    resistance : rolling-resistance coefficient, the drag force over the normal load (>= 0);
    trail : m, swivel casters only: how far the wheel's contact trails behind the swivel axis.
    """

    x: float
    y: float = 0.0
    radius: float = 0.025
    kind: str = "ball"
    resistance: float = DEFAULT_CASTER_RESISTANCE
    trail: float = 0.03

    def __post_init__(self) -> None:
        for name in ("x", "y", "radius", "resistance", "trail"):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(value):
                raise RobotFileError(f"caster {name} must be a finite number, got {value!r}")
            object.__setattr__(self, name, float(value))
        if self.kind not in CASTER_KINDS:
            raise RobotFileError(f"caster kind must be one of {', '.join(CASTER_KINDS)}, got {self.kind!r}")
        if self.radius <= 0:
            raise RobotFileError(f"caster radius must be > 0 m, got {self.radius}")
        if self.resistance < 0 or self.trail < 0:
            raise RobotFileError("caster resistance and trail must be >= 0")

    def to_dict(self) -> dict[str, float | str]:
        return dataclasses.asdict(self)


def default_casters(p: PhysicalParameters) -> tuple[Caster, ...]:
    """Two ball casters on the centre line, in front of and behind the axle, at x = +-max(b, 3 |d_x|).

    Far enough out that the centre of mass stays inside the support polygon; radius min(0.025 m, 0.4 r);
    resistance :data:`DEFAULT_CASTER_RESISTANCE`.
    """
    reach = max(p.b, 3.0 * abs(p.d_x))
    radius = min(0.025, 0.4 * p.r)
    return (Caster(x=reach, radius=radius), Caster(x=-reach, radius=radius))


#: The most casters a robot may have (a mobile robot has two to six): each is a body of the multibody prototype and
#: a drag column of ``--friction wheel+caster``; 10,000 of them made MuJoCo fail to allocate its model.
MAX_CASTERS = 16
_TOO_MANY_CASTERS = f"wmrid takes at most {MAX_CASTERS} casters (a mobile robot has two to six)"


@dataclass(frozen=True)
class Robot:
    """A named robot: nominal parameters and, when known, CAD (reference) parameters.

    Made by :func:`wmrid.load_robot` from a built-in name, a robot file or a URDF.

    Attributes
    ----------
    name
        The robot's name.
    nominal
        The nominal parameters: physical ones (Table 1) or base parameters given directly (:class:`BaseSet`).
    cad
        The CAD (reference) parameters, when known.
    torque_constant
        N m/A, of each motor (``[motor]`` table), or None.
    efficiency
        Of the gearbox (``[motor]`` table), or None.
    casters
        The ``[[caster]]`` tables; None: default casters (multibody only).
    unknown_cad
        Base parameters whose CAD value the source does not give (a URDF's friction): compared as "—", not 0.
    assumed
        What the robot file left out and was assumed (sentences, said in every result that uses the robot).
    gear_ratio_known
        False when the file gave no gear ratio (no rotors): a current log then needs ``--gear-ratio``.
    limits
        The ``[limits]`` table (``wmrid plan``): name -> value, SI (max_wheel_speed rad/s, max_wheel_accel
        rad/s^2, max_torque N m, max_speed m/s, max_turn_rate rad/s, area [W, H] m); checked by
        :mod:`wmrid.design.limits`.
    """

    name: str
    nominal: PhysicalParameters | BaseSet
    cad: PhysicalParameters | BaseSet | None = None
    torque_constant: float | None = None  # N m/A, of each motor ([motor] table)
    efficiency: float | None = None  # of the gearbox ([motor] table)
    casters: tuple[Caster, ...] | None = None  # [[caster]] tables; None: default_casters (multibody only)
    #: Base parameters whose CAD value the source does not give (a URDF's friction): compared as "—", not 0.
    unknown_cad: tuple[str, ...] = ()
    #: What the robot file left out and was assumed (sentences, said in every result that uses the robot).
    assumed: tuple[str, ...] = ()
    #: False when the file gave no gear ratio (no rotors): a current log then needs --gear-ratio.
    gear_ratio_known: bool = True
    #: The [limits] table (``wmrid plan``): name -> value, SI (max_wheel_speed rad/s, max_wheel_accel rad/s^2,
    #: max_torque N m, max_speed m/s, max_turn_rate rad/s, area [W, H] m); checked by wmrid.design.limits.
    limits: tuple[tuple[str, object], ...] = ()

    def __post_init__(self) -> None:
        if self.casters is not None and len(self.casters) > MAX_CASTERS:
            raise RobotFileError(f"robot {self.name!r}: {len(self.casters):,} casters; {_TOO_MANY_CASTERS}")

    @property
    def physical(self) -> bool:
        """Whether both parameter sets are physical (Table 1), not base parameters given directly (:class:`BaseSet`):
        what a payload estimate and a simulation need."""
        return not isinstance(self.nominal, BaseSet) and not isinstance(self.cad, BaseSet)

    @property
    def reference(self) -> PhysicalParameters:
        """The best-known parameters: CAD when given, else nominal."""
        return self.cad if self.cad is not None else self.nominal


# The paper's Table 1.  Nominal friction is unknown (0), as in Table 2's nominal column; the CAD
# ("true") column carries the friction the paper's virtual prototype used (Sec. 5).
PAPER_NOMINAL = PhysicalParameters(
    I_p=4.0, m_p=55.0, d_x=0.15, d_y=0.0, I_wm=0.025, I_w=0.05, m_w=4.0, a=0.23,
    m_r=0.05, I_rm=1e-5, I_r=1e-6, c_x=0.05, c_y=0.08, k_r=100.0, r=0.16, b=0.23,
)  # fmt: skip
PAPER_CAD = PhysicalParameters(
    I_p=4.98, m_p=60.90, d_x=0.1781, d_y=0.0119, I_wm=0.03755, I_w=0.0738, m_w=4.98, a=0.2286,
    m_r=0.0442, I_rm=3.74e-5, I_r=1.24e-6, c_x=0.075, c_y=0.107, k_r=100.0, r=0.16, b=0.23,
    F_v1=0.01, F_v2=0.015, F_d1=0.045, F_d2=0.04,
)  # fmt: skip

# A light AMR (about 14 kg, 16 cm wheels, 20:1 gears) and a heavy base (about 170 kg, 30:1), for the
# multibody prototype's benchmark: the nominal sets are round-number guesses 10-20 % off the CAD sets.
AMR_CAD = PhysicalParameters(
    I_p=0.32, m_p=12.0, d_x=-0.04, d_y=0.004, I_wm=0.0009, I_w=0.0016, m_w=0.6, a=0.185,
    m_r=0.12, I_rm=2e-5, I_r=4e-6, c_x=0.03, c_y=0.11, k_r=20.0, r=0.08, b=0.2,
    F_v1=0.004, F_v2=0.005, F_d1=0.02, F_d2=0.025,
)  # fmt: skip
AMR_NOMINAL = PhysicalParameters(
    I_p=0.28, m_p=11.0, d_x=0.0, d_y=0.0, I_wm=0.001, I_w=0.0015, m_w=0.5, a=0.18,
    m_r=0.1, I_rm=2e-5, I_r=5e-6, c_x=0.03, c_y=0.11, k_r=20.0, r=0.08, b=0.2,
)  # fmt: skip
HEAVY_CAD = PhysicalParameters(
    I_p=14.0, m_p=160.0, d_x=0.06, d_y=-0.01, I_wm=0.02, I_w=0.035, m_w=3.5, a=0.3,
    m_r=0.6, I_rm=3e-4, I_r=6e-5, c_x=0.08, c_y=0.18, k_r=30.0, r=0.1, b=0.3,
    F_v1=0.08, F_v2=0.09, F_d1=0.5, F_d2=0.45,
)  # fmt: skip
HEAVY_NOMINAL = PhysicalParameters(
    I_p=12.0, m_p=150.0, d_x=0.05, d_y=0.0, I_wm=0.02, I_w=0.03, m_w=3.0, a=0.3,
    m_r=0.5, I_rm=3e-4, I_r=5e-5, c_x=0.08, c_y=0.18, k_r=30.0, r=0.1, b=0.3,
)  # fmt: skip

BUILTIN_ROBOTS: dict[str, Robot] = {
    "paper": Robot(name="paper", nominal=PAPER_NOMINAL, cad=PAPER_CAD, casters=default_casters(PAPER_CAD)),
    "amr": Robot(name="amr", nominal=AMR_NOMINAL, cad=AMR_CAD, casters=default_casters(AMR_CAD)),
    "heavy": Robot(name="heavy", nominal=HEAVY_NOMINAL, cad=HEAVY_CAD, casters=default_casters(HEAVY_CAD)),
}


@dataclass(frozen=True)
class BaseSet:
    """A robot's base parameters given directly (a ``[nominal_base]`` or ``[cad_base]`` table): theta0 =
    [m11 m12 m22 Vc Fv1 Fv2 Fd1 Fd2] (SI), and the wheel radius r, half track b and gear ratio k_r when known
    (for unit conversions only).  :func:`wmrid.model.dynamics.base_parameters` returns ``theta0``; what needs the
    physical parameters (a payload, a simulation) refuses a robot described this way."""

    theta0: tuple[float, ...]
    r: float | None = None
    b: float | None = None
    k_r: float | None = None

    def to_dict(self) -> dict[str, float]:
        out = dict(zip(BASE_KEYS, self.theta0, strict=True))
        out.update({k: v for k, v in (("r", self.r), ("b", self.b), ("k_r", self.k_r)) if v is not None})
        return out


#: The keys of a base-parameter table: theta0's, in order (M11 M12 M22 may stand for m11 m12 m22).
BASE_KEYS = ("m11", "m12", "m22", "Vc", "Fv1", "Fv2", "Fd1", "Fd2")


#: Those it may leave out: (group of keys, their values from the table, the sentence that says what was assumed).
#: The motor rotors add k_r^2 I_r to the wheels' inertia and m_r, I_rm to the platform's; without a datasheet,
#: none (then k_r is unknown too: a current log needs --gear-ratio).
OPTIONAL: tuple[tuple[tuple[str, ...], Any, str], ...] = (
    (("d_y",), lambda t: (0.0,), "d_y = 0 (the centre of mass on the centre line)"),
    (("I_wm",), lambda t: (t["I_w"] / 2,), "I_wm = I_w / 2 (each wheel a thin disc)"),
    (("a",), lambda t: (t["b"],), "a = b (each wheel's centre of mass at its contact)"),
    (("m_r", "I_rm", "I_r", "c_x", "c_y", "k_r"), lambda t: (0.0, 0.0, 0.0, 0.0, 0.0, 1.0),
     "no motor rotors (m_r = I_rm = I_r = 0; k_r unknown)"),
    (("F_v1", "F_v2", "F_d1", "F_d2"), lambda t: (0.0, 0.0, 0.0, 0.0), "no friction known (F_v = F_d = 0)"),
)  # fmt: skip
