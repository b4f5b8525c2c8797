"""Change detection (``wmrid monitor``): false alarms per hour, detection delays, run time.

    /work/venv/bin/python bench/bench_monitor.py                   # 150 unchanged logs of 120 s, 40 payload logs
    /work/venv/bin/python bench/bench_monitor.py --seeds 400 --duration 240
    /work/venv/bin/python bench/bench_monitor.py --quick           # 20 + 8 seeds, no 1 h log

Logs: the paper robot (CAD set, controller on the nominal set) on the sinusoid at 1 kHz with the benchmarks'
noise (0.01 rad/s, 0.02 N m, caster 0.05 N m with 0.3 s correlation).  Each seed's model is identified
(``identify(log, paper)``, as ``wmrid identify LOG0 --robot paper -o RESULT.json``) on another 60 s log of
the unchanged robot (seed 100000 + seed): its errors are part of what the monitor must not call a change.

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

Seeded throughout: the same numbers every run.  Runs on all cores.
"""

from __future__ import annotations

import argparse
import os
import time
from concurrent.futures import ProcessPoolExecutor
from types import SimpleNamespace

import numpy as np
from _common import sim_log
from scipy.stats import f as f_dist

from wmrid.model import dynamics as model
from wmrid.model.robot import BUILTIN_ROBOTS, Payload
from wmrid.monitoring.monitor import monitor
from wmrid.monitoring.settings import DOF, MonitorSettings, model_from_dict
from wmrid.pipeline.identify import identify
from wmrid.sim.scenario import NoiseSettings, PlantChange
from wmrid.sim.simulate import simulate

ROBOT = BUILTIN_ROBOTS["paper"]
TRUE, NOMINAL = ROBOT.cad, ROBOT.nominal
LOAD = Payload(25.0, 0.1, -0.05, 0.4)
NOISE = NoiseSettings(eta_std=0.01, tau_std=0.02, caster_std=0.05)
STATED = (10.0, 1.0, 0.3, 0.1, 0.03)


def as_log(sim, name: str) -> SimpleNamespace:
    return SimpleNamespace(t=sim.t, eta=sim.eta, tau=sim.tau, source=name, notes=())


def identified(plant, seed: int):
    sim = simulate(plant, NOMINAL, duration=60.0, noise=NOISE, seed=100000 + seed)
    return model_from_dict(identify(as_log(sim, f"id{seed}"), ROBOT).to_dict(), f"model{seed}")


def alarm_rate_needed(result) -> float:
    """The smallest stated rate (per hour) at which the first segment would have raised an alarm."""
    g, st = result.grid, result.settings
    rates = [
        g.tests_per_hour * f_dist.sf(c["largest_statistic"] / (DOF * st.margin), DOF, c["dof"])
        for c in result.segments[0]["calibrations"]
    ]
    return float(min(rates)) if rates else float("inf")


def unchanged(seed: int, duration: float) -> tuple[int, float, float, float]:
    """(alarms, hours tested, smallest stated rate that would alarm, largest statistic / threshold)."""
    m = identified(TRUE, seed)
    sim = simulate(TRUE, NOMINAL, duration=duration, noise=NOISE, seed=seed)
    result = monitor(as_log(sim, f"h0-{seed}"), m)
    hours = (duration - result.settings.calibration_s) / 3600.0
    ratio = max(c["largest_statistic"] / c["threshold"] for s in result.segments for c in s["calibrations"])
    return len(result.changes), hours, alarm_rate_needed(result), ratio


def changed(seed: int, kind: str) -> dict:
    rng = np.random.default_rng(seed)
    t_change = 30.0 + rng.uniform(0.0, 1.0)
    if kind == "load":
        change, before_model = PlantChange.payload_load(t_change, TRUE, LOAD), TRUE
    elif kind == "drop":
        change, before_model = PlantChange.payload_drop(t_change, TRUE, LOAD), TRUE.with_payload(LOAD)
    else:
        change, before_model = PlantChange.friction_fault(t_change, TRUE, "right", 3.0), TRUE
    m = identified(before_model, seed)
    sim = simulate(change.before, NOMINAL, duration=60.0, noise=NOISE, seed=seed, change=change)
    t_switch = sim.settings["change"]["t_switch"]
    result = monitor(as_log(sim, f"{kind}-{seed}"), m)
    before = [c for c in result.changes if c.t_alarm < t_switch]
    after = [c for c in result.changes if c.t_alarm >= t_switch]
    out = {"before": len(before), "after": len(after)}
    if after:
        first = after[0]
        out.update(delay=first.t_alarm - t_switch, t_error=first.t - t_switch, extra=len(after) - 1)
        truth = model.named_base(model.base_parameters(change.after))
        if first.parameters is not None:
            out["m11_error"] = first.parameters["M11"]["value"] / truth["M11"] - 1.0
        out["tested_after_h"] = max(0.0, 60.0 - first.t - result.settings.calibration_s) / 3600.0
    return out


def changed_log(seed: int):
    """(a 60 s log with the payload loaded at 30 s, the model of the unloaded robot)."""
    change = PlantChange.payload_load(30.0, TRUE, LOAD)
    return simulate(TRUE, NOMINAL, duration=60.0, noise=NOISE, seed=seed, change=change), identified(TRUE, seed)


def _q(values, qs=(0.0, 0.5, 0.9, 1.0)) -> str:
    if len(values) == 0:
        return "-"
    return " / ".join(f"{v:.2f}" for v in np.quantile(values, qs))


def report_changes(kind: str, rows: list[dict]) -> None:
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


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=150, help="unchanged logs (default 150)")
    ap.add_argument("--duration", type=float, default=120.0, help="length of each unchanged log, s (default 120)")
    ap.add_argument("--payload-seeds", type=int, default=40, help="payload-loaded logs (default 40)")
    ap.add_argument("--quick", action="store_true", help="20 unchanged and 8 changed logs per case; no 1 h log")
    args = ap.parse_args()
    if args.quick:
        args.seeds, args.payload_seeds = 20, 8
    settings = MonitorSettings()
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
    for kind, rows_c in results.items():
        report_changes({"load": "payload loaded", "drop": "payload dropped"}.get(kind, "right friction x3"), rows_c)
    # Run time, one process at a time (the pool above shares the cores).
    sims = [changed_log(seed) for seed in range(3)]
    times = []
    for sim, m in sims:
        t0 = time.perf_counter()
        monitor(as_log(sim, "timed"), m)
        times.append(time.perf_counter() - t0)
    n = len(sims[0][0].t)
    print(
        f"3. run time: a 60 s log (1 kHz) with a payload loaded at 30 s, the identifications after it included: "
        f"median {np.median(times):.2f} s = {n / np.median(times):,.0f} samples/s"
    )
    if not args.quick:
        from wmrid.io.logs import read_log

        path = sim_log(3600.0)
        log = read_log(str(path))
        m = identified(TRUE, 0)
        t0 = time.perf_counter()
        result = monitor(log, m)
        seconds = time.perf_counter() - t0
        print(
            f"   {path.name} (unchanged): {len(log.t):,} samples in {seconds:.1f} s = "
            f"{len(log.t) / seconds:,.0f} samples/s; {len(result.changes)} alarms; thresholds "
            + ", ".join(f"{c['threshold']:.1f}" for c in result.segments[0]["calibrations"])
        )


if __name__ == "__main__":
    main()
