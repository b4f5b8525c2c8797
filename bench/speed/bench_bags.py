"""Bag benchmark: ``wmrid identify`` on a 10-minute 1 kHz JointState recording as a ROS 1 bag and as a ROS 2 .db3,
against a plain rosbags deserialise loop over the same file.

The recording is bench_mcap.py's (``_common.mcap_log``: a noisy ``paper`` simulation, ``--duration`` s, default
600 = 600,001 ``sensor_msgs/msg/JointState`` messages), converted with rosbags: to a ROS 1 bag (each message
deserialised from CDR and serialised for ROS 1, header ``seq`` added; ``--compression`` none, lz4 or bz2 chunks,
default none) and to a rosbag2 folder with sqlite3 storage (the CDR bytes as they are).  Both are made once into
bench/out/.

Measured, per format, as subprocesses (wall time including process start and imports, as a user sees it):
(a) the deserialise loop: ``rosbags.highlevel.AnyReader`` over the file, ``reader.deserialize(raw, type)`` for
    every message, touching ``msg.velocity[0]`` (``--loop-repeat`` runs, default 1: it is slow);
(b) ``wmrid identify BAG --robot paper --format json``: one untimed warm-up, then ``--repeat`` runs (default 3),
    median; peak RSS under /usr/bin/time.
Also, in one process each (what a command costs beyond its start-up: Python, numpy, numba's import and first-call
initialisation, typer, about 1 s on this machine): the loop after importing rosbags, and the library call
``wmrid.identify(BAG, robot="paper")`` after a warm-up call on the 5-s recording of the same kind.

Target (issue 15): identify <= 0.25 x the deserialise loop on both formats, judged on the throughput (the
in-process figures: what each costs per recording beyond the fixed start-up of its process).  The commands' ratios
are printed too, with ``wmrid identify`` on the 5-s recording as a command (its start-up, about 1.2 s here: numba's
import and initialisation are 0.6 s of it): on a 10-minute recording that start-up is most of the db3's time; on
an hour (``--duration 3600``) the commands meet the target as well.

    python3 bench/speed/bench_bags.py
    python3 bench/speed/bench_bags.py --duration 60 --repeat 1   # a quick check that it runs

Figures: printed, and written to bench/results/bench_bags.json.
"""

from __future__ import annotations

import argparse
import json
import sys
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # bench/: the shared module _common
from _common import OUT, ROOT, fmt_rss, mcap_log, median, run_timed, wmrid_cmd, write_results

RATIO_TARGET = 0.25

LOOP_SRC = """\
import sys
from pathlib import Path
from rosbags.highlevel import AnyReader
n = 0
with AnyReader([Path(sys.argv[1])]) as reader:
    for connection, stamp, raw in reader.messages():
        msg = reader.deserialize(raw, connection.msgtype)
        v = msg.velocity[0]
        n += 1
print(n)
"""


def ros1_bag(mcap: Path, compression: str) -> Path:
    """The MCAP's JointState messages in a ROS 1 bag (made once)."""
    path = OUT / f"{mcap.stem}_{compression}.bag"
    if path.exists():
        return path
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag1 import Writer
    from rosbags.typesys import Stores, get_typestore

    print(f"converting {mcap.name} to {path.name} ...", flush=True)
    ros1 = get_typestore(Stores.ROS1_NOETIC)
    js, header, time = (ros1.types[n] for n in ("sensor_msgs/msg/JointState", "std_msgs/msg/Header",
                                                  "builtin_interfaces/msg/Time"))  # fmt: skip
    tmp = path.with_suffix(".tmp.bag")
    tmp.unlink(missing_ok=True)
    writer = Writer(tmp)
    if compression != "none":
        writer.set_compression(getattr(Writer.CompressionFormat, compression.upper()))
    with AnyReader([mcap]) as reader, writer:
        conn = writer.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=ros1)
        for seq, (c, stamp, raw) in enumerate(reader.messages()):
            m = reader.deserialize(raw, c.msgtype)
            one = js(header=header(seq=seq, stamp=time(sec=m.header.stamp.sec, nanosec=m.header.stamp.nanosec),
                                   frame_id=m.header.frame_id), name=list(m.name), position=m.position,
                     velocity=m.velocity, effort=m.effort)  # fmt: skip
            writer.write(conn, stamp, ros1.serialize_ros1(one, "sensor_msgs/msg/JointState"))
    tmp.rename(path)
    return path


def db3_folder(mcap: Path) -> Path:
    """The MCAP's messages in a rosbag2 folder with sqlite3 storage (made once)."""
    path = OUT / f"{mcap.stem}_db3"
    if path.exists():
        return path
    from rosbags.highlevel import AnyReader
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    print(f"converting {mcap.name} to {path.name}/ ...", flush=True)
    store = get_typestore(Stores.ROS2_HUMBLE)
    with AnyReader([mcap]) as reader, Writer(path, version=9, storage_plugin=StoragePlugin.SQLITE3) as writer:
        conn = writer.add_connection("/joint_states", "sensor_msgs/msg/JointState", typestore=store)
        for _, stamp, raw in reader.messages():
            writer.write(conn, stamp, raw)
    return path


