"""Reading MCAP files (ROS 2 bags and others): every record streamed, JointState decoded by a compiled path.

What comes out (:func:`read_mcap`) is an inventory of the channels (topic, encoding, schema, message
count, first and last log time) and, for each ``sensor_msgs/msg/JointState`` channel in CDR, the
joint names and per-message arrays of header stamp, log time, position, velocity and effort.
Optionally, JSON-encoded channels are read by field paths.

How (bounded memory, no per-message Python objects on the fast path):

* The file is memory-mapped (standard input is read into memory once).  A compiled scan walks the
  record framing (opcode u8, length u64) of the data section; a Chunk record is decompressed (zstd or
  lz4, with the libraries mcap itself uses) and its inner records scanned the same way, one chunk at a
  time.  Schema, Channel and Metadata records are parsed with the ``mcap`` library's record classes.
  Files without a summary or index, unchunked files and files on a pipe all read the same way.
* Message records give channel id, log time and the payload's place; JointState payloads are decoded
  by :func:`_joint_states`, a compiled CDR reader for the one layout ROS 2 uses for that type
  (little-endian CDR: header stamp, frame id, names, then three sequences of float64).  It matches
  joints BY NAME in every message, so joint order may change from message to message.  A message it
  cannot read (big-endian CDR, a payload that breaks the layout) is decoded by mcap_ros2's generic
  decoder instead; tests check the fast path field for field against that decoder.
* A file cut short (a recording that crashed) is read up to its last complete record and the notes
  say how much was lost; the ``mcap`` summary is never needed.

Times stay integer nanoseconds here; conversion to seconds happens once, when a log is assembled.
"""

from __future__ import annotations

import contextlib
import io
import json
import mmap
import os
from collections.abc import Mapping
from dataclasses import dataclass, field
from typing import Any

import numba
import numpy as np

from wmrid.errors import LogFormatError

MAGIC = b"\x89MCAP0\r\n"
JOINT_STATE = "sensor_msgs/msg/JointState"
JOINT_STATE_NAMES = (JOINT_STATE, "sensor_msgs/JointState")

OP_HEADER = 0x01
OP_FOOTER = 0x02
OP_SCHEMA = 0x03
OP_CHANNEL = 0x04
OP_MESSAGE = 0x05
OP_CHUNK = 0x06
OP_METADATA = 0x0C
OP_DATA_END = 0x0F

STATUS_OK = 0
STATUS_MALFORMED = 1
STATUS_NOT_LE_CDR = 2


# --------------------------------------------------------------------------------------------------
# Compiled kernels


@numba.njit(cache=True, nogil=True)
def _u32(buf, p):
    return np.int64(buf[p]) | (np.int64(buf[p + 1]) << 8) | (np.int64(buf[p + 2]) << 16) | (np.int64(buf[p + 3]) << 24)


@numba.njit(cache=True, nogil=True)
def _u64(buf, p):
    lo = _u32(buf, p)
    hi = _u32(buf, p + 4)
    return lo | (hi << 32)


@numba.njit(cache=True, nogil=True)
def _scan(buf, start, end, ops, starts, lengths):
    """Walk records (opcode u8, length u64, body) in buf[start:end].

    Fills ops/starts (body offset)/lengths and returns (count, offset after the last complete record).
    Stops early when the arrays are full (the caller grows them and continues from that offset) or
    when a record runs past ``end`` (a truncated file).
    """
    p = start
    n = 0
    cap = ops.shape[0]
    while p + 9 <= end and n < cap:
        length = _u64(buf, p + 1)
        if length < 0 or p + 9 + length > end:
            break
        ops[n] = buf[p]
        starts[n] = p + 9
        lengths[n] = length
        n += 1
        p += 9 + length
    return n, p


@numba.njit(cache=True, nogil=True)
def _f64(buf, p):
    return buf[p : p + 8].view(np.float64)[0]


