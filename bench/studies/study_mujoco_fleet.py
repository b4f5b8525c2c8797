"""The fleet report on logs of the MuJoCo multibody prototype (docs/how-to/fleet-dask.md): physics wmrid's reduced
model did not derive, casters' rolling drag included.

    python3 bench/studies/study_mujoco_fleet.py                   # seed 17: ~8 min of simulation, then ~15 s
    python3 bench/studies/study_mujoco_fleet.py --seed-base 18    # another draw of the same fleet

1. Generates 6 paper-robot units x 24 days, one 30 s log a day at 200 Hz (``wmrid.simulate(..., engine="mujoco",
   caster_resistance=0.015)``), with speed/bench_fleet.py's unit-to-unit and day-to-day spreads and noise
   (``_common.unit_robot``, ``_common.day_robot``), as ``DIR/R02/2026-01-13.parquet``.  Injected: the right wheel
   of R02, F_v1 and F_d1 +4 %/day from day 12 (+44 % by the last log); R04 carries 10 kg at (0.05, -0.03) m from
   day 16 (2026-01-17).  Nothing else changes.  Logs already in DIR are kept (a second run only reviews).
2. Identifies them (``wmrid fleet --robot paper --control-rate 1000 --workers 1``) and reviews the table
   (``wmrid fleet-report``), as JSON next to the table; prints every robot's verdict and findings, the largest
   evidence among the unchanged robots, and each robot's log-to-log scatter of F_v, F_d and F_w = F_d + w F_v over
   its first 10 logs (relative std, %), and the median reported std / value of F_v and F_d.
3. Reviews the same table without the four schema-2 columns (a schema-1 table: no wheel speeds, so no F_w).

Seeded throughout (numpy PCG64 [seed, unit, day]).  Figures: bench/results/study_mujoco_fleet.json.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import subprocess
import sys
import time
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # bench/: the shared module _common
from _common import (
    FLEET_START as START,
    OUT,
    WHEEL_COLUMNS,
    day_robot,
    unit_robot,
    wmrid_cmd,
    write_log,
    write_results,
)

DRIFTS = {"R02": ("right", 0.04, 12)}  # robot: (wheel, relative rise per day, onset day)
PAYLOAD = {"R04": (10.0, 0.05, -0.03, 16)}  # robot: (kg, x m, y m, from day)


def generate(folder: Path, units: int, days: int, seed: int) -> None:
    import wmrid

    t0, made = time.perf_counter(), 0
    for u in range(units):
        robot_id = f"R{u + 1:02d}"
        unit = unit_robot(np.random.Generator(np.random.PCG64([seed, u])), robot_id)
        (folder / robot_id).mkdir(parents=True, exist_ok=True)
        for day in range(days):
            path = folder / robot_id / f"{START + dt.timedelta(days=day)}.parquet"
            if path.exists():
                continue
            rng = np.random.Generator(np.random.PCG64([seed, u, day]))
            robot = day_robot(unit, rng, robot_id, day, DRIFTS)
            payload = None
            if robot_id in PAYLOAD and day >= PAYLOAD[robot_id][3]:
                mass, x, y, _ = PAYLOAD[robot_id]
                payload = wmrid.Payload(mass, x, y)
            noise = wmrid.NoiseSettings(eta_std=0.01, tau_std=0.02, seed=int(rng.integers(2**31)))
            run = wmrid.simulate(robot, duration=30.0, rate=200.0, noise=noise, payload=payload,
                                 engine=wmrid.MultibodySettings(caster_resistance=0.015))  # fmt: skip
            write_log(run.to_frame()[WHEEL_COLUMNS], path, run.truth)
            made += 1
    print(f"generated {made} logs in {time.perf_counter() - t0:.0f} s into {folder}", flush=True)


def review(table: Path, out: Path) -> dict:
    subprocess.run([*wmrid_cmd(), "fleet-report", str(table), "--robot", "paper", "-o", str(out), "--force"],
                   check=True, capture_output=True)  # fmt: skip
    return json.loads(out.read_text())


def scatter(table: Path) -> dict:
    import pyarrow.parquet as pq

    t = pq.read_table(table).to_pandas().sort_values(["robot_id", "start_time"])
    print("baseline scatter (first 10 logs), relative std %; median reported std / value:")
    out = {}
    for robot_id, g in t.groupby("robot_id"):
        b = g.iloc[:10]
        parts = []
        for wheel, (fv, fd, speed) in enumerate((("Fv1", "Fd1", "speed_r"), ("Fv2", "Fd2", "speed_l")), 1):
            fw = b[fd] + np.median(b[speed]) * b[fv]

            def rel(x):
                return 100 * np.std(x, ddof=1) / abs(np.mean(x))

            ratio = [np.median(b[f"{n}_std"] / b[n].abs()) for n in (fv, fd)]
            out[f"{robot_id} wheel {wheel}"] = {
                "Fv": rel(b[fv]), "Fd": rel(b[fd]), "Fw": rel(fw), "std_over_value_Fv": ratio[0],
                "std_over_value_Fd": ratio[1],
            }  # fmt: skip
            parts.append(f"wheel {wheel}: Fv {rel(b[fv]):4.1f} Fd {rel(b[fd]):4.1f} Fw {rel(fw):4.2f} "
                         f"(std/value Fv {ratio[0]:.1f}, Fd {ratio[1]:.1f})")  # fmt: skip
        print(f"  {robot_id}  " + "   ".join(parts))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--dir", type=Path, default=None, help="logs folder (default bench/out/mujoco_fleet_SEED)")
    ap.add_argument("--seed-base", type=int, default=17)
    ap.add_argument("--units", type=int, default=6)
    ap.add_argument("--days", type=int, default=24)
    args = ap.parse_args()
    folder = args.dir or OUT / f"mujoco_fleet_{args.seed_base}"
    generate(folder, args.units, args.days, args.seed_base)
    table = folder.with_suffix(".parquet")
    subprocess.run([*wmrid_cmd(), "fleet", str(folder), "--robot", "paper", "--control-rate", "1000", "--workers", "1",
                    "-o", str(table), "--force"], check=True, capture_output=True)  # fmt: skip
    report = review(table, folder.with_suffix(".json"))
    unchanged = []
    for robot in report["robots"]:
        if robot["robot_id"] not in DRIFTS and robot["robot_id"] not in PAYLOAD:
            unchanged.append(robot["evidence"])
        print(f"{robot['robot_id']}: {'FLAGGED' if robot['flagged'] else 'not flagged'} "
              f"(evidence {robot['evidence']:.3f})")  # fmt: skip
        for finding in robot["findings"]:
            print(f"    {finding}")
    print(f"largest evidence among the unchanged robots: {max(unchanged):.3f}")
    spread = scatter(table)

    import pyarrow.parquet as pq

    old = pq.read_table(table).drop_columns(["speed_r", "speed_l", "Fv1_Fd1_corr", "Fv2_Fd2_corr"])
    old = old.replace_schema_metadata({**(old.schema.metadata or {}), b"wmrid_fleet_schema": b"1"})
    schema1 = folder.parent / f"{folder.name}_schema1.parquet"
    pq.write_table(old, schema1)
    flagged = [r["robot_id"] for r in review(schema1, schema1.with_suffix(".json"))["robots"] if r["flagged"]]
    print(f"the same logs as a schema-1 table (no wheel speeds): flagged {', '.join(flagged) or 'none'}")
    write_results({
        "settings": vars(args), "robots": {r["robot_id"]: {"flagged": r["flagged"], "evidence": r["evidence"],
                                                            "findings": r["findings"]} for r in report["robots"]},
        "largest_unchanged_evidence": max(unchanged), "baseline_scatter_percent": spread,
        "schema1_flagged": flagged,
    })  # fmt: skip


if __name__ == "__main__":
    main()
