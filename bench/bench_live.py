"""``wmrid live`` on a CSV written in real time at 1 kHz (the bundled paper-scenario log, rows appended every 50 ms):
the time from the first row written to the first estimate printed, the CPU the process uses while it follows (from
/proc, between the first update and the end of the stream), and the final result against ``wmrid identify`` on the
finished file.

    python3 bench/bench_live.py [--seconds 20] [--every 1]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import threading
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
SAMPLE = ROOT / "sample_logs" / "paper_sinusoid.csv"


def cpu_seconds(pid: int) -> float:
    """User + system CPU time of process ``pid``, s (Linux /proc)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--seconds", type=float, default=20.0, help="log time streamed in real time, s")
    parser.add_argument("--every", type=float, default=1.0, help="wmrid live --every, s")
    args = parser.parse_args()
    lines = SAMPLE.read_bytes().splitlines(keepends=True)
    rows = lines[1 : 1 + int(args.seconds * 1000)]
    with tempfile.TemporaryDirectory() as tmp:
        path = Path(tmp) / "run.csv"
        path.write_bytes(lines[0])
        env = dict(os.environ, PYTHONPATH=str(ROOT))
        cmd = [sys.executable, "-m", "wmrid", "live", str(path), "--robot", "paper", "--every", str(args.every),
               "--idle", "1", "--format", "json", "-o", str(Path(tmp) / "r.json")]  # fmt: skip
        proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, env=env)
        time.sleep(6.0)  # the process starts and loads its kernels before the robot drives
        started = {}

        def write() -> None:
            with open(path, "ab") as fh:
                for i in range(0, len(rows), 50):
                    if i == 0:
                        started["t"] = time.monotonic()
                    fh.write(b"".join(rows[i : i + 50]))
                    fh.flush()
                    time.sleep(max(0.0, started["t"] + (i + 50) / 1000 - time.monotonic()))
            started["end"] = time.monotonic()

        writer = threading.Thread(target=write)
        writer.start()
        first = cpu0 = t_cpu0 = None
        updates = 0
        final = None
        for line in proc.stdout:
            item = json.loads(line)
            if item["event"] == "update" and item["parameters"] and first is None:
                first = time.monotonic() - started["t"]
                cpu0, t_cpu0 = cpu_seconds(proc.pid), time.monotonic()
            if item["event"] == "update":
                updates += 1
                if "end" in started and cpu0 is not None and "cpu" not in started:
                    started["cpu"] = (cpu_seconds(proc.pid) - cpu0) / (time.monotonic() - t_cpu0)
            else:
                final = item
        proc.wait()
        writer.join()
        if proc.returncode != 0:
            raise SystemExit(f"wmrid live failed: {proc.stderr.read().decode()}")
        import wmrid

        offline = wmrid.identify(str(path), "paper")
        worst = max(
            abs(final["result"]["parameters"][n]["value"] - v) / abs(v) for n, (v, _) in offline.parameters.items()
        )
    print(f"streamed {args.seconds:g} s at 1 kHz in real time; {updates} updates (--every {args.every:g})")
    print(f"first row written -> first estimate printed: {first:.3f} s")
    print(f"CPU while following: {100 * started.get('cpu', float('nan')):.1f} % of one core")
    print(f"final result vs wmrid identify on the finished file: largest relative difference {worst:.3g}")


if __name__ == "__main__":
    main()
