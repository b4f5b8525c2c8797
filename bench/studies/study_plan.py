"""Issue 29: does a plan deliver what it predicts?  Closed loop, two robots, both simulator engines, 10 seeds.

    python3 bench/studies/study_plan.py                        # paper + light AMR, reduced + MuJoCo, 10 seeds each
    python3 bench/studies/study_plan.py --robots amr --engines reduced --seeds 3
    python3 bench/studies/study_plan.py --robots amr --engines reduced --seeds 1   # a check that it runs

For each robot (the paper's and the light AMR's CAD sets as the truth; a robot file whose nominal set is the truth
with every inertial and friction parameter 20 % off, alternately up and down, r, b and k_r exact; a [limits] table):

1. ``wmrid.plan(robot_file, duration=60, area 4 m x 4 m, noise as simulated, log_rate=1000)``: the plan, its predicted
   std per base parameter, its criterion against the paper's sinusoid and the back-and-forth (reversing) drive of the
   same duration within the same limits; its CSV reference at 50 Hz.
2. Per engine and seed: ``wmrid.simulate(robot_file, trajectory=plan.csv, engine=E, noise=NoiseSettings(...))``
   at 1 kHz (the log the prediction assumed), identified with defaults (``wmrid.identify(log, robot_file)``).
   Recorded: each base parameter's estimate, std and z = (estimate - truth) / std; the poorly determined and the
   flagged parameters; achieved std / predicted std; the peaks of |eta|, |eta'| (a 5-sample central difference of the
   logged true speeds... of the logged speeds smoothed over 10 ms), |tau| against the limits; how far the whole robot
   (its footprint) came from the area's edge.

``--sequential ETA,TAU`` instead checks sequential design on the paper robot: a 20 s sinusoid with that speed and
effort noise (seed 100), identified and saved; a 30 s plan without and with ``given`` (predicted worst relative std
of each, and of the plan without ``given`` combined with the first log).  Then, on ``--seeds`` seeds, the logs drawn
again (the plans kept): the first identified; the plan without ``given`` identified alone; the plan with ``given``
identified alone and with ``wmrid.identify(log, robot, given=first)`` (what ``wmrid identify B --given A.json``
reports).  Per parameter: the predicted std (``wmrid.predict_plan``: a plan's drive predicted again, without or
with ``given``), the spread of the estimate across seeds, the median reported std and the rms of z, for each.
Relative std is over the plan's scale of each parameter throughout (the floor for the paper robot's friction).
Figures: ``bench/results/study_plan-sequential_ETA_TAU.json``.

Printed per robot and engine: seeds with every parameter determined, with the truth within 3 std, with every limit
within 10 %, with the path in the area; the median achieved/predicted std ratio per parameter (the issue's 0.5-2x),
the prediction being the plan's for the friction model identify chose on each log (``wmrid.predict_plan``).
Figures: ``bench/results/study_plan.json`` (the summaries); every seed's row in ``--json`` (default
``bench/out/study_plan.json``).  The robot files and plans are made in bench/out/study_plan/ (the export and misfit
studies use them).  Seeded throughout; ``--workers`` processes (default 1).
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # bench/: the shared module _common
from _common import OUT as BENCH_OUT, write_results

OUT = BENCH_OUT / "study_plan"
BASE = ("m11", "m12", "m22", "Vc", "Fv1", "Fv2", "Fd1", "Fd2")
#: Per robot: the CAD set (truth), limits, sensor noise (rad/s, N m per sample at 1 kHz).
ROBOTS = {
    "paper": {"limits": {"max_wheel_speed": 6.25, "max_wheel_accel": 6.25, "max_torque": 20.0, "area": [4.0, 4.0]},
              "eta_noise": 0.02, "tau_noise": 0.05},
    "amr": {"limits": {"max_wheel_speed": 12.5, "max_wheel_accel": 12.5, "max_torque": 1.0, "area": [4.0, 4.0]},
            "eta_noise": 0.02, "tau_noise": 0.005},
}  # fmt: skip
#: Parameters kept exact in the nominal set (geometry a user measures); the rest are 20 % off.
EXACT = ("r", "b", "k_r", "a", "c_y")


def _toml(value) -> str:
    return json.dumps(value) if isinstance(value, str) else repr(list(value) if isinstance(value, tuple) else value)


def robot_file(name: str) -> Path:
    """A robot TOML: [cad] = the built-in robot's CAD set, [nominal] = it 20 % off (alternately up and down), its
    casters, and the study's [limits]."""
    import wmrid

    builtin = wmrid.load_robot(name)
    cad = builtin.cad.to_dict()
    nominal, sign = {}, 1.0
    for key, value in cad.items():
        if key in EXACT:
            nominal[key] = value
            continue
        nominal[key] = value * (1.0 + 0.2 * sign)
        sign = -sign
    lines = [f"name = {_toml(f'{name}_20pc')}"]
    for title, values in (("nominal", nominal), ("cad", cad)):
        lines += ["", f"[{title}]", *(f"{key} = {value!r}" for key, value in values.items())]
    for caster in builtin.casters:
        lines += ["", "[[caster]]", *(f"{key} = {_toml(value)}" for key, value in caster.to_dict().items())]
    lines += ["", "[limits]", *(f"{key} = {_toml(value)}" for key, value in ROBOTS[name]["limits"].items())]
    OUT.mkdir(parents=True, exist_ok=True)
    path = OUT / f"{name}_20pc.toml"
    path.write_text("\n".join(lines) + "\n")
    return path


