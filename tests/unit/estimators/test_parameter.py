"""A reported parameter's flags are decided once (:func:`wmrid.estimators.verdict.settle` and the widenings) and read
everywhere: :class:`wmrid.estimators.parameter.Parameter`, ``result.table``, each parameter's ``flags`` in the JSON,
the terminal's table, ``compare`` and the report print the same marks."""

from __future__ import annotations

import json
import math
from dataclasses import replace

import pytest

import wmrid
from wmrid.estimators.findings import Diagnostics
from wmrid.estimators.parameter import FLAGS, Parameter, parameter_table
from wmrid.estimators.result import IdentificationResult
from wmrid.estimators.verdict import settle


@pytest.fixture(scope="module")
def result() -> IdentificationResult:
    log = wmrid.simulate("paper", duration=10.0, rate=200.0, noise=wmrid.NoiseSettings(seed=4))
    return wmrid.identify(log, robot="paper")


@pytest.fixture(scope="module")
def broken(result) -> IdentificationResult:
    """The result with a right viscous friction no robot has (-1 N m s/rad, 0.01 std): settled again, as every
    result is after its last change of numbers."""
    parameters = {**result.parameters, "Fv1": (-1.0, 0.01)}
    return settle(replace(result, parameters=parameters))


def test_a_parameter_round_trips_through_json_with_its_flags_in_order() -> None:
    p = Parameter("Fv1", -1.0, 0.01, "N m s/rad", ("impossible", "flagged"))
    assert p.flags == ("flagged", "impossible")  # FLAGS' order, whatever the order given
    assert p.mark == "!"
    assert not p.trusted
    assert p.impossible
    assert Parameter.from_dict("Fv1", json.loads(json.dumps(p.to_dict()))) == p
    undetermined = Parameter("Vc", 0.2, math.inf, "kg m^2", ("flagged",))
    assert undetermined.to_dict()["std"] is None
    assert Parameter.from_dict("Vc", undetermined.to_dict()) == undetermined
    assert Parameter("M11", 1.0, 0.1, "kg m^2", ("inflated",)).mark == "†"
    with pytest.raises(ValueError, match="unknown flags"):
        Parameter("m11", 1.0, 0.1, "1/(kg m^2)", ("doubtful",))


def test_the_table_holds_the_flags_the_estimator_recorded(broken) -> None:
    table = broken.table
    diagnostics = broken.diagnostics
    assert diagnostics.impossible == ("Fv1",)
    for flag in FLAGS:
        assert [n for n, p in table.items() if flag in p.flags] == list(getattr(diagnostics, flag)), flag
    assert {"flagged", "impossible"} <= set(table["Fv1"].flags)
    assert (table["Fv1"].value, table["Fv1"].std, table["Fv1"].unit) == (-1.0, 0.01, "N m s/rad")


def test_the_json_carries_each_parameter_s_flags_and_reads_back(broken) -> None:
    data = json.loads(json.dumps(broken.to_dict(history=False)))
    for name, p in broken.table.items():
        assert data["parameters"][name] == p.to_dict()
    back = IdentificationResult.from_dict(data)
    assert back.table == broken.table
    assert back.to_dict(history=False) == data


def test_a_document_written_before_the_flags_reads_with_the_same_flags(broken) -> None:
    """A saved result without each parameter's flags nor diagnostics.impossible (as wmrid wrote them before): its
    table's flags are made from its inflated and flagged lists and its values, equal to what is recorded now."""
    data = json.loads(json.dumps(broken.to_dict(history=False)))
    for entry in data["parameters"].values():
        del entry["flags"]
    del data["diagnostics"]["impossible"]
    assert IdentificationResult.from_dict(data).table == broken.table
    diagnostics = Diagnostics.from_dict(data["diagnostics"])
    assert parameter_table(broken.parameters, broken.units, diagnostics) == broken.table


def test_the_terminal_table_and_the_report_print_the_recorded_marks(broken) -> None:
    from io import StringIO

    from rich.console import Console

    from wmrid.reporting.render import print_identification
    from wmrid.reporting.report import build_report

    out = StringIO()
    print_identification(broken, Console(file=out, width=200, color_system=None))
    line = next(row for row in out.getvalue().splitlines() if row.lstrip("│ ").startswith("Fv1"))
    mark = broken.table["Fv1"].mark  # "!" and, when its std was widened, "†!"
    assert mark.endswith("!")
    assert "-1✗" in line.replace(" ", "")
    assert f"0.01{mark}" in line.replace(" ", "")
    report = build_report(broken, figures=False)
    row = next(r for r in report.base.rows if r[0] == "Fv1")
    assert row[3] == f"0.01 {mark}"


def test_compare_prints_the_marks_identify_and_identify_method_give() -> None:
    """``compare``'s entry of a method is that method's ``identify --method`` table: the same value, std, unit and
    flags (the std means one thing wherever it is printed)."""
    run = wmrid.simulate("paper", duration=10.0, rate=200.0, noise=wmrid.NoiseSettings(seed=5))
    data = wmrid.compare(run, "paper", methods=["observer", "idim"]).to_dict()
    for method in ("observer", "idim"):
        alone = wmrid.identify(run, robot="paper", method=method)
        row = data["methods"][method]
        assert row["parameters"] == {n: p.to_dict() for n, p in alone.table.items()}, method
        assert row["marks"] == {n: p.mark for n, p in alone.table.items()}, method
