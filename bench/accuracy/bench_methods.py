"""Benchmark of the identification methods (observer, idim, rls, oe) on simulated closed-loop logs.

For each noise level and seed: simulate the ``paper`` robot (CAD plant, nominal controller) on a 40 s
sinusoid at 1 kHz, run every method (:func:`wmrid.estimators.methods.compare`) and record each base parameter's
relative error against the plant's truth and each method's run time.  Prints, per noise level and method,
the rms and worst relative error (%) of M11, M12, M22, Vc and the friction terms, and the median run time.

    /work/venv/bin/python bench/bench_methods.py                 # 10 seeds, three noise levels
    /work/venv/bin/python bench/bench_methods.py --seeds 20 --trajectory reversing
"""

from __future__ import annotations

import argparse
from types import SimpleNamespace

import numpy as np

LEVELS = {
    # name: (speed noise rad/s, torque noise N m, caster OU torque N m)
    "low": (0.001, 0.005, 0.0),
    "bench": (0.01, 0.02, 0.05),
    "high": (0.03, 0.05, 0.10),
}
GROUPS = {"M11": ["M11"], "M12": ["M12"], "M22": ["M22"], "Vc": ["Vc"], "Fv": ["Fv1", "Fv2"], "Fd": ["Fd1", "Fd2"]}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10, help="seeds per noise level (default 10)")
    ap.add_argument("--duration", type=float, default=40.0, help="log length, s (default 40)")
    ap.add_argument("--trajectory", default="sinusoid", help="sinusoid or reversing (default sinusoid)")
    ap.add_argument("--levels", nargs="+", default=list(LEVELS), help=f"noise levels of {list(LEVELS)}")
    args = ap.parse_args()

    from wmrid.estimators.methods import METHODS, compare
    from wmrid.estimators.options import MethodOptions
    from wmrid.model import dynamics as model
    from wmrid.model.robot import BUILTIN_ROBOTS
    from wmrid.pipeline.identify import identify
    from wmrid.sim.scenario import NoiseSettings
    from wmrid.sim.simulate import simulate

    robot = BUILTIN_ROBOTS["paper"]
    truth = model.named_base(model.base_parameters(robot.reference))
    print(
        f"{args.seeds} seeds per level, {args.duration:g} s {args.trajectory} at 1 kHz, closed loop (CAD plant, "
        "nominal controller); errors in % of the true value: rms / worst"
    )
    print(f"\n| noise | method | {' | '.join(GROUPS)} | run time s |")
    print("| --- | --- |" + " --- |" * (len(GROUPS) + 1))
    for level in args.levels:
        eta_std, tau_std, caster = LEVELS[level]
        noise = NoiseSettings(eta_std=eta_std, tau_std=tau_std, caster_std=caster)
        errors = {m: {g: [] for g in GROUPS} for m in METHODS}
        seconds = {m: [] for m in METHODS}
        for seed in range(1, args.seeds + 1):
            sim = simulate(robot.reference, robot.nominal, trajectory=args.trajectory, duration=args.duration,
                           noise=noise, seed=seed)  # fmt: skip
            log = SimpleNamespace(
                t=sim.t, eta=sim.eta, tau=sim.tau, source=f"seed {seed}", notes=(), reference=sim.eta_ref
            )
            observer = identify(log, robot, feedback=False)  # the observer's own estimate, as compare shows it
            data = compare(log, observer, MethodOptions(), truth=truth).to_dict()
            for m, row in data["methods"].items():
                seconds[m].append(row["seconds"])
                for g, keys in GROUPS.items():
                    errors[m][g] += [row["parameters"][k]["error_percent"] for k in keys]
        label = f"{level} ({eta_std:g} rad/s, {tau_std:g} N m, caster {caster:g} N m)"
        for m in METHODS:
            cells = []
            for g in GROUPS:
                e = np.abs(np.asarray(errors[m][g]))
                cells.append(f"{np.sqrt(np.mean(e**2)):.2g} / {e.max():.2g}")
            print(f"| {label} | {m} | {' | '.join(cells)} | {np.median(seconds[m]):.2f} |")


if __name__ == "__main__":
    main()
