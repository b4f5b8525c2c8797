"""An MCAP recording as a wheel log: JointState topics decoded whole, or in pieces for recordings of more than a
million messages (summarised in a first pass, then decoded chunk by chunk, split topics aligned across pieces; the
few layouts that cannot stream exactly are decoded whole, with a note saying why).
"""

from __future__ import annotations

from collections.abc import Callable, Generator, Iterator, Mapping
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from wmrid.core.errors import LogFormatError, UsageError, option
from wmrid.core.wheel_log import (
    CACHE_ROWS,
    CHUNK_ROWS,
    MIN_SAMPLES,
    REQUIRED,
    LogStream,
    WheelLog,
    cache_rows,
    stream_arrays,
)
from wmrid.io.ros.field_paths import FieldSignals, check_values, field_signals
from wmrid.io.ros.joint_stream import SignalStream, stream_plan
from wmrid.io.ros.joints import signals_from_json, signals_from_mcap
from wmrid.io.ros.selection import TopicSelection
from wmrid.io.signals import SignalOptions
from wmrid.io.sources import Source
from wmrid.io.stamps import ABSOLUTE_LIMIT_S, NS_PER_UNIT, seconds_from_stamps

#: An MCAP whose JointState topics hold at most this many pieces' worth of messages is decoded whole, in one
#: pass (a stream of that length keeps its samples in memory anyway); a longer one is streamed.
_MCAP_WHOLE_PIECES = 4  # pieces of CHUNK_ROWS: bags of up to ~1 M messages are decoded in one pass


#: A streamed recording's first pass keeps the speeds and efforts it decoded while they take at most this many
#: bytes, and the survey reads them instead of decoding the file a second time: the 48 bytes per message of
#: a two-wheel JointState (two stamps, two speeds, two efforts) for as many messages as LogStream caches
#: samples (CACHE_ROWS, about 70 min at 1 kHz), about 200 MB, of the same order as that cache (40 bytes a
#: sample), which the survey fills as it empties these.  Longer recordings are decoded again on each pass.
_MCAP_REPLAY_BYTES = 48 * CACHE_ROWS


def read_mcap_log(
    source: Source,
    columns: Mapping[str, str],
    selection: TopicSelection,
    signals: SignalOptions,
    gear_ratio: float | None,
    rows: int = CHUNK_ROWS,
) -> LogStream:
    """An MCAP recording as a LogStream: JointState topics (or a JSON topic with field paths).

    A first pass (:func:`wmrid.io.mcap.reader.scan_mcap`) reads the file record by record.  When its JointState
    topics hold at most ``_MCAP_WHOLE_PIECES * rows`` messages, that pass keeps them and the log is assembled
    whole (:func:`_mcap_whole_log`).  A longer recording keeps only a summary per topic; the topic, joint and
    time choices are made from it and each pass over the stream decodes the file again, a batch of records
    at a time (:func:`_mcap_pieces`): memory does not grow with the recording, and the samples and notes are
    those of the whole decode.  The first of those passes (the survey) reads the speeds and efforts the scan
    kept instead when they fitted in ``_MCAP_REPLAY_BYTES``: up to about 70 minutes at 1 kHz the file is
    decoded once.  Read whole all the same, with a note saying why: speeds derived from
    positions, messages out of time order in the file, and the other cases
    :func:`wmrid.io.ros.joint_stream.stream_plan`
    lists; a JSON topic is always read whole.
    """
    # the MCAP reader (~15 ms): only an MCAP file (a bag shares this module)
    from wmrid.io.mcap.reader import iter_joint_parts, read_mcap, scan_mcap

    path = source.path or source.name
    fs = field_signals(columns) if columns else None
    if fs is not None:
        topics = fs.topics()
        recording = Recording(
            name=source.name,
            scan=lambda keep, spare: scan_mcap(path, source.data, keep=keep, spare=spare, fields=topics),
            read=lambda: read_mcap(path, data=source.data, fields=topics),
            parts=lambda channels: iter_joint_parts(path, source.data, channels, fields=topics),
        )
        return recording_log(recording, field_selection(selection, fs), signals, gear_ratio, rows, fs)
    if columns and selection.topic:
        missing = [k for k in REQUIRED[1:] if k not in columns]
        if missing:
            raise UsageError(f"a JSON topic needs field paths for {', '.join(missing)} in {option('columns')}")
        contents = read_mcap(path, data=source.data, json_fields={selection.topic: dict(columns)})
        return stream_arrays(_mcap_whole_log(source, contents, selection, signals, gear_ratio), rows)
    recording = Recording(
        name=source.name,
        scan=lambda keep, spare: scan_mcap(path, source.data, keep=keep, spare=spare),
        read=lambda: read_mcap(path, data=source.data),
        parts=lambda channels: iter_joint_parts(path, source.data, channels),
    )
    return recording_log(recording, selection, signals, gear_ratio, rows)


