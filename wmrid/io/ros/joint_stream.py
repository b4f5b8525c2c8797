"""JointState signals streamed piece by piece for recordings of more than a million messages: the plan made from the
survey, then the same signals as :func:`wmrid.io.ros.joints.signals_from_mcap` gives, batch by batch, split topics
aligned across pieces (:class:`SignalStream`)."""

from __future__ import annotations

import numpy as np

from wmrid.core.errors import LogFormatError, UsageError
from wmrid.io.mcap.records import bucket_range
from wmrid.io.ros.contents import McapContents
from wmrid.io.ros.joints import (
    SignalPlan,
    align_note,
    check_effort,
    clean_counts,
    clean_notes,
    no_overlap,
    plan_signals,
)
from wmrid.io.ros.selection import TopicSelection
from wmrid.io.signals import SignalOptions, convert


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
    check_effort(contents, plan)
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
            speed_notes = clean_notes(self.plan.vel.topic, "speed", *self._speed_counts)
            effort_notes = clean_notes(self.plan.eff.topic, "effort", *self._effort_counts)
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
        t_vel, speed, *counts = clean_counts(t, speed)
        self._speed_counts = _add_counts(self._speed_counts, counts)
        t_eff, effort, *counts = clean_counts(t, effort)
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
            raise no_overlap(
                self.source, plan.vel.topic, np.array([t_vel.first, t_vel.last], dtype=np.int64), plan.eff.topic,
                np.array([t_eff.first, t_eff.last], dtype=np.int64),
            )  # fmt: skip
        notes = [*plan.notes, *clean_notes(plan.vel.topic, "speed", 0, False, self._repeats[0]), plan.eff_time_note]
        notes += clean_notes(plan.eff.topic, "effort", 0, False, self._repeats[1])
        notes.append(
            align_note(self.rule, plan.vel.topic, self._vel_median.value(), plan.eff.topic, period, self._dropped)
        )
        self._notes = notes
        return out


def _add_counts(total: list, counts: list) -> list:
    return [total[0] + counts[0], total[1] or counts[1], total[2] + counts[2]]