def footprint(robot) -> float:
    """m: how far the robot reaches from its axle midpoint: its wheels' contacts and its casters' (as ``wmrid plan``
    keeps the whole robot inside the area)."""
    reach = float(robot.nominal.b)
    for caster in robot.casters or ():
        reach = max(reach, math.hypot(caster.x, caster.y) + caster.radius)
    return reach


def make(name: str) -> dict:
    import wmrid

    spec = ROBOTS[name]
    path = robot_file(name)
    start = time.perf_counter()
    plan = wmrid.plan(
        str(path), duration=60.0, eta_noise=spec["eta_noise"], tau_noise=spec["tau_noise"], log_rate=1000.0
    )
    seconds = time.perf_counter() - start
    csv = OUT / f"{name}_plan.csv"
    wmrid.write_plan(plan, csv, force=True)
    wmrid.write_plan(plan, OUT / f"{name}_plan.json", force=True)
    return {"robot": name, "file": str(path), "csv": str(csv), "seconds": seconds, "plan": plan.to_dict()}


def run(job: tuple[str, str, int, str, str]) -> dict:
    import numpy as np

    import wmrid

    name, engine, seed, robot_path, csv = job
    spec = ROBOTS[name]
    sim = wmrid.simulate(
        robot_path,
        engine=engine,
        rate=1000.0,
        trajectory=csv,
        noise=wmrid.NoiseSettings(seed=seed, eta_std=spec["eta_noise"], tau_std=spec["tau_noise"]),
    )
    truth = sim.truth["parameters"]
    result = wmrid.identify(sim.log.to_wheel_log(), robot_path)
    log = sim.log
    eta = np.asarray(log.eta_true)
    dt = float(log.t[1] - log.t[0])
    kernel = np.ones(10) / 10.0
    smooth = np.stack([np.convolve(eta[:, j], kernel, mode="same") for j in range(2)], axis=1)
    deta = np.gradient(smooth, dt, axis=0)[20:-20]
    tau = np.asarray(log.tau)
    reach = footprint(wmrid.load_robot(robot_path))
    limits = spec["limits"]
    pose = np.asarray(log.pose)
    peaks = {
        "max_wheel_speed": float(np.max(np.abs(eta))) / limits["max_wheel_speed"],
        "max_wheel_accel": float(np.max(np.abs(deta))) / limits["max_wheel_accel"],
        "max_torque": float(np.max(np.abs(tau))) / limits["max_torque"],
    }
    edge = {"x": float(np.max(np.abs(pose[:, 0]))) + reach - limits["area"][0] / 2.0,
            "y": float(np.max(np.abs(pose[:, 1]))) + reach - limits["area"][1] / 2.0}  # fmt: skip
    params = {}
    for p in BASE:
        value, std = result.parameters[p]
        params[p] = {"value": value, "std": std, "truth": truth[p], "z": (value - truth[p]) / std if std else None}
    diag = result.diagnostics.to_dict()
    predicted = prediction_for(robot_path, csv, result.form, spec)
    for p in BASE:
        params[p]["predicted"] = predicted[p]
    return {
        "robot": name, "engine": engine, "seed": seed, "method": result.method, "parameters": params,
        "poorly": list(diag.get("poorly_determined", [])), "flagged": list(diag.get("flagged", [])),
        "limit_ratio": peaks, "edge_m": edge, "verdict": None if result.verdict is None else result.verdict.summary,
        "friction_model": result.form.friction,
    }  # fmt: skip


