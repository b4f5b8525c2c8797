"""Physics benchmark (issue 11): accuracy and std coverage of the observer and IDIM on MuJoCo multibody logs.

    python3 bench/accuracy/bench_physics.py --quick                 # 7 cases x (3 seeds + clean), ~1 min on 2 cores
    python3 bench/accuracy/bench_physics.py --json /tmp/bench_physics.json   # 27 cases x (20 seeds + clean), ~20 min
    python3 bench/accuracy/bench_physics.py --robots amr --seeds 50 --workers 4
    python3 bench/accuracy/bench_physics.py --quick --robots amr --seeds 1 --duration 10   # a check that it runs

The logs come from the MuJoCo multibody prototype (``wmrid.simulate(robot, engine=wmrid.MultibodySettings(...))``:
rigid bodies, contacts, joint friction and casters derived by the engine), not from wmrid's reduced simulator, so
they contain physics that the identified model leaves out.  A case is robot x trajectory x log rate x caster x floor:

* robots ``paper``, ``amr``, ``heavy`` (the built-in robots: CAD set = plant, nominal set = controller and
  estimator start); ``heavy`` carries a 50 kg payload ``Payload(50, 0.1, 0, 2)`` throughout (the truth is
  then the loaded robot's, the run's ``truth``);
* trajectories ``sinusoid`` and ``reversing``; logs at 1000 and 100 Hz (the control loop runs at 1 kHz in
  both); casters frictionless (``caster_resistance=0``) and resisting (0.015, rolling resistance x load);
  floor friction 1 (rubber on concrete);
* plus one slipping-floor case per robot: sinusoid, 1 kHz, frictionless casters, ``floor_friction=0.15``.
  A clean run checks that the wheels really slip (``settings["multibody"]["max_slip_speed"]`` >=
  :data:`SLIP_MIN`; rolling creep on the normal floor is ~1e-5 m/s); if not, the friction is halved (up to
  three times) and the change printed.

``--quick`` runs 7 of those cases with 3 seeds: per robot (sinusoid, 1 kHz, frictionless casters) and
(reversing, 100 Hz, resisting casters), plus the slipping floor for ``amr``.

Per case, seeds 0..N-1 add white sensor noise (``NoiseSettings``: eta_std = 0.02 rad/s, tau_std = 1 % of
the robot's rms wheel torque, measured once per robot on a noise-free sinusoid 1 kHz run with frictionless
casters); seed 0 is also run noise-free as the case's "clean" row.  The noise is added to the logged
signals only (no caster disturbance is injected), so the simulated motion is the same in every seed of a
case: the spread over seeds is the noise's, and the model's systematic error is in every seed alike.

Each log is identified with ``wmrid.identify``: the default method (``observer``: the observer with the closed-loop
check, which may report IDIM or IDIM-IV instead), the wheels' friction model, plus ``control_rate=1000`` on the 100
Hz logs, as the prototype's controller runs at 1 kHz; the observer with ``friction="wheel+caster"`` (the robots' caster
positions; reversing logs only); and ``method="idim"``; reading ``result.parameters`` (name -> (value, std)) and
``result.diagnostics["flagged"]`` generically.  (Before the bench used only the public API, the first ran the
closed-loop check after the observer's passes rather than within them, and IDIM started from that observer run: the
same estimates and std on the cases compared, but IDIM's seconds now include its observer run.)

Reported per case and method:

1. error in % of the truth, median over seeds: inertia = max over M11, M12, M22; Vc; viscous = max over
   Fv1, Fv2; Coulomb = max over Fd1, Fd2;
2. coverage: per group, the smallest (over the group's parameters) fraction of seeds whose truth lies within
   3 reported std, and the worst |z| = |estimate - truth| / std over seeds and the group's parameters;
3. the acceptance figure: (log, parameter) pairs, over all 11 reported parameters (m11 m12 m22 M11 M12 M22
   Vc Fv1 Fv2 Fd1 Fd2), more than 3 std from the truth and not flagged.  A parameter whose std is
   infinite or NaN (reported undetermined) is counted apart, not as an offender.  Beside it: how many of the
   unflagged pairs would lie beyond 3 std by chance alone were every std exact (Student's t with the log's
   jackknife dof: 0.74 % per pair at 19 dof, not the normal 0.27 %), and how many lie outside the reported
   99.7 % interval (the t quantile times the std, 3.45 std at 19 dof), of which 0.27 % are expected.

A ``WmridError`` of the simulation or of a method makes a failure row; other exceptions are recorded as
crashes (the run goes on and exits with status 1).  Simulated logs are cached as .npz under ``--cache``,
keyed by the case settings, noise, seed, duration, MuJoCo version and ``wmrid.MultibodySettings.physics_version``,
so a re-run after estimator changes only re-identifies.  Prints two Markdown tables (noisy seeds; clean
runs), the offenders, the failures, wall time and samples/s; writes the summaries to
bench/results/bench_physics.json; ``--json PATH`` dumps everything (every log's row too).
"""