def field_selection(selection: TopicSelection, fs: FieldSignals) -> TopicSelection:
    """The topic selection that reads the field-path signals ``fs``: their topics, and the two joints "right" and
    "left" the readers make of them; UsageError when topics or joints were also chosen by option."""
    chosen = [
        n for n in ("topic", "velocity_topic", "effort_topic", "right_joint", "left_joint") if getattr(selection, n)
    ]
    if chosen:
        raise UsageError(
            f"{option('columns')} with field paths names the topics and wheels itself; drop "
            f"{', '.join(option(n) for n in chosen)}"
        )
    same = fs.speed_topic == fs.effort_topic
    return replace(
        selection, topic=fs.speed_topic if same else None, velocity_topic=None if same else fs.speed_topic,
        effort_topic=None if same else fs.effort_topic, right_joint="right", left_joint="left",
    )  # fmt: skip


@dataclass(frozen=True)
class Recording:
    """A recording whose JointState topics make a log, whatever its format (MCAP here, bags in
    :mod:`wmrid.io.bag`): ``name`` for messages; ``scan(keep, spare)`` the first pass
    (:func:`wmrid.io.mcap.reader.scan_mcap`'s contents), ``read()`` the whole contents, ``parts(channel_ids)``
    a later pass's parts batch by batch (:func:`wmrid.io.mcap.reader.iter_joint_parts`)."""

    name: str
    scan: Callable[[int, int], Any]
    read: Callable[[], Any]
    parts: Callable[[list[int]], Iterator[dict[int, list[tuple[np.ndarray | None, ...]]]]]


def recording_log(
    recording: Recording,
    selection: TopicSelection,
    signals: SignalOptions,
    gear_ratio: float | None,
    rows: int,
    fields: FieldSignals | None = None,
) -> LogStream:
    """The LogStream of a recording's JointState topics (or of the wheel signals by field path ``fields``,
    checked to give numbers): decoded whole, or streamed (see :func:`read_mcap_log`)."""
    source = recording
    contents = recording.scan(_MCAP_WHOLE_PIECES * rows, min(_MCAP_REPLAY_BYTES, 48 * cache_rows()))
    if fields is not None:
        check_values(contents.joints, fields, recording.name)
    if contents.complete:
        return stream_arrays(_mcap_whole_log(source, contents, selection, signals, gear_ratio), rows)
    plan, why = stream_plan(contents, selection, signals, gear_ratio)
    relative = False
    if why is None:  # seconds_from_stamps' choice, from the range of the stamps that can come out
        times = plan.vel.times[plan.vel_time]
        limit = ABSOLUTE_LIMIT_S * NS_PER_UNIT["s"]
        relative = times.low >= limit
        if not relative and not (times.high < limit and times.low > -limit):
            why = "its stamps cross the limit of absolute float64 times"
    if why is not None:
        if contents.replay:
            contents.replay.clear()  # not needed by the whole decode, which would otherwise hold both

        whole = _mcap_whole_log(source, recording.read(), selection, signals, gear_ratio)
        note = f"the recording was decoded whole (memory grows with its length): {why}"
        return stream_arrays(replace(whole, notes=(*whole.notes, note)), rows)
    return _mcap_pieces(recording, contents, plan, selection, signals, gear_ratio, rows, relative)


def _mcap_whole_log(
    source: Any, contents: Any, selection: TopicSelection, signals: SignalOptions, gear_ratio: float | None
) -> WheelLog:
    """The WheelLog of a recording read whole (:class:`wmrid.io.ros.contents.McapContents` with its arrays)."""

    if selection.topic in contents.json:
        sig = signals_from_json(contents, selection.topic, signals, gear_ratio)
    else:
        sig = signals_from_mcap(contents, selection, signals, gear_ratio)
    notes = list(contents.notes) + list(sig.notes)
    _mcap_check_count(source, len(sig.t_ns))
    t, offset = seconds_from_stamps(sig.t_ns, "ns")
    if offset is not None:
        notes.append(f"time relative to the first stamp, {offset} ns")
    _mcap_check_finite(source, t, sig.speed, sig.effort)
    eta = np.ascontiguousarray(sig.speed, dtype=np.float64)
    tau = np.ascontiguousarray(sig.effort, dtype=np.float64)
    return WheelLog(t=t, eta=eta, tau=tau, source=source.name, notes=tuple(notes), effort_unit=sig.effort_unit)


