"""The ``wmrid`` command line: a thin Typer layer over typed functions.

Heavy modules (numpy, pandas, numba, rich) are imported inside the commands so that ``wmrid --help``
answers at once.  :func:`main` is the one place that maps errors to exit codes and messages.
"""

from __future__ import annotations

import contextlib
import os
import signal
import sys
from enum import Enum
from pathlib import Path
from typing import Annotated, Any

import typer

from wmrid import __version__
from wmrid.core.errors import ExitStatus, LogFormatError, ReaderGone, UsageError, WmridError, option_style

app = typer.Typer(
    name="wmrid",
    help="Identify the dynamic parameters of differential-drive wheeled mobile robots from their logs "
    "(Hoang & Kang 2015).",
    no_args_is_help=True,
    add_completion=False,
    pretty_exceptions_enable=False,
    rich_markup_mode=None,
)


class OutputFormat(str, Enum):
    auto = "auto"
    table = "table"
    json = "json"


class MethodChoice(str, Enum):
    observer = "observer"
    idim = "idim"
    iv = "iv"
    rls = "rls"
    oe = "oe"


class FormChoice(str, Enum):
    auto = "auto"
    paper = "paper"
    general = "general"


class TimeUnit(str, Enum):
    auto = "auto"
    s = "s"
    ms = "ms"
    us = "us"
    ns = "ns"


class TorqueHold(str, Enum):
    zoh = "zoh"
    foh = "foh"


class Trajectory(str, Enum):
    sinusoid = "sinusoid"
    reversing = "reversing"


class Engine(str, Enum):
    reduced = "reduced"
    mujoco = "mujoco"


class TimeSource(str, Enum):
    auto = "auto"
    header = "header"
    log = "log"


class AlignRule(str, Enum):
    zoh = "zoh"
    linear = "linear"


class VelocityFrom(str, Enum):
    auto = "auto"
    velocity = "velocity"
    position = "position"


class SpeedUnit(str, Enum):
    rad_s = "rad/s"
    rpm = "rpm"
    deg_s = "deg/s"
    m_s = "m/s"


class EffortKind(str, Enum):
    torque = "torque"
    current = "current"
    pwm = "pwm"
    voltage = "voltage"


_LOG_PANEL = "Log input (MCAP topics, units, effort)"
TopicOpt = Annotated[
    str | None,
    typer.Option(help="MCAP: the JointState (or JSON) topic holding speed and effort.", rich_help_panel=_LOG_PANEL),
]
VelocityTopicOpt = Annotated[
    str | None,
    typer.Option(help="MCAP: the JointState topic with the wheel speeds (or positions).", rich_help_panel=_LOG_PANEL),
]
EffortTopicOpt = Annotated[
    str | None, typer.Option(help="MCAP: the JointState topic with the wheel efforts.", rich_help_panel=_LOG_PANEL)
]
RightJointOpt = Annotated[
    str | None, typer.Option(help="MCAP: name of the right wheel joint.", rich_help_panel=_LOG_PANEL)
]
LeftJointOpt = Annotated[
    str | None, typer.Option(help="MCAP: name of the left wheel joint.", rich_help_panel=_LOG_PANEL)
]
TimeSourceOpt = Annotated[
    TimeSource,
    typer.Option(
        help="MCAP: header stamps, log time, or auto (header when all set and in order).", rich_help_panel=_LOG_PANEL
    ),
]
AlignOpt = Annotated[
    AlignRule,
    typer.Option(
        help="Split topics: effort held from the latest message (zoh) or interpolated (linear).",
        rich_help_panel=_LOG_PANEL,
    ),
]
VelocityFromOpt = Annotated[
    VelocityFrom,
    typer.Option(
        help="Wheel speed from the velocity field, from positions, or auto (positions when no speeds).",
        rich_help_panel=_LOG_PANEL,
    ),
]
SpeedUnitOpt = Annotated[
    SpeedUnit,
    typer.Option(
        help="Unit of the logged wheel speeds (m/s: at the rim, needs the radius).", rich_help_panel=_LOG_PANEL
    ),
]
WheelRadiusOpt = Annotated[
    float | None,
    typer.Option(help="Wheel radius, m (for m/s speeds; default: the robot's r).", rich_help_panel=_LOG_PANEL),
]
EffortOpt = Annotated[
    EffortKind,
    typer.Option(
        help="What the effort is: wheel torque, motor current (A), or a PWM/voltage command.",
        rich_help_panel=_LOG_PANEL,
    ),
]
EffortUnitOpt = Annotated[
    str | None, typer.Option(help="Label of a PWM/voltage effort's unit (default PWM, V).", rich_help_panel=_LOG_PANEL)
]
TorqueConstantOpt = Annotated[
    float | None,
    typer.Option(help="Motor torque constant k_t, N m/A (for --effort current).", rich_help_panel=_LOG_PANEL),
]
GearRatioOpt = Annotated[
    float | None,
    typer.Option(help="Gear ratio k_r (for --effort current; default: the robot's k_r).", rich_help_panel=_LOG_PANEL),
]
EfficiencyOpt = Annotated[
    float, typer.Option(help="Gearbox efficiency in (0, 1] (for --effort current).", rich_help_panel=_LOG_PANEL)
]
FlipEffortOpt = Annotated[
    bool,
    typer.Option(
        help="The effort's sign is opposite to the speed's on both wheels: change it.", rich_help_panel=_LOG_PANEL
    ),
]
MirrorLeftOpt = Annotated[
    bool,
    typer.Option(
        help="The left motor is mirrored: change the sign of its speed and effort.", rich_help_panel=_LOG_PANEL
    ),
]


