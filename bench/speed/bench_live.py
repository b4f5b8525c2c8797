"""``wmrid live`` at 1 kHz in real time: the time from the first message to the first estimate, the latency from a
message's arrival to the first update that includes it (median, 99th percentile), the CPU the process uses while it
follows (from /proc, between the first update and the end of the stream), its peak RSS, and the final result against
``wmrid identify`` on the same messages.  Written as JSON to bench/results/bench_live.json (``--source csv``:
bench_live-csv.json; faster than real time, ``--speed 20``: bench_live-x20.json).

Sources: ``ws`` (default) -- the foxglove-sdk WebSocket server (tests/fxserver.py) in this process publishing the
bundled paper-scenario log as JointState CDR messages, ``wmrid live ws://127.0.0.1:PORT`` in a process of its own;
``csv`` -- rows appended to a CSV file every 50 ms.  The message's arrival is when this process sent it (the server
is on the same machine; the client's receipt follows within a millisecond); the update's time is when this process
read its JSON line.  ``--speed 0`` sends as fast as the server can (memory over a long stream: ``--seconds 28800``
is 8 hours of log).

    python3 bench/speed/bench_live.py [--source ws|csv] [--seconds 20] [--every 1] [--speed 1]
    python3 bench/speed/bench_live.py --seconds 5   # a quick check that it runs
"""

from __future__ import annotations

import argparse
import json
import os
import struct
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # bench/: the shared module _common
from _common import ROOT, write_log, write_results

