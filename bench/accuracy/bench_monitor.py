"""Change detection (``wmrid monitor``): false alarms per hour, detection delays, run time.

    python3 bench/accuracy/bench_monitor.py                   # 150 unchanged logs of 120 s, 40 payload logs
    python3 bench/accuracy/bench_monitor.py --seeds 400 --duration 240
    python3 bench/accuracy/bench_monitor.py --quick           # 20 + 8 seeds, no 1 h log
    python3 bench/accuracy/bench_monitor.py --quick --seeds 2 --payload-seeds 2 --duration 30   # a check that it runs

Logs: the paper robot (CAD set, controller on the nominal set) on the sinusoid at 1 kHz with the benchmarks'
noise (0.01 rad/s, 0.02 N m, caster 0.05 N m with 0.3 s correlation).  Each seed's model is identified
(``wmrid.identify(log, "paper")`` with the wheels' friction model, as ``wmrid identify LOG0 --robot paper --friction
wheel -o RESULT.json``) on another 60 s log of the unchanged robot (seed 100000 + seed): its errors are part of what
the monitor must not call a change.  Every log is ``wmrid.simulate``'s, every run ``wmrid.monitor``'s.

1. False alarms.  Each unchanged log is monitored with the default settings (stated: at most 0.1 false alarms
   per hour); every change it reports is a false alarm.  Rate = alarms / hours tested (the log less its
   10 s calibration span).  The same runs also give the rate at other stated rates: from the largest
   statistic of each calibration stage and the threshold's law, the smallest stated rate at which the log
   would have alarmed; the measured rate at a stated rate R is then (logs that would alarm at R) / hours.
2. Detection.  A 25 kg payload (at x 0.1 m, y -0.05 m, 0.4 kg m^2) loaded at 30 s + U(0, 1) s into a 60 s
   log: delay = t_alarm - switch time (t_alarm: the last log sample the alarming test used), alarms before
   the switch, error of the change time, further (false) alarms after the change, error of the re-identified
   M11.  Also on fewer seeds: the payload dropped (model of the loaded robot) and the right wheel's friction
   tripled (both at 30 s + U(0, 1) s).
3. Run time: ``monitor`` on bench/out/paper_sinusoid_3600s_1000hz_seed1.parquet (one hour at 1 kHz,
   generated if missing), samples/s.

Seeded throughout: the same numbers every run.  Runs on all cores.  Figures: bench/results/bench_monitor.json.
"""

from __future__ import annotations

import argparse
import dataclasses
import os
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np
from scipy.stats import f as f_dist

import wmrid

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # bench/: the shared module _common
from _common import sim_log, write_results

LOAD = wmrid.Payload(25.0, 0.1, -0.05, 0.4)
NOISE = {"eta_std": 0.01, "tau_std": 0.02, "caster_std": 0.05}
STATED = (10.0, 1.0, 0.3, 0.1, 0.03)


def simulated(seed: int, duration: float = 60.0, payload=None, change=None):
    """The paper robot's noisy sinusoid (``wmrid.simulate``)."""
    noise = wmrid.NoiseSettings(seed=seed, **NOISE)
    return wmrid.simulate("paper", duration=duration, noise=noise, payload=payload, change=change)


def wheel_log(run) -> wmrid.WheelLog:
    """The run's log as a robot records it: t, eta, tau (no pose, no wheel-speed reference)."""
    return dataclasses.replace(run.to_wheel_log(), pose=None, reference=None)


def identified(seed: int, payload=None):
    """The model: a 60 s log of the robot (carrying ``payload``) identified with the wheels' friction model."""
    run = simulated(100000 + seed, payload=payload)
    return wmrid.identify(wheel_log(run), "paper", observer=wmrid.ObserverOptions(friction="wheel"))


def alarm_rate_needed(result) -> float:
    """The smallest stated rate (per hour) at which the first segment would have raised an alarm."""
    g, st = result.grid, result.settings
    dim = result.detector_dict()["dof"]
    rates = [
        g.tests_per_hour * f_dist.sf(c["largest_statistic"] / (dim * st.margin), dim, c["dof"])
        for c in result.segments[0]["calibrations"]
    ]
    return float(min(rates)) if rates else float("inf")