from __future__ import annotations

import argparse
import dataclasses
import hashlib
import json
import math
import os
import statistics
import sys
import time
import traceback
from concurrent.futures import ProcessPoolExecutor, as_completed
from pathlib import Path
from typing import Any

import numpy as np
from scipy.special import stdtr, stdtrit

import wmrid

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # bench/: the shared module _common
from _common import jsonable, write_results

ROBOTS = ("paper", "amr", "heavy")
TRAJECTORIES = ("sinusoid", "reversing")
RATES = (1000.0, 100.0)
CASTERS = (0.0, 0.015)
#: Coulomb coefficient of the slipping floor.
SLIP_FLOOR = 0.15
#: m/s: a case "slips" when the largest difference between the platform's forward speed and r (eta_r + eta_l) / 2
#: reaches this (rolling creep on a normal floor is 1e-5 - 1e-4 m/s).
SLIP_MIN = 0.01
#: Payload carried throughout: mass kg, x m, y m, own yaw inertia kg m^2.
PAYLOADS = {"heavy": (50.0, 0.1, 0.0, 2.0)}
ETA_STD = 0.02  # rad/s
TAU_FRACTION = 0.01  # tau_std = this x the robot's rms torque
#: "observer+caster": the observer with --friction wheel+caster (the robots' [[caster]] positions), on logs
#: whose wheels reverse (on the others the drag cannot be told from Coulomb friction, and wmrid refuses it).
METHOD_NAMES = ("observer", "observer+caster", "idim")
#: Hz, the prototype's control rate, given to the observer as --control-rate on slower logs.
CONTROL_RATE = 1000.0
PARAMS = ("m11", "m12", "m22", "M11", "M12", "M22", "Vc", "Fv1", "Fv2", "Fd1", "Fd2")
GROUPS = {"inertia": ("M11", "M12", "M22"), "Vc": ("Vc",), "viscous": ("Fv1", "Fv2"), "Coulomb": ("Fd1", "Fd2")}
Z_LIMIT = 3.0
CACHE_FORMAT = 2  # 2: the truth as the run states it (base parameters), not the physical set


@dataclasses.dataclass(frozen=True)
class Case:
    robot: str
    trajectory: str
    rate: float
    caster: float
    floor: float

    def label(self) -> str:
        return f"{self.robot} {self.trajectory} {self.rate:g}Hz caster {self.caster:g} floor {self.floor:g}"


@dataclasses.dataclass(frozen=True)
class Job:
    case: Case
    seed: int
    clean: bool
    eta_std: float
    tau_std: float
    duration: float
    cache: str
    sim_version: str


def normal_floor() -> float:
    return float(wmrid.MultibodySettings().floor_friction)


def case_set(robots: tuple[str, ...], quick: bool, only: dict[str, Any] | None = None) -> list[Case]:
    """The benchmark's cases; ``only`` = {"trajectory", "rate", "caster"} picks that single case per robot."""
    floor = normal_floor()
    if only is not None:
        return [Case(robot, only["trajectory"], only["rate"], only["caster"], floor) for robot in robots]
    cases: list[Case] = []
    for robot in robots:
        if quick:
            cases += [Case(robot, "sinusoid", 1000.0, 0.0, floor), Case(robot, "reversing", 100.0, 0.015, floor)]
        else:
            cases += [
                Case(robot, traj, rate, caster, floor) for traj in TRAJECTORIES for rate in RATES for caster in CASTERS
            ]
        if not quick or robot == "amr":
            cases.append(Case(robot, "sinusoid", 1000.0, 0.0, SLIP_FLOOR))
    return cases


def reference_case(robot: str) -> Case:
    """The noise-free run whose rms torque sets the robot's torque noise."""
    return Case(robot, "sinusoid", 1000.0, 0.0, normal_floor())


def sim_version() -> str:
    """MuJoCo's version and the prototype's physics version (raised with every change to the simulated motion):
    a change of either invalidates the cache."""
    import mujoco

    return f"mujoco {mujoco.__version__} multibody physics {wmrid.MultibodySettings.physics_version}"


