"""Timing faults (issue 12): efforts stamped late or early, slow logs of a fast controller, speeds from encoder
differences; before and after wmrid's checks and ``--delay auto``.

    python3 bench/accuracy/bench_timing.py                      # 20 seeds, 40 s, reduced and multibody, ~10 min
    python3 bench/accuracy/bench_timing.py --seeds 5 --engines reduced
    python3 bench/accuracy/bench_timing.py --faults 100hz,20hz,backdiff --engines reduced
    python3 bench/accuracy/bench_timing.py --seeds 1 --duration 10 --engines reduced --trajectories sinusoid  # quick

For each engine (wmrid's reduced simulator; the MuJoCo multibody prototype, frictionless casters), trajectory
(sinusoid, reversing) and fault, the light AMR is simulated with sensor noise (0.02 rad/s, 0.01 N m; seeds
0..N-1), its controller at 1 kHz (``wmrid.simulate``).  Faults (``--faults``): ``+5ms``, ``0ms``, ``-5ms``: logged at
1 kHz, the efforts shifted by that delay (:func:`shifted`, linear interpolation; + = stamped late); ``100hz``,
``20hz``: logged at that rate (a decimated record of the 1 kHz loop); ``backdiff``: speeds as backward differences of
a 2^20-count encoder (half a sample of lag; reduced engine only).  Each log is identified three times with
``wmrid.identify`` and the wheels' friction model: ``before`` (``method="observer"`` with ``delay=0``: the efforts as
stamped, without the timing check, as wmrid did before issue 12), ``default`` (``wmrid.identify(log, "amr")``), and
``auto`` (``delay="auto"``).  (Before the bench used only the public API, ``before`` also left out the closed-loop
check, which the public API always runs; on these logs, sensor noise and no disturbance, the check finds no
disturbance and changes nothing but its record, so the figures are those of issue 12's "before".)

Printed per case and run: the delay found (median, and
the share of seeds within 1 ms of the true one), the error of the friction terms (median of the largest |error|
over Fv1, Fv2, Fd1, Fd2, in % of the truth), of the inertia entries and Vc, the share of seeds whose every parameter
is within 3 std or flagged, and the share warned (a delay, a faster controller or --control-rate named, or
the efforts' timing called uncertain).  Figures: bench/results/bench_timing.json.
"""

from __future__ import annotations

import argparse
import os
import statistics
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # bench/: the shared module _common
from _common import write_results

PARAMS = ("m11", "m12", "m22", "M11", "M12", "M22", "Vc", "Fv1", "Fv2", "Fd1", "Fd2")
FRICTION = ("Fv1", "Fv2", "Fd1", "Fd2")
INERTIA = ("M11", "M12", "M22", "Vc")


FAULTS = {"+5ms": 0.005, "0ms": 0.0, "-5ms": -0.005, "100hz": 0.0, "20hz": 0.0, "backdiff": 0.0}
RATES = {"100hz": 100.0, "20hz": 20.0}


def shifted(t: np.ndarray, x: np.ndarray, delay: float) -> np.ndarray:
    """x (n, k) read ``delay`` s earlier, x(t - delay), by linear interpolation between its samples at t (n,) s (held
    at the first and last sample beyond the log's ends): efforts stamped ``delay`` s late."""
    x = np.asarray(x, dtype=np.float64)
    return np.column_stack([np.interp(t - delay, t, x[:, j]) for j in range(x.shape[1])])


