"""The multibody prototype's model: its settings (:class:`MultibodySettings`), the MJCF of a robot with its casters and
payload (:func:`build_mjcf`), the casters' resistance and static loads, and MuJoCo imported with a clear message when it
is missing."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from wmrid.core.errors import UsageError, option
from wmrid.model.robot import Caster, Payload, PhysicalParameters
from wmrid.sim.scenario import positive_number

#: Install hint for the optional engine.
INSTALL_HINT = "--engine mujoco needs MuJoCo: pip install 'wmrid[physics]' (or pip install mujoco)"


#: MuJoCo steps per control period by default (a 0.25 ms step at the 1 ms control period).
SUBSTEPS = 4


#: Bump when a change alters the simulated motion (not its docs or truth fields): benchmarks key their caches on it
#: (:attr:`MultibodySettings.physics_version`).
PHYSICS_VERSION = 3


#: Default Coulomb friction of the wheels on the floor (rubber on concrete).
FLOOR_FRICTION = 1.0


#: The largest floor friction taken (a Coulomb coefficient; MuJoCo's contact solver diverges near 1e100).
MAX_FLOOR_FRICTION = 100.0


#: The tyres' contact with the floor: its time constant in MuJoCo steps (damping ratio 1).  The paper's model
#: assumes rolling without slip (Eqs. 1-4); a soft contact lets the tyre creep under load, which is not in it.
#: At the former 2 ms (8 steps) that creep biased the paper robot's Vc by -0.11 % and m12 by +0.11 % on a
#: noise-free 60 s plan, and the light AMR's structural-mismatch test rejected the model (T2 281 on 17 dof,
#: std widened 15-fold).  Two steps is as stiff as MuJoCo allows (its ``refsafe`` floor), the same rule as the
#: joint friction below; it left -0.004 % and +0.020 %, and T2 14 on 17 dof.  ``MultibodySettings.tyre_time_constant``
#: brings a softer, creeping tyre back for a study (``bench/studies/study_mujoco_misfit.py``).
CONTACT_SOLREF_STEPS = 2


#: The casters' contacts are five times softer in time constant (25 times in stiffness): sprung casters, as
#: most bases have, so the driven wheels keep most of the load and their traction.
CASTER_SOLREF = (0.01, 1.0)


#: MuJoCo enforces a joint's friction loss (F_d) as a soft constraint; with its default time constant of 0.02 s
#: the friction acts like a stiff viscous damper over a band of low speeds, not like F_d sgn(eta), and biased
#: the inertia identified on reversing logs by 0.09 % (heavy base, 20 s, noise-free).  The prototype's
#: joint friction is Coulomb's, so its constraint is made as stiff as MuJoCo allows: two time steps (the same
#: log then gave 0.003 %).
FRICTION_SOLREF_STEPS = 2


#: Below this contact-point speed (m/s) a ball caster's Coulomb drag is regularised (smooth through a stop).
DRAG_SPEED = 1e-3


GRAVITY = 9.81


def import_mujoco() -> Any:
    """The ``mujoco`` module, or a UsageError that says how to install it."""
    try:
        import mujoco  # optional extra [physics]: only --engine mujoco
    except ImportError:
        raise UsageError(INSTALL_HINT) from None
    return mujoco


@dataclass(frozen=True)
class MultibodySettings:
    """Options of the multibody (MuJoCo) prototype, in SI units.

    Attributes
    ----------
    physics_version
        A class attribute, not a setting: the version of the prototype's physics, raised with every change that
        alters the simulated motion; with MuJoCo's version it keys a cache of simulated logs (the same settings, seed
        and version give the same log).
    floor_friction
        Coulomb coefficient of the wheels on the floor (> 0); low values let them slip.
    caster_resistance
        When not None, the rolling-resistance coefficient of every caster (>= 0), overriding the robot's; 0:
        frictionless casters.
    torque_limit
        N m, the wheel torque is clipped to +-torque_limit (None: no limit).
    substeps
        MuJoCo steps per control period.
    cg_height
        m, height of the platform's centre of mass above the axle (it sets the load transfer).
    tyre_time_constant
        s, time constant of the tyres' contact with the floor (None: ``CONTACT_SOLREF_STEPS`` MuJoCo steps, as stiff
        as the engine allows; a larger value lets the tyres creep, as real ones do).
    """

    physics_version: ClassVar[int] = PHYSICS_VERSION

    floor_friction: float = FLOOR_FRICTION
    caster_resistance: float | None = None
    torque_limit: float | None = None
    substeps: int = SUBSTEPS
    cg_height: float = 0.05
    tyre_time_constant: float | None = None

    def __post_init__(self) -> None:
        if positive_number("floor_friction", self.floor_friction) > MAX_FLOOR_FRICTION:
            raise UsageError(
                f"{option('floor_friction')} must be in (0, {MAX_FLOOR_FRICTION:g}], got {self.floor_friction!r} (a "
                "Coulomb coefficient: about 1 for rubber on concrete; 10 already never slips)"
            )
        if self.caster_resistance is not None:
            c = self.caster_resistance
            if isinstance(c, bool) or not isinstance(c, (int, float)) or not math.isfinite(c) or c < 0:
                raise UsageError(f"{option('caster_resistance')} must be a number >= 0, got {c!r}")
        if self.torque_limit is not None:
            positive_number("torque_limit", self.torque_limit)
        if isinstance(self.substeps, bool) or not isinstance(self.substeps, int) or self.substeps < 1:
            raise UsageError(f"multibody substeps must be a whole number >= 1, got {self.substeps!r}")
        if not math.isfinite(self.cg_height):
            raise UsageError("cg_height must be finite")
        if self.tyre_time_constant is not None:
            positive_number("tyre_time_constant", self.tyre_time_constant)

    def to_dict(self) -> dict:
        return {
            "floor_friction": self.floor_friction, "caster_resistance": self.caster_resistance,
            "torque_limit": self.torque_limit, "substeps": self.substeps, "cg_height": self.cg_height,
            "tyre_time_constant": self.tyre_time_constant,
        }  # fmt: skip

    def tyre_solref(self, timestep: float) -> tuple[float, float]:
        """MuJoCo's ``solref`` of the tyres' floor contact.

        Parameters
        ----------
        timestep
            s, MuJoCo's time step.

        Returns
        -------
        tuple of float
            (time constant s, damping ratio).
        """
        if self.tyre_time_constant is not None:
            return (self.tyre_time_constant, 1.0)
        return (CONTACT_SOLREF_STEPS * timestep, 1.0)


def _inertial(mass: float, pos: tuple[float, float, float], diag: tuple[float, float, float]) -> str:
    # MuJoCo needs a strictly positive inertia; 1e-9 kg m^2 stands for the zero of a point mass.
    dx, dy, dz = (max(v, 1e-9) for v in diag)
    return (
        f'<inertial mass="{max(mass, 1e-9)!r}" pos="{pos[0]!r} {pos[1]!r} {pos[2]!r}" '
        f'diaginertia="{dx!r} {dy!r} {dz!r}"/>'
    )


def _flat_inertia(yaw: float) -> tuple[float, float, float]:
    """A body's diagonal inertia with yaw inertia ``yaw`` (kg m^2): that of a flat plate (Ixx + Iyy = Izz)."""
    return (0.5 * yaw, 0.5 * yaw, yaw)