def _read_wheel_log(
    log: str,
    columns: str | None,
    time_unit: str,
    robot_obj,
    *,
    data: bytes | None = None,
    whole: bool = True,
    **log_options,
):
    """Read LOG with the log-input options (shared by the commands that read logs; Enum values accepted).

    whole : the log in memory (a WheelLog); else a LogStream, read piece by piece when iterated.
    """
    from wmrid.api.inputs import open_log

    stream = open_log(log, _log_opts(columns, time_unit, log_options), robot=robot_obj, data=data)
    return stream.read() if whole else stream


def _log_opts(columns: str | None, time_unit: str, log_options: dict):
    """The :class:`wmrid.api.inputs.LogOptions` of a command's log-input flags."""
    from wmrid.api.inputs import LogOptions

    return LogOptions(columns=columns, time_unit=time_unit, **log_options)


#: The log-input options every log-reading command takes (names of its parameters).
_LOG_OPTIONS = (
    "topic", "velocity_topic", "effort_topic", "right_joint", "left_joint", "time_source", "align", "velocity_from",
    "speed_unit", "wheel_radius", "effort", "effort_unit", "torque_constant", "gear_ratio", "efficiency",
    "mirror_left", "flip_effort",
)  # fmt: skip


def _log_options(params: dict) -> dict:
    """The log-input options out of a command's parameters, Enum choices as their plain values."""
    return {name: params[name].value if isinstance(params[name], Enum) else params[name] for name in _LOG_OPTIONS}


RotorInertiaOpt = Annotated[
    float | None,
    typer.Option(help="URDF robots: motor rotor inertia I_r, kg m^2 (when the URDF has no rotor links)."),
]


def _load_robot(spec: str, gear_ratio: float | None, rotor_inertia: float | None, wheel_radius: float | None = None):
    """A robot from a built-in name, a TOML file, or a URDF (which needs the gear ratio from --gear-ratio)."""
    from wmrid.api.inputs import load_robot

    return load_robot(spec, gear_ratio=gear_ratio, rotor_inertia=rotor_inertia, wheel_radius=wheel_radius)


def _version(value: bool) -> None:
    if value:
        typer.echo(f"wmrid {__version__}")
        raise typer.Exit()


@app.callback()
def _root(
    debug: Annotated[bool, typer.Option("--debug", help="Show the full traceback of any error.")] = False,
    version: Annotated[
        bool, typer.Option("--version", callback=_version, is_eager=True, help="Print the version and exit.")
    ] = False,
) -> None:
    """wmrid: observer-based dynamic parameter identification for wheeled mobile robots."""


def _stderr_console():
    from rich.console import Console

    return Console(stderr=True)


_METHOD_PANEL = "Method (observer, or a classical rival; see wmrid compare)"
MethodOpt = Annotated[
    MethodChoice,
    typer.Option(
        help="observer (the paper's, default), idim (least squares on filtered accelerations), rls (recursive "
        "least squares with forgetting), oe (output error from the observer's estimate).",
        rich_help_panel=_METHOD_PANEL,
    ),
]
CutoffOpt = Annotated[
    float | None,
    typer.Option(
        "--cutoff", help="idim/rls: low-pass cutoff of speeds and efforts, Hz (default: from the log).",
        rich_help_panel=_METHOD_PANEL,
    ),
]  # fmt: skip
WeightedOpt = Annotated[
    bool, typer.Option("--weighted", help="idim: two-step weighted least squares.", rich_help_panel=_METHOD_PANEL)
]
ForgettingOpt = Annotated[
    float,
    typer.Option(help="rls: forgetting factor in (0, 1]; 1 = plain least squares.", rich_help_panel=_METHOD_PANEL),
]
DelayOpt = Annotated[
    str | None,
    typer.Option(
        "--delay",
        metavar="auto|SECONDS",
        help="The efforts are stamped SECONDS later than the speeds (two topics, two clocks; negative: earlier): "
        "read them that much earlier.  auto: estimate the delay from the log and apply it when significant (the "
        "output states it).  Reads the log into memory.  Default: as stamped, or auto when the efforts come from "
        "another topic than the speeds.",
    ),
]


ControlRateOpt = Annotated[
    float | None,
    typer.Option(
        "--control-rate",
        metavar="HZ",
        help="The controller updated the (held) effort at HZ, faster than the log: each step is held over its "
        "sub-steps, the unlogged values interpolated (e.g. a 1 kHz controller logged at 100 Hz).",
    ),
]


class FrictionChoice(str, Enum):
    auto = "auto"
    wheel = "wheel"
    wheel_caster = "wheel+caster"


FrictionOpt = Annotated[
    FrictionChoice,
    typer.Option(
        "--friction",
        help="wheel: viscous and Coulomb friction per wheel (Eqs. 15-17); wheel+caster: also the casters' rolling "
        "drag, one drag force per caster when --robot lists [[caster]] positions (else two terms, Cv against "
        "speed and Cw against turning), for the observer, idim, rls and oe (oe and --validate need the positions); "
        "auto: both, and the caster model when the log shows the drag (a Wald test, p < 0.001; the output says "
        "which and why).",
    ),
]


ValidateOpt = Annotated[
    str | None,
    typer.Option(
        "--validate",
        metavar="OTHER",
        help="Also predict the wheel speeds of log OTHER (read with the same options) from its efforts with the "
        "identified model, and report the fit % per wheel.",
    ),
]


