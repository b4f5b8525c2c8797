"""Encoder logs: the paper sinusoid with speeds derived from quantised wheel positions (issue 28, item 5).

    python3 bench/studies/study_encoder.py                   # 2048 and 512 counts/rev, 10 seeds, reduced simulator
    python3 bench/studies/study_encoder.py --engine mujoco --cpr 2048 --seeds 3   # the MuJoCo multibody prototype
    python3 bench/studies/study_encoder.py --cpr 2048 --seeds 1 --duration 10     # a check that it runs

For each counts-per-revolution and seed: the paper robot (CAD true, nominal in the controller) tracks the sinusoid
for 40 s, logged at 1 kHz without sensor noise; its wheel angles are quantised as an encoder counts them (the count
boundaries offset by a seeded uniform draw per wheel: tests/encoder_log.py) and written as an MCAP holding only the
positions and the efforts; ``wmrid.identify(path, "paper")`` reads it with defaults (speeds from the positions) and
identifies it.  Printed per counts/rev: the worst |error| % over seeds of the inertia entries (m11 m12 m22 M11 M12
M22) and of Vc, the share of seeds honest for them (truth within 3 std, or flagged), the method reported, and the
closed-loop check's verdicts.  Figures: bench/results/study_encoder.json (with ``--json PATH`` the per-seed figures
too).  Seeded: the same numbers every time; ``--workers`` processes (default 2).
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # bench/: the shared module _common
from _common import ROOT, write_results

sys.path.insert(0, str(ROOT))  # tests/encoder_log.py: the tests' positions-only MCAP writer
INERTIA = ("m11", "m12", "m22", "M11", "M12", "M22")
JUDGED = (*INERTIA, "Vc")


def one(job: tuple[int, int, str, float]) -> dict:
    import wmrid
    from tests.encoder_log import encoder_mcap

    cpr, seed, engine, duration = job
    # frictionless casters: no disturbance at all
    settings = wmrid.MultibodySettings(caster_resistance=0.0) if engine == "mujoco" else engine
    run = wmrid.simulate("paper", duration=duration, engine=settings, noise=wmrid.NoiseSettings(seed=seed))
    truth = run.truth["parameters"]
    with tempfile.TemporaryDirectory() as tmp:
        path = encoder_mcap(Path(tmp) / "encoder.mcap", run.log, cpr, seed)
        res = wmrid.identify(str(path), "paper")
    flagged = set(res.diagnostics.to_dict().get("flagged", []))
    err = {n: 100.0 * (res.parameters[n][0] / truth[n] - 1.0) for n in JUDGED}
    z = {n: (res.parameters[n][0] - truth[n]) / res.parameters[n][1] for n in JUDGED}
    fb = res.diagnostics.to_dict().get("feedback") or {}
    idim = (res.diagnostics.to_dict().get("method") or {}) if res.method != "observer" else {}
    delay = res.diagnostics.to_dict().get("delay") or {}
    return {
        "cpr": cpr, "seed": seed, "engine": engine, "reported": res.method, "error_percent": err, "z": z,
        "flagged": sorted(flagged & set(JUDGED)),
        "honest": {n: bool(abs(z[n]) <= 3.0 or n in flagged) for n in JUDGED},
        "feedback": {k: fb.get(k) for k in ("checked", "applied", "largest", "largest_ratio", "gate",
                                            "other_systematic", "widened")},
        "idim_cutoff_hz": idim.get("cutoff_hz"),
        "delay_applied_s": delay.get("applied_s"),
    }  # fmt: skip


def summary(rows: list[dict]) -> dict:
    inertia = max(abs(r["error_percent"][n]) for r in rows for n in INERTIA)
    vc = max(abs(r["error_percent"]["Vc"]) for r in rows)
    honest = sum(all(r["honest"].values()) for r in rows) / len(rows)
    reported: dict[str, int] = {}
    for r in rows:
        reported[r["reported"]] = reported.get(r["reported"], 0) + 1
    return {
        "seeds": len(rows), "max_inertia_error_percent": inertia, "max_vc_error_percent": vc,
        "share_honest": honest, "reported": reported,
        "check_applied": sum(bool(r["feedback"]["applied"]) for r in rows),
        "all_flagged": sum(len(r["flagged"]) == len(JUDGED) for r in rows),
        "delay_applied": sum(r["delay_applied_s"] not in (None, 0.0) for r in rows),
    }  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cpr", default="2048,512", help="counts per revolution, comma-separated")
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--engine", default="reduced", choices=["reduced", "mujoco"])
    ap.add_argument("--duration", type=float, default=40.0)
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--json", type=Path, default=None, help="write the summary and per-seed figures here")
    args = ap.parse_args()
    cprs = [int(c) for c in args.cpr.split(",")]
    jobs = [(c, s, args.engine, args.duration) for c in cprs for s in range(args.seeds)]
    start = time.perf_counter()
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        rows = list(pool.map(one, jobs))
    out = {"engine": args.engine, "duration_s": args.duration, "per_cpr": {}, "rows": rows}
    print(f"paper sinusoid, {args.duration:g} s at 1 kHz, engine {args.engine}, speeds from encoder positions "
          f"(MCAP, positions only), {args.seeds} seeds; {time.perf_counter() - start:.0f} s wall")  # fmt: skip
    print("| counts/rev | max inertia err % | max Vc err % | honest | reported | check switched | all flagged |"
          " delay applied |")  # fmt: skip
    print("|---|---|---|---|---|---|---|---|")
    for c in cprs:
        s = summary([r for r in rows if r["cpr"] == c])
        out["per_cpr"][str(c)] = s
        rep = ", ".join(f"{k} {v}" for k, v in sorted(s["reported"].items()))
        print(
            f"| {c} | {s['max_inertia_error_percent']:.3f} | {s['max_vc_error_percent']:.3f} | "
            f"{s['share_honest']:.0%} | {rep} | {s['check_applied']} | {s['all_flagged']} | {s['delay_applied']} |"
        )
    write_results({k: v for k, v in out.items() if k != "rows"})
    if args.json is not None:
        args.json.write_text(json.dumps(out, indent=1, default=float))


if __name__ == "__main__":
    main()
