"""Shared helpers of the bench/ scripts (not a benchmark itself).

Paths; the command that runs the installed ``wmrid`` CLI; subprocess timing under ``/usr/bin/time -v`` (for peak
RSS); seeded simulated logs made and cached in bench/out/ through the public API; the simulated fleet of
speed/bench_fleet.py and studies/study_mujoco_fleet.py; and :func:`write_results`, which writes a script's figures
to ``bench/results/<script>.json`` with the machine, the date, the command, wmrid's version and the git commit.

Like every bench script, this module imports only the public API: ``import wmrid`` and the names of
``wmrid.__all__`` (tests/contract/test_bench.py checks it).  A script in a folder of bench/ imports it after
putting bench/ on ``sys.path``::

    sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # bench/: the shared module _common
"""

from __future__ import annotations

import dataclasses
import datetime as dt
import json
import math
import os
import platform
import re
import shlex
import statistics
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any

BENCH = Path(__file__).resolve().parent
ROOT = BENCH.parent
#: Generated logs and other large outputs, reused between runs (git-ignored).
OUT = BENCH / "out"
#: Each script's figures, ``<script>.json`` (committed); WMRID_BENCH_RESULTS names another folder (the tests that run
#: a script write there, not over the committed figures).
RESULTS = Path(os.environ.get("WMRID_BENCH_RESULTS") or BENCH / "results")
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


# ---- simulated logs, cached in bench/out/


def noisy_paper_sim(duration: float, rate: float = 1000.0, seed: int = 1) -> Any:
    """The ``paper`` robot on the sinusoid with the benchmarks' noise (0.01 rad/s, 0.02 N m, caster 0.05 N m), as
    ``wmrid.simulate`` returns it (:class:`wmrid.SimulationRun`)."""
    import wmrid

    noise = wmrid.NoiseSettings(eta_std=0.01, tau_std=0.02, caster_std=0.05, seed=seed)
    return wmrid.simulate("paper", trajectory="sinusoid", duration=duration, rate=rate, noise=noise)


class _Frame:
    """A table standing in for a simulator's log, so that :func:`wmrid.write_simulation` writes just its columns (a
    JointState MCAP without odometry, a log of t, eta and tau only)."""

    def __init__(self, frame: Any) -> None:
        self.frame = frame

    def to_frame(self) -> Any:
        return self.frame


def write_log(frame: Any, path: Path, truth: dict[str, Any]) -> None:
    """Write the columns of ``frame`` as a log (CSV, Parquet or a JointState MCAP by suffix) with its ``truth``
    beside it (``PATH.truth.json``), as ``wmrid simulate`` writes a log."""
    import wmrid

    wmrid.write_simulation(wmrid.SimulationRun(log=_Frame(frame), truth=truth), path, force=True)


def cached_log(path: Path, duration: float, columns: list[str], rate: float = 1000.0, seed: int = 1) -> Path:
    """``path`` in bench/out/, the ``columns`` of :func:`noisy_paper_sim` written by :func:`write_log`, if missing."""
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
        run = noisy_paper_sim(duration, rate, seed)
        write_log(run.to_frame()[columns], path, run.truth)
    finally:
        if saved is None:
            os.environ.pop("WMRID_MEMORY_BUDGET", None)
        else:
            os.environ["WMRID_MEMORY_BUDGET"] = saved
    print(f"{len(run.log.t):,} samples in {time.perf_counter() - t0:.1f} s", flush=True)
    return path


#: The columns of a wheel log: time, wheel speeds, wheel torques.
WHEEL_COLUMNS = ["t", "eta_r", "eta_l", "tau_r", "tau_l"]


def sim_log(duration: float, rate: float = 1000.0, seed: int = 1, suffix: str = ".parquet") -> Path:
    """A noisy ``paper`` sinusoid log (t, eta_r, eta_l, tau_r, tau_l) in bench/out/, generated if missing."""
    path = OUT / f"paper_sinusoid_{duration:g}s_{rate:g}hz_seed{seed}{suffix}"
    return cached_log(path, duration, WHEEL_COLUMNS, rate, seed)


def mcap_log(duration: float, seed: int = 1) -> Path:
    """The same noisy ``paper`` sinusoid (1 kHz) as a ROS 2 MCAP of ``sensor_msgs/msg/JointState`` only (no
    odometry, zstd chunks) in bench/out/, made if missing."""
    path = OUT / f"paper_jointstate_{duration:g}s_seed{seed}.mcap"
    return cached_log(path, duration, WHEEL_COLUMNS, seed=seed)


# ---- the simulated fleet (speed/bench_fleet.py, studies/study_mujoco_fleet.py)

#: The fleet's first day.
FLEET_START = dt.date(2026, 1, 1)


def unit_robot(rng: Any, name: str) -> Any:
    """The paper's robot with this unit's own CAD ("true") parameters: platform mass 3 %, yaw inertia 5 %,
    centre-of-mass offset 1 cm, each friction coefficient 15 % (log-normal); its two ball casters where wmrid puts
    them by default (at +-max(b, 3 |d_x|) on the centre line)."""
    import numpy as np

    import wmrid

    paper = wmrid.load_robot("paper")
    cad = paper.cad
    spread = np.exp(0.15 * rng.standard_normal(4))
    cad = dataclasses.replace(
        cad, m_p=cad.m_p * (1 + 0.03 * rng.standard_normal()), I_p=cad.I_p * (1 + 0.05 * rng.standard_normal()),
        d_x=cad.d_x + 0.01 * rng.standard_normal(), F_v1=cad.F_v1 * spread[0], F_v2=cad.F_v2 * spread[1],
        F_d1=cad.F_d1 * spread[2], F_d2=cad.F_d2 * spread[3],
    )  # fmt: skip
    reach = max(cad.b, 3.0 * abs(cad.d_x))
    casters = tuple(dataclasses.replace(c, x=math.copysign(reach, c.x)) for c in paper.casters)
    return dataclasses.replace(paper, name=name, cad=cad, casters=casters)


