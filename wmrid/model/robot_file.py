"""Robot files: a robot's TOML read (:func:`load_robot`, :func:`robot_from_toml_text`: the nominal and CAD sets of Table
1's parameters, or base parameters, its casters and drive limits, each value checked with the file named) and written
(:func:`robot_to_toml`)."""

from __future__ import annotations

import dataclasses
import json
import math
import sys
from pathlib import Path
from typing import Any

from wmrid.core.errors import RobotFileError, cannot_read
from wmrid.model.robot import (
    _TOO_MANY_CASTERS,
    BASE_KEYS,
    BUILTIN_ROBOTS,
    MAX_CASTERS,
    OPTIONAL,
    PARAMETER_UNITS,
    BaseSet,
    Caster,
    PhysicalParameters,
    Robot,
)
from wmrid.runtime.limits import ROBOT_FILE_LIMIT, read_limited

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover - exercised only on Python 3.10
    import tomli as tomllib


def _parse_base_set(table: object, where: str) -> tuple[BaseSet, list[str], set[str]]:
    """(the base set, what was assumed, the base names assumed) of a [nominal_base] or [cad_base] table."""
    if not isinstance(table, dict):
        raise RobotFileError(f"{where}: expected a table of base parameters")
    known = {*BASE_KEYS, "M11", "M12", "M22", "r", "b", "k_r"}
    unknown = sorted(set(table) - known)
    if unknown:
        raise RobotFileError(f"{where}: unknown key(s) {', '.join(unknown)}; known: {', '.join(sorted(known))}")
    for key, value in table.items():
        if not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(value):
            raise RobotFileError(f"{where}: {key} must be a finite number, got {value!r}")
    small, big = {"m11", "m12", "m22"} & set(table), {"M11", "M12", "M22"} & set(table)
    if (len(small) != 3 and len(big) != 3) or (small and big):
        raise RobotFileError(f"{where}: give the inverse inertia m11, m12, m22 (1/(kg m^2)) or the inertia M11, M12, "
                             "M22 (kg m^2), all three of one of them")  # fmt: skip
    if "Vc" not in table:
        raise RobotFileError(f"{where}: missing Vc (kg m^2)")
    entries = [table[k] for k in (("m11", "m12", "m22") if small else ("M11", "M12", "M22"))]
    if not (entries[0] > 0 and entries[2] > 0 and entries[0] * entries[2] - entries[1] ** 2 > 0):
        raise RobotFileError(f"{where}: the inertia matrix must be positive definite, got {entries}")
    if big:
        det = entries[0] * entries[2] - entries[1] ** 2
        entries = [entries[2] / det, -entries[1] / det, entries[0] / det]
    friction = [table.get(k) for k in BASE_KEYS[4:]]
    assumed, keys = [], set()
    if any(f is None for f in friction):
        keys = {k for k, f in zip(BASE_KEYS[4:], friction, strict=True) if f is None}
        assumed.append(f"{', '.join(sorted(keys))} = 0 (no friction given)")
        friction = [0.0 if f is None else f for f in friction]
    if any(f < 0 for f in friction):
        raise RobotFileError(f"{where}: friction must be >= 0")
    for key in ("r", "b", "k_r"):
        if key in table and table[key] <= 0:
            raise RobotFileError(f"{where}: {key} must be > 0, got {table[key]}")
    theta0 = tuple(float(v) for v in [*entries, table["Vc"], *friction])
    return BaseSet(theta0, table.get("r"), table.get("b"), table.get("k_r")), assumed, keys


#: The parameters a robot file must give: what M and V_c (Eqs. 10-14) depend on most.
REQUIRED = ("I_p", "m_p", "d_x", "I_w", "m_w", "r", "b")


