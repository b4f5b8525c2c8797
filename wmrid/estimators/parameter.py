"""One reported parameter and what the estimator said of its std (:class:`Parameter`): the same value, std and flags
in the terminal's table, the reports, ``compare``, the monitor and the JSON, decided once (by
:func:`wmrid.estimators.verdict.settle` and the widenings) and read everywhere else.

The flags, each with one meaning wherever it is printed:

* ``inflated`` (mark "†"): the std was widened to cover an error the log shows beyond its noise (model, timing,
  feedback); it includes that error and is to be trusted.
* ``flagged`` (mark "!"): do not trust this std (not defined, an impossible value, or a log whose misfit or units put
  every std in doubt).
* ``impossible`` (mark "✗" after the value): a value no physical robot has (M not positive definite, a friction or a
  caster's drag negative beyond 3 std); always flagged too.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from wmrid.estimators.diagnostics import impossible_parameters
from wmrid.estimators.findings import Diagnostics

#: The flags, in the order they are listed.
FLAGS = ("inflated", "flagged", "impossible")


@dataclass(frozen=True)
class Parameter:
    """A reported parameter: its value, its standard error and what the estimator said of it.

    Attributes
    ----------
    name
        The parameter's name (``"m11"``, ``"Fv1"``, ...).
    value
        In ``unit``.
    std
        Its standard error (inf: not determined).
    unit
        SI; the effort's unit for a PWM log.
    flags
        A subset of :data:`FLAGS`, in that order: ``inflated`` (mark "†": the std was widened to cover an error the
        log shows beyond its noise, and is to be trusted), ``flagged`` (mark "!": do not trust this std),
        ``impossible`` (mark "✗" after the value: a value no physical robot has; always flagged too).
    """

    name: str
    value: float
    std: float
    unit: str
    flags: tuple[str, ...] = ()

    def __post_init__(self) -> None:
        unknown = set(self.flags) - set(FLAGS)
        if unknown:
            raise ValueError(f"{self.name}: unknown flags {sorted(unknown)}; the flags are {', '.join(FLAGS)}")
        object.__setattr__(self, "flags", tuple(f for f in FLAGS if f in self.flags))

    @property
    def mark(self) -> str:
        """The mark after the std in tables: "†" (inflated), "!" (flagged), both, or ""."""
        return ("†" if "inflated" in self.flags else "") + ("!" if "flagged" in self.flags else "")

    @property
    def trusted(self) -> bool:
        """Whether its std may be trusted (not flagged)."""
        return "flagged" not in self.flags

    @property
    def impossible(self) -> bool:
        return "impossible" in self.flags

    def to_dict(self) -> dict[str, Any]:
        """JSON form: {"value", "std" (null when not finite), "unit", "flags"}."""
        std = self.std if math.isfinite(self.std) else None
        return {"value": self.value, "std": std, "unit": self.unit, "flags": list(self.flags)}

    @classmethod
    def from_dict(cls, name: str, data: dict[str, Any]) -> Parameter:
        """Read back a parameter from an entry that :meth:`to_dict` wrote.

        A value null is read as NaN, a std null as inf; an entry without "flags" (documents before they were
        written) has none.

        Parameters
        ----------
        name
            The parameter's name.
        data
            The entry: {"value", "std", "unit"[, "flags"]}.

        Returns
        -------
        Parameter
            The parameter.
        """
        value = math.nan if data["value"] is None else float(data["value"])
        std = math.inf if data["std"] is None else float(data["std"])
        return cls(name, value, std, str(data["unit"]), tuple(data.get("flags") or ()))


def parameter_table(
    parameters: dict[str, tuple[float, float]], units: dict[str, str], diagnostics: Diagnostics
) -> dict[str, Parameter]:
    """The parameters (name -> (value, std)) with their units and the flags the estimator recorded in
    ``diagnostics`` ("inflated", "flagged", "impossible" lists); a result saved before "impossible" was recorded
    has it made from its values (:func:`wmrid.estimators.diagnostics.impossible_parameters`)."""
    inflated = set(diagnostics.inflated or ())
    flagged = set(diagnostics.flagged or ())
    if diagnostics.impossible is not None:
        impossible = set(diagnostics.impossible)
    else:
        impossible = impossible_parameters(parameters)
    table = {}
    for name, (value, std) in parameters.items():
        flags = tuple(f for f, names in zip(FLAGS, (inflated, flagged, impossible), strict=True) if name in names)
        table[name] = Parameter(name, float(value), float(std), units[name], flags)
    return table
