"""The identified robot as a wmrid robot file (TOML): what ``wmrid simulate --robot`` (both engines) and ``wmrid
identify --robot`` read, so an identified robot can be simulated -- the multibody prototype then builds exactly the MJCF
``wmrid export -o robot.xml`` writes.

The [nominal] set is the identified robot (the platform's m_p, d_x, d_y, I_p and the wheels' friction from the log,
the rest from the robot file it was identified with), each identified value with its std as a comment; there is no
[cad] set (the identified robot is the reference).  The casters keep their place and size; a ball caster's rolling
resistance is the identified drag D_k over its static load when the result has the geometric caster model, else 0
(the result says the casters do not drag).  The original file's [limits] and [motor] tables are kept.
"""

from __future__ import annotations

import dataclasses
import json
import math

from wmrid.model.robot import Caster, PhysicalParameters, Robot, robot_to_toml


def robot_file_text(
    robot: Robot,
    identified: PhysicalParameters,
    notes: dict[str, str],
    provenance: dict[str, str],
    drags: list[dict[str, float]],
    loads: list[float],
) -> str:
    """The TOML text (module docstring).  notes: quantity -> "value +/- std unit (source)"; drags: the geometric
    caster model's casters ({"x", "y", "D"}); loads: each of ``robot``'s casters' static normal load, N."""
    casters: list[Caster] = []
    for i, caster in enumerate(robot.casters or ()):
        resistance = 0.0
        for c in drags:
            if math.hypot(c["x"] - caster.x, c["y"] - caster.y) < 1e-9 and caster.kind == "ball" and loads[i] > 0:
                resistance = max(c["D"], 0.0) / loads[i]
        casters.append(dataclasses.replace(caster, resistance=resistance))
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
