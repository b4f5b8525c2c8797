"""Positions-only CSV and Parquet logs (issue 33, item 4): wheel angles pos_r, pos_l and torques, no speeds, read as
a bag's positions-only JointState is (the same Savitzky-Golay derivative and its note); a log with neither speeds nor
positions is refused in one line naming the file and both fixes."""

from __future__ import annotations

import numpy as np
import pandas as pd
import pytest
from locations import ROOT_DIR

import wmrid
from tests.cliutil import wmrid as run_cli
from tests.encoder_log import write_encoder_mcap
from wmrid.core.wheel_log import DERIVED_NOTE
from wmrid.io.logs import open_log, read_log
from wmrid.io.ros.selection import TopicSelection
from wmrid.io.signals import SignalOptions
from wmrid.io.table.columns import guess_candidates

SAMPLE = ROOT_DIR / "sample_logs" / "paper_sinusoid.csv"
BASE = ("m11", "m12", "m22", "Vc", "Fv1", "Fv2", "Fd1", "Fd2")


def wheel_angles(t: np.ndarray, eta: np.ndarray) -> np.ndarray:
    """Wheel angles (n, 2) rad: the speeds (n, 2) rad/s integrated by the trapezoidal rule from 0 at t[0]."""
    steps = 0.5 * (eta[1:] + eta[:-1]) * np.diff(t)[:, None]
    return np.vstack([np.zeros((1, 2)), np.cumsum(steps, axis=0)])


@pytest.fixture(scope="module")
def positions(tmp_path_factory):
    """The bundled sample with its speeds replaced by the wheel angles: a CSV, a Parquet and a positions-only MCAP
    (sensor_msgs/JointState, velocity empty) of the same angles and torques."""
    folder = tmp_path_factory.mktemp("positions")
    frame = pd.read_csv(SAMPLE)
    t = frame["t"].to_numpy()
    angle = wheel_angles(t, frame[["eta_r", "eta_l"]].to_numpy())
    table = pd.DataFrame(
        {"t": t, "pos_r": angle[:, 0], "pos_l": angle[:, 1], "tau_r": frame.tau_r, "tau_l": frame.tau_l}
    )
    table.to_csv(folder / "positions.csv", index=False)
    table.to_parquet(folder / "positions.parquet", index=False)
    write_encoder_mcap(folder / "positions.mcap", t, angle, frame[["tau_r", "tau_l"]].to_numpy())
    return folder


@pytest.fixture(scope="module")
def identified(positions):
    return {kind: wmrid.identify(str(positions / f"positions.{kind}"), "paper") for kind in ("csv", "mcap")}


def test_a_positions_only_csv_identifies_as_the_positions_only_mcap(identified):
    """Within 0.1 % of the MCAP's result for every base parameter (the issue's criterion), and the derivative's note
    says where the speeds came from, with the same window as the MCAP's."""
    csv, mcap = identified["csv"], identified["mcap"]
    for name in BASE:
        assert csv.parameters[name][0] == pytest.approx(mcap.parameters[name][0], rel=1e-3), name
    derived = [n for n in csv.log_info.notes if DERIVED_NOTE in n]
    assert derived == [
        "columns 'pos_r' and 'pos_l': " + DERIVED_NOTE + "21 samples (21 ms) (the log has no speed columns)"
    ]
    assert any(DERIVED_NOTE + "21 samples" in n for n in mcap.log_info.notes)


def test_a_positions_only_parquet_gives_the_csvs_speeds(positions):
    csv, parquet = (read_log(str(positions / f"positions.{kind}")) for kind in ("csv", "parquet"))
    np.testing.assert_array_equal(parquet.t, csv.t)
    np.testing.assert_allclose(parquet.eta, csv.eta, rtol=0, atol=1e-12)
    assert parquet.notes == csv.notes


def test_speeds_come_from_positions_in_pieces_as_read_whole(positions):
    """Read in pieces of 4096 rows, the derivative still sees the whole log: the same speeds as one piece."""
    path = str(positions / "positions.csv")
    whole = read_log(path)
    pieces = list(open_log(path, rows=4096))
    assert max(len(p) for p in pieces) == 4096
    np.testing.assert_array_equal(np.concatenate([p.eta for p in pieces]), whole.eta)


