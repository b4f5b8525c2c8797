"""The wheel-log types every layer shares: a log in memory (:class:`WheelLog`) and one read piece by piece
(:class:`LogStream`).  Readers (:mod:`wmrid.io`) make them; estimators consume them without importing a reader.

Canonical columns: ``t`` (s), ``eta_r``, ``eta_l`` (rad/s; right wheel = eta_1, left = eta_2), ``tau_r``, ``tau_l``
(N m); optional pose ``x``, ``y`` (m), ``phi`` (rad) and wheel-speed reference ``eta_ref_r``, ``eta_ref_l`` (rad/s).
A CSV or Parquet log may give wheel positions ``pos_r``, ``pos_l`` (rad) instead of the speeds; the readers derive the
speeds from them (:func:`wmrid.io.signals.speed_from_position`).
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Generator, Iterator
from contextlib import contextmanager
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
    """One wheel log in SI units, in memory (:func:`wmrid.read_log`).

    Attributes
    ----------
    t
        (n,) float64, s, strictly increasing (as in the file; relative to the first stamp only when the notes say
        so).
    eta
        (n, 2) float64, rad/s, columns [right, left].
    tau
        (n, 2) float64, N m, columns [right, left].
    source
        The file name as the user gave it (``"<stdin>"`` for ``-``).
    notes
        Plain-English statements of what was assumed while reading.
    pose
        (n, 3) float64 [x m, y m, phi rad] when the log has x, y, phi; else None.
    effort_unit
        "N m" for a torque; else the unit of a PWM or voltage effort that could not be converted (tau then holds
        that effort, and the parameters come out in its units).
    reference
        (n, 2) float64 rad/s, the wheel-speed reference (set-points) [right, left] when the log has eta_ref_r,
        eta_ref_l; else None.

    Raises
    ------
    ValueError
        ``t`` is not 1-D, or an array's shape does not match ``t``'s length.
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

#: The limits in force (:func:`stream_limits`): one (cache, piece) entry per block entered and not yet left, in any
#: thread; the tightest of each applies.  A list, not a saved value: blocks may end in any order (two live runs).
_limits: list[tuple[int, int]] = []
_limits_lock = threading.Lock()


def cache_rows() -> int:
    """Samples a stream may keep after its first pass now: CACHE_ROWS, or less within :func:`stream_limits`."""
    return min([CACHE_ROWS, *(cache for cache, _ in _limits)])


def piece_rows() -> int:
    """Samples a reader puts in a piece now (:func:`wmrid.io.logs.open_log`'s default): CHUNK_ROWS, or less within
    :func:`stream_limits`."""
    return min([CHUNK_ROWS, *(piece for _, piece in _limits)])


@contextmanager
def stream_limits(cache: int, piece: int | None = None) -> Iterator[None]:
    """Within: every stream keeps at most ``cache`` samples after its first pass (0: none; each pass reads the file
    again), the readers' caches of decoded records shrink with it (:func:`cache_rows`), and the logs opened put at
    most ``piece`` samples in a piece (:func:`piece_rows`; None: CHUNK_ROWS).  The passes read the same samples (the
    observer does not depend on where pieces are cut), so the result is the same to rounding; only memory and time
    change.  For a process held to a memory budget (``wmrid live``'s final identify after a long stream).
    Process-wide, for every thread; nested or overlapping blocks (in other threads too) apply the tightest of their
    limits, and each block's end lifts only its own."""
    if int(cache) < 0 or (piece is not None and int(piece) < 1):
        raise ValueError(f"stream_limits: cache >= 0 and piece >= 1 samples, got {cache}, {piece}")
    entry = (int(cache), CHUNK_ROWS if piece is None else int(piece))
    with _limits_lock:
        _limits.append(entry)
    try:
        yield
    finally:
        with _limits_lock:
            _limits.remove(entry)


