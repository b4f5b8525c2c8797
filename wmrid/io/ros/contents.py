"""What an MCAP holds, as :func:`wmrid.io.mcap.reader.read_mcap` reports it: channels, JointState series and their
summaries (joints, fields, time sources, steps), JSON series."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from wmrid.io.mcap.records import STEP_BUCKETS, field_stats, step_buckets


@dataclass(frozen=True)
class ChannelInfo:
    """One channel: its topic, encodings, schema, and the messages seen (count, log-time range in ns)."""

    id: int
    topic: str
    message_encoding: str
    schema_name: str
    schema_encoding: str
    count: int
    first_ns: int | None
    last_ns: int | None

    @property
    def rate_hz(self) -> float | None:
        """Mean message rate over the channel's span, Hz (None for fewer than 2 messages)."""
        if self.count < 2 or self.first_ns is None or self.last_ns is None or self.last_ns <= self.first_ns:
            return None
        return (self.count - 1) / ((self.last_ns - self.first_ns) * 1e-9)


@dataclass(frozen=True)
class JointSeries:
    """The JointState messages of one topic, in file order.

    names : the joint names (those of the first message, plus any met later), K of them.
    log_ns, stamp_ns : (n,) int64, the MCAP log time and the header stamp, ns.
    position (rad or m), velocity (rad/s or m/s), effort (N m, N, or whatever was logged) : (n, K)
    float64, NaN where a message does not carry that joint or that field.
    """

    topic: str
    names: tuple[str, ...]
    log_ns: np.ndarray
    stamp_ns: np.ndarray
    position: np.ndarray
    velocity: np.ndarray
    effort: np.ndarray
    skipped: int = 0

    def field(self, name: str) -> np.ndarray:
        return {"position": self.position, "velocity": self.velocity, "effort": self.effort}[name]

    def any_nonzero(self, name: str, cols: list[int]) -> bool:
        """Whether field ``name`` holds a non-NaN, non-zero value in one of the joint columns ``cols``."""
        values = self.field(name)[:, cols]
        return bool(np.any((values != 0) & ~np.isnan(values)))  # (NaN != 0: masked)

    def populated(self, name: str) -> str:
        """'yes', 'zeros' (present but all zero), 'partly' (some NaN) or 'no' for field ``name``."""
        values = self.field(name)
        nan = np.isnan(values)
        if values.size == 0 or nan.all():
            return "no"
        if not np.any((values != 0) & ~nan):
            return "zeros"
        return "partly" if nan.any() else "yes"


FIELDS = ("position", "velocity", "effort")


@dataclass(frozen=True)
class TimeSummary:
    """One time source (MCAP log time or header stamp) of a JointState topic, over the whole file in file order.

    first, last, low, high : ns (None without messages).  ordered : never decreasing from one message to the
    next.  steps_ok : every step fits in int64 (so ``hist`` holds them all).  all_positive : every value > 0.
    repeats : steps of 0.  hist : (STEP_BUCKETS,) counts of the positive steps by :func:`step_buckets`.
    """

    first: int | None
    last: int | None
    low: int | None
    high: int | None
    ordered: bool
    steps_ok: bool
    all_positive: bool
    repeats: int
    hist: np.ndarray


@dataclass(frozen=True)
class JointSummary:
    """What a JointState topic holds, without its arrays (the first pass over a long recording).

    channel_id : the channel whose messages :class:`JointSeries` would hold.  names, count : as there.
    has_value, has_nonzero, has_nan, has_inf : (3, K) bool per field (position, velocity, effort) and joint:
    some value is not NaN, some non-NaN value is not 0, some value is NaN (or missing), some is infinite.
    max_abs : (3, K) the largest finite |value| (0 when none).  times : {"log": ..., "header": ...}.
    """

    topic: str
    channel_id: int
    names: tuple[str, ...]
    count: int
    has_value: np.ndarray
    has_nonzero: np.ndarray
    has_nan: np.ndarray
    has_inf: np.ndarray
    max_abs: np.ndarray
    times: dict[str, TimeSummary]

    def populated(self, name: str) -> str:
        """As :meth:`JointSeries.populated`."""
        f = FIELDS.index(name)
        if self.count == 0 or len(self.names) == 0 or not self.has_value[f].any():
            return "no"
        if not self.has_nonzero[f].any():
            return "zeros"
        return "partly" if self.has_nan[f].any() else "yes"

    def any_nonzero(self, name: str, cols: list[int]) -> bool:
        """Whether field ``name`` holds a non-NaN, non-zero value in one of the joint columns ``cols``."""
        return bool(self.has_nonzero[FIELDS.index(name), cols].any())


class _TimeStats:
    """Builds a :class:`TimeSummary` batch by batch."""

    def __init__(self) -> None:
        self.first: int | None = None
        self.prev: int | None = None
        self.low: int | None = None
        self.high: int | None = None
        self.ordered = True
        self.steps_ok = True
        self.all_positive = True
        self.repeats = 0
        self.hist = np.zeros(STEP_BUCKETS, dtype=np.int64)

    def add(self, values: np.ndarray) -> None:
        if len(values) == 0:
            return
        if self.prev is None:
            self.first = int(values[0])
            steps = np.diff(values)
            up = values[1:] >= values[:-1]
        else:
            steps = np.diff(values, prepend=np.int64(self.prev))
            up = np.concatenate(([values[0] >= self.prev], values[1:] >= values[:-1]))
        self.ordered = self.ordered and bool(up.all())
        if self.ordered and self.steps_ok:
            if (steps < 0).any():  # an int64 overflow: no histogram
                self.steps_ok = False
            else:
                self.repeats += int(np.count_nonzero(steps == 0))
                positive = steps[steps > 0]
                if len(positive):
                    self.hist += np.bincount(step_buckets(positive), minlength=STEP_BUCKETS)
        self.all_positive = self.all_positive and bool((values > 0).all())
        low, high = int(values.min()), int(values.max())
        self.low = low if self.low is None else min(self.low, low)
        self.high = high if self.high is None else max(self.high, high)
        self.prev = int(values[-1])

    def summary(self) -> TimeSummary:
        return TimeSummary(
            first=self.first, last=self.prev, low=self.low, high=self.high, ordered=self.ordered,
            steps_ok=self.steps_ok, all_positive=self.all_positive, repeats=self.repeats, hist=self.hist,
        )  # fmt: skip


