"""Benchmark of ``wmrid fleet`` on Dask, and the fleet report's detection, on a simulated fleet (issue 17).

    python3 bench/bench_fleet.py                      # 20 robots x 50 days of 60 s logs at 1 kHz (2.4 GB, ~10 min)
    python3 bench/bench_fleet.py --robots 6 --days 30 --duration 20   # a quick look

1. Generates the fleet with wmrid's simulator (``wmrid.simulate``, the library call behind ``wmrid simulate``), one
   log a day per robot, as ``DIR/R07/2026-01-05.parquet`` (robot id and date from the path):
   * unit-to-unit spread: platform mass 3 %, yaw inertia 5 %, centre-of-mass offset 1 cm, each friction coefficient
     15 % (log-normal), all drawn once per robot; the controller keeps the model's nominal parameters;
   * day-to-day: each friction coefficient 1 % (temperature, floor), noise on speeds (0.01 rad/s) and torques
     (0.02 N m), a new seed every log;
   * injected: friction drift of the right wheel of R03 (+3 %/day of both F_v and F_d from day 20), of the left
     wheel of R11 (+5 %/day from day 28), and a 10 kg payload at (0.05, -0.03) m on R07 from day 35; nothing else.
2. Times a bare in-process ``wmrid.identify`` of one log (median of 5) and ``wmrid identify`` as a subprocess.
3. Runs ``wmrid fleet`` (the library call) with 1 and with 2 worker processes on a LocalCluster; prints logs/s,
   samples/s, the speed-up, the per-task overhead (fleet wall time per log per worker minus the task's own time),
   the client+scheduler CPU per task, and the run without the fit column against the bare identify.
4. Runs the fleet report and prints which robots it flags and when, against what was injected.
5. Projects a 100-node cluster and a million logs from these figures and Dask's published limits.

Seeded throughout (numpy PCG64); the figures vary by +-10 % between runs on a shared machine.
"""

from __future__ import annotations

import argparse
import datetime as dt
import json
import shutil
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

START = dt.date(2026, 1, 1)
DRIFTS = {"R03": ("right", 0.03, 20), "R11": ("left", 0.05, 28)}  # robot: (wheel, relative rise per day, onset day)
PAYLOAD = {"R07": (10.0, 0.05, -0.03, 35)}  # robot: (kg, x m, y m, from day)


def unit_robot(rng: np.random.Generator, name: str):
    """The paper's robot with this unit's own CAD ("true") parameters."""
    from wmrid.model.robot import BUILTIN_ROBOTS, default_casters

    paper = BUILTIN_ROBOTS["paper"]
    cad = paper.cad
    spread = np.exp(0.15 * rng.standard_normal(4))
    cad = replace(
        cad, m_p=cad.m_p * (1 + 0.03 * rng.standard_normal()), I_p=cad.I_p * (1 + 0.05 * rng.standard_normal()),
        d_x=cad.d_x + 0.01 * rng.standard_normal(), F_v1=cad.F_v1 * spread[0], F_v2=cad.F_v2 * spread[1],
        F_d1=cad.F_d1 * spread[2], F_d2=cad.F_d2 * spread[3],
    )  # fmt: skip
    return replace(paper, name=name, cad=cad, casters=default_casters(cad))


def day_robot(unit, rng: np.random.Generator, robot_id: str, day: int, drifts: dict | None = None):
    """The unit on one day: friction with the day's jitter and any injected drift (``drifts``: as :data:`DRIFTS`,
    the default)."""
    drifts = DRIFTS if drifts is None else drifts
    cad = unit.cad
    factor = 1 + 0.01 * rng.standard_normal(4)
    if robot_id in drifts:
        wheel, rate, onset = drifts[robot_id]
        rise = 1 + rate * max(0, day - onset)
        factor[[0, 2] if wheel == "right" else [1, 3]] *= rise
    cad = replace(cad, F_v1=cad.F_v1 * factor[0], F_v2=cad.F_v2 * factor[1], F_d1=cad.F_d1 * factor[2],
                  F_d2=cad.F_d2 * factor[3])  # fmt: skip
    return replace(unit, cad=cad)


def generate(folder: Path, robots: int, days: int, duration: float, rate: float) -> dict:
    """Write the fleet's logs; returns what was injected."""
    import wmrid
    from wmrid.io.logs import write_log

    folder.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    size = 0
    for u in range(robots):
        robot_id = f"R{u + 1:02d}"
        unit = unit_robot(np.random.Generator(np.random.PCG64([17, u])), robot_id)
        (folder / robot_id).mkdir(exist_ok=True)
        for day in range(days):
            path = folder / robot_id / f"{START + dt.timedelta(days=day)}.parquet"
            if path.exists():
                size += path.stat().st_size
                continue
            rng = np.random.Generator(np.random.PCG64([17, u, day]))
            robot = day_robot(unit, rng, robot_id, day)
            payload = None
            if robot_id in PAYLOAD and day >= PAYLOAD[robot_id][3]:
                mass, x, y, _ = PAYLOAD[robot_id]
                payload = wmrid.Payload(mass, x, y)
            run = wmrid.simulate(
                robot,
                duration=duration,
                rate=rate,
                payload=payload,
                noise=wmrid.NoiseSettings(seed=int(rng.integers(2**31)), eta_std=0.01, tau_std=0.02),
            )
            frame = run.to_frame()[["t", "eta_r", "eta_l", "tau_r", "tau_l"]]
            write_log(frame, str(path))
            size += path.stat().st_size
    return {"seconds": time.perf_counter() - t0, "bytes": size, "logs": robots * days}


