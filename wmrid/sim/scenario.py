"""What a simulated run is made of besides the robot: the sensors' noise (:class:`NoiseSettings`) and one change of
the plant during the run (:class:`PlantChange`: a payload loaded or dropped, a wheel's friction rising), with the
parsers of their command-line forms."""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from wmrid.core.errors import UsageError, option
from wmrid.model import dynamics as model
from wmrid.model.robot import Payload, PhysicalParameters

#: Kinds of :class:`PlantChange` (``settings["change"]["kind"]``).
CHANGE_KINDS = ("payload-load", "payload-drop", "friction-fault", "custom")


#: Wheel name -> index of its friction parameters (F_v1, F_d1: right; F_v2, F_d2: left).
WHEELS = {"right": 1, "left": 2}


#: Which friction terms a friction fault multiplies.
FRICTION_TERMS = {"both": ("F_v", "F_d"), "viscous": ("F_v",), "coulomb": ("F_d",)}


#: Keys of ``settings["change"]`` that a change's ``detail`` may not use.
_CHANGE_KEYS = ("kind", "t", "t_switch", "switch_period", "before", "after", "physical_before", "physical_after")


@dataclass(frozen=True)
class NoiseSettings:
    """Measurement noise, encoder quantisation and the unmodelled caster disturbance of a simulated run.

    Attributes
    ----------
    eta_std
        rad/s, std of white Gaussian noise added to the logged wheel velocities (>= 0).
    tau_std
        N m, std of white Gaussian noise added to the logged torques (>= 0).
    caster_std
        N m, stationary std of the coloured disturbance torque tau_d on each wheel (the paper's ball caster): an
        Ornstein-Uhlenbeck process per wheel, exactly discretised on the control grid (>= 0).
    caster_time
        s, correlation time of that process (> 0).
    encoder_cpr
        Counts per wheel revolution; when > 0 the logged velocity is the finite difference of the quantised wheel
        angle over one log period (then eta_std, if any, is added on top); 0: off.
    seed
        The seed (a whole number >= 0) of ``numpy.random.PCG64``, which draws every random number of a run: the same
        seed, the same log bit for bit.
    """

    eta_std: float = 0.0
    tau_std: float = 0.0
    caster_std: float = 0.0
    caster_time: float = 0.3
    encoder_cpr: int = 0
    seed: int = 0

    def __post_init__(self) -> None:
        for name in ("eta_std", "tau_std", "caster_std", "caster_time"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value):
                raise UsageError(f"{option(name)} must be a finite number, got {value!r}")
            if value < 0:
                raise UsageError(f"{option(name)} must be >= 0, got {value}")
            object.__setattr__(self, name, float(value))
        if self.caster_time <= 0:
            raise UsageError(f"{option('caster_time')} must be > 0 s, got {self.caster_time}")
        cpr = self.encoder_cpr
        if isinstance(cpr, bool) or not isinstance(cpr, (int, np.integer)) or cpr < 0:
            raise UsageError(f"{option('encoder_cpr')} must be a whole number >= 0, got {cpr!r}")
        object.__setattr__(self, "encoder_cpr", int(cpr))
        check_seed(self.seed)
        object.__setattr__(self, "seed", int(self.seed))

    def to_dict(self) -> dict[str, float | int]:
        """The noise as ``settings["noise"]`` records it (the seed is recorded on its own, ``settings["seed"]``)."""
        out = dataclasses.asdict(self)
        del out["seed"]
        return out


def check_seed(seed: object) -> None:
    """Refuse a seed that is not a whole number >= 0."""
    if isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0:
        raise UsageError(f"{option('seed')} must be a whole number >= 0, got {seed!r}")


#: What a :class:`Change` does: the payload loaded or dropped, or one wheel's friction multiplied.
CHANGE_SPECS = ("load", "drop", "fault")


