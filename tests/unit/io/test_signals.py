"""Signal conversions: units, current to torque, PWM labels, mirrored motors, speeds from positions."""

from __future__ import annotations

import math

import numpy as np
import pytest

from wmrid.core.errors import RobotFileError, UsageError
from wmrid.io.signals import SignalOptions, effort_to_torque, mirror_left, speed_from_position, speed_to_rad_s
from wmrid.model.robot import BUILTIN_ROBOTS
from wmrid.model.robot_file import load_robot, robot_from_toml_text, robot_to_toml


@pytest.mark.parametrize(
    ("unit", "factor", "radius"),
    [("rad/s", 1.0, None), ("rpm", 2 * math.pi / 60, None), ("deg/s", math.pi / 180, None), ("m/s", 1 / 0.16, 0.16)],
)
def test_speed_units(unit, factor, radius):
    values = np.array([[1.0, -2.0], [60.0, 0.5]])
    out, _ = speed_to_rad_s(values, SignalOptions(speed_unit=unit, wheel_radius=radius))
    np.testing.assert_allclose(out, values * factor, rtol=1e-15)


def test_current_to_torque_and_pwm_label():
    i = np.array([[1.0, 2.0]])
    tau, note = effort_to_torque(i, SignalOptions(effort="current", torque_constant=0.02, efficiency=0.9), 50.0)
    np.testing.assert_allclose(tau, [[0.02 * 50 * 0.9, 0.04 * 50 * 0.9]])
    assert "0.02 N m/A" in note
    opts = SignalOptions(effort="pwm")
    same, note = effort_to_torque(i, opts, None)
    assert same is i
    assert opts.effort_label == "PWM"
    assert "identified in PWM units" in note
    assert SignalOptions(effort="voltage", effort_unit="V_bus").effort_label == "V_bus"


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"speed_unit": "m/s"}, "wheel_radius"),
        ({"efficiency": 1.5}, "efficiency"),
        ({"speed_unit": "furlong/fortnight"}, "speed_unit"),
        ({"wheel_radius": -1.0}, "wheel_radius"),
    ],
)
def test_options_are_validated(kwargs, message):
    with pytest.raises(UsageError, match=message):
        SignalOptions(**kwargs)


def test_current_without_a_torque_constant_is_identified_in_amperes():
    opts = SignalOptions(effort="current")
    assert opts.effort_label == "A"
    assert not opts.is_torque
    same, note = effort_to_torque(np.ones((1, 2)), opts, None)
    np.testing.assert_array_equal(same, 1.0)
    assert "identified in A units" in note


def test_current_needs_a_gear_ratio():
    with pytest.raises(UsageError, match="gear_ratio"):
        effort_to_torque(np.ones((1, 2)), SignalOptions(effort="current", torque_constant=0.01), None)


def test_mirror_left_changes_only_the_left_column():
    speed, effort = np.array([[1.0, 2.0]]), np.array([[3.0, 4.0]])
    mirror_left(speed, effort)
    np.testing.assert_array_equal(speed, [[1.0, -2.0]])
    np.testing.assert_array_equal(effort, [[3.0, -4.0]])


def test_savitzky_golay_derivative_is_exact_for_cubic_motion_and_unwraps():
    t = np.arange(0, 2, 1e-3)
    angle = np.column_stack([1 + 2 * t - 0.5 * t**2 + 0.3 * t**3, 5 * t])
    wrapped = np.column_stack([angle[:, 0], (angle[:, 1] + math.pi) % (2 * math.pi) - math.pi])
    speed, note = speed_from_position(t, wrapped)
    expected = np.column_stack([2 - t + 0.9 * t**2, np.full_like(t, 5.0)])
    np.testing.assert_allclose(speed, expected, rtol=0, atol=1e-9)  # a cubic fit reproduces a cubic
    assert "Savitzky-Golay" in note


def test_uneven_steps_use_finite_differences():
    t = np.cumsum(np.r_[0.0, np.random.default_rng(2).uniform(0.5e-3, 1.5e-3, 999)])
    speed, note = speed_from_position(t, np.column_stack([3 * t, t**2]))
    np.testing.assert_allclose(speed[1:-1], np.column_stack([np.full(998, 3.0), 2 * t[1:-1]]), atol=1e-9)
    assert "finite differences" in note


def test_robot_motor_table_round_trip(tmp_path):
    text = robot_to_toml(BUILTIN_ROBOTS["paper"]) + "\n[motor]\ntorque_constant = 0.0105\nefficiency = 0.9\n"
    robot = robot_from_toml_text(text, "r.toml")
    assert (robot.torque_constant, robot.efficiency) == (0.0105, 0.9)
    path = tmp_path / "again.toml"
    path.write_text(robot_to_toml(robot))
    assert load_robot(str(path)) == robot
    with pytest.raises(RobotFileError, match=r"\[motor\]"):
        robot_from_toml_text(robot_to_toml(BUILTIN_ROBOTS["paper"]) + "\n[motor]\nkv = 3\n", "bad.toml")
    with pytest.raises(RobotFileError, match="efficiency"):
        robot_from_toml_text(robot_to_toml(BUILTIN_ROBOTS["paper"]) + "\n[motor]\nefficiency = 2\n", "bad.toml")
