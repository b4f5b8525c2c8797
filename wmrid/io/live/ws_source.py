"""A Foxglove WebSocket server followed as a live source (``wmrid live ws://HOST:PORT``): ``foxglove_bridge`` on a
ROS 2 robot, or any server of the foxglove SDK.

The client (:mod:`websockets`' threaded client) offers both subprotocols, subscribes to the channels the reader
options want (the JointState or DynamicJointState topic, ``--topic``/``--velocity-topic``/``--effort-topic``, the
topics of ``--columns`` field paths, a JSON topic) as they are advertised, and writes what arrives as MCAP records
(:class:`wmrid.io.live.foxglove.McapRecords`) into a temporary file: the same bytes go through the MCAP framer and
decoder every followed recording goes through (:class:`wmrid.io.live.follow._Mcap`), and the final ``identify`` reads
that file, so its result is ``identify`` on exactly the messages received.

Robustness. A lost connection (the server killed, the network gone, no answer to pings for PING_S) ends the run with
:class:`wmrid.core.errors.StreamError` (exit 1, the result so far kept) unless ``reconnect``: then the client retries
with back-off (BACKOFF_S doubling to BACKOFF_MAX_S) and subscribes again to what the new server advertises; messages
sent again or out of order after a reconnect are kept in the file as they came, and read as the offline reader reads any
recording (sorted by time, a repeated stamp keeping the first). A server that closes the connection cleanly (a close
frame of code 1000, 1001 or none: it was shut down) ends the source. A malformed frame, or a message that does not
decode once samples have come, ends the run with one line; the file then keeps what decoded before it.
"""

from __future__ import annotations

import contextlib
import logging
import math
import os
import time
from typing import Any

from wmrid.core.errors import LogFormatError, StreamError, UsageError, option
from wmrid.core.wheel_log import WheelLog
from wmrid.io.live import foxglove as fx
from wmrid.io.live.decoders import McapDecoder
from wmrid.io.live.feeds import READ_BYTES
from wmrid.io.live.follow import FinalInput, LiveSource, ReaderSettings, _Mcap

#: s: how long opening a connection (TCP, handshake) may take.
OPEN_TIMEOUT_S = 5.0
#: s: ping interval, and how long a pong may take before the server counts as not answering (WMRID_WS_PING_S sets
#: another: longer on a lossy radio link, shorter to notice a stopped server sooner).
PING_S = 5.0


def ping_seconds() -> float:
    """The ping interval and pong timeout, s: WMRID_WS_PING_S when set (a number > 0), else PING_S."""
    text = os.environ.get("WMRID_WS_PING_S")
    if text is None:
        return PING_S
    try:
        value = float(text)
    except ValueError:
        value = math.nan
    if not (math.isfinite(value) and value > 0):
        raise UsageError(f"WMRID_WS_PING_S must be a number of seconds > 0, got {text!r}")
    return value


#: s: after the first frame of a poll, how long more frames are gathered before they are decoded.
GATHER_S = 0.02
#: s: the first wait before reconnecting; doubled after each failed attempt, up to BACKOFF_MAX_S.
BACKOFF_S = 0.25
BACKOFF_MAX_S = 8.0
#: bytes: the largest frame accepted (an advertise of a large robot's every topic and schema).
MAX_FRAME = 64 << 20
#: frames queued by the receiving thread before it stops reading the socket (the server then buffers).
QUEUE_FRAMES = 4096
#: Close codes of a server shut down on purpose (normal closure, going away, a close frame without a code as the
#: foxglove-sdk server sends when it stops).
CLEAN_CLOSE = (1000, 1001, 1005)


def check_url(url: str) -> None:
    """Refuse a URL that is not ``ws://HOST[:PORT][/PATH]`` or ``wss://...`` before any connection."""
    from websockets.exceptions import InvalidURI  # websockets (~35 ms): only a ws:// source
    from websockets.uri import parse_uri  # websockets: only a ws:// source

    try:
        parse_uri(url)
    except (InvalidURI, ValueError) as err:
        raise UsageError(
            f"{url}: not a WebSocket address ({err}); give ws://HOST:PORT, e.g. ws://robot.local:8765"
        ) from None


