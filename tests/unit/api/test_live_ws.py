"""``wmrid live ws://HOST:PORT`` (issue 32) against real Foxglove WebSocket servers on 127.0.0.1: the foxglove-sdk's
server (tests/fxserver.py; in this process, or a process of its own to kill), and for frames no real server sends, a
small server on the websockets package speaking the protocol.

The messages: the first 5 s of the bundled paper-scenario log (1 kHz) as JointState CDR messages with their ros2msg
schema (wmrid's own MCAP writer), published as they are in that MCAP, each with its log time; the final result must be
``wmrid.identify`` on that MCAP.
"""

from __future__ import annotations

import json
import os
import struct
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from locations import ROOT_DIR

import wmrid
from tests.cliutil import COLUMNS
from tests.fxserver import Publisher, read_recording

ROOT = ROOT_DIR
SAMPLE = ROOT / "sample_logs" / "paper_sinusoid.csv"
N = 5000  # messages: 5 s at 1 kHz
HANG_S = 120  # a guard against hangs only: nothing here is timed


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    """(the MCAP of the first N samples as JointState messages, its Recording, identify's result on it)."""
    import pandas as pd

    from wmrid.io.mcap.writer import write_joint_state_mcap

    whole = wmrid.read_log(str(SAMPLE))
    frame = pd.DataFrame({
        "t": whole.t[:N], "eta_r": whole.eta[:N, 0], "eta_l": whole.eta[:N, 1], "tau_r": whole.tau[:N, 0],
        "tau_l": whole.tau[:N, 1],
    })  # fmt: skip
    path = tmp_path_factory.mktemp("ws") / "run.mcap"
    write_joint_state_mcap(path, frame, odom_topic=None)
    return path, read_recording(str(path)), wmrid.identify(str(path), "paper")


def same(live_result, offline, rel=1e-9):
    """The live run's final result is identify's: the estimate to ``rel``, the std and warnings as offline."""
    assert live_result.parameters.keys() == offline.parameters.keys()
    for name, (value, std) in offline.parameters.items():
        got, got_std = live_result.parameters[name]
        assert got == pytest.approx(value, rel=rel, abs=1e-15), name
        assert got_std == pytest.approx(std, rel=1e-6), name
    assert live_result.warnings == offline.warnings


