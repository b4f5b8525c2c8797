"""ROS 1 bags (format 2.0) walked record by record by a compiled scanner, the JointState messages of each chunk
decoded in one call (:class:`Ros1State`): the ROS 1 counterpart of :mod:`wmrid.io.mcap.reader`.

rosbags reads a bag message by message in Python (7.3 s for a 10-minute 1 kHz JointState bag on the benchmark
machine, ``bench/speed/bench_bags.py``); this reader scans each decompressed chunk with
:func:`wmrid.io.bag.ros1_records.ros1_records` and hands its JointState messages to
:func:`wmrid.io.bag.ros1_records.ros1_joint_states`.  rosbags still deserialises what the kernel does not decode
(:class:`wmrid.io.bag.state._BagState`), with the definitions from the bag's connection records.

Format: ``#ROSBAG V2.0`` then records (uint32 header length, ``name=value`` fields, uint32 data length, data).
Connection records (op 7) give a connection's topic, type and message definition; chunk records (op 5; none, bz2
or lz4) hold connection and message-data records (op 2: ``conn``, ``time``, the serialised message); index and
chunk-info records are not needed.  Messages are taken in file order (as the MCAP reader does); several bags are
read one after the other, ordered by their first message time (the chunk-info records).  A topic recorded over
several connections is one channel.  A file cut short is read up to its last whole record, with a note; a chunk
that cannot be decompressed, or declares more than the memory budget, is skipped with a note.
"""

from __future__ import annotations

import bz2
import contextlib
import mmap
from collections.abc import Generator, Iterator, Sequence
from typing import Any

import numpy as np

from wmrid.core.errors import LogFormatError
from wmrid.io.bag.ros1_records import OP_CHUNK, OP_CHUNK_INFO, OP_CONNECTION, OP_MESSAGE, ros1_records
from wmrid.io.bag.state import _BagState, _Topic
from wmrid.io.binary import cut_short_note, page_releaser
from wmrid.io.mcap.records import BOMB_FLOOR, BOMB_RATIO
from wmrid.runtime.limits import describe

MAGIC = b"#ROSBAG V2.0\n"
OP_BAG_HEADER = 0x03

#: Records scanned at a time.
_RECORDS = 65536
#: bytes: the most of a large compressed chunk decompressed at a time (:meth:`Ros1State._window`).
_WINDOW = 4 << 20


def fields(header: bytes) -> dict[str, bytes]:
    """The ``name=value`` fields of a record header (uint32 length before each)."""
    out: dict[str, bytes] = {}
    q = 0
    while q + 4 <= len(header):
        n = int.from_bytes(header[q : q + 4], "little")
        q += 4
        name, _, value = header[q : q + n].partition(b"=")
        out[name.decode("latin-1")] = value
        q += n
    return out


def msgtype(name: str) -> str:
    """A ROS 1 type name as rosbags writes it: ``sensor_msgs/JointState`` -> ``sensor_msgs/msg/JointState``."""
    pkg, _, rest = name.partition("/")
    return name if not rest or rest.startswith("msg/") else f"{pkg}/msg/{rest}"


