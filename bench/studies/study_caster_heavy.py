"""Caster drag on a heavy robot and on the light AMR (issue 28, item 6).

    python3 bench/studies/study_caster_heavy.py                      # both cases, 20 seeds, every method
    python3 bench/studies/study_caster_heavy.py --seeds 5 --cases heavy --methods auto,idim
    python3 bench/studies/study_caster_heavy.py --seeds 1 --cases amr --methods auto   # a check that it runs

Cases (MuJoCo multibody prototype, reversing, ball casters of rolling resistance 0.015):

* ``heavy``: the paper robot carrying 60 kg off-centre (``payload="60@0.2,0.1"``: the rear caster lifts, the front one
  carries 423 N; ``--payload 60@-0.2,0``: both touch, 25 and 46 N, and trade +-26 N per m/s^2 of acceleration) on a
  mu = 0.6 floor, 40 s at 1 kHz, sensor noise 0.02 rad/s and 0.05 N m (about 1 % of its rms torque);
* ``amr``: the light AMR (``examples/small_amr.toml``, issue 11's configuration): 40 s at 200 Hz, floor mu = 1,
  sensor noise 0.02 rad/s and 0.002 N m.

Each seed's log is identified with ``wmrid.identify(log, robot, method=M)`` (defaults otherwise: ``--friction
auto``) for M in auto (the default), idim, rls, oe and iv (the simulated log carries the reference).  A parameter is
*honest* when its truth lies within 3 reported std or it is in ``diagnostics["flagged"]`` ("do not trust this
std"); a seed is honest when every judged parameter is.  Judged: m11 m12 m22 M11 M12 M22 Vc Fv1 Fv2 Fd1 Fd2 (the
caster drag's truth, resistance x a load that moves, has no single value; its error against the engine's mean
load is printed beside).  Printed per case and method: the share of honest seeds, the share *accurate* (the
AMR's criterion: inertia and Vc within 3 %, friction within 10 % or within 3 std), the median and worst errors per
group, and the worst |z| of an unflagged parameter.  Figures: ``bench/results/study_caster_heavy.json`` (the
summaries); the per-seed rows go to ``--json`` (default ``bench/out/study_caster_heavy.json``).  Logs are cached in
``bench/out/cache_caster/`` (keyed on the case, seed and ``wmrid.MultibodySettings.physics_version``).
Seeded: the same numbers every time; ``--workers`` processes (default 2).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import statistics
import sys
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # bench/: the shared module _common
from _common import OUT, ROOT, write_results

CACHE = OUT / "cache_caster"
INERTIA = ("m11", "m12", "m22", "M11", "M12", "M22")
FRICTION = ("Fv1", "Fv2", "Fd1", "Fd2")
JUDGED = (*INERTIA, "Vc", *FRICTION)
GROUPS = {"inertia": INERTIA, "Vc": ("Vc",), "friction": FRICTION}
METHODS = ("auto", "idim", "rls", "oe", "iv")
CASES = {
    "heavy": {"robot": "paper", "payload": "60@0.2,0.1", "floor_friction": 0.6, "rate": 1000.0,
              "eta_noise": 0.02, "tau_noise": 0.05},
    "amr": {"robot": str(ROOT / "examples" / "small_amr.toml"), "payload": None, "floor_friction": None,
            "rate": 200.0, "eta_noise": 0.02, "tau_noise": 0.002},
}  # fmt: skip
RESISTANCE = 0.015
DURATION = 40.0


def simulated(case: str, seed: int):
    """(WheelLog, truth dict) of one seed, from the cache or simulated."""
    import numpy as np

    import wmrid

    spec = CASES[case]
    key = json.dumps({"case": case, "spec": spec, "seed": seed, "physics": wmrid.MultibodySettings.physics_version,
                      "resistance": RESISTANCE, "duration": DURATION}, sort_keys=True)  # fmt: skip
    path = CACHE / f"{case}_s{seed}_{hashlib.sha1(key.encode()).hexdigest()[:12]}.npz"
    if not path.exists():
        # the engine's default floor (mu = 1) where the case gives none
        floor = {} if spec["floor_friction"] is None else {"floor_friction": spec["floor_friction"]}
        run = wmrid.simulate(
            spec["robot"], trajectory="reversing", duration=DURATION, rate=spec["rate"],
            engine=wmrid.MultibodySettings(caster_resistance=RESISTANCE, **floor),
            payload=None if spec["payload"] is None else wmrid.Payload.parse(spec["payload"]),
            noise=wmrid.NoiseSettings(eta_std=spec["eta_noise"], tau_std=spec["tau_noise"], seed=seed),
        )  # fmt: skip
        log = run.log.to_wheel_log()
        CACHE.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(".tmp.npz")
        np.savez(tmp, t=log.t, eta=log.eta, tau=log.tau, ref=log.reference, pose=log.pose,
                 truth=json.dumps(run.truth, default=float))  # fmt: skip
        tmp.replace(path)
    with np.load(path) as z:
        log = wmrid.WheelLog(t=z["t"], eta=z["eta"], tau=z["tau"], reference=z["ref"], pose=z["pose"],
                             source=f"{case} seed {seed}")  # fmt: skip
        truth = json.loads(str(z["truth"]))
    return log, truth


def one(job: tuple[str, int, tuple[str, ...], str | None]) -> list[dict]:
    import wmrid

    case, seed, methods, payload = job
    if payload:
        CASES["heavy"]["payload"] = payload
    log, truth_file = simulated(case, seed)
    truth = truth_file["parameters"]
    casters = truth_file["settings"]["multibody"]["casters"]
    drag = sum(c["mean_drag_force"] or 0.0 for c in casters)
    rows = []
    for method in methods:
        t0 = time.perf_counter()
        row: dict = {"case": case, "seed": seed, "method": method}
        try:
            res = wmrid.identify(log, CASES[case]["robot"], method=method)
        except Exception as err:  # a method that fails is reported, not fatal to the study
            row.update(status="fail", error=f"{type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''}")
            rows.append(row)
            continue
        flagged = set(res.diagnostics.to_dict().get("flagged", []))
        inflated = set(res.diagnostics.to_dict().get("inflated", []))
        err, z = {}, {}
        for n in JUDGED:
            v, s = res.parameters[n]
            err[n] = 100.0 * (v / truth[n] - 1.0)
            z[n] = (v - truth[n]) / s if s and math.isfinite(s) and s > 0 else math.inf
        honest = {n: bool(abs(z[n]) <= 3.0 or n in flagged) for n in JUDGED}
        accurate = all(abs(err[n]) <= 3.0 for n in (*INERTIA, "Vc")) and all(
            abs(err[n]) <= 10.0 or abs(z[n]) <= 3.0 for n in FRICTION
        )
        d = {n: res.parameters[n][0] for n in res.parameters if n.startswith("D") or n in ("Cv", "Cw")}
        row.update(
            status="ok", reported=res.method, friction=res.form.friction, seconds=time.perf_counter() - t0,
            error_percent=err, z=z, flagged=sorted(flagged & set(JUDGED)), inflated=sorted(inflated & set(JUDGED)),
            honest=honest, all_honest=all(honest.values()), accurate=accurate, drag=d, drag_truth_mean=drag,
            warnings=[w[:200] for w in res.warnings],
        )  # fmt: skip
        rows.append(row)
    return rows


def summary(rows: list[dict]) -> dict:
    ok = [r for r in rows if r["status"] == "ok"]
    out = {"seeds": len(rows), "failed": len(rows) - len(ok)}
    if not ok:
        return out
    out["honest"] = sum(r["all_honest"] for r in ok) / len(rows)
    out["accurate"] = sum(r["accurate"] for r in ok) / len(rows)
    out["flagged_any"] = sum(bool(r["flagged"]) for r in ok) / len(rows)
    for g, names in GROUPS.items():
        per = [max(abs(r["error_percent"][n]) for n in names) for r in ok]
        out[f"err_{g}_median"] = statistics.median(per)
        out[f"err_{g}_worst"] = max(per)
    unflagged = [abs(r["z"][n]) for r in ok for n in JUDGED if n not in r["flagged"]]
    out["worst_unflagged_z"] = max(unflagged) if unflagged else 0.0
    worst = max(((abs(r["z"][n]), n, r["seed"]) for r in ok for n in JUDGED if n not in r["flagged"]), default=None)
    out["worst_unflagged"] = worst
    out["reported"] = sorted({r["reported"] for r in ok})
    out["friction_model"] = sorted({r["friction"] for r in ok})
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seeds", type=int, default=20)
    ap.add_argument("--cases", default="heavy,amr")
    ap.add_argument("--methods", default=",".join(METHODS))
    ap.add_argument("--payload", default=None, help="the heavy case's payload MASS@X,Y instead of 60@0.2,0.1")
    ap.add_argument("--workers", type=int, default=2)
    ap.add_argument("--json", default=str(OUT / "study_caster_heavy.json"), help="every seed's row")
    args = ap.parse_args()
    cases = args.cases.split(",")
    if args.payload:
        CASES["heavy"]["payload"] = args.payload
    methods = tuple(args.methods.split(","))
    jobs = [(c, s, methods, args.payload) for c in cases for s in range(args.seeds)]
    t0 = time.perf_counter()
    with ProcessPoolExecutor(args.workers) as pool:
        rows = [r for rs in pool.map(one, jobs) for r in rs]
    result = {"cases": {c: CASES[c] for c in cases}, "resistance": RESISTANCE, "summary": {}, "rows": rows}
    for c in cases:
        for m in methods:
            s = summary([r for r in rows if r["case"] == c and r["method"] == m])
            result["summary"][f"{c}/{m}"] = s
            if "honest" not in s:
                print(f"{c:6s} {m:5s} all {s['failed']} failed")
                continue
            w = s["worst_unflagged"]
            print(
                f"{c:6s} {m:5s} honest {s['honest']:.2f} accurate {s['accurate']:.2f}"
                f" flagged-any {s['flagged_any']:.2f}"
                f" | err% med/worst inertia {s['err_inertia_median']:.2f}/{s['err_inertia_worst']:.2f}"
                f" Vc {s['err_Vc_median']:.2f}/{s['err_Vc_worst']:.2f}"
                f" friction {s['err_friction_median']:.1f}/{s['err_friction_worst']:.1f}"
                f" | worst unflagged |z| {w[0]:.2f} ({w[1]}, seed {w[2]}) | {','.join(s['reported'])}"
                f" {','.join(s['friction_model'])} fail {s['failed']}"
            )
    print(f"{time.perf_counter() - t0:.0f} s", file=sys.stderr)
    Path(args.json).parent.mkdir(parents=True, exist_ok=True)
    Path(args.json).write_text(json.dumps(result, indent=1, default=lambda x: None if x != x else x))
    write_results({"settings": vars(args), **{k: v for k, v in result.items() if k != "rows"}})


if __name__ == "__main__":
    main()