def cache_path(job: Job) -> Path:
    key = {
        "format": CACHE_FORMAT,
        "case": dataclasses.asdict(job.case),
        "payload": PAYLOADS.get(job.case.robot),
        "seed": job.seed,
        "eta_std": job.eta_std,
        "tau_std": job.tau_std,
        "duration": job.duration,
        "sim": job.sim_version,
    }
    digest = hashlib.sha1(json.dumps(key, sort_keys=True).encode()).hexdigest()[:16]
    c = job.case
    name = f"{c.robot}_{c.trajectory}_{c.rate:g}hz_c{c.caster:g}_f{c.floor:g}_s{job.seed}_{digest}.npz"
    return Path(job.cache) / name


def simulate_cached(job: Job) -> tuple[dict[str, Any], float | None]:
    """The log's arrays, truth (base parameters) and settings; from the cache, else simulated (then also its
    seconds)."""
    path = cache_path(job)
    if path.exists():
        try:
            with np.load(path) as z:
                return {
                    "t": z["t"],
                    "eta": z["eta"],
                    "tau": z["tau"],
                    "truth": json.loads(str(z["truth"])),
                    "settings": json.loads(str(z["settings"])),
                }, None
        except (OSError, ValueError, KeyError):
            pass  # unreadable (e.g. a killed run's half file): simulate again
    c = job.case
    payload = wmrid.Payload(*PAYLOADS[c.robot]) if c.robot in PAYLOADS else None
    t0 = time.perf_counter()
    run = wmrid.simulate(
        c.robot,
        engine=wmrid.MultibodySettings(caster_resistance=c.caster, floor_friction=c.floor),
        trajectory=c.trajectory,
        duration=job.duration,
        rate=c.rate,
        noise=wmrid.NoiseSettings(eta_std=job.eta_std, tau_std=job.tau_std, seed=job.seed),
        payload=payload,
    )
    seconds = time.perf_counter() - t0
    sim = run.log
    data = {
        "t": np.array(sim.t),
        "eta": np.array(sim.eta),
        "tau": np.array(sim.tau),
        "truth": {k: float(v) for k, v in run.truth["parameters"].items()},
        "settings": json.loads(json.dumps(run.truth["settings"], default=float)),
    }
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_name(f"{path.stem}.{os.getpid()}.tmp.npz")
    np.savez(
        tmp,
        t=data["t"],
        eta=data["eta"],
        tau=data["tau"],
        truth=json.dumps(data["truth"]),
        settings=json.dumps(data["settings"]),
    )
    os.replace(tmp, path)
    return data, seconds


def _pair(value: Any) -> list[float]:
    """(value, std) from a result's parameters entry, as floats (None/absent -> NaN)."""
    try:
        v, s = value
    except (TypeError, ValueError):
        return [math.nan, math.nan]
    return [math.nan if v is None else float(v), math.nan if s is None else float(s)]


def _flagged(diagnostics: Any) -> list[str]:
    """Parameter names in ``diagnostics["flagged"]``: a list of names or of dicts with a name, or a dict by name."""
    raw = diagnostics.get("flagged") if isinstance(diagnostics, dict) else None
    if not raw:
        return []
    if isinstance(raw, dict):
        return [str(k) for k in raw]
    names = []
    for item in raw:
        if isinstance(item, dict):
            item = item.get("name", item.get("parameter"))
        if item is not None:
            names.append(str(item))
    return names


def _error_text(err: BaseException) -> str:
    return f"{type(err).__name__}: {str(err).splitlines()[0] if str(err) else ''}"


