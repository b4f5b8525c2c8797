"""Issue 34's round trip: identify a MuJoCo log of the light AMR with a payload, export it, simulate the export,
identify again -- does the export carry the robot?

    python3 bench/studies/study_export_roundtrip.py               # seeds 0-2
    python3 bench/studies/study_export_roundtrip.py --seeds 1 --payload 3@0.05,-0.02   # one seed

Per seed: the light AMR of ``bench/studies/study_plan.py`` (nominal set 20 % off, CAD set the truth, its casters)
carrying ``--payload`` (kg @ x, y m in the platform frame), driven on the MuJoCo prototype along the study's 60 s plan
at 1 kHz with sensor noise (0.02 rad/s, 0.005 N m), identified with defaults; exported (``wmrid.export``) as MJCF and
as a robot file (the file builds the same MJCF: tests/unit/exports/test_export.py); the robot file simulated again on
MuJoCo along the same plan (another noise seed) and identified with the original robot file.  Recorded:

* the second result's base parameters against the first's: z = (second - first) / sqrt(std1^2 + std2^2);
* the exported physical quantities against the truth (the AMR with its payload, :func:`physical_truth`): total mass
  m, yaw inertia about the axle midpoint I, the platform's centre of mass (d_x, d_y), mass m_p and yaw inertia I_p:
  z = (exported - truth) / std.

Figures: ``bench/results/study_export_roundtrip.json``; the files made in ``bench/out/study_export_roundtrip/``.
Seeded throughout.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # bench/: the shared module _common
import study_plan  # the AMR robot file and plan of the closed-loop study (this folder)
from _common import OUT as BENCH_OUT, write_results

OUT = BENCH_OUT / "study_export_roundtrip"
BASE = study_plan.BASE


def physical_truth(p) -> dict[str, float]:
    """The quantities an export states, of the physical parameters ``p`` (the robot with its payload): the total mass
    m = m_p + 2 m_w + 2 m_r; the yaw inertia about the axle midpoint I = I_p + m_p (d_x^2 + d_y^2) + 2 (I_wm + m_w a^2)
    + 2 (I_rm + m_r (c_x^2 + c_y^2)); the platform's own m_p, d_x, d_y and I_p (what wmrid.export's documentation
    defines them as; before the bench used only the public API it took them through the inertia matrix M and V_c)."""
    return {
        "m": p.m_p + 2.0 * p.m_w + 2.0 * p.m_r,
        "I": p.I_p + p.m_p * (p.d_x**2 + p.d_y**2) + 2.0 * (p.I_wm + p.m_w * p.a**2)
        + 2.0 * (p.I_rm + p.m_r * (p.c_x**2 + p.c_y**2)),
        "d_x": p.d_x, "d_y": p.d_y, "m_p": p.m_p, "I_p": p.I_p,
    }  # fmt: skip


def run(seed: int, payload: str) -> dict:
    import numpy as np

    import wmrid

    spec = study_plan.ROBOTS["amr"]
    robot = study_plan.OUT / "amr_20pc.toml"
    plan = study_plan.OUT / "amr_plan.csv"
    if not robot.exists() or not plan.exists():
        study_plan.make("amr")
    OUT.mkdir(parents=True, exist_ok=True)
    noise = {"eta_std": spec["eta_noise"], "tau_std": spec["tau_noise"]}
    first_sim = wmrid.simulate(
        str(robot),
        engine="mujoco",
        trajectory=str(plan),
        rate=1000.0,
        payload=wmrid.Payload.parse(payload),
        noise=wmrid.NoiseSettings(seed=seed, **noise),
    )
    first = wmrid.identify(first_sim.log.to_wheel_log(), str(robot))
    saved = OUT / f"first_{seed}.json"
    saved.write_text(json.dumps(first.to_dict(history=False), default=float))
    exported = wmrid.export(str(saved), str(robot), OUT / f"identified_{seed}.toml", force=True)
    wmrid.export(str(saved), str(robot), OUT / f"identified_{seed}.xml", force=True)
    second_sim = wmrid.simulate(
        str(OUT / f"identified_{seed}.toml"),
        engine="mujoco",
        trajectory=str(plan),
        rate=1000.0,
        noise=wmrid.NoiseSettings(seed=seed + 100, **noise),
    )
    second = wmrid.identify(second_sim.log.to_wheel_log(), str(robot))
    base = {}
    for p in BASE:
        (v1, s1), (v2, s2) = first.parameters[p], second.parameters[p]
        base[p] = {"first": v1, "first_std": s1, "second": v2, "second_std": s2,
                   "z": (v2 - v1) / float(np.hypot(s1, s2))}  # fmt: skip
    truth = physical_truth(wmrid.load_robot(str(robot)).cad.with_payload(wmrid.Payload.parse(payload)))
    physical = {}
    for name, value in truth.items():
        q = exported.physical.quantities[name]
        physical[name] = {"exported": q.value, "std": q.std, "truth": float(value),
                          "z": (q.value - float(value)) / q.std if q.std > 0 else None}  # fmt: skip
    return {
        "seed": seed, "payload": payload, "first_friction_model": first.form.friction,
        "second_friction_model": second.form.friction, "first_poorly": list(first.diagnostics.poorly_determined or ()),
        "second_poorly": list(second.diagnostics.poorly_determined or ()), "base": base, "physical": physical,
    }  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--payload", default="3@0.05,-0.02")
    args = ap.parse_args()
    rows = []
    for seed in range(args.seeds):
        row = run(seed, args.payload)
        rows.append(row)
        worst_base = max(BASE, key=lambda p: abs(row["base"][p]["z"]))
        worst_phys = max(row["physical"], key=lambda n: abs(row["physical"][n]["z"] or 0.0))
        print(f"seed {seed}: second vs first, worst |z| {abs(row['base'][worst_base]['z']):.2f} ({worst_base}); "
              f"exported vs truth, worst |z| {abs(row['physical'][worst_phys]['z']):.2f} ({worst_phys}); "
              + ", ".join(f"{n} {v['exported']:.4g} (truth {v['truth']:.4g}, std {v['std']:.2g})"
                          for n, v in row["physical"].items()), flush=True)  # fmt: skip
    write_results({"args": vars(args), "rows": rows})


if __name__ == "__main__":
    sys.exit(main())
