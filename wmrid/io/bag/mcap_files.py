"""ROS 2 recordings stored in several MCAP files, or in a rosbag2 folder with MCAP storage, read by wmrid's own MCAP
walker file after file (:class:`McapFilesState`): the MCAP counterpart of :mod:`wmrid.io.bag.db3_file`.

Why not rosbags: a recording whose last file was cut short (``ros2 bag record`` killed, the robot's power gone) has
no summary and no closing magic, and rosbags refuses the whole recording ("File end magic is invalid").  One such file
alone is read by :mod:`wmrid.io.mcap.reader` up to its last whole record; here every file of the recording is walked
the same way (:class:`wmrid.io.mcap.reader._ReadState`: the compiled record scan, chunk checks, the CDR kernel), each
file's channels mapped by topic to the recording's (a topic is one channel whatever file and channel id it comes
in), and the files taken in the order of their first message.  A file cut short gives a note naming it and the bytes
lost; one that ends between two records without MCAP's footer, a note that it was not closed; one the crash left
before its first whole record (empty, the magic bytes alone, part of the header record) is skipped with a note.  The
JointState messages are decoded as for rosbags' reads (:class:`wmrid.io.bag.state._BagState`: the compiled CDR
kernel, rosbags' deserialiser with the definitions stored in the files for the rest), so a recording whose files
hold their messages in log-time order reads the same through either (rosbags merges a file's chunks by log time;
wmrid keeps the file's order, as it does for a single .mcap).

The files' time spans (:func:`mcap_span`) come from a walk of the top-level records alone (a chunk's record header
gives its first and last message time; the chunk is not decompressed; the pages walked past are handed back).  What
this reader does not take -- a file that is not MCAP, compressed storage (``.mcap.zstd`` files), files that overlap
in time (rosbags merges files given apart message by message, and reads a rosbag2 folder's files in its
metadata's order) -- :func:`mcap_files` leaves to rosbags.
"""

from __future__ import annotations

import itertools
import os
from collections.abc import Generator, Sequence
from typing import Any

import numpy as np

from wmrid.core.errors import LogFormatError
from wmrid.io.bag.state import _BagState, _Topic, storage_files
from wmrid.io.binary import cut_short_note, map_file, u64s_at
from wmrid.io.mcap.reader import _SCAN_WINDOW, UNCLOSED_NOTE, _check_start, _ReadState, closed
from wmrid.io.mcap.records import JOINT_STATE_NAMES, MAGIC, OP_CHUNK, OP_HEADER, OP_MESSAGE, scan
from wmrid.io.ros.joint_batches import DYNAMIC_JOINT_STATE_NAMES


def mcap_files(paths: Sequence[str]) -> list[str] | None:
    """The MCAP files of the recording ``paths`` names (rosbag2 folders with MCAP storage and .mcap files) in the
    order they are read (files without messages first, then by their first message, then the :func:`stub` files a
    crash left), or None when rosbags must read it (see the module docstring)."""
    files: list[str] = []
    stubs: list[str] = []
    for path in paths:
        got = storage_files(path, "mcap", MAGIC)
        if got is None and os.path.isfile(path) and stub(path):  # e.g. an empty file: no magic bytes to find
            stubs.append(path)
            continue
        if got is None:
            return None
        for file in got:
            (stubs if stub(file) else files).append(file)
    if not files:
        return None
    spans = []
    for file in files:
        span = mcap_span(file)
        if span is None:
            return None
        spans.append(span)
    empty = [i for i, s in enumerate(spans) if s[0] is None]
    timed = sorted((i for i, s in enumerate(spans) if s[0] is not None), key=lambda i: (spans[i][0], i))
    for a, b in itertools.pairwise(timed):
        if spans[a][1] > spans[b][0]:  # overlapping files: rosbags reads them (see the module docstring)
            return None
    return [files[i] for i in empty + timed] + stubs


def stub(path: str) -> bool:
    """Whether ``path`` is what a crash leaves of an MCAP file before its first whole record: empty, part of the
    magic bytes, or the magic and part of the header record."""
    try:
        if os.path.getsize(path) > 4096:
            return False
        with open(path, "rb") as fh:
            head = fh.read()
    except OSError:
        return False
    if len(head) <= len(MAGIC):
        return MAGIC.startswith(head)
    rest = head[len(MAGIC) :]
    if not head.startswith(MAGIC) or rest[0] != OP_HEADER:
        return False
    return len(rest) < 9 or len(rest) < 9 + int.from_bytes(rest[1:9], "little")