@app.command()
def identify(
    log: Annotated[
        str, typer.Argument(metavar="LOG", help="Log file (.csv, .parquet, .mcap) or - for standard input.")
    ],
    robot: Annotated[
        str | None,
        typer.Option(
            help="Robot: built-in name ('paper'), TOML file, or URDF (with --gear-ratio); starts the estimate."
        ),
    ] = None,
    columns: Annotated[
        str | None, typer.Option(help="Column mapping, e.g. t=time,eta_r=vel_right,tau_l=effort_left.")
    ] = None,
    time_unit: Annotated[
        TimeUnit, typer.Option(help="Unit of the time column (auto: float s, integer ns).")
    ] = TimeUnit.auto,
    form: Annotated[
        FormChoice, typer.Option(help="Regressor: paper (7 columns, wheels keep one sign), general (8), auto.")
    ] = FormChoice.auto,
    k: Annotated[
        float, typer.Option("--k", help="Observer/filter gain k of Eqs. 26-30, 1/s (paper: 1; see README).")
    ] = 10.0,
    alpha: Annotated[
        float, typer.Option(help="Initial Gamma = alpha I (Eq. 33): weight of the start value (paper: 5000).")
    ] = 1e-10,
    box_width: Annotated[
        float,
        typer.Option(help="Half-width of the parameter box around the nominal values, in units of max(|theta|, m_ii)."),
    ] = 10.0,
    torque_hold: Annotated[
        TorqueHold,
        typer.Option(help="Torque between samples: zoh (held, as a digital controller applies it) or foh (linear)."),
    ] = TorqueHold.zoh,
    output_format: Annotated[
        OutputFormat, typer.Option("--format", help="table, json, or auto (table on a terminal, json in a pipe).")
    ] = OutputFormat.auto,
    output: Annotated[Path | None, typer.Option("--output", "-o", help="Write the JSON result to this file.")] = None,
    out: Annotated[
        Path | None,
        typer.Option("--out", help="Write the estimates over time and the prediction errors as an MCAP (JSON topic)."),
    ] = None,
    force: Annotated[bool, typer.Option(help="Overwrite an existing output file.")] = False,
    payload: Annotated[
        bool,
        typer.Option(
            "--payload",
            help="Also estimate the payload carried (mass, x, y, inertia) against --robot's unloaded parameters.",
        ),
    ] = False,
    topic: TopicOpt = None,
    velocity_topic: VelocityTopicOpt = None,
    effort_topic: EffortTopicOpt = None,
    right_joint: RightJointOpt = None,
    left_joint: LeftJointOpt = None,
    time_source: TimeSourceOpt = TimeSource.auto,
    align: AlignOpt = AlignRule.linear,
    velocity_from: VelocityFromOpt = VelocityFrom.auto,
    speed_unit: SpeedUnitOpt = SpeedUnit.rad_s,
    wheel_radius: WheelRadiusOpt = None,
    effort: EffortOpt = EffortKind.torque,
    effort_unit: EffortUnitOpt = None,
    torque_constant: TorqueConstantOpt = None,
    gear_ratio: GearRatioOpt = None,
    efficiency: EfficiencyOpt = None,
    mirror_left: MirrorLeftOpt = False,
    flip_effort: FlipEffortOpt = False,
    rotor_inertia: RotorInertiaOpt = None,
    method: MethodOpt = MethodChoice.observer,
    cutoff: CutoffOpt = None,
    weighted: WeightedOpt = False,
    forgetting: ForgettingOpt = 1.0,
    validate: ValidateOpt = None,
    control_rate: ControlRateOpt = None,
    delay: DelayOpt = None,
    friction: FrictionOpt = FrictionChoice.auto,
) -> None:
    """Identify the base parameters [m11 m12 m22 Vc Fv1 Fv2 Fd1 Fd2] of the robot that recorded LOG."""
    from wmrid.api.identification import identify as run_identify
    from wmrid.core.atomic import write_json
    from wmrid.reporting.render import print_identification, to_json

    robot_obj = _load_robot(robot, gear_ratio, rotor_inertia, wheel_radius) if robot is not None else None
    progress_cb, finish = _progress("identify")
    try:
        result = run_identify(
            log, robot_obj, method=method.value, validate=validate,
            options=_log_opts(columns, time_unit.value, _log_options(locals())), form=form.value, k=k, alpha=alpha,
            box_width=box_width, torque_hold=torque_hold.value, payload=payload, control_rate=control_rate,
            delay=delay, friction=friction.value, cutoff=cutoff, weighted=weighted, forgetting=forgetting,
            progress=progress_cb,
        )  # fmt: skip
    finally:
        finish()
    payload = result.to_dict()
    if output is not None:
        write_json(str(output), payload, force=force)
    if out is not None:
        _write_estimates(result, out, force)
    if _on_stdout(output):
        return  # the result went to standard output already: a second document there would not be JSON
    fmt = output_format.value
    if fmt == "auto":
        fmt = "table" if sys.stdout.isatty() else "json"
    if fmt == "json":
        sys.stdout.write(to_json(payload) + "\n")
    else:
        from rich.console import Console

        print_identification(result, Console())


@app.command()
def inspect(
    log: Annotated[
        str, typer.Argument(metavar="LOG", help="Log file (.mcap, .csv, .parquet) or - for standard input.")
    ],
    output_format: Annotated[
        OutputFormat, typer.Option("--format", help="table, json, or auto (table on a terminal, json in a pipe).")
    ] = OutputFormat.auto,
) -> None:
    """What LOG holds: topics, types, counts, rates, time range and JointState joints (MCAP), or columns."""
    from wmrid.io.inspect import inspect_log
    from wmrid.reporting.render import print_inspection, to_json

    info = inspect_log(log)
    fmt = output_format.value
    if fmt == "auto":
        fmt = "table" if sys.stdout.isatty() else "json"
    if fmt == "json":
        sys.stdout.write(to_json(info) + "\n")
    else:
        from rich.console import Console

        print_inspection(info, Console())


