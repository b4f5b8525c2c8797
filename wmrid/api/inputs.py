"""Inputs every command shares: a robot (:func:`load_robot`) and a log read with one set of options
(:class:`LogOptions`, :func:`read_log`, :func:`open_log`).

The options are the command line's log-input flags, one field each (``--speed-unit rpm`` is
``LogOptions(speed_unit="rpm")``).  A robot, when given, fills in what the log does not say: the wheel radius for
speeds in m/s, the torque constant and gearbox efficiency for motor currents, the gear ratio for a PWM effort's
conversion.

Imports inside functions: start-up time (a front door: ``import wmrid`` and each function load only what that
function uses).
"""

from __future__ import annotations

import os
from collections.abc import Sequence
from dataclasses import dataclass, fields, replace
from typing import TYPE_CHECKING, Any

from wmrid.core.errors import UsageError, option
from wmrid.model.robot import Robot

if TYPE_CHECKING:
    from wmrid.core.wheel_log import LogStream, WheelLog

__all__ = ["LogOptions", "inspect", "load_robot", "open_log", "read_log"]


@dataclass(frozen=True)
class LogOptions:
    """How to read a log: the same fields for every command.

    The fields are the command line's "Log input" flags, one field each (``--speed-unit rpm`` is
    ``LogOptions(speed_unit="rpm")``; see ``wmrid identify --help``).  The options are checked when made.

    Attributes
    ----------
    columns
        Canonical name -> the file's column name (``{"t": "time", "eta_r": "vel_right"}``), or the CLI's text form
        ``"t=time,eta_r=vel_right"``.
    time_unit
        Unit of the time column: "auto" (float s, floats past 1e13 us, past 1e16 ns; integer ns), "s", "ms", "us"
        or "ns".
    topic
        Bags (MCAP, ROS 1, db3): the JointState (or JSON) topic holding speed and effort.
    velocity_topic
        Bags: the JointState topic with the wheel speeds (or positions).
    effort_topic
        Bags: the JointState topic with the wheel efforts.
    right_joint
        Bags: name of the right wheel joint.
    left_joint
        Bags: name of the left wheel joint.
    time_source
        Bags: which clock stamps a sample: "header" (the header stamps), "log" (log time) or "auto" (the header when
        all stamps are set and in order).
    align
        Split topics: how the efforts are brought to the speeds' times: "zoh" (held from the latest message) or
        "linear" (interpolated).
    velocity_from
        Where the wheel speeds come from: "velocity" (the velocity field), "position" (the positions) or "auto"
        (the positions when there are no speeds).
    speed_unit
        Unit of the logged wheel speeds: "rad/s", "rpm", "deg/s" or "m/s" (at the rim: needs ``wheel_radius``).
    wheel_radius
        Wheel radius, m, > 0, for speeds in m/s (None: the robot's r).
    effort
        What the effort is: "torque" (wheel torque, N m), "current" (motor current, A: needs ``torque_constant``),
        "pwm" or "voltage" (a command).
    effort_unit
        Label of a PWM or voltage effort's unit (None: PWM, V).
    torque_constant
        Motor torque constant k_t, N m/A, > 0, for ``effort="current"`` (None: the robot's).
    gear_ratio
        Gear ratio k_r, > 0, for ``effort="current"`` (None: the robot's k_r).
    efficiency
        Gearbox efficiency in (0, 1], for ``effort="current"`` (None: the robot's, else 1).
    mirror_left
        The left motor is mirrored: change the sign of its speed and effort.
    flip_effort
        The effort's sign is opposite to the speed's on both wheels: change it.
    """

    columns: dict[str, str] | str | None = None
    time_unit: str = "auto"
    topic: str | None = None
    velocity_topic: str | None = None
    effort_topic: str | None = None
    right_joint: str | None = None
    left_joint: str | None = None
    time_source: str = "auto"
    align: str = "linear"
    velocity_from: str = "auto"
    speed_unit: str = "rad/s"
    wheel_radius: float | None = None
    effort: str = "torque"
    effort_unit: str | None = None
    torque_constant: float | None = None
    gear_ratio: float | None = None
    efficiency: float | None = None
    mirror_left: bool = False
    flip_effort: bool = False

    def __post_init__(self) -> None:
        """Checked once, when made: the topic selection (:class:`~wmrid.io.ros.selection.TopicSelection`) and the
        signals' units and numbers (the wheel radius an m/s speed needs may still come from the robot)."""
        from wmrid.io.ros.selection import TopicSelection
        from wmrid.io.signals import check_signal_choices, check_signal_numbers

        TopicSelection(**_subset(self, TopicSelection))
        check_signal_choices(self.speed_unit, self.effort)
        check_signal_numbers(self.wheel_radius, self.torque_constant, self.gear_ratio, self.efficiency)

    def with_robot(self, robot: Robot | None) -> LogOptions:
        """These options with the robot's values where they are not given.

        Parameters
        ----------
        robot
            The robot (None: the options as they are).

        Returns
        -------
        LogOptions
            The options, with the robot's wheel radius for m/s speeds, and its torque constant and efficiency for
            currents, where they are not given.
        """
        if robot is None:
            return self
        changes: dict[str, Any] = {}
        if self.wheel_radius is None and self.speed_unit == "m/s":
            changes["wheel_radius"] = robot.nominal.r
        if self.effort == "current" and self.torque_constant is None:
            changes["torque_constant"] = robot.torque_constant
        if self.effort == "current" and self.efficiency is None:
            changes["efficiency"] = robot.efficiency
        return replace(self, **changes) if changes else self