def start_server(path: Path, *args: str) -> tuple[subprocess.Popen, int]:
    """tests/fxserver.py as a process of its own, serving ``path``: (the process, its port)."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "tests.fxserver", str(path), *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
        cwd=ROOT, env=dict(os.environ, PYTHONPATH=str(ROOT)),
    )  # fmt: skip
    line = proc.stdout.readline().decode()
    assert line.startswith("port "), (line, proc.stderr.read().decode() if proc.poll() is not None else "")
    return proc, int(line.split()[1])


def ready_server(path: Path, *args: str) -> subprocess.Popen:
    """tests/fxserver.py as a process of its own, serving ``path`` once :func:`go` says so (``--go``): started and
    loaded ahead, so that it takes its port the moment the test chooses (no process start in between)."""
    proc = subprocess.Popen(
        [sys.executable, "-m", "tests.fxserver", str(path), *args, "--go"], stdin=subprocess.PIPE,
        stdout=subprocess.PIPE, stderr=subprocess.PIPE, cwd=ROOT, env=dict(os.environ, PYTHONPATH=str(ROOT)),
    )  # fmt: skip
    line = proc.stdout.readline().decode()
    assert line == "ready\n", (line, proc.stderr.read().decode() if proc.poll() is not None else "")
    return proc


def go(proc: subprocess.Popen) -> int:
    """The server of :func:`ready_server` listens: its port."""
    proc.stdin.write(b"go\n")
    proc.stdin.flush()
    line = proc.stdout.readline().decode()
    assert line.startswith("port "), (line, proc.stderr.read().decode() if proc.poll() is not None else "")
    return int(line.split()[1])


def stop(proc: subprocess.Popen | None) -> None:
    """Kill ``proc`` (if it still runs) and close its pipes."""
    if proc is None:
        return
    proc.kill()
    proc.wait()
    for pipe in (proc.stdout, proc.stderr, proc.stdin):
        if pipe is not None:
            pipe.close()


def start_live(*args: str, ping_s: float | None = None) -> subprocess.Popen:
    env = dict(os.environ, COLUMNS=COLUMNS, PYTHONPATH=str(ROOT))
    if ping_s is not None:
        env["WMRID_WS_PING_S"] = str(ping_s)
    return subprocess.Popen(
        [sys.executable, "-m", "wmrid", "live", *args], stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env
    )


def updates_until(proc: subprocess.Popen, samples: int) -> dict:
    """Read the JSON update lines of a ``wmrid live --format json`` process until one has ``samples``."""
    for line in proc.stdout:
        item = json.loads(line)
        if item["event"] == "update" and item["samples"] >= samples:
            return item
    raise AssertionError(f"the stream ended before {samples} samples: {proc.stderr.read().decode()}")


# -- the foxglove-sdk server -----------------------------------------------------------------------------------------


def test_stream_at_1khz_gives_identify_on_the_same_messages(recording):
    """The sdk's server publishes the messages at 1 kHz in real time (its subprotocol foxglove.sdk.v1): updates carry
    an estimate from the first refresh after the first message on; --idle ends the silent stream; the final result
    is identify's on the MCAP the messages came from."""
    _, rec, offline = recording
    pub = Publisher(rec)
    sender = threading.Thread(target=pub.publish, daemon=True)
    sender.start()
    try:
        run = wmrid.live(f"ws://127.0.0.1:{pub.port}", "paper", every=0.5, idle=1.0)
        items = list(run)
    finally:
        pub.stop()
    sender.join(HANG_S)
    final = items[-1]
    assert isinstance(final, wmrid.LiveResult)
    updates = items[:-1]
    assert "no data for 1 s" in final.reason
    assert final.samples == N
    assert final.failure is None
    assert final.read_from == f"the {N:,} messages received from ws://127.0.0.1:{pub.port}"
    assert final.result.source == f"ws://127.0.0.1:{pub.port}"
    with_estimate = [u for u in updates if u.parameters]
    assert len(with_estimate) >= 5  # refreshed while the messages came
    assert with_estimate[0].samples < N
    assert with_estimate[-1].parameters["m11"][0] == pytest.approx(offline.parameters["m11"][0], rel=1e-3)
    same(final.result, offline)


def test_cli_first_estimate_and_clean_close(recording, tmp_path):
    """The command line against the sdk's server in a process of its own, messages sent faster than real time: JSON
    lines, the result written by -o equal to identify's; the server shut down (a clean close) ends the source."""
    path, _, offline = recording
    server, port = start_server(path, "--speed", "4", "--hold", "2")
    out = tmp_path / "r.json"
    live = start_live(f"ws://127.0.0.1:{port}", "--robot", "paper", "--every", "0.2", "-o", str(out))
    try:
        stdout, stderr = live.communicate(timeout=HANG_S)
    finally:
        stop(server)
        stop(live)
    assert live.returncode == 0, stderr.decode()
    lines = [json.loads(line) for line in stdout.decode().splitlines()]
    assert lines[-1]["event"] == "result"
    assert lines[-1]["reason"] == f"the source ended (ws://127.0.0.1:{port}: the server closed the connection)"
    assert any(item["parameters"] for item in lines[:-1])
    same(wmrid.IdentificationResult.from_dict(json.loads(out.read_text())), offline)