class Ros1State(_BagState):
    """The records of one or more ROS 1 bags, walked into :class:`_BagState`'s channels (see the module)."""

    def __init__(self, paths: Sequence[str], **kwargs: Any):
        super().__init__(", ".join(paths), "ros1", **kwargs)
        self.paths = _by_start(list(paths))
        self._by_topic: dict[str, int] = {}
        self._unknown = 0
        self._release: Any = None

    def steps(self) -> Generator[None, None, None]:
        """Walk every bag, pausing after each chunk."""
        for path in self.paths:
            yield from self._file(path)

    def _file(self, path: str) -> Generator[None, None, None]:
        with open(path, "rb") as fh:
            if fh.read(len(MAGIC)) != MAGIC:
                raise LogFormatError(f"{path}: not a ROS 1 bag of format 2.0 (its first line is not #ROSBAG V2.0)")
            size = fh.seek(0, 2)
            mapped = mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)
        try:
            buf = np.frombuffer(mapped, dtype=np.uint8)
            connections: dict[int, int | None] = {}  # this file's connection ids -> channel (None: skipped)
            self._unknown = 0
            self._release = page_releaser(mapped)  # the pages walked past leave the resident memory (as for MCAP)
            reached = yield from self._records(path, buf, len(MAGIC), size, connections, top=True)
            if self._unknown:
                self.notes.append(
                    f"{path}: {self._unknown} message(s) on a connection no connection record defines were skipped"
                )
            if reached < size:
                self.notes.append(f"{path}: {cut_short_note(reached, size)}")
            del buf
        finally:
            with contextlib.suppress(BufferError):  # a view of it still lives (in a traceback): it goes with it
                mapped.close()

    def _records(
        self, path: str, buf: np.ndarray, p: int, end: int, connections: dict[int, int | None], top: bool
    ) -> Generator[None, None, int]:
        """Handle the records of buf[p:end] (a chunk's when not ``top``); returns the offset reached."""
        arrays = [np.empty(_RECORDS, dtype=np.int64) for _ in range(7)]
        while p < end:
            n, q = ros1_records(buf, p, end, *arrays)
            if n == 0:
                return p
            ops, conns, times, hstart, hlen, dstart, dlen = (a[:n] for a in arrays)
            for i in np.flatnonzero((ops == OP_CONNECTION) | (ops == OP_CHUNK)):
                header = bytes(buf[hstart[i] : hstart[i] + hlen[i]])
                if ops[i] == OP_CONNECTION:
                    self._connection(path, int(conns[i]), header, bytes(buf[dstart[i] : dstart[i] + dlen[i]]),
                                     connections)  # fmt: skip
                elif top:
                    yield from self._chunk(path, header, buf[dstart[i] : dstart[i] + dlen[i]], connections)
                    if self._release is not None:
                        self._release(int(dstart[i] + dlen[i]))
            messages = np.flatnonzero(ops == OP_MESSAGE)
            if len(messages):
                self._messages(path, buf, conns[messages], times[messages], dstart[messages], dlen[messages],
                               connections)  # fmt: skip
                if top:
                    yield
            p = q
            if top and self._release is not None:
                self._release(p)
            if n < _RECORDS:
                return p
        return p

    def _connection(self, path: str, conn: int, header: bytes, data: bytes, connections: dict[int, int | None]) -> None:
        if conn < 0 or conn in connections:
            return  # the index section repeats the connection records
        head, body = fields(header), fields(data)
        topic = (body.get("topic") or head.get("topic") or b"").decode("utf-8", "replace")
        kind = msgtype(body.get("type", b"").decode("utf-8", "replace"))
        channel = self._by_topic.get(topic)
        if channel is None:
            channel = len(self._by_topic) + 1
            self._by_topic[topic] = channel
            definition = body.get("message_definition", b"").decode("utf-8", "replace")
            self.add_topic(_Topic(channel, topic, kind, definition, "ros1", []))
        elif self.topics[channel].msgtype != kind:
            self.notes.append(
                f"{path}: topic {topic}: a connection of type {kind} besides {self.topics[channel].msgtype}; its "
                "messages were skipped"
            )
            channel = None
        connections[conn] = channel

    def _chunk(
        self, path: str, header: bytes, data: np.ndarray, connections: dict[int, int | None]
    ) -> Generator[None, None, None]:
        head = fields(header)
        compression = head.get("compression", b"none").decode("latin-1")
        declared = int.from_bytes(head.get("size", b"\0\0\0\0")[:4], "little")
        if declared > self.budget or (declared > BOMB_FLOOR and declared > BOMB_RATIO * max(len(data), 1)):
            self.notes.append(
                f"{path}: a chunk of {len(data)} bytes declares {describe(declared)} uncompressed, beyond the memory "
                f"budget of {describe(self.budget)} (WMRID_MEMORY_BUDGET) or {BOMB_RATIO} times its size: skipped, "
                "its messages are lost"
            )
            return
        if compression != "none" and declared > self._window():
            yield from self._large_chunk(path, compression, data, declared, connections)
            return
        try:
            raw = _decompress(compression, bytes(data), declared)
        except Exception as err:
            self.notes.append(
                f"{path}: a chunk ({len(data)} bytes, {compression}) could not be decompressed ({type(err).__name__}: "
                f"{err}); its messages are lost"
            )
            return
        if len(raw) != declared:
            self.notes.append(
                f"{path}: a chunk decompressed to {len(raw)} bytes, not the {declared} it declares: skipped, its "
                "messages are lost"
            )
            return
        inner = np.frombuffer(raw, dtype=np.uint8)
        reached = yield from self._records(path, inner, 0, len(inner), connections, top=False)
        if reached < len(inner):
            self.notes.append(
                f"{path}: a chunk's records end mid-record (byte {reached} of {len(inner)}); the rest is lost"
            )
        yield

    def _window(self) -> int:
        """Bytes of a chunk decompressed at a time when it is larger (4 MiB, or an eighth of a small budget; at least
        1 MiB).  lz4 is fastest in small windows: 0.18 s per 100 MB in 1 MiB ones, 0.44 s in one piece."""
        return min(_WINDOW, max(self.budget // 8, 1 << 20))

    def _large_chunk(
        self, path: str, compression: str, data: np.ndarray, declared: int, connections: dict[int, int | None]
    ) -> Generator[None, None, None]:
        """A compressed chunk larger than :meth:`_window` (within the budget), decompressed and walked a window at a
        time, so that memory holds a window and the record it ends in, not the chunk: a 13 MB bag whose lz4 chunk
        decodes to 3 GiB took 3.3 GB.  Its size is checked in a first pass (discarding the output) and the chunk
        skipped as a whole when it is not the declared one, as a smaller chunk is."""
        window = self._window()
        try:
            size = sum(len(piece) for piece in _pieces(compression, data, declared, window))
        except Exception as err:
            self.notes.append(
                f"{path}: a chunk ({len(data)} bytes, {compression}) could not be decompressed ({type(err).__name__}: "
                f"{err}); its messages are lost"
            )
            return
        if size != declared:
            self.notes.append(
                f"{path}: a chunk decompressed to {size} bytes, not the {declared} it declares: skipped, its "
                "messages are lost"
            )
            return
        pending, parts, have, need = b"", [], 0, 0  # the record the window before ended in, and what it needs
        for piece in _pieces(compression, data, declared, window):
            parts.append(piece)
            have += len(piece)
            if have < need:
                continue  # that record is not whole yet: its bytes are joined once, when it is
            buf = b"".join([pending, *parts])
            parts = []
            inner = np.frombuffer(buf, dtype=np.uint8)
            reached = yield from self._records(path, inner, 0, len(inner), connections, top=False)
            pending = buf[reached:]
            del inner, buf
            have, need = len(pending), _record_length(pending)
            if need > self.budget // 2:
                self.notes.append(
                    f"{path}: a chunk holds a record of {describe(need)}, more than half the memory budget of "
                    f"{describe(self.budget)} (WMRID_MEMORY_BUDGET); the rest of the chunk is lost"
                )
                return
            yield
        if pending or parts:
            self.notes.append(
                f"{path}: a chunk's records end mid-record (byte {declared - have} of {declared}); the rest is lost"
            )

    def _messages(self, path, buf, conns, times, dstart, dlen, connections: dict[int, int | None]) -> None:
        channels = _channels_of(conns, connections)  # -1: no connection record, -2: a connection skipped
        self._unknown += int(np.count_nonzero(channels == -1))
        wanted = set(self.joint_channels())
        for channel in np.unique(channels[channels >= 0]):
            sel = channels == channel
            acc = self.channels[int(channel)]
            if int(channel) in wanted:
                self.decode(int(channel), buf, dstart[sel], dlen[sel], times[sel].astype(np.int64))
            else:
                stamps = times[sel]
                lo, hi = int(stamps.min()), int(stamps.max())
                acc.first_ns = lo if acc.first_ns is None else min(acc.first_ns, lo)
                acc.last_ns = hi if acc.last_ns is None else max(acc.last_ns, hi)
            acc.count += int(sel.sum())


def _channels_of(conns: np.ndarray, connections: dict[int, int | None]) -> np.ndarray:
    """The channel of each message's connection id (-1 for an id no connection record defines, -2 for a skipped
    connection), by a lookup table (ids are small counters; a dictionary when a file claims a huge one)."""
    ids = conns.astype(np.int64)
    top = max(int(ids.max()) if len(ids) else -1, max(connections, default=-1))
    if top > 1 << 20:
        return np.array([-1 if int(c) not in connections else (connections[int(c)] or -2) for c in ids], dtype=np.int64)
    table = np.full(top + 2, -1, dtype=np.int64)  # the last entry answers for the ids of -1 (no conn field)
    for conn, channel in connections.items():
        table[conn] = -2 if channel is None else channel
    return table[np.where(ids < 0, top + 1, ids)]


def _decompress(compression: str, data: bytes, size: int) -> bytes:
    """A chunk's records, never more than ``size`` + 1 bytes (a chunk that lies about its size cannot make wmrid
    allocate more)."""
    if compression == "none":
        return data
    if compression == "bz2":
        return bz2.BZ2Decompressor().decompress(data, max_length=size + 1)
    if compression == "lz4":
        import lz4.frame  # lz4: only an lz4 chunk

        with lz4.frame.LZ4FrameDecompressor() as decompressor:
            return decompressor.decompress(data, max_length=size + 1)
    raise ValueError(f"unknown compression {compression!r}")


def _record_length(head: bytes) -> int:
    """The bytes a record needs in all, from the start of it in ``head`` (its header's length, then its data's, each
    once known); 0 when ``head`` is empty."""
    if len(head) < 4:
        return 4 if head else 0
    header = int.from_bytes(head[:4], "little")
    if len(head) < 8 + header:
        return 8 + header
    return 8 + header + int.from_bytes(head[4 + header : 8 + header], "little")


def _pieces(compression: str, data: np.ndarray, size: int, window: int) -> Iterator[bytes]:
    """A bz2 or lz4 chunk's records ``window`` bytes at a time, never more than ``size`` + 1 in all (a chunk that
    lies about its size cannot make wmrid decompress more)."""
    if compression == "bz2":
        decompressor: Any = bz2.BZ2Decompressor()
    elif compression == "lz4":
        import lz4.frame  # lz4: only an lz4 chunk

        decompressor = lz4.frame.LZ4FrameDecompressor()
    else:
        raise ValueError(f"unknown compression {compression!r}")
    given, total = memoryview(data), 0
    while total <= size:
        piece = decompressor.decompress(given, max_length=min(window, size + 1 - total))
        given = b""
        if not piece:
            return
        total += len(piece)
        yield piece
        if decompressor.eof:
            return


def _by_start(paths: list[str]) -> list[str]:
    """The bags in the order of their first message (from their chunk-info records); when one has no index (a
    recording that was not closed), the order given."""

    def start(path: str) -> float:
        try:
            with open(path, "rb") as fh:
                head = fh.read(len(MAGIC) + 4096)
                hl = int.from_bytes(head[len(MAGIC) : len(MAGIC) + 4], "little")
                bag = fields(head[len(MAGIC) + 4 : len(MAGIC) + 4 + hl])
                index = int.from_bytes(bag.get("index_pos", b"")[:8], "little")
                if not index:
                    return float("inf")
                fh.seek(index)
                tail = fh.read(1 << 20)
        except OSError:
            return float("inf")
        first = float("inf")
        q = 0
        while q + 8 <= len(tail):
            hl = int.from_bytes(tail[q : q + 4], "little")
            head_fields = fields(tail[q + 4 : q + 4 + hl])
            dl = int.from_bytes(tail[q + 4 + hl : q + 8 + hl], "little")
            if head_fields.get("op") == bytes([OP_CHUNK_INFO]):
                t = head_fields.get("start_time", b"")
                if len(t) == 8:
                    first = min(first, int.from_bytes(t[:4], "little") * 1e9 + int.from_bytes(t[4:], "little"))
            q += 8 + hl + dl
        return first

    if len(paths) < 2:
        return paths
    starts = [start(p) for p in paths]
    if any(s == float("inf") for s in starts):  # a bag without an index: its start is unknown, keep the given order
        return paths
    return [p for _, p in sorted(zip(starts, paths, strict=True), key=lambda sp: sp[0])]
