"""JointState decoding shared by every recording format: per-channel accumulators fed batches of serialised messages
(:class:`JointChannels`), decoded by a compiled kernel when the message definition is the standard one, else
message by message by the format's generic decoder; the decoded parts kept whole, summarised past ``keep``
messages, or handed out as they come (a second pass).  :mod:`wmrid.io.mcap.reader` walks MCAP records into it,
:mod:`wmrid.io.bag.reader` the messages rosbags reads from ROS 1 bags, sqlite3 bags and rosbag2 folders.
"""

from __future__ import annotations

import contextlib
from abc import ABC, abstractmethod
from collections.abc import Callable, Mapping
from types import SimpleNamespace
from typing import Any

import numpy as np

from wmrid.core.errors import LogFormatError
from wmrid.io.mcap.records import JOINT_STATE_NAMES, MAX_JOINTS, STATUS_MALFORMED, STATUS_OK, cdr_joint_names
from wmrid.io.ros.contents import Accumulator, ChannelInfo, JointStats, join, summary
from wmrid.io.ros.field_paths import FieldPath
from wmrid.runtime.limits import describe, memory_budget

#: ros2_control's joint states with named interfaces: read like a JointState (:func:`as_joint_state`).
DYNAMIC_JOINT_STATE_NAMES = ("control_msgs/msg/DynamicJointState", "control_msgs/DynamicJointState")


def as_joint_state(msg: Any) -> tuple[SimpleNamespace, bool]:
    """(a JointState view of a DynamicJointState message, whether a 'current' interface stood for the effort).

    ``name`` = ``joint_names``; ``position``, ``velocity``, ``effort`` per joint = the value of the interface of
    that name in ``interface_values[j]`` (NaN when the joint has none); the effort falls back on the interface
    'current'.
    """
    names = [str(n) for n in msg.joint_names]
    fields: dict[str, list[float]] = {"position": [], "velocity": [], "effort": []}
    current = False
    for j in range(len(names)):
        iv = msg.interface_values[j] if j < len(msg.interface_values) else None
        values = {} if iv is None else dict(zip(map(str, iv.interface_names), map(float, iv.values), strict=False))
        for field in fields:
            fields[field].append(values.get(field, float("nan")))
        if "effort" not in values and "current" in values:
            fields["effort"][-1] = values["current"]
            current = True
    return SimpleNamespace(name=names, header=msg.header, **fields), current


