"""Simulator speed: ``wmrid.sim.simulate.simulate`` in-process and ``wmrid simulate`` as a subprocess.

In-process (a fresh interpreter is not needed: this script does not import the simulator before):
the first call, which includes numba compilation or loading the on-disk cache, then the median of
``--repeat`` further calls; samples/s.  Subprocess: ``wmrid simulate -o bench/out/X.parquet --duration D
--force`` (one warm-up, then ``--repeat`` runs; wall time with process start, and peak RSS under
``/usr/bin/time -v``).

    /work/venv/bin/python bench/bench_simulate.py                  # 60 s at 1 kHz
    /work/venv/bin/python bench/bench_simulate.py --duration 600 --repeat 3
"""

from __future__ import annotations

import argparse
import time

from _common import OUT, fmt_rss, median, run_timed, wmrid_cmd


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=60.0, help="simulated time, s (default 60)")
    ap.add_argument("--rate", type=float, default=1000.0, help="log rate, Hz (default 1000)")
    ap.add_argument("--seed", type=int, default=1, help="simulation seed (default 1)")
    ap.add_argument("--repeat", type=int, default=5, help="timed calls / runs (default 5)")
    args = ap.parse_args()

    t0 = time.perf_counter()
    from wmrid.model.robot import BUILTIN_ROBOTS
    from wmrid.sim.scenario import NoiseSettings
    from wmrid.sim.simulate import simulate

    t_import = time.perf_counter() - t0
    r = BUILTIN_ROBOTS["paper"]
    noise = NoiseSettings(eta_std=0.01, tau_std=0.02, caster_std=0.05)

    def call() -> tuple[float, int]:
        t0 = time.perf_counter()
        sim = simulate(
            r.reference,
            r.nominal,
            trajectory="sinusoid",
            duration=args.duration,
            rate=args.rate,
            noise=noise,
            seed=args.seed,
        )
        return time.perf_counter() - t0, len(sim.t)

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
    print(f"  import wmrid.sim.simulate            {t_import:8.3f} s   (numba, numpy)")
    print(f"  first call (compile/cache load)  {first:8.3f} s")
    print(f"  median of {args.repeat} further calls     {rest:8.3f} s   {n / rest:12,.0f} samples/s")
    print(f"\nsubprocess: {' '.join(cmd)}")
    print(
        f"  1 warm-up, then {args.repeat} runs: wall min {min(walls):.3f} s, median {median(walls):.3f} s, "
        f"peak RSS {fmt_rss(max(rss) if rss else None)} MB"
    )


if __name__ == "__main__":
    main()
