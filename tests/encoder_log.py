"""Encoder logs for the tests and bench/studies/study_encoder.py (a helper module, not a test module): a simulated run's
wheel angles quantised as an incremental encoder counts them, written as a ROS 2 MCAP of sensor_msgs/JointState
holding only the positions and the efforts (the velocity sequence empty), so wmrid derives the speeds from the
positions (:func:`wmrid.io.signals.speed_from_position`), as it does for a driver that publishes counts only."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np

T0_NS = 1_700_000_000 * 10**9


def quantised_angles(angle: np.ndarray, cpr: int, seed: int) -> np.ndarray:
    """Wheel angles (n, 2) rad as a ``cpr``-count/rev encoder reports them: floor((angle + offset) / step) * step,
    step = 2 pi / cpr, the offset (where each wheel's count changes) drawn uniformly in [0, step) per wheel from
    numpy's PCG64 seeded with ``seed`` (the simulator's run is noise-free, so this is what varies over seeds)."""
    step = 2.0 * math.pi / cpr
    offset = np.random.default_rng(seed).uniform(0.0, step, 2)
    return np.floor((np.asarray(angle, dtype=float) + offset) / step) * step


def write_encoder_mcap(path: Path, t: np.ndarray, angle: np.ndarray, tau: np.ndarray) -> Path:
    """A JointState per sample on /joint_states: position = ``angle`` (n, 2) rad [right, left], effort = ``tau``
    (n, 2) N m, velocity empty; stamps T0_NS + t (n,) s.  Written by mcap_ros2's own (generic) writer."""
    from mcap_ros2.writer import Writer

    from wmrid.io.mcap.writer import JOINT_STATE_MSGDEF

    names = ["left_wheel_joint", "right_wheel_joint"]
    with open(path, "wb") as fh:
        writer = Writer(fh)
        schema = writer.register_msgdef("sensor_msgs/msg/JointState", JOINT_STATE_MSGDEF)
        for k, ns in enumerate((T0_NS + np.round(np.asarray(t) * 1e9).astype(np.int64)).tolist()):
            msg = {
                "header": {"stamp": {"sec": ns // 10**9, "nanosec": ns % 10**9}, "frame_id": "base_link"},
                "name": names, "position": [float(angle[k, 1]), float(angle[k, 0])], "velocity": [],
                "effort": [float(tau[k, 1]), float(tau[k, 0])],
            }  # fmt: skip
            writer.write_message("/joint_states", schema, msg, log_time=ns, publish_time=ns)
        writer.finish()
    return Path(path)


def encoder_mcap(path: Path, sim, cpr: int, seed: int) -> Path:
    """``sim`` (a :class:`wmrid.sim.simulate.SimulatedLog`, noise-free speeds) as a positions-only MCAP of a
    ``cpr``-count encoder (:func:`quantised_angles`, :func:`write_encoder_mcap`)."""
    return write_encoder_mcap(path, sim.t, quantised_angles(sim.wheel_angle, cpr, seed), sim.tau)