def _parse_set(table: object, where: str) -> tuple[PhysicalParameters, list[str], set[str]]:
    """(the parameters, what was assumed for those not given, the keys assumed) of a [nominal] or [cad] table."""
    if not isinstance(table, dict):
        raise RobotFileError(f"{where}: expected a table of parameters")
    unknown = sorted(set(table) - set(PARAMETER_UNITS))
    if unknown:
        raise RobotFileError(f"{where}: unknown parameter(s) {', '.join(unknown)}; known: {', '.join(PARAMETER_UNITS)}")
    missing = [k for k in REQUIRED if k not in table]
    if missing:
        raise RobotFileError(
            f"{where}: missing parameter(s) {', '.join(missing)} (SI units); a robot file needs at least "
            f"{', '.join(REQUIRED)} (see examples/)"
        )
    values = dict(table)
    assumed: list[str] = []
    keys: set[str] = set()
    for group, make, sentence in OPTIONAL:
        absent = [k for k in group if k not in values]
        if not absent:
            continue
        if len(absent) < len(group) and group[0] != "F_v1":  # a group is given whole or not at all
            raise RobotFileError(f"{where}: give all of {', '.join(group)} or none of them (none: {sentence})")
        for key, value in zip(group, make(values), strict=True):
            if key in absent:
                values[key] = value
                keys.add(key)
        assumed.append(sentence if len(absent) == len(group) else f"{', '.join(absent)} = 0 (not given)")
    try:
        return PhysicalParameters(**values), assumed, keys
    except RobotFileError as err:
        raise RobotFileError(f"{where}: {err}") from None


def _huge_number(value: object) -> list[Any] | None:
    """The keys leading to an integer too large for a float in ``value`` (a parsed TOML document), else None."""
    if isinstance(value, int) and not isinstance(value, bool):
        return [] if abs(value) > _FLOAT_MAX else None
    items = value.items() if isinstance(value, dict) else enumerate(value) if isinstance(value, list) else ()
    for key, item in items:
        found = _huge_number(item)
        if found is not None:
            return [key, *found]
    return None


#: The largest float: an integer beyond it cannot be a parameter (10**400 took Python's float() down with it).
_FLOAT_MAX = int(sys.float_info.max)


