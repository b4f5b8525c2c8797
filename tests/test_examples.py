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