def prediction_for(robot_path: str, csv: str, form, spec: dict) -> dict[str, float]:
    """The plan's predicted std of each base parameter under the friction model identify chose (``form``): the plan
    predicts for the model its robot file implies (the casters' drag), but the reduced simulator has no casters, so
    identify fits the wheels' model to its logs."""
    import wmrid

    again = wmrid.predict_plan(Path(csv).with_suffix(".json"), robot_path, friction=form.friction)
    return {n: float(again.predicted[n].std) for n in BASE}


def summarise(made: dict, rows: list[dict]) -> dict:
    out = {}
    for engine in sorted({r["engine"] for r in rows}):
        sel = [r for r in rows if r["engine"] == engine]
        # against the prediction for the friction model identify chose on each log (prediction_for)
        ratio = {
            p: statistics.median(r["parameters"][p]["std"] / r["parameters"][p]["predicted"] for r in sel) for p in BASE
        }
        out[engine] = {
            "seeds": len(sel),
            "determined": sum(not any(p in BASE for p in r["poorly"]) for r in sel),
            "truth_within_3std": sum(all(abs(r["parameters"][p]["z"]) <= 3 for p in BASE) for r in sel),
            "honest": sum(all(abs(r["parameters"][p]["z"]) <= 3 or p in r["flagged"] for p in BASE) for r in sel),
            "limits_within_10pc": sum(max(r["limit_ratio"].values()) <= 1.1 for r in sel),
            "in_area": sum(max(r["edge_m"].values()) <= 0 for r in sel),
            "worst_limit_ratio": max(max(r["limit_ratio"].values()) for r in sel),
            "worst_edge_m": max(max(r["edge_m"].values()) for r in sel),
            "median_std_ratio": ratio,
            "worst_abs_z": max(abs(r["parameters"][p]["z"]) for r in sel for p in BASE),
            "methods": sorted({r["method"] for r in sel}),
        }  # fmt: skip
    return out


def _base(result):
    """(estimate (8,), reported covariance (8, 8), dof) of a result's base parameters, in BASE order."""
    import numpy as np

    idx = [result.form.base_names.index(n) for n in BASE]
    est = result.estimate
    return np.asarray(est.theta0)[idx], np.asarray(est.cov)[np.ix_(idx, idx)], est.dof


def _sequential_seed(job: tuple[int, str, str, str, float, float]) -> dict:
    """One seed of the check: the logs drawn again, the first identified; the plan without ``given`` identified; the
    plan with ``given`` identified alone and with ``given`` the first's result (``wmrid identify B --given A.json``)."""
    import numpy as np

    import wmrid

    seed, robot, csv, alone_csv, eta_noise, tau_noise = job
    noise = {"eta_std": eta_noise, "tau_std": tau_noise}
    sim1 = wmrid.simulate(
        robot, trajectory="sinusoid", duration=20, rate=1000.0, noise=wmrid.NoiseSettings(seed=2000 + seed, **noise)
    )
    first = wmrid.identify(sim1.log.to_wheel_log(), robot)
    sim2 = wmrid.simulate(robot, trajectory=csv, rate=1000.0, noise=wmrid.NoiseSettings(seed=3000 + seed, **noise))
    second = wmrid.identify(sim2.log.to_wheel_log(), robot)
    both = wmrid.identify(sim2.log.to_wheel_log(), robot, given=first)
    alone_sim = wmrid.simulate(
        robot, trajectory=alone_csv, rate=1000.0, noise=wmrid.NoiseSettings(seed=4000 + seed, **noise)
    )
    alone = wmrid.identify(alone_sim.log.to_wheel_log(), robot)
    out = {"seed": seed, "truth": [sim2.truth["parameters"][n] for n in BASE], "fused_dof": both.estimate.dof,
           "first_poorly": list(first.diagnostics.poorly_determined or ()),
           "widened": [bool(r.diagnostics.inflated) for r in (first, second)]}  # fmt: skip
    for key, result in (("second", second), ("fused", both), ("alone", alone)):
        x, cov, _ = _base(result)
        out[key], out[key + "_std"] = x.tolist(), np.sqrt(np.diag(cov)).tolist()
    return out


