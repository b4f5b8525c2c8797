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

import numpy as np

from wmrid.model.robot import Caster, PhysicalParameters, Robot
from wmrid.model.robot_file import robot_to_toml


def _same_columns(caster: Caster, drag: dict[str, float]) -> bool:
    """Whether ``caster`` has the drag columns of the identified caster at (drag["x"], drag["y"]): they depend on y and
    x^2 only (:func:`wmrid.model.dynamics.caster_columns`), so casters at (x, y) and (-x, y) are one parameter."""
    return abs(caster.y - drag["y"]) < 1e-9 and abs(abs(caster.x) - abs(drag["x"])) < 1e-9


def group_resistance(
    casters: tuple[Caster, ...], drags: list[dict[str, float]], loads: list[float] | np.ndarray
) -> tuple[list[float], list[str]]:
    """Each caster's rolling-resistance coefficient that gives the identified drags at rest on the prototype, and why
    (one sentence per caster).  A drag D_k stands for every caster with the same columns (:func:`_same_columns`); the
    ball casters of that group share one coefficient, D_k over their load at rest (``loads``, N, as
    :func:`wmrid.sim.open_loop.settled_caster_loads` gives it); a swivel caster, a negative D or a group carrying no
    load gets 0."""
    resistance = [0.0] * len(casters)
    why = ["no identified drag: resistance 0"] * len(casters)
    for c in drags:
        group = [i for i, k in enumerate(casters) if _same_columns(k, c)]
        total = sum(loads[i] for i in group if casters[i].kind == "ball")
        for i in group:
            if casters[i].kind != "ball":
                why[i] = f"a swivel caster: the identified drag D = {c['D']:.4g} N is not carried (resistance 0)"
            elif c["D"] < 0:
                why[i] = f"identified drag D = {c['D']:.4g} +/- {c['D_std']:.2g} N is negative: resistance 0"
            elif total <= 0:
                why[i] = "the prototype's casters of this group carry no load at rest: resistance 0"
            else:
                resistance[i] = c["D"] / total
                why[i] = (f"resistance = D / {total:.4g} N (the group's load at rest on the prototype), D = "
                          f"{c['D']:.4g} +/- {c['D_std']:.2g} N for the casters at (+-{abs(c['x']):.4g}, "
                          f"{c['y']:.4g}) m")  # fmt: skip
    return resistance, why


def robot_file_text(
    robot: Robot,
    identified: PhysicalParameters,
    notes: dict[str, str],
    provenance: dict[str, str],
    drags: list[dict[str, float]],
    loads: list[float],
    extra: list[str] | None = None,
) -> str:
    """The TOML text (module docstring).  notes: quantity -> "value +/- std unit (source)"; drags: the geometric
    caster model's casters ({"x", "y", "D", "D_std"}); loads: each of ``robot``'s casters' normal load at rest on the
    prototype (:func:`wmrid.sim.open_loop.settled_caster_loads`), N; extra: sentences for the header."""
    found = robot.casters or ()
    resistance, why = group_resistance(found, drags, loads)
    casters = [dataclasses.replace(caster, resistance=resistance[i]) for i, caster in enumerate(found)]
    out = Robot(name=f"{robot.name}_identified", nominal=identified, cad=None, casters=tuple(casters) or None,
                torque_constant=robot.torque_constant, efficiency=robot.efficiency, limits=robot.limits)  # fmt: skip
    lines = []
    section = None
    index = -1
    for line in robot_to_toml(out).splitlines():
        if line.startswith("["):
            section = line
            if line == "[[caster]]":
                index += 1
        key = line.split("=")[0].strip()
        if section == "[nominal]" and key in notes and "(robot file)" not in notes[key]:
            line = f"{line}  # identified: {notes[key]}" if "#" not in line else f"{line}; identified: {notes[key]}"
        elif section == "[[caster]]" and key == "resistance":
            line = f"{line}  # {why[index]}"
        lines.append(line)
    head = ["# wmrid export: the identified robot as a wmrid robot file"]
    head += [f"# {k}: {json.dumps(v)}" for k, v in provenance.items()]
    head += [f"# {json.dumps(e)[1:-1]}" for e in extra or []]
    return "\n".join(head + lines) + "\n"