def unchanged(seed: int, duration: float) -> tuple[int, float, float, float]:
    """(alarms, hours tested, smallest stated rate that would alarm, largest statistic / threshold)."""
    m = identified(seed)
    result = wmrid.monitor(wheel_log(simulated(seed, duration)), m)
    hours = (duration - result.settings.calibration_s) / 3600.0
    ratio = max(c["largest_statistic"] / c["threshold"] for s in result.segments for c in s["calibrations"])
    return len(result.changes), hours, alarm_rate_needed(result), ratio


def changed(seed: int, kind: str) -> dict:
    rng = np.random.default_rng(seed)
    t_change = 30.0 + rng.uniform(0.0, 1.0)
    if kind == "load":
        change, before = wmrid.Change(t_change, "load"), None
    elif kind == "drop":
        change, before = wmrid.Change(t_change, "drop"), LOAD
    else:
        change, before = wmrid.Change(t_change, "fault", wheel="right", factor=3.0), None
    m = identified(seed, payload=before)
    # the friction fault's robot carries no payload, as its model (``before`` None); the kind passed is "friction",
    # so comparing it with "fault" loaded the payload from the start and every log alarmed before the fault
    run = simulated(seed, payload=None if change.kind == "fault" else LOAD, change=change)
    record = run.truth["settings"]["change"]
    t_switch = record["t_switch"]
    result = wmrid.monitor(wheel_log(run), m)
    before_switch = [c for c in result.changes if c.t_alarm < t_switch]
    after = [c for c in result.changes if c.t_alarm >= t_switch]
    out = {"before": len(before_switch), "after": len(after)}
    if after:
        first = after[0]
        out.update(delay=first.t_alarm - t_switch, t_error=first.t - t_switch, extra=len(after) - 1)
        if first.parameters is not None:
            out["m11_error"] = first.parameters["M11"].value / record["after"]["M11"] - 1.0
        out["tested_after_h"] = max(0.0, 60.0 - first.t - result.settings.calibration_s) / 3600.0
    return out


def changed_log(seed: int):
    """(a 60 s log with the payload loaded at 30 s, the model of the unloaded robot)."""
    return wheel_log(simulated(seed, payload=LOAD, change=wmrid.Change(30.0, "load"))), identified(seed)


def _q(values, qs=(0.0, 0.5, 0.9, 1.0)) -> str:
    if len(values) == 0:
        return "-"
    return " / ".join(f"{v:.2f}" for v in np.quantile(values, qs))


