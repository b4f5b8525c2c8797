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
  by :func:`joint_states`, a compiled CDR reader for the one layout ROS 2 uses for that type
  (little-endian CDR: header stamp, frame id, names, then three sequences of float64).  It matches
  joints BY NAME in every message, so joint order may change from message to message.  A message it
  cannot read (big-endian CDR, a payload that breaks the layout) is decoded by mcap_ros2's generic
  decoder instead; tests check the fast path field for field against that decoder.
* A file cut short (a recording that crashed) is read up to its last complete record and the notes
  say how much was lost; the ``mcap`` summary is never needed.
* The mapped file's pages are handed back to the kernel (``madvise(MADV_DONTNEED)``) as the walk passes
  them, so they do not pile up in the process's resident memory on a large file.
* Damage is checked, never trusted (issue 13): a record length is compared with the bytes left without
  overflowing; a chunk whose declared size is beyond the memory budget (:mod:`wmrid.runtime.limits`) is skipped
  unread, and one that decompresses to another size, or fails its CRC (``uncompressed_crc``; set
  ``WMRID_MCAP_CRC=0`` to skip the check), is skipped; each with a note giving its size and time range.
  A JointState channel whose schema lists other fields, or its fields in another order, than the standard
  message goes to the generic decoder, which decodes by field name.

Bounded memory for long recordings (:func:`scan_mcap`, :func:`iter_joint_parts`): a first pass keeps the
decoded JointState arrays only while they hold at most ``keep`` messages; past that it keeps per topic
only what the whole-log choices need (:class:`JointSummary`: joint names, which fields are populated
for which joint, whether each time source is set and in order, its range, its repeated stamps and a
histogram of its steps).  While the speeds and efforts it decoded (positions left out) take at most
``spare`` bytes, it also keeps them, in file order (:attr:`McapContents.replay`): the next pass reads those
instead of the file.  Otherwise a second pass decodes the chosen topics again, handing out the arrays of each
batch of records (a chunk, or the top-level messages of a 4 MiB stretch of an unchunked file) as it goes.
Both passes walk the file exactly as :func:`read_mcap` does, so the arrays come out the same, in the same
order.