def run_job(job: Job) -> dict[str, Any]:
    """Simulate (or load) one log and identify it with every method; one JSON-ready row."""
    row: dict[str, Any] = {"case": dataclasses.asdict(job.case), "seed": job.seed, "clean": job.clean}
    try:
        data, sim_seconds = simulate_cached(job)
    except wmrid.WmridError as err:
        row.update(stage="simulate", status="fail", error=_error_text(err), n=0, methods={})
        return row
    except Exception as err:
        row.update(stage="simulate", status="crash", error=traceback.format_exc(limit=4), n=0, methods={})
        row["error_short"] = _error_text(err)
        return row
    tau = data["tau"]
    row.update(
        n=len(data["t"]),
        sim_seconds=sim_seconds,
        cached=sim_seconds is None,
        max_slip_speed=data["settings"].get("multibody", {}).get("max_slip_speed"),
        tau_rms=float(np.sqrt(np.mean(tau**2))),
        status="ok",
    )
    truth = data["truth"]
    row["truth"] = {p: truth.get(p, math.nan) for p in PARAMS}
    c = job.case
    source = f"mb {c.robot} {c.trajectory} {c.rate:g}Hz c{c.caster:g} f{c.floor:g} seed {job.seed}"
    log = wmrid.WheelLog(t=data["t"], eta=data["eta"], tau=tau, source=source + (" clean" if job.clean else ""))
    out: dict[str, Any] = {}
    # The prototype's controller runs at 1 kHz: a slower log says so with --control-rate, as its user would
    # (what wmrid does without it is issue 12's subject).
    control_rate = CONTROL_RATE if c.rate < CONTROL_RATE else None
    for name in METHOD_NAMES:
        entry: dict[str, Any] = {"status": "ok"}
        t0 = time.perf_counter()
        try:
            if name == "observer":  # the default: the observer's run and its closed-loop check
                options = wmrid.ObserverOptions(friction="wheel", control_rate=control_rate)
                res = wmrid.identify(log, c.robot, observer=options)
            elif name == "observer+caster":
                if c.trajectory == "sinusoid":
                    out[name] = {"status": "skip", "seconds": 0.0}
                    continue
                options = wmrid.ObserverOptions(friction="wheel+caster", control_rate=control_rate)
                res = wmrid.identify(log, c.robot, observer=options)
            else:
                options = wmrid.ObserverOptions(friction="wheel", control_rate=control_rate)
                res = wmrid.identify(log, c.robot, method=name, observer=options)
            entry["parameters"] = {p: _pair(res.parameters.get(p)) for p in PARAMS}
            entry["flagged"] = _flagged(res.diagnostics.to_dict())
            entry["dof"] = None if res.diagnostics.uncertainty is None else res.diagnostics.uncertainty.dof
        except wmrid.WmridError as err:
            entry.update(status="fail", error=_error_text(err))
        except Exception as err:
            entry.update(status="crash", error=traceback.format_exc(limit=4), error_short=_error_text(err))
        entry["seconds"] = time.perf_counter() - t0
        out[name] = entry
    row["methods"] = out
    return row


def z_score(value: float, std: float, truth: float) -> tuple[float, bool]:
    """(|z|, undetermined): |value - truth| / std; a non-finite std is 'undetermined' (|z| 0)."""
    if not math.isfinite(value):
        return math.inf, False
    if not math.isfinite(std):
        return 0.0, True
    err = abs(value - truth)
    if std <= 0:
        return (math.inf if err > 0 else 0.0), False
    return err / std, False


def rel_error(value: float, truth: float) -> float:
    if not math.isfinite(value) or truth == 0:
        return math.inf
    return 100.0 * abs(value - truth) / abs(truth)


def summarize(case: Case, method: str, rows: list[dict[str, Any]]) -> dict[str, Any]:
    """Errors, coverage and offenders of one method over the rows (logs) of one case."""
    rows = [r for r in rows if r.get("methods", {}).get(method, {}).get("status") != "skip"]
    ok = [r for r in rows if r.get("methods", {}).get(method, {}).get("status") == "ok"]
    out: dict[str, Any] = {
        "case": dataclasses.asdict(case),
        "method": method,
        "logs": len(rows),
        "failed": len(rows) - len(ok),
        "error_percent": {},
        "coverage": {},
        "worst_z": {},
        "offenders": [],
        "undetermined": 0,
        "unflagged_pairs": 0,
        "expected_by_chance": 0.0,
        "beyond_interval": 0,
    }
    zs: dict[str, list[float]] = {p: [] for p in PARAMS}
    for r in ok:
        entry = r["methods"][method]
        flagged = set(entry["flagged"])
        dof = entry.get("dof")
        # the chance that |z| > Z_LIMIT if the std were exact: Student's t with the jackknife's dof (normal without)
        chance = 2.0 * (stdtr(dof, -Z_LIMIT) if dof else 0.5 * math.erfc(Z_LIMIT / math.sqrt(2.0)))
        interval = stdtrit(dof, 0.5 + 0.9973 / 2) if dof else 3.0
        for p in PARAMS:
            value, std = entry["parameters"][p]
            z, undetermined = z_score(value, std, r["truth"][p])
            zs[p].append(z)
            out["undetermined"] += undetermined
            if p not in flagged and not undetermined:
                out["unflagged_pairs"] += 1
                out["expected_by_chance"] += chance
                out["beyond_interval"] += int(z > interval)
            if z > Z_LIMIT and p not in flagged:
                out["offenders"].append(
                    {"seed": r["seed"], "clean": r["clean"], "parameter": p, "z": z, "value": value, "std": std,
                     "truth": r["truth"][p], "error_percent": rel_error(value, r["truth"][p])}
                )  # fmt: skip
    for g, names in GROUPS.items():
        if not ok:
            out["error_percent"][g] = out["coverage"][g] = out["worst_z"][g] = math.nan
            continue
        per_log = [max(rel_error(r["methods"][method]["parameters"][p][0], r["truth"][p]) for p in names) for r in ok]
        out["error_percent"][g] = statistics.median(per_log)
        out["coverage"][g] = min(float(np.mean([z <= Z_LIMIT for z in zs[p]])) for p in names)
        out["worst_z"][g] = max(max(zs[p]) for p in names)
    return out


