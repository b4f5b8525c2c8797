"""Regenerate the bundled sample logs: ``python sample_logs/make_samples.py [OUTDIR]``.

The paper's scenario (Hoang & Kang 2015, Sec. 5): the built-in ``paper`` robot with its CAD ("true")
parameters and friction F_v = diag(0.01, 0.015) N m s/rad, F_d = diag(0.045, 0.04) N m tracks the
sinusoid for 40 s under backstepping + computed torque built on the NOMINAL parameters, logged at
1 kHz without noise.  Written as

* ``paper_sinusoid.csv``: the five canonical columns t, eta_r, eta_l, tau_r, tau_l, each value rounded
  to 10 significant digits (a relative change of at most 5e-11, far below what identification resolves)
  to keep the file small;
* ``paper_sinusoid.parquet``: full precision, with the pose (x, y, phi; for path plots), and the truth
  in the schema metadata (key ``wmrid_truth``);
* ``paper_sinusoid.mcap``: a ROS 2 bag (zstd) with ``sensor_msgs/msg/JointState`` on ``/joint_states``
  (joints ``left_wheel_joint``, ``right_wheel_joint``: wheel angle, speed and torque, full precision) and
  the truth in an MCAP metadata record ``wmrid`` (key ``truth``);
* ``<log>.truth.json`` for each: the ground truth, of the form
  ``{"parameters": {"m11": ..., ...}, "physical": {...}, ...}``.

``tests/contract/test_sample_logs.py`` regenerates them and checks they are unchanged.
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

from wmrid.io.logs import write_log
from wmrid.io.mcap.writer import write_joint_state_mcap
from wmrid.model.robot import BUILTIN_ROBOTS
from wmrid.runtime.atomic import to_json_text, write_json
from wmrid.sim.simulate import simulate

NAME = "paper_sinusoid"
DURATION = 40.0  # s, the paper's Fig. 5-7
RATE = 1000.0  # Hz, the paper's T = 1 ms
CANONICAL = ["t", "eta_r", "eta_l", "tau_r", "tau_l"]
WITH_POSE = [*CANONICAL, "x", "y", "phi"]
SIGNIFICANT = 10


def round_significant(values: np.ndarray, digits: int = SIGNIFICANT) -> np.ndarray:
    """``values`` rounded to ``digits`` significant decimal digits (exactly what ``'%.{digits}g'`` prints)."""
    return np.array([float(f"{v:.{digits}g}") for v in values.tolist()], dtype=np.float64)


def build(outdir: Path) -> list[Path]:
    """Write the sample logs into ``outdir``; return the paths written."""
    robot = BUILTIN_ROBOTS["paper"]
    sim = simulate(robot.reference, robot.nominal, trajectory="sinusoid", duration=DURATION, rate=RATE, seed=0)
    truth = sim.truth()
    truth["robot"] = robot.name
    frame = sim.to_frame()
    csv_frame = frame[CANONICAL].copy()
    for col in CANONICAL:
        csv_frame[col] = round_significant(csv_frame[col].to_numpy())
    outdir.mkdir(parents=True, exist_ok=True)
    csv_path = outdir / f"{NAME}.csv"
    parquet_path = outdir / f"{NAME}.parquet"
    write_log(csv_frame, str(csv_path), force=True)
    write_log(frame[WITH_POSE], str(parquet_path), force=True, metadata={"wmrid_truth": to_json_text(truth)})
    mcap_path = outdir / f"{NAME}.mcap"
    with_angles = [*CANONICAL, "theta_r", "theta_l"]
    write_joint_state_mcap(
        mcap_path, frame[with_angles], force=True, odom_topic=None, metadata={"truth": to_json_text(truth)}
    )
    written = [csv_path, parquet_path, mcap_path]
    for path in written[:]:
        truth_path = Path(str(path) + ".truth.json")
        write_json(truth_path, truth, force=True)
        written.append(truth_path)
    return written


if __name__ == "__main__":
    target = Path(sys.argv[1]) if len(sys.argv) > 1 else Path(__file__).resolve().parent
    for p in build(target):
        print(f"wrote {p} ({p.stat().st_size} bytes)")