def build_mjcf(
    p: PhysicalParameters,
    casters: tuple[Caster, ...],
    settings: MultibodySettings = MultibodySettings(),
    payload: Payload | None = None,
    timestep: float = 0.00025,
) -> str:
    """The MJCF text of robot ``p`` with ``casters`` (and an optional welded ``payload``).

    Frames: world z up; the platform frame has its origin at O (the axle midpoint, at wheel-centre height
    r above the ground), x forward, y towards the left wheel.  Bodies: ``platform`` (free joint),
    ``rotor_right``/``rotor_left`` and ``payload`` welded to it, ``wheel_right``/``wheel_left`` on hinges
    ``right``/``left`` about y (positive = forward), swivel casters' ``fork_i`` and ``caster_wheel_i``.
    """
    r, b = p.r, p.b
    h = settings.cg_height
    parts = [
        '<mujoco model="wmrid-multibody">',
        f'<option timestep="{timestep!r}" gravity="0 0 {-GRAVITY!r}" integrator="implicitfast" cone="elliptic" '
        'impratio="10" noslip_iterations="20" tolerance="1e-12" iterations="100"/>',
        '<default><geom contype="0" conaffinity="0"/></default>',
        "<worldbody>",
        '<geom name="floor" type="plane" size="0 0 1"/>',
        '<body name="platform" pos="0 0 0"><freejoint name="base"/>',
        _inertial(p.m_p, (p.d_x, p.d_y, h), _flat_inertia(p.I_p)),
    ]
    for side, sign in (("right", -1.0), ("left", 1.0)):
        parts.append(
            f'<body name="rotor_{side}" pos="{p.c_x!r} {sign * p.c_y!r} 0">'
            + _inertial(p.m_r, (0.0, 0.0, 0.0), _flat_inertia(p.I_rm))
            + "</body>"
        )
    for side, sign in (("right", -1.0), ("left", 1.0)):
        fv = p.F_v1 if side == "right" else p.F_v2
        fd = p.F_d1 if side == "right" else p.F_d2
        parts.append(
            f'<body name="wheel_{side}" pos="0 {sign * b!r} 0">'
            + _inertial(p.m_w, (0.0, sign * (p.a - b), 0.0), (p.I_wm, p.I_w, p.I_wm))
            + f'<joint name="{side}" type="hinge" axis="0 1 0" damping="{fv!r}" frictionloss="{fd!r}" '
            f'solreffriction="{FRICTION_SOLREF_STEPS * timestep!r} 1" '
            f'armature="{p.k_r**2 * p.I_r!r}"/>'
            + f'<geom name="tyre_{side}" type="sphere" size="{r!r}" mass="0"/>'
            + "</body>"
        )
    for i, caster in enumerate(casters):
        rc = caster.radius
        if caster.kind == "ball":
            parts.append(
                f'<geom name="caster_{i}" type="sphere" size="{rc!r}" pos="{caster.x!r} {caster.y!r} {rc - r!r}" '
                'mass="0"/>'
            )
        else:  # swivel: fork on a vertical hinge above (x, y), wheel trailing by ``trail`` behind it
            parts.append(
                f'<body name="fork_{i}" pos="{caster.x!r} {caster.y!r} 0">'
                + _inertial(1e-3, (0.0, 0.0, 0.0), (1e-6, 1e-6, 1e-6))
                + f'<joint name="swivel_{i}" type="hinge" axis="0 0 1" damping="1e-4"/>'
                + f'<body name="caster_wheel_{i}" pos="{-caster.trail!r} 0 {rc - r!r}">'
                + _inertial(1e-2, (0.0, 0.0, 0.0), (1e-6, 1e-6, 1e-6))
                + f'<joint name="caster_axle_{i}" type="hinge" axis="0 1 0" '
                f'solreffriction="{FRICTION_SOLREF_STEPS * timestep!r} 1"/>'
                + f'<geom name="caster_{i}" type="sphere" size="{rc!r}" mass="0"/>'
                + "</body></body>"
            )
    if payload is not None:
        parts.append(
            f'<body name="payload" pos="{payload.x!r} {payload.y!r} {h!r}">'
            + _inertial(payload.mass, (0.0, 0.0, 0.0), _flat_inertia(payload.inertia))
            + "</body>"
        )
    parts.append("</body></worldbody>")
    tyre = settings.tyre_solref(timestep)
    solref = f'solref="{tyre[0]!r} {tyre[1]!r}"'
    sprung = f'solref="{CASTER_SOLREF[0]!r} {CASTER_SOLREF[1]!r}"'
    parts.append("<contact>")
    for side in ("right", "left"):
        mu = settings.floor_friction
        parts.append(f'<pair geom1="tyre_{side}" geom2="floor" condim="3" friction="{mu!r} {mu!r}" {solref}/>')
    for i, caster in enumerate(casters):
        if caster.kind == "ball":  # frictionless contact; the rolling drag is applied as a force (see _Plant)
            parts.append(f'<pair geom1="caster_{i}" geom2="floor" condim="1" {sprung}/>')
        else:
            mu = max(settings.floor_friction, 0.5)
            parts.append(f'<pair geom1="caster_{i}" geom2="floor" condim="3" friction="{mu!r} {mu!r}" {sprung}/>')
    parts.append("</contact>")
    parts.append(
        '<actuator><motor name="tau_right" joint="right" gear="1"/><motor name="tau_left" joint="left" gear="1"/>'
        "</actuator>"
    )
    parts.append("</mujoco>")
    return "\n".join(parts)


