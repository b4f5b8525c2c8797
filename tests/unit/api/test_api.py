"""The library's front door (``wmrid.identify`` and friends): the Python tour of the docs runs, the API and the CLI
give the same document, results round-trip through their JSON, and library errors name options as Python names."""

from __future__ import annotations

import json
import math
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
from locations import ROOT_DIR

import wmrid
from tests.cliutil import wmrid as cli
from wmrid.core.errors import LogFormatError, UsageError
from wmrid.estimators.result import SCHEMA_VERSION, from_dict
from wmrid.model import dynamics as model
from wmrid.reporting.render import to_json

ROOT = ROOT_DIR
SAMPLE = ROOT / "sample_logs" / "paper_sinusoid.csv"


@pytest.fixture(scope="module")
def sample_log():
    return wmrid.read_log(SAMPLE)


@pytest.fixture(scope="module")
def sample_result(sample_log):
    return wmrid.identify(sample_log, wmrid.load_robot("paper"))


def test_the_python_tour_runs(tmp_path, monkeypatch):
    """The Python API page's tour (docs/reference/api.md, "A tour"; it was the README's "Python" block), verbatim but
    for where it writes the reports and the fleet table."""
    page = (ROOT / "docs" / "reference" / "api.md").read_text(encoding="utf-8")
    section = page.split("## A tour", 1)[1]
    code = re.search(r"```python\n(.*?)```", section, re.S).group(1)
    monkeypatch.chdir(ROOT)
    for name in ("r.html", "fleet.parquet", "fleet.html"):
        code = code.replace(f'"{name}"', repr(str(tmp_path / name)))
    scope: dict = {}
    exec(compile(code, "docs/reference/api.md", "exec"), scope)
    assert scope["value"] == pytest.approx(0.7872544, rel=1e-6)
    assert 0 < scope["std"] < 1e-5
    assert set(scope["table"].methods) == {"observer", "idim"}
    assert scope["saved"].to_dict() == scope["result"].to_dict()
    assert scope["sim"].truth["payload"]["mass"] == 25.0
    assert isinstance(scope["changes"], wmrid.MonitorResult)
    assert scope["what"].topics[0].topic == "/joint_states"
    assert (tmp_path / "r.html").read_text(encoding="utf-8").startswith("<!DOCTYPE html>")
    assert scope["run"].identified == 3  # the sample's three files, one robot "sample_logs"
    assert (tmp_path / "fleet.html").read_text(encoding="utf-8").startswith("<!DOCTYPE html>")


def test_import_wmrid_loads_nothing_heavy():
    """``import wmrid`` loads the exports lazily: no numpy, pandas, numba until one is used."""
    code = "import sys, wmrid; print(sorted(m for m in ('numpy', 'pandas', 'numba', 'rich') if m in sys.modules))"
    proc = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=60, check=True)
    assert proc.stdout.strip() == "[]"
    with pytest.raises(AttributeError, match="no attribute 'nonsense'"):
        wmrid.nonsense  # noqa: B018


def test_the_api_and_the_cli_give_the_same_document(sample_result):
    proc = cli("identify", str(SAMPLE), "--robot", "paper", "--format", "json")
    assert proc.returncode == 0, proc.stderr
    assert json.loads(proc.stdout) == json.loads(to_json(sample_result.to_dict()))


@pytest.mark.parametrize("method", ["observer", "idim", "oe"])
def test_a_result_round_trips_through_its_json(sample_log, method):
    """from_dict(to_dict) gives the same document, through real JSON text; the estimate keeps its covariance."""
    result = wmrid.identify(
        sample_log, "paper", method=method, observer=wmrid.ObserverOptions(payload=method == "observer")
    )
    doc = json.loads(to_json(result.to_dict()))
    assert doc["schema_version"] == SCHEMA_VERSION
    back = from_dict(doc, "saved.json")
    assert json.loads(to_json(back.to_dict())) == doc
    assert back.method == method
    assert back.estimate.method == method
    np.testing.assert_array_equal(back.estimate.theta0, result.estimate.theta0)
    np.testing.assert_array_equal(back.estimate.cov, result.estimate.cov)
    assert back.parameters == result.parameters
    if method == "observer":
        assert back.payload == result.payload


def test_a_result_of_a_newer_schema_or_an_incomplete_one_is_refused(sample_result):
    doc = sample_result.to_dict()
    from wmrid.estimators.result import SCHEMA_VERSION

    newer = SCHEMA_VERSION + 1
    with pytest.raises(LogFormatError, match=f"schema version {newer}, newer than this wmrid reads"):
        from_dict({**doc, "schema_version": newer}, "future.json")
    broken = {k: v for k, v in doc.items() if k != "settings"}
    with pytest.raises(LogFormatError, match=r"broken.json: not a complete identify result \(no 'settings'\)"):
        from_dict(broken, "broken.json")
    with pytest.raises(LogFormatError, match="not an identify result"):
        from_dict([1, 2], "list.json")