def _why(err: BaseException) -> str:
    """A connection error in a few words."""
    from websockets.exceptions import ConnectionClosed, InvalidStatus  # websockets (~35 ms): only a ws:// source

    if isinstance(err, ConnectionClosed):
        rcvd = err.rcvd
        if rcvd is None and err.sent is not None and err.sent.code == 1011:  # websockets' keepalive timeout
            return f"the server stopped answering (no reply to a ping within {ping_seconds():g} s)"
        if rcvd is None:
            return "the connection dropped without a closing handshake (the server was killed or the network failed)"
        if rcvd.code == 1005:  # a close frame without a status code
            return "the server closed the connection"
        return f"the server closed the connection (code {rcvd.code}{': ' + rcvd.reason if rcvd.reason else ''})"
    if isinstance(err, InvalidStatus):
        return f"the server refused the WebSocket handshake (HTTP {err.response.status_code})"
    if isinstance(err, TimeoutError):
        return "no answer in time"
    if isinstance(err, OSError) and err.strerror:
        return err.strerror
    return str(err) or type(err).__name__


def _quiet_logger() -> Any:
    """A logger for websockets' own messages that prints nothing: what goes wrong is said once, by the live run (its
    keepalive would otherwise print a traceback when a server stops answering)."""
    logger = logging.getLogger("wmrid.live.websocket")
    if not logger.handlers:
        logger.addHandler(logging.NullHandler())
        logger.propagate = False
    return logger