def bare_identify(log: Path) -> dict:
    """In-process identify of one log (median of 5 after a warm-up) and one `wmrid identify` subprocess."""
    import wmrid

    wmrid.identify(str(log), "paper")
    times = []
    for _ in range(5):
        t = time.perf_counter()
        wmrid.identify(str(log), "paper")
        times.append(time.perf_counter() - t)
    exe = shutil.which("wmrid") or str(Path(sys.executable).with_name("wmrid"))
    t = time.perf_counter()
    subprocess.run([exe, "identify", str(log), "--robot", "paper", "--format", "json"], check=True,
                   stdout=subprocess.DEVNULL)  # fmt: skip
    return {"in_process_s": float(np.median(times)), "subprocess_s": time.perf_counter() - t}


def run_fleet(folder: Path, table: Path, workers: int, fit: bool = True, logs: list[str] | None = None) -> dict:
    from wmrid.fleets.run import fleet

    run = fleet(logs or [str(folder)], str(table), robot="paper", workers=workers, force=True, fit=fit)
    rows = [r for r in run.rows if r["error"] is None]
    task_s = float(np.mean([r["run_time_s"] for r in run.rows]))
    per_log_worker = run.processing_s * workers / max(run.identified, 1)
    return {
        "workers": workers, "logs": run.identified, "failed": run.failed, "startup_s": run.startup_s,
        "processing_s": run.processing_s, "logs_per_s": run.identified / run.processing_s,
        "samples_per_s": sum(r["samples"] for r in rows) / run.processing_s, "task_s": task_s,
        "overhead_per_task_s": per_log_worker - task_s, "client_cpu_per_task_s": run.client_cpu_s / run.identified,
    }  # fmt: skip


