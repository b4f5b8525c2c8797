"""Shared helpers for the bench/ scripts (not a benchmark itself).

Paths, the command that runs the installed ``wmrid`` CLI, subprocess timing under ``/usr/bin/time -v``
(for peak RSS), and generation of seeded simulated logs through the wmrid API.
"""

from __future__ import annotations

import os
import re
import statistics
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path

BENCH = Path(__file__).resolve().parent
ROOT = BENCH.parent
OUT = BENCH / "out"
GNU_TIME = "/usr/bin/time" if os.access("/usr/bin/time", os.X_OK) else None


def wmrid_cmd() -> list[str]:
    """The console script next to this interpreter (the venv's ``wmrid``), else ``python -m wmrid``."""
    exe = Path(sys.executable).with_name("wmrid")
    return [str(exe)] if exe.exists() else [sys.executable, "-m", "wmrid"]


@dataclass
class Run:
    wall: float  # s, measured by this process around the subprocess (process start included)
    rss_mb: float | None  # peak resident set size of the child, MB (None without /usr/bin/time)
    stdout: str


def run_timed(cmd: list[str], *, cwd: Path = ROOT) -> Run:
    """Run ``cmd`` once, under ``/usr/bin/time -v`` when available; raise with its stderr if it fails."""
    full = [GNU_TIME, "-v", *cmd] if GNU_TIME else cmd
    t0 = time.perf_counter()
    proc = subprocess.run(full, cwd=cwd, capture_output=True, text=True, stdin=subprocess.DEVNULL)
    wall = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"command failed ({proc.returncode}): {' '.join(cmd)}\n{proc.stderr[-2000:]}")
    rss = None
    m = re.search(r"Maximum resident set size \(kbytes\): (\d+)", proc.stderr)
    if m:
        rss = int(m.group(1)) / 1024
    return Run(wall, rss, proc.stdout)


def median(xs: list[float]) -> float:
    return statistics.median(xs)


def fmt_rss(rss: float | None) -> str:
    return "n/a" if rss is None else f"{rss:,.0f}"


def noisy_paper_sim(duration: float, rate: float = 1000.0, seed: int = 1):
    """The ``paper`` robot on the sinusoid with the benchmarks' noise (0.01 rad/s, 0.02 N m, caster 0.05 N m)."""
    from wmrid.model.robot import BUILTIN_ROBOTS
    from wmrid.sim.scenario import NoiseSettings
    from wmrid.sim.simulate import simulate

    r = BUILTIN_ROBOTS["paper"]
    noise = NoiseSettings(eta_std=0.01, tau_std=0.02, caster_std=0.05)
    return simulate(r.reference, r.nominal, trajectory="sinusoid", duration=duration, rate=rate, noise=noise, seed=seed)


def cached_log(path: Path, duration: float, write, rate: float = 1000.0, seed: int = 1) -> Path:
    """``path`` in bench/out/, made by ``write(frame, path)`` from :func:`noisy_paper_sim` if missing."""
    if path.exists():
        return path
    OUT.mkdir(parents=True, exist_ok=True)
    print(f"generating {path.relative_to(ROOT)} ...", end=" ", flush=True)
    t0 = time.perf_counter()
    # simulate holds the whole run (about 0.9 kB a sample): a 4 h log needs 12.5 GiB, past the default memory
    # budget, so generation alone gets a budget of 3/4 of this machine's memory (the runs measured keep theirs)
    saved = os.environ.get("WMRID_MEMORY_BUDGET")
    os.environ["WMRID_MEMORY_BUDGET"] = str(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") * 3 // 4)
    try:
        sim = noisy_paper_sim(duration, rate, seed)
        write(sim.to_frame(), path)
    finally:
        if saved is None:
            os.environ.pop("WMRID_MEMORY_BUDGET", None)
        else:
            os.environ["WMRID_MEMORY_BUDGET"] = saved
    print(f"{len(sim.t):,} samples in {time.perf_counter() - t0:.1f} s", flush=True)
    return path


def sim_log(duration: float, rate: float = 1000.0, seed: int = 1, suffix: str = ".parquet") -> Path:
    """A noisy ``paper`` sinusoid log (t, eta_r, eta_l, tau_r, tau_l) in bench/out/, generated if missing."""
    from wmrid.io.logs import write_log

    def write(frame, path):
        write_log(frame[["t", "eta_r", "eta_l", "tau_r", "tau_l"]], str(path), force=True)

    path = OUT / f"paper_sinusoid_{duration:g}s_{rate:g}hz_seed{seed}{suffix}"
    return cached_log(path, duration, write, rate, seed)