#: The names of LogOptions' fields (the CLI's log-input parameters).
LOG_OPTION_NAMES = tuple(f.name for f in fields(LogOptions))


def log_options(options: LogOptions | None = None, **overrides: Any) -> LogOptions:
    """``options`` (default: all defaults) with ``overrides`` by field name; an unknown name is a UsageError."""
    unknown = sorted(set(overrides) - set(LOG_OPTION_NAMES))
    if unknown:
        raise UsageError(f"unknown log option {unknown[0]!r}; the options are {', '.join(LOG_OPTION_NAMES)}")
    base = options if options is not None else LogOptions()
    return replace(base, **overrides) if overrides else base


def load_robot(
    spec: str | os.PathLike[str] | Robot,
    *,
    gear_ratio: float | None = None,
    rotor_inertia: float | None = None,
    wheel_radius: float | None = None,
) -> Robot:
    """A robot from a built-in name (``"paper"``, ``"amr"``), a TOML file, or a URDF.

    Parameters
    ----------
    spec
        A built-in name, the path of a robot file (TOML) or of a URDF, or a :class:`Robot`, which is returned as it
        is.
    gear_ratio
        The gear ratio of a URDF robot: required for one (a URDF does not give it).
    rotor_inertia
        kg m^2, the rotor inertia of a URDF robot that has no rotor links; URDF robots only (a robot TOML file gives
        I_r itself).
    wheel_radius
        m, overrides a URDF robot's wheel radius.

    Returns
    -------
    Robot
        The robot.

    Raises
    ------
    UsageError
        A URDF without ``gear_ratio``, or ``rotor_inertia`` for a robot that is not a URDF.
    """
    if isinstance(spec, Robot):
        return spec
    text = os.fspath(spec)
    if text.lower().endswith(".urdf"):
        from wmrid.model.urdf import load_robot_urdf

        if gear_ratio is None:
            raise UsageError(
                f"{option('robot', text)}: a URDF does not give the gear ratio; add {option('gear_ratio', 'KR')} "
                f"(and {option('rotor_inertia')} when the URDF has no rotor links)"
            )
        return load_robot_urdf(text, gear_ratio=gear_ratio, rotor_inertia=rotor_inertia, wheel_radius=wheel_radius)
    if rotor_inertia is not None:
        raise UsageError(f"{option('rotor_inertia')} applies to a URDF robot only; a robot TOML file gives I_r itself")
    from wmrid.model.robot_file import load_robot as load_toml

    return load_toml(text)


def _subset(opts: LogOptions, kind: type) -> dict[str, Any]:
    """The fields of ``opts`` that the dataclass ``kind`` (TopicSelection, SignalOptions) has, by name."""
    return {f.name: getattr(opts, f.name) for f in fields(kind)}


def open_log(
    path: str | os.PathLike[str] | Sequence[str | os.PathLike[str]],
    options: LogOptions | None = None,
    *,
    robot: Robot | None = None,
    data: bytes | None = None,
    **overrides: Any,
) -> LogStream:
    """A log read piece by piece (memory: one piece, whatever the log's length).

    Parameters
    ----------
    path
        A CSV (plain or compressed), Parquet or MCAP file, a ROS 1 or ROS 2 (.db3) bag, a rosbag2 folder, several
        files of one recording, or ``"-"`` for standard input.
    options
        How to read the log (None: the defaults).
    robot
        The robot whose values fill in what the options do not give (wheel radius for m/s speeds, torque constant
        and efficiency for currents, gear ratio).
    data
        The bytes of standard input, when already read (``path="-"``).
    **overrides
        :class:`LogOptions` fields by name, replacing those of ``options``.

    Returns
    -------
    LogStream
        The log, read a piece at a time each time it is iterated.
    """
    from wmrid.io.logs import open_log as open_file

    return open_file(_fspaths(path), data=data, **reader_arguments(log_options(options, **overrides), robot))


