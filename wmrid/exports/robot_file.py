"""The identified robot as a wmrid robot file (TOML): what ``wmrid simulate --robot`` (both engines) and ``wmrid
identify --robot`` read, so an identified robot can be simulated -- the multibody prototype then builds exactly the MJCF
``wmrid export -o robot.xml`` writes.

The [nominal] set is the identified robot (the platform's m_p, d_x, d_y, I_p and the wheels' friction from the log,
the rest from the robot file it was identified with), each identified value with its std as a comment; there is no
[cad] set (the identified robot is the reference).  The casters keep their place and size.  A ball caster's rolling
resistance (the prototype multiplies it by the caster's normal load) is the identified drag D_k over the load the
prototype's casters carry at rest, shared by the casters D_k stands for (those with the same drag columns), when the
result has the geometric caster model; else 0 (the result says the casters do not drag).  The original file's
[limits] and [motor] tables are kept.
"""

from __future__ import annotations

import dataclasses
import json

from wmrid.model.robot import Caster, PhysicalParameters, Robot, robot_to_toml


def _same_columns(caster: Caster, drag: dict[str, float]) -> bool:
    """Whether ``caster`` has the drag columns of the identified caster at (drag["x"], drag["y"]): they depend on y and
    x^2 only (:func:`wmrid.model.dynamics.caster_columns`), so casters at (x, y) and (-x, y) are one parameter."""
    return abs(caster.y - drag["y"]) < 1e-9 and abs(abs(caster.x) - abs(drag["x"])) < 1e-9


def robot_file_text(
    robot: Robot,
    identified: PhysicalParameters,
    notes: dict[str, str],
    provenance: dict[str, str],
    drags: list[dict[str, float]],
    loads: list[float],
) -> str:
    """The TOML text (module docstring).  notes: quantity -> "value +/- std unit (source)"; drags: the geometric
    caster model's casters ({"x", "y", "D"}); loads: each of ``robot``'s casters' normal load at rest on the prototype
    (:func:`wmrid.sim.multibody.settled_caster_loads`), N."""
    casters: list[Caster] = []
    group_drag = [0.0] * len(robot.casters or ())
    for c in drags:  # a drag D_k stands for every caster with the same columns: the same y and |x| (module docstring)
        group = [i for i, k in enumerate(robot.casters or ()) if _same_columns(k, c)]
        total = sum(loads[i] for i in group if robot.casters[i].kind == "ball")
        for i in group:
            if robot.casters[i].kind == "ball" and total > 0:
                group_drag[i] = max(c["D"], 0.0) / total  # one coefficient for the group: load-shared
    for i, caster in enumerate(robot.casters or ()):
        casters.append(dataclasses.replace(caster, resistance=group_drag[i]))
    out = Robot(name=f"{robot.name}_identified", nominal=identified, cad=None, casters=tuple(casters) or None,
                torque_constant=robot.torque_constant, efficiency=robot.efficiency, limits=robot.limits)  # fmt: skip
    lines = []
    section = None
    for line in robot_to_toml(out).splitlines():
        if line.startswith("["):
            section = line
        key = line.split("=")[0].strip()
        if section == "[nominal]" and key in notes and "(robot file)" not in notes[key]:
            line = f"{line}; identified: {notes[key]}"
        lines.append(line)
    head = ["# wmrid export: the identified robot as a wmrid robot file"]
    head += [f"# {k}: {json.dumps(v)}" for k, v in provenance.items()]
    if not drags:
        head.append("# the result has no caster drag: the casters' rolling resistance is 0")
    return "\n".join(head + lines) + "\n"
