"""Start-up cost of the ``wmrid`` CLI: process wall times and ``python -X importtime`` profiles.

1. Wall time (median of ``--repeat``, after one warm-up) of ``python -c pass`` (the interpreter alone),
   ``wmrid --help`` and ``wmrid --version``.
2. ``python -X importtime -m wmrid --help``: the slowest imports (what ``--help`` pays for; the bench runs wmrid
   only as its users do, so this profiles the command, whose ``wmrid.cli.app`` row is the command line's own cost).
3. ``python -X importtime -m wmrid identify sample_logs/paper_sinusoid.csv --robot paper --format json``
   (a 40 s log, so the run is mostly start-up): the ``--top`` slowest imports by cumulative time, the
   import time of every wmrid module, and the third-party imports summed per (importing wmrid module,
   package), lazy imports at run time (inside functions, or numba loading its cached kernels) counted
   apart.  Per-module figures are medians over ``--profiles`` runs.

Cumulative times nest (a package includes its sub-imports), so the rows of one list do not add up.

    python3 bench/speed/bench_startup.py
    python3 bench/speed/bench_startup.py --log sample_logs/paper_sinusoid.parquet --top 25
    python3 bench/speed/bench_startup.py --repeat 2 --profiles 1   # a quick check that it runs

Figures: printed, and written to bench/results/bench_startup.json (the wall times, the command line's cumulative
import time, and the ``--top`` slowest imports of each profile).
"""

from __future__ import annotations

import argparse
import os
import re
import subprocess
import sys
import time
from collections import defaultdict
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # bench/: the shared module _common
from _common import ROOT, median, wmrid_cmd, write_results

LINE = re.compile(r"import time:\s+(\d+) \|\s+(\d+) \| ( *)(\S+)")


def wall(cmd: list[str], repeat: int) -> float:
    subprocess.run(cmd, cwd=ROOT, capture_output=True, check=True)  # warm-up
    times = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        subprocess.run(cmd, cwd=ROOT, capture_output=True, check=True)
        times.append(time.perf_counter() - t0)
    return median(times)


