"""The install: its size on disk and its time, for the core and for each extra asked for.

For each install (the core, then ``--extras``), a new virtual environment without pip in a temporary folder, and the
system's pip installing this checkout into it, as the README's quick start does
(``python3 -m pip --python VENV/bin/python install .`` or ``".[EXTRA]"``).  Measured: the wall time of that pip
command, the environment's size on disk (every file, the bytecode pip compiles included; ``du`` would count the same
blocks), and each installed distribution's share (the files its RECORD lists, their size on disk), largest first.

pip's own cache is kept (a second run downloads nothing), so the time is that of an install whose wheels are at
hand, not of a first download; the size does not depend on it.

Then the quick start's main job in that environment, twice: ``wmrid identify sample_logs/paper_sinusoid.csv --robot
paper`` (JSON to a file), its wall time the first time (with numba, the kernels compiled and cached) and the second.

    python3 bench/speed/bench_install.py                  # the core
    python3 bench/speed/bench_install.py --extras fast parquet fleet physics

Figures: printed, and written to bench/results/bench_install.json (per install: seconds, megabytes, distributions,
identify_sample_seconds).
"""

from __future__ import annotations

import argparse
import csv
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # bench/: the shared module _common
from _common import ROOT, write_results

MB = 1e6
#: The interpreter this environment was made from (the system's ``python3``, which has pip; a venv made without pip
#: has none): the quick start's ``python3 -m pip --python VENV/bin/python``.
BASE = getattr(sys, "_base_executable", None) or sys.executable


def disk_bytes(path: Path) -> int:
    """Bytes ``path`` takes on disk (allocated blocks, as ``du`` counts them); 0 when it is gone."""
    try:
        return path.lstat().st_blocks * 512
    except FileNotFoundError:
        return 0


def tree_bytes(root: Path) -> int:
    """Bytes on disk of every file and folder under ``root``, each hard link once."""
    seen: set[tuple[int, int]] = set()
    total = 0
    for folder, dirs, files in os.walk(root):
        for name in [*dirs, *files]:
            st = (Path(folder) / name).lstat()
            if (st.st_dev, st.st_ino) not in seen:
                seen.add((st.st_dev, st.st_ino))
                total += st.st_blocks * 512
    return total


def distributions(site: Path) -> dict[str, float]:
    """Megabytes on disk of each distribution installed in ``site`` (the files its RECORD lists), largest first."""
    sizes = {}
    for record in site.glob("*.dist-info/RECORD"):
        meta = (record.parent / "METADATA").read_text(encoding="utf-8", errors="replace")
        name = next((line.split(":", 1)[1].strip() for line in meta.splitlines() if line.startswith("Name:")), "?")
        with record.open(newline="", encoding="utf-8") as fh:
            files = [row[0] for row in csv.reader(fh) if row]
        sizes[name] = sum(disk_bytes((site / f).resolve()) for f in files) / MB
    return dict(sorted(sizes.items(), key=lambda kv: -kv[1]))


def install(extra: str | None) -> dict:
    """Install the checkout (``extra``: with that extra) into a new environment; its time, size and distributions."""
    target = f".[{extra}]" if extra else "."
    with tempfile.TemporaryDirectory(prefix="wmrid-install-") as tmp:
        venv = Path(tmp) / "venv"
        subprocess.run([BASE, "-m", "venv", "--without-pip", str(venv)], check=True)
        python = venv / "bin" / "python"
        t0 = time.perf_counter()
        proc = subprocess.run(
            [BASE, "-m", "pip", "--python", str(python), "install", "-q", target],
            cwd=ROOT, capture_output=True, text=True, stdin=subprocess.DEVNULL,
        )  # fmt: skip
        seconds = time.perf_counter() - t0
        if proc.returncode != 0:
            raise SystemExit(f"pip install {target} failed ({proc.returncode}):\n{proc.stderr[-3000:]}")
        site = next((venv / "lib").glob("python3*/site-packages"))
        megabytes, shares = tree_bytes(venv) / MB, distributions(site)  # before the quick start caches kernels
        runs = []
        for _ in range(2):
            t0 = time.perf_counter()
            subprocess.run(
                [str(venv / "bin" / "wmrid"), "identify", "sample_logs/paper_sinusoid.csv", "--robot", "paper",
                 "--format", "json", "-o", str(Path(tmp) / "result.json"), "--force"],
                cwd=ROOT, check=True, capture_output=True, stdin=subprocess.DEVNULL,
            )  # fmt: skip
            runs.append(time.perf_counter() - t0)
        return {"target": target, "seconds": seconds, "megabytes": megabytes, "distributions": shares,
                "identify_sample_seconds": {"first": runs[0], "second": runs[1]}}  # fmt: skip


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--extras", nargs="*", default=[], help="extras to install each on top of the core, one by one")
    args = ap.parse_args()
    installs = {}
    for extra in [None, *args.extras]:
        name = extra or "core"
        print(f"installing {name} ...", flush=True)
        installs[name] = got = install(extra)
        print(f"  pip install {got['target']}: {got['seconds']:.1f} s, {got['megabytes']:.0f} MB on disk")
        runs = got["identify_sample_seconds"]
        print(f"  the quick start's identify: {runs['first']:.1f} s the first time, {runs['second']:.1f} s the second")
        for dist, mb in list(got["distributions"].items())[:12]:
            print(f"    {dist:28s} {mb:7.1f} MB")
    write_results({"installs": installs, "python": sys.version.split()[0]})


if __name__ == "__main__":
    main()