Times stay integer nanoseconds here; conversion to seconds happens once, when a log is assembled.
"""

from __future__ import annotations

import io
import os
import zlib
from collections.abc import Callable, Generator, Iterable, Mapping
from typing import Any

import numpy as np

from wmrid.core.errors import LogFormatError
from wmrid.io.binary import cut_short_note, map_file, read_only, u64s_at
from wmrid.io.mcap.generic import decode_generic, json_batch
from wmrid.io.mcap.records import (
    BOMB_FLOOR,
    BOMB_RATIO,
    CRC_ENV,
    JOINT_STATE_NAMES,
    MAGIC,
    OP_CHANNEL,
    OP_CHUNK,
    OP_FOOTER,
    OP_HEADER,
    OP_MESSAGE,
    OP_METADATA,
    OP_SCHEMA,
    decompress,
    joint_states,
    scan,
    standard_joint_state,
    time_span,
)
from wmrid.io.ros.contents import (
    Accumulator,
    JsonSeries,
    McapContents,
)
from wmrid.io.ros.joint_batches import DYNAMIC_JOINT_STATE_NAMES, JointChannels
from wmrid.runtime.limits import describe


def read_mcap(
    path: str,
    data: bytes | None = None,
    *,
    json_fields: Mapping[str, Mapping[str, str]] | None = None,
    decode_joint_states: bool = True,
    fields: Mapping[str, Any] | None = None,
) -> McapContents:
    """Read an MCAP file (or ``data``, the bytes of one read from a pipe; ``path`` then only names it).

    json_fields : {topic: {key: dotted field path}} for JSON-encoded channels to read as numbers.
    decode_joint_states : False to take only the inventory (faster for ``inspect`` on huge files).
    """
    buf, release = map_file(path, data)
    state = _ReadState(path, json_fields or {}, decode_joint_states, release=release, fields=fields)
    return _read_buffer(state, buf)


def scan_mcap(
    path: str, data: bytes | None = None, *, keep: int, spare: int = 0, fields: Mapping[str, Any] | None = None
) -> McapContents:
    """The first pass over a recording that may be long: :func:`read_mcap`'s contents (JointState only, no
    JSON) while its JointState topics hold at most ``keep`` messages in all; past that, ``complete`` is
    False and ``joints`` holds a :class:`JointSummary` per topic.  Notes and inventory as in :func:`read_mcap`.
    spare : bytes; when ``complete`` is False and the parts decoded without their positions fit in this many
    bytes, ``replay`` holds them (see the module docstring), else None.
    """
    buf, release = map_file(path, data)
    return _read_buffer(_ReadState(path, {}, True, release=release, keep=keep, spare=spare, fields=fields), buf)


def iter_joint_parts(
    path: str, data: bytes | None, channel_ids: Iterable[int], fields: Mapping[str, Any] | None = None
) -> Generator[dict[int, list[tuple[np.ndarray, ...]]], None, None]:
    """The second pass: for the JointState channels ``channel_ids`` (as in :attr:`JointSummary.channel_id`),
    the arrays decoded from each batch of records, {channel id: [(log_ns, stamp_ns, position, velocity,
    effort), ...]}, in file order; concatenated they are the arrays of :class:`JointSeries`.  Other channels
    are not decoded; notes are those of the first pass (the walk is the same).  Memory: one batch.
    """
    wanted = set(channel_ids)
    buf, release = map_file(path, data)
    _check_start(path, buf)
    state = _ReadState(path, {}, True, release=release, wanted=wanted, fields=fields)

    def drain() -> dict[int, list[tuple[np.ndarray, ...]]]:
        out = {}
        for cid in wanted:
            acc = state.channels.get(cid)
            if acc is not None and acc.parts:
                out[cid], acc.parts = acc.parts, []
        return out

    for _ in state.steps(buf, len(MAGIC), buf.shape[0], top_level=True):
        parts = drain()
        if parts:
            yield parts
    parts = drain()
    if parts:
        yield parts


#: Bytes of top-level records scanned at a time.
_SCAN_WINDOW = 1 << 22


def _check_start(name: str, buf: np.ndarray) -> None:
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


def _read_buffer(state: _ReadState, buf: np.ndarray) -> McapContents:
    name, json_fields = state.name, state.json_fields
    size = buf.shape[0]
    _check_start(name, buf)
    end, lost = state.walk(buf, len(MAGIC), size, top_level=True)
    notes = list(state.notes)
    lost_bytes = 0
    if lost:
        lost_bytes = size - end
        notes.append(cut_short_note(end, size))
    elif not closed(buf):
        notes.append(UNCLOSED_NOTE)
    channels = tuple(state.channel_info())
    joints = state.joints()
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
        complete=state.complete, replay=None if state.complete else state.replay, definitions=_definitions(state),
    )  # fmt: skip


#: Said of a file that ends between two records without MCAP's footer and closing magic bytes.
UNCLOSED_NOTE = (
    "the file ends without MCAP's footer (the recording was not closed, e.g. a crash or a split cut off): read "
    "every record it holds; what was to follow is not in it"
)


def closed(buf: np.ndarray) -> bool:
    """Whether an MCAP file's bytes end with the closing magic (a writer that finished wrote its footer before)."""
    return buf.shape[0] >= 2 * len(MAGIC) and bytes(buf[-len(MAGIC) :]) == MAGIC


def _definitions(state: _ReadState) -> dict[str, tuple[str, str]]:
    """topic -> (type, .msg text) of the channels whose schema is a ROS 2 .msg definition."""
    out = {}
    for acc in state.channels.values():
        schema = state.schemas.get(acc.info["schema_id"])
        if schema and schema["encoding"] == "ros2msg":
            out[acc.info["topic"]] = (schema["name"], bytes(schema["data"]).decode("utf-8", "replace"))
    return out


