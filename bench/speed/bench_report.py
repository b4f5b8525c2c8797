"""How long ``wmrid report`` takes on the bundled sample (issue 33, item 6: under 5 s), and where the time goes.

1. The command as a user runs it, ``wmrid report sample_logs/paper_sinusoid.csv --robot paper -o report.html``
   (the log identified on the fly, the HTML page written), in a fresh process: wall time and the process's CPU time,
   median of ``--repeat`` runs after one warm-up (numba's kernels compiled and cached).
2. The same in this process, stage by stage: reading and identifying the log, building the report (its tables,
   statements and figures), rendering the page.

The checkout this script lives in is measured (``python -m wmrid`` with it first on PYTHONPATH).  The figures are
printed and written to ``bench/out/bench_report.json`` with the machine, the date and the command.

    python bench/bench_report.py
    python bench/bench_report.py --repeat 5
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import statistics
import subprocess
import sys
import time
from datetime import datetime, timezone

from _common import OUT, ROOT

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
    from wmrid.api.reporting import report
    from wmrid.reporting.report import rendered
    from wmrid.reporting.report_html import to_html

    def once() -> dict[str, float]:
        t0 = time.perf_counter()
        log = wmrid.read_log(str(SAMPLE))
        result = wmrid.identify(log, "paper")
        t1 = time.perf_counter()
        made = report(result, log=log)
        t2 = time.perf_counter()
        figures = rendered(made, "svg")
        t3 = time.perf_counter()
        to_html(made)
        t4 = time.perf_counter()
        assert figures
        return {"read_and_identify_s": t1 - t0, "build_report_s": t2 - t1, "render_figures_s": t3 - t2,
                "page_s": t4 - t3, "total_s": t4 - t0}  # fmt: skip

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
    OUT.mkdir(parents=True, exist_ok=True)
    record = {
        "benchmark": "bench/bench_report.py",
        "made_utc": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "machine": {"platform": platform.platform(), "python": platform.python_version(), "cpus": os.cpu_count()},
        "run": " ".join([os.path.basename(sys.executable), *sys.argv]),
        "figures": figures,
    }
    path = OUT / "bench_report.json"
    path.write_text(json.dumps(record, indent=2) + "\n")
    print(f"wrote {path.relative_to(ROOT)}")


if __name__ == "__main__":
    main()