def day_robot(unit: Any, rng: Any, robot_id: str, day: int, drifts: dict[str, tuple[str, float, int]]) -> Any:
    """The unit on one day: each friction coefficient with the day's 1 % jitter, and any injected drift
    (``drifts``: robot id -> (wheel, relative rise per day, onset day))."""
    cad = unit.cad
    factor = 1 + 0.01 * rng.standard_normal(4)
    if robot_id in drifts:
        wheel, rate, onset = drifts[robot_id]
        rise = 1 + rate * max(0, day - onset)
        factor[[0, 2] if wheel == "right" else [1, 3]] *= rise
    cad = dataclasses.replace(cad, F_v1=cad.F_v1 * factor[0], F_v2=cad.F_v2 * factor[1], F_d1=cad.F_d1 * factor[2],
                              F_d2=cad.F_d2 * factor[3])  # fmt: skip
    return dataclasses.replace(unit, cad=cad)


# ---- the figures of a run: bench/results/<script>.json


def machine() -> dict[str, Any]:
    """The platform, the interpreter, the number of CPUs and their model (from /proc/cpuinfo where readable)."""
    model = None
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as fh:
            model = next((line.split(":", 1)[1].strip() for line in fh if line.startswith("model name")), None)
    except OSError:
        pass
    return {
        "platform": platform.platform(), "python": platform.python_version(), "cpu_count": os.cpu_count(),
        "cpu_model": model,
    }  # fmt: skip


def git_commit() -> dict[str, Any] | None:
    """The checkout's commit and whether tracked files differ from it (bench/results/ aside: the figures files are
    what runs write), or None outside a git checkout."""
    try:
        head = subprocess.run(["git", "rev-parse", "HEAD"], cwd=ROOT, capture_output=True, text=True, check=True)
        status = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no", "--", ".",
                                 ":(exclude)bench/results"], cwd=ROOT, capture_output=True, text=True,
                                check=True)  # fmt: skip
    except (OSError, subprocess.CalledProcessError):
        return None
    return {"commit": head.stdout.strip(), "modified": bool(status.stdout.strip())}


def command_line(argv: list[str] | None = None) -> str:
    """The command that ran this script, from the checkout's root: ``python3 bench/KIND/SCRIPT.py ARGS``."""
    argv = sys.argv if argv is None else argv
    script = Path(argv[0]).resolve()
    shown = script.relative_to(ROOT) if script.is_relative_to(ROOT) else script
    return shlex.join(["python3", str(shown), *argv[1:]])


def jsonable(x: Any) -> Any:
    """``x`` as strict JSON data: NaN and infinities as null, numpy numbers and arrays as numbers and lists, tuples as
    lists, paths as text, dataclasses as dicts."""
    if isinstance(x, dict):
        return {str(k): jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple, set, frozenset)):
        return [jsonable(v) for v in x]
    if dataclasses.is_dataclass(x) and not isinstance(x, type):
        return jsonable(dataclasses.asdict(x))
    if isinstance(x, Path):
        return str(x)
    if hasattr(x, "tolist") and not isinstance(x, (str, bytes)):  # numpy scalars and arrays
        return jsonable(x.tolist())
    if isinstance(x, bool) or x is None or isinstance(x, (int, str)):
        return x
    if isinstance(x, float):
        return x if math.isfinite(x) else None
    return str(x)


def results_path(script: str, variant: str | None = None) -> Path:
    """bench/results/SCRIPT.json (SCRIPT-VARIANT.json for a variant, a mode whose figures are kept apart)."""
    return RESULTS / f"{script}{'' if variant is None else '-' + variant}.json"


def write_results(figures: dict[str, Any], *, variant: str | None = None, script: str | None = None) -> Path:
    """Write ``figures`` to ``bench/results/<script>.json`` (atomically: the file is whole or absent) with the
    machine, the date (UTC), the exact command, wmrid's version and the git commit; returns the path.  ``script``:
    the running script's name (default); ``variant``: a mode kept in a file of its own (``<script>-<variant>.json``)."""
    import wmrid

    name = script or Path(sys.argv[0]).stem
    path = results_path(name, variant)
    document = {
        "script": name,
        "command": command_line(),
        "date_utc": dt.datetime.now(dt.timezone.utc).isoformat(timespec="seconds"),
        "machine": machine(),
        "wmrid_version": wmrid.__version__,
        "git": git_commit(),
        "figures": jsonable(figures),
    }
    RESULTS.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", dir=RESULTS)
    try:
        os.fchmod(fd, 0o644)  # as any file of the checkout (mkstemp makes it private)
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            json.dump(document, fh, indent=1, allow_nan=False)
            fh.write("\n")
        os.replace(tmp, path)
    except BaseException:
        Path(tmp).unlink(missing_ok=True)
        raise
    print(f"figures written to {path.relative_to(ROOT) if path.is_relative_to(ROOT) else path}")
    return path