def test_json_channel_by_field_paths(tmp_path):
    """A JSON-encoded channel (the sdk's schemaless JSON channel) read with --topic and --columns field paths, as
    identify reads a JSON topic of an MCAP: the result is identify's on the same values as a CSV."""
    import foxglove
    import pandas as pd
    from foxglove.websocket import ServerListener

    from wmrid.api.inputs import LogOptions

    whole = wmrid.read_log(str(SAMPLE))
    n = 3000
    subscribed = threading.Event()

    class Listener(ServerListener):
        def on_subscribe(self, client, channel) -> None:
            subscribed.set()

    context = foxglove.Context()
    server = foxglove.start_server(host="127.0.0.1", port=0, context=context, server_listener=Listener(),
                                   message_backlog_size=1 << 20)  # fmt: skip
    channel = foxglove.Channel("/wheels", message_encoding="json", context=context)

    def publish() -> None:
        subscribed.wait(HANG_S)
        for i in range(n):
            t = float(whole.t[i])
            wheel = {"vr": float(whole.eta[i, 0]), "vl": float(whole.eta[i, 1])}
            message = {"time": t, "wheel": wheel, "ur": float(whole.tau[i, 0]), "ul": float(whole.tau[i, 1])}
            channel.log(message, log_time=int(1e9 * (1 + t)))

    sender = threading.Thread(target=publish, daemon=True)
    sender.start()
    options = LogOptions(topic="/wheels", columns="t=time,eta_r=wheel.vr,eta_l=wheel.vl,tau_r=ur,tau_l=ul")
    try:
        final = list(wmrid.live(f"ws://127.0.0.1:{server.port}", "paper", options=options, idle=1.0, every=0.3))[-1]
    finally:
        server.stop()
    sender.join(HANG_S)
    assert final.samples == n
    path = tmp_path / "same.csv"
    pd.DataFrame({"t": whole.t[:n], "eta_r": whole.eta[:n, 0], "eta_l": whole.eta[:n, 1], "tau_r": whole.tau[:n, 0],
                  "tau_l": whole.tau[:n, 1]}).to_csv(path, index=False)  # fmt: skip
    offline = wmrid.identify(str(path), "paper")
    for name, (value, _) in offline.parameters.items():
        assert final.result.parameters[name][0] == pytest.approx(value, rel=1e-9), name


# -- robustness ----------------------------------------------------------------------------------------------------


def test_server_killed_mid_stream(recording, tmp_path):
    """The server killed (SIGKILL) mid-stream: one line naming the lost connection, exit 1, no traceback, and -o holds
    identify's result on the messages received before."""
    path, _, _ = recording
    server, port = start_server(path, "--speed", "1")
    out = tmp_path / "r.json"
    live = start_live(f"ws://127.0.0.1:{port}", "--robot", "paper", "--every", "0.2", "-o", str(out))
    try:
        updates_until(live, 1500)
        stop(server)
        stdout, stderr = live.communicate(timeout=HANG_S)
    finally:
        stop(server)
        stop(live)
    err = stderr.decode()
    assert live.returncode == 1, err
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    lost = [line for line in lines if "lost the connection" in line]
    assert len(lost) == 1, err
    assert lost[0].startswith(f"wmrid live: lost the connection to ws://127.0.0.1:{port}"), err
    assert "--reconnect" in lost[0]
    assert all(line.startswith("wmrid: ") and "warning" in line for line in lines if line not in lost), err
    saved = json.loads(out.read_text())
    assert 1500 <= saved["log"]["samples"] < N
    assert saved["parameters"]["m11"]["value"] == pytest.approx(0.787, rel=0.01)
    assert json.loads(stdout.decode().splitlines()[-1])["failure"].startswith("lost the connection")


def test_server_that_stops_answering(recording, tmp_path):
    """The server process stopped (SIGSTOP: the socket stays open, nothing answers): the client's pings go unanswered,
    one line says the server stopped answering, exit 1, the result so far written."""
    import signal

    path, _, _ = recording
    server, port = start_server(path, "--speed", "1")
    out = tmp_path / "r.json"
    # pings every 1 s (WMRID_WS_PING_S) instead of 5: the same path, found within 2 s instead of 10
    live = start_live(f"ws://127.0.0.1:{port}", "--robot", "paper", "--every", "0.2", "-o", str(out), ping_s=1.0)
    try:
        updates_until(live, 1000)
        server.send_signal(signal.SIGSTOP)
        _, stderr = live.communicate(timeout=HANG_S)
    finally:
        if server.poll() is None:
            server.send_signal(signal.SIGCONT)
        stop(server)
        stop(live)
    err = stderr.decode()
    assert live.returncode == 1, err
    assert "Traceback" not in err
    lost = [line for line in err.splitlines() if "lost the connection" in line]
    assert len(lost) == 1, err
    assert "the server stopped answering (no reply to a ping within 1 s)" in lost[0], err
    assert json.loads(out.read_text())["log"]["samples"] >= 1000


