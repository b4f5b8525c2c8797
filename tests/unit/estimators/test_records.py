"""The typed parts of a result (:mod:`wmrid.estimators.records`, :class:`wmrid.model.payload.PayloadEstimate`) write
the JSON objects the result always wrote, key for key and in the same order, and read them back equal.

Independent computation: the JSON of a real identification of the bundled sample (with --payload and --validate),
compared as text with ``json.dumps`` (which keeps key order) before and after a round trip through the types.
"""

from __future__ import annotations

import json
import math

import pytest
from locations import ROOT_DIR

import wmrid
from wmrid.estimators.records import GroupVerdict, LogInfo, Validation, Verdict
from wmrid.model.payload import PayloadEstimate

SAMPLE = ROOT_DIR / "sample_logs" / "paper_sinusoid.parquet"


@pytest.fixture(scope="module")
def document() -> dict:
    result = wmrid.identify(str(SAMPLE), "paper", observer=wmrid.ObserverOptions(payload=True))
    return wmrid.validate(result, str(SAMPLE)).to_dict(history=False)


@pytest.mark.parametrize(
    ("key", "kind"), [("log", LogInfo), ("verdict", Verdict), ("validation", Validation), ("payload", PayloadEstimate)]
)
def test_each_part_writes_back_the_object_it_read_key_for_key(document, key, kind) -> None:
    part = kind.from_dict(document[key])
    assert json.dumps(part.to_dict()) == json.dumps(document[key])  # same keys, same order, same values
    assert kind.from_dict(part.to_dict()) == part


def test_the_whole_result_reads_back_typed_and_writes_the_same_document(document) -> None:
    back = wmrid.IdentificationResult.from_dict(document)
    assert isinstance(back.log_info, LogInfo)
    assert isinstance(back.verdict, Verdict)
    assert isinstance(back.validation, Validation)
    assert isinstance(back.payload, PayloadEstimate)
    assert json.dumps(back.to_dict(history=False)) == json.dumps(document)
    assert back.log_info.samples == document["log"]["samples"]
    assert back.verdict.summary == document["verdict"]["summary"]
    assert [g.status for g in back.verdict.groups] == [g["status"] for g in document["verdict"]["groups"]]


def test_an_older_log_record_keeps_what_it_has_and_what_this_version_does_not_know() -> None:
    old = {"samples": 10, "notes": ["a note"], "effort_unit": "A", "written_by": "a later wmrid"}
    info = LogInfo.from_dict(old)
    assert (info.samples, info.duration_s, info.notes, info.effort_unit) == (10, None, ("a note",), "A")
    assert info.to_dict() == old


def test_a_group_judged_negligible_writes_its_bounds_before_its_sentence() -> None:
    group = GroupVerdict("casters", ("D1",), "D1", 0.5, "determined", None, "casters (D1): ...", {"D1": 1e-4})
    assert list(group.to_dict()) == ["group", "parameters", "worst", "relative_std", "status", "reason", "negligible",
                                     "text"]  # fmt: skip


def test_a_payload_std_that_is_not_finite_is_null_in_json_and_inf_read_back() -> None:
    payload = PayloadEstimate((1.0, math.inf), (0.1, 0.01), (0.0, 0.02), (0.3, math.inf))
    data = payload.to_dict()
    assert data["mass"] == {"value": 1.0, "std": None, "unit": "kg"}
    assert PayloadEstimate.from_dict(data) == payload
    assert [name for name, _ in payload.items()] == ["mass", "x", "y", "inertia"]