@app.command()
def report(
    input_: Annotated[
        str,
        typer.Argument(
            metavar="INPUT", help="A log (identified on the fly) or an `identify --format json` result; - for stdin."
        ),
    ],
    output: Annotated[
        Path | None, typer.Option("--output", "-o", help="Write the report: .html (self-contained), .md or .json.")
    ] = None,
    truth: Annotated[
        Path | None, typer.Option(help='Ground truth JSON {"parameters": {"m11": ...}} (the simulator\'s sidecar).')
    ] = None,
    residuals: Annotated[
        Path | None, typer.Option(help="Export the prediction errors over time (t, e_r, e_l) as .csv or .parquet.")
    ] = None,
    robot: Annotated[str | None, typer.Option(help="Robot (name, TOML or URDF), as for identify.")] = None,
    columns: Annotated[str | None, typer.Option(help="Column mapping, as for identify.")] = None,
    time_unit: Annotated[TimeUnit, typer.Option(help="Unit of the time column.")] = TimeUnit.auto,
    form: Annotated[FormChoice, typer.Option(help="Regressor form, as for identify.")] = FormChoice.auto,
    k: Annotated[float, typer.Option("--k", help="Observer gain, 1/s.")] = 10.0,
    alpha: Annotated[float, typer.Option(help="Initial Gamma = alpha I.")] = 1e-10,
    torque_hold: Annotated[TorqueHold, typer.Option(help="zoh or foh.")] = TorqueHold.zoh,
    payload: Annotated[bool, typer.Option("--payload", help="Also estimate the payload (needs --robot).")] = False,
    force: Annotated[bool, typer.Option(help="Overwrite existing output files.")] = False,
    topic: TopicOpt = None,
    velocity_topic: VelocityTopicOpt = None,
    effort_topic: EffortTopicOpt = None,
    right_joint: RightJointOpt = None,
    left_joint: LeftJointOpt = None,
    time_source: TimeSourceOpt = TimeSource.auto,
    align: AlignOpt = AlignRule.linear,
    velocity_from: VelocityFromOpt = VelocityFrom.auto,
    speed_unit: SpeedUnitOpt = SpeedUnit.rad_s,
    wheel_radius: WheelRadiusOpt = None,
    effort: EffortOpt = EffortKind.torque,
    effort_unit: EffortUnitOpt = None,
    torque_constant: TorqueConstantOpt = None,
    gear_ratio: GearRatioOpt = None,
    efficiency: EfficiencyOpt = None,
    mirror_left: MirrorLeftOpt = False,
    flip_effort: FlipEffortOpt = False,
    rotor_inertia: RotorInertiaOpt = None,
    method: MethodOpt = MethodChoice.observer,
    cutoff: CutoffOpt = None,
    weighted: WeightedOpt = False,
    forgetting: ForgettingOpt = 1.0,
    validate: ValidateOpt = None,
    control_rate: ControlRateOpt = None,
    delay: DelayOpt = None,
    friction: FrictionOpt = FrictionChoice.auto,
) -> None:
    """Tables (paper Tables 2 and 3), comparison with nominal/CAD/truth, diagnostics and figures for INPUT."""
    import json

    from wmrid.core.atomic import atomic_write_text, register_input, write_json
    from wmrid.core.limits import memory_budget, read_limited
    from wmrid.io.sources import open_source as _open_source
    from wmrid.reporting.report import build_report, to_html, to_json_dict, to_markdown

    suffix = output.suffix.lower() if output is not None else None
    if suffix not in (None, ".html", ".htm", ".md", ".json"):
        raise UsageError(f"-o {output}: the report format comes from the suffix: .html, .md or .json")
    truth_params = _load_truth(truth) if truth is not None else None
    if input_ == "-" and validate == "-":
        raise UsageError("INPUT and --validate cannot both be standard input; give one of them as a file")
    source = _open_source(input_)
    head = source.head(64).lstrip()
    result = log = None
    if head.startswith(b"{"):
        if validate is not None or method != MethodChoice.observer:
            raise UsageError(
                f"{source.name}: --validate and --method need a log as INPUT, not a saved result; run "
                "`wmrid identify LOG --method ... --validate OTHER --format json` and report its output"
            )
        if source.data is None:
            register_input(source.path)
        raw = source.data if source.data is not None else read_limited(
            source.path, memory_budget(), f"{source.name}: holds more than {{size}} (WMRID_MEMORY_BUDGET)", UsageError
        )  # fmt: skip
        try:
            data = json.loads(raw)
        except RecursionError:
            raise UsageError(f"{source.name}: nested too deeply to be a saved result") from None
        except ValueError as err:
            raise UsageError(f"{source.name}: starts like JSON but is not valid JSON ({err})") from err
    else:
        from wmrid.api.identification import identify as run_identify

        robot_obj = _load_robot(robot, gear_ratio, rotor_inertia, wheel_radius) if robot is not None else None
        log_opts = _log_opts(columns, time_unit.value, _log_options(locals()))
        log = _read_wheel_log(input_, columns, time_unit.value, robot_obj, **_log_options(locals()), data=source.data)
        result = run_identify(
            log, robot_obj, method=method.value, validate=validate, options=log_opts, form=form.value, k=k,
            alpha=alpha, torque_hold=torque_hold.value, payload=payload, control_rate=control_rate, delay=delay,
            friction=friction.value, cutoff=cutoff, weighted=weighted, forgetting=forgetting,
        )  # fmt: skip
        data = result.to_dict()
    figures = suffix in (".html", ".htm", ".md")
    if result is None:  # a saved result: whatever it lacks or holds malformed is named, with the file
        if isinstance(data, dict) and not data.get("source"):
            data["source"] = source.name
        try:
            rep = build_report(data, truth=truth_params, figures=figures)
        except WmridError:
            raise
        except (KeyError, TypeError, ValueError, IndexError, AttributeError) as err:
            what = f"no {err.args[0]!r}" if isinstance(err, KeyError) and err.args else _one_line(str(err))
            raise LogFormatError(
                f"{source.name}: not a complete identify result ({what}); give a log, or the unedited output of "
                "`wmrid identify LOG --format json`"
            ) from err
    else:
        rep = build_report(data, result=result, log=log, truth=truth_params, figures=figures)
    if residuals is not None:
        _write_residuals(rep, result, log, data, residuals, force)
    if suffix in (".html", ".htm"):
        atomic_write_text(output, to_html(rep), force=force)
    elif suffix == ".md":
        atomic_write_text(output, to_markdown(rep), force=force)
    elif suffix == ".json":
        write_json(str(output), to_json_dict(rep), force=force)
    else:
        from rich.console import Console

        from wmrid.reporting.render import print_report

        print_report(rep, Console())
    if output is not None:
        _stderr_console().print(f"wrote {output}")