def sequential(eta_noise: float, tau_noise: float, seeds: int = 20, workers: int = 1) -> dict:
    """The sequential-design check (module docstring): predicted worst relative std alone and with ``given``; then,
    over ``seeds`` seeds, the logs drawn again (the plans kept) and identified, the planned one also combined with the
    first (:func:`_sequential_seed`): the spread of each estimate across seeds against its reported and its predicted
    std.  Every relative std is
    the plan's: std over the plan's scale of the parameter (its nominal value, or the floor where that is small)."""
    import numpy as np

    import wmrid

    robot = str(robot_file("paper"))
    sim = wmrid.simulate(
        robot,
        trajectory="sinusoid",
        duration=20,
        rate=1000,
        noise=wmrid.NoiseSettings(eta_std=eta_noise, tau_std=tau_noise, seed=100),
    )
    first = wmrid.identify(sim.log.to_wheel_log(), robot)
    saved = OUT / f"sequential_first_{eta_noise}_{tau_noise}.json"
    saved.write_text(json.dumps(first.to_dict(history=False), default=float))
    # the reduced simulator has no casters, so identify fits the wheels' friction: the plans are for that model
    kw = {"duration": 30.0, "eta_noise": eta_noise, "tau_noise": tau_noise, "log_rate": 1000.0, "friction": "wheel"}
    alone, both = wmrid.plan(robot, **kw), wmrid.plan(robot, given=saved, **kw)
    csv = OUT / "sequential_next.csv"
    wmrid.write_plan(both, csv, force=True)
    scale = np.array([both.predicted[n].scale for n in BASE])
    # the plans' own predictions: the targeted plan alone, and the untargeted plan combined with the first log
    second_pred = np.array([wmrid.predict_plan(both, robot).predicted[n].std for n in BASE])
    alone_with = wmrid.predict_plan(alone, robot, given=saved).value
    fused_pred = np.array([both.predicted[n].std for n in BASE])
    alone_csv = OUT / "sequential_alone.csv"
    wmrid.write_plan(alone, alone_csv, force=True)
    alone_pred = np.array([alone.predicted[n].std for n in BASE])
    jobs = [(s, robot, str(csv), str(alone_csv), eta_noise, tau_noise) for s in range(seeds)]
    with ProcessPoolExecutor(max_workers=workers) as pool:
        rows = list(pool.map(_sequential_seed, jobs))
    truth = np.array(rows[0]["truth"])

    def figures(key: str, pred: np.ndarray) -> dict:
        x, std = np.array([r[key] for r in rows]), np.array([r[key + "_std"] for r in rows])
        spread = x.std(axis=0, ddof=1)
        z = (x - truth) / std
        return {n: {"predicted": pred[i] / scale[i], "spread": spread[i] / scale[i],
                    "reported_median": float(np.median(std[:, i])) / scale[i],
                    "spread_over_predicted": spread[i] / pred[i],
                    "reported_over_spread": float(np.median(std[:, i])) / spread[i],
                    "rms_z": float(np.sqrt(np.mean(z[:, i] ** 2))),
                    "spread_over_truth": spread[i] / abs(truth[i])} for i, n in enumerate(BASE)}  # fmt: skip

    worst = np.max(np.array([r["fused_std"] for r in rows]) / scale, axis=1)
    return {
        "noise": [eta_noise, tau_noise], "seeds": seeds, "scale": dict(zip(BASE, scale.tolist(), strict=True)),
        "first_relative_std": {n: first.parameters[n][1] / scale[i] for i, n in enumerate(BASE)},
        "plan_alone": {"worst": alone.value, "with_first_log": alone_with,
                       "relative": {n: v.relative for n, v in alone.predicted.items()}},
        "plan_given": {"worst": both.value, "relative": {n: v.relative for n, v in both.predicted.items()}},
        "second": figures("second", second_pred), "fused": figures("fused", fused_pred),
        "alone": figures("alone", alone_pred),
        "alone_worst_reported": sorted(np.max(np.array([r["alone_std"] for r in rows]) / scale, axis=1).tolist()),
        "fused_worst_reported": sorted(worst.tolist()), "fused_below_2pc": int(np.sum(worst < 0.02)),
        "widened": [sum(r["widened"][j] for r in rows) for j in range(2)],
        "first_friction_poorly": sum(all(n in r["first_poorly"] for n in ("Fv1", "Fv2", "Fd1", "Fd2")) for r in rows),
        "first_poorly_seed100": list(first.diagnostics.poorly_determined or ()),
    }  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--robots", default="paper,amr")
    ap.add_argument("--engines", default="reduced,mujoco")
    ap.add_argument("--seeds", type=int, default=10)
    ap.add_argument("--workers", type=int, default=1)
    ap.add_argument("--json", type=Path, default=BENCH_OUT / "study_plan.json", help="every seed's row")
    ap.add_argument("--sequential", default=None, help="ETA,TAU: the sequential-design check at that noise instead")
    args = ap.parse_args()
    if args.sequential:
        eta_noise, tau_noise = (float(v) for v in args.sequential.split(","))
        out = sequential(eta_noise, tau_noise, args.seeds, args.workers)
        print(f"plan alone: worst {100 * out['plan_alone']['worst']:.3g} % (combined with the first log "
              f"{100 * out['plan_alone']['with_first_log']:.3g} %); with --given: worst "
              f"{100 * out['plan_given']['worst']:.3g} %")  # fmt: skip
        for key in ("alone", "second", "fused"):
            print(
                f"{key} over {out['seeds']} seeds, % of the plan's scale: predicted / spread / reported (median), rms z"
            )
            for n, f in out[key].items():
                print(
                    f"  {n:4s} {100 * f['predicted']:6.3g} {100 * f['spread']:6.3g} "
                    f"{100 * f['reported_median']:6.3g}   {f['rms_z']:.2f}"
                )
        print(f"fused worst reported std below 2 %: {out['fused_below_2pc']}/{out['seeds']} seeds (median "
              f"{100 * statistics.median(out['fused_worst_reported']):.3g} %); widened: first {out['widened'][0]}, "
              f"second {out['widened'][1]}")  # fmt: skip
        alone_median = 100 * statistics.median(out["alone_worst_reported"])
        print(f"plan without --given, worst reported std: median {alone_median:.3g} %; first log's friction all poorly "
              f"determined on {out['first_friction_poorly']}/{out['seeds']} seeds")  # fmt: skip
        write_results(out, variant=f"sequential_{eta_noise:g}_{tau_noise:g}")
        return None
    report: dict = {"args": vars(args) | {"json": str(args.json)}, "robots": {}}
    for name in args.robots.split(","):
        made = make(name)
        plan = made["plan"]
        print(f"{name}: plan in {made['seconds']:.1f} s, predicted worst {100 * plan['criterion']['value']:.3g} % "
              f"({plan['criterion']['worst']}); baselines: " + ", ".join(
                  f"{b} x{v['improvement']:.3g}" for b, v in plan["baselines"].items()), flush=True)  # fmt: skip
        jobs = [(name, e, s, made["file"], made["csv"]) for e in args.engines.split(",") for s in range(args.seeds)]
        rows = []
        with ProcessPoolExecutor(max_workers=args.workers) as pool:
            for row in pool.map(run, jobs):
                rows.append(row)
                worst = max(BASE, key=lambda p: abs(row["parameters"][p]["z"]))
                print(f"  {row['engine']:8s} seed {row['seed']}: method {row['method']}, worst |z| "
                      f"{abs(row['parameters'][worst]['z']):.2f} ({worst}), poorly {row['poorly']}, flagged "
                      f"{row['flagged']}, limits {max(row['limit_ratio'].values()):.2f}, edge "
                      f"{max(row['edge_m'].values()):+.2f} m", flush=True)  # fmt: skip
        summary = summarise(made, rows)
        for engine, s in summary.items():
            print(f"{name} {engine}: determined {s['determined']}/{s['seeds']}, truth within 3 std "
                  f"{s['truth_within_3std']}/{s['seeds']} (honest {s['honest']}), limits within 10 % "
                  f"{s['limits_within_10pc']}/{s['seeds']} (worst {s['worst_limit_ratio']:.3f}), in the area "
                  f"{s['in_area']}/{s['seeds']} (closest {-s['worst_edge_m']:.2f} m from the edge)",
                  flush=True)  # fmt: skip
            print("   achieved/predicted std (median): " + ", ".join(
                f"{p} {v:.2f}" for p, v in s["median_std_ratio"].items()), flush=True)  # fmt: skip
        report["robots"][name] = {"plan": made, "rows": rows, "summary": summary}
        args.json.parent.mkdir(parents=True, exist_ok=True)
        args.json.write_text(json.dumps(report, indent=1, default=float))
    plans = {name: {k: v for k, v in r["plan"].items() if k != "plan"} for name, r in report["robots"].items()}
    for name, r in report["robots"].items():
        plan = r["plan"]["plan"]
        plans[name]["criterion"] = plan["criterion"]
        plans[name]["baselines"] = {b: v["improvement"] for b, v in plan["baselines"].items()}
    write_results({"settings": report["args"], "plans": plans,
                   "summary": {name: r["summary"] for name, r in report["robots"].items()}})  # fmt: skip
    return None


if __name__ == "__main__":
    sys.exit(main())