def test_a_result_saved_before_schema_versions_reads_as_version_1(sample_result):
    """Documents written before ``schema_version`` and ``estimate`` existed: the reported std on the diagonal."""
    doc = json.loads(to_json(sample_result.to_dict()))
    del doc["schema_version"], doc["estimate"]
    back = from_dict(doc)
    std = np.sqrt(np.diag(back.theta0_cov))
    assert std[0] == pytest.approx(doc["parameters"]["m11"]["std"], rel=1e-15)
    assert back.estimate is None


def test_library_errors_name_options_as_python_names(sample_log):
    with pytest.raises(UsageError, match=r"friction='wheel\+caster' with method='oe' needs"):
        wmrid.identify(sample_log, method="oe", observer=wmrid.ObserverOptions(friction="wheel+caster"))
    with pytest.raises(UsageError, match=r"control_rate is modelled by the observer, idim, iv and rls only"):
        wmrid.identify(sample_log, method="oe", observer=wmrid.ObserverOptions(control_rate=1000.0))
    with pytest.raises(UsageError, match="delay must be auto or a number of seconds, got 'soon'"):
        wmrid.ObserverOptions(delay="soon")
    with pytest.raises(UsageError, match="unknown log option 'speed'"):
        wmrid.read_log(SAMPLE, speed="rpm")


def test_the_same_errors_name_flags_on_the_command_line():
    proc = cli("identify", str(SAMPLE), "--method", "oe", "--friction", "wheel+caster")
    assert proc.returncode == 2
    assert "--friction wheel+caster with --method oe needs" in proc.stderr.decode()
    proc = cli("identify", str(SAMPLE), "--delay", "soon")
    assert "--delay must be auto or a number of seconds, got 'soon'" in proc.stderr.decode()


def test_log_options_come_from_one_object_and_the_robot_fills_the_rest():
    opts = wmrid.LogOptions(speed_unit="m/s", effort="current")
    robot = wmrid.load_robot("paper")
    filled = opts.with_robot(robot)
    assert filled.wheel_radius == robot.nominal.r
    assert filled.torque_constant == robot.torque_constant
    assert opts.with_robot(None) is opts
    log = wmrid.read_log(SAMPLE, wmrid.LogOptions(speed_unit="rpm"))
    ref = wmrid.read_log(SAMPLE)
    np.testing.assert_allclose(log.eta, ref.eta * 2 * math.pi / 60, rtol=1e-15)


def test_simulate_and_write_simulation_give_the_cli_files(tmp_path):
    run = wmrid.simulate("paper", duration=2.0, noise=wmrid.NoiseSettings(seed=3, eta_std=0.01))
    truth_path = wmrid.write_simulation(run, tmp_path / "api.csv")
    proc = cli("simulate", "-o", str(tmp_path / "cli.csv"), "--duration", "2", "--seed", "3", "--eta-noise", "0.01")
    assert proc.returncode == 0, proc.stderr
    assert (tmp_path / "api.csv").read_bytes() == (tmp_path / "cli.csv").read_bytes()
    assert Path(truth_path).read_bytes() == (tmp_path / "cli.csv.truth.json").read_bytes()


def test_a_saved_result_without_history_reads_back_without_one_and_reports(sample_result):
    doc = json.loads(to_json(sample_result.to_dict()))
    del doc["history"]
    back = from_dict(doc, "short.json")
    assert back.history is None
    assert "history" not in back.to_dict()
    rep = wmrid.report(doc, figures=False)
    assert rep.result["source"] == doc["source"]
    assert "source" in doc  # the caller's document is not changed
    for bad in ("1", True, 0, -2):
        with pytest.raises(LogFormatError, match="is not a version number"):
            from_dict({**doc, "schema_version": bad}, "odd.json")
    with pytest.raises(LogFormatError, match="not a complete identify result"):
        from_dict({**doc, "settings": {**doc["settings"], "k": 10**400}}, "huge.json")


def test_a_urdf_robot_in_the_library_takes_the_gear_ratio_from_the_log_options(sample_log):
    urdf = ROOT / "tests" / "data" / "paper_robot.urdf"
    result = wmrid.identify(sample_log, urdf, options=wmrid.LogOptions(gear_ratio=100.0))
    paper_cad = model.named_base(model.base_parameters(wmrid.load_robot("paper").cad))
    assert result.reference["m11"] == pytest.approx(paper_cad["m11"], rel=1e-9)  # as test_urdf checks the CLI
    with pytest.raises(UsageError, match=r"robot='.*paper_robot.urdf': a URDF does not give the gear ratio"):
        wmrid.identify(sample_log, urdf)


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (["identify", "-", "--validate", "-", "--robot", "x.urdf"], "LOG and --validate cannot both be standard input"),
        (["identify", str(SAMPLE), "--forgetting", "5", "--robot", "nosuch.toml"], "--forgetting must be in"),
        (["compare", str(SAMPLE), "--methods", "foo", "--truth", "missing.json"], "--method must be one of"),
        (["report", str(SAMPLE), "--method", "oe", "--control-rate", "1000", "--columns", "zz=t"], "--control-rate"),
    ],
)
def test_the_command_line_checks_its_options_in_the_order_it_always_did(args, needle):
    """The first of several mistakes is the one reported, as before the commands became library calls."""
    proc = cli(*args)
    assert proc.returncode == 2
    assert needle in proc.stderr.decode()


