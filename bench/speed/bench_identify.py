"""Headline benchmark: end-to-end ``wmrid identify`` on a long 1 kHz Parquet log.

Measures, for each ``--duration`` (default one hour = 3.6 M samples):

(a) ``wmrid identify LOG --robot paper --format json`` as a subprocess: one untimed warm-up run (so
    numba's on-disk cache is populated and the OS file cache is warm), then ``--repeat`` timed runs
    under ``/usr/bin/time -v``; wall time (min, median), samples/s end-to-end (process start, imports,
    reading, replay and reporting included) and peak RSS.  The JSON output is checked to parse and to
    hold ``parameters``.
(b) in-process, through the public API: ``wmrid.read_log`` of the file (and pyarrow's bare read of it, for
    scale); ``wmrid.identify(log, "paper")`` on the log in memory (the whole call: the observer's passes, covariance,
    fit, checks and diagnostics; numba's compile or cache load excluded by a warm-up call on a short slice); and,
    from the progress the call reports after each piece of 262,144 samples, the observer's replay rate in its first
    pass (samples/s between its first and its last piece) and the number of passes.  (Before the bench used only the
    public API it timed the replay kernel alone, called with settings built by hand; the rate from the progress
    measures the same kernel inside the call.  A pass of one piece, a log of at most 262,144 samples (4.4 min at
    1 kHz), gives no rate.)

The log is simulated (seed ``--seed``) into bench/out/ the first time; later runs reuse it.

    python3 bench/speed/bench_identify.py                         # 1 h log, 3 runs
    python3 bench/speed/bench_identify.py --duration 3600 14400   # also 4 h (memory comparison)
    python3 bench/speed/bench_identify.py --duration 60 --repeat 1   # a quick check that it runs

Figures: printed, and written to bench/results/bench_identify.json.
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # bench/: the shared module _common
from _common import fmt_rss, median, run_timed, sim_log, wmrid_cmd, write_results

TARGET = 1_000_000  # samples/s end-to-end


def end_to_end(path, n: int, repeat: int) -> dict:
    cmd = [*wmrid_cmd(), "identify", str(path), "--robot", "paper", "--format", "json"]
    run_timed(cmd)  # warm-up: numba cache, page cache
    runs = [run_timed(cmd) for _ in range(repeat)]
    for r in runs:
        out = json.loads(r.stdout)
        if "parameters" not in out:
            raise SystemExit("identify JSON has no 'parameters'")
    walls = [r.wall for r in runs]
    rss = [r.rss_mb for r in runs if r.rss_mb is not None]
    return {
        "cmd": cmd,
        "min": min(walls),
        "median": median(walls),
        "rate": n / median(walls),
        "rss": max(rss) if rss else None,
    }


def observer_passes(ticks: list[tuple[float, int, int]]) -> list[list[tuple[float, int, int]]]:
    """The progress ticks (time, samples done, samples) of one call split into the observer's passes (each pass
    counts its samples from the start again)."""
    passes: list[list[tuple[float, int, int]]] = []
    for tick in ticks:
        if not passes or tick[1] <= passes[-1][-1][1]:
            passes.append([])
        passes[-1].append(tick)
    return passes


def in_process(path, repeat: int) -> dict:
    import pyarrow.parquet as pq

    import wmrid

    def best(fn) -> float:  # median wall time of fn() over `repeat` calls
        times = []
        for _ in range(repeat):
            t0 = time.perf_counter()
            fn()
            times.append(time.perf_counter() - t0)
        return median(times)

    log = wmrid.read_log(str(path))
    read = best(lambda: wmrid.read_log(str(path)))
    bare = best(lambda: pq.read_table(str(path)))  # the file's columns into memory, nothing else
    # warm-up on a short slice: JIT compile / numba cache load, not timed
    short = wmrid.WheelLog(t=log.t[:20000], eta=log.eta[:20000], tau=log.tau[:20000], source="warm-up")
    wmrid.identify(short, "paper")
    times, rates, passes, result = [], [], [], None
    for _ in range(repeat):
        ticks: list[tuple[float, int, int]] = []

        def tick(done: int, n: int, ticks: list = ticks) -> None:
            ticks.append((time.perf_counter(), done, n))

        t0 = time.perf_counter()
        result = wmrid.identify(log, "paper", progress=tick)
        times.append(time.perf_counter() - t0)
        runs = observer_passes(ticks)
        passes.append(len(runs))
        first = runs[0] if runs else []
        if len(first) >= 2 and first[-1][0] > first[0][0]:
            rates.append((first[-1][1] - first[0][1]) / (first[-1][0] - first[0][0]))
    rate = median(rates) if rates else None
    return {
        "form": result.form.kind, "k": result.observer_settings.k, "friction": result.form.friction,
        "read": read, "pyarrow_read": bare, "identify": median(times), "observer_passes": max(passes),
        "replay_rate": rate, "replay": None if rate is None else len(log.t) / rate,
    }  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, nargs="+", default=[3600.0], help="log length(s), s (default 3600)")
    ap.add_argument("--rate", type=float, default=1000.0, help="log rate, Hz (default 1000)")
    ap.add_argument("--seed", type=int, default=1, help="simulation seed (default 1)")
    ap.add_argument("--repeat", type=int, default=3, help="timed runs after the warm-up (default 3)")
    ap.add_argument("--skip-in-process", action="store_true", help="skip part (b)")
    args = ap.parse_args()

    rows = []
    for duration in args.duration:
        path = sim_log(duration, args.rate, args.seed)
        n = int(duration * args.rate + 1e-9) + 1
        e2e = end_to_end(path, n, args.repeat)
        ip = None if args.skip_in_process else in_process(path, args.repeat)
        rows.append((duration, n, e2e, ip))

    e2e0, ip0 = rows[0][2], rows[0][3]
    print(f"\ncommand: {' '.join(e2e0['cmd'])}")
    rss_note = "peak RSS from /usr/bin/time -v" if e2e0["rss"] is not None else "no /usr/bin/time: no RSS"
    print(f"1 warm-up run (populates numba's on-disk cache), then {args.repeat} timed runs; {rss_note}")
    print(
        f"\n{'log':>7} {'samples':>11} | {'e2e min s':>9} {'e2e med s':>9} {'e2e samp/s':>11} {'peak MB':>8} |"
        f" {'read s':>6} {'replay s':>8} {'replay samp/s':>13} {'identify() s':>12}"
    )
    for duration, n, e2e, ip in rows:
        tail = ""
        if ip:
            replay = "n/a" if ip["replay"] is None else f"{ip['replay']:.2f}"
            rate = "n/a" if ip["replay_rate"] is None else f"{ip['replay_rate']:,.0f}"
            tail = f" {ip['read']:6.2f} {replay:>8} {rate:>13} {ip['identify']:12.2f}"
        print(
            f"{duration / 3600:>6.2f}h {n:>11,} | {e2e['min']:9.2f} {e2e['median']:9.2f} {e2e['rate']:11,.0f}"
            f" {fmt_rss(e2e['rss']):>8} |{tail}"
        )
    if ip0:
        print(
            f"(in-process medians of {args.repeat}, JIT excluded: read = wmrid.read_log; identify() = "
            f"wmrid.identify(log, 'paper'), {ip0['observer_passes']} observer pass(es); replay = one pass at the "
            f"first pass's rate, from the call's progress; form '{ip0['form']}', k = {ip0['k']:g}, friction "
            f"{ip0['friction']})"
        )
        print(
            f"end to end / bare pyarrow read of the file: {e2e0['median'] / ip0['pyarrow_read']:.2f}x "
            f"(pyarrow.parquet.read_table {ip0['pyarrow_read']:.3f} s)"
        )
    print(f"\ntarget: end-to-end >= {TARGET:,} samples/s")
    for duration, _, e2e, _ in rows:
        print(f"  {duration:g} s log: {e2e['rate']:,.0f} samples/s -> {'MET' if e2e['rate'] >= TARGET else 'NOT met'}")
    write_results({
        "target_samples_per_s": TARGET,
        "rows": [{"duration_s": d, "samples": n, "end_to_end": {k: v for k, v in e.items() if k != "cmd"},
                  "in_process": ip} for d, n, e, ip in rows],
    })  # fmt: skip


if __name__ == "__main__":
    main()