def report_changes(kind: str, rows: list[dict]) -> dict:
    found = [r for r in rows if "delay" in r]
    delays = [r["delay"] for r in found]
    print(
        f"{kind}: {len(rows)} logs; found after the switch in {len(found)}; alarms before the switch: "
        f"{sum(r['before'] for r in rows)}; further alarms after the change: {sum(r.get('extra', 0) for r in rows)} "
        f"in {sum(r.get('tested_after_h', 0.0) for r in rows):.2f} h tested"
    )
    print(f"  delay s (min / median / 90 % / max): {_q(delays)}; within 2 s: {sum(d <= 2.0 for d in delays)}")
    print(f"  change-time error s (min / median / 90 % / max): {_q([r['t_error'] for r in found])}")
    errs = [100 * abs(r["m11_error"]) for r in found if "m11_error" in r]
    if errs:
        print(f"  |M11 re-identified - truth| %: median {np.median(errs):.2f}, max {np.max(errs):.2f}")
    return {
        "logs": len(rows), "found_after_switch": len(found), "alarms_before_switch": sum(r["before"] for r in rows),
        "further_alarms_after": sum(r.get("extra", 0) for r in rows),
        "hours_tested_after": sum(r.get("tested_after_h", 0.0) for r in rows),
        "delay_s": {"min": min(delays, default=None), "median": float(np.median(delays)) if delays else None,
                    "p90": float(np.quantile(delays, 0.9)) if delays else None, "max": max(delays, default=None)},
        "within_2_s": sum(d <= 2.0 for d in delays),
        "m11_error_percent": {"median": float(np.median(errs)), "max": float(np.max(errs))} if errs else None,
    }  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=None, help="unchanged logs (default 150; 20 with --quick)")
    ap.add_argument("--duration", type=float, default=120.0, help="length of each unchanged log, s (default 120)")
    ap.add_argument("--payload-seeds", type=int, default=None, help="payload-loaded logs (default 40; 8 with --quick)")
    ap.add_argument("--quick", action="store_true", help="20 unchanged and 8 changed logs per case; no 1 h log")
    args = ap.parse_args()
    if args.seeds is None:
        args.seeds = 20 if args.quick else 150
    if args.payload_seeds is None:
        args.payload_seeds = 8 if args.quick else 40
    settings = wmrid.MonitorSettings()
    workers = os.cpu_count() or 1

    started = time.perf_counter()
    with ProcessPoolExecutor(max_workers=workers) as pool:
        rows = list(pool.map(unchanged, range(args.seeds), [args.duration] * args.seeds))
    alarms = sum(r[0] for r in rows)
    hours = sum(r[1] for r in rows)
    needed = np.array([r[2] for r in rows])
    ratios = np.array([r[3] for r in rows])
    print(
        f"1. false alarms: {args.seeds} unchanged logs of {args.duration:g} s ({hours:.2f} h tested after the "
        f"{settings.calibration_s:g} s calibration spans), {time.perf_counter() - started:.0f} s wall"
    )
    print(
        f"   default (stated at most {settings.false_alarm_rate:g}/h): {alarms} alarms = {alarms / hours:.3f} per hour"
    )
    print(
        "   measured per hour at stated rates: "
        + ", ".join(f"{r:g}/h -> {np.sum(needed < r) / hours:.3f}" for r in STATED)
    )
    print(f"   largest statistic / threshold per log (median / 90 % / 99 % / max): {_q(ratios, (0.5, 0.9, 0.99, 1))}")

    started = time.perf_counter()
    cases = (("load", args.payload_seeds), ("drop", max(4, args.payload_seeds // 2)),
             ("friction x3", max(4, args.payload_seeds // 2)))  # fmt: skip
    with ProcessPoolExecutor(max_workers=workers) as pool:
        results = {kind: list(pool.map(changed, range(1000, 1000 + n), [kind.split()[0]] * n)) for kind, n in cases}
    print(f"2. detection ({time.perf_counter() - started:.0f} s wall); change at 30 s + U(0, 1) s of a 60 s log")
    detection = {}
    for kind, rows_c in results.items():
        label = {"load": "payload loaded", "drop": "payload dropped"}.get(kind, "right friction x3")
        detection[label] = report_changes(label, rows_c)
    # Run time, one process at a time (the pool above shares the cores).
    sims = [changed_log(seed) for seed in range(3)]
    times = []
    for log, m in sims:
        t0 = time.perf_counter()
        wmrid.monitor(log, m)
        times.append(time.perf_counter() - t0)
    n = len(sims[0][0].t)
    print(
        f"3. run time: a 60 s log (1 kHz) with a payload loaded at 30 s, the identifications after it included: "
        f"median {np.median(times):.2f} s = {n / np.median(times):,.0f} samples/s"
    )
    figures = {
        "settings": vars(args),
        "false_alarms": {"logs": args.seeds, "hours_tested": hours, "alarms": alarms, "per_hour": alarms / hours,
                         "stated_per_hour": settings.false_alarm_rate,
                         "measured_at_stated": {f"{r:g}": float(np.sum(needed < r) / hours) for r in STATED},
                         "largest_statistic_over_threshold": {q: float(np.quantile(ratios, v)) for q, v in
                                                              (("median", 0.5), ("p90", 0.9), ("p99", 0.99),
                                                               ("max", 1.0))}},
        "detection": detection,
        "run_time": {"samples": n, "median_s": float(np.median(times)), "samples_per_s": n / float(np.median(times))},
    }  # fmt: skip
    if not args.quick:
        path = sim_log(3600.0)
        log = wmrid.read_log(path)
        m = identified(0)
        t0 = time.perf_counter()
        result = wmrid.monitor(log, m)
        seconds = time.perf_counter() - t0
        print(
            f"   {path.name} (unchanged): {len(log.t):,} samples in {seconds:.1f} s = "
            f"{len(log.t) / seconds:,.0f} samples/s; {len(result.changes)} alarms; thresholds "
            + ", ".join(f"{c['threshold']:.1f}" for c in result.segments[0]["calibrations"])
        )
        figures["hour_log"] = {"path": path.name, "samples": len(log.t), "seconds": seconds,
                               "samples_per_s": len(log.t) / seconds, "alarms": len(result.changes)}  # fmt: skip
    write_results(figures)


if __name__ == "__main__":
    main()
