"""The typed parts of an identification result besides its parameters: what the log was (:class:`LogInfo`), what
the result says of its parameter groups (:class:`Verdict`, :class:`GroupVerdict`) and how its model fits another
log (:class:`Validation`).

Each is frozen and has ``to_dict``/``from_dict``: ``to_dict`` gives the result JSON's ``log``, ``verdict`` and
``validation`` objects key for key as before these types existed, and ``from_dict(r.to_dict()) == r``.  A document
of an older version comes back with what it lacks filled in as those versions meant it (a log's ``effort_unit`` "N m"
and ``notes`` [], a group's ``reason`` null, a verdict's ``lines`` []); a key of a log record this version does not
know is kept (``other``) and written back after the known ones.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

#: LogInfo's keys, in the order the JSON's ``log`` object has them.
_LOG_KEYS = ("samples", "duration_s", "rate_hz", "uneven_steps", "notes", "effort_unit", "scales", "delay")


@dataclass(frozen=True)
class LogInfo:
    """What the log was, as the identification read it.

    A field that is None was not recorded (a document of an older version).

    Attributes
    ----------
    samples
        Samples read.
    duration_s
        s, last time minus first.
    rate_hz
        Hz, 1 / the median step.
    uneven_steps
        The steps differ by more than 1e-6 of the median.
    notes
        What reading it changed or found (a derivative taken, rows dropped, ...).
    effort_unit
        "N m", or the unit of currents/PWM read as efforts.
    scales
        The largest speeds and efforts and the duration (the units check reads them): {"speed_max": [r, l] rad/s,
        "effort_max": [r, l], "duration_s"}.
    delay
        The efforts' delay ``wmrid monitor`` applied to the whole log (its record), else None.
    other
        Keys of other versions' documents, kept as read.
    """

    samples: int | None = None
    duration_s: float | None = None
    rate_hz: float | None = None
    uneven_steps: bool | None = None
    notes: tuple[str, ...] = ()
    effort_unit: str = "N m"
    scales: Mapping[str, Any] | None = None
    delay: Mapping[str, Any] | None = None
    other: Mapping[str, Any] = field(default_factory=dict)

    def to_dict(self) -> dict[str, Any]:
        """The result JSON's ``log``: the recorded keys (None ones left out, ``notes`` and ``effort_unit`` always)."""
        values = {
            "samples": self.samples, "duration_s": self.duration_s, "rate_hz": self.rate_hz,
            "uneven_steps": self.uneven_steps, "notes": list(self.notes), "effort_unit": self.effort_unit,
            "scales": None if self.scales is None else dict(self.scales),
            "delay": None if self.delay is None else dict(self.delay),
        }  # fmt: skip
        return {**{k: v for k, v in values.items() if v is not None}, **self.other}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> LogInfo:
        """The log record :meth:`to_dict` wrote (any of its keys may be missing: an older document)."""
        return cls(
            samples=data.get("samples"), duration_s=data.get("duration_s"), rate_hz=data.get("rate_hz"),
            uneven_steps=data.get("uneven_steps"), notes=tuple(str(n) for n in data.get("notes") or ()),
            effort_unit=str(data.get("effort_unit") or "N m"), scales=data.get("scales"), delay=data.get("delay"),
            other={k: v for k, v in data.items() if k not in _LOG_KEYS},
        )  # fmt: skip


