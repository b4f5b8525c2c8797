"""The joint names of a channel's first JointState, read straight from its bytes (CDR: :func:`cdr_joint_names`;
ROS 1: :func:`ros1_joint_names`) instead of through a generic deserialiser, checked against
rosbags' deserialisers: equal names on every well-formed message, and on damaged bytes either None (the caller
then decodes the message generically) or the names rosbags reads from the same bytes."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from rosbags.typesys import Stores, get_typestore

from wmrid.io.mcap.records import cdr_joint_names, ros1_joint_names

ROS2 = get_typestore(Stores.ROS2_HUMBLE)
ROS1 = get_typestore(Stores.ROS1_NOETIC)
JS = "sensor_msgs/msg/JointState"


def _message(store, names, frame_id="", sec=0, nsec=0, n_values=None):
    types = store.types
    header_fields = {"stamp": types["builtin_interfaces/msg/Time"](sec=sec, nanosec=nsec), "frame_id": frame_id}
    if store is ROS1:
        header_fields["seq"] = 7
    k = len(names) if n_values is None else n_values
    values = np.arange(k, dtype=np.float64)
    return types[JS](header=types["std_msgs/msg/Header"](**header_fields), name=list(names), position=values,
                     velocity=values + 0.5, effort=values - 0.5)  # fmt: skip


def cdr(names, **kw) -> bytes:
    return bytes(ROS2.serialize_cdr(_message(ROS2, names, **kw), JS))


def ros1(names, **kw) -> bytes:
    return bytes(ROS1.serialize_ros1(_message(ROS1, names, **kw), JS))


READERS = {
    "cdr": (cdr, cdr_joint_names, lambda raw: ROS2.deserialize_cdr(raw, JS)),
    "ros1": (ros1, ros1_joint_names, lambda raw: ROS1.deserialize_ros1(raw, JS)),
}

CASES = [
    ["right_wheel_joint", "left_wheel_joint"],
    [],
    [""],
    ["a"],
    ["ab", "abc", "abcd", "abcde"],  # every alignment of the next string
    ["räder_rechts", "轮子"],  # multi-byte UTF-8
    [f"joint_{i}" for i in range(300)],
]


def _rosbags_names(decode, raw):
    """rosbags' names for ``raw``, or None when its deserialiser refuses the bytes or reads nonsense."""
    try:
        return [str(n) for n in decode(raw).name]
    except Exception:
        return None


@pytest.mark.parametrize("fmt", READERS)
@pytest.mark.parametrize("names", CASES)
@pytest.mark.parametrize("frame_id", ["", "o", "odom", "base_link_12"])
def test_names_equal_the_deserialisers(fmt, names, frame_id):
    make, read, decode = READERS[fmt]
    raw = make(names, frame_id=frame_id, sec=1_700_000_000, nsec=999_999_999)
    assert read(raw) == names == _rosbags_names(decode, raw)


TEXT = st.text(st.characters(blacklist_categories=("Cs",), blacklist_characters="\x00"), max_size=12)


@given(names=st.lists(TEXT, max_size=8), frame_id=TEXT)
@settings(max_examples=200, deadline=None, derandomize=True)
def test_generated_names_equal_the_deserialisers(names, frame_id):
    for make, read, decode in READERS.values():
        raw = make(names, frame_id=frame_id)
        assert read(raw) == names == _rosbags_names(decode, raw)


@pytest.mark.parametrize("fmt", READERS)
def test_damaged_bytes_give_none_or_what_rosbags_reads(fmt):
    """Every truncation, and every byte set to 0x00, 0xFF and a random value (seeded): the reader never raises and
    never invents names.  It returns None, or rosbags' names for the same bytes, or the original names where rosbags
    refuses the message for damage the reader does not look at (a frame_id no longer UTF-8, cut arrays)."""
    make, read, decode = READERS[fmt]
    original = ["ab", "right_wheel_joint", "left"]
    raw = make(original, frame_id="odom")
    rng = np.random.default_rng(15)
    variants = [raw[:cut] for cut in range(len(raw))]
    variants += [raw[:i] + bytes([v]) + raw[i + 1 :] for i in range(len(raw)) for v in (0, 255, int(rng.integers(256)))]
    wrong = []
    for damaged in variants:
        names = read(damaged)
        if names is None:
            continue
        theirs = _rosbags_names(decode, damaged)
        if names != theirs and not (theirs is None and names == original):
            wrong.append((damaged, names, theirs))
    assert not wrong