def run_external(logs: list[str], table: Path, workers: int) -> dict:
    """The fleet on a scheduler and workers started as separate processes (`dask scheduler`, `dask worker`), so that
    the scheduler's own CPU time is measured apart from the client's (psutil on its process)."""
    import psutil

    from wmrid.fleets.run import fleet

    folder = Path(tempfile.mkdtemp(prefix="wmrid-sched-"))
    sched_file = folder / "scheduler.json"
    procs = [subprocess.Popen([sys.executable, "-m", "dask", "scheduler", "--host", "127.0.0.1", "--port", "0",
                               "--dashboard-address", "127.0.0.1:0", "--scheduler-file", str(sched_file)],
                              stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)]  # fmt: skip
    try:
        while not sched_file.exists():
            time.sleep(0.1)
        address = json.loads(sched_file.read_text())["address"]
        procs.append(subprocess.Popen([sys.executable, "-m", "dask", "worker", address, "--nworkers", str(workers),
                                       "--nthreads", "1", "--no-dashboard"], stdout=subprocess.DEVNULL,
                                      stderr=subprocess.DEVNULL))  # fmt: skip
        sched = psutil.Process(procs[0].pid)
        before = sched.cpu_times()
        run = fleet(logs, str(table), robot="paper", scheduler=address, force=True)
        after = sched.cpu_times()
    finally:
        for p in procs[::-1]:
            p.terminate()
            p.wait(timeout=60)
        shutil.rmtree(folder, ignore_errors=True)
    sched_cpu = (after.user - before.user) + (after.system - before.system)
    return {
        "workers": workers, "logs": run.identified, "processing_s": run.processing_s,
        "logs_per_s": run.identified / run.processing_s, "scheduler_cpu_per_task_s": sched_cpu / run.identified,
        "client_cpu_per_task_s": run.client_cpu_s / run.identified,
    }  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--robots", type=int, default=20)
    ap.add_argument("--days", type=int, default=50)
    ap.add_argument("--duration", type=float, default=60.0, help="seconds per log")
    ap.add_argument("--rate", type=float, default=1000.0, help="log rate, Hz")
    ap.add_argument("--dir", type=Path, default=None, help="fleet folder (kept); default a temporary one (removed)")
    ap.add_argument("--overhead-logs", type=int, default=100, help="logs of the overhead measurement")
    args = ap.parse_args()
    folder = args.dir or Path(tempfile.mkdtemp(prefix="wmrid-fleet-"))
    try:
        gen = generate(folder, args.robots, args.days, args.duration, args.rate)
        print(
            f"fleet: {gen['logs']} logs ({args.robots} robots x {args.days} days, {args.duration:g} s at "
            f"{args.rate:g} Hz), {gen['bytes'] / 1e9:.2f} GB, generated in {gen['seconds']:.0f} s  [{folder}]"
        )
        first = sorted(folder.glob("R01/*.parquet"))[0]
        bare = bare_identify(first)
        print(f"bare identify of one log: {bare['in_process_s']:.3f} s in-process, {bare['subprocess_s']:.2f} s as "
              "a `wmrid identify` subprocess")  # fmt: skip
        table = folder.parent / (folder.name + ".parquet")
        results = [run_fleet(folder, table, w) for w in (1, 2)]
        for r in results:
            print(f"{r['workers']} worker(s): {r['logs']} logs in {r['processing_s']:.1f} s (+{r['startup_s']:.1f} s "
                  f"cluster start): {r['logs_per_s']:.2f} logs/s, {r['samples_per_s'] / 1e6:.2f} M samples/s; task "
                  f"{r['task_s']:.3f} s, overhead per task {1e3 * r['overhead_per_task_s']:.1f} ms, client+scheduler "
                  f"CPU per task {1e3 * r['client_cpu_per_task_s']:.1f} ms")  # fmt: skip
        speedup = results[0]["processing_s"] / results[1]["processing_s"]
        print(f"speed-up 2 workers / 1 worker: {speedup:.2f}x")
        subset = sorted(str(p) for p in folder.glob("*/*.parquet"))[: args.overhead_logs]
        import wmrid

        t = time.perf_counter()
        for p in subset:
            wmrid.identify(p, "paper")
        loop = (time.perf_counter() - t) / len(subset)
        nofit = run_fleet(folder, folder.parent / (folder.name + "-nofit.parquet"), 1, fit=False, logs=subset)
        per_log = nofit["processing_s"] / nofit["logs"]
        print(
            f"overhead, {len(subset)} logs, 1 worker, no fit: {per_log:.4f} s per log in the fleet vs "
            f"{loop:.4f} s per bare in-process identify in a loop: {100 * (per_log / loop - 1):+.1f} %"
        )
        ext = run_external(subset, folder.parent / (folder.name + "-ext.parquet"), 2)
        print(f"separately started scheduler, 2 workers, {ext['logs']} logs: {ext['logs_per_s']:.2f} logs/s; CPU per "
              f"task: scheduler {1e3 * ext['scheduler_cpu_per_task_s']:.2f} ms, client "
              f"{1e3 * ext['client_cpu_per_task_s']:.2f} ms")  # fmt: skip
        review(table)
        project(results, bare, gen, ext)
    finally:
        if args.dir is None:
            shutil.rmtree(folder, ignore_errors=True)


def review(table: Path) -> None:
    import wmrid

    rep = wmrid.fleet_report(str(table), robot="paper")
    flagged = [rv for rv in rep.review.robots if rv.flagged]
    print(f"fleet report: {len(flagged)} robots flagged of {len(rep.review.robots)}")
    for rv in flagged:
        for text in rv.findings:
            print(f"  {rv.robot_id}: {text}")
    for robot_id, (wheel, rate, onset) in DRIFTS.items():
        print(
            f"  injected: {robot_id} {wheel} wheel friction +{100 * rate:g} %/day from "
            f"{START + dt.timedelta(days=onset)} (first changed log {START + dt.timedelta(days=onset + 1)})"
        )
    for robot_id, (mass, x, y, day) in PAYLOAD.items():
        print(f"  injected: {robot_id} payload {mass:g} kg at ({x:g}, {y:g}) m from {START + dt.timedelta(days=day)}")


def project(results: list[dict], bare: dict, gen: dict, ext: dict) -> None:
    """A 100-node cluster (32 cores each) and a million logs, from the measured figures: compute, the scheduler (its
    measured CPU per task, at least Dask's published "about 1 ms of overhead per task", distributed.dask.org), the
    client, and the storage it reads from."""
    task = results[0]["task_s"]
    mb = gen["bytes"] / gen["logs"] / 1e6
    cores = 100 * 32
    compute = cores / task  # logs/s
    sched = max(ext["scheduler_cpu_per_task_s"], 1e-3)
    client = ext["client_cpu_per_task_s"]
    print(f"projection, 100 nodes x 32 cores, 1,000,000 logs like these ({task:.3f} core-s and {mb:.1f} MB each):")
    print(f"  compute: {compute:,.0f} logs/s -> {1e6 / compute:,.0f} s")
    for batch in (1, 16, 64):
        limit = batch / max(sched, client)
        rate = min(compute, limit)
        print(
            f"  --batch {batch}: the scheduler and client handle {limit:,.0f} logs/s -> {rate:,.0f} logs/s, "
            f"{1e6 / rate:,.0f} s; reads {rate * mb / 1e3:,.1f} GB/s from storage"
        )
    print(json.dumps({"results": results, "bare": bare, "generate": gen, "external": ext}, default=float))


if __name__ == "__main__":
    main()