@numba.njit(cache=True, nogil=True)
def _joint_states(buf, starts, lengths, ref, ref_off, stamp, pos, vel, eff, status):
    """Decode JointState CDR payloads buf[starts[i] : starts[i] + lengths[i]] into per-joint arrays.

    ref, ref_off: the reference joint names, concatenated bytes and offsets (K + 1,).
    stamp (n,) int64 header stamp in ns; pos, vel, eff (n, K) float64, NaN where the message lacks the
    joint or the field; status (n,) int8: 0 ok, 1 malformed, 2 not little-endian CDR (for the caller
    to decode another way).
    """
    n = starts.shape[0]
    k_ref = ref_off.shape[0] - 1
    idx = np.empty(k_ref, dtype=np.int64)
    for i in range(n):
        b = starts[i]
        end = b + lengths[i]
        status[i] = STATUS_OK
        for k in range(k_ref):
            pos[i, k] = np.nan
            vel[i, k] = np.nan
            eff[i, k] = np.nan
        if lengths[i] < 16:
            status[i] = STATUS_MALFORMED
            continue
        if buf[b] != 0 or buf[b + 1] != 1:
            status[i] = STATUS_NOT_LE_CDR
            continue
        o = b + 4  # CDR alignment is relative to the payload after the encapsulation header
        sec = _u32(buf, o)
        if sec >= 2**31:
            sec -= 2**32
        nsec = _u32(buf, o + 4)
        stamp[i] = sec * 1_000_000_000 + nsec
        p = 8
        slen = _u32(buf, o + p)
        p += 4 + slen
        p = (p + 3) & ~3
        if o + p + 4 > end:
            status[i] = STATUS_MALFORMED
            continue
        count = _u32(buf, o + p)
        p += 4
        for k in range(k_ref):
            idx[k] = -1
        bad = False
        for j in range(count):
            p = (p + 3) & ~3
            if o + p + 4 > end:
                bad = True
                break
            slen = _u32(buf, o + p)
            p += 4
            if o + p + slen > end or slen < 1:
                bad = True
                break
            name_len = slen - 1  # the length counts the terminating NUL
            for k in range(k_ref):
                a = ref_off[k]
                if ref_off[k + 1] - a != name_len or idx[k] >= 0:
                    continue
                same = True
                for c in range(name_len):
                    if buf[o + p + c] != ref[a + c]:
                        same = False
                        break
                if same:
                    idx[k] = j
            p += slen
        if bad:
            status[i] = STATUS_MALFORMED
            continue
        for which in range(3):
            p = (p + 3) & ~3
            if o + p + 4 > end:
                bad = True
                break
            m = _u32(buf, o + p)
            p += 4
            if m > 0:
                p = (p + 7) & ~7
                if o + p + 8 * m > end:
                    bad = True
                    break
            for k in range(k_ref):
                j = idx[k]
                if j >= 0 and j < m:
                    value = _f64(buf, o + p + 8 * j)
                    if which == 0:
                        pos[i, k] = value
                    elif which == 1:
                        vel[i, k] = value
                    else:
                        eff[i, k] = value
            p += 8 * m
        if bad:
            status[i] = STATUS_MALFORMED


# --------------------------------------------------------------------------------------------------
# Results


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

    def populated(self, name: str) -> str:
        """'yes', 'zeros' (present but all zero), 'partly' (some NaN) or 'no' for field ``name``."""
        values = self.field(name)
        if values.size == 0 or np.all(np.isnan(values)):
            return "no"
        finite = values[~np.isnan(values)]
        if np.all(finite == 0):
            return "zeros"
        return "partly" if np.any(np.isnan(values)) else "yes"


@dataclass(frozen=True)
class JsonSeries:
    """Numeric fields read from a JSON-encoded channel: log_ns (n,) int64 and {key: (n,) float64}."""

    topic: str
    log_ns: np.ndarray
    values: dict[str, np.ndarray]


