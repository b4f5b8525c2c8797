"""Timing faults (issue 12): efforts stamped late or early, slow logs of a fast controller, speeds from encoder
differences; before and after wmrid's checks and ``--delay auto``.

    python bench/bench_timing.py                      # 20 seeds, 40 s, reduced and multibody, ~10 min on 2 cores
    python bench/bench_timing.py --seeds 5 --engines reduced
    python bench/bench_timing.py --faults 100hz,20hz,backdiff --engines reduced

For each engine (wmrid's reduced simulator; the MuJoCo multibody prototype, frictionless casters), trajectory
(sinusoid, reversing) and fault, the light AMR is simulated with sensor noise (0.02 rad/s, 0.01 N m; seeds
0..N-1), its controller at 1 kHz.  Faults (``--faults``): ``+5ms``, ``0ms``, ``-5ms``: logged at 1 kHz, the efforts
shifted by that delay (:func:`wmrid.estimators.regression.idim_rows.shifted`; + = stamped late); ``100hz``, ``20hz``:
logged at that
rate
(a decimated record of the 1 kHz loop); ``backdiff``: speeds as backward differences of a 2^20-count encoder (half
a sample of lag; reduced engine only).  Each log is identified three times with the default method: ``before``
(``feedback=False, timing=False``: without the closed-loop and timing checks, as wmrid did before issue 12), ``default``
(``identify(log, amr)``), and ``auto`` (``delay="auto"``).  Printed per case and run: the delay found (median, and
the share of seeds within 1 ms of the true one), the error of the friction terms (median of the largest |error|
over Fv1, Fv2, Fd1, Fd2, in % of the truth), of the inertia entries and Vc, the share of seeds whose every parameter
is within 3 std or flagged, and the share warned (a delay, a faster controller or --control-rate named, or
the efforts' timing called uncertain).
"""

from __future__ import annotations

import argparse
import os
import statistics
import time
from concurrent.futures import ProcessPoolExecutor
from types import SimpleNamespace

import numpy as np

PARAMS = ("m11", "m12", "m22", "M11", "M12", "M22", "Vc", "Fv1", "Fv2", "Fd1", "Fd2")
FRICTION = ("Fv1", "Fv2", "Fd1", "Fd2")
INERTIA = ("M11", "M12", "M22", "Vc")


FAULTS = {"+5ms": 0.005, "0ms": 0.0, "-5ms": -0.005, "100hz": 0.0, "20hz": 0.0, "backdiff": 0.0}
RATES = {"100hz": 100.0, "20hz": 20.0}


def one(job: tuple[str, str, str, int, float]) -> dict:
    engine, trajectory, fault, seed, duration = job
    delay = FAULTS[fault]
    rate = RATES.get(fault, 1000.0)
    from wmrid.estimators.regression.idim_rows import shifted
    from wmrid.model import dynamics as model
    from wmrid.model.robot import BUILTIN_ROBOTS
    from wmrid.pipeline.identify import identify
    from wmrid.sim.scenario import NoiseSettings
    from wmrid.sim.simulate import simulate

    amr = BUILTIN_ROBOTS["amr"]
    noise = NoiseSettings(eta_std=0.02, tau_std=0.01, encoder_cpr=2**20 if fault == "backdiff" else 0)
    if engine == "reduced":
        sim = simulate(
            amr.cad, amr.nominal, trajectory=trajectory, duration=duration, rate=rate, noise=noise, seed=seed
        )  # fmt: skip
    else:
        from wmrid.sim.multibody import simulate_multibody
        from wmrid.sim.multibody_model import MultibodySettings

        sim = simulate_multibody(
            amr.cad, amr.nominal, settings=MultibodySettings(caster_resistance=0.0), trajectory=trajectory,
            duration=duration, noise=noise, seed=seed, rate=rate,
        )  # fmt: skip
    truth = model.named_base(model.base_parameters(sim.true))
    log = SimpleNamespace(t=sim.t, eta=sim.eta, tau=shifted(sim.t, sim.tau, delay), source="bench", notes=())
    out = {"job": job}
    before = {"feedback": False, "timing": False}
    for name, kwargs in (("before", before), ("default", {}), ("auto", {"delay": "auto"})):
        res = identify(log, amr, **kwargs)
        flagged = set(res.diagnostics.get("flagged", []))
        err = {p: abs(res.parameters[p][0] / truth[p] - 1) * 100 for p in PARAMS}
        z = {p: abs(res.parameters[p][0] - truth[p]) / res.parameters[p][1] for p in PARAMS}
        out[name] = {
            "friction": max(err[p] for p in FRICTION),
            "inertia": max(err[p] for p in INERTIA),
            "honest": all(z[p] <= 3 or p in flagged or not np.isfinite(z[p]) for p in PARAMS),
            "delay": (res.diagnostics.get("delay") or res.diagnostics.get("timing") or {}).get("delay_s"),
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
            print(
                f"| {case[0]} | {case[1]} | {case[2]} | {run} | {found_text} | "
                f"{statistics.median(v['friction'] for v in vals):.3g} | "
                f"{statistics.median(v['inertia'] for v in vals):.3g} | "
                f"{np.mean([v['honest'] for v in vals]):.2f} | {np.mean([v['warned'] for v in vals]):.2f} |"
            )
    print(f"\n{len(rows)} logs, {wall:.0f} s wall")


if __name__ == "__main__":
    main()
