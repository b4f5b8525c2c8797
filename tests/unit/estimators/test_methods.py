"""The methods behind one interface (observer, idim, rls, oe), ``wmrid compare`` and ``--validate``.

Truth: the simulator's plant parameters (:func:`wmrid.model.dynamics.base_parameters` of the CAD robot, itself
checked against the paper's tables in test_model).
"""

from __future__ import annotations

import json
import subprocess
from pathlib import Path
from types import SimpleNamespace

import cliutil
import numpy as np
import pytest
from locations import ROOT_DIR

from wmrid.core.errors import UsageError
from wmrid.estimators.methods import METHODS, compare
from wmrid.estimators.options import MethodOptions
from wmrid.model import dynamics as model
from wmrid.model.robot import BUILTIN_ROBOTS, Payload
from wmrid.pipeline.identify import identify
from wmrid.sim.scenario import NoiseSettings
from wmrid.sim.simulate import simulate

ROBOT = BUILTIN_ROBOTS["paper"]
SAMPLES = ROOT_DIR / "sample_logs"
NOISE = NoiseSettings(eta_std=0.01, tau_std=0.02, caster_std=0.05)  # sensor noise plus a coloured caster torque
PAYLOAD = Payload(mass=25.0, x=0.1, y=-0.05, inertia=0.4)


def wmrid(*args: str) -> subprocess.CompletedProcess:
    """``wmrid ARGS`` in this process, stdout and stderr as text."""
    return cliutil.text(cliutil.wmrid(*args))


def _log(seed: int, true=None) -> SimpleNamespace:
    sim = simulate(true or ROBOT.reference, ROBOT.nominal, duration=40.0, noise=NOISE, seed=seed)
    return SimpleNamespace(t=sim.t, eta=sim.eta, tau=sim.tau, source=f"seed {seed}", notes=(), reference=sim.eta_ref)


@pytest.fixture(scope="module")
def comparison() -> dict:
    """All methods on a noisy 40 s closed-loop log (seed 1), validated on a second log of the same robot."""
    log = _log(1)
    truth = model.named_base(model.base_parameters(ROBOT.reference))
    observer = identify(log, ROBOT, feedback=False)
    return compare(log, observer, MethodOptions(), other=_log(2), truth=truth).to_dict()


def test_every_method_gets_the_inertia_and_vc_within_5_percent(comparison: dict) -> None:
    # Measured (seed 1): every method within 0.6 % on M11, M12, M22 and Vc; issue 6 asks for 5 %.
    assert set(comparison["methods"]) == set(METHODS)
    for name, row in comparison["methods"].items():
        for key in ("M11", "M12", "M22", "Vc"):
            assert abs(row["parameters"][key]["error_percent"]) < 5.0, (name, key)
        assert row["seconds"] > 0


def test_the_standard_errors_are_finite_and_the_truth_within_4_std(comparison: dict) -> None:
    # 4 std: every method's std is a segment jackknife or sandwich (t with 10-40 dof); a caster in closed loop
    # biases the inertia terms by up to ~0.7 std (docs/explanation/uncertainty.md), so 4 std, not 3, for one seed.
    truth = comparison["truth"]
    for name, row in comparison["methods"].items():
        for key in ("M11", "M12", "M22", "Vc"):
            entry = row["parameters"][key]
            assert entry["std"] is not None, (name, key)
            assert abs(entry["value"] - truth[key]) < 4 * entry["std"], (name, key)


def test_a_second_log_of_the_same_robot_fits_well(comparison: dict) -> None:
    # Measured: 96.7-97.8 % for every method; issue 6 asks for >= 80 %.
    for name, row in comparison["methods"].items():
        for wheel in ("eta_r", "eta_l"):
            assert row["validation"]["fit_percent"][wheel] >= 80.0, (name, wheel)


def test_a_log_with_a_payload_fits_clearly_worse() -> None:
    # Measured: 65-68 % against 97 % on the unloaded robot's second log; issue 6 asks for 5 points lower.
    log = _log(1)
    observer = identify(log, ROBOT, feedback=False)
    same = compare(log, observer, MethodOptions(), ("observer", "idim"), other=_log(2)).to_dict()
    loaded = compare(
        log, observer, MethodOptions(), ("observer", "idim"), other=_log(3, ROBOT.reference.with_payload(PAYLOAD))
    ).to_dict()
    for name in ("observer", "idim"):
        for wheel in ("eta_r", "eta_l"):
            good = same["methods"][name]["validation"]["fit_percent"][wheel]
            bad = loaded["methods"][name]["validation"]["fit_percent"][wheel]
            assert bad <= good - 5.0, (name, wheel, good, bad)


def test_method_options_are_validated() -> None:
    with pytest.raises(UsageError, match="forgetting"):
        MethodOptions(forgetting=0.0)
    with pytest.raises(UsageError, match="cutoff"):
        MethodOptions(cutoff_hz=-1.0)


@pytest.mark.parametrize("method", [m for m in METHODS if m != "iv"])
def test_identify_method_on_the_cli(method: str) -> None:
    # The noise-free sample: the observer and OE are exact to ~1e-6 %; IDIM's low-pass filter (its residual
    # gain and phase at the signal's frequencies) costs it 0.04 % on the inertia terms, 0.11 % on Vc (measured)
    # and ~7 % on the small friction terms, so 0.2 % for IDIM and RLS.  The sample has no reference columns, so
    # `iv` refuses it; tests/unit/estimators/test_iv.py runs `--method iv` on a log that has them.
    proc = wmrid("identify", str(SAMPLES / "paper_sinusoid.csv"), "--robot", "paper", "--method", method,
                 "--format", "json")  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    out = json.loads(proc.stdout)
    assert out["method"] == method
    truth = json.loads((SAMPLES / "paper_sinusoid.csv.truth.json").read_text())["parameters"]
    tol = 0.2 if method in ("idim", "rls") else 1e-3
    for key in ("M11", "M12", "M22", "Vc"):
        assert abs(out["parameters"][key]["value"] / truth[key] - 1) * 100 < tol, key
    if method != "observer":
        assert out["diagnostics"]["method"]["name"] == method
        assert "observer_parameters" in out["diagnostics"]