@dataclass(frozen=True)
class McapContents:
    """What :func:`read_mcap` found."""

    source: str
    profile: str
    library: str
    channels: tuple[ChannelInfo, ...]
    joints: dict[str, JointSeries]
    json: dict[str, JsonSeries]
    metadata: dict[str, dict[str, str]]
    notes: tuple[str, ...]
    size_bytes: int
    lost_bytes: int = 0

    def channel(self, topic: str) -> ChannelInfo | None:
        return next((c for c in self.channels if c.topic == topic), None)


# --------------------------------------------------------------------------------------------------
# Reading


@dataclass
class _Accumulator:
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


def read_mcap(
    path: str,
    data: bytes | None = None,
    *,
    json_fields: Mapping[str, Mapping[str, str]] | None = None,
    decode_joint_states: bool = True,
) -> McapContents:
    """Read an MCAP file (or ``data``, the bytes of one read from a pipe; ``path`` then only names it).

    json_fields : {topic: {key: dotted field path}} for JSON-encoded channels to read as numbers.
    decode_joint_states : False to take only the inventory (faster for ``inspect`` on huge files).
    """
    name = path
    if data is not None:
        buf = np.frombuffer(data, dtype=np.uint8)
        return _read_buffer(name, buf, json_fields or {}, decode_joint_states)
    try:
        with open(path, "rb") as fh:
            size = os.fstat(fh.fileno()).st_size
            if size == 0:
                raise LogFormatError(f"{name}: the file is empty (0 bytes)")
            # Not closed explicitly: numpy views of it may live on in a traceback; the map is released
            # when the last view goes (the file descriptor closes here, the map keeps its own).
            mapped = mmap.mmap(fh.fileno(), 0, access=mmap.ACCESS_READ)
    except OSError as err:
        raise LogFormatError(f"{name}: cannot be read ({err.strerror or err})") from err
    return _read_buffer(name, np.frombuffer(mapped, dtype=np.uint8), json_fields or {}, decode_joint_states)


def _read_buffer(
    name: str, buf: np.ndarray, json_fields: Mapping[str, Mapping[str, str]], decode_joint_states: bool
) -> McapContents:
    size = buf.shape[0]
    if size < len(MAGIC) or bytes(buf[: len(MAGIC)]) != MAGIC:
        raise LogFormatError(
            f"{name}: not an MCAP file (it does not start with the MCAP magic bytes); give a .mcap recording "
            "(ros2 bag record -s mcap) or a CSV/Parquet log"
        )
    if size < len(MAGIC) + 9 or buf[len(MAGIC)] != OP_HEADER:
        raise LogFormatError(
            f"{name}: starts like an MCAP file but no Header record follows the magic bytes: it is damaged or "
            "not MCAP; check the file (mcap doctor) or record it again"
        )
    state = _ReadState(name, json_fields, decode_joint_states)
    end, lost = state.walk(buf, len(MAGIC), size, top_level=True)
    notes = list(state.notes)
    lost_bytes = 0
    if lost:
        lost_bytes = size - end
        notes.append(
            f"the file ends inside a record (byte {end} of {size}): it was cut short, e.g. by a crash; "
            f"read everything up to there, {lost_bytes} bytes at the end are lost"
        )
    channels = tuple(state.channel_info())
    joints = {}
    for acc in state.channels.values():
        if acc.ref is not None and acc.parts:
            joints[acc.info["topic"]] = _join(acc)
    json_out = {}
    for acc in state.channels.values():
        keys = json_fields.get(acc.info["topic"])
        if keys is not None and acc.info["message_encoding"] == "json":
            rows = acc.json_rows
            json_out[acc.info["topic"]] = JsonSeries(
                topic=acc.info["topic"],
                log_ns=np.array([r[0] for r in rows], dtype=np.int64),
                values={k: np.array([r[1][i] for r in rows], dtype=np.float64) for i, k in enumerate(keys)},
            )
    return McapContents(
        source=name, profile=state.profile, library=state.library, channels=channels, joints=joints,
        json=json_out, metadata=state.metadata, notes=tuple(notes), size_bytes=size, lost_bytes=lost_bytes,
    )  # fmt: skip