def robot_from_toml_text(text: str, source: str) -> Robot:
    try:
        data = tomllib.loads(text)
    except tomllib.TOMLDecodeError as err:
        raise RobotFileError(f"{source}: not valid TOML ({err})") from None
    except RecursionError:
        raise RobotFileError(f"{source}: nested too deeply to be a robot file; see reference/robot-file.md") from None
    except ValueError:  # an integer of more than 4,300 digits: Python's limit on turning text into an int
        raise RobotFileError(
            f"{source}: holds an integer of more than 4,300 digits; a robot file's values are SI numbers such as "
            "12.5 or 3e-4"
        ) from None
    huge = _huge_number(data)
    if huge is not None:
        where = " ".join(  # [nominal] m_p, [[caster]] 2: x, [limits] area 1
            f"[{k}]" if i == 0 and not isinstance(huge[1] if len(huge) > 1 else None, int)
            else f"[[{k}]]" if i == 0 else f"{k + 1}:" if isinstance(k, int) else str(k)
            for i, k in enumerate(huge)
        ).rstrip(":")  # fmt: skip
        raise RobotFileError(
            f"{source} {where}: an integer over 1.8e308, more than any number wmrid computes with; give the value in "
            "SI units, e.g. 12.5 or 3e-4"
        )
    if ("nominal" in data) == ("nominal_base" in data) or ("cad" in data and "cad_base" in data):
        raise RobotFileError(
            f"{source}: give the nominal parameters as one table, [nominal] (physical, Table 1) or [nominal_base] "
            "(m11 m12 m22 Vc ... directly), and the CAD ones likewise, [cad] or [cad_base] (see examples/)"
        )
    friction_names = {"F_v1": "Fv1", "F_v2": "Fv2", "F_d1": "Fd1", "F_d2": "Fd2"}
    if "nominal" in data:
        nominal, assumed, nominal_keys = _parse_set(data["nominal"], f"{source} [nominal]")
        unknown_k_r = "k_r" in nominal_keys
        assumed = [f"[nominal] {a}" for a in assumed]
    else:
        nominal, assumed, _ = _parse_base_set(data["nominal_base"], f"{source} [nominal_base]")
        unknown_k_r = nominal.k_r is None
        assumed = [f"[nominal_base] {a}" for a in assumed]
        assumed.append("[nominal_base] base parameters only: no payload estimate and no simulation")
    cad, unknown_cad = None, ()
    if "cad" in data:
        cad, cad_assumed, cad_keys = _parse_set(data["cad"], f"{source} [cad]")
        assumed += [f"[cad] {a}" for a in cad_assumed]
        unknown_cad = tuple(friction_names[k] for k in friction_names if k in cad_keys)
    elif "cad_base" in data:
        cad, cad_assumed, cad_keys = _parse_base_set(data["cad_base"], f"{source} [cad_base]")
        assumed += [f"[cad_base] {a}" for a in cad_assumed]
        unknown_cad = tuple(n for n in BASE_KEYS[4:] if n in cad_keys)
    name = str(data.get("name", Path(source).stem))
    motor = data.get("motor", {})
    if not isinstance(motor, dict) or set(motor) - {"torque_constant", "efficiency"}:
        raise RobotFileError(f"{source} [motor]: only torque_constant (N m/A) and efficiency may be given")
    for key, value in motor.items():
        ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and value > 0
        if not ok or (key == "efficiency" and value > 1):
            raise RobotFileError(f"{source} [motor]: {key} must be a number > 0 (efficiency <= 1), got {value!r}")
    casters = _parse_casters(data.get("caster"), source)
    return Robot(
        name=name, nominal=nominal, cad=cad, torque_constant=motor.get("torque_constant"),
        efficiency=motor.get("efficiency"), casters=casters, unknown_cad=unknown_cad, assumed=tuple(assumed),
        gear_ratio_known=not unknown_k_r, limits=_parse_limits(data.get("limits"), source),
    )  # fmt: skip


#: Keys of a robot file's [limits] table (SI units: rad/s, rad/s^2, N m, m/s, rad/s, and [W, H] m or "WxH").
LIMIT_KEYS = ("max_wheel_speed", "max_wheel_accel", "max_torque", "max_speed", "max_turn_rate", "area")


def _parse_limits(table: object, source: str) -> tuple[tuple[str, object], ...]:
    """The [limits] table as (key, value) pairs: numbers > 0, and area as [W, H] in m (or the string "WxH")."""
    if table is None:
        return ()
    if not isinstance(table, dict):
        raise RobotFileError(f"{source}: [limits] must be a table of {', '.join(LIMIT_KEYS)}")
    unknown = sorted(set(table) - set(LIMIT_KEYS))
    if unknown:
        raise RobotFileError(f"{source} [limits]: unknown key(s) {', '.join(unknown)}; known: {', '.join(LIMIT_KEYS)}")
    out: list[tuple[str, object]] = []
    for key in LIMIT_KEYS:
        if key not in table:
            continue
        value = table[key]
        if key == "area":
            if isinstance(value, str):
                parts = value.lower().split("x")
                try:
                    value = [float(v) for v in parts]
                except ValueError:
                    value = None
            ok = isinstance(value, list) and len(value) == 2
            ok = ok and all(isinstance(v, (int, float)) and not isinstance(v, bool) for v in value)
            if not ok or not all(math.isfinite(v) and v > 0 for v in value):
                raise RobotFileError(f'{source} [limits]: area must be [W, H] in metres or "WxH", got {table[key]!r}')
            out.append((key, (float(value[0]), float(value[1]))))
            continue
        ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value) and value > 0
        if not ok:
            raise RobotFileError(f"{source} [limits]: {key} must be a number > 0, got {value!r}")
        out.append((key, float(value)))
    return tuple(out)


