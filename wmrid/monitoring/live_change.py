"""A change found along a stream (:class:`LiveChange`, with a payload's mass: :class:`PayloadMass`), as ``wmrid live
--monitor`` reports it: made by :class:`wmrid.monitoring.live_monitor.LiveMonitor`, read by the terminal view
(:func:`wmrid.reporting.live_view.change_line`) and written as the JSON line ``wmrid live`` prints in a pipe.

Each is frozen and has ``to_dict``/``from_dict``: ``to_dict`` writes back the JSON object it was read from key for key,
and ``from_dict(c.to_dict()) == c``.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any


@dataclass(frozen=True)
class PayloadMass:
    """The mass of a payload change, estimated from the inertia terms' change alone.

    Attributes
    ----------
    mass
        kg, the payload's mass.
    std
        kg, its std.
    """

    mass: float
    std: float

    def to_dict(self) -> dict[str, float]:
        """The change line's ``payload``: {"mass": kg, "std": kg}."""
        return {"mass": self.mass, "std": self.std}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> PayloadMass:
        return cls(mass=float(data["mass"]), std=float(data["std"]))


@dataclass(frozen=True)
class LiveChange:
    """A change found along the stream (``wmrid live --monitor``).

    Times are in s of log time from the stream's first sample.

    Attributes
    ----------
    t
        s, the located change.
    t_alarm
        s, the time of the last sample the alarming test used (as offline).
    t_raised
        s, the time of the last sample received when the alarm was raised (``fit_s`` after the change, for the
        estimates).
    statistic
        The alarming window's test statistic.
    threshold
        The threshold it crossed.
    window_s
        s, that window's length.
    kind
        "payload" when the inertia terms alone explain the change, "friction" when the friction terms alone do, else
        "other" (all terms fitted).
    moved
        {parameter: (before, after, std of the change)} for the parameters of p = [M11 M12 M22 Vc Fv1 Fv2 Fd1 Fd2
        ...] that moved by more than 3 std (SI units: kg m^2, kg m, N m s/rad, N m).
    payload
        A payload change's mass (:class:`PayloadMass`; the inertia terms alone fitted), or None when the change is
        not a payload's or the robot's geometry is unknown.
    fit_s
        s, the span the estimates used.
    notes
        Notes on the change, a sentence each (the JSON line's "notes").
    """

    t: float
    t_alarm: float
    t_raised: float
    statistic: float
    threshold: float
    window_s: float
    kind: str
    moved: dict[str, tuple[float, float, float]]
    payload: PayloadMass | None
    fit_s: float
    notes: tuple[str, ...] = ()

    @property
    def delay_s(self) -> float:
        """s of log time from the change to the alarm's raising: ``t_raised - t``."""
        return self.t_raised - self.t

    def to_dict(self) -> dict[str, Any]:
        """The JSON line ``wmrid live --monitor`` prints in a pipe ("event": "change")."""
        return {
            "event": "change", "t": self.t, "t_alarm": self.t_alarm, "t_raised": self.t_raised,
            "delay_s": self.delay_s,
            "statistic": self.statistic, "threshold": self.threshold, "window_s": self.window_s, "kind": self.kind,
            "moved": {n: {"before": b, "after": a, "std": s} for n, (b, a, s) in self.moved.items()},
            "payload": None if self.payload is None else self.payload.to_dict(), "fit_s": self.fit_s,
            "notes": list(self.notes),
        }  # fmt: skip

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> LiveChange:
        """Read back the change from a JSON line that :meth:`to_dict` wrote ("delay_s" is derived: not read)."""
        payload = data.get("payload")
        return cls(
            t=float(data["t"]), t_alarm=float(data["t_alarm"]), t_raised=float(data["t_raised"]),
            statistic=float(data["statistic"]), threshold=float(data["threshold"]), window_s=float(data["window_s"]),
            kind=str(data["kind"]),
            moved={str(n): (float(m["before"]), float(m["after"]), float(m["std"])) for n, m in data["moved"].items()},
            payload=None if payload is None else PayloadMass.from_dict(payload), fit_s=float(data["fit_s"]),
            notes=tuple(str(n) for n in data.get("notes") or ()),
        )  # fmt: skip