def caster_resistance(caster: Caster, settings: MultibodySettings) -> float:
    """The rolling-resistance coefficient of ``caster`` (settings override the robot file's)."""
    return caster.resistance if settings.caster_resistance is None else float(settings.caster_resistance)


def static_loads(p: PhysicalParameters, casters: tuple[Caster, ...], payload: Payload | None = None) -> np.ndarray:
    """Normal loads (N) of [right wheel, left wheel, casters...] at rest, by least-norm statics.

    Three or more supports make the statics indeterminate; the minimum-norm solution of the three
    equilibrium equations (vertical force, roll and pitch moments) stands in for the engine's (which also
    depends on the contacts' compliance).  Used only to size a swivel caster's axle friction.
    """
    mass = p.m_p + 2 * p.m_w + 2 * p.m_r + (payload.mass if payload else 0.0)
    mx = p.m_p * p.d_x + 2 * p.m_r * p.c_x + (payload.mass * payload.x if payload else 0.0)
    my = p.m_p * p.d_y + (payload.mass * payload.y if payload else 0.0)
    xs = [0.0, 0.0, *[c.x - (c.trail if c.kind == "swivel" else 0.0) for c in casters]]
    ys = [-p.b, p.b, *[c.y for c in casters]]
    a = np.array([np.ones(len(xs)), xs, ys])
    rhs = GRAVITY * np.array([mass, mx, my])
    return np.linalg.lstsq(a, rhs, rcond=None)[0]