def _parse_casters(tables: object, source: str) -> tuple[Caster, ...] | None:
    """[[caster]] tables -> casters (None when there are none)."""
    if tables is None:
        return None
    if not isinstance(tables, list) or not all(isinstance(t, dict) for t in tables):
        raise RobotFileError(f"{source}: casters are [[caster]] tables with x, y, radius, kind, resistance, trail")
    if len(tables) > MAX_CASTERS:
        raise RobotFileError(f"{source}: {len(tables):,} [[caster]] tables; {_TOO_MANY_CASTERS}")
    known = {f.name for f in dataclasses.fields(Caster)}
    out = []
    for i, table in enumerate(tables):
        unknown = sorted(set(table) - known)
        if unknown or "x" not in table:
            raise RobotFileError(
                f"{source} [[caster]] {i + 1}: "
                + (f"unknown key(s) {', '.join(unknown)}" if unknown else "needs x (m)")
                + f"; known: {', '.join(sorted(known))}"
            )
        try:
            out.append(Caster(**table))
        except RobotFileError as err:
            raise RobotFileError(f"{source} [[caster]] {i + 1}: {err}") from None
    return tuple(out)


def robot_to_toml(robot: Robot) -> str:
    """Serialise a robot to the TOML form :func:`load_robot` reads (a round trip)."""
    lines = [f"name = {json.dumps(robot.name)}"]  # a TOML basic string: JSON's escapes are TOML's
    sets = [("nominal", robot.nominal)] + ([("cad", robot.cad)] if robot.cad is not None else [])
    for title, params in sets:
        base = isinstance(params, BaseSet)
        lines.append(f"\n[{title}_base]" if base else f"\n[{title}]")
        for key, value in params.to_dict().items():
            lines.append(f"{key} = {value!r}" if base else f"{key} = {value!r}  # {PARAMETER_UNITS[key][0]}")
    for caster in robot.casters or ():
        lines.append("\n[[caster]]")
        for key, value in caster.to_dict().items():
            lines.append(f"{key} = {value!r}" if not isinstance(value, str) else f"{key} = {json.dumps(value)}")
    if robot.limits:
        lines.append("\n[limits]")
        for key, value in robot.limits:
            lines.append(f"{key} = {list(value)!r}" if isinstance(value, tuple) else f"{key} = {value!r}")
    if robot.torque_constant is not None or robot.efficiency is not None:
        lines.append("\n[motor]")
        if robot.torque_constant is not None:
            lines.append(f"torque_constant = {robot.torque_constant!r}  # N m/A")
        if robot.efficiency is not None:
            lines.append(f"efficiency = {robot.efficiency!r}")
    return "\n".join(lines) + "\n"


def load_robot(spec: str) -> Robot:
    """A built-in robot by name (``paper``) or a TOML file path."""
    if spec in BUILTIN_ROBOTS:
        return BUILTIN_ROBOTS[spec]
    path = Path(spec)
    if not path.exists():
        raise RobotFileError(
            f"robot {spec!r}: no such file and no built-in robot of that name (built-in: {', '.join(BUILTIN_ROBOTS)})"
        )
    if path.is_dir():
        raise RobotFileError(f"robot {spec!r} is a directory; give a robot TOML file")
    # runtime.atomic (tempfile, ~10 ms): only a robot file, not a built-in robot
    from wmrid.runtime.atomic import register_input

    register_input(path)
    try:
        text = read_limited(
            path, ROBOT_FILE_LIMIT, f"robot {spec!r}: holds more than {{size}}; a robot TOML file is a few kilobytes",
            RobotFileError,
        ).decode("utf-8")  # fmt: skip
    except OSError as err:
        raise RobotFileError(f"robot file {spec}: {cannot_read(err)}") from None
    except UnicodeDecodeError as err:
        raise RobotFileError(f"robot file {spec}: not UTF-8 text (byte {err.start}); give a robot TOML file") from None
    return robot_from_toml_text(text, str(path))
