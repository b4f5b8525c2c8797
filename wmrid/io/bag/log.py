"""A ROS 1 bag, a ROS 2 sqlite3 bag, a rosbag2 folder or a recording split over several files as a wheel log: the
recording's paths (:func:`wmrid.io.bag.paths.recording_paths`) read through rosbags (:mod:`wmrid.io.bag.reader`) into
the same JointState logic as an MCAP file (:func:`wmrid.io.mcap.log.recording_log`: topics, joints, alignment, whole or
streamed in bounded memory).
"""

from __future__ import annotations

from collections.abc import Sequence

from wmrid.core.wheel_log import CHUNK_ROWS, LogStream
from wmrid.io.bag.reader import iter_bag_joint_parts, read_bag
from wmrid.io.mcap.log import Recording, field_selection, recording_log
from wmrid.io.ros.field_paths import FieldSignals
from wmrid.io.ros.selection import TopicSelection
from wmrid.io.signals import SignalOptions


def read_bag_log(
    paths: Sequence[str],
    selection: TopicSelection,
    signals: SignalOptions,
    gear_ratio: float | None,
    rows: int = CHUNK_ROWS,
    fields: FieldSignals | None = None,
) -> LogStream:
    """The LogStream of the recording in ``paths`` (see :func:`recording_paths`), JointState topics chosen, aligned
    and converted as for an MCAP file; ``fields``: the wheel signals by field path instead."""
    files = list(paths)
    topics = fields.topics() if fields is not None else None
    if fields is not None:
        selection = field_selection(selection, fields)
    recording = Recording(
        name=files[0] if len(files) == 1 else f"{files[0]} (+{len(files) - 1} more)",
        scan=lambda keep, spare: read_bag(files, keep=keep, spare=spare, fields=topics),
        read=lambda: read_bag(files, fields=topics),
        parts=lambda channels: iter_bag_joint_parts(files, channels, fields=topics),
    )
    return recording_log(recording, selection, signals, gear_ratio, rows, fields)