@pytest.mark.slow  # a whole report with figures (4 s)
def test_report_of_a_saved_result_ignores_the_robot_flags(tmp_path, sample_result):
    saved = tmp_path / "saved.json"
    saved.write_text(to_json(sample_result.to_dict()), encoding="utf-8")
    proc = cli("report", str(saved), "--robot", "x.urdf", "-o", str(tmp_path / "r.md"))
    assert proc.returncode == 0, proc.stderr


def test_a_simulated_log_identifies_as_its_wheel_log():
    # wmrid.simulate(...).log is taken by identify as it is (it failed: its reference pose is (n, 3))
    run = wmrid.simulate("paper", duration=4.0, noise=wmrid.NoiseSettings(seed=2, eta_std=0.01))
    direct = wmrid.identify(run.log, "paper")
    log = run.log.to_wheel_log()
    assert log.reference is run.log.eta_ref  # the wheel-speed reference, not the pose
    assert direct.estimate.theta0.tolist() == wmrid.identify(log, "paper").estimate.theta0.tolist()


def test_a_version_1_result_of_another_method_reads_its_settings_as_the_observers(sample_log):
    """Schema version 1 put the observer's settings under ``settings`` whatever the method; version 2 gives another
    method its own (``MethodSettings``) and the observer's under ``observer_settings``.  Both read back."""
    idim = wmrid.identify(sample_log, "paper", method="idim")
    doc = json.loads(to_json(idim.to_dict(history=False)))
    assert doc["schema_version"] == 2
    assert doc["settings"]["method"] == "idim"
    assert doc["settings"]["cutoff_hz"] > 0
    assert doc["observer_settings"]["k"] == 10.0
    back = from_dict(doc)
    assert back.settings == idim.settings
    assert back.observer_settings.k == 10.0
    old = {**doc, "schema_version": 1, "settings": doc["observer_settings"]}
    del old["observer_settings"]
    was = from_dict(old)
    assert was.method_settings is None  # what version 1 said, read as it said it
    assert was.settings.k == 10.0
    assert was.parameters == back.parameters


def test_option_objects_parse_and_refuse_as_the_flags_do():
    assert wmrid.ObserverOptions(delay="0.012").delay == 0.012
    assert wmrid.ObserverOptions(delay=" AUTO ").delay == "auto"
    for bad in ("soon", float("nan"), float("inf")):
        with pytest.raises(UsageError, match="delay must be auto or a number of seconds"):
            wmrid.ObserverOptions(delay=bad)
    with pytest.raises(UsageError, match="no built-in trajectory of that name"):
        wmrid.simulate("paper", trajectory="sinusiod")
    robot = wmrid.load_robot("paper")
    fault = wmrid.PlantChange.friction_fault(1.0, robot.reference, "right", 3.0)
    with pytest.raises(UsageError, match="with a friction-fault PlantChange: the change holds the plant"):
        wmrid.simulate("paper", duration=2.0, payload=wmrid.Payload(20.0), change=fault)
    loaded = wmrid.simulate("paper", duration=2.0, payload=wmrid.Payload(20.0), change=wmrid.Change(1.0, "drop"))
    unloaded = model.named_base(model.base_parameters(robot.reference))
    assert loaded.truth["parameters"]["m11"] < unloaded["m11"]  # carried until the drop: the plant at t = 0 is loaded


def test_a_saved_result_is_read_without_numba(tmp_path):
    """The result's types load no compiled code (ObserverSettings lives apart from the kernel): reading a saved result
    back (``IdentificationResult.from_dict``) starts without numba."""
    code = "import sys, json; from wmrid.estimators.result import IdentificationResult; print('numba' in sys.modules)"
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True, cwd=tmp_path)
    assert done.stdout.strip() == "False", done.stderr


@pytest.mark.parametrize(
    ("fields", "named"),
    [({"time_source": "x"}, "time_source"), ({"speed_unit": "furlong"}, "speed_unit"), ({"effort": "x"}, "effort"),
     ({"topic": "/a", "velocity_topic": "/b"}, "velocity_topic")],
)  # fmt: skip
def test_log_options_are_checked_when_made_not_when_a_log_is_read(fields, named) -> None:
    with pytest.raises(wmrid.WmridError, match=named):
        wmrid.LogOptions(**fields)