def test_reconnect_to_a_restarted_server(recording):
    """--reconnect: the server killed after 2500 messages, a new one on the same port sends messages 2000 to the end
    (500 again): the run goes on, says what happened, and its result is identify's on the MCAP of all the messages
    (the repeated ones read as the offline reader reads them: sorted, a repeated stamp keeping the first).  The run
    is stopped once the last message came (a restarted server never ends a --reconnect run; --idle would, 4 s
    later)."""
    path, _, offline = recording
    first, port = start_server(path, "--speed", "0", "--stop", "2500")
    second, restarted = None, False
    try:
        # the new server's process is started and loaded ahead; it takes the port once the first is killed
        second = ready_server(path, "--speed", "0", "--start", "2000", "--port", str(port))
        # --idle counts while the connection is down too: 4 s covers the first three reconnection attempts (0.25,
        # 0.75 and 1.75 s after the loss) where the new server listens within milliseconds of the kill
        run = wmrid.live(f"ws://127.0.0.1:{port}", "paper", every=0.2, idle=4.0, reconnect=True)
        events = []
        final = None
        for item in run:
            if isinstance(item, wmrid.LiveResult):
                final = item
                break
            events += item.events
            if not restarted and item.samples >= 2500:
                stop(first)
                restarted = True
                assert go(second) == port
            elif restarted and item.samples >= N:
                run.stop("the last message came")
    finally:
        stop(first)
        stop(second)
    assert final is not None
    assert final.failure is None
    assert final.reason == "the last message came"
    assert final.samples == N  # the 500 sent again are older than what came: dropped live
    assert any(e.startswith(f"lost the connection to ws://127.0.0.1:{port}") for e in events), events
    assert f"reconnected to ws://127.0.0.1:{port}" in events
    assert final.result.log_info.samples == N
    for name, (value, _) in offline.parameters.items():
        assert final.result.parameters[name][0] == pytest.approx(value, rel=1e-9), name


def test_reconnect_waits_for_a_server_not_started_yet(recording):
    """--reconnect and no server yet: the run waits (saying so) and follows the server once it starts."""
    import socket

    path, _, _ = recording
    with socket.socket() as sock:  # a free port, released for the server
        sock.bind(("127.0.0.1", 0))
        port = sock.getsockname()[1]
    server = ready_server(path, "--speed", "0", "--stop", "2000", "--port", str(port))  # loaded, not listening
    # --idle: 3 s covers the reconnection attempts 0.25, 0.75 and 1.75 s after the first; the server listens as the
    # run starts.  The run is stopped once the 2000 messages came (as --idle would, 3 s later).
    run = wmrid.live(f"ws://127.0.0.1:{port}", "paper", every=0.2, idle=3.0, reconnect=True)
    items = []
    try:
        assert go(server) == port
        for item in run:
            items.append(item)
            if isinstance(item, wmrid.LiveUpdate) and item.samples >= 2000:
                run.stop("the last message came")
    finally:
        stop(server)
    assert items[-1].reason == "the last message came"
    events = [e for u in items[:-1] for e in u.events]
    assert events[0] == f"ws://127.0.0.1:{port}: not answering yet; retrying (reconnect=True)"
    assert f"reconnected to ws://127.0.0.1:{port}" in events
    assert items[-1].samples == 2000


class RawServer:
    """A WebSocket server (the websockets package) that speaks the Foxglove protocol to one client as ``script`` says:
    serverInfo and an advertise of ``rec``'s channel, then, once subscribed, ``good`` messages and ``frames`` (raw
    frames sent as they are), then it closes with ``code``."""

    def __init__(self, rec, good: int, frames: list[bytes | str], code: int = 1000,
                 subprotocol: str = "foxglove.websocket.v1") -> None:  # fmt: skip
        from websockets.sync.server import serve

        def handler(ws) -> None:
            ws.send(json.dumps({"op": "serverInfo", "name": "raw", "capabilities": [], "sessionId": "1"}))
            ws.send(json.dumps({"op": "status", "level": 1, "message": "a warning from the server"}))
            ws.send(json.dumps({"op": "advertise", "channels": [{
                "id": 7, "topic": rec.topic, "encoding": rec.encoding, "schemaName": rec.schema_name,
                "schema": rec.schema.decode(),
            }]}))  # fmt: skip
            sub = json.loads(ws.recv(timeout=HANG_S))
            assert sub["op"] == "subscribe"
            sid = sub["subscriptions"][0]["id"]
            for stamp, data in rec.messages[:good]:
                ws.send(struct.pack("<BIQ", 1, sid, stamp) + data)
            for frame in frames:
                ws.send(frame)
            time.sleep(0.5)
            ws.close(code)

        self.server = serve(handler, "127.0.0.1", 0, subprotocols=[subprotocol])
        self.port = self.server.socket.getsockname()[1]
        self.thread = threading.Thread(target=self.server.serve_forever, daemon=True)
        self.thread.start()

    def stop(self) -> None:
        self.server.shutdown()
        self.thread.join(HANG_S)


