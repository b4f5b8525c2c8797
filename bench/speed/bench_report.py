"""How long ``wmrid report`` takes on the bundled sample (issue 33, item 6: under 5 s), and where the time goes.

1. The command as a user runs it, ``wmrid report sample_logs/paper_sinusoid.csv --robot paper -o report.html``
   (the log identified on the fly, the HTML page written), in a fresh process: wall time and the process's CPU time,
   median of ``--repeat`` runs after one warm-up (numba's kernels compiled and cached).
2. The same in this process, stage by stage, through the public API: reading and identifying the log
   (``wmrid.read_log``, ``wmrid.identify``), building the report (``wmrid.report``: its tables, statements and
   figures), writing the page (``wmrid.write_report`` to an .html file: the figures rendered as SVG and the page
   written; before the bench used only the public API it timed the figures' rendering and the page apart).

The checkout this script lives in is measured (``python -m wmrid`` with it first on PYTHONPATH).  The figures are
printed and written to ``bench/results/bench_report.json`` with the machine, the date and the command.

    python3 bench/speed/bench_report.py
    python3 bench/speed/bench_report.py --repeat 5
    python3 bench/speed/bench_report.py --repeat 1   # a quick check that it runs
"""

from __future__ import annotations

import argparse
import os
import resource
import statistics
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # bench/: the shared module _common
from _common import OUT, ROOT, write_results

SAMPLE = ROOT / "sample_logs" / "paper_sinusoid.csv"


def command_times(repeat: int) -> tuple[list[float], list[float], list[str]]:
    """(wall s, CPU s) of each of ``repeat`` runs of the report command, after one warm-up; and the command."""
    OUT.mkdir(parents=True, exist_ok=True)
    out = OUT / "bench_report.html"
    cmd = [sys.executable, "-m", "wmrid", "report", str(SAMPLE), "--robot", "paper", "-o", str(out), "--force"]
    env = {**os.environ, "PYTHONPATH": str(ROOT)}
    walls, cpus = [], []
    for i in range(repeat + 1):
        before = resource.getrusage(resource.RUSAGE_CHILDREN)
        t0 = time.perf_counter()
        subprocess.run(cmd, cwd=ROOT, env=env, check=True, capture_output=True, stdin=subprocess.DEVNULL)
        wall = time.perf_counter() - t0
        after = resource.getrusage(resource.RUSAGE_CHILDREN)
        if i:  # the first run is the warm-up
            walls.append(wall)
            cpus.append(after.ru_utime - before.ru_utime + after.ru_stime - before.ru_stime)
    return walls, cpus, ["wmrid", *cmd[3:]]


def stage_times() -> dict[str, float]:
    """Seconds of each stage in this process (wall), after a warm-up run of the whole."""
    sys.path.insert(0, str(ROOT))
    import wmrid

    page = OUT / "bench_report_in_process.html"

    def once() -> dict[str, float]:
        t0 = time.perf_counter()
        log = wmrid.read_log(str(SAMPLE))
        result = wmrid.identify(log, "paper")
        t1 = time.perf_counter()
        made = wmrid.report(result, log=log)
        t2 = time.perf_counter()
        wmrid.write_report(made, page, force=True)
        t3 = time.perf_counter()
        assert made.figure_objects
        return {"read_and_identify_s": t1 - t0, "build_report_s": t2 - t1, "write_html_s": t3 - t2,
                "total_s": t3 - t0}  # fmt: skip

    OUT.mkdir(parents=True, exist_ok=True)
    once()
    return once()


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--repeat", type=int, default=3, help="timed runs of the command (after one warm-up)")
    args = parser.parse_args()
    walls, cpus, cmd = command_times(args.repeat)
    stages = stage_times()
    figures = {
        "command": " ".join(cmd),
        "wall_s_median": statistics.median(walls),
        "cpu_s_median": statistics.median(cpus),
        "wall_s": walls,
        "cpu_s": cpus,
        "stages_in_process_s": stages,
    }
    print(f"{figures['command']}")
    print(f"  wall {figures['wall_s_median']:.2f} s, CPU {figures['cpu_s_median']:.2f} s (median of {args.repeat})")
    for name, seconds in stages.items():
        print(f"  in process: {name.removesuffix('_s').replace('_', ' ')} {seconds:.2f} s")
    write_results(figures)


if __name__ == "__main__":
    main()