class JointStats:
    """Builds a :class:`JointSummary` part by part."""

    def __init__(self, k: int) -> None:
        self.count = 0
        self.has_value = np.zeros((3, k), dtype=bool)
        self.has_nonzero = np.zeros((3, k), dtype=bool)
        self.has_nan = np.zeros((3, k), dtype=bool)
        self.has_inf = np.zeros((3, k), dtype=bool)
        self.max_abs = np.zeros((3, k))
        self.times = {"log": _TimeStats(), "header": _TimeStats()}

    def add(self, part: tuple[np.ndarray, ...]) -> None:
        log_ns, stamp = part[0], part[1]
        self.count += len(log_ns)
        for f in range(3):
            field_stats(part[2 + f], self.has_value[f], self.has_nonzero[f], self.has_nan[f], self.has_inf[f],
                         self.max_abs[f])  # fmt: skip
        self.times["log"].add(log_ns)
        self.times["header"].add(stamp)


@dataclass(frozen=True)
class JsonSeries:
    """Numeric fields read from a JSON-encoded channel: log_ns (n,) int64 and {key: (n,) float64}."""

    topic: str
    log_ns: np.ndarray
    values: dict[str, np.ndarray]


@dataclass(frozen=True)
class McapContents:
    """What :func:`read_mcap` found.

    complete : False when :func:`scan_mcap` stopped keeping the arrays: ``joints`` then holds a
    :class:`JointSummary` per topic instead of a :class:`JointSeries`.
    replay : with ``complete`` False, the JointState parts the scan decoded, without positions, when they fit
    in its ``spare`` bytes: [(channel id, (log_ns, stamp_ns, None, velocity, effort))] in file order, to be
    read (and emptied) by the next pass instead of decoding the file again; else None.
    """

    source: str
    profile: str
    library: str
    channels: tuple[ChannelInfo, ...]
    joints: dict[str, Any]
    json: dict[str, JsonSeries]
    metadata: dict[str, dict[str, str]]
    notes: tuple[str, ...]
    size_bytes: int
    lost_bytes: int = 0
    complete: bool = True
    replay: list | None = field(default=None, repr=False, compare=False)
    format: str = "mcap"  # or "ros1 bag", "ros2 bag" (wmrid.io.bag)
    definitions: dict[str, tuple[str, str]] = field(default_factory=dict)  # topic -> (type, .msg text or "")

    def channel(self, topic: str) -> ChannelInfo | None:
        return next((c for c in self.channels if c.topic == topic), None)


# --------------------------------------------------------------------------------------------------
# Per-channel accumulation while the reader streams


@dataclass
class Accumulator:
    """Per-channel state while streaming."""

    info: dict[str, Any]
    count: int = 0
    first_ns: int | None = None
    last_ns: int | None = None
    names: list[str] = field(default_factory=list)
    ref: np.ndarray | None = None
    ref_off: np.ndarray | None = None
    parts: list[tuple[np.ndarray, ...]] = field(default_factory=list)
    skipped: int = 0
    json_rows: list[tuple[int, list[float]]] = field(default_factory=list)
    batches: int = 0  # parts made (kept or not)
    stats: JointStats | None = None
    standard: bool | None = None  # the schema is the standard JointState (the compiled reader may decode it)
    too_wide: bool = False  # its messages name more than MAX_JOINTS joints: skipped


def summary(acc: Accumulator) -> JointSummary:
    stats = acc.stats or JointStats(len(acc.names))
    return JointSummary(
        topic=acc.info["topic"], channel_id=acc.info["id"], names=tuple(acc.names), count=stats.count,
        has_value=stats.has_value, has_nonzero=stats.has_nonzero, has_nan=stats.has_nan, has_inf=stats.has_inf,
        max_abs=stats.max_abs, times={key: t.summary() for key, t in stats.times.items()},
    )  # fmt: skip


def join(acc: Accumulator) -> JointSeries:
    k = len(acc.names)
    log_ns = np.concatenate([p[0] for p in acc.parts])
    stamp = np.concatenate([p[1] for p in acc.parts])

    def stack(i: int) -> np.ndarray:
        blocks = []
        for part in acc.parts:
            block = part[i]
            if block.shape[1] < k:  # joints first met later: NaN before
                block = np.hstack([block, np.full((block.shape[0], k - block.shape[1]), np.nan)])
            blocks.append(block)
        return np.concatenate(blocks)

    return JointSeries(
        topic=acc.info["topic"], names=tuple(acc.names), log_ns=log_ns, stamp_ns=stamp,
        position=stack(2), velocity=stack(3), effort=stack(4), skipped=acc.skipped,
    )  # fmt: skip
