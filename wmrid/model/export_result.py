"""What ``wmrid export`` wrote (:class:`ExportResult`) and how the exported model fits a check log
(:class:`ExportCheck`).

Made by :func:`wmrid.api.exporting.export`, read by the terminal view (:func:`wmrid.reporting.export_view.print_export`)
and written as the JSON ``wmrid export --format json`` prints; kept here, beside the physical quantities it carries
(:class:`wmrid.model.physical.PhysicalEstimate`) and below the views, so the view reads its attributes.  Each is frozen
and has ``to_dict``/``from_dict``: ``to_dict`` writes back the JSON object it was read from key for key.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from wmrid.model.physical import PhysicalEstimate


@dataclass(frozen=True)
class ExportCheck:
    """The exported models driven by a check log's torques (``wmrid export --check``).

    The models run over windows of ``window_s`` s, each restarted from the logged speeds
    (:func:`wmrid.api.exporting.check_fit`).

    Attributes
    ----------
    log
        The check log.
    samples
        Its samples.
    window_s
        s, each window's length.
    windows
        How many windows.
    definition
        The fit's formula.
    multibody
        {"eta_r", "eta_l"} fit %, 100 a perfect prediction, of the exported multibody model (None: not simulated,
        or not finite).
    reduced
        {"eta_r", "eta_l"} fit %, 100 a perfect prediction, of the reduced model (None: not simulated, or not
        finite).
    reduced_not_simulated
        Why the reduced model could not be simulated (None: it was).
    """

    log: str
    samples: int
    window_s: float
    windows: int
    definition: str
    multibody: Mapping[str, float | None]
    reduced: Mapping[str, float | None]
    reduced_not_simulated: str | None = None

    def fits(self) -> tuple[tuple[str, Mapping[str, float | None]], ...]:
        """(model, {"eta_r", "eta_l"} fit %) for "multibody" then "reduced"."""
        return (("multibody", self.multibody), ("reduced", self.reduced))

    def to_dict(self) -> dict[str, Any]:
        """The export JSON's ``check``."""
        return {
            "log": self.log, "samples": self.samples, "window_s": self.window_s, "windows": self.windows,
            "definition": self.definition, "multibody": dict(self.multibody), "reduced": dict(self.reduced),
            "reduced_not_simulated": self.reduced_not_simulated,
        }  # fmt: skip

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> ExportCheck:
        return cls(
            log=str(data["log"]), samples=int(data["samples"]), window_s=data["window_s"],
            windows=int(data["windows"]), definition=str(data["definition"]), multibody=dict(data["multibody"]),
            reduced=dict(data["reduced"]), reduced_not_simulated=data.get("reduced_not_simulated"),
        )  # fmt: skip


@dataclass(frozen=True)
class ExportResult:
    """What :func:`wmrid.api.exporting.export` wrote.

    Attributes
    ----------
    path
        The output file.
    format
        What it is ("MJCF (MuJoCo)", "URDF", ...).
    physical
        The physical quantities (None: a result in PWM/voltage units, or a robot given as base parameters).
    provenance
        {what: where from} (the wmrid version, the result, the log, the method, the robot).
    check
        The fit of the exported models on a check log (None: no check log).
    notes
        What the export changed or left out, a sentence each.
    """

    path: str
    format: str
    physical: PhysicalEstimate | None
    provenance: dict[str, str]
    check: ExportCheck | None = None
    notes: tuple[str, ...] = ()

    def to_dict(self) -> dict[str, Any]:
        """The JSON ``wmrid export --format json`` prints ("schema" 1, "kind" "export")."""
        return {
            "schema": 1, "kind": "export", "path": self.path, "format": self.format,
            "physical": None if self.physical is None else self.physical.to_dict(),
            "provenance": dict(self.provenance), "check": None if self.check is None else self.check.to_dict(),
            "notes": list(self.notes),
        }  # fmt: skip

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> ExportResult:
        check = data.get("check")
        return cls(path=str(data["path"]), format=str(data["format"]),
                   physical=None if data["physical"] is None else PhysicalEstimate.from_dict(data["physical"]),
                   provenance=dict(data["provenance"]),
                   check=None if check is None else ExportCheck.from_dict(check),
                   notes=tuple(data.get("notes", ())))  # fmt: skip