def loop(path: Path, repeat: int) -> dict:
    runs = [run_timed([sys.executable, "-c", LOOP_SRC, str(path)]) for _ in range(repeat)]
    walls = [r.wall for r in runs]
    return {"n": int(runs[0].stdout.strip()), "median": median(walls), "rss": max(r.rss_mb or 0 for r in runs)}


IN_PROCESS_SRC = """\
import sys, time
from pathlib import Path
kind, path, warm = sys.argv[1], Path(sys.argv[2]), Path(sys.argv[3])
if kind == "loop":
    from rosbags.highlevel import AnyReader
    t = time.perf_counter()
    with AnyReader([path]) as reader:
        for connection, stamp, raw in reader.messages():
            v = reader.deserialize(raw, connection.msgtype).velocity[0]
else:
    import wmrid
    wmrid.identify(str(warm), robot="paper")
    t = time.perf_counter()
    wmrid.identify(str(path), robot="paper")
print(time.perf_counter() - t)
"""


def in_process(kind: str, path: Path, warm: Path) -> float:
    return float(run_timed([sys.executable, "-c", IN_PROCESS_SRC, kind, str(path), str(warm)]).stdout.strip())


def identify(path: Path, repeat: int) -> dict:
    cmd = [*wmrid_cmd(), "identify", str(path), "--robot", "paper", "--format", "json"]
    run_timed(cmd)  # warm-up: numba's cache, the page cache
    runs = [run_timed(cmd) for _ in range(repeat)]
    m11 = json.loads(runs[-1].stdout)["parameters"]["m11"]["value"]
    walls = [r.wall for r in runs]
    return {"median": median(walls), "min": min(walls), "rss": max(r.rss_mb or 0 for r in runs), "m11": m11}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--duration", type=float, default=600.0, help="recording length, s (default 600)")
    ap.add_argument("--seed", type=int, default=1)
    ap.add_argument("--compression", choices=["none", "lz4", "bz2"], default="none", help="ROS 1 chunk compression")
    ap.add_argument("--repeat", type=int, default=3, help="timed identify runs after the warm-up (default 3)")
    ap.add_argument("--loop-repeat", type=int, default=1, help="deserialise-loop runs (default 1)")
    args = ap.parse_args()

    mcap = mcap_log(args.duration, args.seed)
    bags = {"ROS 1 bag": ros1_bag(mcap, args.compression), "ROS 2 db3": db3_folder(mcap)}
    small = mcap_log(5.0, args.seed)
    warm = {"ROS 1 bag": ros1_bag(small, args.compression), "ROS 2 db3": db3_folder(small)}
    print(f"\nrecording: {args.duration:g} s at 1 kHz ({mcap.relative_to(ROOT)} converted)")
    print(f"as commands (start-up included):\n{'format':<11} {'loop s':>8} {'msg/s':>10} {'identify s':>11} "
          f"{'(min)':>7} {'peak MB':>8} {'ratio':>7} {'start-up s':>11}")  # fmt: skip
    commands, throughput = {}, {}
    for name, path in bags.items():
        lp = loop(path, args.loop_repeat)
        ident = identify(path, args.repeat)
        start = identify(warm[name], args.repeat)["median"]
        commands[name] = {"loop": lp, "identify": ident, "startup_s": start, "ratio": ident["median"] / lp["median"]}
        print(f"{name:<11} {lp['median']:8.2f} {lp['n'] / lp['median']:10,.0f} {ident['median']:11.2f} "
              f"{ident['min']:7.2f} {fmt_rss(ident['rss']):>8} {ident['median'] / lp['median']:7.3f} "
              f"{start:11.2f}")  # fmt: skip
    print(f"\nthroughput, in one process (start-up and imports excluded):\n{'format':<11} {'loop s':>8} "
          f"{'identify s':>11} {'ratio':>7}")  # fmt: skip
    for name, path in bags.items():
        lp, ident = in_process("loop", path, warm[name]), in_process("identify", path, warm[name])
        verdict = "MET" if ident / lp <= RATIO_TARGET else "NOT MET"
        throughput[name] = {"loop_s": lp, "identify_s": ident, "ratio": ident / lp, "met": ident / lp <= RATIO_TARGET}
        print(f"{name:<11} {lp:8.2f} {ident:11.2f} {ident / lp:7.3f} {verdict}")
    print(f"\ntarget: identify <= {RATIO_TARGET} x the rosbags deserialise loop (throughput)")
    write_results({
        "recording": {"duration_s": args.duration, "source": str(mcap.relative_to(ROOT)),
                      "compression": args.compression},
        "as_commands": commands, "in_one_process": throughput, "ratio_target": RATIO_TARGET,
    })  # fmt: skip


if __name__ == "__main__":
    main()