class JointChannels(ABC):
    """Channels (id -> :class:`Accumulator`), their schemas (id -> {"name", "encoding", "data"}) and notes, and the
    JointState decoding of batches of their messages.

    keep : None to keep every JointState array (a whole read); else keep them while they hold at most ``keep``
    messages, and past that only their statistics (``complete`` turns False); with ``spare`` bytes, also the parts
    without positions while they fit (``replay``: [(channel id, part)] in file order, or None once they do not).
    wanted : decode only these JointState channels (a second pass; the caller takes their parts as they come).

    A format supplies :meth:`generic` (one message decoded to an object with ``name``, ``header.stamp.sec``,
    ``.nanosec``, ``position``, ``velocity``, ``effort``), :meth:`standard` (may the kernel decode the channel)
    and :meth:`kernel` (the compiled decoder of its wire format).
    """

    def __init__(
        self, name: str, *, keep: int | None = None, spare: int = 0, wanted: set[int] | None = None,
        fields: Mapping[str, Mapping[str, tuple[FieldPath, FieldPath]]] | None = None,
    ):  # fmt: skip
        self.name = name
        self.fields = dict(fields or {})  # topic -> {"velocity"/"effort": (right, left) paths}: :meth:`_field_batch`
        self.budget = memory_budget()
        self.keep = keep
        self.wanted = wanted
        self.complete = True
        self.kept = 0
        self.kept_bytes = 0  # bytes of the parts kept (a message of many joints is large: count bytes too)
        self.spare = spare
        self.replay: list[tuple[int, tuple[np.ndarray | None, ...]]] | None = [] if keep is not None and spare else None
        self.replay_bytes = 0
        self.schemas: dict[int, dict[str, Any]] = {}
        self.channels: dict[int, Accumulator] = {}
        self.notes: list[str] = []
        self.decoders: dict[int, Any] = {}

    # ---- what a format supplies (abstract: the MCAP reader's _ReadState and the bag readers' _BagState)

    @abstractmethod
    def generic(self, acc: Accumulator, payload: bytes) -> Any:
        """One message of the channel decoded by the format's generic decoder, None when it cannot be."""

    @abstractmethod
    def standard(self, acc: Accumulator) -> bool:
        """Whether the channel's message definition is the standard JointState (the kernel may decode it)."""

    @abstractmethod
    def kernel(self, acc: Accumulator) -> Callable[..., None]:
        """The compiled JointState decoder of the channel's wire format (CDR or ROS 1)."""

    def names_of(self, acc: Accumulator, payload: bytes) -> list[str] | None:
        """The joint names of a channel's first message (None when it cannot be decoded): read from the bytes of a
        standard CDR JointState (:func:`cdr_joint_names`), else from the generic decoder's message."""
        if (
            acc.info["message_encoding"] == "cdr"
            and acc.info["schema_name"] in JOINT_STATE_NAMES
            and self.standard(acc)
        ):
            names = cdr_joint_names(payload)
            if names is not None:
                return names
        first = self.decoded(acc, payload)
        return None if first is None else [str(n) for n in first.name]

    def decoded(self, acc: Accumulator, payload: bytes) -> Any:
        """One message decoded by :meth:`generic`, a DynamicJointState seen as a JointState (:func:`as_joint_state`;
        its 'current' interface stands for the effort where it has no 'effort' one, with a note)."""
        msg = self.generic(acc, payload)
        if msg is None or acc.info["schema_name"] not in DYNAMIC_JOINT_STATE_NAMES:
            return msg
        try:
            view, current = as_joint_state(msg)
        except (AttributeError, TypeError, ValueError):
            return None
        if current and not getattr(acc, "current_noted", False):
            acc.current_noted = True  # type: ignore[attr-defined]
            self.notes.append(
                f"topic {acc.info['topic']}: no 'effort' interface; its 'current' interface is read as the effort "
                "(give --effort current, with the torque constant, to turn it into a torque)"
            )
        return view

    def _field_batch(self, acc: Accumulator, buf, starts, lengths, times) -> None:
        """A batch of a topic read by field paths (:mod:`wmrid.io.ros.field_paths`): each message decoded by
        :meth:`generic`, its right and left speed and/or effort taken by path, as a JointState of two joints
        "right" and "left" (stamp from ``header.stamp``, 0 when it has none)."""
        spec = self.fields[acc.info["topic"]]
        if acc.ref is None:
            self._set_names(acc, ["right", "left"])
            acc.standard = False
            said = "; ".join(f"{what} {paths[0].text} and {paths[1].text}" for what, paths in spec.items())
            self.notes.append(
                f"topic {acc.info['topic']}: wheel signals read by field path ({said}), message by message"
            )
        n = len(starts)
        stamp = np.zeros(n, dtype=np.int64)
        pos = np.full((n, 2), np.nan)
        vel = np.full((n, 2), np.nan)
        eff = np.full((n, 2), np.nan)
        keep = np.ones(n, dtype=bool)
        for i in range(n):
            msg = self.generic(acc, bytes(buf[starts[i] : starts[i] + lengths[i]]))
            if msg is None:
                keep[i] = False
                acc.skipped += 1
                continue
            header = getattr(msg, "header", None)
            if header is not None and hasattr(header, "stamp"):
                with contextlib.suppress(AttributeError, TypeError, ValueError):
                    stamp[i] = int(header.stamp.sec) * 1_000_000_000 + int(header.stamp.nanosec)
            for field, out in (("velocity", vel), ("effort", eff)):
                if field in spec:
                    out[i] = [path.value(msg) for path in spec[field]]
        if not keep.all():
            times, stamp, pos, vel, eff = times[keep], stamp[keep], pos[keep], vel[keep], eff[keep]
        self._store(acc, (np.array(times, dtype=np.int64), stamp, pos, vel, eff))

    # ---- results

    def joints(self) -> dict[str, Any]:
        """{topic: JointSeries} of a whole read (``complete``), else {topic: JointSummary}."""
        out: dict[str, Any] = {}
        for acc in self.channels.values():
            if acc.ref is not None and acc.batches:
                out[acc.info["topic"]] = join(acc) if self.complete else summary(acc)
        return out

    def channel_info(self) -> list[ChannelInfo]:
        out = []
        for acc in self.channels.values():
            info = acc.info
            schema = self.schemas.get(info["schema_id"])
            out.append(
                ChannelInfo(
                    id=info["id"],
                    topic=info["topic"],
                    message_encoding=info["message_encoding"],
                    schema_name=schema["name"] if schema else info["schema_name"],
                    schema_encoding=schema["encoding"] if schema else info["schema_encoding"],
                    count=acc.count,
                    first_ns=acc.first_ns,
                    last_ns=acc.last_ns,
                )
            )
        return sorted(out, key=lambda c: c.topic)

    def _joint_batch(self, acc: Accumulator, buf, starts, lengths, times) -> None:
        if acc.ref is None:
            names = self.names_of(acc, bytes(buf[starts[0] : starts[0] + lengths[0]]))
            if names is None:
                acc.skipped += len(starts)
                return
            if len(names) > MAX_JOINTS:
                self.notes.append(
                    f"topic {acc.info['topic']}: its JointState messages name {len(names):,} joints, more than the "
                    f"{MAX_JOINTS:,} wmrid decodes; skipped"
                )
                acc.too_wide = True
                self._set_names(acc, [])
            else:
                self._set_names(acc, names)
        if acc.too_wide:
            acc.skipped += len(starts)
            return
        need = len(starts) * len(acc.names) * 24
        if need > self.budget:
            self.notes.append(
                f"topic {acc.info['topic']}: a batch of {len(starts):,} messages x {len(acc.names)} joints needs "
                f"{describe(need)}, beyond the memory budget of {describe(self.budget)} (WMRID_MEMORY_BUDGET); skipped"
            )
            acc.skipped += len(starts)
            return
        if acc.standard is None and acc.info["schema_name"] in DYNAMIC_JOINT_STATE_NAMES:
            acc.standard = False
            self.notes.append(
                f"topic {acc.info['topic']}: DynamicJointState (ros2_control), read like a JointState: its joint "
                "names, and the interfaces named position, velocity and effort (decoded message by message)"
            )
        if acc.standard is None:
            acc.standard = self.standard(acc)
            if not acc.standard:
                self.notes.append(
                    f"topic {acc.info['topic']}: its JointState schema is not the standard one (other fields, or "
                    "another order); decoded field by field by name, more slowly"
                )
        n = len(starts)
        k = len(acc.names)
        stamp = np.zeros(n, dtype=np.int64)
        pos = np.full((n, k), np.nan)
        vel = np.full((n, k), np.nan)
        eff = np.full((n, k), np.nan)
        status = np.full(n, STATUS_MALFORMED, dtype=np.int8)
        if acc.standard:
            self.kernel(acc)(buf, starts, lengths, acc.ref, acc.ref_off, stamp, pos, vel, eff, status)
        slow = np.flatnonzero(status != STATUS_OK)
        keep = np.ones(n, dtype=bool)
        for i in slow:  # rare: other endianness, a layout the fast path refuses, or new joint names
            msg = self.decoded(acc, bytes(buf[starts[i] : starts[i] + lengths[i]]))
            if msg is None:
                keep[i] = False
                acc.skipped += 1
                continue
            try:
                stamp[i] = int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)
                names = list(msg.name)
                # rosbags gives numpy arrays, mcap_ros2 lists (an array has no truth value: no `or ()` here)
                fields = [getattr(msg, f, None) for f in ("position", "velocity", "effort")]
                values = [[] if f is None else [float(v) for v in f] for f in fields]
            except (AttributeError, TypeError, ValueError):
                keep[i] = False
                acc.skipped += 1
                continue
            for kk, joint in enumerate(acc.names):
                if joint in names:
                    j = names.index(joint)
                    pos[i, kk] = values[0][j] if j < len(values[0]) else np.nan
                    vel[i, kk] = values[1][j] if j < len(values[1]) else np.nan
                    eff[i, kk] = values[2][j] if j < len(values[2]) else np.nan
        if not keep.all():
            times, stamp, pos, vel, eff = times[keep], stamp[keep], pos[keep], vel[keep], eff[keep]
        self._store(acc, (times.copy(), stamp, pos, vel, eff))

    def _store(self, acc: Accumulator, part: tuple[np.ndarray, ...]) -> None:
        """Keep a channel's decoded part, or (past ``keep`` messages) only its statistics."""
        acc.batches += 1
        if self.replay is not None:
            times, stamp, _, vel, eff = part
            self.replay_bytes += times.nbytes + stamp.nbytes + vel.nbytes + eff.nbytes
            if self.replay_bytes <= self.spare:
                self.replay.append((acc.info["id"], (times, stamp, None, vel, eff)))  # arrays shared, not copied
            else:
                self.replay = None
        size = sum(a.nbytes for a in part if a is not None)
        self.kept_bytes += size
        if self.keep is None:  # a whole read: the arrays must fit, however few the messages
            if self.kept_bytes > self.budget:
                raise LogFormatError(
                    f"{self.name}: its JointState messages, decoded whole, need more than the memory budget of "
                    f"{describe(self.budget)} (WMRID_MEMORY_BUDGET): {len(acc.names)} joints a message on "
                    f"{acc.info['topic']}; raise the budget or record fewer joints on the wheel topic"
                )
            acc.parts.append(part)
            return
        if self.complete:
            acc.parts.append(part)
            self.kept += len(part[0])
            if self.kept <= self.keep and self.kept_bytes <= self.budget // 4:  # messages and bytes: both bounded
                return
            self.complete = False  # too long to keep: statistics from here on
            for other in self.channels.values():
                for kept in other.parts:
                    self._add_stats(other, kept)
                other.parts = []
            return
        self._add_stats(acc, part)

    @staticmethod
    def _add_stats(acc: Accumulator, part: tuple[np.ndarray, ...]) -> None:
        if acc.stats is None:
            acc.stats = JointStats(len(acc.names))
        acc.stats.add(part)

    def _set_names(self, acc: Accumulator, names: list[str]) -> None:
        acc.names = names
        encoded = [n.encode("utf-8") for n in names]
        acc.ref = np.frombuffer(b"".join(encoded) or b"\0", dtype=np.uint8).copy()
        acc.ref_off = np.cumsum([0, *[len(e) for e in encoded]]).astype(np.int64)
