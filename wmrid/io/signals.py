"""What a log records, turned into what the model needs: wheel speed in rad/s and wheel torque in N m.

Real logs rarely hold exactly that.  :class:`SignalOptions` says what they hold instead, and the
functions here convert, each returning a note that says what was done:

* speed units (:func:`speed_to_rad_s`): rad/s, rpm, deg/s, or m/s at the rim (needs the wheel radius);
* effort (:func:`effort_to_torque`): a wheel torque (N m); a motor current i (A), converted as
  tau = k_t i k_r efficiency with the motor's torque constant k_t (N m/A) and the gear ratio k_r; or a
  PWM duty / voltage command, which has no known conversion: the log is then identified in the units
  given, and every output says so (the parameters absorb the drive's gain and back-EMF);
* a mirrored motor (``mirror_left``): the left wheel's speed, position and effort change sign;
* speeds from positions (:func:`speed_from_position`): unwrapped angles differentiated by a
  Savitzky-Golay filter (a local cubic fit over a window of ``SMOOTHING_S`` seconds, evaluated at the
  window's centre: zero phase lag, exact for cubic motion, and it averages encoder quantisation).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from wmrid.core.choices import EffortKind, SpeedUnit, values
from wmrid.core.errors import UsageError, option
from wmrid.core.wheel_log import DERIVED_NOTE

SPEED_UNITS = values(SpeedUnit)
EFFORT_KINDS = values(EffortKind)
#: Window of the Savitzky-Golay differentiator, s (at least 5 samples).
SMOOTHING_S = 0.02


def check_signal_numbers(
    wheel_radius: float | None, torque_constant: float | None, gear_ratio: float | None, efficiency: float | None
) -> None:
    """Refuse a wheel radius, torque constant or gear ratio that is not a finite number > 0, an efficiency outside
    (0, 1] (None: not given)."""
    for name, value in (
        ("wheel_radius", wheel_radius),
        ("torque_constant", torque_constant),
        ("gear_ratio", gear_ratio),
    ):
        if value is not None and not (math.isfinite(value) and value > 0):
            raise UsageError(f"{option(name)} must be a finite number > 0, got {value!r}")
    if efficiency is not None and not (0 < efficiency <= 1):
        raise UsageError(f"{option('efficiency')} must be in (0, 1], got {efficiency!r}")


def check_signal_choices(speed_unit: str, effort: str) -> None:
    """Raise a UsageError naming the flag unless ``speed_unit`` is one of SPEED_UNITS and ``effort`` of
    EFFORT_KINDS."""
    if speed_unit not in SPEED_UNITS:
        raise UsageError(f"{option('speed_unit')} {speed_unit!r} is not one of {', '.join(SPEED_UNITS)}")
    if effort not in EFFORT_KINDS:
        raise UsageError(f"{option('effort')} {effort!r} is not one of {', '.join(EFFORT_KINDS)}")


@dataclass(frozen=True)
class SignalOptions:
    """What the speed and effort columns hold.

    speed_unit : one of SPEED_UNITS.  wheel_radius : m, needed for m/s (and rim positions in m).
    effort : one of EFFORT_KINDS.  effort_unit : the label of a PWM/voltage effort (default "PWM", "V").
    torque_constant : N m/A of the motor; gear_ratio : motor turns per wheel turn (k_r); efficiency : of
    the gearbox, in (0, 1].  mirror_left : the left motor is mounted mirrored (its signals change sign).
    flip_effort : the effort's sign convention is opposite to the speed's on both wheels.
    A current without a torque constant is identified in amperes (like a PWM effort, in its own units).
    """

    speed_unit: str = "rad/s"
    wheel_radius: float | None = None
    effort: str = "torque"
    effort_unit: str | None = None
    torque_constant: float | None = None
    gear_ratio: float | None = None
    efficiency: float = 1.0
    mirror_left: bool = False
    flip_effort: bool = False

    def __post_init__(self) -> None:
        check_signal_choices(self.speed_unit, self.effort)
        check_signal_numbers(self.wheel_radius, self.torque_constant, self.gear_ratio, self.efficiency)
        if self.speed_unit == "m/s" and self.wheel_radius is None:
            raise UsageError(
                f"speeds in m/s at the rim need the wheel radius: give {option('wheel_radius')} R (m) or "
                f"{option('robot')}"
            )

    @property
    def is_torque(self) -> bool:
        """True when the effort becomes a torque in N m (a torque, or a current with its torque constant)."""
        return self.effort == "torque" or (self.effort == "current" and self.torque_constant is not None)

    @property
    def effort_label(self) -> str:
        """The unit of the effort after conversion: "N m" for a torque, else the given label (PWM, V, A)."""
        if self.is_torque:
            return "N m"
        return self.effort_unit or {"pwm": "PWM", "voltage": "V", "current": "A"}[self.effort]


def speed_to_rad_s(values: np.ndarray, opts: SignalOptions) -> tuple[np.ndarray, str | None]:
    """Wheel speeds (n, 2) in ``opts.speed_unit`` -> rad/s, with a note (None for rad/s)."""
    if opts.speed_unit == "rad/s":
        return values, None
    if opts.speed_unit == "rpm":
        return values * (2 * math.pi / 60.0), "wheel speeds read in rpm and converted to rad/s"
    if opts.speed_unit == "deg/s":
        return values * (math.pi / 180.0), "wheel speeds read in deg/s and converted to rad/s"
    r = float(opts.wheel_radius)  # validated in SignalOptions
    return values / r, f"wheel speeds read as m/s at the rim and divided by the wheel radius r = {r:g} m"


def position_to_rad(values: np.ndarray, opts: SignalOptions) -> np.ndarray:
    """Wheel positions (n, 2) to rad: read as m at the rim in m/s logs, deg in deg/s logs, else rad."""
    if opts.speed_unit == "m/s":
        return values / float(opts.wheel_radius)
    if opts.speed_unit == "deg/s":
        return values * (math.pi / 180.0)
    return values


def effort_to_torque(
    values: np.ndarray, opts: SignalOptions, robot_gear_ratio: float | None
) -> tuple[np.ndarray, str | None]:
    """Efforts (n, 2) -> wheel torque in N m (torque, current) or the given units (pwm, voltage), with a note
    (None for a torque, which needs no conversion)."""
    if opts.effort == "torque":
        return values, None
    if opts.effort == "current" and opts.torque_constant is None:
        return values, (
            f"effort read as motor current in {opts.effort_label} with no torque constant given: the parameters are "
            f"identified in {opts.effort_label} units (give --torque-constant, or a robot [motor] table, for N m)"
        )
    if opts.effort == "current":
        k_r = opts.gear_ratio if opts.gear_ratio is not None else robot_gear_ratio
        if k_r is None:
            raise UsageError(
                f"{option('effort', 'current')} needs the gear ratio: give {option('gear_ratio')} KR or a "
                f"{option('robot')} with k_r"
            )
        gain = float(opts.torque_constant) * float(k_r) * opts.efficiency
        return values * gain, (
            f"effort read as motor current (A) and converted to wheel torque: tau = k_t i k_r eta = "
            f"{opts.torque_constant:g} N m/A x i x {k_r:g} x {opts.efficiency:g}"
        )
    label = opts.effort_label
    return values, (
        f"effort is a {opts.effort} command in {label}, not a torque: there is no known conversion, so the "
        f"parameters are identified in {label} units (they absorb the drive's gain and back-EMF)"
    )


def flip_effort(effort: np.ndarray) -> None:
    """Change the sign of both wheels' efforts in place (an effort convention opposite to the speed's)."""
    effort *= -1.0


def mirror_left(speed: np.ndarray | None, effort: np.ndarray | None, position: np.ndarray | None = None) -> None:
    """Change the sign of the left wheel's columns in place (a mirrored left motor)."""
    for arr in (speed, effort, position):
        if arr is not None:
            arr[:, 1] *= -1.0


