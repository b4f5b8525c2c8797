"""From an MCAP's joints to a wheel log (wmrid.io.ros.joints), function by function, against hand values; and
inspect (wmrid.io.inspect) on CSV and Parquet."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest

import wmrid
from wmrid.core.errors import LogFormatError
from wmrid.core.wheel_log import SPLIT_NOTE, split_topics
from wmrid.io.ros.joints import align, choose_joints
from wmrid.io.ros.selection import TopicSelection


@pytest.mark.parametrize(
    ("names", "right", "left"),
    [
        (("left_wheel_joint", "right_wheel_joint"), "right_wheel_joint", "left_wheel_joint"),
        (("caster_left", "wheel_left", "wheel_right", "caster_right"), "wheel_right", "wheel_left"),
        (("RightWheel", "LeftWheel", "arm"), "RightWheel", "LeftWheel"),
        (("right", "left"), "right", "left"),  # no "wheel" anywhere: right/left alone
    ],
)
def test_wheel_joints_are_chosen_by_name_and_the_choice_is_said(names, right, left):
    r, l_, note = choose_joints(names, TopicSelection(), "bag.mcap", "/joint_states")
    assert (r, l_) == (right, left)
    assert note == f"wheel joints chosen by name: right = {right!r}, left = {left!r}"


def test_named_joints_are_checked_and_ambiguous_ones_refused_with_the_fix():
    sel = TopicSelection(right_joint="a", left_joint="b")
    assert choose_joints(("a", "b", "c"), sel, "bag.mcap", "/js") == ("a", "b", None)
    with pytest.raises(LogFormatError, match=r"bag.mcap: topic /js has no joint 'b'; its joints are a, c"):
        choose_joints(("a", "c"), sel, "bag.mcap", "/js")
    with pytest.raises(LogFormatError, match=r"cannot tell the right and left wheel joints.*right_joint NAME"):
        choose_joints(("wheel_a", "wheel_b"), TopicSelection(), "bag.mcap", "/js")


def test_efforts_are_put_on_the_speed_stamps_held_or_interpolated():
    """Speeds at 1 kHz, efforts at 250 Hz from 2 ms on: zoh takes the latest effort at or before each speed stamp
    (searchsorted by hand), linear np.interp; speeds before the first effort are dropped and counted in the note."""
    t_vel = np.arange(0, 20) * 1e-3
    speed = np.column_stack([t_vel, -t_vel])
    t_eff = 2e-3 + np.arange(0, 5) * 4e-3
    effort = np.column_stack([np.arange(5.0), 10 + np.arange(5.0)])
    t, s, e, note = align(t_vel, speed, t_eff, effort, "zoh", "/v", "/e", "bag")
    assert t[0] == 2e-3 and len(t) == 18  # noqa: PT018 (one statement: the first kept stamp and the count)
    np.testing.assert_array_equal(s, speed[2:])
    held = [int(np.floor((x - 2e-3) / 4e-3 + 1e-9)) for x in t]
    np.testing.assert_array_equal(e[:, 0], held)
    assert SPLIT_NOTE in note
    assert "2 speed samples outside the effort's time span dropped" in note
    assert split_topics((note,))
    t, s, e, note = align(t_vel, speed, t_eff, effort, "linear", "/v", "/e", "bag")
    assert t[-1] == t_eff[-1]  # linear: no extrapolation past the last effort
    np.testing.assert_allclose(e[:, 1], np.interp(t, t_eff, effort[:, 1]), rtol=0, atol=1e-15)
    with pytest.raises(LogFormatError, match="too few messages on /v or /e"):
        align(t_vel[:1], speed[:1], t_eff, effort, "zoh", "/v", "/e", "bag")


def test_inspect_a_csv_and_a_parquet_log(tmp_path):
    frame = pd.DataFrame({"t": [0.0, 0.001, 0.002], "eta_r": [1.0, 1.0, 1.0], "tau_r": [0.1, 0.2, 0.3], "x": [0, 0, 0]})
    frame.to_csv(tmp_path / "a.csv", index=False)
    frame.to_parquet(tmp_path / "a.parquet")
    csv = wmrid.inspect(tmp_path / "a.csv")
    parquet = wmrid.inspect(tmp_path / "a.parquet")
    for info in (csv, parquet):
        assert [c.name for c in info.columns] == ["t", "eta_r", "tau_r", "x"]
        assert info.canonical_found == ["t", "eta_r", "tau_r", "x"]
        assert info.canonical_missing == ["eta_l", "tau_l"]
    assert (csv.format, csv.rows) == ("csv", None)
    assert (parquet.format, parquet.rows) == ("parquet", 3)
    assert list(parquet.to_dict()) == [
        "source", "format", "rows", "columns", "canonical_found", "canonical_missing", "notes", "comments"
    ]  # fmt: skip
