"""Simulated logs as one call: :func:`simulate` runs the paper's virtual prototype (or the MuJoCo multibody one)
with an optional payload and one change of the dynamics during the run; :func:`write_simulation` writes the log and
its ground truth together.  ``wmrid simulate`` is these two functions with its flags translated.

Imports inside functions: start-up time (a front door: ``import wmrid`` and each function load only what that
function uses).
"""

from __future__ import annotations

import os
from collections.abc import Mapping
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any, cast

from wmrid.api.inputs import load_robot
from wmrid.core.choices import Trajectory, values
from wmrid.core.errors import UsageError, option
from wmrid.model.robot import Payload, PhysicalParameters, Robot
from wmrid.sim.scenario import Change, NoiseSettings, PlantChange

if TYPE_CHECKING:
    from wmrid.sim.multibody_model import MultibodySettings

__all__ = ["Change", "NoiseSettings", "Payload", "SimulationRun", "load_reference", "simulate", "write_simulation"]


@dataclass(frozen=True)
class SimulationRun:
    """A simulated run: the simulator's log, its ground truth and the change of the dynamics during the run.

    Attributes
    ----------
    log
        The simulator's output: t (n,) s, eta (n, 2) rad/s, tau (n, 2) N m, pose; ``to_frame()``.
    truth
        Its ground truth, JSON-ready: "parameters" at t = 0, settings, robot, payload.
    change
        The change of the dynamics during the run (:class:`wmrid.sim.scenario.PlantChange`), or None.
    """

    log: Any
    truth: dict[str, Any]
    change: Any = None

    def to_frame(self) -> Any:
        """The log as a pandas DataFrame of the canonical columns."""
        return self.log.to_frame()

    def to_wheel_log(self) -> Any:
        """The log as the :class:`wmrid.core.wheel_log.WheelLog` it stands for, so that a run is identified as it is:
        ``wmrid.identify(wmrid.simulate("paper"), robot="paper")``."""
        return self.log.to_wheel_log()


def load_reference(reference: Any, *, topic: str | None = None) -> Any:
    """The reference to track that ``reference`` gives, for :func:`simulate`.

    Parameters
    ----------
    reference
        A file (.csv, .parquet or .mcap, read by :func:`wmrid.io.reference_files.read_reference`, recorded with its
        SHA-256), a mapping with ``t`` (s), ``v`` (m/s), ``omega`` (rad/s), a tuple (t, v, omega) of (n,) arrays, or
        a :class:`~wmrid.sim.reference.Reference` (returned as it is).
    topic
        An MCAP file's Twist topic (None: the only one); for an MCAP file only.

    Returns
    -------
    Reference
        The :class:`wmrid.sim.reference.Reference`.

    Raises
    ------
    UsageError
        A ``topic`` for a reference that is not a file, a mapping without ``t``, ``v`` or ``omega``, or a value of
        another kind.
    """
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
    trajectory: Any = None,
    duration: float | None = None,
    rate: float = 1000.0,
    noise: NoiseSettings | None = None,
    payload: Payload | None = None,
    change: Change | PlantChange | None = None,
    engine: str | MultibodySettings = "reduced",
) -> SimulationRun:
    """Simulate ``robot`` tracking ``trajectory`` for ``duration`` s, logged at ``rate`` Hz (control at 1 kHz).

    Seeded: the same arguments give the same log bit for bit.

    Parameters
    ----------
    robot
        A built-in name, a robot file or a :class:`Robot` with physical parameters: its CAD set is the truth, the
        controller uses its nominal set.
    trajectory
        A built-in trajectory's name (None: "sinusoid"; "reversing"), or a reference to track: a file, arrays or a
        :class:`~wmrid.sim.reference.Reference` (:func:`load_reference`, which also takes an MCAP file's topic).
    duration
        s, the run's length (None: 40 s, or the whole reference).
    rate
        Hz, the log's rate.
    noise
        The sensors' noise, the caster disturbance, the encoder and the seed (:class:`NoiseSettings`; None: none,
        seed 0).
    payload
        A rigid :class:`Payload` carried throughout, or loaded or dropped by ``change``.
    change
        At most one change during the run: a :class:`Change` (the payload loaded or dropped, a wheel's friction
        multiplied, at a time) or a :class:`PlantChange` (its own before and after).
    engine
        "reduced" (the paper's model), "mujoco" (multibody, default settings) or a
        :class:`~wmrid.sim.multibody_model.MultibodySettings` (mujoco with its floor friction, caster resistance,
        torque limit).

    Returns
    -------
    SimulationRun
        The log, its ground truth and the change.

    Raises
    ------
    UsageError
        A robot of base parameters only, an unknown trajectory or engine, a ``noise``, ``payload`` or ``change`` of
        the wrong kind, a change at or after the run's end, or a ``payload`` that does not fit a
        :class:`PlantChange`.
    """
    from wmrid.sim.simulate import plan_duration, simulate as run_reduced

    robot_obj = load_robot(robot)
    if not robot_obj.physical:
        raise UsageError(
            f"{option('robot', robot_obj.name)}: gives base parameters only; a simulation needs the physical ones "
            "([nominal] and [cad] tables of Table 1's parameters; see examples/)"
        )
    nominal = cast(PhysicalParameters, robot_obj.nominal)  # physical, not a BaseSet: checked just above
    noise = noise if noise is not None else NoiseSettings()
    for name, value, kind in (("noise", noise, NoiseSettings), ("payload", payload, Payload)):
        if value is not None and not isinstance(value, kind):
            raise UsageError(f"{option(name)} must be a {kind.__name__}, got {type(value).__name__}")
    ref = None
    if trajectory is not None and not (isinstance(trajectory, str) and trajectory in values(Trajectory)):
        if isinstance(trajectory, str) and not os.path.exists(trajectory) and "." not in os.path.basename(trajectory):
            raise UsageError(
                f"{option('trajectory', trajectory)}: no built-in trajectory of that name (choose one of "
                f"{', '.join(values(Trajectory))}) and no such reference file"
            )
        ref, trajectory = load_reference(trajectory), None
    duration = plan_duration(duration, ref)
    plant, truth_params = _plant_change(robot_obj.reference, payload, change, duration)
    settings = _engine(engine)
    if settings is not None:
        from wmrid.sim.multibody import simulate_multibody
        from wmrid.sim.multibody_model import import_mujoco

        import_mujoco()  # before anything else, so that a missing engine says how to install it
        sim = simulate_multibody(
            robot_obj.reference, nominal, casters=robot_obj.casters, settings=settings,
            trajectory=trajectory, duration=duration, rate=rate, noise=noise, change=plant, payload=payload,
            reference=ref,
        )  # fmt: skip
    else:
        sim = run_reduced(
            truth_params, nominal, trajectory=trajectory, duration=duration, rate=rate, noise=noise,
            change=plant, reference=ref,
        )  # fmt: skip
    truth = sim.truth()
    truth["robot"] = robot_obj.name
    if payload is not None:
        truth["payload"] = {"mass": payload.mass, "x": payload.x, "y": payload.y, "inertia": payload.inertia}
    return SimulationRun(log=sim, truth=truth, change=plant)