def fmt(x: float) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "n/a"
    if math.isinf(x):
        return "inf"
    if abs(x) >= 100:
        return f"{x:.0f}"
    if abs(x) >= 10:
        return f"{x:.1f}"
    if abs(x) >= 0.01 or x == 0:
        return f"{x:.2f}"
    return f"{x:.1g}"


def run_all(pool: ProcessPoolExecutor, jobs: list[Job], what: str) -> list[dict[str, Any]]:
    """Run ``jobs`` in the pool, in their order, with a progress line to stderr every ~5 %."""
    start = time.perf_counter()
    futures = {pool.submit(run_job, job): i for i, job in enumerate(jobs)}
    rows: list[dict[str, Any] | None] = [None] * len(jobs)
    step = max(1, len(jobs) // 20)
    for done, fut in enumerate(as_completed(futures), 1):
        rows[futures[fut]] = fut.result()
        if done % step == 0 or done == len(jobs):
            elapsed = time.perf_counter() - start
            eta = elapsed / done * (len(jobs) - done)
            print(f"  {what}: {done}/{len(jobs)} logs, {elapsed:.0f} s, ~{eta:.0f} s left", file=sys.stderr, flush=True)
    return [r for r in rows if r is not None]


def print_case_table(cases: list[Case], summaries: dict, clean: bool) -> None:
    """One Markdown row per case and method: errors, then coverage with the worst |z| (noisy seeds) or the
    |z| alone (the clean run), and the unflagged offenders."""
    groups = list(GROUPS)
    counts = "fail" if clean else "logs | fail"
    stats = (f"\\|z\\| {g}" for g in groups) if clean else (f"cov {g} (worst \\|z\\|)" for g in groups)
    head = (
        f"| robot | trajectory | Hz | caster | floor | method | {counts} | "
        + " | ".join(f"err % {g}" for g in groups)
        + " | "
        + " | ".join(stats)
        + " | unflagged >3σ |"
    )
    print(head)
    print("|" + " --- |" * (head.replace("\\|", "").count("|") - 1))
    for case in cases:
        for m in METHOD_NAMES:
            s = summaries[(case, clean, m)]
            if not s["logs"]:
                continue
            errs = " | ".join(fmt(s["error_percent"][g]) for g in groups)
            if clean:
                cells = " | ".join(fmt(s["worst_z"][g]) for g in groups)
                n = f"{s['failed']}"
            else:
                cells = " | ".join(f"{fmt(s['coverage'][g])} ({fmt(s['worst_z'][g])})" for g in groups)
                n = f"{s['logs']} | {s['failed']}"
            print(
                f"| {case.robot} | {case.trajectory} | {case.rate:g} | {case.caster:g} | {case.floor:g} | {m} | "
                f"{n} | {errs} | {cells} | {len(s['offenders'])} |"
            )


def page_table(summaries: list[dict[str, Any]]) -> str:
    """The noisy logs' table as the validation page shows it (docs/validation/index.md renders it from the results
    file): per case and method, the median error over seeds in % of the truth of the worst inertia entry, Vc and the
    worst friction term; the share of seeds whose truth lies within 3 std for the worst group, with that group's worst
    |z|; the (log, parameter) pairs beyond 3 std that the output did not flag."""
    lines = [
        "| robot | trajectory | Hz | caster | floor | method | err % M / Vc / friction "
        "| within 3 std, worst group (worst \\|z\\|) | unflagged > 3 std |",
        "| --- | --- | --- | --- | --- | --- | --- | --- | --- |",
    ]
    for s in summaries:
        if s["clean"] or not s["logs"]:
            continue
        c, err, cov, z = s["case"], s["error_percent"], s["coverage"], s["worst_z"]
        friction = max(err["viscous"], err["Coulomb"])
        worst = min(GROUPS, key=lambda g: (cov[g], -z[g]))
        lines.append(
            f"| {c['robot']} | {c['trajectory']} | {c['rate']:g} | {c['caster']:g} | {c['floor']:g} | {s['method']} | "
            f"{fmt(err['inertia'])} / {fmt(err['Vc'])} / {fmt(friction)} | "
            f"{cov[worst]:.2f} {worst} ({fmt(z[worst])}) | {len(s['offenders'])} |"
        )
    return "\n".join(lines)


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--seeds", type=int, default=None, help="noisy seeds per case (default 20; 3 with --quick)")
    ap.add_argument("--duration", type=float, default=40.0, help="log length, s (default 40)")
    ap.add_argument("--quick", action="store_true", help="7 cases (see the docstring), 3 seeds unless --seeds")
    ap.add_argument("--robots", nargs="+", default=list(ROBOTS), choices=ROBOTS)
    ap.add_argument("--cache", default="/tmp/wmrid-physics-cache", help="directory of cached .npz logs")
    ap.add_argument("--workers", type=int, default=2, help="worker processes (default 2)")
    ap.add_argument("--json", metavar="PATH", help="also write everything as JSON here")
    ap.add_argument(
        "--only", metavar="TRAJ:HZ:CASTER", help="one case per robot instead of the set, e.g. reversing:200:0.015"
    )
    args = ap.parse_args()
    seeds = args.seeds if args.seeds is not None else (3 if args.quick else 20)
    if seeds < 1 or args.workers < 1 or not args.duration > 0:
        ap.error("--seeds and --workers must be >= 1 and --duration > 0")

    try:
        import mujoco  # noqa: F401  (a clear message when MuJoCo is missing)
    except ImportError:
        raise SystemExit(
            "the physics benchmark needs MuJoCo: pip install 'wmrid[physics]' (or pip install mujoco)"
        ) from None
    wall0 = time.perf_counter()
    version = sim_version()
    robots = tuple(args.robots)
    only = None
    if args.only:
        try:
            traj, hz, caster = args.only.split(":")
            only = {"trajectory": traj, "rate": float(hz), "caster": float(caster)}
        except ValueError:
            ap.error(f"--only {args.only!r}: expected TRAJ:HZ:CASTER, e.g. reversing:200:0.015")
    cases = case_set(robots, args.quick, only)

    def job(case: Case, seed: int, clean: bool, tau_std: float = 0.0) -> Job:
        eta_std = 0.0 if clean else ETA_STD
        return Job(case, seed, clean, eta_std, 0.0 if clean else tau_std, args.duration, args.cache, version)

    rows: list[dict[str, Any]] = []
    with ProcessPoolExecutor(max_workers=args.workers) as pool:
        # 1. Noise-free reference run per robot (its rms torque sets tau_std) and slipping-floor check.
        slip_cases = {c.robot: c for c in cases if c.floor == SLIP_FLOOR}
        first = [job(reference_case(r), 0, True) for r in robots] + [job(c, 0, True) for c in slip_cases.values()]
        pre = run_all(pool, first, "reference and slip-check runs")
        tau_rms: dict[str, float] = {}
        slip_checks: dict[str, list[dict[str, Any]]] = {}
        for r, row in zip(robots, pre[: len(robots)], strict=True):
            if row["status"] != "ok":
                raise SystemExit(f"reference run of {r} failed: {row.get('error')}")
            tau_rms[r] = row["tau_rms"]
        clean_rows = {(Case(**row["case"]), row["seed"]): row for row in pre if row["status"] == "ok"}
        for r, row in zip(slip_cases, pre[len(robots) :], strict=True):
            case = slip_cases[r]
            slip_checks[r] = [{"floor_friction": case.floor, "max_slip_speed": row.get("max_slip_speed")}]
            while (row.get("max_slip_speed") or 0.0) < SLIP_MIN and len(slip_checks[r]) < 4:
                lower = dataclasses.replace(case, floor=case.floor / 2)
                print(
                    f"note: {r} on floor friction {case.floor:g} slips only {row.get('max_slip_speed')} m/s; "
                    f"lowering it to {lower.floor:g}",
                    flush=True,
                )
                case = lower
                row = run_all(pool, [job(case, 0, True)], f"slip check {r} {case.floor:g}")[0]
                clean_rows[(case, 0)] = row
                slip_checks[r].append({"floor_friction": case.floor, "max_slip_speed": row.get("max_slip_speed")})
            cases = [case if (c.robot == r and c.floor == SLIP_FLOOR) else c for c in cases]
        tau_std = {r: TAU_FRACTION * v for r, v in tau_rms.items()}

        # 2. Every case: noisy seeds and the clean seed-0 run (the ones done above are reused).
        jobs = []
        for case in cases:
            jobs += [job(case, s, False, tau_std[case.robot]) for s in range(seeds)]
            if (case, 0) not in clean_rows:
                jobs.append(job(case, 0, True))
        print(
            f"{len(cases)} cases x ({seeds} noisy seeds + 1 clean) = {len(jobs) + len(clean_rows)} logs of "
            f"{args.duration:g} s; {args.workers} workers; cache {args.cache}",
            file=sys.stderr,
            flush=True,
        )
        rows = run_all(pool, jobs, "logs")
    case_keys = set(cases)
    rows += [row for (case, _), row in clean_rows.items() if case in case_keys]
    wall = time.perf_counter() - wall0

    # Summaries.
    by_case: dict[tuple[Case, bool], list[dict[str, Any]]] = {}
    for row in rows:
        by_case.setdefault((Case(**row["case"]), row["clean"]), []).append(row)
    summaries = {
        (case, clean, m): summarize(case, m, by_case.get((case, clean), []))
        for case in cases
        for clean in (False, True)
        for m in METHOD_NAMES
    }

    print(
        f"\n## Physics benchmark: MuJoCo multibody logs ({args.duration:g} s; {seeds} noisy seeds + 1 clean per case)\n"
    )
    print(f"{version}. Noise per seed: eta_std {ETA_STD} rad/s, tau_std = {TAU_FRACTION:.0%} of the rms torque:")
    for r in robots:
        extra = f", payload {PAYLOADS[r][0]:g} kg carried" if r in PAYLOADS else ""
        print(f"- {r}: rms torque {tau_rms[r]:.4g} N m -> tau_std {tau_std[r]:.3g} N m{extra}")
    for r, checks in slip_checks.items():
        text = "; ".join(
            f"floor {c['floor_friction']:g}: max slip {fmt(c['max_slip_speed'] or 0.0)} m/s" for c in checks
        )
        print(f"- slipping floor, {r}: {text}")
    print(
        "\nError: median over seeds of the largest |error| in % of the truth within the group (inertia = M11, M12, "
        "M22; viscous = Fv1, Fv2; Coulomb = Fd1, Fd2).  Coverage: smallest fraction, over the group's parameters, "
        f"of seeds whose truth is within {Z_LIMIT:g} std, with the worst |z| over seeds in brackets.  "
        f"Unflagged: (log, parameter) pairs over all {len(PARAMS)} reported parameters beyond {Z_LIMIT:g} std and "
        "not in diagnostics['flagged'].\n"
    )
    print_case_table(cases, summaries, clean=False)
    print("\nClean runs (seed 0, no noise): error in % of the truth and |z| per group.\n")
    print_case_table(cases, summaries, clean=True)

    # Acceptance figure and offenders.
    offenders = []
    for (case, _clean, m), s in summaries.items():
        offenders += [{"case": case.label(), "method": m, **o} for o in s["offenders"]]
    n_pairs = sum(
        (s["logs"] - s["failed"]) * len(PARAMS) for s in summaries.values()
    )  # (log, parameter) pairs examined
    undetermined = sum(s["undetermined"] for s in summaries.values())
    unflagged = sum(s["unflagged_pairs"] for s in summaries.values())
    chance = sum(s["expected_by_chance"] for s in summaries.values())
    beyond_interval = sum(s["beyond_interval"] for s in summaries.values())
    print(
        f"\n**Acceptance: {len(offenders)} unflagged (log, parameter) pairs beyond {Z_LIMIT:g} std** "
        f"(of {n_pairs} examined; {undetermined} undetermined, infinite/NaN std, not counted).  Of the {unflagged} "
        f"unflagged pairs, {chance:.1f} would lie beyond {Z_LIMIT:g} std by chance alone were every std exact "
        f"(Student's t with each log's jackknife dof), and {beyond_interval} lie outside the reported 99.7 % "
        f"interval (t quantile x std; {0.0027 * unflagged:.1f} expected)."
    )
    for m in METHOD_NAMES:
        for clean in (False, True):
            k = sum(1 for o in offenders if o["method"] == m and o["clean"] == clean)
            print(f"- {m}, {'clean' if clean else 'noisy'} logs: {k}")
    if offenders:
        print("\nOffenders (case, method, parameter: logs beyond 3 std, worst |z|, its error %; seeds):")
        grouped: dict[tuple[str, str, str, bool], list[dict[str, Any]]] = {}
        for o in offenders:
            grouped.setdefault((o["case"], o["method"], o["parameter"], o["clean"]), []).append(o)
        for (label, m, p, clean), items in grouped.items():
            worst = max(items, key=lambda o: o["z"])
            seeds_text = "clean" if clean else ",".join(str(o["seed"]) for o in items)
            print(
                f"- {label} | {m} | {p}: {len(items)} logs, worst |z| {fmt(worst['z'])} "
                f"(error {fmt(worst['error_percent'])} %); seeds {seeds_text}"
            )

    failures = [
        (Case(**row["case"]).label(), row["seed"], row["clean"], m, e)
        for row in rows
        for m, e in ([("simulate", row)] if row["status"] != "ok" else [(m, e) for m, e in row["methods"].items()])
        if e.get("status") not in ("ok", "skip")  # a skipped method (the caster model on a sinusoid) did not fail
    ]
    crashes = [f for f in failures if f[4].get("status") == "crash"]
    if failures:
        print(f"\nFailures ({len(failures)}, of which {len(crashes)} crashes):")
        for label, seed, clean, m, e in failures:
            text = e.get("error_short") or e.get("error")
            print(f"- {label} seed {seed}{' clean' if clean else ''} | {m}: {text}")
        for *_, e in crashes[:3]:
            print(e.get("error"), file=sys.stderr)

    # Timing.
    seen = {id(row) for row in rows}
    all_rows = rows + [row for row in pre if id(row) not in seen]  # + reference runs outside the case set
    fresh = [row for row in all_rows if row.get("sim_seconds") is not None]
    samples = sum(row.get("n", 0) for row in rows)
    est = {m: [row["methods"][m]["seconds"] for row in rows if m in row.get("methods", {})] for m in METHOD_NAMES}
    print(f"\nWall time {wall:.1f} s for {len(rows)} logs ({samples:,} samples: {samples / wall:,.0f} samples/s)")
    for rate in sorted({Case(**row["case"]).rate for row in fresh}, reverse=True):
        secs = [row["sim_seconds"] for row in fresh if row["case"]["rate"] == rate]
        print(f"- simulation at {rate:g} Hz logging: {len(secs)} fresh runs, median {statistics.median(secs):.2f} s")
    if not fresh:
        print("- simulation: every log came from the cache")
    for m, secs in est.items():
        if secs:
            print(f"- {m}: median {statistics.median(secs):.2f} s per log")
    print(f"- {len(fresh)} of {len(all_rows)} logs simulated, the rest read from the cache")

    dump = {
        "config": {
            "seeds": seeds,
            "duration": args.duration,
            "quick": args.quick,
            "robots": list(robots),
            "eta_std": ETA_STD,
            "tau_fraction": TAU_FRACTION,
            "payloads": PAYLOADS,
            "z_limit": Z_LIMIT,
            "sim_version": version,
            "workers": args.workers,
        },
        "tau_rms": tau_rms,
        "tau_std": tau_std,
        "slip_checks": slip_checks,
        "summaries": [{"clean": clean, **s} for (_, clean, _), s in summaries.items()],
        "acceptance": {
            "unflagged_beyond_3_std": len(offenders),
            "pairs": n_pairs,
            "undetermined": undetermined,
            "unflagged_pairs": unflagged,
            "expected_by_chance": chance,
            "beyond_99_7_interval": beyond_interval,
        },
        "offenders": offenders,
        "failures": [
            {"case": label, "seed": seed, "clean": clean, "method": m, "error": e.get("error")}
            for label, seed, clean, m, e in failures
        ],
        "timing": {"wall": wall, "samples": samples, "samples_per_s": samples / wall, "estimate_seconds": est},
        "logs": rows,
    }
    # the results file: the summaries with their offenders counted (every offender is listed once, below them), the
    # methods' median seconds; every log's row only in --json
    # a method not run on a case (the caster model on a sinusoid) has no summary: its NaN would read as null
    summary = [{**entry, "offenders": len(entry["offenders"])} for entry in dump["summaries"] if entry["logs"]]
    timing = {**dump["timing"], "estimate_seconds": {m: statistics.median(v) for m, v in est.items() if v}}
    # a run other than the full one keeps a file of its own: the validation page renders the full run's
    # (bench_physics.json); the variant names what differs (bench_physics-only-reversing-200-0.015-amr.json)
    parts = [
        *(["quick"] if args.quick else []),
        *([f"only-{args.only.replace(':', '-')}"] if args.only else []),
        *(["-".join(args.robots)] if tuple(args.robots) != ROBOTS else []),
        *([f"seeds{args.seeds}"] if args.seeds is not None and args.seeds != 20 else []),
        *([f"{args.duration:g}s"] if args.duration != 40.0 else []),
    ]
    variant = "-".join(parts) or None
    write_results(
        {**{k: v for k, v in dump.items() if k != "logs"}, "summaries": summary, "timing": timing,
         "page_table": page_table(dump["summaries"])},
        variant=variant,
    )  # fmt: skip
    if args.json:
        Path(args.json).write_text(json.dumps(jsonable(dump), indent=1))
        print(f"JSON written to {args.json}")
    return 1 if crashes else 0


if __name__ == "__main__":
    sys.exit(main())
