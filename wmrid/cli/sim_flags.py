"""``wmrid simulate``'s text forms turned into the library's objects: ``--payload MASS[@X,Y]`` into a
:class:`~wmrid.model.robot.Payload`, ``--load-at``/``--drop-at``/``--friction-fault WHEEL:FACTOR[:TERMS]``/
``--fault-at`` into a :class:`~wmrid.sim.scenario.Change`, the noise flags into a
:class:`~wmrid.sim.scenario.NoiseSettings`, the engine's into a :class:`~wmrid.sim.multibody_model.MultibodySettings`.
The library never parses these texts; each error here names the flag as the user wrote it.

Imports inside functions: start-up time (``wmrid --help`` and each command load only what that command runs).
"""

from __future__ import annotations

from typing import Any

from wmrid.core.errors import UsageError, option


def payload_of(text: str | None, inertia: float) -> Any:
    """The payload ``--payload`` gives (None: none), with ``--payload-inertia`` kg m^2."""
    from wmrid.model.robot import Payload

    if text is None:
        if inertia:
            raise UsageError(f"{option('payload_inertia')} needs {option('payload', 'MASS[@X,Y]')}")
        return None
    return Payload.parse(text, inertia=inertia)


def reference_of(trajectory: str | None, reference: str | None, topic: str | None) -> Any:
    """What the run tracks: the built-in ``--trajectory`` (None: the default), or the ``--reference`` file read
    (:func:`wmrid.api.simulation.load_reference`); not both."""
    from wmrid.api.simulation import load_reference

    if reference is None:
        if topic is not None:
            raise UsageError(f"{option('reference_topic')} needs {option('reference')} (an MCAP file)")
        return trajectory
    if trajectory is not None:
        raise UsageError(
            f"{option('reference')} and {option('trajectory', trajectory)}: the run tracks one reference; give one "
            "of them"
        )
    return load_reference(reference, topic=topic)


def change_of(
    payload: Any, load_at: str | None, drop_at: str | None, friction_fault: str | None, fault_at: str | None,
    duration: float, robot: Any,
) -> Any:  # fmt: skip
    """The change ``--load-at``, ``--drop-at`` or ``--friction-fault`` with ``--fault-at`` asks for (None: none),
    before the end of a run of ``duration`` s, checked against the ``robot``'s plant (a fault on a friction the
    plant does not have is refused here, naming the flag)."""
    from wmrid.sim.scenario import Change, parse_friction_fault, parse_time

    times = {"load_at": load_at, "drop_at": drop_at, "fault_at": fault_at}
    given = [name for name, text in times.items() if text is not None]
    if len(given) > 1:
        raise UsageError(f"{' and '.join(option(n) for n in given)}: one change per run; give only one of them")
    if (load_at is not None or drop_at is not None) and payload is None:
        raise UsageError(f"{option(given[0])} needs {option('payload', 'MASS[@X,Y]')} (the payload loaded or dropped)")
    if (friction_fault is None) != (fault_at is None):
        raise UsageError(
            f"{option('friction_fault', 'WHEEL:FACTOR')} and {option('fault_at', 'T')} go together; give both"
        )
    if not given:
        return None
    name = given[0]
    when = parse_time(str(times[name]), option(name))
    if when >= duration:
        raise UsageError(
            f"{option(name, times[name])}: the change must come before the end of the run ({duration:g} s)"
        )
    if load_at is not None:
        return Change(when, "load")
    if drop_at is not None:
        return Change(when, "drop")
    wheel, factor, terms = parse_friction_fault(str(friction_fault))
    try:
        change = Change(when, "fault", wheel=wheel, factor=factor, terms=terms)
        change.plant(robot.reference, payload)
    except UsageError as err:
        raise UsageError(f"{option('friction_fault', friction_fault)}: {err}") from None
    return change


def engine_of(
    engine: str, floor_friction: float | None, caster_resistance: float | None, torque_limit: float | None
) -> Any:
    """``--engine``: "reduced", or the multibody settings its flags give; those flags refused with the reduced
    model."""
    given = {"floor_friction": floor_friction, "caster_resistance": caster_resistance, "torque_limit": torque_limit}
    if engine == "reduced":
        for name, value in given.items():
            if value is not None:
                raise UsageError(
                    f"{option(name)} applies to {option('engine', 'mujoco')} only; the reduced model has no floor "
                    "or casters"
                )
        return "reduced"
    from wmrid.sim.multibody_model import MultibodySettings, import_mujoco

    import_mujoco()  # before anything else, so that a missing engine says how to install it
    return MultibodySettings(**{name: value for name, value in given.items() if value is not None})