class _ReadState(JointChannels):
    """Schemas, channels and accumulators while walking the records (:class:`JointChannels`: keep, spare,
    wanted).  release : hands the mapped pages below an offset back to the kernel.
    """

    def __init__(
        self,
        name: str,
        json_fields: Mapping[str, Mapping[str, str]],
        decode_joint_states: bool,
        *,
        keep: int | None = None,
        spare: int = 0,
        wanted: set[int] | None = None,
        release: Callable[[int], None] | None = None,
        fields: Mapping[str, Any] | None = None,
    ):
        super().__init__(name, keep=keep, spare=spare, wanted=wanted, fields=fields)
        self.json_fields = json_fields
        self.decode = decode_joint_states
        self.check_crc = os.environ.get(CRC_ENV, "1").strip() != "0"
        self.release = release
        self.metadata: dict[str, dict[str, str]] = {}
        self.profile = ""
        self.library = ""
        self._unknown_channels: set[int] = set()

    # ---- the format's JointState decoding

    def generic(self, acc: Accumulator, payload: bytes) -> Any:
        return decode_generic(self, acc, payload)

    def standard(self, acc: Accumulator) -> bool:
        schema = self.schemas.get(acc.info["schema_id"])
        return bool(schema) and standard_joint_state(schema["encoding"], schema["data"])

    def kernel(self, acc: Accumulator) -> Callable[..., None]:
        return joint_states

    # ---- walking

    def walk(self, buf: np.ndarray, start: int, end: int, top_level: bool) -> tuple[int, bool]:
        """Scan records in buf[start:end]; returns (offset reached, True if a record was cut short)."""
        steps = self.steps(buf, start, end, top_level)
        while True:
            try:
                next(steps)
            except StopIteration as stop:
                return stop.value

    def steps(self, buf: np.ndarray, start: int, end: int, top_level: bool) -> Generator[None, None, tuple[int, bool]]:
        """:meth:`walk` as a generator that pauses after each batch of messages it has decoded."""
        buf = read_only(buf)  # one array type for the kernels, whatever held the bytes
        cap = 65536
        ops = np.empty(cap, dtype=np.uint8)
        starts = np.empty(cap, dtype=np.int64)
        lengths = np.empty(cap, dtype=np.int64)
        p = start
        while True:
            # At top level, scan at most _SCAN_WINDOW bytes ahead: each record header read maps the pages
            # around it, and over a whole file of chunks those would add up to a good part of the file.
            stop = min(end, p + _SCAN_WINDOW) if top_level else end
            n, q = scan(buf, p, stop, ops, starts, lengths)
            if n == 0 and stop < end:  # a record longer than the window
                n, q = scan(buf, p, end, ops[:1], starts[:1], lengths[:1])
                stop = q if n else end
            if n:
                done = yield from self._handle(buf, ops[:n], starts[:n], lengths[:n], top_level)
                if done:
                    return end, False
            if n < cap and (stop >= end or n == 0):
                return q, q < end and not self._only_padding(buf, q, end, top_level)
            p = q

    @staticmethod
    def _only_padding(buf: np.ndarray, q: int, end: int, top_level: bool) -> bool:
        # The closing magic (8 bytes) follows the footer at top level; inside a chunk nothing may remain.
        return top_level and end - q == len(MAGIC) and bytes(buf[q:end]) == MAGIC

    def _handle(self, buf, ops, starts, lengths, top_level: bool) -> Generator[None, None, bool]:
        """Process a batch of records (pausing after each batch of messages); True once the footer has been read."""
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
            if int(lengths[i]) > self.budget:  # checked before the record is copied (a sparse file can claim GBs)
                self.notes.append(
                    f"a record of {describe(int(lengths[i]))} (opcode {op}), beyond the memory budget of "
                    f"{describe(self.budget)} (WMRID_MEMORY_BUDGET), was skipped unread"
                )
                continue
            body = bytes(buf[starts[i] : starts[i] + lengths[i]])
            try:
                if op == OP_CHUNK:
                    yield from self._chunk(body)
                else:
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
            if top_level and self.release is not None:
                self.release(int(starts[i] + lengths[i]))
        if is_msg.any():
            self._messages(buf, starts[is_msg], lengths[is_msg])
            if top_level and self.release is not None:
                self.release(int(starts[-1] + lengths[-1]))
            yield
        return footer

    def _chunk(self, body: bytes) -> Generator[None, None, None]:
        # mcap (~20 ms): only once a file is read (live's warm-up imports this module and reads nothing)
        from mcap.data_stream import ReadDataStream
        from mcap.records import Chunk  # mcap: only once a file is read

        chunk = Chunk.read(ReadDataStream(io.BytesIO(body)))
        span = time_span(chunk.message_start_time, chunk.message_end_time)
        declared = int(chunk.uncompressed_size)
        if declared > self.budget or (declared > BOMB_FLOOR and declared > BOMB_RATIO * max(len(chunk.data), 1)):
            self.notes.append(
                f"a chunk ({len(chunk.data)} bytes, messages {span}) declares {describe(declared)} uncompressed, "
                f"beyond the memory budget of {describe(self.budget)} (WMRID_MEMORY_BUDGET) or {BOMB_RATIO} times its "
                "compressed size: skipped, its messages are lost"
            )
            return
        try:
            raw = decompress(self.name, chunk.compression, chunk.data, declared)
        except LogFormatError:
            raise
        except Exception as err:  # a corrupt chunk: say so, keep what the other chunks hold
            self.notes.append(
                f"a chunk ({len(chunk.data)} bytes, messages {span}) could not be decompressed ({type(err).__name__}: "
                f"{err}); its messages are lost"
            )
            return
        if len(raw) != declared:
            self.notes.append(
                f"a chunk (messages {span}) decompressed to {len(raw)} bytes, not the {declared} it declares: "
                "skipped, its messages are lost"
            )
            return
        if self.check_crc and chunk.uncompressed_crc and zlib.crc32(raw) != chunk.uncompressed_crc:
            self.notes.append(
                f"a chunk ({len(chunk.data)} bytes, messages {span}) fails its CRC check (damaged): skipped, its "
                f"messages are lost ({CRC_ENV}=0 reads it anyway)"
            )
            return
        inner = np.frombuffer(raw, dtype=np.uint8)
        reached, cut = yield from self.steps(inner, 0, inner.shape[0], top_level=False)
        if cut:
            self.notes.append(
                f"a chunk's records end mid-record (byte {reached} of {inner.shape[0]}); the rest is lost"
            )

    def _schema(self, body: bytes) -> None:
        # mcap (~20 ms): only once a file is read (live's warm-up imports this module and reads nothing)
        from mcap.data_stream import ReadDataStream
        from mcap.records import Schema  # mcap: only once a file is read

        s = Schema.read(ReadDataStream(io.BytesIO(body)))
        self.schemas[s.id] = {"name": s.name, "encoding": s.encoding, "data": s.data}

    def _channel(self, body: bytes) -> int | None:
        """Add the channel of a Channel record; its id, None when it was known (the summary repeats them)."""
        # mcap (~20 ms): only once a file is read (live's warm-up imports this module and reads nothing)
        from mcap.data_stream import ReadDataStream
        from mcap.records import Channel  # mcap: only once a file is read

        c = Channel.read(ReadDataStream(io.BytesIO(body)))
        if c.id in self.channels:
            return None
        schema = self.schemas.get(c.schema_id, {"name": "", "encoding": "", "data": b""})
        self.channels[c.id] = Accumulator(
            info={
                "id": c.id, "topic": c.topic, "message_encoding": c.message_encoding, "schema_id": c.schema_id,
                "schema_name": schema["name"], "schema_encoding": schema["encoding"],
            }
        )  # fmt: skip
        return c.id

    def _metadata(self, body: bytes) -> None:
        # mcap (~20 ms): only once a file is read (live's warm-up imports this module and reads nothing)
        from mcap.data_stream import ReadDataStream
        from mcap.records import Metadata  # mcap: only once a file is read

        m = Metadata.read(ReadDataStream(io.BytesIO(body)))
        self.metadata[m.name] = dict(m.metadata)

    def _header(self, body: bytes) -> None:
        # mcap (~20 ms): only once a file is read (live's warm-up imports this module and reads nothing)
        from mcap.data_stream import ReadDataStream
        from mcap.records import Header  # mcap: only once a file is read

        h = Header.read(ReadDataStream(io.BytesIO(body)))
        self.profile, self.library = h.profile, h.library

    # ---- messages

    def _messages(self, buf: np.ndarray, starts: np.ndarray, lengths: np.ndarray) -> None:
        short = lengths < 22  # a Message record holds channel u16, sequence u32, log and publish times u64
        if short.any():
            self.notes.append(f"{int(short.sum())} message record(s) shorter than a message header were skipped")
            starts, lengths = starts[~short], lengths[~short]
            if not len(starts):
                return
        # channel u16, sequence u32, log_time u64
        chan = buf[starts].astype(np.int64) | (buf[starts + 1].astype(np.int64) << 8)
        log_ns = u64s_at(buf, starts + 6)
        data_start = starts + 22
        data_len = lengths - 22
        for cid in np.unique(chan):
            sel = chan == cid
            self._channel_messages(int(cid), buf, data_start[sel], data_len[sel], log_ns[sel])

    def _channel_messages(
        self, cid: int, buf: np.ndarray, starts: np.ndarray, lengths: np.ndarray, times: np.ndarray
    ) -> None:
        """The messages of channel ``cid`` in one batch: payloads buf[starts[i] : starts[i] + lengths[i]], log times
        ``times`` (ns)."""
        acc = self.channels.get(cid)
        if acc is None:
            if cid not in self._unknown_channels:
                self._unknown_channels.add(cid)
                self.notes.append(f"messages on channel id {cid}, which no Channel record defines, were skipped")
            return
        acc.count += len(times)
        lo, hi = int(times.min()), int(times.max())
        acc.first_ns = lo if acc.first_ns is None else min(acc.first_ns, lo)
        acc.last_ns = hi if acc.last_ns is None else max(acc.last_ns, hi)
        info = acc.info
        joint_like = info["schema_name"] in JOINT_STATE_NAMES + DYNAMIC_JOINT_STATE_NAMES
        by_path = info["topic"] in self.fields and info["message_encoding"] == "cdr"
        if by_path and (self.wanted is None or cid in self.wanted):
            self._field_batch(acc, buf, starts, lengths, times)
        elif self.decode and joint_like and info["message_encoding"] == "cdr" and not by_path:
            if self.wanted is None or cid in self.wanted:
                self._joint_batch(acc, buf, starts, lengths, times)
        elif info["message_encoding"] == "json" and info["topic"] in self.json_fields:
            json_batch(self, acc, buf, starts, lengths, times)
