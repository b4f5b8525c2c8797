"""Timing faults (issue 12): efforts stamped late or early against the speeds, before and after ``--delay auto``.

    python bench/bench_timing.py                      # 20 seeds, 40 s, reduced and multibody, ~10 min on 2 cores
    python bench/bench_timing.py --seeds 5 --engines reduced

For each engine (wmrid's reduced simulator; the MuJoCo multibody prototype, frictionless casters), trajectory
(sinusoid, reversing) and true delay (+5 ms: the torque stamped 5 ms late; 0; -5 ms), the light AMR is simulated
at 1 kHz with sensor noise (0.02 rad/s, 0.01 N m; seeds 0..N-1), its efforts shifted by the delay
(:func:`wmrid.idim.shifted`), and identified twice with the observer: as stamped (``identify(log, amr)``) and
with ``delay="auto"``.  Printed per case and run: the delay found (median, and the share of seeds within 1 ms),
the error of the friction terms (median of the largest |error| over Fv1, Fv2, Fd1, Fd2, in % of the truth), of
the inertia entries and Vc, and the share of seeds whose every parameter is within 3 std or flagged.
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


def one(job: tuple[str, str, float, int, float]) -> dict:
    engine, trajectory, delay, seed, duration = job
    from wmrid import model
    from wmrid.identify import identify
    from wmrid.idim import shifted
    from wmrid.robot import BUILTIN_ROBOTS
    from wmrid.simulate import NoiseSettings, simulate

    amr = BUILTIN_ROBOTS["amr"]
    noise = NoiseSettings(eta_std=0.02, tau_std=0.01)
    if engine == "reduced":
        sim = simulate(amr.cad, amr.nominal, trajectory=trajectory, duration=duration, noise=noise, seed=seed)
    else:
        from wmrid.multibody import MultibodySettings, simulate_multibody

        sim = simulate_multibody(
            amr.cad, amr.nominal, settings=MultibodySettings(caster_resistance=0.0), trajectory=trajectory,
            duration=duration, noise=noise, seed=seed,
        )  # fmt: skip
    truth = model.named_base(model.base_parameters(sim.true))
    log = SimpleNamespace(t=sim.t, eta=sim.eta, tau=shifted(sim.t, sim.tau, delay), source="bench", notes=())
    out = {"job": job}
    for name, kwargs in (("stamped", {}), ("auto", {"delay": "auto"})):
        res = identify(log, amr, **kwargs)
        flagged = set(res.diagnostics.get("flagged", []))
        err = {p: abs(res.parameters[p][0] / truth[p] - 1) * 100 for p in PARAMS}
        z = {p: abs(res.parameters[p][0] - truth[p]) / res.parameters[p][1] for p in PARAMS}
        out[name] = {
            "friction": max(err[p] for p in FRICTION),
            "inertia": max(err[p] for p in INERTIA),
            "honest": all(z[p] <= 3 or p in flagged or not np.isfinite(z[p]) for p in PARAMS),
            "delay": (res.diagnostics.get("delay") or {}).get("delay_s"),
            "warned": any("stamped" in w or "faster than the log" in w for w in res.warnings),
        }
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--duration", type=float, default=40.0)
    ap.add_argument("--engines", default="reduced,multibody")
    ap.add_argument("--workers", type=int, default=os.cpu_count() or 1)
    args = ap.parse_args()
    engines = [e.strip() for e in args.engines.split(",") if e.strip()]
    jobs = [
        (engine, trajectory, delay, seed, args.duration)
        for engine in engines
        for trajectory in ("sinusoid", "reversing")
        for delay in (0.005, 0.0, -0.005)
        for seed in range(args.seeds)
    ]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        rows = list(pool.map(one, jobs))
    wall = time.perf_counter() - t0
    print(f"\nlight AMR, {args.duration:g} s at 1 kHz, noise 0.02 rad/s and 0.01 N m, {args.seeds} seeds per case\n")
    print("| engine | trajectory | true delay ms | run | delay found ms (median; within 1 ms) | friction err % "
          "| M, Vc err % | all within 3 std or flagged | warned |")  # fmt: skip
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    cases = sorted({r["job"][:3] for r in rows}, key=lambda c: (engines.index(c[0]), c[1], -c[2]))
    for case in cases:
        sel = [r for r in rows if r["job"][:3] == case]
        for run in ("stamped", "auto"):
            vals = [r[run] for r in sel]
            found = [v["delay"] for v in vals if v["delay"] is not None]
            found_text = "—"
            if found:
                within = np.mean([abs(f - case[2]) <= 1e-3 for f in found])
                found_text = f"{1e3 * statistics.median(found):+.2f}; {within:.2f}"
            print(
                f"| {case[0]} | {case[1]} | {1e3 * case[2]:+g} | {run} | {found_text} | "
                f"{statistics.median(v['friction'] for v in vals):.3g} | "
                f"{statistics.median(v['inertia'] for v in vals):.3g} | "
                f"{np.mean([v['honest'] for v in vals]):.2f} | {np.mean([v['warned'] for v in vals]):.2f} |"
            )
    print(f"\n{len(rows)} logs, {wall:.0f} s wall")


if __name__ == "__main__":
    main()
