"""Presentation (wmrid.reporting.render): the terminal tables show what the result holds, and the JSON is strict."""

from __future__ import annotations

import io
import json
import math

import pytest
from locations import ROOT_DIR
from rich.console import Console

import wmrid
from wmrid.reporting.render import print_comparison, print_identification, print_inspection, to_json

ROOT = ROOT_DIR
SAMPLE = ROOT / "sample_logs" / "paper_sinusoid.csv"


def _console() -> tuple[Console, io.StringIO]:
    out = io.StringIO()
    return Console(file=out, width=140, color_system=None), out


@pytest.fixture(scope="module")
def result():
    return wmrid.identify(wmrid.read_log(SAMPLE), "paper")


def test_json_is_strict_nan_and_inf_become_null():
    text = to_json({"a": math.nan, "b": [math.inf, -math.inf, 1.5], "c": {"d": 2}})
    assert json.loads(text) == {"a": None, "b": [None, None, 1.5], "c": {"d": 2}}
    assert "NaN" not in text
    assert "Infinity" not in text
    assert not text.endswith("\n")


def test_the_identification_table_shows_every_parameter_with_its_std_nominal_and_cad(result):
    console, out = _console()
    print_identification(result, console)
    text = out.getvalue()
    rows = {
        line.split()[0]: line.split()
        for line in text.splitlines()
        if line.split()[:1] and line.split()[0] in result.parameters
    }
    assert set(rows) == set(result.parameters)
    for name, (value, std) in result.parameters.items():
        cells = rows[name]
        assert cells[1] == f"{value:.6g}", name
        assert cells[2].rstrip("†!") == f"{std:.2g}", name
        assert f"{result.nominal[name]:.6g}" in cells, name
        z = (value - result.reference[name]) / std
        assert f"{z:+.1f}" in cells, name
    assert f"{result.log_info.samples} samples" in text
    assert "regressor: paper form (7 columns), wheel friction" in text


def test_the_inspection_and_comparison_tables_name_what_they_hold(result):
    console, out = _console()
    print_inspection(wmrid.inspect(ROOT / "sample_logs" / "paper_sinusoid.mcap"), console)
    text = out.getvalue()
    assert "/joint_states" in text
    assert "sensor_msgs/msg/JointState" in text
    console, out = _console()
    comparison = wmrid.compare(wmrid.read_log(SAMPLE), "paper", methods=["observer", "idim"])
    print_comparison(comparison, console)
    text = out.getvalue()
    assert "observer" in text
    assert "idim" in text
    m11 = comparison.methods["idim"].parameters["m11"].value
    assert f"{m11:.6g}" in text
