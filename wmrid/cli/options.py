"""The command line's choices and options, shared by the commands: enums of the allowed values, and each option once
(type, help and panel) as an ``Annotated`` alias."""

from __future__ import annotations

from enum import Enum
from pathlib import Path
from typing import Annotated

import typer

from wmrid.core.choices import (
    AlignRule,
    Criterion,
    EffortKind,
    Engine,
    Form as FormChoice,
    Friction as FrictionChoice,
    Friction as PlanFriction,
    Method as MethodChoice,
    SpeedUnit,
    TimeSource,
    TimeUnit,
    TorqueHold,
    Trajectory,
    VelocityFrom,
)
from wmrid.estimators.options import ObserverOptions

#: The observer's defaults: the library's own (``ObserverOptions()``), so a flag's default is never written twice.
OBSERVER_DEFAULTS = ObserverOptions()

__all__ = [
    "AlignRule",
    "Criterion",
    "EffortKind",
    "Engine",
    "FormChoice",
    "FrictionChoice",
    "MethodChoice",
    "PlanFriction",
    "SpeedUnit",
    "TimeSource",
    "TimeUnit",
    "TorqueHold",
    "Trajectory",
    "VelocityFrom",
]  # fmt: skip  (the choices the commands import from here, declared in the library: wmrid.core.choices)


class OutputFormat(str, Enum):
    auto = "auto"
    table = "table"
    json = "json"


#: The panels of detail: ``--help`` folds each into one line, ``--help-all`` shows them (:mod:`wmrid.cli.help`).  Titles
#: fit an 80-column terminal's panel border.
LOG_PANEL = "Log input (bag topics, units, effort)"
CHECK_LOG_PANEL = "Log input of --check (bag topics, units, effort)"
OBSERVER_PANEL = "Observer (Eqs. 26-37), friction and the efforts' timing"
MULTIBODY_PANEL = "Multibody prototype"
CHANGE_PANEL = "Change of the dynamics during the run (one per run)"
NOISE_PANEL = "Noise and disturbances of the simulated log"
FOLDED_PANELS = (LOG_PANEL, CHECK_LOG_PANEL, OBSERVER_PANEL, MULTIBODY_PANEL, NOISE_PANEL)
_LOG_PANEL, _OBSERVER_PANEL = LOG_PANEL, OBSERVER_PANEL


VerboseOpt = Annotated[
    bool,
    typer.Option(
        "--verbose", "-v",
        help="The table also gives the estimator's own figures (regressor, gains, lambda_min(Gamma), the structural "
        "mismatch test, how the std was computed); the JSON always holds them.",
    ),
]  # fmt: skip


TopicOpt = Annotated[
    str | None,
    typer.Option(
        help="Bags (MCAP, ROS 1, db3): the JointState (or JSON) topic holding speed and effort.",
        rich_help_panel=_LOG_PANEL,
    ),
]


VelocityTopicOpt = Annotated[
    str | None,
    typer.Option(help="Bags: the JointState topic with the wheel speeds (or positions).", rich_help_panel=_LOG_PANEL),
]


EffortTopicOpt = Annotated[
    str | None, typer.Option(help="Bags: the JointState topic with the wheel efforts.", rich_help_panel=_LOG_PANEL)
]


RightJointOpt = Annotated[
    str | None, typer.Option(help="Bags: name of the right wheel joint.", rich_help_panel=_LOG_PANEL)
]


LeftJointOpt = Annotated[
    str | None, typer.Option(help="Bags: name of the left wheel joint.", rich_help_panel=_LOG_PANEL)
]


