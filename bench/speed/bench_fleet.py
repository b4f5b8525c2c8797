"""Benchmark of ``wmrid fleet`` on Dask, and the fleet report's detection, on a simulated fleet (issue 17).

    python3 bench/speed/bench_fleet.py                    # 20 robots x 50 days of 60 s logs at 1 kHz (2.4 GB, ~10 min)
    python3 bench/speed/bench_fleet.py --robots 6 --days 30 --duration 20   # a quick look
    python3 bench/speed/bench_fleet.py --robots 4 --days 8 --duration 10 --overhead-logs 8   # a check that it runs

1. Generates the fleet with wmrid's simulator (``wmrid.simulate``, the library call behind ``wmrid simulate``), one
   log a day per robot, as ``DIR/R07/2026-01-05.parquet`` (robot id and date from the path; the units and days of
   ``_common.unit_robot`` and ``_common.day_robot``):
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

Seeded throughout (numpy PCG64); the figures vary by +-10 % between runs on a shared machine.  Figures: printed, and
written to bench/results/bench_fleet.json.
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
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # bench/: the shared module _common
from _common import FLEET_START as START, WHEEL_COLUMNS, day_robot, unit_robot, write_log, write_results

DRIFTS = {"R03": ("right", 0.03, 20), "R11": ("left", 0.05, 28)}  # robot: (wheel, relative rise per day, onset day)
PAYLOAD = {"R07": (10.0, 0.05, -0.03, 35)}  # robot: (kg, x m, y m, from day)


def generate(folder: Path, robots: int, days: int, duration: float, rate: float) -> dict:
    """Write the fleet's logs; returns what was injected."""
    import wmrid

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
            robot = day_robot(unit, rng, robot_id, day, DRIFTS)
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
            write_log(run.to_frame()[WHEEL_COLUMNS], path, run.truth)
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
    import wmrid

    run = wmrid.fleet(logs or [str(folder)], str(table), robot="paper", workers=workers, force=True, fit=fit)
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

    import wmrid

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
        run = wmrid.fleet(logs, str(table), robot="paper", scheduler=address, force=True)
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
        flagged = review(table)
        projection = project(results, bare, gen, ext)
        write_results({
            "fleet": {"robots": args.robots, "days": args.days, "duration_s": args.duration, "rate_hz": args.rate},
            "generate": gen, "bare": bare, "workers": results, "speedup_2_over_1": speedup,
            "overhead": {"logs": len(subset), "fleet_per_log_s": per_log, "loop_per_log_s": loop},
            "external": ext, "flagged": flagged,
            "injected": {"drifts": {k: {"wheel": w, "per_day": r, "onset_day": d} for k, (w, r, d) in DRIFTS.items()},
                         "payload": {k: {"kg": m, "x": x, "y": y, "from_day": d}
                                     for k, (m, x, y, d) in PAYLOAD.items()}},
            "projection": projection,
        })  # fmt: skip
    finally:
        if args.dir is None:
            shutil.rmtree(folder, ignore_errors=True)


def review(table: Path) -> dict[str, list[str]]:
    """The fleet report's flagged robots and their findings, printed beside what was injected."""
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
    return {rv.robot_id: list(rv.findings) for rv in flagged}


def project(results: list[dict], bare: dict, gen: dict, ext: dict) -> dict:
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
    out: dict = {"nodes": 100, "cores": cores, "logs": 1_000_000, "compute_logs_per_s": compute, "batches": {}}
    for batch in (1, 16, 64):
        limit = batch / max(sched, client)
        rate = min(compute, limit)
        print(
            f"  --batch {batch}: the scheduler and client handle {limit:,.0f} logs/s -> {rate:,.0f} logs/s, "
            f"{1e6 / rate:,.0f} s; reads {rate * mb / 1e3:,.1f} GB/s from storage"
        )
        out["batches"][str(batch)] = {"limit_logs_per_s": limit, "logs_per_s": rate, "seconds": 1e6 / rate,
                                      "storage_gb_per_s": rate * mb / 1e3}  # fmt: skip
    return out


if __name__ == "__main__":
    main()
