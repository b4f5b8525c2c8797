"""The lean core (issue 33, item 5): a command or format that needs a missing extra says so in one line, naming the
extra (exit 2, no traceback), and the core commands run without the extras' libraries.

A missing library is made real in a fresh process: ``sys.modules[name] = None`` before wmrid is imported makes every
``import name`` there fail with ImportError, as on an install without it (nothing of wmrid is replaced)."""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from locations import ROOT_DIR

from wmrid.core.extras import EXTRAS, MissingExtraError, install_hint, require

ROOT = ROOT_DIR
SAMPLE = ROOT / "sample_logs" / "paper_sinusoid"


def without(modules: tuple[str, ...], argv: list[str], cwd: Path, *more: list[str]) -> subprocess.CompletedProcess:
    """``wmrid ARGV`` as its entry point runs it, in a process where ``modules`` cannot be imported; then, in the
    same process, each of ``more`` while the commands before it exited 0 (the exit code is the last one run)."""
    shim = "".join(f"sys.modules[{m!r}] = None; " for m in modules)
    code = f"import sys; {shim}sys.argv = ['wmrid', *{argv!r}]; from wmrid.cli import main; main()"
    if more:
        code = (
            f"import sys; {shim}from wmrid.cli import main\n"
            f"for argv in {[argv, *more]!r}:\n"
            "    sys.argv = ['wmrid', *argv]\n"
            "    try:\n"
            "        main()\n"
            "    except SystemExit as stop:\n"
            "        if stop.code not in (0, None):\n"
            "            raise\n"
        )
    return subprocess.run(
        [sys.executable, "-c", code], cwd=cwd, capture_output=True, timeout=600, stdin=subprocess.DEVNULL,
        env={**os.environ, "PYTHONPATH": str(ROOT), "COLUMNS": "100"},
    )  # fmt: skip


def test_require_names_the_extra_and_the_command_that_installs_it(monkeypatch):
    monkeypatch.setitem(sys.modules, "distributed", None)
    with pytest.raises(MissingExtraError) as exc:
        require("distributed", "fleet")
    assert str(exc.value) == "wmrid fleet needs the fleet extra: pip install 'wmrid[fleet]'"
    assert isinstance(exc.value, ImportError)
    assert require("json", "fleet") is json
    assert set(EXTRAS) == {"fast", "fleet", "parquet", "physics"}
    with pytest.raises(ValueError, match="unknown extra"):
        install_hint("gpu")


def test_the_test_extra_pulls_every_extra():
    """CI installs ``.[test]`` only: every extra's libraries must come with it, so that no test is left out."""
    try:
        import tomllib
    except ImportError:  # Python 3.10
        import tomli as tomllib

    project = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]
    extras = project["optional-dependencies"]
    assert "wmrid[all]" in extras["test"]
    assert extras["all"] == [f"wmrid[{','.join(sorted(EXTRAS))}]"]
    core = " ".join(project["dependencies"])
    for name in ("numba", "distributed", "pyarrow", "mujoco"):
        assert name not in core


def test_fleet_without_its_extra_says_how_to_install_it_in_one_line(tmp_path):
    done = without(("distributed",), ["fleet", str(tmp_path), "-o", "fleet.parquet"], tmp_path)
    assert done.returncode == 2
    assert done.stderr.decode() == "wmrid: error: wmrid fleet needs the fleet extra: pip install 'wmrid[fleet]'\n"
    assert not (tmp_path / "fleet.parquet").exists()


def test_a_parquet_log_without_pyarrow_names_the_parquet_extra(tmp_path):
    done = without(("pyarrow",), ["identify", str(SAMPLE.with_suffix(".parquet")), "--robot", "paper"], tmp_path)
    assert done.returncode == 2
    assert done.stderr.decode() == (
        f"wmrid: error: {SAMPLE.with_suffix('.parquet')}: reading a Parquet log needs the parquet extra: "
        "pip install 'wmrid[parquet]'\n"
    )


def test_the_core_identifies_and_simulates_csv_without_pyarrow(tmp_path):
    """Without pyarrow the CSV log goes through pandas' C engine and the CSV output through pandas: the same
    parameters, to the last bit, as with it; a simulated CSV reads back as the same log.  (Both commands run in one
    process per case, without pyarrow and with it: two process starts instead of four; simulate writes nothing to
    standard output, so it holds identify's JSON only.)"""
    args = ["identify", str(SAMPLE.with_suffix(".csv")), "--robot", "paper", "--format", "json"]
    sim = ["simulate", "--robot", "paper", "--duration", "2", "--seed", "1"]
    lean = without(("pyarrow",), args, tmp_path, [*sim, "-o", "lean.csv"])
    assert lean.returncode == 0, lean.stderr.decode()
    full = without((), args, tmp_path, [*sim, "-o", "full.csv"])
    assert full.returncode == 0, full.stderr.decode()
    assert json.loads(lean.stdout)["parameters"] == json.loads(full.stdout)["parameters"]
    from wmrid.io.logs import read_log

    lean_log, full_log = read_log(str(tmp_path / "lean.csv")), read_log(str(tmp_path / "full.csv"))
    np.testing.assert_array_equal(lean_log.t, full_log.t)
    np.testing.assert_array_equal(lean_log.eta, full_log.eta)
    np.testing.assert_array_equal(lean_log.tau, full_log.tau)


def test_series_json_without_pyarrow_holds_the_same_numbers():
    from wmrid.io.mcap.series_writer import _json_objects, _json_objects_python

    rng = np.random.default_rng(7)
    values = rng.normal(size=500) * 10.0 ** rng.integers(-30, 30, 500)
    values[:6] = [0.0, -0.0, 3.0, math.nan, math.inf, 1e16]
    columns = {"t": np.arange(500) * 1e-3, "a": values, "b": values[::-1].copy()}
    (fast, fast_at), (plain, plain_at) = _json_objects(columns), _json_objects_python(columns)
    assert len(fast_at) == len(plain_at) == 501
    for i in range(500):
        a = json.loads(fast[fast_at[i] : fast_at[i + 1]])
        b = json.loads(plain[plain_at[i] : plain_at[i + 1]])
        assert list(a) == list(b) == ["t", "a", "b"]
        for key in a:
            assert (a[key] is None and b[key] is None) or (
                math.copysign(1.0, a[key]) == math.copysign(1.0, b[key]) and a[key] == b[key]
            ), (i, key)