def reader_arguments(options: LogOptions | None, robot: Robot | None = None) -> dict[str, Any]:
    """The readers' arguments for ``options`` (with ``robot``'s values where they are not given): columns, time_unit,
    selection, signals and gear_ratio, as :func:`wmrid.io.logs.open_log` and the live readers
    (:mod:`wmrid.io.live`) take them."""
    from wmrid.io.ros.selection import TopicSelection
    from wmrid.io.signals import SignalOptions
    from wmrid.io.table.columns import parse_column_mapping

    opts = (options or LogOptions()).with_robot(robot)
    selection = TopicSelection(**_subset(opts, TopicSelection))
    signals = SignalOptions(
        **{**_subset(opts, SignalOptions), "efficiency": 1.0 if opts.efficiency is None else opts.efficiency}
    )
    mapping = parse_column_mapping(opts.columns) if isinstance(opts.columns, str) and opts.columns else opts.columns
    k_r = robot.nominal.k_r if robot is not None and getattr(robot, "gear_ratio_known", True) else None
    return {
        "columns": mapping or None, "time_unit": opts.time_unit, "selection": selection, "signals": signals,
        "gear_ratio": k_r,
    }  # fmt: skip


def read_log(
    path: str | os.PathLike[str] | Sequence[str | os.PathLike[str]],
    options: LogOptions | None = None,
    *,
    robot: Robot | None = None,
    data: bytes | None = None,
    **overrides: Any,
) -> WheelLog:
    """A whole log in memory, read as :func:`open_log` reads it.

    Parameters
    ----------
    path
        A CSV (plain or compressed), Parquet or MCAP file, a ROS 1 or ROS 2 (.db3) bag, a rosbag2 folder, several
        files of one recording, or ``"-"`` for standard input.
    options
        How to read the log (None: the defaults).
    robot
        The robot whose values fill in what the options do not give (as for :func:`open_log`).
    data
        The bytes of standard input, when already read (``path="-"``).
    **overrides
        :class:`LogOptions` fields by name, replacing those of ``options``.

    Returns
    -------
    WheelLog
        The log: t (n,) s, eta (n, 2) rad/s, tau (n, 2) N m.
    """
    return open_log(path, options, robot=robot, data=data, **overrides).read()


def _fspaths(path: Any) -> str | list[str]:
    return os.fspath(path) if isinstance(path, (str, os.PathLike)) else [os.fspath(p) for p in path]


def inspect(path: str | os.PathLike[str] | Sequence[str | os.PathLike[str]]) -> Any:
    """What the log at ``path`` holds, before any identification (``wmrid inspect``).

    Parameters
    ----------
    path
        The log: a file, or several files of one recording.

    Returns
    -------
    McapInventory or TableInventory
        An :class:`~wmrid.io.inspect.McapInventory` (topics, types, rates, joints) or a
        :class:`~wmrid.io.inspect.TableInventory` (columns, rows, canonical columns found); its ``to_dict`` is the
        JSON.
    """
    from wmrid.io.inspect import inspect_log

    return inspect_log(_fspaths(path))


def read_json_input(path: str, name: str, what: str) -> Any:
    """The JSON document at ``path`` (an input: never overwritten), read in bounded memory (WMRID_MEMORY_BUDGET);
    UsageError naming ``name`` when it cannot be read or is not JSON."""
    import json

    from wmrid.core.errors import cannot_read
    from wmrid.runtime.atomic import register_input
    from wmrid.runtime.limits import memory_budget, read_limited

    register_input(path)
    try:
        raw = read_limited(path, memory_budget(), f"{name}: holds more than {{size}} (WMRID_MEMORY_BUDGET)", UsageError)
    except OSError as err:
        raise UsageError(f"{name}: {cannot_read(err)}") from None
    try:
        return json.loads(raw)
    except (ValueError, RecursionError) as err:
        raise UsageError(f"{name}: not {what} (not JSON: {err})") from None


def given_results(given: Any) -> list[tuple[Any, str]]:
    """[(result, where it came from)] of ``--given``: saved results (``wmrid identify --format json``) by path, or
    :class:`~wmrid.estimators.result.IdentificationResult` objects ("result"); one or a sequence; None: none."""
    if given is None:
        return []
    from wmrid.estimators.result import IdentificationResult, from_dict as result_from_dict

    items = [given] if isinstance(given, (str, os.PathLike, IdentificationResult)) else list(given)
    out = []
    for item in items:
        if isinstance(item, IdentificationResult):
            out.append((item, "result"))
            continue
        source = os.fspath(item)
        out.append((result_from_dict(read_json_input(source, option("given", source), "a saved result"), source),
                    source))  # fmt: skip
    return out
