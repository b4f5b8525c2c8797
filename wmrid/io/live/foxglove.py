"""The Foxglove WebSocket protocol as a client speaks it (``wmrid live ws://HOST:PORT``), and MCAP records to keep what
it receives.  Pure functions and small records: no I/O here (:mod:`wmrid.io.live.ws_source` owns the connection).

The protocol (foxglove/ws-protocol, v1; the same on ``foxglove_bridge`` and on the foxglove-sdk server): the client
offers the subprotocols :data:`SUBPROTOCOLS` (``foxglove.websocket.v1`` is foxglove_bridge's, ``foxglove.sdk.v1`` the
foxglove-sdk server's; each server picks the one it speaks).  Text frames are JSON objects with an ``op``: the server
sends ``serverInfo`` first, then ``advertise`` (channels: id, topic, encoding, schemaName, schema, schemaEncoding),
and at any time ``unadvertise``, ``status`` and others the client may ignore; the client sends ``subscribe``
(subscription ids of its own choosing, one per channel) and ``unsubscribe``.  Binary frames start with an opcode;
0x01 is a message: subscription id (u32 LE), the server's receive timestamp (u64 LE, ns), then the payload, encoded
as the channel says (``cdr`` for ROS 2, with a ``ros2msg`` schema; ``json``).

What arrives is written as MCAP records (:class:`McapRecords`): one Schema and Channel per distinct advertised channel
and one Message per message (log time and publish time = the frame's timestamp), so that wmrid's own MCAP reader
decodes it (JointState, DynamicJointState, field paths, JSON) and the final ``identify`` reads it as a recording.
"""

from __future__ import annotations

import json
import struct
from dataclasses import dataclass
from typing import Any

from wmrid.core.errors import StreamError
from wmrid.io.mcap.records import MAGIC, OP_CHANNEL, OP_DATA_END, OP_FOOTER, OP_HEADER, OP_MESSAGE, OP_SCHEMA

#: The WebSocket subprotocols offered, in order of preference.
SUBPROTOCOLS = ("foxglove.websocket.v1", "foxglove.sdk.v1")
#: Binary opcodes sent by a server.
OP_MESSAGE_DATA = 0x01
#: bytes: opcode, subscription id, timestamp.
MESSAGE_HEADER = 13
#: Message encodings whose messages wmrid decodes (ROS 2 CDR with a .msg schema; JSON).
ENCODINGS = ("cdr", "json")
#: The schema encoding a channel's message encoding implies when the advertisement names none.
SCHEMA_ENCODING = {"cdr": "ros2msg", "json": "jsonschema", "ros1": "ros1msg"}
#: Status levels of a ``status`` message.
STATUS_LEVELS = {0: "info", 1: "warning", 2: "error"}


@dataclass(frozen=True)
class Advertised:
    """A channel a server advertised: ``id`` (the server's, u32), ``topic``, ``encoding`` of its messages,
    ``schema_name``, ``schema_encoding`` (implied by ``encoding`` when not advertised) and ``schema`` (its text)."""

    id: int
    topic: str
    encoding: str
    schema_name: str
    schema_encoding: str
    schema: str

    @property
    def key(self) -> tuple[str, str, str, str, str]:
        """What makes two advertisements the same channel (a server may reuse an id only for the same key)."""
        return (self.topic, self.encoding, self.schema_name, self.schema_encoding, self.schema)


def malformed(url: str, what: str) -> StreamError:
    """The error of a frame that breaks the protocol: one line naming the server and what was wrong."""
    return StreamError(f"{url}: a malformed frame from the server ({what}); is it a Foxglove WebSocket server?")


def parse_text(url: str, text: str) -> dict[str, Any]:
    """A text frame as the JSON object it must be, with a string ``op``."""
    try:
        obj = json.loads(text)
    except (ValueError, RecursionError) as err:
        raise malformed(url, f"a text frame that is not JSON: {err}") from None
    if not isinstance(obj, dict) or not isinstance(obj.get("op"), str):
        raise malformed(url, f"a text frame without an 'op': {text[:60]!r}")
    return obj


def parse_channels(url: str, obj: dict[str, Any]) -> list[Advertised]:
    """The channels of an ``advertise`` message."""
    channels = obj.get("channels")
    if not isinstance(channels, list):
        raise malformed(url, "an advertise without a list of channels")
    out = []
    for ch in channels:
        if not isinstance(ch, dict):
            raise malformed(url, f"an advertised channel that is not an object: {str(ch)[:60]!r}")
        cid, topic, encoding = ch.get("id"), ch.get("topic"), ch.get("encoding")
        name, schema = ch.get("schemaName"), ch.get("schema", "")
        schema_encoding = ch.get("schemaEncoding") or SCHEMA_ENCODING.get(str(encoding), "")
        texts = (topic, encoding, name, schema, schema_encoding)
        if not (isinstance(cid, int) and 0 <= cid < 1 << 32 and all(isinstance(x, str) for x in texts)):
            raise malformed(url, f"an advertised channel without id, topic, encoding, schemaName: {str(ch)[:80]!r}")
        out.append(Advertised(cid, topic, encoding, name, schema_encoding, schema))
    return out


