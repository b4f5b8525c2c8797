"""Issue 29: why a plan's MuJoCo log does not determine the robot -- the caster's drag, its load transfer, or neither?

    python bench/study_mujoco_misfit.py                  # paper + light AMR, 3 variants, seeds 0-2
    python bench/study_mujoco_misfit.py --robots amr --seeds 1

The plans and robot files of ``bench/study_plan.py`` (made by it when missing: the nominal set 20 % off, 60 s in a
4 m x 4 m area), driven on the MuJoCo prototype at 1 kHz with the study's sensor noise, in three variants:

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
their truth from the engine: each ball caster's contact normal force at every logged sample (the engine's own,
:meth:`wmrid.sim.multibody._Plant.caster_normals`) fitted by least squares on 1, v', w^2, v w, w' (from the true
wheel speeds, a 41-sample Savitzky-Golay derivative), times its rolling resistance, summed over the casters that
share a parameter (:func:`wmrid.estimators.observer.observe.caster_geometry`); ``load_fit_rms_N`` is that fit's
residual. JSON: ``bench/out/study_mujoco_misfit.json``.  Seeded throughout.

    python bench/study_mujoco_misfit.py --friction wheel+caster,auto      # before / after the load terms
"""

from __future__ import annotations

import argparse
import dataclasses
import json
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(ROOT / "bench"))

import numpy as np  # noqa: E402
import study_plan  # noqa: E402  (the plans and robot files of the closed-loop study)

VARIANTS = ("default", "no_load_transfer", "frictionless_casters")


def engine_normals(run_sim):
    """run_sim() with every ball caster's normal force (N) recorded at each logged sample: (its result, (n, K))."""
    from wmrid.sim import multibody

    rec = []
    original = multibody._Plant.caster_normals

    def recording(plant):
        out = original(plant)
        rec.append(out.copy())
        return out

    multibody._Plant.caster_normals = recording
    try:
        sim = run_sim()
    finally:
        multibody._Plant.caster_normals = original
    return sim, np.array(rec)


def load_truth(robot, sim, normals: np.ndarray, resistance: list[float]) -> dict:
    """The truth of D_k and its load terms (module docstring), named as the ``wheel+caster+load`` model names them."""
    from scipy.signal import savgol_filter

    from wmrid.estimators.observer.observe import caster_geometry
    from wmrid.model.dynamics import LOAD_SIGNALS, platform_speeds

    p = robot.reference
    t = np.asarray(sim.t)
    eta = np.asarray(sim.eta_true)
    v, w = platform_speeds(eta, p.r, p.b)
    dv, dw = (savgol_filter(x, 41, 3, deriv=1, delta=t[1] - t[0]) for x in (v, w))
    x = np.column_stack([np.ones_like(v), dv, w * w, v * w, dw])
    geo = caster_geometry(robot)
    keys = [(geo[2 + 2 * k], geo[3 + 2 * k]) for k in range((len(geo) - 2) // 2)]
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
    from wmrid.api.inputs import load_robot
    from wmrid.api.simulation import load_reference
    from wmrid.sim.multibody import simulate_multibody
    from wmrid.sim.multibody_model import MultibodySettings
    from wmrid.sim.scenario import NoiseSettings

    spec = study_plan.ROBOTS[name]
    robot_path = study_plan.OUT / f"{name}_20pc.toml"
    csv = study_plan.OUT / f"{name}_plan.csv"
    if not robot_path.exists() or not csv.exists():
        study_plan.make(name)
    robot = load_robot(str(robot_path))
    settings = MultibodySettings()
    if variant == "no_load_transfer":
        settings = dataclasses.replace(settings, cg_height=-robot.reference.r)
    elif variant == "frictionless_casters":
        settings = dataclasses.replace(settings, caster_resistance=0.0)
    noise = NoiseSettings(eta_std=spec["eta_noise"], tau_std=spec["tau_noise"])
    ref = load_reference(str(csv))
    sim, normals = engine_normals(lambda: simulate_multibody(
        robot.reference, robot.nominal, casters=robot.casters, settings=settings, rate=1000.0, noise=noise,
        seed=seed, reference=ref))  # fmt: skip
    truth = sim.truth()
    casters = truth["settings"]["multibody"]["casters"]
    drag = [c.get("mean_drag_force") for c in casters]
    caster_truth = load_truth(robot, sim, normals, [c["resistance_used"] for c in casters])
    rows = []
    for friction in frictions:
        result = wmrid.identify(sim.to_wheel_log(), str(robot_path), observer=wmrid.ObserverOptions(friction=friction))
        diag = result.diagnostics
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
    ap.add_argument("--json", type=Path, default=ROOT / "bench" / "out" / "study_mujoco_misfit.json")
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
    args.json.parent.mkdir(parents=True, exist_ok=True)
    args.json.write_text(json.dumps({"args": vars(args) | {"json": str(args.json)}, "rows": rows}, indent=1))


if __name__ == "__main__":
    sys.exit(main())