@dataclass(frozen=True)
class GroupVerdict:
    """What the log determines of one parameter group (:func:`wmrid.estimators.verdict.verdict`).

    Attributes
    ----------
    group
        "inertia", "Coriolis coefficient", "friction" or "casters".
    parameters
        The group's parameters judged.
    worst
        The one of largest relative std.
    relative_std
        Its std / |value| (None: unbounded).
    status
        "determined", "poorly determined", "not determined" or "in doubt".
    reason
        Why, when not determined (None when it is).
    text
        The sentence printed.
    negligible
        {name: bound} of parameters determined as negligible, their bound in the parameter's unit (None: none).
    """

    group: str
    parameters: tuple[str, ...]
    worst: str
    relative_std: float | None
    status: str
    reason: str | None
    text: str
    negligible: Mapping[str, float] | None = None

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {
            "group": self.group, "parameters": list(self.parameters), "worst": self.worst,
            "relative_std": self.relative_std, "status": self.status, "reason": self.reason,
        }  # fmt: skip
        if self.negligible is not None:
            out["negligible"] = dict(self.negligible)
        out["text"] = self.text
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> GroupVerdict:
        return cls(
            group=str(data["group"]), parameters=tuple(data["parameters"]), worst=str(data["worst"]),
            relative_std=data.get("relative_std"), status=str(data["status"]), reason=data.get("reason"),
            text=str(data["text"]), negligible=data.get("negligible"),
        )  # fmt: skip


@dataclass(frozen=True)
class Verdict:
    """The result's last word (:func:`wmrid.estimators.verdict.verdict`), said before any number.

    Attributes
    ----------
    summary
        One sentence: what the log determines, or "Do not use these numbers: ..." when its units are in doubt.
    groups
        One :class:`GroupVerdict` per group.
    lines
        The groups' sentences to print (one for all when they say the same).
    first
        Said before the summary (a method switched).
    check
        Unit findings that are warnings, not doubts.
    units
        What units were assumed when no robot file could check them (None: checked).
    """

    summary: str
    groups: tuple[GroupVerdict, ...] = ()
    lines: tuple[str, ...] = ()
    first: tuple[str, ...] = ()
    check: tuple[str, ...] = ()
    units: str | None = None

    @property
    def doubt(self) -> bool:
        """The numbers are not to be used (the summary says so)."""
        return self.summary.startswith("Do not use")

    def to_dict(self) -> dict[str, Any]:
        """The result JSON's ``verdict``: summary, groups, lines, then first, check and units when there are."""
        out: dict[str, Any] = {"summary": self.summary, "groups": [g.to_dict() for g in self.groups],
                               "lines": list(self.lines)}  # fmt: skip
        if self.first:
            out["first"] = list(self.first)
        if self.check:
            out["check"] = list(self.check)
        if self.units is not None:
            out["units"] = self.units
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Verdict:
        return cls(
            summary=str(data["summary"]), groups=tuple(GroupVerdict.from_dict(g) for g in data.get("groups") or ()),
            lines=tuple(data.get("lines") or ()), first=tuple(data.get("first") or ()),
            check=tuple(data.get("check") or ()), units=data.get("units"),
        )  # fmt: skip


@dataclass(frozen=True)
class Validation:
    """How the result's model predicts another log of the same robot (``--validate``).

    The wheel speeds are simulated open loop from that log's efforts (:func:`wmrid.api.identification.validate`).

    Attributes
    ----------
    log
        That log.
    samples
        Its samples.
    definition
        The fit's formula.
    fit_percent
        {"eta_r", "eta_l"} %, 100 a perfect prediction (None: not simulated, or not finite).
    predictor
        How the speeds were simulated (None: not simulated).
    not_simulated
        Why the model could not be simulated (None: it was).
    """

    log: str
    samples: int
    definition: str
    fit_percent: Mapping[str, float | None]
    predictor: str | None
    not_simulated: str | None = None

    def to_dict(self) -> dict[str, Any]:
        """The result JSON's ``validation``."""
        out: dict[str, Any] = {"log": self.log, "samples": self.samples, "definition": self.definition,
                               "fit_percent": dict(self.fit_percent), "predictor": self.predictor}  # fmt: skip
        if self.not_simulated is not None:
            out["not_simulated"] = self.not_simulated
        return out

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> Validation:
        return cls(
            log=str(data["log"]), samples=int(data["samples"]), definition=str(data["definition"]),
            fit_percent=dict(data["fit_percent"]), predictor=data.get("predictor"),
            not_simulated=data.get("not_simulated"),
        )  # fmt: skip