class WsSource(LiveSource):
    """The messages of a Foxglove WebSocket server at ``url``, written to a temporary MCAP as they arrive.

    ``events``: lines on what happened (connection lost or regained, the server's warnings, channels not followed),
    taken by the live run for its display; ``messages``: messages received.
    """

    tables = False

    def __init__(self, url: str, settings: ReaderSettings, reconnect: bool = False) -> None:
        super().__init__(url)
        check_url(url)
        s = settings
        self.url = url
        self.reconnect = reconnect
        self.decoder = McapDecoder(url, s.columns, s.selection, s.signals, s.gear_ratio)
        self.mcap = _Mcap(url, self.decoder)
        self.records = fx.McapRecords()
        self.spill_path = os.path.join(self.tmpdir(), "websocket.mcap")
        self.spill = open(self.spill_path, "wb")  # noqa: SIM115 - closed by close()
        self.good = 0  # bytes of the spill whose messages decoded (or that hold no message)
        self.events: list[str] = []
        self.messages = 0
        self.handed = 0  # samples handed out
        self.conn: Any = None
        self.server: str | None = None  # the server's name and session
        self.channels: dict[int, fx.Advertised] = {}  # the server's channels on this connection
        self.subs: dict[int, int] = {}  # subscription id -> MCAP channel id
        self.sub_of: dict[int, int] = {}  # server channel id -> subscription id
        self.next_sub = 1
        self.waiting_note = False
        self.broken: StreamError | None = None  # raised at the next poll (after the samples that came with it)
        self.attempts = 0
        self.next_try = 0.0
        self._write(fx.McapRecords.start())
        self.good = self.spill.tell()
        try:
            self.conn = self._open()
        except StreamError:
            if not reconnect:
                self.close()
                raise
            self._schedule()
            self.events.append(f"{url}: not answering yet; retrying ({option('reconnect', True)})")

    # -- the connection ---------------------------------------------------------------------------------------------
    def _open(self) -> Any:
        """A new connection (the handshake done), or StreamError naming why not."""
        # websockets (~50 ms with its client): only a ws:// source
        from websockets.exceptions import InvalidHandshake, WebSocketException
        from websockets.sync.client import connect  # websockets: only a ws:// source

        ping = ping_seconds()
        try:
            conn = connect(
                self.url, subprotocols=list(fx.SUBPROTOCOLS), open_timeout=OPEN_TIMEOUT_S, ping_interval=ping,
                ping_timeout=ping, close_timeout=1.0, max_size=MAX_FRAME, max_queue=QUEUE_FRAMES, proxy=None,
                logger=_quiet_logger(),
            )  # type: ignore[arg-type]  # fmt: skip
        except (OSError, TimeoutError, InvalidHandshake, WebSocketException) as err:
            raise StreamError(
                f"{self.url}: cannot connect ({_why(err)}); start foxglove_bridge on the robot (ros2 launch "
                "foxglove_bridge foxglove_bridge_launch.xml) or check the address and port"
            ) from None
        conn = conn.__enter__()  # the connection is closed by _drop; entered, as websockets >= 17.1 asks
        if conn.subprotocol not in fx.SUBPROTOCOLS:
            conn.close()
            raise StreamError(
                f"{self.url}: the server speaks none of the Foxglove subprotocols ({', '.join(fx.SUBPROTOCOLS)}); "
                "give the address of foxglove_bridge or a Foxglove SDK server"
            )
        self.channels.clear()
        self.subs.clear()
        self.sub_of.clear()
        return conn

    def _schedule(self) -> None:
        self.next_try = time.monotonic() + min(BACKOFF_S * 2**self.attempts, BACKOFF_MAX_S)
        self.attempts += 1

    def _lost(self, err: BaseException) -> None:
        """The connection ended: the source ends (a clean close), a retry is scheduled (``reconnect``), or the run
        ends at the next poll (StreamError)."""
        from websockets.exceptions import ConnectionClosed  # websockets (~35 ms): only a ws:// source

        why = _why(err)
        clean = isinstance(err, ConnectionClosed) and err.rcvd is not None and err.rcvd.code in CLEAN_CLOSE
        self._drop()
        if self.reconnect:
            self.attempts = 0
            self._schedule()
            self.events.append(f"lost the connection to {self.url} ({why}); reconnecting")
        elif clean:
            self.ended = f"{self.url}: {why}"
        else:
            self.broken = StreamError(
                f"lost the connection to {self.url}: {why}; give {option('reconnect', True)} to wait for the server"
            )

    def _drop(self) -> None:
        if self.conn is not None:
            conn, self.conn = self.conn, None
            with contextlib.suppress(Exception):  # a connection already broken closes as it can
                conn.close()

    def _retry(self, timeout: float) -> None:
        """One reconnection attempt when it is due (else wait up to ``timeout``)."""
        wait = self.next_try - time.monotonic()
        if wait > 0:
            time.sleep(min(wait, timeout))
            return
        try:
            self.conn = self._open()
        except StreamError as err:
            self._schedule()
            if self.attempts in (3, 10) or self.attempts % 30 == 0:
                self.events.append(f"{err} (attempt {self.attempts}, retrying)")
            return
        self.events.append(f"reconnected to {self.url}")

    # -- frames -----------------------------------------------------------------------------------------------------
    def _wanted(self, ch: fx.Advertised) -> bool:
        if not self.decoder.keep(ch.topic, ch.schema_name):
            return False
        if ch.encoding not in fx.ENCODINGS:
            self.events.append(
                f"{self.url}: {ch.topic} ({ch.schema_name}) is sent as {ch.encoding}; wmrid reads cdr (ROS 2) and "
                "json channels: not followed"
            )
            return False
        return True

    def _advertise(self, channels: list[fx.Advertised], out: bytearray) -> None:
        pairs = []
        for ch in channels:
            old = self.channels.get(ch.id)
            if old is not None and old.key == ch.key and ch.id in self.sub_of:
                continue  # advertised again, unchanged: still subscribed
            if old is not None and ch.id in self.sub_of:
                self.subs.pop(self.sub_of.pop(ch.id), None)
            self.channels[ch.id] = ch
            if not self._wanted(ch):
                continue
            cid, records = self.records.channel(ch)
            out += records
            sub = self.next_sub
            self.next_sub = (self.next_sub + 1) & 0xFFFFFFFF or 1
            self.subs[sub] = cid
            self.sub_of[ch.id] = sub
            pairs.append((sub, ch.id))
        if pairs:
            self.conn.send(fx.subscribe(pairs))
        elif not self.sub_of and not self.waiting_note and self.channels:
            self.waiting_note = True
            listing = ", ".join(f"{c.topic} ({c.schema_name})" for c in list(self.channels.values())[:12])
            self.events.append(
                f"{self.url}: no channel to follow yet; the server advertises {listing}; waiting for a JointState or "
                f"DynamicJointState topic (or name one with {option('topic')})"
            )

    def _frame(self, frame: str | bytes, out: bytearray) -> None:
        if isinstance(frame, str):
            obj = fx.parse_text(self.url, frame)
            op = obj["op"]
            if op == "advertise":
                self._advertise(fx.parse_channels(self.url, obj), out)
            elif op == "unadvertise":
                for cid in fx.parse_ids(self.url, obj, "channelIds"):
                    self.channels.pop(cid, None)
                    sub = self.sub_of.pop(cid, None)
                    if sub is not None:
                        self.subs.pop(sub, None)
            elif op == "serverInfo":
                name, session = obj.get("name"), obj.get("sessionId")
                server = f"{name} (session {session})" if session else str(name)
                if self.server is not None and server != self.server:
                    self.events.append(f"{self.url}: a new server session: {server}")
                self.server = server
            elif op == "status":
                line = fx.status_line(self.url, obj)
                if line is not None:
                    self.events.append(line)
            return
        data = fx.parse_message_data(self.url, frame)
        if data is None:
            return
        sub, stamp, payload = data
        channel = self.subs.get(sub)
        if channel is None:
            return  # a subscription just ended
        self.messages += 1
        out += fx.McapRecords.message(channel, self.messages, stamp, payload)

    # -- the source -------------------------------------------------------------------------------------------------
    def _write(self, data: bytes) -> list[WheelLog]:
        self.spill.write(data)
        return self.mcap.samples(data, flush=False) if data else []

    def _push(self, data: bytes, flush: bool) -> list[WheelLog]:
        """Write ``data`` (MCAP records) and decode what is due; a message that does not decode once samples have come
        breaks the stream (the spill is cut back to what decoded)."""
        self.spill.write(data)
        try:
            pieces = self.mcap.samples(data, flush)
        except (LogFormatError, UsageError) as err:
            if not self.handed:
                raise
            self.spill.truncate(self.good)
            self.spill.seek(self.good)
            self.mcap.framer.messages = []
            self.mcap.waiting = 0
            raise StreamError(f"{self.url}: a message that does not decode: {err}") from None
        if self.mcap.waiting == 0:
            self.good = self.spill.tell()
        self.handed += sum(len(p) for p in pieces)
        return pieces

    def poll(self, timeout: float) -> list[WheelLog]:
        if self.broken is not None:
            raise self.broken
        if self.conn is None:
            if self.reconnect and self.ended is None:
                self._retry(timeout)
            else:
                time.sleep(timeout)
            self._got(b"")
            return self._push(b"", flush=self.mcap.waiting > 0)
        from websockets.exceptions import ConnectionClosed  # websockets (~35 ms): only a ws:// source

        out = bytearray()
        start = time.monotonic()
        gather_end: float | None = None
        before = self.messages
        try:
            while len(out) < READ_BYTES:
                now = time.monotonic()
                wait = (start + timeout if gather_end is None else gather_end) - now
                try:
                    frame = self.conn.recv(timeout=max(wait, 0.0))
                except TimeoutError:
                    break
                self._frame(frame, out)
                if gather_end is None:
                    gather_end = now + GATHER_S
        except ConnectionClosed as err:
            self._lost(err)
        except StreamError:
            self._drop()
            self._push(bytes(out), flush=True)  # what came whole before the bad frame is kept
            raise
        got = self.messages > before
        self._got(bytes(out) if got else b"")
        return self._push(bytes(out), flush=not got)

    def flush(self) -> list[WheelLog]:
        """Decode the messages waiting for a batch (before a refresh, so that it includes them)."""
        return self._push(b"", flush=True) if self.mcap.waiting else []

    def take_events(self) -> list[str]:
        events, self.events = self.events, []
        return events

    def final_input(self, natural: bool) -> FinalInput:
        self._drop()
        try:
            self.flush()
        except (StreamError, LogFormatError, UsageError):
            self.spill.truncate(self.good)
            self.spill.seek(self.good)
        self.spill.truncate(self.spill.tell())
        self.spill.write(fx.McapRecords.end())
        self.spill.flush()
        what = f"the {self.messages:,} messages received from {self.url}"
        return FinalInput(self.spill_path, True, self.url, what)

    def close(self) -> None:
        self._drop()
        if self.spill is not None and not self.spill.closed:
            self.spill.close()
        super().close()