def speed_from_position(t: np.ndarray, position: np.ndarray, window_s: float = SMOOTHING_S) -> tuple[np.ndarray, str]:
    """Wheel speeds (n, 2) rad/s from wheel angles (n, 2) rad at times t (n,) s, with a note.

    Angles are unwrapped first (a position that wraps at +/-pi or 2 pi is common).  On a uniform grid
    (steps within 1 % of their median) a Savitzky-Golay cubic over ``window_s`` seconds (an odd number
    of samples, at least 5) gives the derivative at each sample, zero-phase; otherwise second-order
    finite differences on the uneven grid (numpy.gradient).
    """
    from scipy.signal import savgol_filter  # scipy.signal (~0.6 s): only speeds from wheel positions

    angle = np.unwrap(position, axis=0) if np.nanmax(np.abs(np.diff(position, axis=0))) > math.pi else position
    dt = np.diff(t)
    h = float(np.median(dt))
    if len(t) >= 5 and np.all(np.abs(dt - h) <= 0.01 * h):
        window = max(5, round(window_s / h) | 1)
        window = min(window, len(t) if len(t) % 2 else len(t) - 1)
        speed = savgol_filter(angle, window, polyorder=3, deriv=1, delta=h, axis=0, mode="interp")
        return speed, f"{DERIVED_NOTE}{window} samples ({window * h * 1e3:.3g} ms)"
    speed = np.gradient(angle, t, axis=0)
    return speed, "wheel speeds derived from wheel positions by second-order finite differences (uneven time steps)"


def convert(
    speed: np.ndarray,
    effort: np.ndarray,
    opts: SignalOptions,
    gear_ratio: float | None,
    *,
    speed_in_rad_s: bool = False,
) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Speeds and efforts (n, 2) as the model needs them (rad/s; N m or the given units), with notes.

    The one place that applies ``opts`` to a log's signals: speed unit (unless ``speed_in_rad_s``, e.g.
    speeds derived from positions already in rad), effort conversion, mirrored left motor, flipped efforts.
    The inputs are not modified.
    """
    notes: list[str] = []
    speed, effort = speed.copy(), effort.copy()
    if not speed_in_rad_s:
        speed, note = speed_to_rad_s(speed, opts)
        if note:
            notes.append(note)
    effort, note = effort_to_torque(effort, opts, gear_ratio)
    if note:
        notes.append(note)
    if opts.mirror_left:
        mirror_left(speed, effort)
        notes.append("left wheel mirrored: its speed and effort changed sign (--mirror-left)")
    if opts.flip_effort:
        flip_effort(effort)
        notes.append("both efforts changed sign (--flip-effort)")
    return speed, effort, notes
