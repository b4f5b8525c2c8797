"""What ``wmrid live`` shows at each refresh (:class:`LiveUpdate`): the online estimate
(:func:`wmrid.estimators.observer.online.online_estimate`) with the stream's state.

Made by :meth:`wmrid.api.live.LiveRun.update`, read by the terminal view (:mod:`wmrid.reporting.live_view`) and
written as the JSON line ``wmrid live`` prints in a pipe; kept here, below both, so the view reads its attributes.
``LiveUpdate.from_dict(u.to_dict()) == u`` for an update whose values are finite (the estimate's always are), and its
``to_dict`` writes back the JSON line it was read from key for key.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

#: What the std of a :class:`LiveUpdate` is.
ONLINE_STD = (
    "delete-a-segment jackknife of the observer's estimate over contiguous segments of the samples received so far "
    "(the offline std before its widening terms: model error, discretisation, slow speeds, closed-loop check, timing); "
    "the final result's std is the offline one"
)


@dataclass(frozen=True)
class LiveUpdate:
    """One refresh of a live run: the online estimate with the stream's state.

    Attributes
    ----------
    source
        The name of the source followed.
    elapsed_s
        s since the run started.
    samples
        Samples received so far.
    log_time_s
        s of log time they span.
    rate_hz
        Samples received per second of wall time since the last update.
    log_rate_hz
        Samples per second of log time (None before any log time has passed).
    since_last_data_s
        s of wall time since the last bytes arrived.
    form
        The regressor ("paper", "general", "general+caster"; None before the observer started).
    parameters
        {name: (value, std)} in SI units (empty until the samples determine an estimate); the std is what
        :data:`ONLINE_STD` says (a jackknife over the samples received so far), inf when not determined.
    segments
        How many segments the jackknife has.
    notes
        What the estimate assumes (e.g. the friction model).
    events
        What happened to the source since the last update (a connection lost or regained, a server's warning).
    """

    source: str
    elapsed_s: float
    samples: int
    log_time_s: float
    rate_hz: float
    log_rate_hz: float | None
    since_last_data_s: float
    form: str | None
    parameters: dict[str, tuple[float, float]]
    segments: int
    notes: tuple[str, ...] = ()
    events: tuple[str, ...] = ()

    def relative_std(self, name: str) -> float:
        """std / |value| of a parameter.

        Parameters
        ----------
        name
            The parameter's name.

        Returns
        -------
        float
            Its relative std (inf when unknown or zero).
        """
        value, std = self.parameters.get(name, (0.0, math.inf))
        return std / abs(value) if value != 0 and math.isfinite(std) else math.inf

    def to_dict(self) -> dict[str, Any]:
        """The JSON line ``wmrid live`` prints in a pipe ("event": "update"; a parameter's std null when not finite;
        "std" says what the std is: :data:`ONLINE_STD`)."""
        return {
            "event": "update", "source": self.source, "elapsed_s": self.elapsed_s, "samples": self.samples,
            "log_time_s": self.log_time_s, "rate_hz": self.rate_hz, "log_rate_hz": self.log_rate_hz,
            "since_last_data_s": self.since_last_data_s, "form": self.form,
            "parameters": {n: {"value": v, "std": s if math.isfinite(s) else None} for n, (v, s) in
                           self.parameters.items()},
            "std": ONLINE_STD, "segments": self.segments, "notes": list(self.notes), "events": list(self.events),
        }  # fmt: skip

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> LiveUpdate:
        """Read back an update from a JSON line that :meth:`to_dict` wrote.

        A std null is read as inf, a value null as NaN.
        """

        def pair(entry: Mapping[str, Any]) -> tuple[float, float]:
            value, std = entry["value"], entry["std"]
            return (math.nan if value is None else float(value), math.inf if std is None else float(std))

        return cls(
            source=str(data["source"]), elapsed_s=float(data["elapsed_s"]), samples=int(data["samples"]),
            log_time_s=float(data["log_time_s"]), rate_hz=float(data["rate_hz"]), log_rate_hz=data.get("log_rate_hz"),
            since_last_data_s=float(data["since_last_data_s"]), form=data.get("form"),
            parameters={str(n): pair(e) for n, e in data["parameters"].items()}, segments=int(data["segments"]),
            notes=tuple(str(n) for n in data.get("notes") or ()),
            events=tuple(str(e) for e in data.get("events") or ()),
        )  # fmt: skip
