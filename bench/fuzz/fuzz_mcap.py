"""Ten minutes of the MCAP framing fuzzer (tests/contract/test_fuzz_mcap.py), in fresh processes so a segfault is
counted.

    python3 bench/fuzz/fuzz_mcap.py                 # 600 s, 1000 examples per compression per run
    python3 bench/fuzz/fuzz_mcap.py --seconds 60
    python3 bench/fuzz/fuzz_mcap.py --seconds 1 --examples 20   # one short run: a check that it runs

Each run is ``pytest tests/contract/test_fuzz_mcap.py`` with WMRID_FUZZ_EXAMPLES examples per compression (none, zstd,
lz4) and its own --hypothesis-seed (0, 1, 2, ...).  Printed: runs, cases tried, wall time, and every run that
failed or died (its seed, exit code and the tail of its output), which reproduces with the same seed.  Figures:
bench/results/fuzz_mcap.json.
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # bench/: the shared module _common
from _common import ROOT, write_results


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--seconds", type=float, default=600.0)
    ap.add_argument("--examples", type=int, default=1000, help="examples per compression per run")
    args = ap.parse_args()
    env = dict(os.environ, WMRID_FUZZ_EXAMPLES=str(args.examples))
    start = time.monotonic()
    runs = cases = 0
    failures = []
    seed = 0
    while time.monotonic() - start < args.seconds:
        proc = subprocess.run(
            [sys.executable, "-m", "pytest", "-q", "-p", "no:cacheprovider", f"--hypothesis-seed={seed}",
             "tests/contract/test_fuzz_mcap.py", "-k", "mutated"],
            cwd=ROOT, env=env, capture_output=True, text=True,
        )  # fmt: skip
        runs += 1
        if proc.returncode == 0:
            cases += 3 * args.examples
        else:
            failures.append((seed, proc.returncode, (proc.stdout + proc.stderr)[-2000:]))
        seed += 1
    wall = time.monotonic() - start
    print(f"{runs} runs, {cases} cases passed, {len(failures)} failed runs, {wall:.0f} s wall")
    for seed, code, tail in failures:
        print(f"\n--- seed {seed}: exit {code}\n{tail}")
    write_results({
        "runs": runs, "examples_per_compression": args.examples, "cases_passed": cases, "wall_s": wall,
        "failed_runs": [{"seed": seed, "exit_code": code} for seed, code, _ in failures],
    })  # fmt: skip
    sys.exit(1 if failures else 0)


if __name__ == "__main__":
    main()
