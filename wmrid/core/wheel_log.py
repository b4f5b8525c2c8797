"""The wheel-log types every layer shares: a log in memory (:class:`WheelLog`) and one read piece by piece
(:class:`LogStream`).  Readers (:mod:`wmrid.io`) make them; estimators consume them without importing a reader.

Canonical columns: ``t`` (s), ``eta_r``, ``eta_l`` (rad/s; right wheel = eta_1, left = eta_2), ``tau_r``, ``tau_l``
(N m); optional pose ``x``, ``y`` (m), ``phi`` (rad) and wheel-speed reference ``eta_ref_r``, ``eta_ref_l`` (rad/s).
A CSV or Parquet log may give wheel positions ``pos_r``, ``pos_l`` (rad) instead of the speeds; the readers derive the
speeds from them (:func:`wmrid.io.signals.speed_from_position`).
"""

from __future__ import annotations

from collections.abc import Callable, Generator, Iterator
from dataclasses import dataclass
from typing import Any

import numpy as np

from wmrid.core.errors import LogFormatError

REQUIRED = ("t", "eta_r", "eta_l", "tau_r", "tau_l")


POSE = ("x", "y", "phi")


#: Optional wheel-speed reference (set-points, rad/s): the instruments of ``--method iv``
# (:mod:`wmrid.estimators.regression.iv`).
REFERENCE = ("eta_ref_r", "eta_ref_l")


#: Wheel positions (angles, rad; deg or m at the rim with the speed unit deg/s or m/s), read instead of the speeds
#: eta_r, eta_l when a log has no speeds (or ``velocity_from="position"``).
POSITION = ("pos_r", "pos_l")


CANONICAL = REQUIRED + POSE + REFERENCE + POSITION


MIN_SAMPLES = 10


@dataclass(frozen=True)
class WheelLog:
    """One wheel log in SI units.

    t : (n,) float64, s, strictly increasing (as in the file; relative to the first stamp only when
        the notes say so).
    eta : (n, 2) float64, rad/s, columns [right, left].
    tau : (n, 2) float64, N m, columns [right, left].
    source : the file name as the user gave it (``"<stdin>"`` for ``-``).
    notes : plain-English statements of what was assumed while reading.
    pose : (n, 3) float64 [x m, y m, phi rad] when the log has x, y, phi; else None.
    reference : (n, 2) float64 rad/s, the wheel-speed reference (set-points) [right, left] when the log has
        eta_ref_r, eta_ref_l; else None.
    effort_unit : "N m" for a torque; else the unit of a PWM or voltage effort that could not be
        converted (tau then holds that effort, and the parameters come out in its units).
    """

    t: np.ndarray
    eta: np.ndarray
    tau: np.ndarray
    source: str
    notes: tuple[str, ...] = ()
    pose: np.ndarray | None = None
    effort_unit: str = "N m"
    reference: np.ndarray | None = None

    def __post_init__(self) -> None:
        n = np.shape(self.t)[0] if np.ndim(self.t) == 1 else -1
        if n < 0:
            raise ValueError(f"WheelLog.t must be 1-D, got shape {np.shape(self.t)}")
        for name, arr, width in (
            ("eta", self.eta, 2), ("tau", self.tau, 2), ("pose", self.pose, 3), ("reference", self.reference, 2)
        ):  # fmt: skip
            if arr is not None and np.shape(arr) != (n, width):
                raise ValueError(f"WheelLog.{name} must have shape ({n}, {width}), got {np.shape(arr)}")

    def __len__(self) -> int:
        return int(self.t.shape[0])

    @property
    def duration(self) -> float:
        """Time from the first to the last sample, s."""
        return float(self.t[-1] - self.t[0]) if len(self) else 0.0


#: Rows per piece when a log is read in pieces (about 10 MB of t, eta, tau).
CHUNK_ROWS = 262_144


#: A stream keeps its pieces after the first pass when the log has at most this many samples (160 MB;
#: about 70 min at 1 kHz), so that a second pass (identify's replay) does not read the file again; longer
#: logs are re-read, so memory never exceeds this cache plus one piece.
CACHE_ROWS = 4_194_304