SAMPLE = ROOT / "sample_logs" / "paper_sinusoid.csv"
sys.path.insert(0, str(ROOT))  # tests/fxserver.py: the Foxglove server of the tests


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of process ``pid``, s (Linux /proc)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def peak_rss_mb(pid: int) -> float:
    """Peak resident set size of process ``pid``, MB (VmHWM)."""
    for line in Path(f"/proc/{pid}/status").read_text().splitlines():
        if line.startswith("VmHWM:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def frame(seconds: float):
    """The first ``seconds`` of the bundled log, repeated (time running on) when longer."""
    import pandas as pd

    import wmrid

    log = wmrid.read_log(str(SAMPLE))
    n = round(seconds * 1000)
    idx = np.arange(n) % len(log.t)
    t = np.arange(n) * 1e-3
    return pd.DataFrame({"t": t, "eta_r": log.eta[idx, 0], "eta_l": log.eta[idx, 1], "tau_r": log.tau[idx, 0],
                         "tau_l": log.tau[idx, 1]})  # fmt: skip


class Looped:
    """Message i of a stream that repeats ``messages`` (log time ns, JointState CDR), each period's stamps (log time and
    header) moved on by the period's length: an hour or eight of 1 kHz messages without holding them."""

    def __init__(self, messages: list[tuple[int, bytes]]) -> None:
        self.messages = messages
        stamps = [m[0] for m in messages]
        step = (stamps[-1] - stamps[0]) // max(len(stamps) - 1, 1)  # ns between messages
        self.period_ns = stamps[-1] - stamps[0] + step

    def message(self, i: int) -> tuple[int, bytes]:
        k, j = divmod(i, len(self.messages))
        stamp, payload = self.messages[j]
        if k == 0:
            return stamp, payload
        shift = k * self.period_ns
        data = bytearray(payload)
        assert data[:4] == b"\x00\x01\x00\x00", "little-endian CDR (its header stamp read at bytes 4..12)"
        sec, nanosec = struct.unpack_from("<iI", data, 4)  # after CDR's 4-byte encapsulation: header.stamp
        total = sec * 1_000_000_000 + nanosec + shift
        struct.pack_into("<iI", data, 4, total // 1_000_000_000, total % 1_000_000_000)
        return stamp + shift, bytes(data)

    def write(self, path: Path, rec, n: int) -> None:
        """The first ``n`` messages as an MCAP (zstd chunks), for ``wmrid identify`` to compare with."""
        from mcap.writer import Writer

        with open(path, "wb") as fh:
            writer = Writer(fh)
            writer.start(profile="ros2", library="bench_live")
            sid = writer.register_schema(name=rec.schema_name, encoding=rec.schema_encoding, data=rec.schema)
            cid = writer.register_channel(topic=rec.topic, message_encoding=rec.encoding, schema_id=sid)
            for i in range(n):
                stamp, payload = self.message(i)
                writer.add_message(cid, log_time=stamp, data=payload, publish_time=stamp, sequence=i)
            writer.finish()


class Sender:
    """Sends the messages (by ``send(i)``) paced at 1 kHz x speed, recording each one's send time."""

    def __init__(self, n: int, speed: float, send, block: int = 10) -> None:
        self.sent = np.full(n, np.nan)
        self.n, self.speed, self.send, self.block = n, speed, send, block

    def run(self) -> None:
        t0 = time.monotonic()
        for i in range(0, self.n, self.block):
            if self.speed > 0:
                wait = t0 + i / 1000.0 / self.speed - time.monotonic()
                if wait > 0:
                    time.sleep(wait)
            self.send(i, min(i + self.block, self.n))
            self.sent[i : i + self.block] = time.monotonic()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--source", choices=("ws", "csv"), default="ws")
    parser.add_argument("--seconds", type=float, default=20.0, help="log time streamed, s")
    parser.add_argument("--every", type=float, default=1.0, help="wmrid live --every, s")
    parser.add_argument("--speed", type=float, default=1.0, help="times real time (0: as fast as possible)")
    args = parser.parse_args()
    import wmrid

    n = round(args.seconds * 1000)
    with tempfile.TemporaryDirectory() as tmp:
        env = dict(os.environ, PYTHONPATH=str(ROOT))
        live_args = ["--robot", "paper", "--every", str(args.every), "--idle", "2", "--format", "json",
                     "-o", str(Path(tmp) / "r.json")]  # fmt: skip
        if args.source == "ws":
            from tests.fxserver import Publisher, read_recording

            # one period (the bundled log's length) encoded once; the stream repeats it with its stamps moved on
            period = Path(tmp) / "period.mcap"
            truth = json.loads(SAMPLE.with_name(SAMPLE.name + ".truth.json").read_text())  # the sample's, repeated
            write_log(frame(min(args.seconds, len(wmrid.read_log(str(SAMPLE)).t) / 1000.0)), period, truth)
            pub = Publisher(read_recording(str(period)))
            looped = Looped(pub.rec.messages)

            def send(a: int, b: int) -> None:
                for i in range(a, b):
                    stamp, payload = looped.message(i)
                    pub.channel.log(payload, log_time=stamp)

            ref = Path(tmp) / "run.mcap"
            looped.write(ref, pub.rec, n)
            target = f"ws://127.0.0.1:{pub.port}"
        else:
            ref = Path(tmp) / "run.csv"
            data = frame(args.seconds)
            lines = data.to_csv(index=False).encode().splitlines(keepends=True)
            ref.write_bytes(lines[0])
            fh = open(ref, "ab")  # noqa: SIM115 - closed below

            def send(a: int, b: int) -> None:
                fh.write(b"".join(lines[1 + a : 1 + b]))
                fh.flush()

            target = str(ref)
        proc = subprocess.Popen([sys.executable, "-m", "wmrid", "live", target, *live_args], stdout=subprocess.PIPE,
                                stderr=subprocess.PIPE, env=env)  # fmt: skip
        if args.source == "ws":
            if not pub.subscribed.wait(120):
                raise SystemExit(f"wmrid live did not subscribe: {proc.stderr.read().decode()}")
        else:
            time.sleep(6.0)  # the process starts and loads its kernels before the robot drives
        sender = Sender(n, args.speed, send, block=10 if args.source == "ws" else 50)
        thread = threading.Thread(target=sender.run)
        thread.start()
        updates = []  # (time read, samples, has estimate)
        started = time.monotonic()
        cpu0 = t_cpu0 = cpu = rss_stream = None
        final = None
        for line in proc.stdout:
            now = time.monotonic()
            item = json.loads(line)
            if item["event"] == "update":
                updates.append((now, item["samples"], bool(item["parameters"])))
                if cpu0 is None and item["parameters"]:
                    cpu0, t_cpu0 = cpu_seconds(proc.pid), now
                if not thread.is_alive() and cpu is None and cpu0 is not None and now > t_cpu0 + 0.5:
                    cpu = (cpu_seconds(proc.pid) - cpu0) / (now - t_cpu0)
                    rss_stream = peak_rss_mb(proc.pid)
            elif item["event"] == "result":
                final = item
                rss = peak_rss_mb(proc.pid)
                rss_stream = rss_stream if rss_stream is not None else rss
        proc.wait()
        thread.join()
        if args.source == "ws":
            pub.stop()
        else:
            fh.close()
        if proc.returncode != 0 or final is None:
            raise SystemExit(f"wmrid live failed: {proc.stderr.read().decode()}")
        offline = wmrid.identify(str(ref), "paper")
    worst = max(abs(final["result"]["parameters"][k]["value"] - v) / abs(v) for k, (v, _) in offline.parameters.items())
    times = np.array([u[0] for u in updates])
    counts = np.array([u[1] for u in updates])
    # message i is in the first update whose count exceeds i
    first_update = np.searchsorted(counts, np.arange(n) + 1, side="left")
    ok = first_update < len(updates)
    latency = times[first_update[ok]] - sender.sent[ok]
    first_estimate = next(t for t, _, has in updates if has) - sender.sent[0]
    out = {
        "source": args.source, "log_seconds": args.seconds, "rate_hz": 1000.0, "speed": args.speed,
        "every_s": args.every, "messages": n, "updates": len(updates),
        "first_estimate_after_first_message_s": first_estimate,
        "latency_s": {"median": float(np.median(latency)), "p99": float(np.percentile(latency, 99)),
                      "max": float(latency.max()), "messages": int(ok.sum())},
        "cpu_fraction_of_one_core": cpu, "peak_rss_mb_while_streaming": rss_stream,
        "peak_rss_mb_with_final_identify": rss, "seconds_wall": time.monotonic() - started,
        "final_vs_identify_largest_relative_difference": worst, "samples": final["samples"],
    }  # fmt: skip
    print(json.dumps(out, indent=2))
    # a run faster than real time (the long-stream memory run, --speed 20) keeps its own file: bench_live-x20.json
    faster = None if args.speed == 1 else ("asap" if args.speed == 0 else f"x{args.speed:g}")
    write_results(out, variant="-".join(v for v in (None if args.source == "ws" else args.source, faster) if v) or None)


if __name__ == "__main__":
    main()