@dataclass(frozen=True)
class Change:
    """One change of the plant during a run, said against the robot and its payload.

    What :func:`wmrid.simulate` takes; :meth:`plant` makes the :class:`PlantChange`.

    Attributes
    ----------
    at
        s, when (> 0; before the run's end).
    kind
        "load" (the run's payload is loaded at ``at``), "drop" (it is carried until ``at``, then dropped) or
        "fault" (``wheel``'s friction multiplied by ``factor``).
    wheel
        A fault's wheel: "right" (F_v1, F_d1) or "left" (F_v2, F_d2); None for a load or drop.
    factor
        A fault's factor on the wheel's friction, >= 0 and not 1; None for a load or drop.
    terms
        The friction terms a fault multiplies: "both", "viscous" (F_v only) or "coulomb" (F_d only).
    """

    at: float
    kind: str = "load"
    wheel: str | None = None
    factor: float | None = None
    terms: str = "both"

    def __post_init__(self) -> None:
        object.__setattr__(self, "at", _time("change.at", self.at))
        if self.kind not in CHANGE_SPECS:
            raise UsageError(f"change.kind must be one of {', '.join(CHANGE_SPECS)}, got {self.kind!r}")
        fault = (self.wheel, self.factor) != (None, None)
        if self.kind == "fault" and (self.wheel is None or self.factor is None):
            raise UsageError("a friction fault (change.kind 'fault') needs change.wheel and change.factor")
        if self.kind != "fault" and fault:
            raise UsageError(f"change.wheel and change.factor describe a friction fault, not a {self.kind}")
        if self.kind == "fault":
            factor = self.factor
            if isinstance(factor, bool) or not isinstance(factor, (int, float, np.integer, np.floating)):
                raise UsageError(f"friction fault factor must be a number, got {factor!r}")
            if not math.isfinite(factor) or factor < 0 or factor == 1:
                raise UsageError(f"friction fault factor must be a finite number >= 0 other than 1, got {factor}")
            if self.wheel not in WHEELS:
                raise UsageError(f"friction fault: unknown wheel {self.wheel!r}; choose one of {', '.join(WHEELS)}")
            if self.terms not in FRICTION_TERMS:
                raise UsageError(
                    f"friction fault: unknown terms {self.terms!r}; choose one of {', '.join(FRICTION_TERMS)}"
                )

    def plant(self, robot: PhysicalParameters, payload: Payload | None) -> PlantChange:
        """The change of ``robot`` that carries ``payload`` as this says.

        Parameters
        ----------
        robot
            The robot's physical parameters without the payload.
        payload
            The run's payload (needed for a load or drop), or None.

        Returns
        -------
        PlantChange
            The change of the plant.
        """
        if self.kind in ("load", "drop"):
            if payload is None:
                raise UsageError(f"a change of kind {self.kind!r} needs the payload (loaded or dropped)")
            make = PlantChange.payload_load if self.kind == "load" else PlantChange.payload_drop
            return make(self.at, robot, payload)
        base = robot if payload is None else robot.with_payload(payload)
        return PlantChange.friction_fault(self.at, base, str(self.wheel), float(self.factor or 0.0), self.terms)