def importtime(args: list[str]) -> tuple[list[dict], float]:
    """Rows {name, self, cum (ms), depth, parent} in the order printed (children before parents); wall s."""
    t0 = time.perf_counter()
    proc = subprocess.run(
        [sys.executable, "-X", "importtime", *args], cwd=ROOT, capture_output=True, text=True, stdin=subprocess.DEVNULL
    )
    elapsed = time.perf_counter() - t0
    if proc.returncode != 0:
        raise SystemExit(f"failed: {args}\n{proc.stderr[-2000:]}")
    rows = [
        {"name": m[4], "self": int(m[1]) / 1e3, "cum": int(m[2]) / 1e3, "depth": len(m[3]) // 2}
        for m in map(LINE.match, proc.stderr.splitlines())
        if m
    ]
    stack: list[dict] = []  # walk in reverse = parents before children
    for row in reversed(rows):
        while stack and stack[-1]["depth"] >= row["depth"]:
            stack.pop()
        row["parent"] = stack[-1]["name"] if stack else None
        stack.append(row)
    return rows, elapsed


def profile(args: list[str], runs: int) -> tuple[list[dict], float]:
    """importtime ``runs`` times; rows of the first run with self/cum replaced by medians over the runs."""
    importtime(args)  # warm-up (numba cache, page cache)
    results = [importtime(args) for _ in range(runs)]
    samples: dict[str, dict[str, list[float]]] = defaultdict(lambda: {"self": [], "cum": []})
    for rows, _ in results:
        for r in rows:
            samples[r["name"]]["self"].append(r["self"])
            samples[r["name"]]["cum"].append(r["cum"])
    rows = results[0][0]
    for r in rows:
        r["self"], r["cum"] = median(samples[r["name"]]["self"]), median(samples[r["name"]]["cum"])
    return rows, median([e for _, e in results])


def is_wmrid(name: str | None) -> bool:
    return name is not None and (name == "wmrid" or name.startswith("wmrid."))


def show(title: str, rows: list[dict], top: int) -> None:
    print(f"\n{title}")
    print(f"  {'cum ms':>8} {'self ms':>8}  {'module':<40} imported by")
    for r in rows[:top]:
        print(f"  {r['cum']:8.1f} {r['self']:8.1f}  {r['name']:<40} {r['parent'] or '(none: start-up or lazy)'}")


def entry_points(rows: list[dict], top: int) -> None:
    """Non-wmrid imports made directly by a wmrid module, or lazily at run time (no importer), summed
    per (importer, top-level package).  Entries are disjoint subtrees, so these sums do not double count.

    (Packages that load sub-packages through ``importlib.import_module``, as scipy does for
    ``scipy.optimize`` / ``scipy.stats``, print no line for the sub-package itself: its modules appear
    directly under the wmrid module that asked for it.)
    """
    groups: dict[tuple[str, str], list[dict]] = defaultdict(list)
    for r in rows:
        if not is_wmrid(r["name"]) and (r["parent"] is None or is_wmrid(r["parent"])):
            groups[(r["parent"] or "(none: start-up or lazy)", r["name"].split(".")[0])].append(r)
    ranked = sorted(groups.items(), key=lambda kv: -sum(r["cum"] for r in kv[1]))
    print("\nthird-party imports by the wmrid module that makes them (or lazily at run time):")
    print(f"  {'cum ms':>8}  {'package':<10} {'imported by':<25} largest entries (cum ms)")
    for (importer, pkg), members in ranked[:top]:
        members.sort(key=lambda r: -r["cum"])
        big = ", ".join(f"{r['name']} {r['cum']:.0f}" for r in members[:3]) + (" ..." if len(members) > 3 else "")
        print(f"  {sum(r['cum'] for r in members):8.1f}  {pkg:<10} {importer:<25} {big}")


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=10, help="runs per wall-time median (default 10)")
    ap.add_argument("--profiles", type=int, default=3, help="importtime runs per profile (default 3)")
    ap.add_argument("--top", type=int, default=15, help="rows per list (default 15)")
    ap.add_argument(
        "--log",
        default="sample_logs/paper_sinusoid.csv",
        help="log for the identify profile (default sample_logs/paper_sinusoid.csv)",
    )
    args = ap.parse_args()

    wm = wmrid_cmd()
    print(
        f"interpreter {sys.executable}; PYTHONDONTWRITEBYTECODE={os.environ.get('PYTHONDONTWRITEBYTECODE', '')!r}"
        " (if set, wmrid's own modules are byte-compiled on every run)"
    )
    print(f"\nwall time, median of {args.repeat} (after 1 warm-up):")
    walls = {}
    for label, cmd in [
        ("python -c pass", [sys.executable, "-c", "pass"]),
        ("wmrid --help", [*wm, "--help"]),
        ("wmrid --version", [*wm, "--version"]),
    ]:
        walls[label] = wall(cmd, args.repeat)
        print(f"  {label:<18} {walls[label] * 1e3:8.1f} ms")

    rows, help_elapsed = profile(["-m", "wmrid", "--help"], args.profiles)
    help_top = sorted((r for r in rows if r["name"] != "wmrid.cli.app"), key=lambda r: -r["cum"])
    cli = next(r for r in rows if r["name"] == "wmrid.cli.app")
    show(
        f"python -X importtime -m wmrid --help: wmrid.cli.app cumulative {cli['cum']:.1f} ms "
        f"(process {help_elapsed * 1e3:.0f} ms); slowest imports:",
        help_top,
        10,
    )

    ident = ["-m", "wmrid", "identify", args.log, "--robot", "paper", "--format", "json"]
    rows, elapsed = profile(ident, args.profiles)
    total = sum(r["cum"] for r in rows if r["depth"] == 0)
    print(f"\npython -X importtime {' '.join(ident)}")
    print(
        f"  process wall {elapsed * 1e3:.0f} ms (with -X importtime), of which imports {total:.0f} ms "
        f"(sum of top-level cumulative)"
    )
    show(f"{args.top} slowest imports by cumulative time:", sorted(rows, key=lambda r: -r["cum"]), args.top)
    show(
        "wmrid modules (cumulative includes what each imports):",
        sorted((r for r in rows if is_wmrid(r["name"])), key=lambda r: -r["cum"]),
        99,
    )
    entry_points(rows, args.top)

    def listed(entries: list[dict], top: int) -> list[dict]:
        return [{"module": r["name"], "cum_ms": r["cum"], "self_ms": r["self"]} for r in entries[:top]]

    write_results({
        "wall_s": walls,
        "help": {"process_s": help_elapsed, "cli_app_cumulative_ms": cli["cum"], "slowest": listed(help_top, 10)},
        "identify": {"command": " ".join(ident), "process_s": elapsed, "imports_ms": total,
                     "slowest": listed(sorted(rows, key=lambda r: -r["cum"]), args.top)},
    })  # fmt: skip


if __name__ == "__main__":
    main()
