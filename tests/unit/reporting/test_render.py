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
    # plain words by default (issue 33): what the rows are; the estimator's figures only with --verbose
    assert "rows: the inverse of the inertia matrix M (m11 m12 m22)" in " ".join(text.split())
    for jargon in ("regressor:", "lambda_min", "structural mismatch", "jackknife"):
        assert jargon not in text, jargon
    console, out = _console()
    print_identification(result, console, verbose=True)
    verbose = out.getvalue()
    assert "regressor: paper form (7 columns)" in verbose
    assert "lambda_min(Gamma)" in verbose
    assert "jackknife" in verbose


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


def test_compare_says_each_verdict_and_warning_once():
    """Issue 33: ``wmrid compare`` said each warning once per method (141 lines of warnings on ME169, 179 lines in
    all; now 52): a text several methods give is said once, naming them, and one method's "X is poorly determined"
    warnings (each with the value and std the table shows) are one line naming the parameters."""
    from dataclasses import replace

    from wmrid.reporting.render import said_once

    assert said_once([("a", "x"), ("b", "y"), ("b", "x"), ("a", "x")]) == [(["a", "b"], "x"), (["b"], "y")]
    comparison = wmrid.compare(wmrid.read_log(SAMPLE), "paper", methods=["observer", "idim"])
    shared = [
        "the log is short",
        "m11 is poorly determined by this log: 1 +/- 2",
        "Vc is poorly determined by this log",
    ]
    methods = {name: replace(m, warnings=tuple(shared)) for name, m in comparison.methods.items()}
    console, out = _console()
    print_comparison(replace(comparison, methods=methods), console)
    lines = [" ".join(line.split()) for line in out.getvalue().splitlines()]
    assert lines.count("warning (observer, idim): the log is short") == 1
    poorly = [line for line in lines if "poorly determined" in line]
    assert poorly == ["warning (observer, idim): poorly determined by this log (std in the table): m11, Vc"]
    assert sum(line.startswith("verdict (") for line in lines) == 1


def test_identify_says_the_poorly_determined_parameters_in_one_line_keeping_what_the_table_does_not_show():
    """Issue 33: identify printed one warning per poorly determined parameter (11 lines on ME169), each repeating the
    value and std of the table; now one line naming them, in the place of the first.  What a warning adds beyond the
    table (the parameters it cannot be told apart from) stays with its name.  The JSON keeps every warning."""
    from dataclasses import replace

    from wmrid.reporting.warning_groups import grouped_warnings as _grouped

    warnings = (
        "the log is short",
        "m11 is poorly determined by this log (idim): 0.43 +/- 1.1 (rad/s^2)/PWM",
        "Fv1 is poorly determined by this log: 4.8 +/- 40 PWM s/rad; it is not separable from Fd1 (correlation 0.97)",
        "to determine m11 and Fv1, drive the robot as wmrid plan designs it",
    )
    assert _grouped(warnings) == [
        "the log is short",
        "poorly determined by this log (std in the table): m11; Fv1, not separable from Fd1 (correlation 0.97)",
        "to determine m11 and Fv1, drive the robot as wmrid plan designs it",
    ]
    assert _grouped(warnings[:2]) == ["the log is short", "poorly determined by this log (std in the table): m11"]
    result = wmrid.identify(SAMPLE, "paper")
    console, out = _console()
    print_identification(replace(result, warnings=warnings), console)
    lines = [" ".join(line.split()) for line in out.getvalue().splitlines()]
    assert [line for line in lines if "poorly determined" in line] == [
        "warning: poorly determined by this log (std in the table): m11; Fv1, not separable from Fd1 (correlation 0.97)"
    ]
