"""A plan's parts, typed (:mod:`wmrid.design.plan_records`): a saved plan reads back into records and writes the very
JSON it was read from, key for key and in order; an older plan (no ``counted``, no ``caster_geometry``) and keys a
newer wmrid may add read and write back too; the views and the report are made from the records."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

import wmrid
from tests.locations import DATA_DIR as DATA
from wmrid.core.errors import UsageError
from wmrid.design.plan import Plan
from wmrid.design.plan_records import (
    BaselineForecast,
    Criterion,
    LimitUse,
    OpenFloorForecast,
    PlanSettings,
    PredictedStd,
    ReferenceSamples,
    Separability,
    WheelSpread,
)

SAVED = [
    pytest.param(DATA / "paper_plan_60s_wheel.json", id="paper_60s"),
    pytest.param(DATA / "plan_hostile_names.json", id="older_hostile_names"),
]


@pytest.mark.parametrize("path", SAVED)
def test_a_saved_plan_reads_back_typed_and_writes_the_same_text(path: Path) -> None:
    text = json.dumps(json.loads(path.read_text()))
    plan = wmrid.read_plan(path)
    assert isinstance(plan.criterion, Criterion)
    assert isinstance(plan.settings, PlanSettings)
    assert isinstance(plan.margins, Separability)
    assert isinstance(plan.margins.right, WheelSpread)
    assert all(isinstance(p, PredictedStd) for p in plan.predicted.values())
    assert all(isinstance(u, LimitUse) for u in plan.limits_used.values())
    assert all(isinstance(b, BaselineForecast) for b in plan.baselines.values())
    assert all(isinstance(b.area_ignored, OpenFloorForecast) for b in plan.baselines.values())
    assert plan.worst == plan.criterion.worst
    assert plan.value == plan.criterion.value
    assert json.dumps(plan.to_dict()) == text
    # and through the file the command writes
    assert json.dumps(Plan.from_dict(json.loads(json.dumps(plan.to_dict()))).to_dict()) == text


def test_an_older_plan_lacks_keys_and_keeps_them_absent() -> None:
    """A plan of the first release: no ``counted`` (every parameter counts) and no ``caster_geometry``."""
    plan = wmrid.read_plan(DATA / "plan_hostile_names.json")
    assert all(p.counted is None and p.in_criterion for p in plan.predicted.values())
    assert plan.settings.caster_geometry is None
    assert plan.form.friction == "wheel"
    written = plan.to_dict()
    assert "counted" not in written["predicted"]["m11"]
    assert "caster_geometry" not in written["settings"]


def test_keys_a_newer_wmrid_adds_are_kept_in_order(tmp_path: Path) -> None:
    data = json.loads((DATA / "paper_plan_60s_wheel.json").read_text())
    data["predicted"]["m11"]["interval"] = [0.9, 0.95]
    data["settings"]["solver"] = "slsqp"
    data["margins"]["right"]["dwell"] = 0.1
    data["baselines"]["sinusoid"]["area_ignored"]["note"] = "x"
    data["limits_used"]["max_torque"]["peak"] = None
    plan = Plan.from_dict(data)
    assert plan.predicted["m11"].other == {"interval": [0.9, 0.95]}
    assert plan.settings.other == {"solver": "slsqp"}
    assert plan.limits_used["max_torque"].peak is None
    assert json.dumps(plan.to_dict()) == json.dumps(data)


def test_a_plan_that_is_not_one_is_refused_in_one_line() -> None:
    data = json.loads((DATA / "paper_plan_60s_wheel.json").read_text())
    for broken in ({**data, "predicted": [1, 2]}, {**data, "margins": "wide"}, {**data, "criterion": {"value": None}}):
        with pytest.raises(UsageError, match="not a valid plan"):
            Plan.from_dict(broken)


def test_the_samples_and_the_tables_are_records() -> None:
    from wmrid.reporting.plan_report import tables
    from wmrid.reporting.report_table import ReportTable

    plan = wmrid.read_plan(DATA / "paper_plan_60s_wheel.json")
    samples = plan.samples(10.0)
    assert isinstance(samples, ReferenceSamples)
    assert list(samples.columns()) == ["t", "v", "omega", "eta_r", "eta_l", "x", "y", "phi"]
    assert samples.t.shape == (601,)
    made = tables(plan)
    assert all(isinstance(t, ReportTable) for t in made.values())
    precision = made["Predicted precision"]
    assert precision.header[-2:] == ["sinusoid (relative)", "reversing (relative)"]
    assert [row[0] for row in precision.rows] == list(plan.predicted)
    assert [row[0] for row in made["Limits"].rows] == [n for n, u in plan.limits_used.items() if u.limit is not None]
