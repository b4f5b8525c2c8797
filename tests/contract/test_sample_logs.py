"""The bundled sample logs are exactly what ``sample_logs/make_samples.py`` produces."""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pyarrow.parquet as pq
import pytest
from locations import ROOT_DIR

ROOT = ROOT_DIR
SAMPLES = ROOT / "sample_logs"
NAMES = [
    "paper_sinusoid.mcap",
    "paper_sinusoid.mcap.truth.json",
    "paper_sinusoid.csv",
    "paper_sinusoid.parquet",
    "paper_sinusoid.csv.truth.json",
    "paper_sinusoid.parquet.truth.json",
]


@pytest.fixture(scope="module")
def regenerated(tmp_path_factory) -> Path:
    """``python sample_logs/make_samples.py OUT`` run as that script, in this process (runpy: ``__main__``, its
    arguments; a process of its own cost 2 s of imports and compiled kernels loaded again)."""
    import runpy

    out = tmp_path_factory.mktemp("samples")
    script = str(SAMPLES / "make_samples.py")
    with pytest.MonkeyPatch.context() as patch:
        patch.setattr(sys, "argv", [script, str(out)])
        runpy.run_path(script, run_name="__main__")
    return out


def test_regenerated_files_are_the_same_set(regenerated):
    assert sorted(p.name for p in regenerated.iterdir()) == sorted(NAMES)
    for name in NAMES:
        assert (SAMPLES / name).is_file(), name


def test_parquet_sample_is_unchanged(regenerated):
    # Full precision.  The simulator is deterministic (seeded, fixed-step RK4); 1e-12 relative allows
    # only for a different CPU's last-bit rounding in the compiled kernel.
    new = pq.read_table(regenerated / "paper_sinusoid.parquet")
    old = pq.read_table(SAMPLES / "paper_sinusoid.parquet")
    assert new.column_names == old.column_names
    for col in old.column_names:
        np.testing.assert_allclose(new[col].to_numpy(), old[col].to_numpy(), rtol=1e-12, atol=1e-12, err_msg=col)
    assert json.loads(new.schema.metadata[b"wmrid_truth"]) == json.loads(old.schema.metadata[b"wmrid_truth"])


def test_csv_sample_is_unchanged(regenerated):
    # Values rounded to 10 significant digits: a last-bit difference upstream can move the 10th digit by
    # one unit, i.e. 1e-9 relative at most.
    new = pd.read_csv(regenerated / "paper_sinusoid.csv")
    old = pd.read_csv(SAMPLES / "paper_sinusoid.csv")
    assert list(new.columns) == list(old.columns) == ["t", "eta_r", "eta_l", "tau_r", "tau_l"]
    np.testing.assert_allclose(new.to_numpy(), old.to_numpy(), rtol=1e-9, atol=0)


@pytest.mark.parametrize("name", [n for n in NAMES if n.endswith(".truth.json")])
def test_truth_is_unchanged(regenerated, name):
    new = json.loads((regenerated / name).read_text())
    old = json.loads((SAMPLES / name).read_text())
    assert new.keys() == old.keys()
    for key, value in old["parameters"].items():
        assert new["parameters"][key] == pytest.approx(value, rel=1e-14), key
    assert new["physical"] == old["physical"]


def test_mcap_sample_is_unchanged(regenerated):
    # Compare what the bag holds (not its bytes: the writer library's version is recorded in the header).
    from wmrid.io.mcap.reader import read_mcap

    new = read_mcap(str(regenerated / "paper_sinusoid.mcap"))
    old = read_mcap(str(SAMPLES / "paper_sinusoid.mcap"))
    a, b = new.joints["/joint_states"], old.joints["/joint_states"]
    assert a.names == b.names
    np.testing.assert_array_equal(a.stamp_ns, b.stamp_ns)
    for field in ("position", "velocity", "effort"):
        np.testing.assert_allclose(a.field(field), b.field(field), rtol=1e-12, atol=1e-12, err_msg=field)
    assert json.loads(new.metadata["wmrid"]["truth"]) == json.loads(old.metadata["wmrid"]["truth"])


def test_the_three_samples_give_the_same_parameters():
    from wmrid.io.logs import read_log
    from wmrid.model.robot import BUILTIN_ROBOTS
    from wmrid.pipeline.identify import identify

    robot = BUILTIN_ROBOTS["paper"]
    mcap = identify(read_log(str(SAMPLES / "paper_sinusoid.mcap")), robot)
    parquet = identify(read_log(str(SAMPLES / "paper_sinusoid.parquet")), robot)
    csv = identify(read_log(str(SAMPLES / "paper_sinusoid.csv")), robot)
    for name, (value, _) in parquet.parameters.items():
        # MCAP and Parquet hold the same doubles (MCAP time: integer ns, i.e. rounded to 1 ns).
        assert mcap.parameters[name][0] == pytest.approx(value, rel=1e-9), name
        # The CSV's values are rounded to 10 significant digits.
        assert csv.parameters[name][0] == pytest.approx(value, rel=1e-6), name