def one(job: tuple[str, str, str, int, float]) -> dict:
    engine, trajectory, fault, seed, duration = job
    delay = FAULTS[fault]
    rate = RATES.get(fault, 1000.0)
    import wmrid

    noise = wmrid.NoiseSettings(eta_std=0.02, tau_std=0.01, encoder_cpr=2**20 if fault == "backdiff" else 0, seed=seed)
    settings = "reduced" if engine == "reduced" else wmrid.MultibodySettings(caster_resistance=0.0)
    run = wmrid.simulate("amr", trajectory=trajectory, duration=duration, rate=rate, noise=noise, engine=settings)
    truth = run.truth["parameters"]
    sim = run.log
    log = wmrid.WheelLog(t=sim.t, eta=sim.eta, tau=shifted(sim.t, sim.tau, delay), source="bench")
    out = {"job": job}
    runs = (
        ("before", "observer", {"delay": 0.0}), ("default", "auto", {}), ("auto", "auto", {"delay": "auto"}),
    )  # fmt: skip
    for name, method, options in runs:
        res = wmrid.identify(log, "amr", method=method, observer=wmrid.ObserverOptions(friction="wheel", **options))
        flagged = set(res.diagnostics.flagged or ())
        err = {p: abs(res.parameters[p][0] / truth[p] - 1) * 100 for p in PARAMS}
        z = {p: abs(res.parameters[p][0] - truth[p]) / res.parameters[p][1] for p in PARAMS}
        diag = res.diagnostics.to_dict()
        found = (diag.get("delay") or diag.get("timing") or {}).get("delay_s")
        out[name] = {
            "friction": max(err[p] for p in FRICTION),
            "inertia": max(err[p] for p in INERTIA),
            "honest": all(z[p] <= 3 or p in flagged or not np.isfinite(z[p]) for p in PARAMS),
            "delay": None if name == "before" else found,  # "before" looks for no delay (given as 0)
            "warned": any(
                "stamped" in w or "faster than the log" in w or "--control-rate" in w or "timing against" in w
                for w in res.warnings
            ),
        }
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--duration", type=float, default=40.0)
    ap.add_argument("--engines", default="reduced,multibody")
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    ap.add_argument("--faults", default="+5ms,0ms,-5ms", help=f"comma-separated, of {', '.join(FAULTS)}")
    ap.add_argument("--trajectories", default="sinusoid,reversing")
    args = ap.parse_args()
    engines = [e.strip() for e in args.engines.split(",") if e.strip()]
    faults = [f.strip() for f in args.faults.split(",") if f.strip()]
    jobs = [
        (engine, trajectory, fault, seed, args.duration)
        for engine in engines
        for trajectory in args.trajectories.split(",")
        for fault in faults
        for seed in range(args.seeds)
        if not (fault == "backdiff" and engine != "reduced")
    ]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        rows = list(pool.map(one, jobs))
    wall = time.perf_counter() - t0
    print(f"\nlight AMR, {args.duration:g} s, 1 kHz controller, noise 0.02 rad/s and 0.01 N m, {args.seeds} seeds\n")
    print("| engine | trajectory | fault | run | delay found ms (median; within 1 ms) | friction err % "
          "| M, Vc err % | all within 3 std or flagged | warned |")  # fmt: skip
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    cases = sorted({r["job"][:3] for r in rows}, key=lambda c: (engines.index(c[0]), c[1], faults.index(c[2])))
    table = []
    for case in cases:
        sel = [r for r in rows if r["job"][:3] == case]
        true_delay = FAULTS[case[2]]
        for run in ("before", "default", "auto"):
            vals = [r[run] for r in sel]
            found = [v["delay"] for v in vals if v["delay"] is not None]
            found_text = "—"
            if found:
                within = np.mean([abs(f - true_delay) <= 1e-3 for f in found])
                found_text = f"{1e3 * statistics.median(found):+.2f}; {within:.2f}"
            table.append({
                "engine": case[0], "trajectory": case[1], "fault": case[2], "run": run,
                "delay_found_ms_median": 1e3 * statistics.median(found) if found else None,
                "delay_within_1ms": float(np.mean([abs(f - true_delay) <= 1e-3 for f in found])) if found else None,
                "friction_error_percent": statistics.median(v["friction"] for v in vals),
                "inertia_error_percent": statistics.median(v["inertia"] for v in vals),
                "honest": float(np.mean([v["honest"] for v in vals])),
                "warned": float(np.mean([v["warned"] for v in vals])),
            })  # fmt: skip
            print(
                f"| {case[0]} | {case[1]} | {case[2]} | {run} | {found_text} | "
                f"{statistics.median(v['friction'] for v in vals):.3g} | "
                f"{statistics.median(v['inertia'] for v in vals):.3g} | "
                f"{np.mean([v['honest'] for v in vals]):.2f} | {np.mean([v['warned'] for v in vals]):.2f} |"
            )
    print(f"\n{len(rows)} logs, {wall:.0f} s wall")
    write_results({"settings": vars(args), "logs": len(rows), "wall_s": wall, "rows": table})


if __name__ == "__main__":
    main()
