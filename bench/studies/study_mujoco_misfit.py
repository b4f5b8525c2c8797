"""Issue 29: why a plan's MuJoCo log does not determine the robot -- the caster's drag, its load transfer, or neither?

    python3 bench/studies/study_mujoco_misfit.py                  # paper + light AMR, 3 variants, seeds 0-2
    python3 bench/studies/study_mujoco_misfit.py --robots amr --seeds 1
    python3 bench/studies/study_mujoco_misfit.py --robots amr --variants default --seeds 1   # a check that it runs

The plans and robot files of ``bench/studies/study_plan.py`` (made by it when missing: the nominal set 20 % off, 60 s
in a 4 m x 4 m area), driven on the MuJoCo prototype at 1 kHz with the study's sensor noise, in three variants:

* ``default``: the prototype as ``wmrid simulate --engine mujoco`` builds it (ball casters with rolling resistance
  0.015, the platform's centre of mass 0.05 m above the axle);
* ``no_load_transfer``: the centre of mass lowered to the ground (``cg_height = -r``), so accelerating does not
  move load between the wheels and the casters -- the casters' drag keeps a constant size, as the
  ``wheel+caster`` model assumes;
* ``frictionless_casters``: caster resistance 0 (no drag at all).

Each log is identified with defaults (``--friction auto``; a comma list, e.g. ``wheel+caster,auto``, identifies each
log once per model).  Recorded per run: the friction model chosen, the model-error scale S and
its T^2, the largest relative misfit of the intermediate parameters, whether the low-speed term and the
"fragile" rule applied, the poorly determined parameters, and per base parameter its error (% of the truth) and
z = error / std; the caster parameters (D_k, and the load terms D{k}dv, D{k}w2, ... of ``wheel+caster+load``) with
their truth from the engine: each ball caster's contact normal force at every logged sample (the engine's own, the
run's ``log.caster_load``) fitted by least squares on 1, v', w^2, v w, w' (from the true wheel speeds, a 41-sample
Savitzky-Golay derivative), times its rolling resistance, summed over the casters that share a parameter (mirrored
about the platform's x axis: :func:`caster_keys`); ``load_fit_rms_N`` is that fit's residual.  Figures:
``bench/results/study_mujoco_misfit.json``.  Seeded throughout.

    python3 bench/studies/study_mujoco_misfit.py --friction wheel+caster,auto      # before / after the load terms
"""

from __future__ import annotations

import argparse
import dataclasses
import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # bench/: the shared module _common
import study_plan  # the plans and robot files of the closed-loop study (this folder)
from _common import write_results

VARIANTS = ("default", "no_load_transfer", "frictionless_casters")
#: The platform motions a caster's normal load follows, as the ``wheel+caster+load`` model names its load terms.
LOAD_SIGNALS = ("dv", "w2", "vw", "dw")


def caster_keys(robot) -> list[tuple[float, float]]:
    """(|x|, y) of each caster parameter D_k, k = 1, 2, ...: casters at (x, y) and (-x, y) have the same drag columns
    (their contacts' velocities mirror each other about the platform's x axis), so one parameter stands for their
    total drag (casters within 1 mm count as one position)."""
    keys: list[tuple[float, float]] = []
    for c in robot.casters or ():
        key = (abs(c.x), c.y)
        if not any(abs(key[0] - k[0]) < 1e-3 and abs(key[1] - k[1]) < 1e-3 for k in keys):
            keys.append(key)
    return keys


def load_truth(robot, sim, normals: np.ndarray, resistance: list[float]) -> dict:
    """The truth of D_k and its load terms (module docstring), named as the ``wheel+caster+load`` model names them."""
    from scipy.signal import savgol_filter

    p = robot.reference
    t = np.asarray(sim.t)
    eta = np.asarray(sim.eta_true)
    v, w = 0.5 * p.r * (eta[:, 0] + eta[:, 1]), p.r / (2.0 * p.b) * (eta[:, 0] - eta[:, 1])
    dv, dw = (savgol_filter(x, 41, 3, deriv=1, delta=t[1] - t[0]) for x in (v, w))
    x = np.column_stack([np.ones_like(v), dv, w * w, v * w, dw])
    keys = caster_keys(robot)
    out: dict[str, float] = {}
    rms = 0.0
    for i, c in enumerate(robot.casters):
        coef, *_ = np.linalg.lstsq(x, normals[:, i], rcond=None)
        rms = max(rms, float(np.std(normals[:, i] - x @ coef)))
        k = next(j for j, key in enumerate(keys) if abs(key[0] - abs(c.x)) < 1e-3 and abs(key[1] - c.y) < 1e-3)
        for name, value in zip(("", *LOAD_SIGNALS), coef, strict=True):
            out[f"D{k + 1}{name}"] = out.get(f"D{k + 1}{name}", 0.0) + resistance[i] * float(value)
    return {"parameters": out, "load_fit_rms_N": rms}