def test_the_speed_unit_says_the_positions_unit(positions, tmp_path):
    """--speed-unit deg/s: positions in degrees, as a bag's positions are read; the same speeds in rad/s."""
    table = pd.read_csv(positions / "positions.csv")
    table[["pos_r", "pos_l"]] = np.degrees(table[["pos_r", "pos_l"]])
    table.to_csv(tmp_path / "degrees.csv", index=False)
    degrees = read_log(str(tmp_path / "degrees.csv"), signals=SignalOptions(speed_unit="deg/s"))
    radians = read_log(str(positions / "positions.csv"))
    np.testing.assert_allclose(degrees.eta, radians.eta, rtol=1e-9, atol=1e-9)


def test_velocity_from_chooses_between_speeds_and_positions(tmp_path):
    """Both in the file: auto and velocity read the speeds, position derives them from the angles (with its note)."""
    frame = pd.read_csv(SAMPLE).iloc[:2000]
    frame["pos_r"], frame["pos_l"] = wheel_angles(frame.t.to_numpy(), frame[["eta_r", "eta_l"]].to_numpy()).T
    frame.to_csv(tmp_path / "both.csv", index=False)
    auto = read_log(str(tmp_path / "both.csv"))
    derived = read_log(str(tmp_path / "both.csv"), selection=TopicSelection(velocity_from="position"))
    np.testing.assert_array_equal(auto.eta, frame[["eta_r", "eta_l"]].to_numpy())
    assert not any(DERIVED_NOTE in n for n in auto.notes)
    assert [n for n in derived.notes if DERIVED_NOTE in n] == [
        "columns 'pos_r' and 'pos_l': " + DERIVED_NOTE + "21 samples (21 ms)"
    ]
    assert np.abs(derived.eta - auto.eta)[50:-50].max() < 1e-3  # the angles are the speeds' trapezoidal integral


def test_a_log_with_neither_speeds_nor_positions_is_refused_in_one_line(tmp_path):
    frame = pd.read_csv(SAMPLE).iloc[:100][["t", "tau_r", "tau_l"]]
    frame["wheel_a"] = 1.0
    frame.to_csv(tmp_path / "torques.csv", index=False)
    done = run_cli("identify", str(tmp_path / "torques.csv"), "--robot", "paper")
    assert done.returncode == 2
    lines = done.stderr.decode().splitlines()
    assert len(lines) == 1, lines
    assert str(tmp_path / "torques.csv") in lines[0]
    assert "--columns eta_r=...,eta_l=..." in lines[0]
    assert "pos_r=...,pos_l=..." in lines[0]
    assert "Traceback" not in done.stderr.decode()


def test_velocity_from_velocity_on_a_positions_only_log_names_the_way_out(positions):
    done = run_cli("identify", str(positions / "positions.csv"), "--robot", "paper", "--velocity-from", "velocity")
    assert done.returncode == 2
    (line,) = done.stderr.decode().splitlines()
    assert "no columns 'eta_r', 'eta_l'" in line
    assert line.endswith("or derive the speeds from the log's wheel positions with --velocity-from auto")


def test_position_columns_are_guessed_from_their_names():
    columns = [
        "__time", "/joint_states/right_wheel_joint/position", "/joint_states/left_wheel_joint/position",
        "/joint_states/right_wheel_joint/effort", "/joint_states/left_wheel_joint/effort", "cmd_pos_right",
        "right_angle_target",
    ]  # fmt: skip
    assert guess_candidates("pos_r", columns) == ["/joint_states/right_wheel_joint/position"]
    assert guess_candidates("pos_l", columns) == ["/joint_states/left_wheel_joint/position"]
    assert guess_candidates("eta_r", columns) == []  # a position is no speed
    assert guess_candidates("tau_r", columns) == ["/joint_states/right_wheel_joint/effort"]
