"""The example robot files in examples/ load, say what examples/README.md says they are, and identify."""

from __future__ import annotations

import numpy as np
import pytest
from locations import ROOT_DIR

from tests.cliutil import text, wmrid
from wmrid.api.inputs import load_robot
from wmrid.model import dynamics as model
from wmrid.model.robot import BUILTIN_ROBOTS

ROOT = ROOT_DIR
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
    from wmrid.model.robot_file import robot_from_toml_text

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
    from wmrid.model.robot_file import robot_from_toml_text

    with pytest.raises(RobotFileError, match=r"missing parameter\(s\) m_w.*needs at least I_p, m_p, d_x, I_w, m_w"):
        robot_from_toml_text(MINIMAL.replace("m_w = 4.0\n", "", 1), "x.toml")
    with pytest.raises(RobotFileError, match="give all of m_r, I_rm, I_r, c_x, c_y, k_r or none"):
        robot_from_toml_text(MINIMAL.replace("b = 0.23\n[cad]", "b = 0.23\nk_r = 100.0\n[cad]"), "x.toml")


BASE_ONLY = """
name = "base-only"
[nominal_base]
M11 = 1.15485
M12 = -0.287168
M22 = 1.15485
Vc = 0.159794
r = 0.16
[cad_base]
m11 = 0.787254
m12 = 0.240611
m22 = 0.744638
Vc = 0.210083
Fv1 = 0.01
Fv2 = 0.015
Fd1 = 0.045
Fd2 = 0.04
"""


def test_a_robot_file_of_base_parameters(tmp_path):
    """Nominal base parameters given directly (M here, m converted), CAD ones as m: the comparison uses them as
    given; what needs physical parameters (a payload, a simulation) is refused by name; the assumption is said."""
    path = tmp_path / "base.toml"
    path.write_text(BASE_ONLY)
    robot = load_robot(str(path))
    assert robot.gear_ratio_known is False
    m = np.linalg.inv([[1.15485, -0.287168], [-0.287168, 1.15485]])
    np.testing.assert_allclose(model.base_parameters(robot.nominal)[:3], [m[0, 0], m[0, 1], m[1, 1]], rtol=1e-15)
    sample = ROOT / "sample_logs" / "paper_sinusoid.csv"
    out = text(wmrid("identify", sample, "--robot", path, "--format", "json"))
    assert out.returncode == 0, out.stderr
    import json

    result = json.loads(out.stdout)
    assert result["reference"]["m11"] == pytest.approx(0.787254)
    assert result["nominal"]["M11"] == pytest.approx(1.15485, rel=1e-12)
    assert result["parameters"]["m11"]["value"] == pytest.approx(0.787254, rel=1e-4)  # the sample's CAD robot
    assert "[nominal_base] base parameters only: no payload estimate and no simulation" in result["diagnostics"][
        "robot_assumed"]  # fmt: skip
    refused = text(wmrid("identify", sample, "--robot", path, "--payload", "--format", "json"))
    assert refused.returncode == 2
    assert "--payload needs the robot's physical parameters" in refused.stderr
    sim = text(wmrid("simulate", "-o", tmp_path / "s.csv", "--robot", path, "--duration", "1"))
    assert sim.returncode == 2
    assert "gives base parameters only; a simulation needs the physical ones" in sim.stderr
    from wmrid.model.robot_file import robot_from_toml_text, robot_to_toml

    again = robot_from_toml_text(robot_to_toml(robot), "again")
    assert again.nominal == robot.nominal
    assert again.cad == robot.cad


def test_base_parameter_tables_are_checked():
    from wmrid.core.errors import RobotFileError
    from wmrid.model.robot_file import robot_from_toml_text

    cases = {
        BASE_ONLY.replace("M22 = 1.15485\n", ""): "all three of one of them",
        BASE_ONLY.replace("M11 = 1.15485", "M11 = 0.05"): "positive definite",
        BASE_ONLY.replace("Vc = 0.159794\n", ""): "missing Vc",
        BASE_ONLY + "\n[nominal]\nI_p = 1.0\n": "as one table",
        BASE_ONLY.replace("r = 0.16", "wheel = 0.16"): "unknown key",
    }
    for text_, message in cases.items():
        with pytest.raises(RobotFileError, match=message):
            robot_from_toml_text(text_, "x.toml")