def run(name: str, variant: str, seed: int, frictions: tuple[str, ...] = ("auto",)) -> list[dict]:
    import wmrid

    spec = study_plan.ROBOTS[name]
    robot_path = study_plan.OUT / f"{name}_20pc.toml"
    csv = study_plan.OUT / f"{name}_plan.csv"
    if not robot_path.exists() or not csv.exists():
        study_plan.make(name)
    robot = wmrid.load_robot(str(robot_path))
    settings = wmrid.MultibodySettings()
    if variant == "no_load_transfer":
        settings = dataclasses.replace(settings, cg_height=-robot.reference.r)
    elif variant == "frictionless_casters":
        settings = dataclasses.replace(settings, caster_resistance=0.0)
    noise = wmrid.NoiseSettings(eta_std=spec["eta_noise"], tau_std=spec["tau_noise"], seed=seed)
    run_ = wmrid.simulate(robot, engine=settings, rate=1000.0, noise=noise, trajectory=wmrid.load_reference(str(csv)))
    sim, normals = run_.log, run_.log.caster_load
    truth = run_.truth
    casters = truth["settings"]["multibody"]["casters"]
    drag = [c.get("mean_drag_force") for c in casters]
    caster_truth = load_truth(robot, sim, normals, [c["resistance_used"] for c in casters])
    rows = []
    for friction in frictions:
        result = wmrid.identify(sim.to_wheel_log(), str(robot_path), observer=wmrid.ObserverOptions(friction=friction))
        diag = result.diagnostics.to_dict()
        error = diag["uncertainty"]["model_error"]
        params = {}
        for p in study_plan.BASE:
            value, std = result.parameters[p]
            true = truth["parameters"][p]
            params[p] = {"value": value, "std": std, "truth": true, "error_pc": 100 * (value - true) / abs(true),
                         "z": (value - true) / std if std else None}  # fmt: skip
        extra = {}
        for p in result.form.base_names[8:]:
            value, std = result.parameters[p]
            true = caster_truth["parameters"].get(p)
            extra[p] = {"value": value, "std": std, "truth": true}
        rows.append({
            "robot": name, "variant": variant, "seed": seed, "friction": friction,
            "friction_model": result.form.friction, "friction_text": diag["friction"].get("text"),
            "friction_record": diag["friction"], "caster_drag_truth_N": drag,
            "scale": error["scale"], "T2": error["T2"], "relative_misfit": error["relative_misfit"],
            "slow_applied": error["slow_speed"]["applied"], "slow_left_out": error["slow_speed"]["left_out_fraction"],
            "fragile": error["slow_speed"]["fragile"], "poorly": list(diag.get("poorly_determined", [])),
            "parameters": params, "caster_parameters": extra, "load_fit_rms_N": caster_truth["load_fit_rms_N"],
        })  # fmt: skip
    return rows


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--robots", default="paper,amr")
    ap.add_argument("--variants", default=",".join(VARIANTS))
    ap.add_argument("--seeds", type=int, default=3)
    ap.add_argument("--friction", default="auto", help="comma list: identify each log once per friction model")
    args = ap.parse_args()
    rows = []
    for name in args.robots.split(","):
        for variant in args.variants.split(","):
            for seed in range(args.seeds):
                for row in run(name, variant, seed, tuple(args.friction.split(","))):
                    rows.append(row)
                    base_poorly = [p for p in row["poorly"] if p in study_plan.BASE]
                    worst = max(study_plan.BASE, key=lambda p: abs(row["parameters"][p]["error_pc"]))
                    load = ", ".join(f"{p} {v['value']:.3g} ({v['truth']:.3g})" for p, v in
                                     row["caster_parameters"].items() if v["truth"] is not None)  # fmt: skip
                    print(f"{name:5s} {variant:20s} seed {seed}: {row['friction_model']:17s} S {row['scale']:7.3g} "
                          f"misfit {row['relative_misfit']:.2g} fragile {len(row['fragile'])} poorly "
                          f"{len(base_poorly)}/8, largest error {worst} {row['parameters'][worst]['error_pc']:+.2g} %,"
                          f" max |z| {max(abs(v['z']) for v in row['parameters'].values()):.2f}; {load}",
                          flush=True)  # fmt: skip
    write_results({"args": vars(args), "rows": rows})


if __name__ == "__main__":
    sys.exit(main())