def parse_ids(url: str, obj: dict[str, Any], key: str) -> list[int]:
    """The list of integer ids under ``key`` (``unadvertise``'s ``channelIds``)."""
    ids = obj.get(key)
    if not isinstance(ids, list) or not all(isinstance(i, int) for i in ids):
        raise malformed(url, f"a {obj['op']} without a list of integer {key}")
    return ids


def parse_message_data(url: str, frame: bytes) -> tuple[int, int, bytes] | None:
    """(subscription id, timestamp ns, payload) of a binary message frame; None for the other binary opcodes (time,
    service responses, assets: not used here)."""
    if not frame:
        raise malformed(url, "an empty binary frame")
    if frame[0] != OP_MESSAGE_DATA:
        return None
    if len(frame) < MESSAGE_HEADER:
        raise malformed(url, f"a message frame of {len(frame)} bytes, shorter than its {MESSAGE_HEADER}-byte header")
    sub, stamp = struct.unpack_from("<IQ", frame, 1)
    return sub, stamp, frame[MESSAGE_HEADER:]


def subscribe(pairs: list[tuple[int, int]]) -> str:
    """A ``subscribe`` message for (subscription id, channel id) pairs."""
    return json.dumps({"op": "subscribe", "subscriptions": [{"id": s, "channelId": c} for s, c in pairs]})


def unsubscribe(ids: list[int]) -> str:
    """An ``unsubscribe`` message for subscription ids."""
    return json.dumps({"op": "unsubscribe", "subscriptionIds": ids})


def status_line(url: str, obj: dict[str, Any]) -> str | None:
    """A ``status`` message of level warning or error as one line (None for info and malformed ones)."""
    level, message = obj.get("level"), obj.get("message")
    if not isinstance(level, int) or level < 1 or not isinstance(message, str):
        return None
    return f"{url}: the server says ({STATUS_LEVELS.get(level, 'error')}): {message}"


# -- MCAP records of what arrives ---------------------------------------------------------------------------------


def _string(text: str) -> bytes:
    data = text.encode("utf-8")
    return struct.pack("<I", len(data)) + data


def _record(op: int, body: bytes) -> bytes:
    return struct.pack("<BQ", op, len(body)) + body


class McapRecords:
    """The records of an MCAP file holding what a WebSocket client received, in the order it received it.

    Channels are numbered by :meth:`channel` (u16, from 1) per distinct :attr:`Advertised.key`, so a channel
    advertised again (after a reconnect, under another id) keeps its MCAP channel; schemas likewise per (name,
    encoding, text).  ``start`` is the file's magic and header; ``end`` its DataEnd, Footer and closing magic.
    """

    def __init__(self) -> None:
        self.channels: dict[tuple[str, str, str, str, str], int] = {}
        self.schemas: dict[tuple[str, str, str], int] = {}

    @staticmethod
    def start(profile: str = "ros2") -> bytes:
        return MAGIC + _record(OP_HEADER, _string(profile) + _string("wmrid live (Foxglove WebSocket)"))

    @staticmethod
    def end() -> bytes:
        return _record(OP_DATA_END, bytes(4)) + _record(OP_FOOTER, bytes(20)) + MAGIC

    def channel(self, ch: Advertised) -> tuple[int, bytes]:
        """(the MCAP channel id of ``ch``, the Schema and Channel records to write before its first message: b"" when
        they were written before)."""
        if ch.key in self.channels:
            return self.channels[ch.key], b""
        if len(self.channels) >= 0xFFFF:
            raise StreamError("more than 65,535 distinct channels advertised; restart wmrid live")
        out = b""
        skey = (ch.schema_name, ch.schema_encoding, ch.schema)
        sid = self.schemas.get(skey)
        if sid is None:
            sid = self.schemas[skey] = len(self.schemas) + 1
            data = ch.schema.encode("utf-8")
            body = struct.pack("<H", sid) + _string(ch.schema_name) + _string(ch.schema_encoding)
            out += _record(OP_SCHEMA, body + struct.pack("<I", len(data)) + data)
        cid = self.channels[ch.key] = len(self.channels) + 1
        body = struct.pack("<HH", cid, sid) + _string(ch.topic) + _string(ch.encoding) + struct.pack("<I", 0)
        return cid, out + _record(OP_CHANNEL, body)

    @staticmethod
    def message(channel: int, sequence: int, stamp_ns: int, payload: bytes) -> bytes:
        """A Message record: log time and publish time both ``stamp_ns`` (the server's receive time)."""
        head = struct.pack("<BQHIQQ", OP_MESSAGE, 22 + len(payload), channel, sequence & 0xFFFFFFFF, stamp_ns, stamp_ns)
        return head + payload
