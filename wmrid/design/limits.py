"""What a planned drive must keep to: wheel speed, acceleration and torque, platform speed and turn rate, and the
floor area it may use; from ``wmrid plan``'s flags, else the robot file's ``[limits]`` table, else defaults."""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from wmrid.core.errors import UsageError, option

#: Defaults when neither a flag nor the robot file sets a limit: a platform speed of 1 m/s and an acceleration of
#: 1 m/s^2 at the wheel rim (turned into rad/s and rad/s^2 with the robot's wheel radius), a 4 m x 4 m area.
DEFAULT_RIM_SPEED = 1.0
DEFAULT_RIM_ACCEL = 1.0
DEFAULT_AREA = (4.0, 4.0)
#: Default share of each limit kept free: the plan is built on the nominal model, and a real robot whose inertia is
#: 20 % off needs 20 % more torque for the same motion; a tracking controller adds its own errors.
DEFAULT_MARGIN = 0.15

#: name -> (unit, what it bounds), in the order they are reported.
LIMIT_NAMES = {
    "max_wheel_speed": ("rad/s", "|wheel speed|"),
    "max_wheel_accel": ("rad/s^2", "|wheel acceleration|"),
    "max_torque": ("N m", "|wheel torque| (nominal model)"),
    "max_speed": ("m/s", "|forward speed|"),
    "max_turn_rate": ("rad/s", "|turn rate|"),
    "area_x": ("m", "|x| of the axle midpoint from the start: half the area's width less the robot's reach"),
    "area_y": ("m", "|y| of the axle midpoint from the start: half the area's height less the robot's reach"),
}


def parse_area(text: str) -> tuple[float, float]:
    """``WxH`` in metres (e.g. ``4x4`` or ``6x3.5``) -> (W, H); UsageError naming the flag otherwise."""
    parts = str(text).lower().replace(" ", "").split("x")
    try:
        values = tuple(float(p) for p in parts)
    except ValueError:
        values = ()
    if len(values) != 2 or not all(math.isfinite(v) and v > 0 for v in values):
        raise UsageError(f"{option('area', str(text))}: expected WxH in metres, e.g. 4x4 or 6x3.5")
    return values  # type: ignore[return-value]