TimeSourceOpt = Annotated[
    TimeSource,
    typer.Option(
        help="Bags: header stamps, log time, or auto (header when all set and in order).", rich_help_panel=_LOG_PANEL
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
    typer.Option(help="Wheel radius, m, > 0 (for m/s speeds; default: the robot's r).", rich_help_panel=_LOG_PANEL),
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
    typer.Option(help="Motor torque constant k_t, N m/A, > 0 (for --effort current).", rich_help_panel=_LOG_PANEL),
]


GearRatioOpt = Annotated[
    float | None,
    typer.Option(
        help="Gear ratio k_r, > 0 (for --effort current; default: the robot's k_r).", rich_help_panel=_LOG_PANEL
    ),
]


EfficiencyOpt = Annotated[
    float, typer.Option(help="Gearbox efficiency in (0, 1] (for --effort current).", rich_help_panel=_LOG_PANEL)
]


FlipEffortOpt = Annotated[
    bool,
    typer.Option(
        "--flip-effort",
        help="The effort's sign is opposite to the speed's on both wheels: change it.",
        rich_help_panel=_LOG_PANEL,
    ),
]


MirrorLeftOpt = Annotated[
    bool,
    typer.Option(
        "--mirror-left",
        help="The left motor is mirrored: change the sign of its speed and effort.",
        rich_help_panel=_LOG_PANEL,
    ),
]


RotorInertiaOpt = Annotated[
    float | None,
    typer.Option(help="URDF robots: motor rotor inertia I_r, kg m^2, >= 0 (when the URDF has no rotor links)."),
]


_METHOD_PANEL = "Method (observer, or a classical rival; see wmrid compare)"


MethodOpt = Annotated[
    MethodChoice,
    typer.Option(
        help="auto (default: the observer, or IDIM/IDIM-IV when the closed-loop check finds the observer biased by "
        "feedback, said first), observer (the paper's, always reported), idim (least squares on filtered "
        "accelerations), iv (IDIM with the logged reference as instruments), rls (recursive least squares with "
        "forgetting), oe (output error from the observer's estimate).",
        rich_help_panel=_METHOD_PANEL,
    ),
]


CutoffOpt = Annotated[
    float | None,
    typer.Option(
        "--cutoff", help="idim/rls: low-pass cutoff of speeds and efforts, Hz, > 0 (default: from the log).",
        rich_help_panel=_METHOD_PANEL,
    ),
]  # fmt: skip


WeightedOpt = Annotated[
    bool, typer.Option("--weighted", help="idim: two-step weighted least squares.", rich_help_panel=_METHOD_PANEL)
]


ForgettingOpt = Annotated[
    float,
    typer.Option(
        help="rls: forgetting factor in [0.98, 1] (below 0.98 it remembers fewer than 50 samples for 8 "
        "parameters); 1 = plain least squares.",
        rich_help_panel=_METHOD_PANEL,
    ),
]


DelayOpt = Annotated[
    str | None,
    typer.Option(
        "--delay",
        metavar="auto|SECONDS",
        help="The efforts are stamped SECONDS later than the speeds (two topics, two clocks; negative: earlier): "
        "read them that much earlier.  auto: estimate the delay from the log and apply it when significant (the "
        "output states it).  Reads the log into memory.  Default: the timing check estimates the delay on every log of "
        "up to 2 M samples and applies it when significant, as auto does (always auto when the efforts come from "
        "another topic than the speeds); 0: as stamped.",
        rich_help_panel=_OBSERVER_PANEL,
    ),
]


ControlRateOpt = Annotated[
    float | None,
    typer.Option(
        "--control-rate",
        metavar="HZ",
        help="The controller updated the (held) effort at HZ (> 0), faster than the log: each step is held over its "
        "sub-steps, the unlogged values interpolated (e.g. a 1 kHz controller logged at 100 Hz).",
        rich_help_panel=_OBSERVER_PANEL,
    ),
]


FrictionOpt = Annotated[
    FrictionChoice,
    typer.Option(
        "--friction",
        help="wheel: viscous and Coulomb friction per wheel (Eqs. 15-17); wheel+caster: also the casters' rolling "
        "drag, one drag force per caster when --robot lists [[caster]] positions (else two terms, Cv against "
        "speed and Cw against turning), for the observer, idim, rls and oe (oe and --validate need the positions); "
        "wheel+caster+load: also the drag's change with each caster's load as the robot accelerates and turns "
        "(needs the positions; the observer only); "
        "auto: both, and the caster model when the log shows the drag (a Wald test, p < 0.001; the output says "
        "which and why), then its load terms when the log shows them too.",
        rich_help_panel=_OBSERVER_PANEL,
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


_CHANGE_PANEL = CHANGE_PANEL


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
        "calibrated, s, > 0.",
        rich_help_panel=_MONITOR_PANEL,
    ),
]


FalseAlarmRateOpt = Annotated[
    float,
    typer.Option(
        "--false-alarm-rate",
        help="Stated false alarms per hour of log, > 0 (Bonferroni bound over the tests); sets the threshold.",
        rich_help_panel=_MONITOR_PANEL,
    ),
]


#: The observer's settings and the table options, declared once for every command that identifies a log (issue 31).
ColumnsOpt = Annotated[
    str | None,
    typer.Option(
        help="Column mapping NAME=COLUMN, comma-separated, e.g. t=time,eta_r=vr,tau_l=ul.", rich_help_panel=_LOG_PANEL
    ),
]
TimeUnitOpt = Annotated[
    TimeUnit,
    typer.Option(
        help="Time column unit (auto: float s, floats past 1e13 us, 1e16 ns; integer ns).", rich_help_panel=_LOG_PANEL
    ),
]
FormOpt = Annotated[
    FormChoice,
    typer.Option(
        help="Regressor: paper (7 columns, wheels keep one sign), general (8), auto.", rich_help_panel=_OBSERVER_PANEL
    ),
]
KOpt = Annotated[
    float,
    typer.Option(
        "--k",
        help="Observer/filter gain k of Eqs. 26-30, 1/s, in (0, 100000] (paper: 1; the docs' page on the observer).",
        rich_help_panel=_OBSERVER_PANEL,
    ),
]
AlphaOpt = Annotated[
    float,
    typer.Option(
        help="Initial Gamma = alpha I (Eq. 33), > 0: weight of the start value (paper: 5000).",
        rich_help_panel=_OBSERVER_PANEL,
    ),
]
BoxWidthOpt = Annotated[
    float,
    typer.Option(
        help="Half-width of the parameter box around the nominal values, in units of max(|theta|, m_ii), "
        "in (0, inf] (inf: no box).",
        rich_help_panel=_OBSERVER_PANEL,
    ),
]
TorqueHoldOpt = Annotated[
    TorqueHold,
    typer.Option(
        help="Torque between samples: zoh (held, as a digital controller applies it) or foh (linear).",
        rich_help_panel=_OBSERVER_PANEL,
    ),
]
PayloadOpt = Annotated[
    bool,
    typer.Option(
        "--payload",
        help="Also estimate the payload carried (mass, x, y, inertia) against --robot's unloaded parameters.",
        rich_help_panel=_OBSERVER_PANEL,
    ),
]
GivenOpt = Annotated[
    list[str] | None,
    typer.Option(
        metavar="RESULT",
        help="A saved result of an earlier log of this robot (--format json -o run.json) to combine with this "
        "log's, as wmrid plan --given predicted. Repeatable.",
    ),
]

#: The observer's default choices as the flags offer them (read from :data:`OBSERVER_DEFAULTS`).
DEFAULT_FORM = FormChoice(OBSERVER_DEFAULTS.form)
DEFAULT_TORQUE_HOLD = TorqueHold(OBSERVER_DEFAULTS.torque_hold)
DEFAULT_FRICTION = FrictionChoice(OBSERVER_DEFAULTS.friction)