def _join(acc: _Accumulator) -> JointSeries:
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


class _ReadState:
    """Schemas, channels and accumulators while walking the records."""

    def __init__(self, name: str, json_fields: Mapping[str, Mapping[str, str]], decode_joint_states: bool):
        self.name = name
        self.json_fields = json_fields
        self.decode = decode_joint_states
        self.schemas: dict[int, dict[str, Any]] = {}
        self.channels: dict[int, _Accumulator] = {}
        self.metadata: dict[str, dict[str, str]] = {}
        self.notes: list[str] = []
        self.profile = ""
        self.library = ""
        self._decoders: dict[int, Any] = {}
        self._unknown_channels: set[int] = set()

    # ---- walking

    def walk(self, buf: np.ndarray, start: int, end: int, top_level: bool) -> tuple[int, bool]:
        """Scan records in buf[start:end]; returns (offset reached, True if a record was cut short)."""
        cap = 65536
        ops = np.empty(cap, dtype=np.uint8)
        starts = np.empty(cap, dtype=np.int64)
        lengths = np.empty(cap, dtype=np.int64)
        p = start
        while True:
            n, q = _scan(buf, p, end, ops, starts, lengths)
            if n:
                done = self._handle(buf, ops[:n], starts[:n], lengths[:n], top_level)
                if done:
                    return end, False
            if n < cap:
                return q, q < end and not self._only_padding(buf, q, end, top_level)
            p = q

    @staticmethod
    def _only_padding(buf: np.ndarray, q: int, end: int, top_level: bool) -> bool:
        # The closing magic (8 bytes) follows the footer at top level; inside a chunk nothing may remain.
        return top_level and end - q == len(MAGIC) and bytes(buf[q:end]) == MAGIC

    def _handle(self, buf, ops, starts, lengths, top_level: bool) -> bool:
        """Process a batch of records; True once the footer has been read."""
        is_msg = ops == OP_MESSAGE
        other = np.flatnonzero(~is_msg)
        # Non-message records are few; handle them in order relative to the messages around them:
        # a Channel always precedes its messages, so handling all of them first is equivalent.
        footer = False
        handlers = {OP_CHUNK: self._chunk, OP_SCHEMA: self._schema, OP_CHANNEL: self._channel,
                    OP_METADATA: self._metadata, OP_HEADER: self._header}  # fmt: skip
        for i in other:
            op = int(ops[i])
            if op == OP_FOOTER and top_level:
                footer = True
                continue
            handler = handlers.get(op)
            if handler is None:
                continue  # index and summary records: not needed
            body = bytes(buf[starts[i] : starts[i] + lengths[i]])
            try:
                handler(body)
            except LogFormatError:
                raise
            except Exception as err:  # a damaged record: skip it, say so, keep the rest
                what = {OP_CHUNK: "chunk", OP_SCHEMA: "schema", OP_CHANNEL: "channel", OP_METADATA: "metadata",
                        OP_HEADER: "header"}[op]  # fmt: skip
                self.notes.append(
                    f"a damaged {what} record ({type(err).__name__}) was skipped"
                    + ("; its messages are lost" if op == OP_CHUNK else "")
                )
        if is_msg.any():
            self._messages(buf, starts[is_msg], lengths[is_msg])
        return footer

    def _chunk(self, body: bytes) -> None:
        from mcap.data_stream import ReadDataStream
        from mcap.records import Chunk

        chunk = Chunk.read(ReadDataStream(io.BytesIO(body)))
        try:
            if chunk.compression == "zstd":
                import zstandard

                raw = zstandard.decompress(chunk.data, chunk.uncompressed_size)
            elif chunk.compression == "lz4":
                import lz4.frame

                raw = lz4.frame.decompress(chunk.data)
            elif chunk.compression == "":
                raw = chunk.data
            else:
                raise LogFormatError(
                    f"{self.name}: a chunk uses compression {chunk.compression!r}, which wmrid cannot read "
                    "(zstd, lz4 or none); recompress the file with `mcap convert`"
                )
        except LogFormatError:
            raise
        except Exception as err:  # a corrupt chunk: say so, keep what the other chunks hold
            self.notes.append(f"a chunk could not be decompressed ({type(err).__name__}: {err}); its messages are lost")
            return
        inner = np.frombuffer(raw, dtype=np.uint8)
        reached, cut = self.walk(inner, 0, inner.shape[0], top_level=False)
        if cut:
            self.notes.append(
                f"a chunk's records end mid-record (byte {reached} of {inner.shape[0]}); the rest is lost"
            )

    def _schema(self, body: bytes) -> None:
        from mcap.data_stream import ReadDataStream
        from mcap.records import Schema

        s = Schema.read(ReadDataStream(io.BytesIO(body)))
        self.schemas[s.id] = {"name": s.name, "encoding": s.encoding, "data": s.data}

    def _channel(self, body: bytes) -> None:
        from mcap.data_stream import ReadDataStream
        from mcap.records import Channel

        c = Channel.read(ReadDataStream(io.BytesIO(body)))
        if c.id in self.channels:
            return
        schema = self.schemas.get(c.schema_id, {"name": "", "encoding": "", "data": b""})
        self.channels[c.id] = _Accumulator(
            info={
                "id": c.id, "topic": c.topic, "message_encoding": c.message_encoding, "schema_id": c.schema_id,
                "schema_name": schema["name"], "schema_encoding": schema["encoding"],
            }
        )  # fmt: skip

    def _metadata(self, body: bytes) -> None:
        from mcap.data_stream import ReadDataStream
        from mcap.records import Metadata

        m = Metadata.read(ReadDataStream(io.BytesIO(body)))
        self.metadata[m.name] = dict(m.metadata)

    def _header(self, body: bytes) -> None:
        from mcap.data_stream import ReadDataStream
        from mcap.records import Header

        h = Header.read(ReadDataStream(io.BytesIO(body)))
        self.profile, self.library = h.profile, h.library

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

    # ---- messages

    def _messages(self, buf: np.ndarray, starts: np.ndarray, lengths: np.ndarray) -> None:
        head = buf[starts[:, None] + np.arange(14)[None, :]]  # channel u16, sequence u32, log_time u64
        chan = head[:, 0].astype(np.int64) | (head[:, 1].astype(np.int64) << 8)
        log_ns = np.zeros(len(starts), dtype=np.uint64)
        for b in range(8):
            log_ns |= head[:, 6 + b].astype(np.uint64) << np.uint64(8 * b)
        log_ns = log_ns.astype(np.int64)
        data_start = starts + 22
        data_len = lengths - 22
        for cid in np.unique(chan):
            sel = chan == cid
            acc = self.channels.get(int(cid))
            if acc is None:
                if int(cid) not in self._unknown_channels:
                    self._unknown_channels.add(int(cid))
                    self.notes.append(
                        f"messages on channel id {int(cid)}, which no Channel record defines, were skipped"
                    )
                continue
            times = log_ns[sel]
            acc.count += int(sel.sum())
            lo, hi = int(times.min()), int(times.max())
            acc.first_ns = lo if acc.first_ns is None else min(acc.first_ns, lo)
            acc.last_ns = hi if acc.last_ns is None else max(acc.last_ns, hi)
            info = acc.info
            if self.decode and info["schema_name"] in JOINT_STATE_NAMES and info["message_encoding"] == "cdr":
                self._joint_batch(acc, buf, data_start[sel], data_len[sel], times)
            elif info["message_encoding"] == "json" and info["topic"] in self.json_fields:
                self._json_batch(acc, buf, data_start[sel], data_len[sel], times)

    def _joint_batch(self, acc: _Accumulator, buf, starts, lengths, times) -> None:
        if acc.ref is None:
            first = self._generic(acc, bytes(buf[starts[0] : starts[0] + lengths[0]]))
            if first is None:
                acc.skipped += len(starts)
                return
            self._set_names(acc, list(first.name))
        n = len(starts)
        k = len(acc.names)
        stamp = np.zeros(n, dtype=np.int64)
        pos = np.empty((n, k))
        vel = np.empty((n, k))
        eff = np.empty((n, k))
        status = np.zeros(n, dtype=np.int8)
        _joint_states(buf, starts, lengths, acc.ref, acc.ref_off, stamp, pos, vel, eff, status)
        slow = np.flatnonzero(status != STATUS_OK)
        keep = np.ones(n, dtype=bool)
        for i in slow:  # rare: other endianness, a layout the fast path refuses, or new joint names
            msg = self._generic(acc, bytes(buf[starts[i] : starts[i] + lengths[i]]))
            if msg is None:
                keep[i] = False
                acc.skipped += 1
                continue
            stamp[i] = int(msg.header.stamp.sec) * 1_000_000_000 + int(msg.header.stamp.nanosec)
            for kk, joint in enumerate(acc.names):
                if joint in msg.name:
                    j = list(msg.name).index(joint)
                    pos[i, kk] = msg.position[j] if j < len(msg.position) else np.nan
                    vel[i, kk] = msg.velocity[j] if j < len(msg.velocity) else np.nan
                    eff[i, kk] = msg.effort[j] if j < len(msg.effort) else np.nan
        if not keep.all():
            times, stamp, pos, vel, eff = times[keep], stamp[keep], pos[keep], vel[keep], eff[keep]
        acc.parts.append((times.copy(), stamp, pos, vel, eff))

    def _set_names(self, acc: _Accumulator, names: list[str]) -> None:
        acc.names = names
        encoded = [n.encode("utf-8") for n in names]
        acc.ref = np.frombuffer(b"".join(encoded) or b"\0", dtype=np.uint8).copy()
        acc.ref_off = np.cumsum([0, *[len(e) for e in encoded]]).astype(np.int64)

    def _generic(self, acc: _Accumulator, payload: bytes) -> Any:
        """Decode one message with mcap_ros2's generic decoder (None if it cannot be decoded)."""
        cid = acc.info["id"]
        decoder = self._decoders.get(cid)
        if decoder is None:
            from mcap.records import Schema
            from mcap_ros2.decoder import DecoderFactory

            s = self.schemas.get(acc.info["schema_id"])
            if s is None:
                return None
            schema = Schema(id=acc.info["schema_id"], name=s["name"], encoding=s["encoding"], data=s["data"])
            try:
                # mcap_ros2 prints parse problems of a damaged schema; keep them off wmrid's stdout/stderr.
                with contextlib.redirect_stdout(io.StringIO()), contextlib.redirect_stderr(io.StringIO()):
                    decoder = DecoderFactory().decoder_for("cdr", schema)
            except Exception as err:
                self.notes.append(f"topic {acc.info['topic']}: its schema cannot be parsed ({err}); skipped")
                return None
            if decoder is None:
                return None
            self._decoders[cid] = decoder
        try:
            return decoder(payload)
        except Exception:
            return None

    def _json_batch(self, acc: _Accumulator, buf, starts, lengths, times) -> None:
        keys = self.json_fields[acc.info["topic"]]
        paths = [path.split(".") for path in keys.values()]
        for s, n, t in zip(starts, lengths, times, strict=True):
            try:
                obj = json.loads(bytes(buf[s : s + n]))
            except ValueError:
                acc.skipped += 1
                continue
            acc.json_rows.append((int(t), [_lookup(obj, path) for path in paths]))


def _lookup(obj: Any, path: list[str]) -> float:
    """obj[path[0]][path[1]]... as a float (list indices as integers); NaN when absent or not a number."""
    for part in path:
        if isinstance(obj, list):
            try:
                obj = obj[int(part)]
            except (ValueError, IndexError):
                return float("nan")
        elif isinstance(obj, dict) and part in obj:
            obj = obj[part]
        else:
            return float("nan")
    if isinstance(obj, bool) or not isinstance(obj, (int, float)):
        return float("nan")
    return float(obj)