def _time(name: str, value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise UsageError(f"{name} must be a number of seconds, got {value!r}")
    value = float(value)
    if not math.isfinite(value) or value <= 0:
        raise UsageError(f"{name} must be a finite time > 0 s, got {value}")
    return value


@dataclass(frozen=True, eq=False)
class PlantChange:
    """One change of the plant during a run: ``before`` until time t (s), ``after`` from then on.

    The switch happens at the first control period starting at or after t (:meth:`switch_period`).  Build one with
    :meth:`payload_load`, :meth:`payload_drop` or :meth:`friction_fault`, or directly (kind ``custom``).

    Attributes
    ----------
    t
        s, the time of the change (> 0).
    before
        The plant's physical parameters until t.
    after
        The plant's physical parameters from t on (not the same as ``before``).
    kind
        One of :data:`CHANGE_KINDS`.
    detail
        A JSON-serialisable description (the payload, or the wheel and factor of a friction fault), copied into
        ``settings["change"]``.
    """

    t: float
    before: PhysicalParameters
    after: PhysicalParameters
    kind: str = "custom"
    detail: dict = field(default_factory=dict)

    def __post_init__(self) -> None:
        object.__setattr__(self, "t", _time("change time", self.t))
        if not isinstance(self.before, PhysicalParameters) or not isinstance(self.after, PhysicalParameters):
            raise UsageError("a plant change needs PhysicalParameters before and after")
        if self.kind not in CHANGE_KINDS:
            raise UsageError(f"unknown plant change kind {self.kind!r}; choose one of {', '.join(CHANGE_KINDS)}")
        if not isinstance(self.detail, dict) or set(self.detail) & set(_CHANGE_KEYS):
            raise UsageError(f"plant change detail must be a dict without the keys {', '.join(_CHANGE_KEYS)}")
        if self.before == self.after:
            raise UsageError("the plant change changes nothing: before and after are the same parameters")

    @classmethod
    def payload_load(cls, t: float, robot: PhysicalParameters, payload: Payload) -> PlantChange:
        """``robot`` until t, then ``robot`` carrying ``payload``.

        Parameters
        ----------
        t
            s, the time of the change.
        robot
            The robot's physical parameters without the payload.
        payload
            The payload loaded at t.

        Returns
        -------
        PlantChange
            The change, of kind "payload-load".
        """
        if not isinstance(payload, Payload):
            raise UsageError(f"payload must be a Payload, got {type(payload).__name__}")
        return cls(t, robot, robot.with_payload(payload), "payload-load", {"payload": dataclasses.asdict(payload)})

    @classmethod
    def payload_drop(cls, t: float, robot: PhysicalParameters, payload: Payload) -> PlantChange:
        """``robot`` carrying ``payload`` until t, then ``robot`` alone.

        Parameters
        ----------
        t
            s, the time of the change.
        robot
            The robot's physical parameters without the payload.
        payload
            The payload dropped at t.

        Returns
        -------
        PlantChange
            The change, of kind "payload-drop".
        """
        if not isinstance(payload, Payload):
            raise UsageError(f"payload must be a Payload, got {type(payload).__name__}")
        return cls(t, robot.with_payload(payload), robot, "payload-drop", {"payload": dataclasses.asdict(payload)})

    @classmethod
    def friction_fault(
        cls, t: float, robot: PhysicalParameters, wheel: str, factor: float, terms: str = "both"
    ) -> PlantChange:
        """``robot`` until t, then with one wheel's friction multiplied by ``factor``.

        Parameters
        ----------
        t
            s, the time of the change.
        robot
            The plant's physical parameters before the change.
        wheel
            ``right`` (F_v1, F_d1) or ``left`` (F_v2, F_d2).
        factor
            The factor on the wheel's friction, >= 0 and not 1.
        terms
            ``both``, ``viscous`` (F_v only) or ``coulomb`` (F_d only).

        Returns
        -------
        PlantChange
            The change, of kind "friction-fault".
        """
        if wheel not in WHEELS:
            raise UsageError(f"friction fault: unknown wheel {wheel!r}; choose one of {', '.join(WHEELS)}")
        if terms not in FRICTION_TERMS:
            raise UsageError(f"friction fault: unknown terms {terms!r}; choose one of {', '.join(FRICTION_TERMS)}")
        if isinstance(factor, bool) or not isinstance(factor, (int, float, np.integer, np.floating)):
            raise UsageError(f"friction fault factor must be a number, got {factor!r}")
        factor = float(factor)
        if not math.isfinite(factor) or factor < 0 or factor == 1:
            raise UsageError(f"friction fault factor must be a finite number >= 0 other than 1, got {factor}")
        names = [f"{term}{WHEELS[wheel]}" for term in FRICTION_TERMS[terms]]
        if all(getattr(robot, name) == 0 for name in names):
            raise UsageError(
                f"friction fault: {' and '.join(names)} of the {wheel} wheel are 0 in the plant, so a factor changes "
                "nothing"
            )
        after = robot.replace(**{name: getattr(robot, name) * factor for name in names})
        detail = {"wheel": wheel, "factor": factor, "terms": terms, "parameters": names}
        return cls(t, robot, after, "friction-fault", detail)

    def switch_period(self, period: float) -> int:
        """k_s: the first control period whose start k_s T is >= t.

        That is ceil(t / T), with t / T within 1e-9 (relative) of a whole number taken as that number.

        Parameters
        ----------
        period
            s, the control period T.

        Returns
        -------
        int
            k_s.
        """
        ratio = self.t / period
        near = round(ratio)
        if abs(ratio - near) <= 1e-9 * max(1.0, ratio):
            return int(near)
        return math.ceil(ratio)

    def to_dict(self, period: float) -> dict:
        """The change as recorded in ``settings["change"]``.

        Parameters
        ----------
        period
            s, the control period T.

        Returns
        -------
        dict
            The record: kind, t, the switch's time and period, the base and physical parameters before and after,
            then ``detail``.
        """
        k = self.switch_period(period)
        return {
            "kind": self.kind,
            "t": self.t,
            "t_switch": k * period,
            "switch_period": k,
            "before": model.named_base(model.base_parameters(self.before)),
            "after": model.named_base(model.base_parameters(self.after)),
            "physical_before": self.before.to_dict(),
            "physical_after": self.after.to_dict(),
            **self.detail,
        }

    @classmethod
    def from_dict(cls, data: dict) -> PlantChange:
        """The change back from ``settings["change"]`` (to reproduce a run)."""
        detail = {key: value for key, value in data.items() if key not in _CHANGE_KEYS}
        return cls(
            data["t"], PhysicalParameters(**data["physical_before"]), PhysicalParameters(**data["physical_after"]),
            data["kind"], detail,
        )  # fmt: skip


def positive_number(name: str, value: object) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise UsageError(f"{option(name)} must be a number, got {value!r}")
    value = float(value)
    if not math.isfinite(value) or value <= 0:
        raise UsageError(f"{option(name)} must be a finite number > 0, got {value}")
    return value


def parse_time(text: str, option: str) -> float:
    """A time in seconds (> 0, finite) from an option's text; UsageError naming ``option`` otherwise."""
    try:
        value = float(text)
    except ValueError:
        raise UsageError(f"{option} {text!r}: expected a time in seconds, e.g. 30") from None
    if not math.isfinite(value) or value <= 0:
        raise UsageError(f"{option} {text!r}: the time must be a finite number of seconds > 0")
    return value


def parse_friction_fault(text: str) -> tuple[str, float, str]:
    """(wheel, factor, terms) from ``WHEEL:FACTOR[:TERMS]``, e.g. ``right:3`` or ``left:0.5:coulomb``.

    WHEEL is right or left, FACTOR a number, TERMS one of :data:`FRICTION_TERMS` (default both); the
    factor's range is checked by :meth:`PlantChange.friction_fault`.
    """
    parts = [part.strip() for part in text.split(":")]
    usage = (
        f"--friction-fault {text!r}: expected WHEEL:FACTOR[:TERMS] with WHEEL right or left and TERMS both, "
        "viscous or coulomb, e.g. right:3"
    )
    if len(parts) not in (2, 3) or parts[0].lower() not in WHEELS:
        raise UsageError(usage)
    terms = parts[2].lower() if len(parts) == 3 else "both"
    if terms not in FRICTION_TERMS:
        raise UsageError(usage)
    try:
        factor = float(parts[1])
    except ValueError:
        raise UsageError(usage) from None
    return parts[0].lower(), factor, terms
