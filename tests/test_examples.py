"""The example robot files in examples/ load, say what the README says they are, and identify."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from tests.cliutil import text, wmrid
from wmrid.api.inputs import load_robot
from wmrid.model import dynamics as model
from wmrid.model.robot import BUILTIN_ROBOTS

ROOT = Path(__file__).resolve().parents[1]
EXAMPLES = ROOT / "examples"


@pytest.mark.parametrize(("file", "builtin"), [("paper_robot.toml", "paper"), ("small_amr.toml", "amr")])
def test_the_toml_examples_are_the_builtin_robots(file, builtin):
    robot = load_robot(str(EXAMPLES / file))
    expected = BUILTIN_ROBOTS[builtin]
    assert robot.nominal == expected.nominal
    assert robot.cad == expected.cad
    assert robot.casters == expected.casters
    assert (EXAMPLES / file).read_text().count("#") > 40  # commented, parameter by parameter


def test_the_small_amr_example_gives_its_motor():
    robot = load_robot(str(EXAMPLES / "small_amr.toml"))
    assert robot.torque_constant == pytest.approx(0.035)
    assert robot.efficiency == pytest.approx(0.9)


def test_the_urdf_example_with_the_gear_ratio_it_names_is_the_paper_robot():
    """The examples' README says --gear-ratio 100 for the URDF: with it, M and V_c are the paper robot's CAD ones."""
    assert "--robot examples/paper_robot.urdf --gear-ratio 100" in (EXAMPLES / "README.md").read_text()
    robot = load_robot(str(EXAMPLES / "paper_robot.urdf"), gear_ratio=100.0)
    got = model.base_parameters(robot.cad)[:4]
    want = model.base_parameters(BUILTIN_ROBOTS["paper"].cad)[:4]
    np.testing.assert_allclose(got, want, rtol=1e-12)
    assert robot.unknown_cad == ("Fv1", "Fv2", "Fd1", "Fd2")


def test_identify_with_an_example_file():
    out = text(wmrid("identify", ROOT / "sample_logs" / "paper_sinusoid.csv", "--robot", EXAMPLES / "paper_robot.toml",
                     "--format", "table", columns="120"))  # fmt: skip
    assert out.returncode == 0, out.stderr
    assert "m11" in out.stdout


MINIMAL = """
name = "minimal"
[nominal]
I_p = 4.0
m_p = 55.0
d_x = 0.15
I_w = 0.05
m_w = 4.0
r = 0.16
b = 0.23
[cad]
I_p = 4.98
m_p = 60.9
d_x = 0.1781
d_y = 0.0119
I_w = 0.0738
m_w = 4.98
r = 0.16
b = 0.23
"""


def test_a_partial_robot_file_states_what_was_assumed(tmp_path):
    """A robot file with only what M and V_c depend on most: the rest is assumed (no rotors, a thin-disc wheel,
    a = b, no friction), the parameters are those of the full file with the assumed values written out, and
    identify says what it assumed; the CAD friction, not given, is compared with nothing ("—")."""
    from wmrid.model.robot import robot_from_toml_text

    path = tmp_path / "minimal.toml"
    path.write_text(MINIMAL)
    robot = load_robot(str(path))
    explicit = robot_from_toml_text(
        MINIMAL.replace("b = 0.23\n[cad]", "b = 0.23\nd_y = 0.0\nI_wm = 0.025\na = 0.23\nm_r = 0.0\nI_rm = 0.0\n"
                        "I_r = 0.0\nc_x = 0.0\nc_y = 0.0\nk_r = 1.0\n[cad]"), "explicit")  # fmt: skip
    assert robot.nominal == explicit.nominal
    assert robot.gear_ratio_known is False
    assert robot.unknown_cad == ("Fv1", "Fv2", "Fd1", "Fd2")
    assert "[nominal] no motor rotors (m_r = I_rm = I_r = 0; k_r unknown)" in robot.assumed
    assert "[nominal] I_wm = I_w / 2 (each wheel a thin disc)" in robot.assumed
    out = text(wmrid("identify", ROOT / "sample_logs" / "paper_sinusoid.csv", "--robot", path, "--format", "table",
                     columns="200"))  # fmt: skip
    assert out.returncode == 0, out.stderr
    assert "robot file: assumed [nominal] d_y = 0" in out.stdout
    fd1 = next(line for line in out.stdout.splitlines() if line.strip().startswith("Fd1"))
    assert fd1.split()[-2:] == ["—", "—"]


def test_a_robot_file_missing_what_matters_is_refused_with_the_list():
    from wmrid.core.errors import RobotFileError
    from wmrid.model.robot import robot_from_toml_text

    with pytest.raises(RobotFileError, match=r"missing parameter\(s\) m_w.*needs at least I_p, m_p, d_x, I_w, m_w"):
        robot_from_toml_text(MINIMAL.replace("m_w = 4.0\n", "", 1), "x.toml")
    with pytest.raises(RobotFileError, match="give all of m_r, I_rm, I_r, c_x, c_y, k_r or none"):
        robot_from_toml_text(MINIMAL.replace("b = 0.23\n[cad]", "b = 0.23\nk_r = 100.0\n[cad]"), "x.toml")
