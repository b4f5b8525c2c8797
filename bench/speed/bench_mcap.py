"""MCAP benchmark: ``wmrid`` on a 10-minute 1 kHz ROS 2 JointState MCAP against the generic decoder.

The log (``--duration`` s, default 600 = 600,001 messages) is a noisy ``paper`` simulation (``wmrid.simulate``'s
default trajectory at 1 kHz, seed ``--seed``) written by ``wmrid.write_simulation`` as ``sensor_msgs/msg/JointState``
only (no odometry), zstd chunks (``_common.mcap_log``).  It is made once into bench/out/ and reused.  Measured:

(a) generic decode: a ``python -c`` subprocess that opens the file with ``mcap.reader.make_reader`` and
    ``mcap_ros2.decoder.DecoderFactory`` and iterates ``iter_decoded_messages()``, touching each
    ``ros_msg.velocity``; wall time including process start and imports (as for the CLI), messages/s.
    ``--decode-repeat`` runs (default 1; it is slow), median reported.
(b) ``wmrid identify LOG --robot paper --format json`` as a subprocess: one untimed warm-up run
    (numba's on-disk cache, page cache), then ``--repeat`` timed runs under ``/usr/bin/time -v`` when
    available; wall min/median, samples/s, peak RSS.  The JSON must parse; the largest relative error of
    m11, m12, m22, Vc against the simulation's truth (the paper robot's CAD set, the result's "reference") is
    printed.
(c) ``wmrid inspect LOG --format json`` as a subprocess (same warm-up/repeat scheme), wall time.
(d) in-process ``wmrid.read_log(path)``, median of ``--repeat`` calls, after one warm-up call on a small MCAP (so
    JIT compile / numba cache load is excluded).  (Before the bench used only the public API this timed the MCAP
    reader alone, without the checks and the conversion to a WheelLog that read_log adds.)

Target: end-to-end identify <= 0.15 x the generic decode time (medians).

    python3 bench/speed/bench_mcap.py
    python3 bench/speed/bench_mcap.py --repeat 5 --decode-repeat 2
    python3 bench/speed/bench_mcap.py --duration 30 --repeat 1   # a quick check that it runs

Figures: printed, and written to bench/results/bench_mcap.json.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # bench/: the shared module _common
from _common import ROOT, fmt_rss, mcap_log, median, run_timed, wmrid_cmd, write_results

RATIO_TARGET = 0.15  # identify end-to-end / generic decode

DECODE_SRC = """\
import sys
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
n = 0
with open(sys.argv[1], "rb") as f:
    reader = make_reader(f, decoder_factories=[DecoderFactory()])
    for schema, channel, message, ros_msg in reader.iter_decoded_messages():
        v = ros_msg.velocity[0]
        n += 1
print(n)
"""


def generic_decode(path, repeat: int) -> dict:
    cmd = [sys.executable, "-c", DECODE_SRC, str(path)]
    runs = [run_timed(cmd) for _ in range(repeat)]
    counts = {int(r.stdout.strip()) for r in runs}
    if len(counts) != 1:
        raise SystemExit(f"generic decoder message counts differ between runs: {sorted(counts)}")
    walls = [r.wall for r in runs]
    return {"n": counts.pop(), "min": min(walls), "median": median(walls), "rss": _max_rss(runs)}


def _max_rss(runs) -> float | None:
    rss = [r.rss_mb for r in runs if r.rss_mb is not None]
    return max(rss) if rss else None


def cli(args_: list[str], repeat: int) -> tuple[dict, list]:
    cmd = [*wmrid_cmd(), *args_]
    run_timed(cmd)  # warm-up: numba cache, page cache
    runs = [run_timed(cmd) for _ in range(repeat)]
    walls = [r.wall for r in runs]
    return {"cmd": cmd, "min": min(walls), "median": median(walls), "rss": _max_rss(runs)}, runs


def max_rel_error(runs) -> tuple[float, str]:
    """The largest relative error of m11, m12, m22, Vc over the runs, against the CAD set (the simulation's truth)
    that each result holds as its "reference"."""
    worst, worst_name = 0.0, ""
    for r in runs:
        out = json.loads(r.stdout)
        params, truth = out["parameters"], out["reference"]
        for name in ("m11", "m12", "m22", "Vc"):
            err = abs(params[name]["value"] - truth[name]) / abs(truth[name])
            if err >= worst:
                worst, worst_name = err, name
    return worst, worst_name


def in_process_read(path, seed: int, repeat: int) -> float:
    import wmrid

    small = mcap_log(5.0, seed)
    wmrid.read_log(str(small))  # warm-up: JIT compile / numba cache load, not timed
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        wmrid.read_log(str(path))
        times.append(time.perf_counter() - t0)
    return median(times)


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=600.0, help="log length, s (default 600)")
    ap.add_argument("--seed", type=int, default=1, help="simulation seed (default 1)")
    ap.add_argument("--repeat", type=int, default=3, help="timed CLI runs after the warm-up (default 3)")
    ap.add_argument("--decode-repeat", type=int, default=1, help="generic decoder runs (default 1)")
    args = ap.parse_args()

    path = mcap_log(args.duration, args.seed)
    size_mb = path.stat().st_size / 1e6

    dec = generic_decode(path, args.decode_repeat)
    n = dec["n"]
    ident, ident_runs = cli(["identify", str(path), "--robot", "paper", "--format", "json"], args.repeat)
    err, err_name = max_rel_error(ident_runs)
    insp, _ = cli(["inspect", str(path), "--format", "json"], args.repeat)
    read = in_process_read(path, args.seed, args.repeat)

    print(f"\nlog: {path.relative_to(ROOT)} ({size_mb:.1f} MB, {n:,} JointState messages, zstd)")
    print(f"identify: {' '.join(ident['cmd'])}  (1 warm-up + {args.repeat} timed; inspect likewise)")
    print(f"\n{'step':<34} {'min s':>7} {'med s':>7} {'msg/s':>11} {'peak MB':>8}")
    rows = [
        (f"generic decode (mcap_ros2) x{args.decode_repeat}", dec),
        ("wmrid identify (e2e)", ident),
        ("wmrid inspect (e2e)", insp),
        (f"wmrid.read_log in-process x{args.repeat}", {"min": None, "median": read, "rss": None}),
    ]
    for label, d in rows:
        mn = "" if d["min"] is None else f"{d['min']:7.2f}"
        print(f"{label:<34} {mn:>7} {d['median']:7.2f} {n / d['median']:11,.0f} {fmt_rss(d['rss']):>8}")
    print(f"identify max rel. error of m11 m12 m22 Vc vs truth: {err:.2%} ({err_name})")
    ratio = ident["median"] / dec["median"]
    verdict = "MET" if ratio <= RATIO_TARGET else "NOT MET"
    print(f"\ntarget: identify end-to-end <= {RATIO_TARGET} x generic decode time -> ratio = {ratio:.3f} ({verdict})")
    write_results({
        "log": {"path": str(path.relative_to(ROOT)), "megabytes": size_mb, "messages": n},
        "generic_decode": dec, "identify": {k: v for k, v in ident.items() if k != "cmd"},
        "inspect": {k: v for k, v in insp.items() if k != "cmd"}, "read_log_in_process_s": read,
        "max_relative_error": {"value": err, "parameter": err_name},
        "ratio_identify_to_decode": ratio, "ratio_target": RATIO_TARGET, "met": ratio <= RATIO_TARGET,
    })  # fmt: skip


if __name__ == "__main__":
    main()