def mcap_span(path: str) -> tuple[int | None, int | None] | None:
    """(first, last) message log time (ns) of an MCAP file, (None, None) when it holds no message, None when it is not
    an MCAP file.  Only top-level records are read: a chunk's times from its record header, a message's from its own;
    a file cut short is walked up to its last whole record."""
    try:
        buf, release = map_file(path, None)
    except LogFormatError:
        return None
    size = buf.shape[0]
    if size < len(MAGIC) or bytes(buf[: len(MAGIC)]) != MAGIC:
        return None
    cap = 65536
    ops = np.empty(cap, dtype=np.uint8)
    starts = np.empty(cap, dtype=np.int64)
    lengths = np.empty(cap, dtype=np.int64)
    lows: list[int] = []
    highs: list[int] = []
    p = len(MAGIC)
    while p < size:
        stop = min(size, p + _SCAN_WINDOW)
        n, q = scan(buf, p, stop, ops, starts, lengths)
        if n == 0 and stop < size:  # a record longer than the window
            n, q = scan(buf, p, size, ops[:1], starts[:1], lengths[:1])
        if n == 0:
            break
        op, at, length = ops[:n], starts[:n], lengths[:n]
        chunks = at[(op == OP_CHUNK) & (length >= 16)]
        if len(chunks):
            first, last = u64s_at(buf, chunks), u64s_at(buf, chunks + 8)
            held = (last >= first) & ~((first == 0) & (last == 0))  # an empty chunk's times are both 0
            if held.any():
                lows.append(int(first[held].min()))
                highs.append(int(last[held].max()))
        messages = at[(op == OP_MESSAGE) & (length >= 22)]
        if len(messages):
            times = u64s_at(buf, messages + 6)
            lows.append(int(times.min()))
            highs.append(int(times.max()))
        p = q
        if release is not None:
            release(p)
    del buf
    return (min(lows), max(highs)) if lows else (None, None)


class McapFilesState(_BagState):
    """The messages of the MCAP files of one recording (:func:`mcap_files`, in that order), walked into
    :class:`_BagState`'s channels (see the module)."""

    def __init__(self, paths: Sequence[str], files: Sequence[str], **kwargs: Any):
        super().__init__(", ".join(paths), "ros2", **kwargs)
        self.files = list(files)
        self._by_topic: dict[str, int] = {}
        self._decoded: set[int] = set()

    def steps(self) -> Generator[None, None, None]:
        """Walk every file, pausing after each batch of messages."""
        for path in self.files:
            if stub(path):
                self.notes.append(
                    f"{path}: holds no whole MCAP record ({os.path.getsize(path)} bytes: the recording stopped as this "
                    "file began): skipped"
                )
                continue
            buf, release = map_file(path, None)
            _check_start(path, buf)
            size = buf.shape[0]
            walker = _FileWalker(self, path, release)
            reached, cut = yield from walker.steps(buf, len(MAGIC), size, top_level=True)
            ended = closed(buf)
            del buf
            self.notes.extend(f"{path}: {note}" for note in walker.notes)
            if cut:
                self.notes.append(f"{path}: {cut_short_note(reached, size)}")
            elif not ended:
                self.notes.append(f"{path}: {UNCLOSED_NOTE}")

    def channel_for(self, path: str, info: dict[str, Any], schema: dict[str, Any] | None) -> int | None:
        """The recording's channel of a file's channel (its topic's), registered on first sight; None (with a note)
        when the topic came earlier with another type or encoding."""
        topic, kind, encoding = info["topic"], info["schema_name"], info["message_encoding"]
        channel = self._by_topic.get(topic)
        if channel is None:
            channel = len(self._by_topic) + 1
            self._by_topic[topic] = channel
            definition = ""
            if schema is not None and schema["encoding"] == "ros2msg":
                definition = bytes(schema["data"]).decode("utf-8", "replace")
            self.add_topic(_Topic(channel, topic, kind, definition, encoding, []))
            decodable = kind in JOINT_STATE_NAMES + DYNAMIC_JOINT_STATE_NAMES or topic in self.fields
            if decodable and encoding == "cdr" and (self.wanted is None or channel in self.wanted):
                self._decoded.add(channel)
            return channel
        known = self.topics[channel]
        if (known.msgtype, known.encoding) != (kind, encoding):
            self.notes.append(
                f"{path}: topic {topic}: a channel of type {kind} ({encoding}) besides {known.msgtype} "
                f"({known.encoding}); its messages were skipped"
            )
            return None
        return channel

    def channel_messages(
        self, channel: int, buf: np.ndarray, starts: np.ndarray, lengths: np.ndarray, times: np.ndarray
    ) -> None:
        """One batch of a channel's messages: decoded when it is a JointState (or field-path) topic, else counted."""
        acc = self.channels[channel]
        acc.count += len(times)
        if channel in self._decoded:
            self.decode(channel, buf, starts, lengths, times)
        else:
            lo, hi = int(times.min()), int(times.max())
            acc.first_ns = lo if acc.first_ns is None else min(acc.first_ns, lo)
            acc.last_ns = hi if acc.last_ns is None else max(acc.last_ns, hi)


class _FileWalker(_ReadState):
    """One file of a :class:`McapFilesState`: the MCAP reader's walk (records, chunks, damage checks), its channels
    mapped to the recording's, its messages handed to the recording."""

    def __init__(self, owner: McapFilesState, path: str, release: Any):
        super().__init__(path, {}, False, release=release)
        self.owner = owner
        self.local: dict[int, int | None] = {}  # this file's channel id -> the recording's (None: skipped)

    def _channel(self, body: bytes) -> int | None:
        cid = super()._channel(body)
        if cid is not None:
            info = self.channels[cid].info
            self.local[cid] = self.owner.channel_for(self.name, info, self.schemas.get(info["schema_id"]))
        return cid

    def _channel_messages(
        self, cid: int, buf: np.ndarray, starts: np.ndarray, lengths: np.ndarray, times: np.ndarray
    ) -> None:
        if cid not in self.channels:
            super()._channel_messages(cid, buf, starts, lengths, times)  # the note of an undefined channel
            return
        channel = self.local.get(cid)
        if channel is not None:
            self.owner.channel_messages(channel, buf, starts, lengths, times)
