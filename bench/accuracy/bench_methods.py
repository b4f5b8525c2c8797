"""Benchmark of the identification methods (observer, idim, rls, oe) on simulated closed-loop logs.

For each noise level and seed: simulate the ``paper`` robot (CAD plant, nominal controller) on a 40 s
sinusoid at 1 kHz (``wmrid.simulate``), run every method on it (``wmrid.compare``, with the wheels' friction model,
the observer's own estimate shown as it is) and record each base parameter's relative error against the plant's
truth and each method's run time.  Prints, per noise level and method, the rms and worst relative error (%) of M11,
M12, M22, Vc and the friction terms, and the median run time; writes them to bench/results/bench_methods.json.
(Before the bench used only the public API the observer's run was made without the closed-loop check, which
``compare`` runs and which widens only the observer's std, never its estimate: the errors are the same.)

    python3 bench/accuracy/bench_methods.py                 # 10 seeds, three noise levels
    python3 bench/accuracy/bench_methods.py --seeds 20 --trajectory reversing
    python3 bench/accuracy/bench_methods.py --seeds 1 --duration 10 --levels bench   # a quick check that it runs
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # bench/: the shared module _common
from _common import write_results

LEVELS = {
    # name: (speed noise rad/s, torque noise N m, caster OU torque N m)
    "low": (0.001, 0.005, 0.0),
    "bench": (0.01, 0.02, 0.05),
    "high": (0.03, 0.05, 0.10),
}
GROUPS = {"M11": ["M11"], "M12": ["M12"], "M22": ["M22"], "Vc": ["Vc"], "Fv": ["Fv1", "Fv2"], "Fd": ["Fd1", "Fd2"]}


def _pct(x: float) -> str:
    """A percentage to two significant figures, without an exponent (170, not 1.7e+02)."""
    return f"{x:.0f}" if x >= 100 else f"{x:.2g}"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=10, help="seeds per noise level (default 10)")
    ap.add_argument("--duration", type=float, default=40.0, help="log length, s (default 40)")
    ap.add_argument("--trajectory", default="sinusoid", help="sinusoid or reversing (default sinusoid)")
    ap.add_argument("--levels", nargs="+", default=list(LEVELS), help=f"noise levels of {list(LEVELS)}")
    args = ap.parse_args()

    import wmrid

    print(
        f"{args.seeds} seeds per level, {args.duration:g} s {args.trajectory} at 1 kHz, closed loop (CAD plant, "
        "nominal controller); errors in % of the true value: rms / worst"
    )
    # the table as printed, kept for docs/explanation/methods.md (rendered from the results file)
    lines = [f"| noise | method | {' | '.join(GROUPS)} | run time s |", "| --- | --- |" + " --- |" * (len(GROUPS) + 1)]
    print("\n" + "\n".join(lines))
    table = []
    for level in args.levels:
        eta_std, tau_std, caster = LEVELS[level]
        errors: dict[str, dict[str, list[float]]] = {}
        seconds: dict[str, list[float]] = {}
        for seed in range(1, args.seeds + 1):
            noise = wmrid.NoiseSettings(eta_std=eta_std, tau_std=tau_std, caster_std=caster, seed=seed)
            run = wmrid.simulate("paper", trajectory=args.trajectory, duration=args.duration, noise=noise)
            data = wmrid.compare(
                run.to_wheel_log(), "paper", observer=wmrid.ObserverOptions(friction="wheel"),
                truth=run.truth["parameters"],
            ).to_dict()  # fmt: skip
            for m, row in data["methods"].items():
                seconds.setdefault(m, []).append(row["seconds"])
                for g, keys in GROUPS.items():
                    errors.setdefault(m, {k: [] for k in GROUPS})[g] += [
                        row["parameters"][k]["error_percent"] for k in keys
                    ]
        label = f"{level} ({eta_std:g} rad/s, {tau_std:g} N m, caster {caster:g} N m)"
        for m in errors:
            cells, figures = [], {}
            for g in GROUPS:
                e = np.abs(np.asarray(errors[m][g]))
                rms, worst = float(np.sqrt(np.mean(e**2))), float(e.max())
                cells.append(f"{_pct(rms)} / {_pct(worst)}")
                figures[g] = {"rms_percent": rms, "worst_percent": worst}
            run_time = float(np.median(seconds[m]))
            lines.append(f"| {label} | {m} | {' | '.join(cells)} | {run_time:.2f} |")
            print(lines[-1])
            table.append({"level": level, "noise": {"eta_std": eta_std, "tau_std": tau_std, "caster_std": caster},
                          "method": m, "errors": figures, "median_seconds": run_time})  # fmt: skip
    write_results({"seeds": args.seeds, "duration_s": args.duration, "trajectory": args.trajectory, "rows": table,
                   "page_table": "\n".join(lines)})  # fmt: skip


if __name__ == "__main__":
    main()