def _mcap_check_count(source: Any, n: int) -> None:
    if n < MIN_SAMPLES:
        raise LogFormatError(
            f"{source.name}: only {n} usable samples after reading the topics; identification needs "
            f"at least {MIN_SAMPLES}"
        )


def _mcap_check_finite(source: Any, t: np.ndarray, speed: np.ndarray, effort: np.ndarray) -> None:
    for arr, what in ((speed, "speed"), (effort, "effort")):
        bad = ~np.isfinite(arr)
        if bad.any():
            raise LogFormatError(
                f"{source.name}: a wheel {what} is not a finite number at t = {t[np.argmax(bad.any(axis=1))]:.6g} s"
            )


def _mcap_pieces(
    recording: Recording,
    contents: Any,
    plan: Any,
    selection: TopicSelection,
    signals: SignalOptions,
    gear_ratio: float | None,
    rows: int,
    relative: bool,
) -> LogStream:
    """The streamed LogStream of a long recording (see :func:`read_mcap_log`): pieces of exactly ``rows``
    samples, as :func:`stream_arrays` cuts the whole log.  Its ``_mcap_peak`` is the most JointState samples
    the last pass held at once (decoded, waiting and cut into pieces)."""
    source = recording
    unit = signals.effort_label
    per_s = float(NS_PER_UNIT["s"])
    kept = [contents.replay]  # the scan's parts, for the first pass

    def pieces() -> Generator[WheelLog, None, tuple[str, ...]]:
        signal = SignalStream(plan, selection, signals, gear_ratio, source.name, rows)
        ready: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        state = {"ready": 0, "total": 0, "offset": None, "error": None, "peak": 0, "kept": 0}

        def batches(channels: list[int]) -> Iterator[dict[int, list[tuple[np.ndarray | None, ...]]]]:
            """The parts of the chosen channels: those the scan kept, each let go once handed out (the first
            pass only), or decoded from the file again."""
            replay, kept[0] = kept[0], None
            if replay is None:
                yield from recording.parts(channels)
                return
            wanted = set(channels)
            state["kept"] = sum(len(part[0]) for cid, part in replay if cid in wanted)
            for i, (cid, part) in enumerate(replay):
                replay[i] = (cid, None)
                if cid in wanted:
                    state["kept"] -= len(part[0])
                    yield {cid: [part]}
            replay.clear()

        def take(batch: list[tuple[np.ndarray, np.ndarray, np.ndarray]]) -> None:
            for t_ns, speed, effort in batch:
                if state["offset"] is None and relative:
                    state["offset"] = int(t_ns[0])
                if relative:
                    t = (t_ns - np.int64(state["offset"])).astype(np.float64) / per_s
                else:
                    t = t_ns.astype(np.float64) / per_s
                if state["error"] is None:
                    try:
                        _mcap_check_finite(source, t, speed, effort)
                    except LogFormatError as err:
                        state["error"] = err  # raised once the log is known to have MIN_SAMPLES samples
                ready.append((t, np.ascontiguousarray(speed, dtype=np.float64),
                              np.ascontiguousarray(effort, dtype=np.float64)))  # fmt: skip
                state["ready"] += len(t)
                state["total"] += len(t)
            if state["error"] is not None and state["total"] >= MIN_SAMPLES:
                raise state["error"]

        def cut(final: bool) -> Iterator[WheelLog]:
            if not ready or (state["ready"] < rows and not final) or state["total"] < MIN_SAMPLES:
                return
            t, eta, tau = (np.concatenate([r[i] for r in ready]) for i in range(3))
            ready.clear()
            start = 0
            while len(t) - start >= rows or (final and start < len(t)):
                stop = min(start + rows, len(t))
                yield WheelLog(t=t[start:stop], eta=eta[start:stop], tau=tau[start:stop], source=source.name,
                               effort_unit=unit)  # fmt: skip
                start = stop
            if start < len(t):
                ready.append((t[start:], eta[start:], tau[start:]))
            state["ready"] = len(t) - start

        for parts in batches(signal.channels):
            decoded = sum(len(p[0]) for got in parts.values() for p in got) + state["kept"]
            take(signal.feed(parts))
            state["peak"] = max(state["peak"], decoded + signal.held + state["ready"])
            stream._mcap_peak = state["peak"]  # type: ignore[attr-defined]
            yield from cut(final=False)
        take(signal.finish())
        _mcap_check_count(source, state["total"])
        if state["error"] is not None:
            raise state["error"]
        yield from cut(final=True)
        notes = [*contents.notes, *signal.notes()]
        if relative:
            notes.append(f"time relative to the first stamp, {state['offset']} ns")
        return tuple(notes)

    stream = LogStream(source.name, unit, pieces)
    stream._mcap_peak = 0  # type: ignore[attr-defined]
    return stream
