"""A multibody virtual prototype on MuJoCo: physics that wmrid's equations did not derive.

The reduced simulator (:mod:`wmrid.sim.simulate`) integrates the very model (Eqs. 9-14) that the estimators
invert, so its logs cannot show what that model leaves out.  This one builds the robot as rigid bodies in
MuJoCo (an optional dependency, ``pip install 'wmrid[physics]'``) and lets the engine derive the
dynamics from masses, inertias, joints and contacts, as the paper's SimMechanics prototype did (Sec. 4):

* the platform (mass m_p, yaw inertia I_p about its centre of mass at (d_x, d_y), at height ``cg_height``
  above the axle) on a free joint;
* two driven wheels, hinged at (0, -b) (right) and (0, +b) (left) with their centre of mass at distance a
  from O, inertia I_w about the axle and I_wm about a diameter, and a sphere of radius r that touches the
  ground plane with Coulomb friction ``floor_friction`` (they slip when it is low);
* each rotor as a welded body of mass m_r and inertia I_rm at (c_x, +-c_y), its spin inertia reflected
  through the gear as the wheel joint's armature k_r^2 I_r;
* joint friction: viscous F_v (joint damping) and Coulomb F_d (joint friction loss), per wheel;
* the casters of :class:`wmrid.model.robot.Caster`: a ball caster is a sprung sphere fixed under the platform
  with a frictionless contact, and a force of ``resistance`` x (its normal load) against the velocity of
  its contact point -- the rolling resistance of a ball caster, with the normal load the engine computes
  (it moves with acceleration and payload), applied before every engine step; a swivel
  caster is a fork on a vertical hinge trailing a small wheel (both on real joints), whose axle has
  friction loss resistance x (static load) x radius, so its drag points along the fork, which lags the motion;
* a payload as a welded body.

The robot tracks the same reference under the same backstepping + computed-torque controller as the
reduced simulator (:func:`wmrid.sim.closed_loop.control_torque`, on the NOMINAL parameters), fed with the engine's
state at each 1 ms control period: the pose of O from the platform's free joint (yaw unwrapped) and the
wheel joints' speeds.  The torque, optionally clipped to +-``torque_limit``, is held over the control
period while MuJoCo takes ``substeps`` steps (implicit-in-velocity integration, elliptic friction cones,
the no-slip post-solver).  The logged torque is the applied (clipped) one.  Noise, encoder quantisation,
the coloured disturbance torque and plant changes (payload loaded or dropped, a friction fault) are those
of :mod:`wmrid.sim.simulate`, drawn from the same streams.

Before t = 0 the robot settles on its contacts for ``SETTLE_SECONDS`` at rest; then it is put on the
reference with the reference's speeds, keeping the settled height and tilt, so no start-up transient is
logged.  The truth is the base parameters the physical description implies
(:func:`wmrid.model.dynamics.base_parameters`),
plus, under ``settings["multibody"]``, the mean normal load of each caster and (ball casters) its mean drag
force, resistance x load: the truth of the drag D_k of ``identify --friction wheel+caster``.
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np

from wmrid.core.errors import UsageError
from wmrid.model.robot import Caster, Payload, PhysicalParameters, default_casters
from wmrid.sim.closed_loop import KIND, control_torque, reference_state, reversing_advance
from wmrid.sim.multibody_model import (
    DRAG_SPEED,
    PHYSICS_VERSION as PHYSICS_VERSION,
    MultibodySettings,
    _flat_inertia,
    build_mjcf,
    caster_resistance,
    import_mujoco,
    static_loads,
)
from wmrid.sim.reference import Reference
from wmrid.sim.scenario import NoiseSettings, PlantChange
from wmrid.sim.simulate import SimulatedLog, plan_run

#: Time the robot settles on its contacts, at rest, before t = 0, s.
SETTLE_SECONDS = 0.5


class _Plant:
    """The compiled MuJoCo model and data of one robot, with handles to what the loop reads and writes."""

    def __init__(self, mujoco, p, casters, settings, payload, period):
        self.mujoco = mujoco
        self.timestep = period / settings.substeps
        xml = build_mjcf(p, casters, settings, payload, self.timestep)
        self.model = mujoco.MjModel.from_xml_string(xml)
        self.data = mujoco.MjData(self.model)
        m = self.model
        self.qadr = [int(m.jnt_qposadr[m.joint(name).id]) for name in ("right", "left")]
        self.vadr = [int(m.jnt_dofadr[m.joint(name).id]) for name in ("right", "left")]
        self.base_q = int(m.jnt_qposadr[m.joint("base").id])
        self.base_v = int(m.jnt_dofadr[m.joint("base").id])
        self.caster_geoms = {int(m.geom(f"caster_{i}").id): i for i in range(len(casters))}
        self.platform = int(m.body("platform").id)
        self.payload_body = int(m.body("payload").id) if payload is not None else -1
        self.swivel_axles = [
            (i, int(m.jnt_dofadr[m.joint(f"caster_axle_{i}").id])) for i, c in enumerate(casters) if c.kind == "swivel"
        ]
        self.force6 = np.zeros(6)

    def apply_caster_drag(self, coefficients: np.ndarray, forces: np.ndarray | None = None) -> None:
        """Set the platform's applied force to the ball casters' rolling drag at the current state.

        Each ball caster in contact is pushed with coefficients[i] x its normal load (N) against the
        horizontal velocity v of its contact point, as -c N v / sqrt(|v|^2 + DRAG_SPEED^2) (Coulomb drag,
        regularised below DRAG_SPEED so that it is smooth through a stop).  An applied force rather than
        contact friction: MuJoCo's soft friction on a sliding sphere feeds back into its normal force and
        made two resisting balls chatter and lift the driven wheels.
        """
        mj, m, d = self.mujoco, self.model, self.data
        body = self.platform
        # Python floats, not numpy: np.cross on 3-vectors cost 70 % of a multibody run (11 of 16 s for the AMR's
        # 40 s); the same products and sums in the same order, so the same bits.
        lx, ly, _ = (float(v) for v in d.qvel[self.base_v : self.base_v + 3])
        wx, wy, wz = (float(v) for v in d.xmat[body].reshape(3, 3) @ d.qvel[self.base_v + 3 : self.base_v + 6])
        ox, oy, oz = (float(v) for v in d.xpos[body])
        cx, cy, cz = (float(v) for v in d.xipos[body])
        fx = fy = fz = tx = ty = tz = 0.0
        for k in range(d.ncon):
            con = d.contact[k]
            i = self.caster_geoms.get(con.geom1, self.caster_geoms.get(con.geom2, -1))
            if i < 0 or coefficients[i] == 0.0:
                continue
            mj.mj_contactForce(m, d, k, self.force6)
            normal = float(self.force6[0])
            px, py, pz = (float(v) for v in con.pos)
            rx, ry, rz = px - ox, py - oy, pz - oz
            vx = lx + (wy * rz - wz * ry)  # the contact point's velocity: lin + omega x (point - origin)
            vy = ly + (wz * rx - wx * rz)
            scale = -float(coefficients[i]) * normal / math.sqrt(vx * vx + vy * vy + DRAG_SPEED**2)
            gx, gy, gz = scale * vx, scale * vy, 0.0
            fx, fy, fz = fx + gx, fy + gy, fz + gz
            qx, qy, qz = px - cx, py - cy, pz - cz  # torque about the centre of mass: (point - com) x f
            tx, ty, tz = tx + (qy * gz - qz * gy), ty + (qz * gx - qx * gz), tz + (qx * gy - qy * gx)
        if forces is not None:  # constant drag forces (N), at each caster's lowest point, in contact or not
            for geom, i in self.caster_geoms.items():
                if forces[i] == 0.0:
                    continue
                gx_, gy_, gz_ = (float(v) for v in d.geom_xpos[geom])
                px, py, pz = gx_, gy_, gz_ - float(m.geom_size[geom][0])
                rx, ry, rz = px - ox, py - oy, pz - oz
                vx = lx + (wy * rz - wz * ry)
                vy = ly + (wz * rx - wx * rz)
                scale = -float(forces[i]) / math.sqrt(vx * vx + vy * vy + DRAG_SPEED**2)
                gx, gy = scale * vx, scale * vy
                fx, fy = fx + gx, fy + gy
                qx, qy, qz = px - cx, py - cy, pz - cz
                tx, ty, tz = tx - qz * gy, ty + qz * gx, tz + (qx * gy - qy * gx)
        d.xfrc_applied[body, :3] = (fx, fy, fz)
        d.xfrc_applied[body, 3:] = (tx, ty, tz)

    def set_joint_friction(self, p: PhysicalParameters) -> None:
        m = self.model
        for j, (fv, fd) in enumerate(((p.F_v1, p.F_d1), (p.F_v2, p.F_d2))):
            m.dof_damping[self.vadr[j]] = fv
            m.dof_frictionloss[self.vadr[j]] = fd

    def set_payload(self, payload: Payload | None) -> None:
        """Give the welded payload body its mass and inertia, or (None) make it a 1e-9 kg point."""
        if self.payload_body < 0:
            return
        m = self.model
        mass = payload.mass if payload is not None else 1e-9
        inertia = _flat_inertia(payload.inertia) if payload is not None else (0.0, 0.0, 0.0)
        m.body_mass[self.payload_body] = mass
        m.body_inertia[self.payload_body] = [max(v, 1e-9) for v in inertia]

    def caster_normals(self) -> np.ndarray:
        """Normal contact force (N) on each caster now (0 when it is off the ground)."""
        mj, m, d = self.mujoco, self.model, self.data
        out = np.zeros(len(self.caster_geoms))
        for k in range(d.ncon):
            con = d.contact[k]
            for g in (con.geom1, con.geom2):
                if g in self.caster_geoms:
                    mj.mj_contactForce(m, d, k, self.force6)
                    out[self.caster_geoms[g]] += self.force6[0]
        return out

    def yaw(self) -> float:
        w, x, y, z = self.data.qpos[self.base_q + 3 : self.base_q + 7]
        return math.atan2(2.0 * (w * z + x * y), 1.0 - 2.0 * (y * y + z * z))


def simulate_multibody(
    true: PhysicalParameters,
    nominal: PhysicalParameters,
    *,
    casters: tuple[Caster, ...] | None = None,
    settings: MultibodySettings = MultibodySettings(),  # noqa: B008 - frozen, so one shared default is safe
    trajectory: str | None = None,
    duration: float | None = None,
    rate: float = 1000.0,
    noise: NoiseSettings = NoiseSettings(),  # noqa: B008 - frozen, so one shared default is safe
    seed: int | None = None,
    change: PlantChange | None = None,
    payload: Payload | None = None,
    reference: Reference | None = None,
) -> SimulatedLog:
    """Simulate the closed loop on the MuJoCo prototype; arguments as :func:`wmrid.sim.simulate.simulate` (a
    ``reference`` is tracked from the origin facing +x, as there).

    ``true`` is the robot WITHOUT ``payload``: the payload is its own welded body (carried throughout, or
    loaded or dropped by ``change``, whose before/after must then be ``true`` and ``true.with_payload(payload)``).
    A friction fault in ``change`` switches the joint friction.  ``casters`` default to
    :func:`wmrid.model.robot.default_casters`.  The returned log's ``true`` is the plant at t = 0 (with the
    payload when it is carried from the start).

    MuJoCo's own warnings (which it would print, one per step, and append to ``MUJOCO_LOG.TXT`` in the working
    folder) are counted instead: the first is quoted in the error of a run that diverged, and a run that finished
    lists their number and the first in its ``multibody`` record (``mujoco_warnings``).
    """
    mujoco = import_mujoco()
    warned = _Warnings()
    previous = mujoco.get_mju_user_warning()
    mujoco.set_mju_user_warning(warned)
    try:
        return _simulate(
            mujoco, warned, true, nominal, casters=casters, settings=settings, trajectory=trajectory,
            duration=duration, rate=rate, noise=noise, seed=seed, change=change, payload=payload, reference=reference,
        )  # fmt: skip
    finally:
        mujoco.set_mju_user_warning(previous)


class _Warnings:
    """MuJoCo's warnings of one run: how many, and the first (a user warning handler, :func:`simulate_multibody`)."""

    def __init__(self) -> None:
        self.count = 0
        self.first: str | None = None

    def __call__(self, message: str) -> None:
        self.count += 1
        if self.first is None:
            self.first = " ".join(str(message).split())

    def said(self) -> str:
        return (
            ""
            if self.first is None
            else f" (MuJoCo: {self.first}" + (f"; {self.count} warnings)" if self.count > 1 else ")")
        )


