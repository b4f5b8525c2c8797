"""Simulated logs as one call: :func:`simulate` runs the paper's virtual prototype (or the MuJoCo multibody one)
with an optional payload and one change of the dynamics during the run; :func:`write_simulation` writes the log and
its ground truth together.  ``wmrid simulate`` is these two functions with its flags translated.
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from wmrid.api.inputs import load_robot
from wmrid.core.errors import UsageError, option
from wmrid.model.robot import Payload, Robot

__all__ = ["SimulationRun", "load_reference", "simulate", "write_simulation"]


@dataclass(frozen=True)
class SimulationRun:
    """A simulated run: ``log`` the simulator's output (t (n,) s, eta (n, 2) rad/s, tau (n, 2) N m, pose,
    ``to_frame()``), ``truth`` its ground truth (JSON-ready: "parameters" at t = 0, settings, robot, payload) and
    ``change`` the change of the dynamics during the run, if any (:class:`wmrid.sim.scenario.PlantChange`)."""

    log: Any
    truth: dict[str, Any]
    change: Any = None

    def to_frame(self) -> Any:
        """The log as a pandas DataFrame of the canonical columns."""
        return self.log.to_frame()


def _change(truth_params, load, duration, load_at, drop_at, friction_fault, fault_at):
    """(the change during the run or None, the physical parameters at t = 0)."""
    from wmrid.sim.scenario import PlantChange, parse_friction_fault, parse_time

    times = {"load_at": load_at, "drop_at": drop_at, "fault_at": fault_at}
    given = [name for name, text in times.items() if text is not None]
    if len(given) > 1:
        raise UsageError(f"{' and '.join(option(n) for n in given)}: one change per run; give only one of them")
    if (load_at is not None or drop_at is not None) and load is None:
        raise UsageError(f"{option(given[0])} needs {option('payload', 'MASS[@X,Y]')} (the payload loaded or dropped)")
    if (friction_fault is None) != (fault_at is None):
        raise UsageError(
            f"{option('friction_fault', 'WHEEL:FACTOR')} and {option('fault_at', 'T')} go together; give both"
        )
    if not given:
        return None, truth_params if load is None else truth_params.with_payload(load)
    name = given[0]
    when = parse_time(times[name], option(name))
    if when >= duration:
        raise UsageError(
            f"{option(name, times[name])}: the change must come before the end of the run ({duration:g} s)"
        )
    if load_at is not None:
        change = PlantChange.payload_load(when, truth_params, load)
    elif drop_at is not None:
        change = PlantChange.payload_drop(when, truth_params, load)
    else:
        wheel, factor, terms = parse_friction_fault(friction_fault)
        base = truth_params if load is None else truth_params.with_payload(load)
        try:
            change = PlantChange.friction_fault(when, base, wheel, factor, terms)
        except UsageError as err:
            raise UsageError(f"{option('friction_fault', friction_fault)}: {err}") from None
    return change, change.before


def load_reference(reference: Any, *, topic: str | None = None) -> Any:
    """The :class:`wmrid.sim.reference.Reference` of ``reference``: a file (.csv, .parquet or .mcap, read by
    :func:`wmrid.io.reference_files.read_reference`, recorded with its SHA-256), a mapping with ``t`` (s), ``v``
    (m/s), ``omega`` (rad/s), a tuple (t, v, omega) of (n,) arrays, or a Reference.  ``topic``: an MCAP file's
    Twist topic (default: the only one)."""
    from wmrid.sim.reference import Reference

    if isinstance(reference, Reference):
        return reference
    if isinstance(reference, (str, os.PathLike)):
        from wmrid.io.digest import file_digests
        from wmrid.io.reference_files import read_reference

        t, v, omega = read_reference(reference, topic=topic)
        sha256 = file_digests(os.fspath(reference))[0]["sha256"]
        return Reference.from_arrays(t, v, omega, source=os.fspath(reference), sha256=sha256)
    if topic is not None:
        raise UsageError(f"{option('reference_topic')} applies to an MCAP reference file only")
    if isinstance(reference, Mapping):
        missing = [k for k in ("t", "v", "omega") if k not in reference]
        if missing:
            raise UsageError(f"{option('reference')}: no {', '.join(map(repr, missing))}; give t, v and omega")
        return Reference.from_arrays(reference["t"], reference["v"], reference["omega"])
    if isinstance(reference, (tuple, list)) and len(reference) == 3:
        return Reference.from_arrays(*reference)
    raise UsageError(
        f"{option('reference')} must be a file, a mapping of t, v, omega or a tuple (t, v, omega), "
        f"got {type(reference).__name__}"
    )


def simulate(
    robot: str | os.PathLike[str] | Robot = "paper",
    *,
    trajectory: str | None = None,
    duration: float | None = None,
    rate: float = 1000.0,
    seed: int = 0,
    payload: str | Payload | None = None,
    payload_inertia: float = 0.0,
    eta_noise: float = 0.0,
    tau_noise: float = 0.0,
    caster: float = 0.0,
    caster_time: float = 0.3,
    encoder_cpr: int = 0,
    load_at: str | float | None = None,
    drop_at: str | float | None = None,
    friction_fault: str | None = None,
    fault_at: str | float | None = None,
    engine: str = "reduced",
    floor_friction: float | None = None,
    caster_resistance: float | None = None,
    torque_limit: float | None = None,
    gear_ratio: float | None = None,
    rotor_inertia: float | None = None,
    reference: Any = None,
    reference_topic: str | None = None,
) -> SimulationRun:
    """Simulate ``robot`` (its CAD set is the truth; the controller uses its nominal set) tracking ``trajectory``
    (None: "sinusoid") or a ``reference`` (a file or arrays, :func:`load_reference`; not both) for ``duration`` s (None:
    40 s, or the whole reference), logged at ``rate`` Hz (control at 1 kHz), with white noise (``eta_noise`` rad/s,
    ``tau_noise`` N m), a coloured caster disturbance (``caster`` N m, ``caster_time`` s), encoder quantisation
    (``encoder_cpr``), a ``payload`` ("MASS[@X,Y]" or a :class:`Payload`), and at most one change during the run:
    the payload loaded at ``load_at`` or dropped at ``drop_at`` s, or a friction fault ("right:3") at ``fault_at`` s.
    ``engine``: "reduced" (the paper's model) or "mujoco" (multibody, with ``floor_friction``, ``caster_resistance``
    and ``torque_limit``).  Seeded: the same arguments give the same log bit for bit."""
    from wmrid.sim.scenario import NoiseSettings
    from wmrid.sim.simulate import simulate as run_reduced

    robot_obj = load_robot(robot, gear_ratio=gear_ratio, rotor_inertia=rotor_inertia)
    if not robot_obj.physical:
        raise UsageError(
            f"{option('robot', robot_obj.name)}: gives base parameters only; a simulation needs the physical ones "
            "([nominal] and [cad] tables of Table 1's parameters; see examples/)"
        )
    load = None
    if isinstance(payload, Payload):
        load = payload
    elif payload is not None:
        load = Payload.parse(payload, inertia=payload_inertia)
    elif payload_inertia:
        raise UsageError(f"{option('payload_inertia')} needs {option('payload', 'MASS[@X,Y]')}")
    load_at, drop_at, fault_at = (None if v is None else str(v) for v in (load_at, drop_at, fault_at))
    ref = None
    if reference is not None:
        if trajectory is not None:
            raise UsageError(
                f"{option('reference')} and {option('trajectory', trajectory)}: the run tracks one reference; give "
                "one of them"
            )
        ref = load_reference(reference, topic=reference_topic)
    elif reference_topic is not None:
        raise UsageError(f"{option('reference_topic')} needs {option('reference')} (an MCAP file)")
    from wmrid.sim.simulate import plan_duration

    duration = plan_duration(duration, ref)
    change, truth_params = _change(robot_obj.reference, load, duration, load_at, drop_at, friction_fault, fault_at)
    noise = NoiseSettings(
        eta_std=eta_noise, tau_std=tau_noise, caster_std=caster, caster_time=caster_time, encoder_cpr=encoder_cpr
    )
    if engine == "mujoco":
        from wmrid.sim.multibody import FLOOR_FRICTION, MultibodySettings, import_mujoco, simulate_multibody

        import_mujoco()  # before anything else, so that a missing engine says how to install it
        mb_settings = MultibodySettings(
            floor_friction=FLOOR_FRICTION if floor_friction is None else floor_friction,
            caster_resistance=caster_resistance, torque_limit=torque_limit,
        )  # fmt: skip
        sim = simulate_multibody(
            robot_obj.reference, robot_obj.nominal, casters=robot_obj.casters, settings=mb_settings,
            trajectory=trajectory, duration=duration, rate=rate, noise=noise, seed=seed, change=change, payload=load,
            reference=ref,
        )  # fmt: skip
    elif engine == "reduced":
        given = {"floor_friction": floor_friction, "caster_resistance": caster_resistance, "torque_limit": torque_limit}
        for name, value in given.items():
            if value is not None:
                raise UsageError(
                    f"{option(name)} applies to {option('engine', 'mujoco')} only; the reduced model has no floor "
                    "or casters"
                )
        sim = run_reduced(
            truth_params, robot_obj.nominal, trajectory=trajectory, duration=duration, rate=rate, noise=noise,
            seed=seed, change=change, reference=ref,
        )  # fmt: skip
    else:
        raise UsageError(f"{option('engine')} must be reduced or mujoco, got {engine!r}")
    truth = sim.truth()
    truth["robot"] = robot_obj.name
    if load is not None:
        truth["payload"] = {"mass": load.mass, "x": load.x, "y": load.y, "inertia": load.inertia}
    return SimulationRun(log=sim, truth=truth, change=change)


def write_simulation(run: SimulationRun, output: str | os.PathLike[str], *, force: bool = False) -> str | None:
    """Write the log (CSV, Parquet or MCAP by suffix; ``"-"``: CSV on standard output) and its truth
    (``OUTPUT.truth.json``, also inside the log's metadata) together: both appear or neither.  Returns the truth
    file's path (None for standard output)."""
    from wmrid.core.atomic import output_group, to_json_text, write_json
    from wmrid.io.logs import write_log

    output = os.fspath(output)
    truth_path = None if output == "-" else output + ".truth.json"
    if truth_path is not None and not force and os.path.exists(truth_path):
        raise UsageError(f"{truth_path} exists; use {option('force', True)} to overwrite it")
    frame = run.to_frame()
    with output_group():  # the log and its truth appear together or not at all
        if output.lower().endswith(".mcap"):
            from wmrid.io.mcap.writer import write_joint_state_mcap

            write_joint_state_mcap(output, frame, force=force, metadata={"truth": to_json_text(run.truth)})
        else:
            write_log(frame, output, force=force, metadata={"wmrid_truth": to_json_text(run.truth)})
        if truth_path is not None:
            write_json(truth_path, run.truth, force=force)
    return truth_path
