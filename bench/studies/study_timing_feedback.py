"""Issue 28, item 4: a timing check that finds delays, not feedback.  Prints and writes (JSON) the figures of

(a) the light AMR (examples/small_amr.toml), 200 Hz log on one clock (no real delay), a coloured caster
    disturbance inside the feedback loop (``caster`` N m), reversing, sensor noise 0.02 rad/s and 0.01 N m: per
    seed, whether the default ``identify`` applied a delay, and each parameter's std against ``delay=0``;
(b) the paper's robot, white sensor noise only, 300 s: the std of m11, m12, m22, M11, M12, M22, Vc on the first
    75 s against the whole 300 s (1/sqrt(T) predicts 2), and the share of parameters within 3 std of the truth.

    python3 bench/studies/study_timing_feedback.py                 # (a) 20 seeds reduced + 4 multibody, (b) 6 seeds
    python3 bench/studies/study_timing_feedback.py --a-seeds 5 --b-seeds 2 --mb-seeds 0
    python3 bench/studies/study_timing_feedback.py --no-reference --b-seeds 0      # its own results file
    python3 bench/studies/study_timing_feedback.py --a-seeds 1 --mb-seeds 0 --b-seeds 1 --b-duration 40 --caster 0.02

Logs come from :func:`wmrid.simulate` (seeded) and are identified (``wmrid.identify``, the wheels' friction model) as
:class:`wmrid.WheelLog` (their wheel-speed reference included, as ``wmrid simulate`` writes it).  At most
``--workers`` processes (default 2).  Figures: bench/results/study_timing_feedback.json (``--no-reference``:
study_timing_feedback-no_reference.json); every run's row with ``--json PATH``.
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import os
import statistics
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # bench/: the shared module _common
from _common import ROOT, write_results

AMR = str(ROOT / "examples" / "small_amr.toml")
INERTIA = ("m11", "m12", "m22", "M11", "M12", "M22", "Vc")
NOISE = {"eta_std": 0.02, "tau_std": 0.01}


def case_a(job: tuple[str, int, float, float, bool]) -> dict:
    engine, seed, caster, duration, reference = job
    import wmrid

    run = wmrid.simulate(
        AMR,
        trajectory="reversing",
        duration=duration,
        rate=200.0,
        engine=engine,
        noise=wmrid.NoiseSettings(seed=seed, caster_std=caster, **NOISE),
    )
    log = run.log.to_wheel_log()
    if not reference:  # a field log without the controller's set-points: least squares times the efforts
        log = dataclasses.replace(log, reference=None)
    default = wmrid.identify(log, AMR, observer=wmrid.ObserverOptions(friction="wheel"))
    zero = wmrid.identify(log, AMR, observer=wmrid.ObserverOptions(friction="wheel", delay=0.0))
    timing = default.diagnostics.to_dict().get("timing") or {}
    applied = (default.diagnostics.to_dict().get("delay") or {}).get("applied_s") or 0.0
    ratio = {k: default.parameters[k][1] / zero.parameters[k][1] for k in default.parameters}
    return {
        "engine": engine, "seed": seed, "caster": caster, "delay_s": timing.get("delay_s"),
        "std_s": timing.get("std_s"), "estimator": timing.get("estimator"), "applied_s": applied,
        "std_ratio": ratio, "max_ratio": max(ratio.values()),
        "hold_term": bool((timing.get("hold_term") or {}).get("widened")),
        "timing_term": bool((timing.get("timing_term") or {}).get("widened")),
    }  # fmt: skip


def case_b(job: tuple[int, str, float]) -> dict:
    seed, trajectory, duration = job
    import wmrid

    run = wmrid.simulate(
        "paper", trajectory=trajectory, duration=duration, noise=wmrid.NoiseSettings(seed=seed, **NOISE)
    )
    log = run.log.to_wheel_log()
    truth = run.truth["parameters"]
    out: dict = {"seed": seed, "trajectory": trajectory}
    for length in (duration / 4, duration):
        keep = log.t <= log.t[0] + length
        sub = wmrid.WheelLog(
            t=log.t[keep], eta=log.eta[keep], tau=log.tau[keep], source="b", reference=log.reference[keep]
        )
        res = wmrid.identify(sub, "paper", observer=wmrid.ObserverOptions(friction="wheel"))
        timing = res.diagnostics.to_dict().get("timing") or {}
        out[f"{length:g}"] = {
            "std": {k: res.parameters[k][1] for k in res.parameters},
            "z": {k: abs(res.parameters[k][0] - truth[k]) / res.parameters[k][1] for k in res.parameters},
            "delay_s": timing.get("delay_s"), "std_s": timing.get("std_s"), "applied": bool(timing.get("apply")),
            "timing_term": bool((timing.get("timing_term") or {}).get("widened")),
            "model_error_scale": res.diagnostics.model_error.scale,
        }  # fmt: skip
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--a-seeds", type=int, default=20)
    ap.add_argument("--mb-seeds", type=int, default=4, help="multibody (MuJoCo) seeds for (a)")
    ap.add_argument("--caster", type=float, nargs="+", default=[0.02, 0.005], help="N m, for (a)")
    ap.add_argument("--a-duration", type=float, default=40.0)
    ap.add_argument("--no-reference", action="store_true", help="(a) without the logged wheel-speed reference")
    ap.add_argument("--b-seeds", type=int, default=6)
    ap.add_argument("--b-duration", type=float, default=300.0)
    ap.add_argument("--b-trajectories", default="sinusoid,reversing")
    ap.add_argument("--workers", type=int, default=min(2, os.cpu_count() or 1))
    ap.add_argument("--json", default=None, help="also every run's row, here")
    args = ap.parse_args()
    ref = not args.no_reference
    jobs_a = [("reduced", s, c, args.a_duration, ref) for c in args.caster for s in range(args.a_seeds)]
    jobs_a += [("mujoco", s, c, args.a_duration, ref) for c in args.caster for s in range(args.mb_seeds)]
    jobs_b = [(s, tr, args.b_duration) for tr in args.b_trajectories.split(",") if tr for s in range(args.b_seeds)]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        rows_a = list(pool.map(case_a, jobs_a))
        rows_b = list(pool.map(case_b, jobs_b))
    wall = time.perf_counter() - t0
    summary_a = []
    print("(a) light AMR, 200 Hz, one clock, caster disturbance in the loop, reversing, noise 0.02 rad/s 0.01 N m")
    print(
        "| engine | caster N m | seeds | delay applied (seeds) | worst std ratio vs delay=0 (max over seeds; median) "
        "| seeds with any ratio > 1.5 | hold term / timing term (seeds) |"
    )
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for engine in ("reduced", "mujoco"):
        for caster in args.caster:
            sel = [r for r in rows_a if r["engine"] == engine and r["caster"] == caster]
            if not sel:
                continue
            worst = [r["max_ratio"] for r in sel]
            row = {
                "engine": engine, "caster": caster, "seeds": len(sel), "applied": sum(r["applied_s"] != 0 for r in sel),
                "max_ratio": max(worst), "median_ratio": statistics.median(worst),
                "over_1_5": sum(w > 1.5 for w in worst), "hold": sum(r["hold_term"] for r in sel),
                "timing_term": sum(r["timing_term"] for r in sel),
            }  # fmt: skip
            summary_a.append(row)
            print(
                f"| {engine} | {caster:g} | {row['seeds']} | {row['applied']} | {row['max_ratio']:.2f}; "
                f"{row['median_ratio']:.2f} | {row['over_1_5']} | {row['hold']} / {row['timing_term']} |"
            )
    print(f"\n(b) paper robot, white noise only, {args.b_duration:g} s against its first quarter")
    heads = " | ".join(f"{k} std({args.b_duration / 4:g})/std({args.b_duration:g})" for k in INERTIA)
    print(f"| trajectory | seeds | {heads} | within 3 std (all params, both lengths) |")
    print("| --- | --- | " + " | ".join("---" for _ in INERTIA) + " | --- |")
    summary_b = []
    short, long = f"{args.b_duration / 4:g}", f"{args.b_duration:g}"
    for trajectory in args.b_trajectories.split(","):
        sel = [r for r in rows_b if r["trajectory"] == trajectory]
        if not sel:
            continue
        ratios = {k: float(np.mean([r[short]["std"][k] / r[long]["std"][k] for r in sel])) for k in INERTIA}
        zs = [z for r in sel for length in (short, long) for z in r[length]["z"].values()]
        within = float(np.mean([z <= 3 for z in zs]))
        summary_b.append({"trajectory": trajectory, "seeds": len(sel), "mean_ratio": ratios, "within_3_std": within})
        cells = " | ".join(f"{ratios[k]:.2f}" for k in INERTIA)
        print(f"| {trajectory} | {len(sel)} | {cells} | {within:.2f} |")
    print(f"\n{len(rows_a) + len(rows_b)} runs, {wall:.0f} s wall")
    write_results({"args": vars(args), "a": summary_a, "b": summary_b, "wall_s": wall},
                  variant="no_reference" if args.no_reference else None)  # fmt: skip
    if args.json:
        os.makedirs(os.path.dirname(args.json) or ".", exist_ok=True)
        with open(args.json, "w") as fh:
            json.dump({"args": vars(args), "a": {"summary": summary_a, "rows": rows_a},
                       "b": {"summary": summary_b, "rows": rows_b}, "wall_s": wall}, fh, indent=1)  # fmt: skip
        print(f"written {args.json}")


if __name__ == "__main__":
    main()