class LogStream:
    """A wheel log that yields :class:`WheelLog` pieces in time order and can be iterated again.

    :func:`wmrid.open_log` makes one.  Iterating reads the file (or, for a log of at most CACHE_ROWS samples, the
    pieces kept from the first pass).  A pass raises :class:`LogFormatError` at the first unusable row, as
    :func:`read_log` does, and checks across pieces what :func:`read_log` checks across rows (time strictly
    increasing, one time unit).  Memory: one piece (at most CHUNK_ROWS samples) at a time, whatever the log's length.

    Parameters
    ----------
    source
        The file name for messages.
    effort_unit
        As in :class:`WheelLog`.
    pieces
        Called at the start of each pass: a generator of the pieces, which returns the notes when it ends.

    Attributes
    ----------
    notes
        What was assumed while reading; set when a pass ends.
    samples
        The log's samples; set when a pass ends (None before).
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
        limit = cache_rows()
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
                if count > limit:
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


def shifted_stream(stream: LogStream, delay: float) -> LogStream:
    """``stream`` with its efforts read ``delay`` s earlier, tau(t - delay), by linear interpolation between their
    samples, piece by piece: the same values as :func:`wmrid.estimators.regression.idim_rows.shifted` gives on the
    whole log (held at the first and last sample beyond the log's ends; ``np.interp`` between the same two samples).

    A piece's samples leave once the samples their time ``t - delay`` falls between have come (for a negative delay,
    samples of the next piece), so the pieces may be cut elsewhere than the stream's.  Memory: a piece and the
    samples within ``|delay|`` of its ends.
    """
    delay = float(delay)

    def pieces() -> Generator[WheelLog, None, tuple[str, ...]]:
        held: list[WheelLog] = []  # samples not yet out, and before them those their interpolation may still need
        first = 0  # in held's concatenation: the first sample not yet out
        for piece in stream:
            if len(piece) == 0:
                continue
            held.append(piece)
            out, held, first = _shift_out(held, first, delay, last=False)
            if out is not None:
                yield out
        if held:
            out, held, first = _shift_out(held, first, delay, last=True)
            if out is not None:
                yield out
        return stream.notes

    return LogStream(stream.source, stream.effort_unit, pieces)


def _shift_out(
    held: list[WheelLog], first: int, delay: float, last: bool
) -> tuple[WheelLog | None, list[WheelLog], int]:
    """(the samples of ``held`` from ``first`` on whose shifted effort is known, as one piece, or None; what to hold
    on; the index there of the first sample not yet out) for :func:`shifted_stream`; ``last``: no sample follows."""
    t = np.concatenate([p.t for p in held]) if len(held) > 1 else np.asarray(held[0].t)
    x = t[first:] - delay
    end = len(t) if last else first + int(np.searchsorted(x, t[-1], side="right"))
    if end == first:
        return None, held, first
    tau = np.concatenate([p.tau for p in held]) if len(held) > 1 else np.asarray(held[0].tau)
    tau = np.asarray(tau, dtype=np.float64)
    xs = x[: end - first]
    shifted = np.column_stack([np.interp(xs, t, tau[:, j]) for j in range(tau.shape[1])])

    def part(name: str) -> np.ndarray | None:
        values = [getattr(p, name) for p in held]
        if any(v is None for v in values):
            return None
        return (np.concatenate(values) if len(values) > 1 else values[0])[first:end]

    eta = part("eta")
    assert eta is not None, "a piece has speeds"
    h = held[0]
    out = WheelLog(
        t=t[first:end], eta=eta, tau=shifted, source=h.source, effort_unit=h.effort_unit, pose=part("pose"),
        reference=part("reference"),
    )  # fmt: skip
    if last:
        return out, [], 0
    # keep from the sample at or before the next one's shifted time, the left end of its interpolation (of a sample
    # still to come when all went out: its time is past the last one's)
    after = (t[end] if end < len(t) else t[-1]) - delay
    keep = min(max(int(np.searchsorted(t, after, side="right")) - 1, 0), end)
    rest = WheelLog(
        t=t[keep:], eta=_tail(held, "eta", keep), tau=tau[keep:], source=h.source, effort_unit=h.effort_unit,
        pose=_tail(held, "pose", keep), reference=_tail(held, "reference", keep),
    )  # fmt: skip
    return out, [rest], end - keep


def _tail(held: list[WheelLog], name: str, start: int) -> Any:
    values = [getattr(p, name) for p in held]
    if any(v is None for v in values):
        return None
    return (np.concatenate(values) if len(values) > 1 else values[0])[start:]


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
