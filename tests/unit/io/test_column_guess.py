"""Column names that say what they hold (PlotJuggler and Foxglove exports, vendor CSVs) are mapped without
``--columns``: right/left plus a speed or effort word, no command or set-point word.  One candidate per signal:
used, with a note; several: refused with the candidates listed.  A PlotJuggler export (time column ``__time``)
interleaves other topics' rows, empty in the wheel columns: those rows are dropped, with a note.
"""

from __future__ import annotations

import json

import numpy as np
import pandas as pd
import pytest

from tests.cliutil import wmrid
from wmrid.io.logs import read_log
from wmrid.io.table.columns import guess_candidates, words
from wmrid.model.robot import BUILTIN_ROBOTS
from wmrid.sim.simulate import simulate

PAPER = BUILTIN_ROBOTS["paper"]
T0 = 1.7e9  # PlotJuggler's __time: epoch seconds


@pytest.fixture(scope="module")
def frame():
    return simulate(PAPER.reference, PAPER.nominal, trajectory="sinusoid", duration=3.0, seed=3).to_frame()


def plotjuggler(frame: pd.DataFrame, with_commands: bool = True) -> pd.DataFrame:
    """A PlotJuggler CSV export of /joint_states (renamed by joint, as PlotJuggler does) and /cmd_vel at 100 Hz:
    one table on the union of the topics' times, blank where a topic has no sample."""
    js = pd.DataFrame({
        "__time": T0 + frame.t,
        "/joint_states/header/stamp": T0 + frame.t,
        "/joint_states/left_wheel_joint/position": np.cumsum(frame.eta_l) * 1e-3,
        "/joint_states/left_wheel_joint/velocity": frame.eta_l,
        "/joint_states/left_wheel_joint/effort": frame.tau_l,
        "/joint_states/right_wheel_joint/position": np.cumsum(frame.eta_r) * 1e-3,
        "/joint_states/right_wheel_joint/velocity": frame.eta_r,
        "/joint_states/right_wheel_joint/effort": frame.tau_r,
    })  # fmt: skip
    if not with_commands:
        return js
    cmd = pd.DataFrame({"__time": T0 + frame.t[::10] + 5e-4, "/cmd_vel/linear/x": 0.3, "/cmd_vel/angular/z": 0.1})
    return pd.concat([js, cmd]).sort_values("__time", kind="stable")


def test_words_split_names_as_they_are_written():
    assert words("/joint_states/right_wheel_joint/velocity") == [
        "joint",
        "states",
        "right",
        "wheel",
        "joint",
        "velocity",
    ]
    assert words("velLeft") == ["vel", "left"]
    assert words("meas_right_vel") == ["meas", "right", "vel"]
    assert words("Motor2Current") == ["motor", "2", "current"]
    assert words("/joint_states.velocity[0]") == ["joint", "states", "velocity", "0"]


def test_candidates_leave_out_commands_positions_and_the_other_side():
    cols = ["ros_time", "cmd_right_vel", "meas_right_vel", "right_wheel_position", "left_right_vel", "right_torque_max",
            "velocity_r", "torque_right", "tau_r_desired"]  # fmt: skip
    assert guess_candidates("eta_r", cols) == ["meas_right_vel", "velocity_r"]
    assert guess_candidates("tau_r", cols) == ["torque_right"]
    assert guess_candidates("eta_l", cols) == []
    assert guess_candidates("t", ["stamp", "Time", "x"]) == ["Time"]  # the first name of the list present
    assert guess_candidates("t", ["/joint_states/header/stamp", "__time"]) == ["__time"]


def test_a_plotjuggler_export_reads_as_the_plain_log(tmp_path, frame):
    path = tmp_path / "pj.csv"
    plotjuggler(frame).to_csv(path, index=False)
    log = read_log(str(path))
    assert np.array_equal(log.eta, frame[["eta_r", "eta_l"]].to_numpy())
    assert np.array_equal(log.tau, frame[["tau_r", "tau_l"]].to_numpy())
    assert np.allclose(log.t - log.t[0], frame.t - frame.t[0], rtol=0, atol=1e-6)  # epoch seconds: 0.24 us rounding
    notes = " | ".join(log.notes)
    assert "columns for t, eta_r, eta_l, tau_r, tau_l guessed from their names" in notes
    assert "301 rows without any wheel speed or effort" in notes
    assert "eta_r = '/joint_states/right_wheel_joint/velocity'" in notes


def test_the_cli_identifies_a_guessed_parquet_export_as_the_canonical_log(tmp_path, frame):
    """The same figures as the log with canonical names; in Parquet (the guess does not depend on the format)."""
    canonical, guessed = tmp_path / "canonical.parquet", tmp_path / "guessed.parquet"
    frame[["t", "eta_r", "eta_l", "tau_r", "tau_l"]].to_parquet(canonical)
    frame.rename(columns={"t": "time", "eta_r": "meas_right_vel", "eta_l": "meas_left_vel", "tau_r": "torque_right",
                          "tau_l": "torque_left"}).to_parquet(guessed)  # fmt: skip
    a, b = (wmrid("identify", str(p), "--format", "json") for p in (canonical, guessed))
    assert a.returncode == b.returncode == 0, b.stderr.decode()
    assert json.loads(a.stdout)["parameters"] == json.loads(b.stdout)["parameters"]


def test_an_ambiguous_guess_is_refused_with_the_candidates(tmp_path, frame):
    table = plotjuggler(frame, with_commands=False)
    table["/wheel_state/right/velocity"] = table["/joint_states/right_wheel_joint/velocity"]
    path = tmp_path / "two.csv"
    table.to_csv(path, index=False)
    out = wmrid("identify", str(path))
    assert out.returncode == 2
    err = out.stderr.decode().strip()
    assert len(err.splitlines()) == 1, err
    assert "eta_r could be any of '/joint_states/right_wheel_joint/velocity', '/wheel_state/right/velocity'" in err
    assert "choose with --columns eta_r=" in err
    # naming it settles it; the other columns are still guessed
    ok = wmrid("identify", str(path), "--columns", "eta_r=/wheel_state/right/velocity", "--format", "json")
    assert ok.returncode == 0, ok.stderr.decode()


def test_canonical_names_are_never_second_guessed(tmp_path, frame):
    table = frame[["t", "eta_r", "eta_l", "tau_r", "tau_l"]].copy()
    table["right_wheel_velocity_filtered"] = 0.0
    path = tmp_path / "c.csv"
    table.to_csv(path, index=False)
    assert not any("guessed" in n for n in read_log(str(path)).notes)


def test_a_partly_empty_row_of_a_merged_export_is_still_an_error(tmp_path, frame):
    table = plotjuggler(frame)
    table.iloc[40, table.columns.get_loc("/joint_states/left_wheel_joint/effort")] = np.nan
    path = tmp_path / "hole.csv"
    table.to_csv(path, index=False)
    out = wmrid("identify", str(path))
    assert out.returncode == 2
    err = out.stderr.decode()
    assert "line 42" in err
    assert "'/joint_states/left_wheel_joint/effort' is empty or NaN" in err


def test_controller_error_columns_are_not_taken_for_speeds():
    assert guess_candidates("eta_r", ["time", "right_speed_error", "right_vel_err", "delta_right_vel"]) == []