def _plant_change(
    robot: Any, payload: Payload | None, change: Change | PlantChange | None, duration: float
) -> tuple[PlantChange | None, Any]:
    """(the change of the plant during the run or None, the plant's physical parameters at t = 0)."""
    if change is None:
        return None, robot if payload is None else robot.with_payload(payload)
    if isinstance(change, Change):
        if change.at >= duration:
            raise UsageError(
                f"change.at {change.at:g} s: the change must come before the end of the run ({duration:g} s)"
            )
        plant = change.plant(robot, payload)
    elif isinstance(change, PlantChange):
        plant = change
        loads = change.kind in ("payload-load", "payload-drop")
        if payload is not None and not loads:
            raise UsageError(
                f"{option('payload')} with a {change.kind} PlantChange: the change holds the plant before and after; "
                "build it on the loaded robot, or give a Change, which carries the payload throughout"
            )
        if loads and payload is None:
            raise UsageError(f"a {change.kind} PlantChange needs {option('payload')} (the payload loaded or dropped)")
    else:
        raise UsageError(f"{option('change')} must be a Change or a PlantChange, got {type(change).__name__}")
    return plant, plant.before


def _engine(engine: Any) -> Any:
    """The multibody settings of ``engine`` (None: the reduced model)."""
    from wmrid.sim.multibody_model import MultibodySettings

    if isinstance(engine, MultibodySettings):
        return engine
    if engine == "reduced":
        return None
    if engine == "mujoco":
        return MultibodySettings()
    raise UsageError(f"{option('engine')} must be reduced, mujoco or a MultibodySettings, got {engine!r}")


def write_simulation(run: SimulationRun, output: str | os.PathLike[str], *, force: bool = False) -> str | None:
    """Write a simulated run's log and its truth together: both appear or neither.

    Parameters
    ----------
    run
        The run (:func:`simulate`).
    output
        The log's path: CSV, Parquet or MCAP by its suffix; ``"-"``: CSV on standard output.  The truth goes to
        ``OUTPUT.truth.json``, and inside the log's metadata.
    force
        Overwrite existing files.

    Returns
    -------
    str or None
        The truth file's path (None for standard output).

    Raises
    ------
    UsageError
        The truth file exists and ``force`` is not given.
    OutputExistsError
        The log exists and ``force`` is not given.
    """
    from wmrid.io.logs import write_log
    from wmrid.runtime.atomic import output_group, to_json_text, write_json

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
