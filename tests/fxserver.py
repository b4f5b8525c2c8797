"""A real Foxglove WebSocket server for the tests of ``wmrid live ws://`` (and bench/speed/bench_live.py): the
foxglove-sdk's server on 127.0.0.1, publishing the messages of an MCAP (JointState as CDR with their ros2msg schema, as
foxglove_bridge publishes them), each with its MCAP log time as the frame's timestamp.

In the test process (:class:`Publisher`) or as a process of its own, to be killed::

    python -m tests.fxserver RUN.mcap [--port 0] [--start 0] [--stop N] [--speed 1] [--hold 600] [--wait 120] [--go]

prints ``port N`` once it listens, waits (up to ``wait`` s) for a client to subscribe, publishes messages [start,
stop) at ``speed`` times real time (0: as fast as it can), prints ``done``, and keeps serving for ``hold`` s.  With
``--go`` it first reads the MCAP and loads the server, prints ``ready`` and listens only once a line comes on its
standard input: a server started ahead that takes a port at a moment the test chooses.
"""

from __future__ import annotations

import argparse
import sys
import threading
import time
from dataclasses import dataclass, field


@dataclass
class Recording:
    """The messages of one channel of an MCAP: topic, schema (name, encoding, text), and (log time ns, payload)."""

    topic: str
    schema_name: str
    schema_encoding: str
    schema: bytes
    encoding: str
    messages: list[tuple[int, bytes]] = field(default_factory=list)


def read_recording(path: str) -> Recording:
    """The messages of the MCAP at ``path`` (one channel), in file order."""
    from mcap.reader import make_reader

    rec = None
    with open(path, "rb") as fh:
        for schema, channel, message in make_reader(fh).iter_messages(log_time_order=False):
            if rec is None:
                rec = Recording(channel.topic, schema.name, schema.encoding, schema.data, channel.message_encoding)
            rec.messages.append((message.log_time, message.data))
    if rec is None:
        raise ValueError(f"{path}: no messages")
    return rec


class Publisher:
    """A foxglove-sdk WebSocket server on 127.0.0.1:``port`` (0: any free port; :attr:`port` says which) serving
    ``rec``'s channel; :meth:`publish` sends messages once a client has subscribed."""

    def __init__(self, rec: Recording, port: int = 0) -> None:
        import foxglove
        from foxglove.websocket import ServerListener

        self.rec = rec
        self.subscribed = threading.Event()
        self.first_sent: float | None = None  # monotonic time the first message was sent
        self.context = foxglove.Context()
        outer = self

        class Listener(ServerListener):
            def on_subscribe(self, client, channel) -> None:
                outer.subscribed.set()

        self.server = foxglove.start_server(
            name="wmrid test server", host="127.0.0.1", port=port, context=self.context, server_listener=Listener(),
            message_backlog_size=1 << 20,
        )  # fmt: skip
        self.port = self.server.port
        schema = foxglove.Schema(name=rec.schema_name, encoding=rec.schema_encoding, data=rec.schema)
        self.channel = foxglove.Channel(rec.topic, schema=schema, message_encoding=rec.encoding, context=self.context)

    def publish(self, start: int = 0, stop: int | None = None, speed: float = 1.0, timeout: float = 60.0) -> float:
        """Send messages [start, stop) once a client subscribes (waiting up to ``timeout`` s), paced by their log times
        at ``speed`` times real time (0: at once); the monotonic time the first was sent."""
        if not self.subscribed.wait(timeout):
            raise TimeoutError("no client subscribed")
        msgs = self.rec.messages[start:stop]
        t0 = self.first_sent = time.monotonic()
        first_ns = msgs[0][0]
        for i, (stamp, data) in enumerate(msgs):
            if speed > 0 and i % 10 == 0:
                due = t0 + (stamp - first_ns) / 1e9 / speed
                wait = due - time.monotonic()
                if wait > 0:
                    time.sleep(wait)
            self.channel.log(data, log_time=stamp)
        return t0

    def stop(self) -> None:
        self.server.stop()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("mcap")
    parser.add_argument("--port", type=int, default=0)
    parser.add_argument("--start", type=int, default=0)
    parser.add_argument("--stop", type=int, default=None)
    parser.add_argument("--speed", type=float, default=1.0)
    parser.add_argument("--hold", type=float, default=600.0)
    parser.add_argument("--wait", type=float, default=120.0, help="s to wait for a client to subscribe")
    parser.add_argument("--go", action="store_true", help="listen only once a line comes on standard input")
    args = parser.parse_args()
    rec = read_recording(args.mcap)
    if args.go:
        import foxglove  # noqa: F401  (loaded before the wait: listening is then immediate)

        print("ready", flush=True)
        sys.stdin.readline()
    pub = Publisher(rec, args.port)
    print(f"port {pub.port}", flush=True)
    pub.publish(args.start, args.stop, args.speed, timeout=args.wait)
    print("done", flush=True)
    time.sleep(args.hold)
    pub.stop()
    sys.exit(0)


if __name__ == "__main__":
    main()
