"""Coverage of wmrid's standard errors over many seeds of noisy simulated logs.

    python3 bench/accuracy/bench_coverage.py                       # 50 seeds, paper sinusoid, 40 s, default noise
    python3 bench/accuracy/bench_coverage.py --trajectory reversing --seeds 50
    python3 bench/accuracy/bench_coverage.py --caster 0 --seeds 100  # sensor noise only
    python3 bench/accuracy/bench_coverage.py --robot amr --caster 0.02 --eta-noise 0.02 --tau-noise 0.01 --seeds 20
    python3 bench/accuracy/bench_coverage.py --seeds 2 --duration 10   # a quick check that it runs

For each seed: ``wmrid.simulate`` with velocity noise, torque noise and a coloured caster disturbance (an
Ornstein-Uhlenbeck torque, 0.3 s correlation, in closed loop), then ``wmrid.identify`` with the built-in robot
(``--robot``, paper by default), the wheels' friction model and otherwise default settings (``--method``: auto, the
default, or another method; ``--method observer`` keeps the observer's estimate, the closed-loop check only widening
its std).  Prints, per base parameter, how often the truth lies within +/-2 and +/-3 reported standard errors, the
mean and spread of z = (estimate - truth)/std, and the rms and worst relative error. Nominal coverage of +/-2 and
+/-3 std under Student's t with the jackknife's degrees of freedom is printed for comparison. Runs on all cores
(seeded, so the same numbers every time). Also counts the seeds whose std wmrid widened for model error,
discretisation or low-speed friction (docs/explanation/uncertainty.md).  Figures: bench/results/bench_coverage.json.

(Before the bench used only the public API, ``--no-feedback`` ran the observer without the closed-loop check at
all, the "before" of docs/explanation/checks.md; the public API always runs the check.)
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

import wmrid

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # bench/: the shared module _common
from _common import write_results

#: The base parameters theta0, in order.
BASE = ("m11", "m12", "m22", "Vc", "Fv1", "Fv2", "Fd1", "Fd2")
ROBOTS = ("paper", "amr", "heavy")


def one_seed(seed: int, args: argparse.Namespace) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, dict, dict]:
    noise = wmrid.NoiseSettings(
        eta_std=args.eta_noise, tau_std=args.tau_noise, caster_std=args.caster, caster_time=args.caster_time,
        seed=seed,
    )  # fmt: skip
    run = wmrid.simulate(args.robot, trajectory=args.trajectory, duration=args.duration, noise=noise)
    log = run.to_wheel_log()
    if not args.reference:
        log = dataclasses.replace(log, reference=None)
    options = wmrid.ObserverOptions(friction="wheel", **({} if args.k is None else {"k": args.k}))
    result = wmrid.identify(log, args.robot, method=args.method, observer=options)
    truth = run.truth["parameters"]
    value = np.array([result.parameters[n][0] for n in BASE])
    std = np.array([result.parameters[n][1] for n in BASE])
    unc = result.diagnostics.to_dict()["uncertainty"]["model_error"]
    widened = {
        "scale": unc["applied"], "discretisation": bool((unc.get("discretisation") or {}).get("applied")),
        "low-speed": bool(unc["slow_speed"].get("applied") or unc["slow_speed"].get("fragile")),
    }  # fmt: skip
    flagged = np.array([n in set(result.diagnostics.flagged or ()) for n in BASE])
    extra = {"method": result.method, "flagged": flagged}
    dof = result.diagnostics.uncertainty.dof
    return value, std, np.array([truth[n] for n in BASE]), dof, widened, extra


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seeds", type=int, default=50)
    parser.add_argument("--robot", default="paper", choices=ROBOTS, help="built-in robot")
    parser.add_argument("--trajectory", default="sinusoid", choices=["sinusoid", "reversing"])
    parser.add_argument("--duration", type=float, default=40.0)
    parser.add_argument("--eta-noise", type=float, default=0.01, help="rad/s")
    parser.add_argument("--tau-noise", type=float, default=0.02, help="N m")
    parser.add_argument("--caster", type=float, default=0.05, help="N m")
    parser.add_argument("--caster-time", type=float, default=0.3, help="s")
    parser.add_argument("--k", type=float, default=None, help="observer gain (default: wmrid's)")
    parser.add_argument("--reference", action="store_true", help="give identify the reference wheel speeds")
    parser.add_argument("--method", default="auto", help="identify's method (default auto)")
    args = parser.parse_args()

    from scipy.special import stdtr

    start = time.perf_counter()
    with ProcessPoolExecutor(max_workers=os.cpu_count()) as pool:
        rows = list(pool.map(one_seed, range(args.seeds), [args] * args.seeds))
    wall = time.perf_counter() - start
    value = np.array([r[0] for r in rows])
    std = np.array([r[1] for r in rows])
    truth = np.array([r[2] for r in rows])
    dof = rows[0][3]
    z = (value - truth) / std
    rel = (value - truth) / truth
    print(
        f"{args.seeds} seeds, {args.trajectory}, {args.duration:g} s at 1 kHz, eta noise {args.eta_noise} rad/s, "
        f"tau noise {args.tau_noise} N m, caster {args.caster} N m / {args.caster_time} s; {wall:.1f} s wall"
    )
    two, three = 2 * stdtr(dof, 2.0) - 1, 2 * stdtr(dof, 3.0) - 1
    print(f"nominal coverage with t({dof}): +/-2 std {two:.3f}, +/-3 std {three:.3f}")
    print("| param | within 2 std | within 3 std | mean z | std z | rms rel err % | worst rel err % |")
    print("|---|---|---|---|---|---|---|")
    for j, name in enumerate(BASE):
        zz = z[:, j]
        print(
            f"| {name} | {np.mean(np.abs(zz) < 2):.2f} | {np.mean(np.abs(zz) < 3):.2f} | {zz.mean():+.2f} | "
            f"{zz.std():.2f} | {100 * np.sqrt(np.mean(rel[:, j] ** 2)):.3g} | {100 * np.max(np.abs(rel[:, j])):.3g} |"
        )
    print(f"| all | {np.mean(np.abs(z) < 2):.3f} | {np.mean(np.abs(z) < 3):.3f} | | | | |")
    flagged = np.array([r[5]["flagged"] for r in rows])
    methods = [r[5]["method"] for r in rows]
    print(
        "reported by: "
        + ", ".join(f"{m} {methods.count(m)}" for m in sorted(set(methods)))
        + "; within 3 std or flagged: "
        + ", ".join(f"{n} {np.mean((np.abs(z[:, j]) < 3) | flagged[:, j]):.2f}" for j, n in enumerate(BASE))
    )
    widened = [r[4] for r in rows]
    counts = ", ".join(f"{key} {sum(w[key] for w in widened)}" for key in widened[0])
    print(
        f"seeds whose std was widened (docs/explanation/uncertainty.md): {sum(any(w.values()) for w in widened)} of "
        f"{args.seeds} ({counts}); median std of m11 {100 * np.median(std[:, 0] / np.abs(value[:, 0])):.3g} %"
    )
    per_parameter = {}
    for j, name in enumerate(BASE):
        zz, rr = z[:, j], rel[:, j]
        per_parameter[name] = {
            "within_2_std": np.mean(np.abs(zz) < 2), "within_3_std": np.mean(np.abs(zz) < 3), "mean_z": zz.mean(),
            "std_z": zz.std(), "rms_relative_error_percent": 100 * np.sqrt(np.mean(rr**2)),
            "worst_relative_error_percent": 100 * np.max(np.abs(rr)),
            "within_3_std_or_flagged": np.mean((np.abs(zz) < 3) | flagged[:, j]),
        }  # fmt: skip
    write_results({
        "settings": vars(args), "wall_s": wall, "dof": dof, "nominal_coverage": {"2_std": two, "3_std": three},
        "parameters": per_parameter,
        "all": {"within_2_std": np.mean(np.abs(z) < 2), "within_3_std": np.mean(np.abs(z) < 3)},
        "reported_by": {m: methods.count(m) for m in sorted(set(methods))},
        "widened": {"seeds": sum(any(w.values()) for w in widened),
                    **{key: sum(w[key] for w in widened) for key in widened[0]}},
        "median_relative_std_m11_percent": 100 * np.median(std[:, 0] / np.abs(value[:, 0])),
    })  # fmt: skip


if __name__ == "__main__":
    main()
