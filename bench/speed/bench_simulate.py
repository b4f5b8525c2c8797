"""Simulator speed: ``wmrid.simulate`` in-process and ``wmrid simulate`` as a subprocess.

In-process (a fresh interpreter is not needed: this script does not import the simulator before): ``import wmrid``
and the first use of ``wmrid.simulate`` (the lazy front door loads the API's module then); the first call, which
imports the simulator (numpy, numba) and compiles its kernels or loads them from numba's cache; then the median of
``--repeat`` further calls; samples/s.  Subprocess: ``wmrid simulate -o bench/out/X.parquet --duration D --force``
(one warm-up, then ``--repeat`` runs; wall time with process start, and peak RSS under ``/usr/bin/time -v``).

    python3 bench/speed/bench_simulate.py                  # 60 s at 1 kHz
    python3 bench/speed/bench_simulate.py --duration 600 --repeat 3
    python3 bench/speed/bench_simulate.py --duration 10 --repeat 1   # a quick check that it runs

Figures: printed, and written to bench/results/bench_simulate.json.  (Before the bench used only the public API it
timed the simulator's kernel call with the robot's parameter sets; ``wmrid.simulate`` also loads the robot and
builds the truth, a few milliseconds.)
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # bench/: the shared module _common
from _common import OUT, fmt_rss, median, run_timed, wmrid_cmd, write_results


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=60.0, help="simulated time, s (default 60)")
    ap.add_argument("--rate", type=float, default=1000.0, help="log rate, Hz (default 1000)")
    ap.add_argument("--seed", type=int, default=1, help="simulation seed (default 1)")
    ap.add_argument("--repeat", type=int, default=5, help="timed calls / runs (default 5)")
    args = ap.parse_args()

    t0 = time.perf_counter()
    import wmrid

    simulate = wmrid.simulate  # the lazy front door imports the simulator here
    t_import = time.perf_counter() - t0
    noise = wmrid.NoiseSettings(eta_std=0.01, tau_std=0.02, caster_std=0.05, seed=args.seed)

    def call() -> tuple[float, int]:
        t0 = time.perf_counter()
        run = simulate("paper", trajectory="sinusoid", duration=args.duration, rate=args.rate, noise=noise)
        return time.perf_counter() - t0, len(run.log.t)

    first, n = call()
    rest = median([call()[0] for _ in range(args.repeat)])

    OUT.mkdir(parents=True, exist_ok=True)
    out = OUT / f"bench_simulate_{args.duration:g}s.parquet"
    cmd = [
        *wmrid_cmd(),
        "simulate",
        "-o",
        str(out),
        "--duration",
        f"{args.duration:g}",
        "--rate",
        f"{args.rate:g}",
        "--seed",
        str(args.seed),
        "--eta-noise",
        "0.01",
        "--tau-noise",
        "0.02",
        "--caster",
        "0.05",
        "--force",
    ]
    run_timed(cmd)  # warm-up
    runs = [run_timed(cmd) for _ in range(args.repeat)]
    walls = [x.wall for x in runs]
    rss = [x.rss_mb for x in runs if x.rss_mb is not None]

    print(f"simulate(): paper robot, sinusoid, {args.duration:g} s at {args.rate:g} Hz = {n:,} samples, 4 RK4 substeps")
    print(f"  import wmrid; wmrid.simulate     {t_import:8.3f} s   (the API's modules)")
    print(f"  first call (simulator's import, numba compile/cache load)  {first:8.3f} s")
    print(f"  median of {args.repeat} further calls     {rest:8.3f} s   {n / rest:12,.0f} samples/s")
    print(f"\nsubprocess: {' '.join(cmd)}")
    print(
        f"  1 warm-up, then {args.repeat} runs: wall min {min(walls):.3f} s, median {median(walls):.3f} s, "
        f"peak RSS {fmt_rss(max(rss) if rss else None)} MB"
    )
    write_results({
        "duration_s": args.duration, "rate_hz": args.rate, "samples": n,
        "in_process": {"import_s": t_import, "first_call_s": first, "median_call_s": rest, "samples_per_s": n / rest},
        "subprocess": {"min_s": min(walls), "median_s": median(walls), "peak_rss_mb": max(rss) if rss else None},
    })  # fmt: skip


if __name__ == "__main__":
    main()
