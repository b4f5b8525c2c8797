"""The typed diagnostics tree (:mod:`wmrid.estimators.findings`) and its JSON records (:mod:`wmrid.core.json_record`):
every golden result's diagnostics read back to the same object, a fresh result's key for key and in order, and the
records' rules (null kept or left out, spliced keys, unknown keys kept) each checked on its own."""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import pytest

import wmrid
from tests.locations import DATA_DIR, ROOT_DIR
from wmrid.core.json_record import JsonRecord, kept, names, nested, other_keys, spliced
from wmrid.estimators.findings import (
    Diagnostics,
    EstimatedDelay,
    FrictionChoice,
    StructuralMismatch,
    TimingCheck,
    Uncertainty,
    UnitsCheck,
)

GOLDEN = DATA_DIR / "golden"


@pytest.mark.parametrize("path", sorted(GOLDEN.glob("*.json")), ids=lambda p: p.stem)
def test_every_golden_results_diagnostics_read_back_to_the_same_object(path: Path) -> None:
    """The 29 golden results take every route (each method, friction auto, the timing check, an applied delay and its
    timing term, the hold term, the closed-loop check): their diagnostics, typed and written again, are equal."""
    data = json.loads(path.read_text())["result"]["diagnostics"]
    assert Diagnostics.from_dict(data).to_dict() == data


@pytest.fixture(scope="module")
def result() -> wmrid.IdentificationResult:
    return wmrid.identify(str(ROOT_DIR / "sample_logs" / "paper_sinusoid.csv"), "paper")


def test_a_results_diagnostics_are_typed_and_write_the_jsons_object_in_order(result) -> None:
    diag = result.diagnostics
    assert isinstance(diag, Diagnostics)
    assert isinstance(diag.uncertainty, Uncertainty)
    assert isinstance(diag.structural_mismatch, StructuralMismatch)
    assert isinstance(diag.friction, FrictionChoice)
    assert isinstance(diag.timing, TimingCheck)
    assert isinstance(diag.timing.estimate, EstimatedDelay)
    assert isinstance(diag.units, UnitsCheck)
    assert isinstance(diag.flagged, tuple)
    assert diag.other == {}  # every key the estimator writes is a field
    text = json.dumps(result.to_dict()["diagnostics"])
    assert json.dumps(diag.to_dict()) == text
    assert json.dumps(Diagnostics.from_dict(json.loads(text)).to_dict()) == text  # key order too


def test_the_timing_checks_delay_estimate_is_written_among_its_own_keys(result) -> None:
    """The estimate's figures (delay_s, std_s, ...) are the check's own keys in the JSON, after "checked"."""
    timing = result.diagnostics.timing.to_dict()
    keys = list(timing)
    assert keys[:2] == ["checked", "delay_s"]
    assert set(EstimatedDelay.keys()) <= set(keys)
    assert "estimate" not in timing


@dataclass(frozen=True, kw_only=True)
class _Inner(JsonRecord):
    a: int | None = kept()
    b: int | None = None
    other: dict[str, Any] = other_keys()


@dataclass(frozen=True, kw_only=True)
class _Outer(JsonRecord):
    first: str | None = None
    inner: _Inner | None = spliced(_Inner)
    child: _Inner | None = nested(_Inner)
    tags: tuple[str, ...] | None = names()
    other: dict[str, Any] = other_keys()


def test_a_records_rules_null_kept_or_left_out_spliced_nested_and_unknown_keys() -> None:
    record = _Outer(first="x", inner=_Inner(a=None, b=2), child=_Inner(a=1), tags=("p", "q"))
    # a kept field is written as null; a None field is left out; a spliced record's keys are this object's
    assert record.to_dict() == {"first": "x", "a": None, "b": 2, "child": {"a": 1}, "tags": ["p", "q"]}
    assert list(record.to_dict()) == ["first", "a", "b", "child", "tags"]
    assert _Outer.from_dict(record.to_dict()) == record
    # keys a record does not know (a newer wmrid's) are kept, in their order, after the known ones
    newer = {"zz": 1, "first": "x", "child": {"a": 1, "new": [1]}, "aa": {"k": 2}}
    back = _Outer.from_dict(newer)
    assert back.other == {"zz": 1, "aa": {"k": 2}}
    assert back.child.other == {"new": [1]}
    assert back.inner is None  # none of its keys: no spliced record
    assert back.to_dict() == {"first": "x", "child": {"a": 1, "new": [1]}, "zz": 1, "aa": {"k": 2}}


def test_a_null_read_for_a_field_written_only_with_a_value_is_written_back_in_its_place() -> None:
    read = _Inner.from_dict({"a": 1, "b": None, "c": 3})
    assert read.b is None
    assert list(read.to_dict().items()) == [("a", 1), ("b", None), ("c", 3)]
    assert list(replace(read, b=2).to_dict().items()) == [("a", 1), ("b", 2), ("c", 3)]
    assert _Inner(a=1).to_dict() == {"a": 1}  # made, not read: no null


def test_a_later_record_is_written_over_an_earlier_one() -> None:
    earlier = _Inner(a=1, b=2)
    assert earlier.merged(_Inner(b=3)) == _Inner(a=None, b=3)  # the later's a is kept as null, as {**x, **y}
    assert earlier.merged(None) == earlier