@pytest.mark.parametrize(
    ("frame", "what"),
    [(b"\x01\x00\x00", "a message frame of 3 bytes"), ("not json", "not JSON"), ('{"no": "op"}', "without an 'op'")],
    ids=["short-binary", "text-not-json", "no-op"],
)
def test_malformed_frame_keeps_the_result(recording, tmp_path, frame, what):
    """A malformed frame after 3000 good messages (subprotocol foxglove.websocket.v1, as foxglove_bridge): one line
    naming the server and the frame, exit 1, the result on the 3000 messages written by -o."""
    from tests.cliutil import wmrid as run

    _, rec, _ = recording
    server = RawServer(rec, 3000, [frame])
    out = tmp_path / "r.json"
    try:
        proc = run("live", f"ws://127.0.0.1:{server.port}", "--robot", "paper", "--format", "json", "-o", str(out))
    finally:
        server.stop()
    err = proc.stderr.decode()
    assert proc.returncode == 1, err
    assert "Traceback" not in err
    assert f"wmrid live: ws://127.0.0.1:{server.port}: the server says (warning): a warning from the server" in err
    last = err.strip().splitlines()[-1]
    assert f"ws://127.0.0.1:{server.port}: a malformed frame from the server" in last, err
    assert what in last, err
    assert json.loads(out.read_text())["log"]["samples"] == 3000


def test_clean_close_and_unknown_ops(recording):
    """Frames a client may ignore (an unknown op, a time message, a message of no subscription) are ignored; a clean
    close (code 1000) ends the source; the result is identify's on the messages sent."""
    _, rec, _ = recording
    ignored = [json.dumps({"op": "somethingNew"}), struct.pack("<BQ", 2, 123), struct.pack("<BIQ", 1, 99, 1) + b"x"]
    server = RawServer(rec, 4000, ignored)
    try:
        final = list(wmrid.live(f"ws://127.0.0.1:{server.port}", "paper", every=0.2))[-1]
    finally:
        server.stop()
    assert final.failure is None
    assert "the server closed the connection (code 1000)" in final.reason
    assert final.samples == 4000


def test_refused_and_unreachable_are_one_line():
    """No server at the address: one line naming it and the fix, exit 1; not a WebSocket address: exit 2."""
    from tests.cliutil import wmrid as run

    for args, code, needle in (
        (["ws://127.0.0.1:9"], 1, "ws://127.0.0.1:9: cannot connect (Connection refused); start foxglove_bridge"),
        (["ws://:8765"], 2, "not a WebSocket address"),
    ):
        proc = run("live", *args)
        err = proc.stderr.decode()
        assert proc.returncode == code, err
        assert "Traceback" not in err
        assert len(err.strip().splitlines()) == 1, err
        assert needle in err, err


def test_the_ping_time_comes_from_the_environment_when_set(monkeypatch):
    from wmrid.core.errors import UsageError
    from wmrid.io.live.ws_source import PING_S, ping_seconds

    monkeypatch.delenv("WMRID_WS_PING_S", raising=False)
    assert ping_seconds() == PING_S == 5.0
    monkeypatch.setenv("WMRID_WS_PING_S", "12.5")
    assert ping_seconds() == 12.5
    for bad in ("0", "-1", "nan", "soon"):
        monkeypatch.setenv("WMRID_WS_PING_S", bad)
        with pytest.raises(UsageError, match=f"WMRID_WS_PING_S must be a number of seconds > 0, got '{bad}'"):
            ping_seconds()