def _simulate(
    mujoco,
    warned: _Warnings,
    true: PhysicalParameters,
    nominal: PhysicalParameters,
    *,
    casters: tuple[Caster, ...] | None,
    settings: MultibodySettings,
    trajectory: str | None,
    duration: float | None,
    rate: float,
    noise: NoiseSettings,
    seed: int | None,
    change: PlantChange | None,
    payload: Payload | None,
    reference: Reference | None,
) -> SimulatedLog:
    """:func:`simulate_multibody`, with MuJoCo's warnings going to ``warned``."""
    if not isinstance(settings, MultibodySettings):
        raise UsageError("settings must be MultibodySettings")
    if not isinstance(true, PhysicalParameters):
        raise UsageError("true and nominal must be PhysicalParameters")
    run = plan_run(
        nominal, trajectory=trajectory, duration=duration, rate=rate, noise=noise, seed=seed, reference=reference
    )
    period, every, n, n_ctrl = run.period, run.every, run.n, run.n_ctrl
    if n_ctrl > MAX_CONTROL_PERIODS:
        raise UsageError(
            f"duration {run.duration:g} s: at most {MAX_CONTROL_PERIODS * period:g} s of multibody simulation"
        )
    casters = default_casters(true) if casters is None else tuple(casters)
    if not casters:
        raise UsageError(
            "the multibody prototype needs at least one caster to stand on (a robot file's [[caster]] tables); "
            "omit them for the default two ball casters"
        )

    # The plant at t = 0 and after a change, as physical parameter sets (for the truth) and as what the
    # engine switches: the payload's mass, or the joint friction.
    carried = payload is not None and (change is None or change.kind != "payload-load")
    plant0 = true.with_payload(payload) if carried else true
    switch = -1
    after_payload: Payload | None = payload if carried else None
    after_friction = plant0
    if change is not None:
        switch = change.switch_period(period)
        if switch < 1 or switch >= n_ctrl - 1:
            raise UsageError(f"change time {change.t:g} s must come after 0 and before the end of the run")
        if change.kind == "payload-load":
            after_payload = payload
        elif change.kind == "payload-drop":
            after_payload = None
        elif change.kind == "friction-fault":
            after_friction = change.after
        else:
            raise UsageError(f"the multibody prototype cannot simulate a {change.kind} change")
        if payload is None and change.kind != "friction-fault":
            raise UsageError("a payload change needs the payload")

    caster_z = run.caster_z

    plant = _Plant(mujoco, true, casters, settings, payload, period)
    plant.set_payload(payload if (carried or (change is not None and change.kind == "payload-drop")) else None)
    plant.set_joint_friction(plant0)
    m, d = plant.model, plant.data

    kind = KIND[run.trajectory]
    traj, ctrl, gains = run.traj, run.ctrl, run.gains

    # Settle at rest on the contacts, then start on the reference with its speeds (true r, b).
    r, b = true.r, true.b
    ref0 = reference_state(kind, traj, 0.0, 0.0, 0.0)
    d.qpos[plant.base_q : plant.base_q + 3] = [ref0[0], ref0[1], r]
    half = 0.5 * ref0[2]
    d.qpos[plant.base_q + 3 : plant.base_q + 7] = [math.cos(half), 0.0, 0.0, math.sin(half)]
    mujoco.mj_forward(m, d)
    mujoco.mj_step(m, d, round(SETTLE_SECONDS / plant.timestep))
    bad_qacc = int(mujoco.mjtWarning.mjWARN_BADQACC)
    if d.warning[bad_qacc].number > 0 or not np.all(np.isfinite(d.qpos)):
        raise UsageError(
            "the multibody simulation became unstable while the robot settled on the floor, before t = 0 (the "
            "integration diverged); check the robot's parameters, its casters and --floor-friction" + warned.said()
        )
    d.qpos[plant.base_q : plant.base_q + 2] = [ref0[0], ref0[1]]
    tilt = d.qpos[plant.base_q + 3 : plant.base_q + 7].copy()
    yaw_now = math.atan2(2.0 * (tilt[0] * tilt[3] + tilt[1] * tilt[2]), 1.0 - 2.0 * (tilt[2] ** 2 + tilt[3] ** 2))
    rot = (math.cos(0.5 * (ref0[2] - yaw_now)), 0.0, 0.0, math.sin(0.5 * (ref0[2] - yaw_now)))
    d.qpos[plant.base_q + 3 : plant.base_q + 7] = _quat_mul(rot, tilt)
    d.qvel[:] = 0.0
    d.qvel[plant.base_v : plant.base_v + 3] = [ref0[3] * math.cos(ref0[2]), ref0[3] * math.sin(ref0[2]), 0.0]
    d.qvel[plant.base_v + 5] = ref0[4]
    d.qvel[plant.vadr[0]] = (ref0[3] + b * ref0[4]) / r
    d.qvel[plant.vadr[1]] = (ref0[3] - b * ref0[4]) / r
    for i, adr in plant.swivel_axles:  # a trailing caster wheel rolls with the platform from the start
        d.qvel[adr] = ref0[3] / casters[i].radius
    for j in range(2):
        d.qpos[plant.qadr[j]] = 0.0
    d.time = 0.0
    mujoco.mj_forward(m, d)
    # Swivel casters: axle friction loss = resistance x static load x radius (a constant torque).
    loads = static_loads(true, casters, payload if carried else None)
    for i, adr in plant.swivel_axles:
        m.dof_frictionloss[adr] = caster_resistance(casters[i], settings) * max(loads[2 + i], 0.0) * casters[i].radius

    drag = np.array([caster_resistance(c, settings) if c.kind == "ball" else 0.0 for c in casters])
    any_drag = bool(np.any(drag > 0))
    pose = np.empty((n, 3))
    angle = np.empty((n, 2))
    eta = np.empty((n, 2))
    tau = np.empty((n, 2))
    refpose = np.empty((n, 3))
    dist = np.empty((n, 2))
    normals = np.zeros(len(casters))
    n_normals = 0
    caster_load = np.zeros((n, len(casters)))  # each caster's normal force at each logged sample
    slip_max = 0.0

    a_ou = math.exp(-period / noise.caster_time)
    q_ou = noise.caster_std * math.sqrt(-math.expm1(-2.0 * period / noise.caster_time))
    d1 = noise.caster_std * caster_z[0, 0]
    d2 = noise.caster_std * caster_z[0, 1]
    limit = settings.torque_limit
    xr_int, yr_int = 0.0, 0.0
    phi_prev = ref0[2]
    phi_unwrapped = ref0[2]
    s = np.zeros(7)
    h = period
    qpos, qvel = d.qpos, d.qvel
    bq, bv = plant.base_q, plant.base_v
    (q1, q2), (v1, v2) = plant.qadr, plant.vadr
    for k in range(n_ctrl):
        t = k * period
        yaw = plant.yaw()
        phi_unwrapped += (yaw - phi_prev + math.pi) % (2.0 * math.pi) - math.pi
        phi_prev = yaw
        s[0], s[1], s[2] = qpos[bq], qpos[bq + 1], phi_unwrapped
        s[3], s[4] = qpos[q1], qpos[q2]
        s[5], s[6] = qvel[v1], qvel[v2]
        ref = reference_state(kind, traj, t, xr_int, yr_int)
        tau1, tau2 = control_torque(s, ref, ctrl, gains)
        if limit is not None:
            tau1 = min(max(tau1, -limit), limit)
            tau2 = min(max(tau2, -limit), limit)
        if k % every == 0:
            i = k // every
            pose[i] = s[0], s[1], s[2]
            angle[i] = s[3], s[4]
            eta[i] = s[5], s[6]
            tau[i] = tau1, tau2
            refpose[i] = ref[0], ref[1], ref[2]
            dist[i] = d1, d2
            if plant.caster_geoms:
                now = plant.caster_normals()
                caster_load[i] = now
                normals += now
                n_normals += 1
            v_body = qvel[bv] * math.cos(yaw) + qvel[bv + 1] * math.sin(yaw)
            slip_max = max(slip_max, abs(v_body - 0.5 * r * (s[5] + s[6])))
        if k == n_ctrl - 1:
            break
        if k == switch:
            plant.set_payload(after_payload)
            plant.set_joint_friction(after_friction)
        d.ctrl[0], d.ctrl[1] = tau1, tau2
        d.qfrc_applied[v1], d.qfrc_applied[v2] = -d1, -d2
        if any_drag:
            for _ in range(settings.substeps):
                plant.apply_caster_drag(drag)
                mujoco.mj_step(m, d)
        else:
            mujoco.mj_step(m, d, settings.substeps)
        if d.warning[bad_qacc].number > 0 or abs(_tilt(qpos[bq + 3 : bq + 7])) > MAX_TILT:
            raise UsageError(
                f"the multibody simulation became unstable at t = {t:.3f} s (the platform tipped over or the "
                "integration diverged); check the robot's parameters and its casters (the centre of mass must lie "
                "inside the wheels' and casters' support)" + warned.said()
            )
        if kind == 1:
            dx, dy = reversing_advance(traj, t, h)
            xr_int += dx
            yr_int += dy
        d1 = a_ou * d1 + q_ou * caster_z[k + 1, 0]
        d2 = a_ou * d2 + q_ou * caster_z[k + 1, 1]

    mean_normals = normals / max(n_normals, 1)
    multibody = {
        **settings.to_dict(),
        "engine": f"mujoco {mujoco.__version__}",
        "timestep": plant.timestep,
        "settle_seconds": SETTLE_SECONDS,
        "contact_solref": list(settings.tyre_solref(plant.timestep)),
        "casters": [
            {
                **c.to_dict(),
                "resistance_used": caster_resistance(c, settings),
                "mean_normal_load": float(nl),
                "mean_drag_force": float(caster_resistance(c, settings) * nl) if c.kind == "ball" else None,
            }
            for c, nl in zip(casters, mean_normals, strict=True)
        ],
        "max_slip_speed": float(slip_max),
    }
    if warned.count:
        multibody["mujoco_warnings"] = {"count": warned.count, "first": warned.first}
    extra = {"engine": "mujoco", "substeps": settings.substeps, "multibody": multibody}
    caster_load.setflags(write=False)
    log = run.log(plant0, pose, angle, eta, tau, refpose, dist, extra, change)
    return dataclasses.replace(log, caster_load=caster_load)


#: Most control periods of one run (50,000 s at 1 kHz): a bound on the time and memory of a simulation.
MAX_CONTROL_PERIODS = 50_000_000
#: Largest roll or pitch of the platform (rad) before the run is called unstable (it has tipped over).
MAX_TILT = 0.3


def _tilt(q) -> float:
    """The platform's tilt from the vertical (rad) for its orientation quaternion q = (w, x, y, z)."""
    _, x, y, _ = q
    cos_tilt = 1.0 - 2.0 * (x * x + y * y)  # z-axis of the body, z component
    return math.acos(max(-1.0, min(1.0, cos_tilt)))


def _quat_mul(a, b) -> list[float]:
    aw, ax, ay, az = a
    bw, bx, by, bz = b
    return [
        aw * bw - ax * bx - ay * by - az * bz,
        aw * bx + ax * bw + ay * bz - az * by,
        aw * by - ax * bz + ay * bw + az * bx,
        aw * bz + ax * by - ay * bx + az * bw,
    ]
