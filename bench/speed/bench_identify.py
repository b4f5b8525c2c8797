"""Headline benchmark: end-to-end ``wmrid identify`` on a long 1 kHz Parquet log.

Measures, for each ``--duration`` (default one hour = 3.6 M samples):

(a) ``wmrid identify LOG --robot paper --format json`` as a subprocess: one untimed warm-up run (so
    numba's on-disk cache is populated and the OS file cache is warm), then ``--repeat`` timed runs
    under ``/usr/bin/time -v``; wall time (min, median), samples/s end-to-end (process start, imports,
    reading, replay and reporting included) and peak RSS.  The JSON output is checked to parse and to
    hold ``parameters``.
(b) in-process, the parts alone: ``wmrid.io.logs.read_log``; the sample-by-sample
``wmrid.estimators.observer.replay.replay``
    with settings built as ``wmrid.pipeline.identify.identify`` builds them (JIT compile excluded by a warm-up
    call on a short slice), in samples/s; and the whole ``wmrid.pipeline.identify.identify`` call (replay plus
    covariance, base-parameter fit and diagnostics).

The log is simulated (seed ``--seed``) into bench/out/ the first time; later runs reuse it.

    /work/venv/bin/python bench/bench_identify.py                         # 1 h log, 3 runs
    /work/venv/bin/python bench/bench_identify.py --duration 3600 14400   # also 4 h (memory comparison)
"""

from __future__ import annotations

import argparse
import datetime
import json
import platform
import sys
import time
from types import SimpleNamespace

from _common import OUT, fmt_rss, median, run_timed, sim_log, wmrid_cmd

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


def in_process(path, repeat: int) -> dict:
    import pyarrow.parquet as pq

    from wmrid.estimators.observer.observe import default_box, resolve_form
    from wmrid.estimators.observer.replay import replay
    from wmrid.estimators.observer.settings import ObserverSettings
    from wmrid.estimators.options import ObserverOptions
    from wmrid.io.logs import read_log
    from wmrid.model import dynamics as model
    from wmrid.model.robot import BUILTIN_ROBOTS
    from wmrid.pipeline.identify import identify

    def best(fn) -> float:  # median wall time of fn() over `repeat` calls
        times = []
        for _ in range(repeat):
            t0 = time.perf_counter()
            fn()
            times.append(time.perf_counter() - t0)
        return median(times)

    robot = BUILTIN_ROBOTS["paper"]
    log = read_log(str(path))
    read = best(lambda: read_log(str(path)))
    bare = best(lambda: pq.read_table(str(path)))  # the file's columns into memory, nothing else
    t, eta, tau = log.t, log.eta, log.tau
    # settings as the observer's pass builds them for --robot paper, with the options' defaults
    d = vars(ObserverOptions())
    form = resolve_form(model.choose_form(eta), d["form"])
    theta_init = model.intermediate_parameters(model.base_parameters(robot.nominal), form)
    lo, hi = default_box(theta_init, form, d["box_width"], True)
    settings = ObserverSettings(
        form=form,
        theta_init=theta_init,
        theta_min=lo,
        theta_max=hi,
        k=d["k"],
        alpha=d["alpha"],
        torque_hold=d["torque_hold"],
    )
    # warm-ups on a short slice: JIT compile / numba cache load, not timed
    short = SimpleNamespace(t=t[:20000], eta=eta[:20000], tau=tau[:20000], source="warm-up", notes=())
    replay(short.t, short.eta, short.tau, settings)
    identify(short, robot)
    rep = best(lambda: replay(t, eta, tau, settings, max_history=d["max_history"]))
    whole = best(lambda: identify(log, robot))
    return {
        "form": form.kind, "k": d["k"], "read": read, "pyarrow_read": bare, "replay": rep,
        "replay_rate": len(t) / rep, "identify": whole,
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
        tail = f" {ip['read']:6.2f} {ip['replay']:8.2f} {ip['replay_rate']:13,.0f} {ip['identify']:12.2f}" if ip else ""
        print(
            f"{duration / 3600:>6.2f}h {n:>11,} | {e2e['min']:9.2f} {e2e['median']:9.2f} {e2e['rate']:11,.0f}"
            f" {fmt_rss(e2e['rss']):>8} |{tail}"
        )
    if ip0:
        print(
            f"(in-process medians of {args.repeat}, JIT excluded: read = read_log, replay = replay() alone, "
            f"identify() = replay + covariance, fit, diagnostics; form '{ip0['form']}', k = {ip0['k']:g})"
        )
        print(
            f"end to end / bare pyarrow read of the file: {e2e0['median'] / ip0['pyarrow_read']:.2f}x "
            f"(pyarrow.parquet.read_table {ip0['pyarrow_read']:.3f} s)"
        )
    print(f"\ntarget: end-to-end >= {TARGET:,} samples/s")
    for duration, _, e2e, _ in rows:
        print(f"  {duration:g} s log: {e2e['rate']:,.0f} samples/s -> {'MET' if e2e['rate'] >= TARGET else 'NOT met'}")
    OUT.mkdir(parents=True, exist_ok=True)
    record = {
        "command": " ".join(["python", *sys.argv]), "machine": platform.node(), "cpus": platform.processor() or None,
        "date_utc": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "rows": [{"duration_s": d, "samples": n, "end_to_end": {k: v for k, v in e.items() if k != "cmd"},
                  "in_process": ip} for d, n, e, ip in rows],
    }  # fmt: skip
    (OUT / "bench_identify.json").write_text(json.dumps(record, indent=1) + "\n")
    print(f"figures written to {(OUT / 'bench_identify.json').relative_to(OUT.parent.parent)}")


if __name__ == "__main__":
    main()
