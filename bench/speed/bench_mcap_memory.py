"""MCAP memory benchmark: peak RSS of ``wmrid identify BAG`` for a 1 h and a 4 h 1 kHz ROS 2 bag.

The bags (``--short`` and ``--long`` s, default 3600 and 14400 s: 3.6 M and 14.4 M
``sensor_msgs/msg/JointState`` messages, zstd chunks, no odometry) are noisy ``paper`` sinusoid
simulations (``_common.mcap_log``: ``wmrid.simulate``, seed ``--seed``, written by ``wmrid.write_simulation``), made
once into bench/out/ and reused.

For each bag, ``wmrid identify BAG --robot paper --format json`` runs as a subprocess under
``/usr/bin/time -v`` (one untimed warm-up for numba's cache and the page cache, then ``--repeat`` runs):
wall time and peak RSS (the largest of the runs).  The JSON must parse.  Printed: both figures and the
ratio long/short of the peak RSS.  Target: ratio <= 1.5 (the MCAP is decoded piece by piece, so memory
should not grow with the length of the recording).

    python3 bench/speed/bench_mcap_memory.py
    python3 bench/speed/bench_mcap_memory.py --short 600 --long 2400 --repeat 1
    python3 bench/speed/bench_mcap_memory.py --short 30 --long 120 --repeat 1   # a quick check that it runs

Figures: printed, and written to bench/results/bench_mcap_memory.json.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # bench/: the shared module _common
from _common import GNU_TIME, ROOT, fmt_rss, mcap_log, median, run_timed, wmrid_cmd, write_results

RATIO_TARGET = 1.5  # peak RSS long / short


def measure(path: Path, repeat: int) -> dict:
    cmd = [*wmrid_cmd(), "identify", str(path), "--robot", "paper", "--format", "json"]
    run_timed(cmd)  # warm-up: numba cache, page cache
    runs = [run_timed(cmd) for _ in range(repeat)]
    for r in runs:
        json.loads(r.stdout)  # must parse
    rss = [r.rss_mb for r in runs if r.rss_mb is not None]
    walls = [r.wall for r in runs]
    return {"wall": median(walls), "rss": max(rss) if rss else None, "json": json.loads(runs[-1].stdout)}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--short", type=float, default=3600.0, help="short bag, s (default 3600)")
    ap.add_argument("--long", type=float, default=14400.0, help="long bag, s (default 14400)")
    ap.add_argument("--seed", type=int, default=1, help="simulation seed (default 1)")
    ap.add_argument("--repeat", type=int, default=1, help="measured runs after the warm-up (default 1)")
    args = ap.parse_args()
    if GNU_TIME is None:
        raise SystemExit("/usr/bin/time is needed for peak RSS (apt-get install time)")

    rows = []
    for duration in (args.short, args.long):
        path = mcap_log(duration, args.seed)
        result = measure(path, args.repeat)
        rows.append((duration, path, result))

    print(f"\nwmrid identify BAG --robot paper --format json  (1 warm-up + {args.repeat} measured)")
    print(f"{'bag':<44} {'MB':>8} {'messages':>12} {'wall s':>8} {'peak RSS MB':>12}")
    for duration, path, r in rows:
        size = path.stat().st_size / 1e6
        n = round(duration * 1000) + 1
        print(f"{path.relative_to(ROOT)!s:<44} {size:8.1f} {n:12,} {r['wall']:8.1f} {fmt_rss(r['rss']):>12}")
    short, long_ = rows[0][2], rows[1][2]
    for name in ("m11", "m22", "Vc"):
        a, b = short["json"]["parameters"][name]["value"], long_["json"]["parameters"][name]["value"]
        print(f"  {name}: {a:.6g} (short)  {b:.6g} (long)")
    ratio = None
    if short["rss"] and long_["rss"]:
        ratio = long_["rss"] / short["rss"]
        verdict = "MET" if ratio <= RATIO_TARGET else "NOT MET"
        print(f"\ntarget: peak RSS long/short <= {RATIO_TARGET} -> ratio = {ratio:.3f} ({verdict})")
    write_results({
        "bags": [{"duration_s": d, "path": str(p.relative_to(ROOT)), "megabytes": p.stat().st_size / 1e6,
                  "messages": round(d * 1000) + 1, "wall_s": r["wall"], "peak_rss_mb": r["rss"],
                  "parameters": {n: r["json"]["parameters"][n]["value"] for n in ("m11", "m22", "Vc")}}
                 for d, p, r in rows],
        "ratio_peak_rss_long_to_short": ratio, "ratio_target": RATIO_TARGET,
    })  # fmt: skip


if __name__ == "__main__":
    main()
