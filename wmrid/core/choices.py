"""The choices of wmrid's settings, declared once: each is a ``str`` enum that the library's checks derive their
allowed values from and the command line offers as is (issue 31: options declared once).

A member equals its value (``Method.idim == "idim"``), so the library takes either.  This module imports nothing
heavy: the command line reads it to build its help without loading the estimators.
"""

from __future__ import annotations

from enum import Enum


class Method(str, Enum):
    """An identification method (``--method``); auto: the observer, or IDIM/IDIM-IV when its closed-loop check
    finds the observer's estimate biased by feedback."""

    auto = "auto"
    observer = "observer"
    idim = "idim"
    iv = "iv"
    rls = "rls"
    oe = "oe"


class Form(str, Enum):
    """The regressor's form (``--form``): the paper's 7 columns (each wheel keeps one sign), the general 8, or auto."""

    auto = "auto"
    paper = "paper"
    general = "general"


class Friction(str, Enum):
    """The friction model (``--friction``): the wheels' viscous and Coulomb friction; also the casters' drag; the
    drag following the casters' load; or auto (the log decides)."""

    auto = "auto"
    wheel = "wheel"
    wheel_caster = "wheel+caster"
    wheel_caster_load = "wheel+caster+load"


class TorqueHold(str, Enum):
    """How a logged effort is held between samples (``--torque-hold``): held (zoh, as a digital controller applies
    it) or linear (foh)."""

    zoh = "zoh"
    foh = "foh"


class TimeUnit(str, Enum):
    """The time column's unit (``--time-unit``); auto: float seconds, floats past 1e13 us, 1e16 ns; integers ns."""

    auto = "auto"
    s = "s"
    ms = "ms"
    us = "us"
    ns = "ns"


class SpeedUnit(str, Enum):
    """The wheel speeds' unit (``--speed-unit``; m/s at the rim needs the wheel radius)."""

    rad_s = "rad/s"
    rpm = "rpm"
    deg_s = "deg/s"
    m_s = "m/s"


class EffortKind(str, Enum):
    """What the effort signal is (``--effort``): a torque, or a current, PWM or voltage to be made into one."""

    torque = "torque"
    current = "current"
    pwm = "pwm"
    voltage = "voltage"


class TimeSource(str, Enum):
    """Which clock stamps a JointState sample (``--time-source``): its header, the log's, or auto."""

    auto = "auto"
    header = "header"
    log = "log"


class AlignRule(str, Enum):
    """How efforts on their own topic are brought to the speeds' times (``--align``)."""

    zoh = "zoh"
    linear = "linear"


class VelocityFrom(str, Enum):
    """Where the wheel speeds come from (``--velocity-from``): the velocity field, the positions, or auto."""

    auto = "auto"
    velocity = "velocity"
    position = "position"


class Criterion(str, Enum):
    """``wmrid plan --criterion``: the largest relative std, D- or A-optimality."""

    worst = "worst"
    d = "d"
    a = "a"


class Trajectory(str, Enum):
    """The built-in reference trajectories (``wmrid simulate --trajectory``)."""

    sinusoid = "sinusoid"
    reversing = "reversing"


class Engine(str, Enum):
    """The simulator (``wmrid simulate --engine``): the paper's reduced model, or the MuJoCo multibody prototype."""

    reduced = "reduced"
    mujoco = "mujoco"


def values(choice: type[Enum], *, without: tuple[str, ...] = ()) -> tuple[str, ...]:
    """The allowed values of a choice, in its order, leaving out ``without``."""
    return tuple(member.value for member in choice if member.value not in without)