def test_validate_on_the_cli_writes_the_fit(tmp_path: Path) -> None:
    # A second, noisy log of the same robot (another seed): the model of the sample log predicts it well.
    other = tmp_path / "other.csv"
    made = wmrid("simulate", "-o", str(other), "--duration", "20", "--seed", "5", "--eta-noise", "0.01",
                 "--caster", "0.05")  # fmt: skip
    assert made.returncode == 0, made.stderr
    proc = wmrid("identify", str(SAMPLES / "paper_sinusoid.csv"), "--robot", "paper", "--validate", str(other),
                 "--format", "json")  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    validation = json.loads(proc.stdout)["validation"]
    assert set(validation["fit_percent"]) == {"eta_r", "eta_l"}
    assert min(validation["fit_percent"].values()) >= 80.0
    assert validation["log"] == str(other)


def test_compare_on_the_cli(tmp_path: Path) -> None:
    out = tmp_path / "cmp.json"
    proc = wmrid("compare", str(SAMPLES / "paper_sinusoid.parquet"), "--robot", "paper", "--truth",
                 str(SAMPLES / "paper_sinusoid.parquet.truth.json"), "--methods", "observer,idim", "-o", str(out),
                 "--format", "json")  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    data = json.loads(proc.stdout)
    assert data == json.loads(out.read_text())
    assert set(data["methods"]) == {"observer", "idim"}
    for row in data["methods"].values():
        assert set(row) >= {"parameters", "seconds"}
        assert np.isfinite(row["parameters"]["m11"]["value"])
        assert "error_percent" in row["parameters"]["m11"]


def test_the_compare_validation_reads_back_typed_and_writes_the_same_json() -> None:
    """`wmrid compare --validate` (in process): the JSON's ``validation`` read as a :class:`ValidationLog` writes back
    exactly the object it was read from (same keys, same order, same values); the table names the log and predictor
    from the typed record."""
    from wmrid.estimators.methods import ValidationLog

    args = (str(SAMPLES / "paper_sinusoid.csv"), "--robot", "paper", "--methods", "observer,idim", "--validate",
            str(SAMPLES / "paper_sinusoid.parquet"))  # fmt: skip
    proc = wmrid("compare", *args, "--format", "json")
    assert proc.returncode == 0, proc.stderr
    data = json.loads(proc.stdout)
    back = ValidationLog.from_dict(data["validation"])
    assert json.dumps(back.to_dict()) == json.dumps(data["validation"])
    assert ValidationLog.from_dict(back.to_dict()) == back
    assert back.log == str(SAMPLES / "paper_sinusoid.parquet")
    assert back.predictor
    table = wmrid("compare", *args, "--format", "table")
    assert table.returncode == 0, table.stderr
    assert f"fit on {back.log}: {back.predictor[:30]}" in " ".join(table.stdout.split())


@pytest.mark.parametrize(
    ("args", "needle"),
    [
        (("compare", "LOG", "--methods", "observer,magic"), "--method must be one of"),
        (("identify", "LOG", "--method", "rls", "--forgetting", "1.5"), "--forgetting must be in [0.98, 1]"),
        (("identify", "LOG", "--validate", "missing.csv"), "missing.csv: no such file"),
        (
            ("identify", "LOG", "--method", "oe", "--control-rate", "2000"),
            "modelled by the observer, idim, iv and rls only",
        ),
        (("identify", "LOG", "--validate", "LOG", "--control-rate", "2000"), "--validate predictor"),
        (("compare", "LOG", "--control-rate", "2000"), "observer, idim, iv and rls only"),
        (("identify", "LOG", "--control-rate", "1e9"), "1,000,000 held sub-steps"),
        (("identify", "-", "--validate", "-"), "cannot both be standard input"),
    ],
)
def test_bad_method_options_exit_2_with_one_line(args: tuple[str, ...], needle: str) -> None:
    args = tuple(str(SAMPLES / "paper_sinusoid.csv") if a == "LOG" else a for a in args)
    proc = wmrid(*args)
    assert proc.returncode == 2, proc.stderr
    assert needle in proc.stderr
    assert len(proc.stderr.strip().splitlines()) == 1
    assert "Traceback" not in proc.stderr


def test_report_shows_the_method_and_the_validation(tmp_path: Path) -> None:
    out = tmp_path / "r.json"
    proc = wmrid("report", str(SAMPLES / "paper_sinusoid.csv"), "--robot", "paper", "--method", "rls", "--validate",
                 str(SAMPLES / "paper_sinusoid.parquet"), "-o", str(out))  # fmt: skip
    assert proc.returncode == 0, proc.stderr
    text = out.read_text()
    assert "Validation on" in text
    assert "Method: rls" in text
    proc = wmrid("report", str(out), "--validate", str(SAMPLES / "paper_sinusoid.parquet"))
    assert proc.returncode == 2
    assert "need a log as INPUT" in proc.stderr


def test_a_control_rate_no_faster_than_the_log_is_said_to_change_nothing() -> None:
    proc = wmrid("identify", str(SAMPLES / "paper_sinusoid.csv"), "--control-rate", "1000", "--format", "json")
    assert proc.returncode == 0, proc.stderr
    assert any("not faster than the log" in w for w in json.loads(proc.stdout)["warnings"])
