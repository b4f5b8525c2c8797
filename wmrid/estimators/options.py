"""The observer's options and the classical methods', declared and checked once (:class:`ObserverOptions`,
:class:`MethodOptions`).

Every command that runs the observer (identify, compare, report, fleet, monitor, live) takes these; the command line
turns its flags into one, the library's functions take one, and nothing checks them again downstream.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

from wmrid.core.choices import Form, Friction, TorqueHold, values
from wmrid.core.errors import UsageError, option

#: Friction models: ``auto`` lets the log decide between the others (:mod:`wmrid.pipeline.friction`).
FRICTION_CHOICES = (*values(Friction, without=("auto",)), "auto")
#: The observer's history is decimated to at most this many samples (the convergence figures and JSON history).
MAX_HISTORY = 20000


def check_box_width(box_width: float) -> None:
    """Refuse a box half-width that is not a number > 0 (inf: no box)."""
    if not (isinstance(box_width, (int, float)) and box_width > 0):  # NaN fails too
        raise UsageError(f"{option('box_width')} must be a number > 0 (inf: no box), got {box_width!r}")


def delay_value(delay: float | str | None) -> float | str | None:
    """``delay``: None (as stamped, or estimated for split topics), "auto" or seconds (a number or its text), checked;
    a UsageError otherwise."""
    if delay is None:
        return None
    if isinstance(delay, (int, float)) and not isinstance(delay, bool):
        value = float(delay)
    elif isinstance(delay, str) and delay.strip().lower() == "auto":
        return "auto"
    else:
        try:
            value = float(delay) if isinstance(delay, str) else math.nan
        except ValueError:
            value = math.nan
    if not math.isfinite(value):
        raise UsageError(f"{option('delay')} must be auto or a number of seconds, got {delay!r}")
    return value


@dataclass(frozen=True)
class ObserverOptions:
    """How the observer reads a log (Eqs. 26-37), checked when made.

    Attributes
    ----------
    form
        "auto" (the paper's 7 columns when each wheel keeps one sign, else the general 8), "paper" or "general".
    k
        1/s, the state predictor's and filter's gain, in (0, MAX_K].
    alpha
        The start value's weight, Gamma(0) = alpha I, > 0.
    box_width
        The parameter box's half-width in units of the start value (inf: no box;
        :func:`wmrid.estimators.observer.observe.default_box`).
    torque_hold
        "zoh" (each effort held over its step) or "foh" (linear between samples).
    control_rate
        Hz, the rate of a controller faster than the log that held the effort (None: the log's own).
    delay
        s, how late the efforts are stamped against the speeds: they are read that much earlier; "auto": estimated
        and applied when significant; None: as stamped unless the timing check finds otherwise.
    friction
        "wheel" (Eqs. 15-17), "wheel+caster", "wheel+caster+load" or "auto" (the log decides).
    payload
        Also estimate the payload the robot carries, from the estimate against the robot's unloaded parameters
        (:mod:`wmrid.model.payload`; needs a robot with physical parameters).
    max_history
        Samples: the history kept for figures, at most (>= 2).

    Raises
    ------
    UsageError
        An option out of its range or not one of its choices.
    """

    form: str = "auto"
    k: float = 10.0
    alpha: float = 1e-10
    box_width: float = 10.0
    torque_hold: str = "zoh"
    control_rate: float | None = None
    delay: float | str | None = None
    friction: str = "auto"
    payload: bool = False
    max_history: int = MAX_HISTORY

    def __post_init__(self) -> None:
        check_gains(self.k, self.alpha, self.control_rate)
        check_box_width(self.box_width)
        if self.torque_hold not in values(TorqueHold):
            raise UsageError(f"{option('torque_hold')} must be zoh or foh, got {self.torque_hold!r}")
        if self.form not in values(Form):
            raise UsageError(f"{option('form')} must be auto, paper or general, got {self.form!r}")
        if self.friction not in FRICTION_CHOICES:
            raise UsageError(
                f"{option('friction')} must be one of {', '.join(FRICTION_CHOICES)}, got {self.friction!r}"
            )
        object.__setattr__(self, "delay", delay_value(self.delay))
        if not isinstance(self.payload, bool):  # a text "false" would count as true
            raise UsageError(f"{option('payload')} must be true or false, got {self.payload!r}")
        if not (isinstance(self.max_history, int) and self.max_history >= 2):
            raise UsageError(f"max_history must be an integer >= 2, got {self.max_history!r}")


#: 1/s: the largest predictor gain: a time constant of 10 us, a hundredth of a 1 kHz step (--k 1e308 used to be
#: accepted and reported as "the log does not excite the dynamics").
MAX_K = 1e5


def check_control_rate_value(control_rate: float | None) -> None:
    """Refuse a control rate that is not a frequency > 0 Hz (None: none)."""
    if control_rate is not None and not (math.isfinite(control_rate) and control_rate > 0):
        raise UsageError(f"{option('control_rate')} must be a frequency > 0 in Hz, got {control_rate!r}")


def check_gains(k: float, alpha: float, control_rate: float | None = None) -> None:
    """Refuse a gain k outside (0, MAX_K] 1/s, an alpha that is not a finite number > 0, a control rate that is not
    a frequency > 0 Hz (None: none)."""
    check_control_rate_value(control_rate)
    if not (math.isfinite(k) and 0 < k <= MAX_K):
        raise UsageError(
            f"{option('k')} must be a number in (0, {MAX_K:g}] (1/s, the state predictor's gain; default 10), got "
            f"{k}: beyond that the predictor forgets within microseconds and its filter carries no signal"
        )
    if not (math.isfinite(alpha) and alpha > 0):
        raise UsageError(f"{option('alpha')} must be a finite number > 0, got {alpha}")


#: The smallest RLS forgetting factor: a memory of 1/(1 - lambda) = 50 samples, about six per parameter.
MIN_FORGETTING = 0.98


@dataclass(frozen=True)
class MethodOptions:
    """Options of the classical methods (IDIM, IDIM-IV, RLS, OE), checked when made.

    How the effort was held between samples is the observer's (its ``torque_hold`` and ``control_rate``,
    :class:`wmrid.estimators.options.ObserverOptions`): OE simulates it, IDIM and RLS read the efforts half a hold
    period earlier under "zoh" (:func:`wmrid.estimators.regression.idim_rows.effort_delay`).

    Attributes
    ----------
    cutoff_hz
        Hz, the IDIM/RLS low-pass cutoff, > 0 (None: from the log, see
        :func:`wmrid.estimators.regression.idim_rows.default_cutoff`).
    weighted
        IDIM two-step weighted least squares.
    forgetting
        The RLS forgetting factor, in [MIN_FORGETTING, 1] (MIN_FORGETTING = 0.98: a memory of 50 samples).

    Raises
    ------
    UsageError
        An option out of its range.
    """

    cutoff_hz: float | None = None
    weighted: bool = False
    forgetting: float = 1.0

    def __post_init__(self) -> None:
        if not isinstance(self.weighted, bool):  # a text "false" would count as true
            raise UsageError(f"{option('weighted')} must be true or false, got {self.weighted!r}")
        if self.cutoff_hz is not None and not (math.isfinite(self.cutoff_hz) and self.cutoff_hz > 0):
            raise UsageError(f"{option('cutoff')} must be a positive frequency in Hz, got {self.cutoff_hz!r}")
        if not (MIN_FORGETTING <= self.forgetting <= 1.0):
            why = (
                "above 1 the recursion weights old samples more than new ones and diverges"
                if self.forgetting > 1.0
                else f"below {MIN_FORGETTING} the recursion remembers fewer than "
                f"{round(1 / (1 - MIN_FORGETTING))} samples for 8 parameters"
                if self.forgetting < MIN_FORGETTING
                else "it is not a number"
            )
            raise UsageError(f"{option('forgetting')} must be in [{MIN_FORGETTING}, 1], got {self.forgetting!r}: {why}")


#: The classical methods' settings by their command-line names: MethodOptions' fields.
FIT_NAMES = {"cutoff": "cutoff_hz", "weighted": "weighted", "forgetting": "forgetting"}


#: The observer's settings by name: ObserverOptions' fields a user sets.
OBSERVER_NAMES = tuple(f.name for f in fields(ObserverOptions) if f.name != "max_history")


#: identify's settings by name (a fleet manifest's columns, the command line's flags): the method, the observer's
#: options, the classical methods'.
SETTING_NAMES = ("method", *OBSERVER_NAMES, *FIT_NAMES)