class LogStream:
    """A wheel log that yields :class:`WheelLog` pieces in time order and can be iterated again.

    source : the file name for messages.  effort_unit : as in :class:`WheelLog`.
    Iterating reads the file (or, for a log of at most CACHE_ROWS samples, the pieces kept from the first
    pass).  A pass raises :class:`LogFormatError` at the first unusable row, as :func:`read_log` does, and
    checks across pieces what :func:`read_log` checks across rows (time strictly increasing, one time
    unit).  ``notes`` (what was assumed while reading) and ``samples`` are set when a pass ends.
    Memory: one piece (at most CHUNK_ROWS samples) at a time, whatever the log's length.
    """

    def __init__(self, source: str, effort_unit: str, pieces: Callable[[], Generator[WheelLog, None, tuple[str, ...]]]):
        self.source = source
        self.effort_unit = effort_unit
        self._pieces = pieces
        self._cache: list[WheelLog] | None = None
        self.notes: tuple[str, ...] = ()
        self.samples: int | None = None

    def __iter__(self) -> Iterator[WheelLog]:
        if self._cache is not None:
            yield from self._cache
            return
        kept: list[WheelLog] | None = []
        count = 0
        gen = self._pieces()
        while True:
            try:
                piece = next(gen)
            except StopIteration as stop:
                notes = tuple(stop.value or ())
                break
            count += len(piece)
            if kept is not None:
                kept.append(piece)
                if count > CACHE_ROWS:
                    kept = None
            yield piece
        if self.samples is not None and count != self.samples:
            raise LogFormatError(
                f"{self.source}: the file changed while it was read ({self.samples} samples, then {count}); "
                "identify a copy that is not being written"
            )
        self.samples, self.notes, self._cache = count, notes, kept

    def read(self) -> WheelLog:
        """The whole log as one :class:`WheelLog` (memory: the whole log)."""
        pieces = list(self)
        poses = [p.pose for p in pieces]
        pose = np.concatenate(poses) if all(p is not None for p in poses) else None
        refs = [p.reference for p in pieces]
        reference = np.concatenate(refs) if refs and all(r is not None for r in refs) else None
        return WheelLog(
            t=np.concatenate([p.t for p in pieces]), eta=np.concatenate([p.eta for p in pieces]),
            tau=np.concatenate([p.tau for p in pieces]), source=self.source, notes=self.notes, pose=pose,
            effort_unit=self.effort_unit, reference=reference,
        )  # fmt: skip


def stream_arrays(log: Any, rows: int = CHUNK_ROWS) -> LogStream:
    """A :class:`LogStream` over a log already in memory (t, eta, tau arrays; source, notes, effort_unit; pose and
    reference when it has them)."""
    t, eta, tau = log.t, log.eta, log.tau
    pose, reference = getattr(log, "pose", None), getattr(log, "reference", None)
    source = getattr(log, "source", "log")
    unit = getattr(log, "effort_unit", "N m")
    notes = tuple(getattr(log, "notes", ()))

    def pieces() -> Generator[WheelLog, None, tuple[str, ...]]:
        for start in range(0, len(t), rows):
            stop = start + rows
            yield WheelLog(
                t=t[start:stop], eta=eta[start:stop], tau=tau[start:stop], source=source, effort_unit=unit,
                pose=None if pose is None else pose[start:stop],
                reference=None if reference is None else reference[start:stop],
            )  # fmt: skip
        return notes

    return LogStream(source, unit, pieces)


#: The words of the note that says the effort came from another topic than the speeds (:func:`split_topics`).
SPLIT_NOTE = "put on the speed stamps"


#: The words of the reading note of speeds derived from positions by a Savitzky-Golay derivative, then its window
#: in samples (:func:`wmrid.io.signals.speed_from_position`; read by :mod:`wmrid.estimators.noise_floor`).
DERIVED_NOTE = "wheel speeds derived from wheel positions by a Savitzky-Golay cubic derivative over "

#: The words of the note that says a topic's efforts were all whole numbers before they were put on the speed stamps
#: (PWM counts look like that; interpolation hides it from the units check, :mod:`wmrid.estimators.plausibility`).
WHOLE_EFFORTS_NOTE = "every effort message holds whole numbers"


def whole_efforts(effort) -> str | None:
    """The :data:`WHOLE_EFFORTS_NOTE` clause for efforts (k, 2) that are all whole numbers, not all zero; else None."""
    effort = np.asarray(effort, dtype=float)
    if effort.size == 0 or not np.all(np.isfinite(effort)) or not np.any(effort):
        return None
    if not np.array_equal(effort, np.floor(effort)):
        return None
    return f"{WHOLE_EFFORTS_NOTE} (up to {float(np.abs(effort).max()):.6g})"


def split_topics(notes: tuple[str, ...] | list[str]) -> bool:
    """Whether a log's reading notes say its efforts and speeds came from two topics (two clocks, two drivers), the
    case where ``identify`` estimates their delay by default (:func:`wmrid.estimators.timing_check.apply_delay`)."""
    return any(SPLIT_NOTE in note for note in notes)
