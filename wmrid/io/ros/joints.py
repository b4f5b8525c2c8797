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
  late; tests/unit/io/test_mcap_read.py): linear leaves m11 0.014 %, Vc 0.12 %, Fv1 4.9 % off; zoh 0.065 %,
  0.60 %, 25 %.  Interpolation recovers much of the torque between effort messages that a hold loses.
* **Speed from positions** when the speed field is empty or all zero (or ``velocity_from="position"``):
  :func:`wmrid.io.signals.speed_from_position`.

Streaming (:func:`stream_plan`, :class:`SignalStream`): for a long recording the choices above are made
from a first pass's :class:`wmrid.io.ros.contents.JointSummary` (the same rules, the same messages and errors),
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

from wmrid.core.errors import LogFormatError, option
from wmrid.core.wheel_log import SPLIT_NOTE, whole_efforts
from wmrid.io.mcap.records import JOINT_STATE
from wmrid.io.ros.contents import JointSeries, JointSummary, JsonSeries, McapContents
from wmrid.io.ros.selection import TopicSelection
from wmrid.io.signals import SignalOptions, convert, position_to_rad, speed_from_position


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
        f"{JOINT_STATE} in CDR; for a JSON topic map its fields with {option('columns')} (e.g. "
        "eta_r=wheels.right.velocity)"
    )


def choose_topics(contents: McapContents, sel: TopicSelection) -> tuple[Any, Any, list[str]]:
    """(speed series, effort series, notes) following the rules in the module docstring (each a
    :class:`JointSeries`, or a :class:`JointSummary` when ``contents`` is not complete)."""
    if not contents.joints:
        bag = contents.format != "mcap"  # a ROS 1 or ROS 2 bag (wmrid.io.bag): no JSON topics there
        raise LogFormatError(
            f"{contents.source}: no {JOINT_STATE} messages{'' if bag else ' (CDR)'} found; {_topic_listing(contents)}. "
            "wmrid needs the wheel speeds and efforts as JointState"
            + ("" if bag else f", or a JSON topic with {option('topic')} and {option('columns')} field paths")
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
        f"({_joint_listing(contents)}); say it with {option('topic')} T, or {option('velocity_topic')} V "
        f"{option('effort_topic')} E"
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
        f"name them with {option('right_joint')} NAME {option('left_joint')} NAME"
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


def clean_counts(t: np.ndarray, values: np.ndarray) -> tuple[np.ndarray, np.ndarray, int, bool, int]:
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


def clean_notes(topic: str, what: str, skipped: int, unsorted: bool, repeats: int) -> list[str]:
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
    t, values, skipped, unsorted, repeats = clean_counts(t, values)
    return t, values, clean_notes(topic, what, skipped, unsorted, repeats)


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
                    f"{', '.join(series.names)}; name them with {option('right_joint')} and {option('left_joint')}"
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
            f"{right!r} and {left!r}; choose the topic that does with {option('velocity_topic')}"
        )
    return SignalPlan(
        vel=vel_series, eff=eff_series, right=right, left=left, vcols=vcols, ecols=ecols, vel_time=vel_time,
        eff_time=eff_time, eff_time_note=eff_note, use_position=use_position, notes=tuple(notes),
    )  # fmt: skip


def check_effort(contents: McapContents, plan: SignalPlan) -> None:
    if not _populated(plan.eff, "effort", plan.ecols):
        raise LogFormatError(
            f"{contents.source}: the effort of {plan.right!r} and {plan.left!r} on {plan.eff.topic} is "
            f"{plan.eff.populated('effort')}; the efforts must come from another topic: give {option('effort_topic')} "
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
    check_effort(contents, plan)
    if eff_series is vel_series:
        t_eff, effort, more = _clean(
            _time_values(eff_series, plan.eff_time), eff_series.effort[:, ecols].copy(), eff_series.topic, "effort"
        )
        notes += more
        if np.array_equal(t_vel, t_eff):  # the usual case; _clean leaves both sorted and unique, as intersect1d's
            t_out = t_vel
        else:
            common, i_vel, i_eff = np.intersect1d(t_vel, t_eff, assume_unique=True, return_indices=True)
            t_out, speed, effort = common, speed[i_vel], effort[i_eff]
    else:
        notes.append(plan.eff_time_note)
        t_eff = _time_values(eff_series, plan.eff_time)
        t_eff, effort, more = _clean(t_eff, eff_series.effort[:, ecols].copy(), eff_series.topic, "effort")
        notes += more
        whole = whole_efforts(effort)
        t_out, speed, effort, note = align(
            t_vel, speed, t_eff, effort, sel.align, vel_series.topic, eff_series.topic, contents.source
        )
        notes.append(note + (f"; {whole}" if whole else ""))

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
        raise no_overlap(source, vel_topic, t_vel, eff_topic, t_eff)
    t_out, speed = t_vel[keep], speed[keep]
    if rule == "zoh":
        idx = np.searchsorted(t_eff, t_out, side="right") - 1
        out = effort[idx]
    else:
        out = np.column_stack([np.interp(t_out, t_eff, effort[:, i]) for i in range(2)])
    dropped = int((~keep).sum())
    note = align_note(rule, vel_topic, float(np.median(np.diff(t_vel))), eff_topic, period, dropped)
    return t_out, speed, out, note


def no_overlap(source: str, vel_topic: str, t_vel: np.ndarray, eff_topic: str, t_eff: np.ndarray) -> LogFormatError:
    return LogFormatError(
        f"{source}: {vel_topic} ({_span(t_vel)}) and {eff_topic} ({_span(t_eff)}) do not overlap in time; "
        f"check that both topics come from the same run (or try {option('time_source', 'log')})"
    )


def align_note(rule: str, vel_topic: str, vel_step: float, eff_topic: str, period: float, dropped: int) -> str:
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
