"""From what an MCAP holds (:mod:`wmrid.io.mcap.reader`) to one wheel log: topics, joints, time, alignment.

Choices, each stated in the log's notes:

* **Topics.** ``topic`` when one JointState holds both speed and effort; ``velocity_topic`` and
  ``effort_topic`` when they differ.  Without either, the JointState topic with speed (or position)
  and effort when it is the only one with either; when several topics carry speeds (a measured state
  next to a command, say) wmrid refuses to guess and lists them with what each holds.
* **Joints** by name (``right_joint``, ``left_joint``); without them, the one name containing "right"
  and "wheel" and the one containing "left" and "wheel" (case-insensitive), else the one containing
  "right" and the one containing "left"; anything else is refused with the candidates listed.
* **Time.** ``time_source="auto"`` takes the header stamps when every one is set (non-zero) and they
  never go backwards, else the MCAP log time (when the recorder received the message).  Messages are
  put in time order; a repeated stamp keeps the first message.
* **Alignment of split topics** on the speed topic's stamps (where eta is measured).  ``"linear"``
  (default): the effort interpolated linearly between its two neighbours.  ``"zoh"``: at each speed
  stamp, the latest effort at or before it (what a drive does with a command until the next arrives).
  Speed samples before the first effort, or after the last (zoh: more than 1.5 effort periods after),
  are dropped.  Measured on the paper scenario (40 s, 1 kHz speeds, efforts at 500 Hz stamped 0.3 ms
  late; tests/test_mcap_read.py): linear leaves m11 0.014 %, Vc 0.12 %, Fv1 4.9 % off; zoh 0.065 %,
  0.60 %, 25 %.  Interpolation recovers much of the torque between effort messages that a hold loses.
* **Speed from positions** when the speed field is empty or all zero (or ``velocity_from="position"``):
  :func:`wmrid.io.signals.speed_from_position`.

Streaming (:func:`stream_plan`, :class:`SignalStream`): for a long recording the choices above are made
from a first pass's :class:`wmrid.io.mcap.contents.JointSummary` (the same rules, the same messages and errors),
and the signals are then computed batch by batch as the second pass decodes the messages, giving exactly
the values :func:`signals_from_mcap` gives.  One topic: each batch is cleaned and matched on its own,
holding back the messages that share the batch's last time stamp for the next one.  Split topics: the
efforts are kept from the one at or before the oldest speed stamp still waiting, and a speed is put out
once an effort stamped after it has been read; the effort's median period (for the zero-order hold's end
and the note) is found exactly from the first pass's histogram of steps and the steps in its middle
buckets, counted again.  Kept whole (:func:`stream_plan` says why): speeds derived from positions (the
Savitzky-Golay window), topics whose messages are not in time order in the file, infinite values, and for
split topics messages that lack a wheel value or topics that plainly do not overlap.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from wmrid.core.errors import LogFormatError, UsageError
from wmrid.core.wheel_log import SPLIT_NOTE
from wmrid.io.mcap.contents import JointSeries, JointSummary, JsonSeries, McapContents
from wmrid.io.mcap.records import JOINT_STATE, bucket_range
from wmrid.io.signals import SignalOptions, convert, position_to_rad, speed_from_position

TIME_SOURCES = ("auto", "header", "log")
ALIGN_RULES = ("zoh", "linear")
VELOCITY_FROM = ("auto", "velocity", "position")


@dataclass(frozen=True)
class TopicSelection:
    """Which topics and joints hold the wheel signals, and how to put them on one time base."""

    topic: str | None = None
    velocity_topic: str | None = None
    effort_topic: str | None = None
    right_joint: str | None = None
    left_joint: str | None = None
    time_source: str = "auto"
    align: str = "linear"
    velocity_from: str = "auto"

    def __post_init__(self) -> None:
        if self.time_source not in TIME_SOURCES:
            raise UsageError(f"--time-source must be one of {', '.join(TIME_SOURCES)}, got {self.time_source!r}")
        if self.align not in ALIGN_RULES:
            raise UsageError(f"--align must be one of {', '.join(ALIGN_RULES)}, got {self.align!r}")
        if self.velocity_from not in VELOCITY_FROM:
            raise UsageError(f"--velocity-from must be one of {', '.join(VELOCITY_FROM)}, got {self.velocity_from!r}")
        if self.topic and (self.velocity_topic or self.effort_topic):
            raise UsageError("give either --topic, or --velocity-topic and --effort-topic, not both")


@dataclass(frozen=True)
class Signals:
    """Two-wheel signals on one time base: t_ns (n,) int64; speed, effort (n, 2) [right, left]; notes."""

    t_ns: np.ndarray
    speed: np.ndarray
    effort: np.ndarray
    notes: tuple[str, ...]
    effort_unit: str


def _topic_listing(contents: McapContents) -> str:
    damage = [n for n in contents.notes if "lost" in n or "skipped" in n or "cut short" in n]
    if not contents.channels:
        return "it holds no channels" + (f" ({'; '.join(damage)})" if damage else "")
    parts = []
    for c in contents.channels:
        enc = "" if c.message_encoding in ("cdr", "json") else f", message encoding {c.message_encoding!r}"
        parts.append(f"{c.topic} ({c.schema_name or '?'}{enc}, {c.count} messages)")
    return "its topics are " + ", ".join(parts)


def _joint_listing(contents: McapContents) -> str:
    parts = []
    for topic, series in sorted(contents.joints.items()):
        fields = ", ".join(f"{f} {series.populated(f)}" for f in ("position", "velocity", "effort"))
        parts.append(f"{topic} [joints {', '.join(series.names)}; {fields}]")
    return "; ".join(parts)


def _series(contents: McapContents, topic: str, role: str) -> Any:
    if topic in contents.joints:
        return contents.joints[topic]
    chan = contents.channel(topic)
    if chan is None:
        raise LogFormatError(f"{contents.source}: no topic {topic!r} (--{role}); {_topic_listing(contents)}")
    raise LogFormatError(
        f"{contents.source}: topic {topic!r} holds {chan.schema_name or chan.message_encoding} messages, not "
        f"{JOINT_STATE} in CDR; for a JSON topic map its fields with --columns (e.g. eta_r=wheels.right.velocity)"
    )


def choose_topics(contents: McapContents, sel: TopicSelection) -> tuple[Any, Any, list[str]]:
    """(speed series, effort series, notes) following the rules in the module docstring (each a
    :class:`JointSeries`, or a :class:`JointSummary` when ``contents`` is not complete)."""
    if not contents.joints:
        raise LogFormatError(
            f"{contents.source}: no {JOINT_STATE} messages (CDR) found; {_topic_listing(contents)}. wmrid needs "
            "the wheel speeds and efforts as JointState, or a JSON topic with --topic and --columns field paths"
        )
    if sel.topic:
        series = _series(contents, sel.topic, "topic")
        return series, series, [f"speed and effort read from {sel.topic}"]
    if sel.velocity_topic or sel.effort_topic:
        vel = _series(contents, sel.velocity_topic or sel.effort_topic, "velocity-topic")
        eff = _series(contents, sel.effort_topic or sel.velocity_topic, "effort-topic")
        return vel, eff, [f"speed read from {vel.topic}, effort from {eff.topic}"]

    def has(series: Any, *names: str) -> bool:
        return any(series.populated(n) in ("yes", "partly") for n in names)

    with_effort = [s for s in contents.joints.values() if has(s, "effort")]
    with_speed = [s for s in contents.joints.values() if has(s, "velocity", "position")]
    if len(with_effort) == 1 and len(with_speed) == 1 and with_effort[0] is with_speed[0]:
        only = with_effort[0]
        return only, only, [f"speed and effort read from {only.topic}, the one JointState topic with both"]
    if len(contents.joints) == 1 and not with_effort:
        only = next(iter(contents.joints.values()))
        return only, only, [f"speed and effort read from {only.topic}, the only JointState topic"]
    raise LogFormatError(
        f"{contents.source}: cannot tell which JointState topic holds the wheel speeds and which the efforts "
        f"({_joint_listing(contents)}); say it with --topic T, or --velocity-topic V --effort-topic E"
    )


def choose_joints(names: tuple[str, ...], sel: TopicSelection, source: str, topic: str) -> tuple[str, str, str | None]:
    """(right joint, left joint, note) by name, following the rules in the module docstring."""
    if sel.right_joint and sel.left_joint:
        for joint in (sel.right_joint, sel.left_joint):
            if joint not in names:
                raise LogFormatError(
                    f"{source}: topic {topic} has no joint {joint!r}; its joints are {', '.join(names)}"
                )
        return sel.right_joint, sel.left_joint, None
    lower = {n: n.lower() for n in names}
    for need_wheel in (True, False):
        right = [n for n, low in lower.items() if "right" in low and (not need_wheel or "wheel" in low)]
        left = [n for n, low in lower.items() if "left" in low and (not need_wheel or "wheel" in low)]
        right = [sel.right_joint] if sel.right_joint else right
        left = [sel.left_joint] if sel.left_joint else left
        if len(right) == 1 and len(left) == 1 and right[0] != left[0]:
            return right[0], left[0], f"wheel joints chosen by name: right = {right[0]!r}, left = {left[0]!r}"
    raise LogFormatError(
        f"{source}: cannot tell the right and left wheel joints of {topic} apart (joints: {', '.join(names)}); "
        "name them with --right-joint NAME --left-joint NAME"
    )


def _time_source(series: Any, sel: TopicSelection) -> tuple[str, str]:
    """("header" or "log", note): the time source of a topic by ``sel.time_source`` (module docstring)."""
    if sel.time_source == "header":
        return "header", f"{series.topic}: times from the message header stamps"
    if sel.time_source == "log":
        return "log", f"{series.topic}: times from the MCAP log time (when the recorder received each message)"
    if isinstance(series, JointSummary):
        stamps = series.times["header"]
        n, all_set, in_order = series.count, stamps.all_positive, stamps.ordered
    else:
        stamp = series.stamp_ns
        n, all_set, in_order = len(stamp), bool(np.all(stamp > 0)), bool(np.all(np.diff(stamp) >= 0))
    if n and all_set and in_order:
        return "header", f"{series.topic}: times from the message header stamps (all set, never going back)"
    why = "some are zero" if n and not all_set else "they go backwards"
    return "log", f"{series.topic}: times from the MCAP log time, not the header stamps ({why})"


def _time_values(series: JointSeries, source: str) -> np.ndarray:
    return series.stamp_ns if source == "header" else series.log_ns


def _times(series: JointSeries, sel: TopicSelection) -> tuple[np.ndarray, str]:
    source, note = _time_source(series, sel)
    return _time_values(series, source), note


def _clean_counts(t: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray, int, bool, int]:
    """(t, values, rows with NaN dropped, whether sorting was needed, repeated stamps dropped): see :func:`_clean`."""
    ok = ~np.any(np.isnan(values), axis=1)
    skipped = int((~ok).sum())
    if skipped:
        t, values = t[ok], values[ok]
    order = np.argsort(t, kind="stable")
    unsorted = bool(np.any(np.diff(order) < 0))
    if unsorted:
        t, values = t[order], values[order]
    dup = np.concatenate([[False], np.diff(t) == 0])
    repeats = int(dup.sum())
    if repeats:
        t, values = t[~dup], values[~dup]
    return t, values, skipped, unsorted, repeats


def _clean_notes(topic: str, what: str, skipped: int, unsorted: bool, repeats: int) -> list[str]:
    notes = []
    if skipped:
        notes.append(f"{topic}: {skipped} messages without the wheel {what} were skipped")
    if unsorted:
        notes.append(f"{topic}: messages were not in time order; sorted by time")
    if repeats:
        notes.append(f"{topic}: {repeats} messages repeat the previous time stamp and were dropped")
    return notes


def _clean(t: np.ndarray, values: np.ndarray, topic: str, what: str) -> tuple[np.ndarray, np.ndarray, list[str]]:
    """Drop rows with NaN, sort by time, drop repeated stamps (keeping the first); notes on what was dropped."""
    t, values, skipped, unsorted, repeats = _clean_counts(t, values)
    return t, values, _clean_notes(topic, what, skipped, unsorted, repeats)


def _populated(series: Any, name: str, cols: list[int]) -> bool:
    return series.any_nonzero(name, cols)


@dataclass(frozen=True)
class SignalPlan:
    """The whole-log choices of :func:`signals_from_mcap`, made before any value is read.

    vel, eff : the speed and effort topics (:class:`JointSeries` or :class:`JointSummary`; the same object for
    one topic).  right, left : joint names; vcols, ecols : their columns in vel and eff.  vel_time, eff_time :
    "header" or "log"; eff_time_note : its note (split topics).  use_position : speeds from positions.
    notes : topics, joints and the speed topic's time source.
    """

    vel: Any
    eff: Any
    right: str
    left: str
    vcols: list[int]
    ecols: list[int]
    vel_time: str
    eff_time: str
    eff_time_note: str
    use_position: bool
    notes: tuple[str, ...]


def plan_signals(contents: McapContents, sel: TopicSelection) -> SignalPlan:
    """Topics, joints, time sources and where the speeds come from, with the errors of :func:`signals_from_mcap`."""
    vel_series, eff_series, notes = choose_topics(contents, sel)
    right, left, joint_note = choose_joints(vel_series.names, sel, contents.source, vel_series.topic)
    if joint_note:
        notes.append(joint_note)
    for series in {vel_series.topic: vel_series, eff_series.topic: eff_series}.values():
        for joint in (right, left):
            if joint not in series.names:
                raise LogFormatError(
                    f"{contents.source}: topic {series.topic} has no joint {joint!r}; its joints are "
                    f"{', '.join(series.names)}; name them with --right-joint and --left-joint"
                )
    vcols = [vel_series.names.index(right), vel_series.names.index(left)]
    ecols = [eff_series.names.index(right), eff_series.names.index(left)]

    vel_time, note = _time_source(vel_series, sel)
    notes.append(note)
    eff_time, eff_note = _time_source(eff_series, sel)
    use_position = sel.velocity_from == "position" or (
        sel.velocity_from == "auto" and not _populated(vel_series, "velocity", vcols)
    )
    if use_position and not _populated(vel_series, "position", vcols):
        raise LogFormatError(
            f"{contents.source}: topic {vel_series.topic} carries neither wheel speeds nor positions for "
            f"{right!r} and {left!r}; choose the topic that does with --velocity-topic"
        )
    return SignalPlan(
        vel=vel_series, eff=eff_series, right=right, left=left, vcols=vcols, ecols=ecols, vel_time=vel_time,
        eff_time=eff_time, eff_time_note=eff_note, use_position=use_position, notes=tuple(notes),
    )  # fmt: skip


def _check_effort(contents: McapContents, plan: SignalPlan) -> None:
    if not _populated(plan.eff, "effort", plan.ecols):
        raise LogFormatError(
            f"{contents.source}: the effort of {plan.right!r} and {plan.left!r} on {plan.eff.topic} is "
            f"{plan.eff.populated('effort')}; the efforts must come from another topic: give --effort-topic "
            f"({_joint_listing(contents)})"
        )


def signals_from_mcap(
    contents: McapContents, sel: TopicSelection, opts: SignalOptions, gear_ratio: float | None
) -> Signals:
    """Speed (rad/s) and effort (N m, or the given PWM/voltage units) of both wheels on one time base."""
    plan = plan_signals(contents, sel)
    vel_series, eff_series, vcols, ecols = plan.vel, plan.eff, plan.vcols, plan.ecols
    notes = list(plan.notes)
    t_vel = _time_values(vel_series, plan.vel_time)
    use_position = plan.use_position
    if use_position:
        t_vel, pos, more = _clean(t_vel, vel_series.position[:, vcols].copy(), vel_series.topic, "position")
        notes += more
        pos = position_to_rad(pos, opts)
        speed, note = speed_from_position((t_vel - t_vel[0]) * 1e-9, pos)
        notes.append(
            f"{vel_series.topic}: {note}"
            + (" (its speed field is empty or all zero)" if sel.velocity_from == "auto" else "")
        )
    else:
        t_vel, speed, more = _clean(t_vel, vel_series.velocity[:, vcols].copy(), vel_series.topic, "speed")
        notes += more
    _check_effort(contents, plan)
    if eff_series is vel_series:
        t_eff, effort, more = _clean(
            _time_values(eff_series, plan.eff_time), eff_series.effort[:, ecols].copy(), eff_series.topic, "effort"
        )
        notes += more
        common, i_vel, i_eff = np.intersect1d(t_vel, t_eff, assume_unique=True, return_indices=True)
        t_out, speed, effort = common, speed[i_vel], effort[i_eff]
    else:
        notes.append(plan.eff_time_note)
        t_eff = _time_values(eff_series, plan.eff_time)
        t_eff, effort, more = _clean(t_eff, eff_series.effort[:, ecols].copy(), eff_series.topic, "effort")
        notes += more
        t_out, speed, effort, note = align(
            t_vel, speed, t_eff, effort, sel.align, vel_series.topic, eff_series.topic, contents.source
        )
        notes.append(note)

    speed, effort, more = convert(speed, effort, opts, gear_ratio, speed_in_rad_s=use_position)
    notes += more
    return Signals(t_ns=t_out, speed=speed, effort=effort, notes=tuple(notes), effort_unit=opts.effort_label)


def align(
    t_vel: np.ndarray,
    speed: np.ndarray,
    t_eff: np.ndarray,
    effort: np.ndarray,
    rule: str,
    vel_topic: str,
    eff_topic: str,
    source: str,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, str]:
    """Effort put on the speed stamps by ``rule`` ("zoh" or "linear"); (t, speed, effort, note)."""
    if len(t_eff) < 2 or len(t_vel) < 2:
        raise LogFormatError(f"{source}: too few messages on {vel_topic} or {eff_topic} to align them")
    period = float(np.median(np.diff(t_eff)))
    lo = t_eff[0]
    hi = t_eff[-1] + (1.5 * period if rule == "zoh" else 0.0)
    keep = (t_vel >= lo) & (t_vel <= hi)
    if not keep.any():
        raise _no_overlap(source, vel_topic, t_vel, eff_topic, t_eff)
    t_out, speed = t_vel[keep], speed[keep]
    if rule == "zoh":
        idx = np.searchsorted(t_eff, t_out, side="right") - 1
        out = effort[idx]
    else:
        out = np.column_stack([np.interp(t_out, t_eff, effort[:, i]) for i in range(2)])
    dropped = int((~keep).sum())
    note = _align_note(rule, vel_topic, float(np.median(np.diff(t_vel))), eff_topic, period, dropped)
    return t_out, speed, out, note


def _no_overlap(source: str, vel_topic: str, t_vel: np.ndarray, eff_topic: str, t_eff: np.ndarray) -> LogFormatError:
    return LogFormatError(
        f"{source}: {vel_topic} ({_span(t_vel)}) and {eff_topic} ({_span(t_eff)}) do not overlap in time; "
        "check that both topics come from the same run (or try --time-source log)"
    )


def _align_note(rule: str, vel_topic: str, vel_step: float, eff_topic: str, period: float, dropped: int) -> str:
    if rule == "zoh":
        how = "held from the latest effort message at or before each speed stamp (zero-order hold)"
    else:
        how = "interpolated linearly between effort messages"
    rate_v = 1e9 / vel_step
    rate_e = 1e9 / period
    return f"effort ({eff_topic}, {rate_e:.4g} Hz) {SPLIT_NOTE} ({vel_topic}, {rate_v:.4g} Hz): {how}" + (
        f"; {dropped} speed samples outside the effort's time span dropped" if dropped else ""
    )


def _span(t: np.ndarray) -> str:
    return f"{t[0] * 1e-9:.3f} s to {t[-1] * 1e-9:.3f} s"


# --------------------------------------------------------------------------------------------------
# Streaming: the same signals, batch by batch


def stream_plan(
    contents: McapContents, sel: TopicSelection, opts: SignalOptions, gear_ratio: float | None
) -> tuple[SignalPlan, str | None]:
    """(plan, why not) for a recording summarised by :func:`wmrid.io.mcap.reader.scan_mcap` (``contents.complete``
    False): ``why not`` is None when :class:`SignalStream` gives exactly what :func:`signals_from_mcap` gives,
    else the reason to read the log whole.  Raises what :func:`signals_from_mcap` raises before reading values.
    """
    plan = plan_signals(contents, sel)
    if plan.use_position:
        return plan, "its wheel speeds are derived from positions (a Savitzky-Golay window over the whole series)"
    _check_effort(contents, plan)
    vel, eff, vcols, ecols = plan.vel, plan.eff, plan.vcols, plan.ecols
    t_vel, t_eff = vel.times[plan.vel_time], eff.times[plan.eff_time]
    for series, times in ((vel, t_vel), (eff, t_eff)):
        if not (times.ordered and times.steps_ok):
            return plan, f"the messages of {series.topic} are not in time order in the file"
    if vel.has_inf[1, vcols].any() or eff.has_inf[2, ecols].any():
        return plan, "a wheel speed or effort is infinite"
    try:  # the largest values converted: if they stay finite, so does every value (the conversion scales)
        with np.errstate(all="ignore"):
            speed, effort, _ = convert(vel.max_abs[1, vcols][None], eff.max_abs[2, ecols][None], opts, gear_ratio)
    except UsageError:  # the whole read raises it, after its other checks
        return plan, "its efforts cannot be converted"
    if not (np.isfinite(speed).all() and np.isfinite(effort).all()):
        return plan, "a converted wheel speed or effort is not finite"
    if eff is vel:
        return plan, None
    if vel.has_nan[1, vcols].any() or eff.has_nan[2, ecols].any():
        return plan, f"some messages of {vel.topic} or {eff.topic} lack a wheel value"
    if vel.count - t_vel.repeats < 2 or eff.count - t_eff.repeats < 2:
        return plan, "too few messages to align"
    lo, last = np.int64(t_eff.first), np.int64(t_eff.last)

    def inside(x: int) -> bool:
        return bool(np.int64(x) >= lo) and bool(np.int64(x) <= last + 0.0)

    overlap = inside(t_vel.first) or inside(t_vel.last)
    apart = np.int64(t_vel.last) < lo or (sel.align == "linear" and np.int64(t_vel.first) > last + 0.0)
    if apart and not overlap:
        return plan, "the topics do not overlap in time"
    return plan, None  # otherwise, when overlap is not proven here (speeds around the efforts), the end decides


class _StepMedian:
    """``float(np.median(np.diff(t)))`` of a sorted series t without repeats, exactly, in bounded memory: the
    first pass's histogram of its positive steps says which buckets hold the middle steps; the steps falling
    in them are counted again as the series comes by."""

    def __init__(self, hist: np.ndarray):
        cum = np.cumsum(hist)
        n = int(cum[-1])
        ranks = [n // 2] if n % 2 else [n // 2 - 1, n // 2]
        first = int(np.searchsorted(cum, ranks[0], side="right"))
        last = int(np.searchsorted(cum, ranks[-1], side="right"))
        below = int(cum[first - 1]) if first else 0
        self.ranks = [r - below for r in ranks]
        self.low, self.high = bucket_range(first)[0], bucket_range(last)[1]
        self.counts: dict[int, int] = {}

    def add(self, steps: np.ndarray) -> None:
        inside = steps[(steps >= self.low) & (steps <= self.high)]
        if len(inside):
            values, counts = np.unique(inside, return_counts=True)
            for v, c in zip(values.tolist(), counts.tolist(), strict=True):
                self.counts[v] = self.counts.get(v, 0) + c

    def value(self) -> float:
        values = sorted(self.counts)
        cum = np.cumsum([self.counts[v] for v in values])
        picked = np.array([values[int(np.searchsorted(cum, r, side="right"))] for r in self.ranks], dtype=np.int64)
        return float(np.median(picked))


def _changed(source: str) -> LogFormatError:
    return LogFormatError(
        f"{source}: the file changed while it was read (its messages are no longer in time order); identify a copy "
        "that is not being written"
    )


class SignalStream:
    """:func:`signals_from_mcap` for a plan :func:`stream_plan` accepted, batch by batch.

    ``feed`` the parts of :func:`wmrid.io.mcap.reader.iter_joint_parts` for ``channels`` as they come, then call
    ``finish``; each returns a list of (t_ns (k,), speed (k, 2), effort (k, 2)) in time order which, joined,
    are :class:`Signals` ``t_ns, speed, effort``.  ``notes()`` after ``finish``: the notes of
    :func:`signals_from_mcap`.  ``held``: the messages waiting (for the caller's accounting).
    Memory: about ``rows`` messages, plus those decoded ahead of the other topic (split topics).
    """

    def __init__(
        self, plan: SignalPlan, sel: TopicSelection, opts: SignalOptions, gear_ratio: float | None, source: str,
        rows: int,
    ):  # fmt: skip
        self.plan, self.opts, self.gear_ratio, self.source, self.rows = plan, opts, gear_ratio, source, rows
        self.rule = sel.align
        self.same = plan.eff is plan.vel
        self.channels = sorted({plan.vel.channel_id, plan.eff.channel_id})
        self.held = 0
        self._notes: list[str] = []
        if self.same:
            self._pending: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
            self._pending_n = 0
            self._prev: np.int64 | None = None  # the last stamp processed
            self._speed_counts = [0, False, 0]
            self._effort_counts = [0, False, 0]
        else:
            t_vel, t_eff = plan.vel.times[plan.vel_time], plan.eff.times[plan.eff_time]
            self._vel_summary, self._eff_summary = t_vel, t_eff
            self._lo, self._last = np.int64(t_eff.first), np.int64(t_eff.last)
            self._eff_median, self._vel_median = _StepMedian(t_eff.hist), _StepMedian(t_vel.hist)
            if self.rule == "zoh":  # no speed stamp beyond this can be kept (the period is at most the bucket's top)
                self._hi_bound = self._last + 1.5 * float(self._eff_median.high)
            else:
                self._hi_bound = self._last + 0.0
            self._eff_prev: np.int64 | None = None
            self._vel_prev: np.int64 | None = None
            self._eff_t = np.empty(0, dtype=np.int64)
            self._eff_v = np.empty((0, 2))
            self._vel_t = np.empty(0, dtype=np.int64)
            self._vel_v = np.empty((0, 2))
            self._repeats = [0, 0]  # speed, effort
            self._dropped = 0
            self._kept = 0

    # ---- feeding

    def feed(self, parts: dict[int, list[tuple[np.ndarray, ...]]]) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        plan = self.plan
        if self.same:
            got = parts.get(plan.vel.channel_id)
            if not got:
                return []
            t = self._column(got, plan.vel_time)
            if not len(t):  # a batch whose messages could not be decoded
                return []
            speed = np.concatenate([p[3] for p in got])[:, plan.vcols]
            effort = np.concatenate([p[4] for p in got])[:, plan.ecols]
            self._pending.append((t, speed, effort))
            self._pending_n += len(t)
            self.held = self._pending_n
            return self._same_batch(final=False) if self._pending_n >= self.rows else []
        eff = parts.get(plan.eff.channel_id)
        if eff:
            self._add_efforts(self._column(eff, plan.eff_time), np.concatenate([p[4] for p in eff])[:, plan.ecols])
        vel = parts.get(plan.vel.channel_id)
        if vel:
            self._add_speeds(self._column(vel, plan.vel_time), np.concatenate([p[3] for p in vel])[:, plan.vcols])
        out = self._split_ready(final=False)
        self._trim_efforts()
        self.held = len(self._eff_t) + len(self._vel_t)
        return out

    def finish(self) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        if self.same:
            out = self._same_batch(final=True)
            speed_notes = _clean_notes(self.plan.vel.topic, "speed", *self._speed_counts)
            effort_notes = _clean_notes(self.plan.eff.topic, "effort", *self._effort_counts)
            self._notes = [*self.plan.notes, *speed_notes, *effort_notes]
        else:
            out = self._split_finish()
        _, _, more = convert(np.empty((0, 2)), np.empty((0, 2)), self.opts, self.gear_ratio)
        self._notes += more
        self.held = 0
        return out

    def notes(self) -> list[str]:
        return list(self._notes)

    @staticmethod
    def _column(parts: list[tuple[np.ndarray, ...]], time: str) -> np.ndarray:
        return np.concatenate([p[1] if time == "header" else p[0] for p in parts])

    def _convert(self, t: np.ndarray, speed: np.ndarray, effort: np.ndarray) -> tuple[np.ndarray, ...]:
        speed, effort, _ = convert(speed, effort, self.opts, self.gear_ratio)
        return t, speed, effort

    # ---- one topic

    def _same_batch(self, final: bool) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        if not self._pending:
            return []
        t = np.concatenate([p[0] for p in self._pending])
        speed = np.concatenate([p[1] for p in self._pending])
        effort = np.concatenate([p[2] for p in self._pending])
        if np.any(t[1:] < t[:-1]) or (self._prev is not None and t[0] <= self._prev):
            raise _changed(self.source)
        if not final:  # hold back the messages sharing the last stamp: a repeat may follow in the next batch
            cut = int(np.searchsorted(t, t[-1], side="left"))
            if cut == 0:
                return []
            self._pending = [(t[cut:], speed[cut:], effort[cut:])]
            t, speed, effort = t[:cut], speed[:cut], effort[:cut]
        else:
            self._pending = []
        self._pending_n = sum(len(p[0]) for p in self._pending)
        self.held = self._pending_n
        self._prev = t[-1]
        t_vel, speed, *counts = _clean_counts(t, speed)
        self._speed_counts = _add_counts(self._speed_counts, counts)
        t_eff, effort, *counts = _clean_counts(t, effort)
        self._effort_counts = _add_counts(self._effort_counts, counts)
        common, i_vel, i_eff = np.intersect1d(t_vel, t_eff, assume_unique=True, return_indices=True)
        if not len(common):
            return []
        return [self._convert(common, speed[i_vel], effort[i_eff])]

    # ---- split topics

    def _dedup(self, t: np.ndarray, values: np.ndarray, prev: np.int64 | None, which: int) -> tuple[np.ndarray, ...]:
        """Drop repeated stamps (keeping the first); the positive steps, counted for the medians."""
        up = t[1:] >= t[:-1]
        if not up.all() or (prev is not None and t[0] < prev):
            raise _changed(self.source)
        steps = np.diff(t) if prev is None else np.diff(t, prepend=prev)
        fresh = np.concatenate(([True], steps != 0)) if prev is None else steps != 0
        self._repeats[which] += int(len(t) - np.count_nonzero(fresh))
        (self._vel_median if which == 0 else self._eff_median).add(steps[steps > 0])
        if not fresh.all():
            t, values = t[fresh], values[fresh]
        return t, values

    def _add_efforts(self, t: np.ndarray, effort: np.ndarray) -> None:
        if not len(t):
            return
        prev, self._eff_prev = self._eff_prev, t[-1]
        t, effort = self._dedup(t, effort, prev, 1)
        self._eff_t = np.concatenate([self._eff_t, t])
        self._eff_v = np.concatenate([self._eff_v, effort])

    def _add_speeds(self, t: np.ndarray, speed: np.ndarray) -> None:
        if not len(t):
            return
        prev, self._vel_prev = self._vel_prev, t[-1]
        t, speed = self._dedup(t, speed, prev, 0)
        keep = (t >= self._lo) & (t <= self._hi_bound)  # outside these the speed is dropped whatever the period
        if not keep.all():
            self._dropped += int(len(t) - np.count_nonzero(keep))
            t, speed = t[keep], speed[keep]
        self._vel_t = np.concatenate([self._vel_t, t])
        self._vel_v = np.concatenate([self._vel_v, speed])

    def _split_ready(self, final: bool) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        """Put the efforts on the waiting speed stamps whose neighbours have all been read (all when final)."""
        t_vel, t_eff = self._vel_t, self._eff_t
        if not len(t_vel) or not len(t_eff):
            return []
        linear = self.rule == "linear"
        if final:
            n = len(t_vel)
        elif linear:  # the effort after each speed stamp (as np.interp compares them: in float64) has been read
            n = int(np.searchsorted(t_vel.astype(np.float64), np.float64(t_eff[-1]), side="left"))
        else:
            n = int(np.searchsorted(t_vel, t_eff[-1], side="left"))
        if n == 0:
            return []
        t_out, speed = t_vel[:n], self._vel_v[:n]
        if linear:  # np.interp uses the last effort at or before each stamp and the next: the buffer holds both
            out = np.column_stack([np.interp(t_out, t_eff, self._eff_v[:, i]) for i in range(2)])
        else:
            out = self._eff_v[np.searchsorted(t_eff, t_out, side="right") - 1]
        self._vel_t, self._vel_v = t_vel[n:], self._vel_v[n:]
        self._kept += n
        return [self._convert(t_out, speed, out)]

    def _trim_efforts(self) -> None:
        """Forget the efforts no speed stamp still to come needs: those before the one at or before the next
        speed stamp, and those after the one following the last speed stamp of the file."""
        t_eff = self._eff_t
        if len(t_eff) < 4:
            return
        if len(self._vel_t):
            upcoming = self._vel_t[0]
        else:
            upcoming = self._vel_prev if self._vel_prev is not None else np.int64(self._vel_summary.first)
        final = np.int64(self._vel_summary.last)
        if self.rule == "linear":  # np.interp compares stamps in float64
            t_eff, upcoming, final = t_eff.astype(np.float64), np.float64(upcoming), np.float64(final)
        start = max(int(np.searchsorted(t_eff, upcoming, side="right")) - 2, 0)
        stop = int(np.searchsorted(t_eff, final, side="right")) + 1
        if start > 0 or stop < len(t_eff):
            self._eff_t, self._eff_v = self._eff_t[start:stop], self._eff_v[start:stop]

    def _split_finish(self) -> list[tuple[np.ndarray, np.ndarray, np.ndarray]]:
        plan = self.plan
        period = self._eff_median.value()
        hi = self._last + (1.5 * period if self.rule == "zoh" else 0.0)
        keep = self._vel_t <= hi
        if not keep.all():
            self._dropped += int(len(keep) - np.count_nonzero(keep))
            self._vel_t, self._vel_v = self._vel_t[keep], self._vel_v[keep]
        out = self._split_ready(final=True)
        t_vel, t_eff = self._vel_summary, self._eff_summary
        if self._kept == 0:
            raise _no_overlap(
                self.source, plan.vel.topic, np.array([t_vel.first, t_vel.last], dtype=np.int64), plan.eff.topic,
                np.array([t_eff.first, t_eff.last], dtype=np.int64),
            )  # fmt: skip
        notes = [*plan.notes, *_clean_notes(plan.vel.topic, "speed", 0, False, self._repeats[0]), plan.eff_time_note]
        notes += _clean_notes(plan.eff.topic, "effort", 0, False, self._repeats[1])
        notes.append(
            _align_note(self.rule, plan.vel.topic, self._vel_median.value(), plan.eff.topic, period, self._dropped)
        )
        self._notes = notes
        return out


def _add_counts(total: list, counts: list) -> list:
    return [total[0] + counts[0], total[1] or counts[1], total[2] + counts[2]]


def signals_from_json(contents: McapContents, topic: str, opts: SignalOptions, gear_ratio: float | None) -> Signals:
    """Speed and effort from a JSON topic read with field paths (keys eta_r, eta_l, tau_r, tau_l, optional t)."""
    series: JsonSeries = contents.json[topic]
    v = series.values
    notes = [f"speed and effort read from the JSON topic {topic} by the field paths given with --columns"]
    if "t" in v:
        t_ns = np.round(v["t"] * 1e9).astype(np.int64)
        notes.append(f"{topic}: times from the field mapped to t (seconds)")
    else:
        t_ns = series.log_ns
        notes.append(f"{topic}: times from the MCAP log time")
    both = np.column_stack([v["eta_r"], v["eta_l"], v["tau_r"], v["tau_l"]])
    t_ns, both, more = _clean(t_ns, both, topic, "speed or effort")
    notes += more
    speed, effort, more = convert(both[:, :2], both[:, 2:], opts, gear_ratio)
    notes += more
    return Signals(t_ns=t_ns, speed=speed, effort=effort, notes=tuple(notes), effort_unit=opts.effort_label)
