"""What ``wmrid inspect`` finds (:mod:`wmrid.io.inspect`), typed: each topic and column a record that writes back
the JSON object it was read from, key for key and in order, on the bundled sample and a real ROS 2 recording."""

from __future__ import annotations

import json

import pytest

import wmrid
from tests.locations import ROOT_DIR
from wmrid.io.inspect import ColumnSummary, McapInventory, TableInventory, TopicSummary

REAL = ROOT_DIR.parent / "shared" / "real_logs"


NO_REAL = pytest.mark.skipif(not REAL.exists(), reason="../shared/real_logs is not beside the checkout")


@pytest.mark.parametrize(
    "path",
    [
        pytest.param(ROOT_DIR / "sample_logs" / "paper_sinusoid.mcap", id="sample"),
        pytest.param(REAL / "rosbag2_conformance" / "topics_and_services.mcap", id="rosbag2", marks=NO_REAL),
    ],
)
def test_each_topic_is_a_record_that_writes_back_its_json(path) -> None:
    inventory = wmrid.inspect(path)
    assert isinstance(inventory, McapInventory)
    assert all(isinstance(t, TopicSummary) for t in inventory.topics)
    text = json.dumps(inventory.to_dict())
    for entry in json.loads(text)["topics"]:
        assert json.dumps(TopicSummary.from_dict(entry).to_dict()) == json.dumps(entry)
    assert any(t.joints or t.field_paths for t in inventory.topics)


def test_each_column_is_a_record() -> None:
    inventory = wmrid.inspect(ROOT_DIR / "sample_logs" / "paper_sinusoid.parquet")
    assert isinstance(inventory, TableInventory)
    assert [c.name for c in inventory.columns][:5] == ["t", "eta_r", "eta_l", "tau_r", "tau_l"]
    for entry in inventory.to_dict()["columns"]:
        assert ColumnSummary.from_dict(entry).to_dict() == entry