@dataclass(frozen=True)
class Limits:
    """The limits of a plan (SI).  ``None``: not limited (torque, speed and turn rate are optional).  ``margin``: the
    share of each limit the plan keeps free (it plans to (1 - margin) x each).  ``sources``: name -> "flag",
    "robot file" or "default"."""

    max_wheel_speed: float
    max_wheel_accel: float
    area: tuple[float, float]
    max_torque: float | None = None
    max_speed: float | None = None
    max_turn_rate: float | None = None
    margin: float = DEFAULT_MARGIN
    sources: dict[str, str] = field(default_factory=dict, compare=False)
    #: m: how far the robot reaches from its axle midpoint (wheel contacts, casters): the whole robot stays in the area
    footprint: float = 0.0

    def __post_init__(self) -> None:
        for name in ("max_wheel_speed", "max_wheel_accel", "max_torque", "max_speed", "max_turn_rate"):
            value = getattr(self, name)
            if value is None and name in ("max_wheel_speed", "max_wheel_accel"):
                raise UsageError(f"{option(name)} is required")
            if value is not None:
                bad = isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value)
                if bad or value <= 0:
                    raise UsageError(f"{option(name, str(value))}: must be a number > 0")
                object.__setattr__(self, name, float(value))
        if not (isinstance(self.margin, (int, float)) and 0.0 <= self.margin < 0.9):
            raise UsageError(f"{option('margin', str(self.margin))}: must be a share in [0, 0.9)")
        area = tuple(float(v) for v in self.area)
        if len(area) != 2 or not all(math.isfinite(v) and v > 0 for v in area):
            raise UsageError(f"{option('area')}: must be W x H > 0 in metres")
        object.__setattr__(self, "area", area)
        room = min(area) * (1.0 - self.margin) / 2.0 - self.footprint
        if room < 0.05:
            need = 2.0 * (self.footprint + 0.05) / (1.0 - self.margin)
            raise UsageError(
                f"{option('area', f'{area[0]:g}x{area[1]:g}')}: too small for the robot, which reaches "
                f"{self.footprint:.2g} m from its axle midpoint; with the {100 * self.margin:g} % margin the area must "
                f"be at least {need:.2g} m on each side to leave it room to move"
            )

    def bounds(self) -> dict[str, float]:
        """name -> the bound the plan keeps to, (1 - margin) x the limit, for each limit that is set (area as half
        width and half height, the start at the centre)."""
        keep = 1.0 - self.margin
        out = {"max_wheel_speed": keep * self.max_wheel_speed, "max_wheel_accel": keep * self.max_wheel_accel}
        for name in ("max_torque", "max_speed", "max_turn_rate"):
            value = getattr(self, name)
            if value is not None:
                out[name] = keep * value
        out["area_x"] = keep * self.area[0] / 2.0 - self.footprint
        out["area_y"] = keep * self.area[1] / 2.0 - self.footprint
        return out

    def limit(self, name: str) -> float | None:
        """The limit itself (no margin) of a :data:`LIMIT_NAMES` entry (the area's: for the axle midpoint, the
        robot's footprint taken off)."""
        if name == "area_x":
            return self.area[0] / 2.0 - self.footprint
        if name == "area_y":
            return self.area[1] / 2.0 - self.footprint
        return getattr(self, name)

    def to_dict(self) -> dict:
        return {
            "max_wheel_speed": self.max_wheel_speed, "max_wheel_accel": self.max_wheel_accel,
            "max_torque": self.max_torque, "max_speed": self.max_speed, "max_turn_rate": self.max_turn_rate,
            "area": list(self.area), "margin": self.margin, "sources": dict(self.sources), "footprint": self.footprint,
            "units": {"max_wheel_speed": "rad/s", "max_wheel_accel": "rad/s^2", "max_torque": "N m",
                      "max_speed": "m/s", "max_turn_rate": "rad/s", "area": "m"},
        }  # fmt: skip

    @classmethod
    def from_dict(cls, data: dict) -> Limits:
        return cls(
            max_wheel_speed=data["max_wheel_speed"], max_wheel_accel=data["max_wheel_accel"],
            area=tuple(data["area"]), max_torque=data.get("max_torque"), max_speed=data.get("max_speed"),
            max_turn_rate=data.get("max_turn_rate"), margin=data.get("margin", DEFAULT_MARGIN),
            sources=dict(data.get("sources", {})), footprint=float(data.get("footprint", 0.0)),
        )  # fmt: skip


def resolve_limits(
    wheel_radius: float,
    file_limits: dict[str, object],
    *,
    margin: float = DEFAULT_MARGIN,
    footprint: float = 0.0,
    **flags: object,
) -> Limits:
    """The limits from the flags given (None: not given), else the robot file's [limits], else the defaults
    (:data:`DEFAULT_RIM_SPEED` and :data:`DEFAULT_RIM_ACCEL` over the wheel radius, :data:`DEFAULT_AREA`)."""
    values: dict[str, object] = {}
    sources: dict[str, str] = {}
    for name in ("max_wheel_speed", "max_wheel_accel", "max_torque", "max_speed", "max_turn_rate", "area"):
        flag = flags.get(name)
        if flag is not None:
            values[name] = parse_area(flag) if name == "area" and isinstance(flag, str) else flag
            sources[name] = "flag"
        elif name in file_limits:
            values[name] = file_limits[name]
            sources[name] = "robot file"
    defaults = {
        "max_wheel_speed": DEFAULT_RIM_SPEED / wheel_radius, "max_wheel_accel": DEFAULT_RIM_ACCEL / wheel_radius,
        "area": DEFAULT_AREA,
    }  # fmt: skip
    for name, value in defaults.items():
        if name not in values:
            values[name] = value
            sources[name] = "default"
    return Limits(**values, margin=margin, sources=sources, footprint=footprint)  # type: ignore[arg-type]