def _load_truth(path: Path) -> dict[str, float]:
    """The "parameters" of a truth file (the simulator's sidecar), name -> value."""
    import json

    from wmrid.core.atomic import register_input

    register_input(path)
    try:
        return {k: float(v) for k, v in json.loads(path.read_text(encoding="utf-8"))["parameters"].items()}
    except (OSError, ValueError, KeyError, TypeError, AttributeError) as err:
        raise UsageError(f"--truth {path}: not a truth file {{'parameters': {{'m11': ...}}}} ({err})") from err


@app.command()
def compare(
    log: Annotated[
        str, typer.Argument(metavar="LOG", help="Log file (.csv, .parquet, .mcap) or - for standard input.")
    ],
    robot: Annotated[
        str | None, typer.Option(help="Robot (name, TOML or URDF): starts the observer and gives nominal/CAD values.")
    ] = None,
    truth: Annotated[
        Path | None, typer.Option(help='Ground truth JSON {"parameters": {"m11": ...}} (the simulator\'s sidecar).')
    ] = None,
    validate: ValidateOpt = None,
    control_rate: ControlRateOpt = None,
    delay: DelayOpt = None,
    methods: Annotated[
        str, typer.Option(help="Comma-separated methods to run, of observer, idim, iv, rls, oe.")
    ] = "observer,idim,rls,oe",
    columns: Annotated[str | None, typer.Option(help="Column mapping, as for identify.")] = None,
    time_unit: Annotated[TimeUnit, typer.Option(help="Unit of the time column.")] = TimeUnit.auto,
    torque_hold: Annotated[TorqueHold, typer.Option(help="zoh or foh (observer and oe).")] = TorqueHold.zoh,
    cutoff: CutoffOpt = None,
    weighted: WeightedOpt = False,
    forgetting: ForgettingOpt = 1.0,
    output_format: Annotated[
        OutputFormat, typer.Option("--format", help="table, json, or auto (table on a terminal, json in a pipe).")
    ] = OutputFormat.auto,
    output: Annotated[
        Path | None, typer.Option("--output", "-o", help="Write the JSON comparison to this file.")
    ] = None,
    force: Annotated[bool, typer.Option(help="Overwrite an existing output file.")] = False,
    topic: TopicOpt = None,
    velocity_topic: VelocityTopicOpt = None,
    effort_topic: EffortTopicOpt = None,
    right_joint: RightJointOpt = None,
    left_joint: LeftJointOpt = None,
    time_source: TimeSourceOpt = TimeSource.auto,
    align: AlignOpt = AlignRule.linear,
    velocity_from: VelocityFromOpt = VelocityFrom.auto,
    speed_unit: SpeedUnitOpt = SpeedUnit.rad_s,
    wheel_radius: WheelRadiusOpt = None,
    effort: EffortOpt = EffortKind.torque,
    effort_unit: EffortUnitOpt = None,
    torque_constant: TorqueConstantOpt = None,
    gear_ratio: GearRatioOpt = None,
    efficiency: EfficiencyOpt = None,
    mirror_left: MirrorLeftOpt = False,
    flip_effort: FlipEffortOpt = False,
    rotor_inertia: RotorInertiaOpt = None,
    friction: FrictionOpt = FrictionChoice.auto,
) -> None:
    """Run every identification method on LOG: estimates, standard errors, errors against --truth, fit on
    --validate OTHER, run time.  Every method identifies the same friction model (--friction)."""
    from wmrid.api.identification import compare as run_compare
    from wmrid.core.atomic import write_json
    from wmrid.reporting.render import print_comparison, to_json

    truth_params = _load_truth(truth) if truth is not None else None
    robot_obj = _load_robot(robot, gear_ratio, rotor_inertia, wheel_radius) if robot is not None else None
    data = run_compare(
        log, robot_obj, methods=methods.split(","), validate=validate, truth=truth_params,
        options=_log_opts(columns, time_unit.value, _log_options(locals())), torque_hold=torque_hold.value,
        control_rate=control_rate, delay=delay, friction=friction.value, cutoff=cutoff, weighted=weighted,
        forgetting=forgetting,
    )  # fmt: skip
    if output is not None:
        write_json(str(output), data, force=force)
    if _on_stdout(output):
        return  # the result went to standard output already
    fmt = output_format.value
    if fmt == "auto":
        fmt = "table" if sys.stdout.isatty() else "json"
    if fmt == "json":
        sys.stdout.write(to_json(data) + "\n")
    else:
        from rich.console import Console

        print_comparison(data, Console())


def _write_residuals(rep, result, log, data, path: Path, force: bool) -> None:
    """Residuals over time: with the log, every sample's torque residual (N m) plus the nearest recorded
    prediction error (rad/s) and lambda_min; from a saved result, its history only."""
    import pandas as pd

    from wmrid.io.logs import write_log

    if result is not None and "torque" in rep.residuals:
        log_t = rep.residuals["torque"]["residual"]
        hist = result.history
        frame = pd.DataFrame({"t": hist.t, "e_r": hist.e[:, 0], "e_l": hist.e[:, 1], "lambda_min": hist.lambda_min})
        full = pd.DataFrame({"t": log.t - log.t[0], "tau_res_r": log_t[:, 0], "tau_res_l": log_t[:, 1]})
        frame = pd.merge_asof(full, frame, on="t", direction="nearest")
    elif result is not None:
        hist = result.history
        frame = pd.DataFrame({"t": hist.t, "e_r": hist.e[:, 0], "e_l": hist.e[:, 1], "lambda_min": hist.lambda_min})
    elif "history" in data:
        h = data["history"]
        frame = pd.DataFrame({"t": h["t"], "e_r": h["e_r"], "e_l": h["e_l"], "lambda_min": h["lambda_min"]})
    else:
        raise UsageError("--residuals: this result holds no history; give the log itself")
    write_log(frame, str(path), force=force)


