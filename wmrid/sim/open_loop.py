"""The multibody prototype driven open loop: an exported robot checked against a log (``wmrid export --check``),
and the loads its casters carry at rest.

:func:`drive_windows` runs the prototype of :mod:`wmrid.sim.multibody` on a log's torques, restarted from the logged
speeds at the start of each window; :func:`settled_caster_loads` lets it settle and reads each caster's normal
force.  Both build the same plant (:class:`wmrid.sim.multibody._Plant`) as the closed-loop simulation.
"""

from __future__ import annotations

import math

import numpy as np

from wmrid.core.errors import UsageError
from wmrid.model.robot import Caster, PhysicalParameters, default_casters
from wmrid.sim.multibody import SETTLE_SECONDS, _Plant, _quat_mul
from wmrid.sim.multibody_model import MultibodySettings, caster_resistance, import_mujoco, static_loads

#: The prototype's settings unless given (frozen, so one shared instance is safe).
DEFAULT_SETTINGS = MultibodySettings()


def drive_windows(
    p: PhysicalParameters,
    casters: tuple[Caster, ...],
    t: np.ndarray,
    eta: np.ndarray,
    tau: np.ndarray,
    starts: np.ndarray,
    *,
    drag: np.ndarray | None = None,
    forces: np.ndarray | None = None,
    settings: MultibodySettings = DEFAULT_SETTINGS,
) -> np.ndarray:
    """The multibody robot ``p`` driven open loop by logged torques: its wheel speeds (n, 2) rad/s.

    t (n,) s increasing, eta (n, 2) rad/s the logged speeds (read at the restarts only), tau (n, 2) N m held over each
    sample interval, starts (G,) increasing sample indices from 0: at each the robot is put back on the flat floor,
    settled on its contacts, at the origin facing +x, moving as the logged speeds say (v = r (eta_1 + eta_2) / 2,
    w = r (eta_1 - eta_2) / (2 b)); then it runs on the torques alone until the next.  ``drag`` (K,): each ball
    caster's rolling-resistance coefficient (x its normal load, the force against its contact's motion); ``forces``
    (K,) N: a constant drag force per ball caster instead (the identified model's D_k, whatever the load); default
    neither (frictionless casters); swivel casters keep their axle friction.  The MuJoCo step divides each sample
    interval into whole steps of at most 0.25 ms.  What ``wmrid export --check`` drives an exported MJCF with.
    """
    mujoco = import_mujoco()
    t = np.asarray(t, dtype=float)
    eta = np.asarray(eta, dtype=float)
    tau = np.asarray(tau, dtype=float)
    starts = np.asarray(starts, dtype=np.int64)
    n = t.size
    casters = default_casters(p) if casters is None else tuple(casters)
    if not casters:
        raise UsageError("the multibody prototype needs at least one caster to stand on")
    dt = np.diff(t)
    step = float(np.median(dt)) / max(1, math.ceil(float(np.median(dt)) / 0.00025 - 1e-9)) if n > 1 else 0.00025
    plant = _Plant(mujoco, p, casters, settings, None, step * settings.substeps)
    m, d = plant.model, plant.data
    m.opt.timestep = step
    loads = static_loads(p, casters)
    for i, adr in plant.swivel_axles:
        m.dof_frictionloss[adr] = caster_resistance(casters[i], settings) * max(loads[2 + i], 0.0) * casters[i].radius
    coeff = np.zeros(len(casters)) if drag is None else np.asarray(drag, dtype=float)
    constant = None if forces is None else np.asarray(forces, dtype=float)
    any_drag = bool(np.any(coeff > 0)) or (constant is not None and bool(np.any(constant != 0)))
    _settle(mujoco, plant, p)  # once, at rest; every window starts from this pose
    settled = d.qpos.copy()
    settled[plant.base_q : plant.base_q + 2] = 0.0
    tilt = settled[plant.base_q + 3 : plant.base_q + 7].copy()
    yaw = math.atan2(2.0 * (tilt[0] * tilt[3] + tilt[1] * tilt[2]), 1.0 - 2.0 * (tilt[2] ** 2 + tilt[3] ** 2))
    unyaw = (math.cos(-0.5 * yaw), 0.0, 0.0, math.sin(-0.5 * yaw))
    settled[plant.base_q + 3 : plant.base_q + 7] = _quat_mul(unyaw, tilt)
    out = np.empty((n, 2))
    bounds = [*starts.tolist(), n]
    (v1, v2) = plant.vadr
    for g in range(len(starts)):
        a, z = bounds[g], bounds[g + 1]
        mujoco.mj_resetData(m, d)
        d.qpos[:] = settled
        e1, e2 = eta[a]
        v = 0.5 * p.r * (e1 + e2)
        w = p.r / (2.0 * p.b) * (e1 - e2)
        d.qvel[:] = 0.0
        d.qvel[plant.base_v : plant.base_v + 3] = [v, 0.0, 0.0]
        d.qvel[plant.base_v + 5] = w
        d.qvel[v1], d.qvel[v2] = e1, e2
        for i, adr in plant.swivel_axles:
            d.qvel[adr] = v / casters[i].radius
        mujoco.mj_forward(m, d)
        out[a] = e1, e2
        for k in range(a, z - 1):
            d.ctrl[0], d.ctrl[1] = tau[k]
            steps = max(1, round((t[k + 1] - t[k]) / step))
            if any_drag:
                for _ in range(steps):
                    plant.apply_caster_drag(coeff, constant)
                    mujoco.mj_step(m, d)
            else:
                mujoco.mj_step(m, d, steps)
            out[k + 1] = d.qvel[v1], d.qvel[v2]
    return out


def settled_caster_loads(
    p: PhysicalParameters, casters: tuple[Caster, ...], settings: MultibodySettings = DEFAULT_SETTINGS
) -> np.ndarray:
    """Each caster's normal load (K,) N on the multibody prototype at rest, settled on its contacts.

    Statics alone cannot say it (two wheels and two casters are four supports: :func:`static_loads` takes the
    least-norm solution); the prototype's contacts decide it (its sprung casters leave most of the load on the
    driven wheels), so a drag force per caster becomes the rolling-resistance coefficient that reproduces it here.
    """
    mujoco = import_mujoco()
    casters = tuple(casters)
    plant = _Plant(mujoco, p, casters, settings, None, 0.00025 * settings.substeps)
    _settle(mujoco, plant, p)
    return plant.caster_normals()


def _settle(mujoco, plant, p: PhysicalParameters) -> None:
    """Put the robot at the origin, wheel centres at height r, level, at rest, and let it settle on its contacts for
    SETTLE_SECONDS."""
    m, d = plant.model, plant.data
    d.qpos[plant.base_q : plant.base_q + 3] = [0.0, 0.0, p.r]
    d.qpos[plant.base_q + 3 : plant.base_q + 7] = [1.0, 0.0, 0.0, 0.0]
    mujoco.mj_forward(m, d)
    mujoco.mj_step(m, d, round(SETTLE_SECONDS / plant.timestep))