def _write_estimates(result, path: Path, force: bool) -> None:
    """The decimated history of an identification as an MCAP JSON topic /wmrid/estimates."""
    from wmrid.core.atomic import to_json_text
    from wmrid.io.mcap.writer import write_series_mcap

    if path.suffix.lower() != ".mcap":
        raise UsageError(f"--out {path}: the estimates are written as MCAP; name the file .mcap")
    hist = result.history
    series = {name: hist.theta[:, i // hist.theta.shape[2], i % hist.theta.shape[2]] for i, name in
              enumerate(result.form.theta_names())}  # fmt: skip
    series["e_r"] = hist.e[:, 0]
    series["e_l"] = hist.e[:, 1]
    series["lambda_min"] = hist.lambda_min
    write_series_mcap(str(path), hist.t, series, force=force, metadata={"result": to_json_text(result.to_dict())})


def _progress(label: str):
    """(callback(done, total), finish): a rich progress bar on stderr, shown for logs of a million samples
    or more when stderr is a terminal; else no-ops."""
    if not sys.stderr.isatty():
        return None, lambda: None
    state: dict = {}

    def update(done: int, total: int) -> None:
        if total < 1_000_000:
            return
        if not state:
            from rich.progress import Progress

            bar = Progress(console=_stderr_console(), transient=True)
            state["bar"], state["task"] = bar, bar.add_task(label, total=total)
            bar.start()
        state["bar"].update(state["task"], completed=done)

    def finish() -> None:
        if state:
            state["bar"].stop()

    return update, finish


_CHANGE_PANEL = "Change of the dynamics during the run (one per run)"
LoadAtOpt = Annotated[
    str | None,
    typer.Option(
        "--load-at",
        metavar="T",
        help="Load the --payload at T s: unloaded before, loaded from the first 1 ms control period starting at "
        "or after T.",
        rich_help_panel=_CHANGE_PANEL,
    ),
]
DropAtOpt = Annotated[
    str | None,
    typer.Option(
        "--drop-at",
        metavar="T",
        help="Drop the --payload at T s: loaded before, unloaded from the first control period at or after T.",
        rich_help_panel=_CHANGE_PANEL,
    ),
]
FrictionFaultOpt = Annotated[
    str | None,
    typer.Option(
        "--friction-fault",
        metavar="WHEEL:FACTOR[:TERMS]",
        help="Multiply one wheel's true friction by FACTOR from --fault-at on: WHEEL right or left, TERMS both "
        "(default, F_v and F_d), viscous (F_v) or coulomb (F_d); e.g. right:3.",
        rich_help_panel=_CHANGE_PANEL,
    ),
]
FaultAtOpt = Annotated[
    str | None,
    typer.Option(
        "--fault-at",
        metavar="T",
        help="Time of the --friction-fault, s (from the first control period starting at or after T).",
        rich_help_panel=_CHANGE_PANEL,
    ),
]


@app.command()
def simulate(
    output: Annotated[
        str, typer.Option("--output", "-o", help="Log to write: .csv, .parquet or .mcap (- for CSV on stdout).")
    ],
    robot: Annotated[str, typer.Option(help="Robot TOML file or built-in name; its CAD set is the truth.")] = "paper",
    trajectory: Annotated[Trajectory, typer.Option(help="Reference trajectory.")] = Trajectory.sinusoid,
    duration: Annotated[float, typer.Option(help="Duration, s.")] = 40.0,
    rate: Annotated[float, typer.Option(help="Log rate, Hz (control runs at 1 kHz).")] = 1000.0,
    seed: Annotated[int, typer.Option(help="Seed of every random number.")] = 0,
    payload: Annotated[
        str | None,
        typer.Option(
            help="Rigid payload MASS[@X,Y] (kg, m in the platform frame), e.g. 25@0.1,-0.05; carried throughout "
            "unless --load-at or --drop-at says when."
        ),
    ] = None,
    payload_inertia: Annotated[
        float, typer.Option(help="Payload yaw inertia about its own centre of mass, kg m^2.")
    ] = 0.0,
    eta_noise: Annotated[float, typer.Option(help="Std of white noise on logged wheel speeds, rad/s.")] = 0.0,
    tau_noise: Annotated[float, typer.Option(help="Std of white noise on logged torques, N m.")] = 0.0,
    caster: Annotated[float, typer.Option(help="Std of the coloured caster disturbance torque, N m.")] = 0.0,
    caster_time: Annotated[float, typer.Option(help="Correlation time of the caster disturbance, s.")] = 0.3,
    encoder_cpr: Annotated[int, typer.Option(help="Encoder counts per wheel revolution (0: no quantisation).")] = 0,
    force: Annotated[bool, typer.Option(help="Overwrite existing output files.")] = False,
    gear_ratio: Annotated[float | None, typer.Option(help="URDF robots: gear ratio k_r.")] = None,
    rotor_inertia: RotorInertiaOpt = None,
    load_at: LoadAtOpt = None,
    drop_at: DropAtOpt = None,
    friction_fault: FrictionFaultOpt = None,
    fault_at: FaultAtOpt = None,
    engine: Annotated[
        Engine,
        typer.Option(
            help="reduced: the paper's reduced model (Eqs. 9-14); mujoco: a multibody prototype (rigid bodies, "
            "wheel-ground contact, casters) that knows nothing of those equations (pip install 'wmrid[physics]').",
            rich_help_panel="Multibody prototype",
        ),
    ] = Engine.reduced,
    floor_friction: Annotated[
        float | None,
        typer.Option(
            help="mujoco: Coulomb friction of the wheels on the floor (low values let them slip); default 1.0.",
            rich_help_panel="Multibody prototype",
        ),
    ] = None,
    caster_resistance: Annotated[
        float | None,
        typer.Option(
            help="mujoco: rolling-resistance coefficient of every caster (drag / normal load; 0: frictionless); "
            "default: the robot file's [[caster]] values, else 0.015 (polyurethane).",
            rich_help_panel="Multibody prototype",
        ),
    ] = None,
    torque_limit: Annotated[
        float | None,
        typer.Option(help="mujoco: clip each wheel torque to +-this, N m.", rich_help_panel="Multibody prototype"),
    ] = None,
) -> None:
    """Simulate the paper's virtual prototype and write a log plus its ground truth (<log>.truth.json).

    The dynamics may change once during the run, the controller keeping the nominal parameters:
    --payload 25@0.1,-0.05 --load-at 30 loads the payload at 30 s, --payload 25 --drop-at 30 drops it,
    --friction-fault right:3 --fault-at 30 triples the right wheel's friction.  The truth's "parameters"
    are those at t = 0; its settings.change holds both parameter sets ("before", "after", base and
    physical), the requested time t and the switch time t_switch (s).
    """
    from wmrid.api.simulation import simulate as run_simulate
    from wmrid.api.simulation import write_simulation

    run = run_simulate(
        robot, trajectory=trajectory.value, duration=duration, rate=rate, seed=seed, payload=payload,
        payload_inertia=payload_inertia, eta_noise=eta_noise, tau_noise=tau_noise, caster=caster,
        caster_time=caster_time, encoder_cpr=encoder_cpr, load_at=load_at, drop_at=drop_at,
        friction_fault=friction_fault, fault_at=fault_at, engine=engine.value, floor_friction=floor_friction,
        caster_resistance=caster_resistance, torque_limit=torque_limit, gear_ratio=gear_ratio,
        rotor_inertia=rotor_inertia,
    )  # fmt: skip
    truth_path = write_simulation(run, output, force=force)
    if truth_path is not None:
        change = run.change
        what = "" if change is None else f", {change.kind} at {run.log.settings['change']['t_switch']:g} s"
        _stderr_console().print(f"wrote {output} ({len(run.log.t)} samples{what}) and {truth_path}")


_MONITOR_PANEL = "Change detection"
MonitorModelOpt = Annotated[
    Path,
    typer.Option(
        "--model",
        metavar="RESULT.json",
        help="The model to replay LOG against: the JSON `wmrid identify LOG0 -o RESULT.json` wrote.",
        rich_help_panel=_MONITOR_PANEL,
    ),
]
CalibrationOpt = Annotated[
    float,
    typer.Option(
        "--calibration",
        help="Span at the start of LOG (and after each change) assumed unchanged, on which the residual's noise is "
        "calibrated, s.",
        rich_help_panel=_MONITOR_PANEL,
    ),
]
FalseAlarmRateOpt = Annotated[
    float,
    typer.Option(
        "--false-alarm-rate",
        help="Stated false alarms per hour of log (Bonferroni bound over the tests); sets the threshold.",
        rich_help_panel=_MONITOR_PANEL,
    ),
]


@app.command()
def monitor(
    log: Annotated[
        str, typer.Argument(metavar="LOG", help="Log file (.csv, .parquet, .mcap) or - for standard input.")
    ],
    model: MonitorModelOpt,
    calibration: CalibrationOpt = 10.0,
    false_alarm_rate: FalseAlarmRateOpt = 0.1,
    columns: Annotated[str | None, typer.Option(help="Column mapping, as for identify.")] = None,
    time_unit: Annotated[TimeUnit, typer.Option(help="Unit of the time column.")] = TimeUnit.auto,
    output_format: Annotated[
        OutputFormat, typer.Option("--format", help="table, json, or auto (table on a terminal, json in a pipe).")
    ] = OutputFormat.auto,
    output: Annotated[Path | None, typer.Option("--output", "-o", help="Write the JSON result to this file.")] = None,
    force: Annotated[bool, typer.Option(help="Overwrite an existing output file.")] = False,
    topic: TopicOpt = None,
    velocity_topic: VelocityTopicOpt = None,
    effort_topic: EffortTopicOpt = None,
    right_joint: RightJointOpt = None,
    left_joint: LeftJointOpt = None,
    time_source: TimeSourceOpt = TimeSource.auto,
    align: AlignOpt = AlignRule.linear,
    velocity_from: VelocityFromOpt = VelocityFrom.auto,
    speed_unit: SpeedUnitOpt = SpeedUnit.rad_s,
    wheel_radius: WheelRadiusOpt = None,
    effort: EffortOpt = EffortKind.torque,
    effort_unit: EffortUnitOpt = None,
    torque_constant: TorqueConstantOpt = None,
    gear_ratio: GearRatioOpt = None,
    efficiency: EfficiencyOpt = None,
    mirror_left: MirrorLeftOpt = False,
    flip_effort: FlipEffortOpt = False,
) -> None:
    """Replay LOG against an identified model; report when the dynamics change, and the parameters after.

    A windowed likelihood-ratio test on the model's torque residual, with a stated false-alarm rate, finds
    changes such as a payload loaded or dropped or a wheel's friction rising; after each, the robot is
    identified again and the test restarts.  JSON: {"changes": [{"t": s from the log's start,
    "parameters": {...}, ...}], "detector": {..., "threshold", "false_alarm_rate_per_hour"}, ...}.
    """
    from wmrid.core.atomic import write_json
    from wmrid.monitoring.monitor import MonitorSettings, load_model
    from wmrid.monitoring.monitor import monitor as run_monitor
    from wmrid.reporting.monitor_view import print_monitor
    from wmrid.reporting.render import to_json

    settings = MonitorSettings(calibration_s=calibration, false_alarm_rate=false_alarm_rate)
    model_obj = load_model(model)
    wheel_log = _read_wheel_log(log, columns, time_unit.value, None, **_log_options(locals()))
    result = run_monitor(wheel_log, model_obj, settings)
    payload = result.to_dict()
    if output is not None:
        write_json(str(output), payload, force=force)
    if _on_stdout(output):
        return  # the result went to standard output already
    fmt = output_format.value
    if fmt == "auto":
        fmt = "table" if sys.stdout.isatty() else "json"
    if fmt == "json":
        sys.stdout.write(to_json(payload) + "\n")
    else:
        from rich.console import Console

        print_monitor(result, Console())


def main(argv: list[str] | None = None) -> None:
    """Entry point: run the app and map every outcome to one exit code and at most one stderr line.

    Exit codes: 0 success, 1 no result (or an output that could not be written), 2 usage or unreadable input,
    128 + the signal for Ctrl-C, SIGTERM and SIGHUP (130, 143, 129; temporary files removed either way)."""
    from wmrid.cli.streams import finish_output, guard
    from wmrid.core import interrupts
    from wmrid.core.atomic import clear_inputs, track_inputs

    previous = interrupts.install()  # Ctrl-C is deferred while numba compiles (an interrupt there crashes LLVM)
    if argv is None:  # the command-line process: a signal that finds it stuck in compiled code still ends it
        interrupts.start_watchdog()
    saved = guard()  # a failing stdout is an error naming it; a failing stderr never changes the outcome
    args = list(sys.argv[1:] if argv is None else argv)
    debug = "--debug" in args
    if debug:  # accepted anywhere on the line, not only before the command
        args = ["--debug", *[a for a in args if a != "--debug"]]
    try:
        track_inputs()  # an output that is one of the command's inputs is refused
        try:
            from wmrid.core.limits import memory_budget

            if not {"--help", "-h", "--version"} & set(args):
                memory_budget()  # a malformed WMRID_MEMORY_BUDGET is a usage error whatever the command reads
            with option_style("flag"):  # library messages name options as the flags the user typed
                rv = app(args=args, prog_name="wmrid", standalone_mode=False)
            finish_output()
        finally:
            clear_inputs()
        code = rv if isinstance(rv, int) else ExitStatus.OK
        if code == ExitStatus.INTERRUPTED:  # Typer turns Ctrl-C into an exit code of 130
            code = interrupts.exit_code()
            sys.stderr.write(f"wmrid: {_stopped_by()}; no output was written\n")
    except KeyboardInterrupt:
        sys.stderr.write(f"wmrid: {_stopped_by()}\n")
        code = interrupts.exit_code()
    except WmridError as exc:
        if debug:
            _leave(argv, saved, previous)
            raise
        sys.stderr.write(f"wmrid: error: {_one_line(str(exc))}\n")
        code = exc.exit_status
    except (BrokenPipeError, ReaderGone):  # the reader (| head) has seen enough
        if argv is None:  # and nothing more is flushed into the closed pipe at exit
            with contextlib.suppress(OSError, ValueError):
                os.dup2(os.open(os.devnull, os.O_WRONLY), 1)
        code = ExitStatus.OK
    except Exception as exc:
        if hasattr(exc, "show") and hasattr(exc, "exit_code"):  # a Click/Typer usage error: its own message
            exc.show()
            code = ExitStatus.USAGE
        elif type(exc).__name__ == "Abort":
            code = interrupts.exit_code()
        elif debug:
            _leave(argv, saved, previous)
            raise
        else:  # the last resort: never a traceback without --debug
            sys.stderr.write(
                f"wmrid: internal error: {type(exc).__name__}: {_one_line(str(exc))} "
                "(run with --debug for the traceback)\n"
            )
            code = ExitStatus.NO_RESULT
    if argv is not None:  # called in-process: leave the caller's signal handlers and streams as they were
        _leave(argv, saved, previous)
        sys.exit(int(code))
    for signum in interrupts.STOPPING:  # the outcome is decided: a late signal must not change it
        signal.signal(signum, signal.SIG_IGN)
    if code >= 128:
        # Python remembers a KeyboardInterrupt that went through an embedded interpreter call (even one caught
        # later) and, at exit, kills itself with SIGINT instead of returning 130; leave at once instead.
        for stream in (sys.stdout, sys.stderr):
            with contextlib.suppress(Exception):
                stream.flush()
        os._exit(int(code))
    sys.exit(int(code))


def _on_stdout(output: Any) -> bool:
    """Whether ``-o`` named standard output (``-``, /dev/stdout, /dev/fd/1: :func:`wmrid.core.atomic.stream_fd`)."""
    from wmrid.core.atomic import stream_fd

    return output is not None and stream_fd(str(output)) == 1


def _leave(argv: list[str] | None, saved: Any, previous: Any) -> None:
    """In-process (``argv`` given): put back the caller's streams and signal handlers."""
    if argv is None:
        return
    from wmrid.cli.streams import unguard
    from wmrid.core import interrupts

    unguard(saved)
    interrupts.restore(previous)


def _stopped_by() -> str:
    from wmrid.core import interrupts

    received = interrupts.received
    if received is None or received == signal.SIGINT:
        return "interrupted"
    return f"terminated by {signal.Signals(received).name}"


def _one_line(text: str) -> str:
    return " ".join(text.split())
