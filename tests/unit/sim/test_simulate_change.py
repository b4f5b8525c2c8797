"""A change of the plant during a simulated run (payload loaded or dropped, friction fault), library and CLI."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
from cliutil import assert_clean_error, wmrid
from locations import ROOT_DIR

from wmrid.core.errors import UsageError
from wmrid.model import dynamics as model, torques
from wmrid.model.robot import BUILTIN_ROBOTS, Payload
from wmrid.sim.closed_loop import closed_loop_kernel
from wmrid.sim.scenario import NoiseSettings, PlantChange, parse_friction_fault, parse_time
from wmrid.sim.simulate import GAINS, SimulatedLog, simulate

PAPER = BUILTIN_ROBOTS["paper"]
TRUE = PAPER.cad
NOMINAL = PAPER.nominal
assert TRUE is not None
LOAD = Payload(25.0, 0.1, -0.05, 0.4)
ARRAYS = ("eta", "tau", "pose", "wheel_angle", "reference", "disturbance", "eta_true")
NOISE = NoiseSettings(eta_std=0.01, tau_std=0.02, caster_std=0.05, encoder_cpr=409600)


def _changes(t: float) -> dict[str, PlantChange]:
    return {
        "payload-load": PlantChange.payload_load(t, TRUE, LOAD),
        "payload-drop": PlantChange.payload_drop(t, TRUE, LOAD),
        "friction-fault": PlantChange.friction_fault(t, TRUE, "right", 3.0),
    }


# ------------------------------------------------------------------------------------------ no change


def test_no_change_is_the_plain_simulation() -> None:
    # Without a change the kernel runs as it always did (called without the new arguments), and the
    # switching path itself changes no arithmetic: the same plant passed as "after" gives the same bits.
    log = simulate(TRUE, NOMINAL, trajectory="reversing", duration=2.0, noise=NoiseSettings(caster_std=0.05), seed=3)
    assert log.change is None
    assert "change" not in log.settings
    assert log.plant_at(1.5) is TRUE
    rng = np.random.Generator(np.random.PCG64(3))
    n = len(log.t)
    rng.standard_normal((n, 2))
    rng.standard_normal((n, 2))
    caster_z = rng.standard_normal((n, 2))
    theta0 = model.base_parameters(TRUE)
    m = model.inverse_inertia(theta0)
    big = model.inertia_matrix(NOMINAL)
    plant = np.array([m[0, 0], m[0, 1], m[1, 1], *theta0[3:], TRUE.r, TRUE.b])
    ctrl = np.array([big[0, 0], big[0, 1], big[1, 1], model.coriolis_coefficient(NOMINAL), 0, 0, 0, 0, NOMINAL.r,
                     NOMINAL.b])  # fmt: skip
    traj = np.array(list(log.settings["trajectory_parameters"].values()))
    gains = np.array([GAINS[k] for k in ("k1", "k2", "k3", "K")])
    args = (1, traj, plant, ctrl, gains, 1e-3, 4, n, 1, caster_z, 0.05, 0.3)
    plain = closed_loop_kernel(*args)
    same_after = closed_loop_kernel(*args, plant.copy(), 1000)
    for a, b in zip(plain, same_after, strict=True):
        np.testing.assert_array_equal(a, b)
    np.testing.assert_array_equal(plain[0], log.pose)
    np.testing.assert_array_equal(plain[2], log.eta_true)
    np.testing.assert_array_equal(plain[3], log.tau)
    np.testing.assert_array_equal(plain[5], log.disturbance)
    assert set(log.truth()) == {"parameters", "physical", "nominal_physical", "settings"}


# ------------------------------------------------------------------------------------ switching rule


@pytest.mark.parametrize(
    ("t", "period", "expected"),
    [(2.0, 1e-3, 2000), (30.0, 1e-3, 30000), (2.0000001, 1e-3, 2001), (2.0023, 1e-3, 2003), (1e-10, 1e-3, 1),
     (1.00025, 5e-4, 2001), (0.3, 1e-3, 300), (0.7, 1e-3, 700)],
)  # fmt: skip
def test_switch_period_is_the_first_control_period_starting_at_or_after_t(t, period, expected) -> None:
    # 0.3 / 1e-3 = 299.99999999999994 and 0.7 / 1e-3 = 699.9999999999999 in floating point: on the grid.
    change = PlantChange.payload_load(t, TRUE, LOAD)
    k = change.switch_period(period)
    assert k == expected
    assert k * period >= t * (1 - 1e-9)
    assert (k - 1) * period < t


@pytest.mark.parametrize("kind", ["payload-load", "payload-drop", "friction-fault"])
@pytest.mark.parametrize(("rate", "t_change"), [(1000.0, 2.0), (200.0, 2.0023), (2000.0, 1.00025)])
def test_samples_up_to_the_switch_are_the_unchanged_run(kind: str, rate: float, t_change: float) -> None:
    # Same seed: every logged value at t <= t_switch is bit for bit the run with the "before" plant and no
    # change (noise, caster disturbance and encoder included); the next sample already differs.
    change = _changes(t_change)[kind]
    plain = simulate(change.before, NOMINAL, duration=4.0, rate=rate, noise=NOISE, seed=7)
    changed = simulate(change.before, NOMINAL, duration=4.0, rate=rate, noise=NOISE, seed=7, change=change)
    t_switch = changed.settings["change"]["t_switch"]
    assert t_change <= t_switch < t_change + changed.settings["control_period"]
    last = int(np.flatnonzero(changed.t <= t_switch + 1e-12)[-1])
    assert last > 0
    for name in ARRAYS:
        np.testing.assert_array_equal(getattr(changed, name)[: last + 1], getattr(plain, name)[: last + 1], name)
    assert not np.array_equal(changed.eta_true[last + 1], plain.eta_true[last + 1])
    assert not np.array_equal(changed.pose[-1], plain.pose[-1])
    # The controller and the random streams are untouched: the disturbance sequence is the same throughout.
    np.testing.assert_array_equal(changed.disturbance, plain.disturbance)
    assert changed.plant_at(changed.t[last] - 1e-3) is change.before
    assert changed.plant_at(t_switch) is change.after


# ------------------------------------------------------------------------------- dynamics after the switch


def _acceleration_check(log: SimulatedLog, theta0: np.ndarray, rows: np.ndarray) -> tuple[float, float]:
    """(max error, its bound) of the finite-difference acceleration over the intervals ``rows`` against
    model.wheel_acceleration with theta0.

    Over one log period (= one control period at 1 kHz) the torque is held, so (eta[k+1] - eta[k]) / h =
    eta'(t_k + h/2) + h^2/24 eta''' and f(eta_mid) - f(eta(t_k + h/2)) = J h^2/8 eta'' (J = df/deta), as in
    tests/unit/sim/test_simulate.py.  Here the bound is computed from the run: |eta'| <= max |fd|,
    ||J|| <= ||m|| (3 Vc max|eta| + max F_v) (dV/deta has entries Vc e2, Vc (e1 - 2 e2), Vc (e2 - 2 e1),
    Vc e1), |eta''| <= ||J|| |eta'|, and |eta'''| <= ||J|| |eta''| + ||m|| 4 Vc |eta'|^2 (the second
    derivatives of V are at most 2 Vc per entry).  Observed errors are ~1e-6 rad/s^2, the bound ~1e-5.
    """
    h = log.t[1] - log.t[0]
    fd = np.diff(log.eta, axis=0)[rows] / h
    mid = 0.5 * (log.eta[1:] + log.eta[:-1])[rows]
    acc = torques.wheel_acceleration(mid, log.tau[:-1][rows], theta0)
    m_norm = np.linalg.norm(model.inverse_inertia(theta0), 2)
    vc, eta_max, d1 = theta0[3], np.abs(log.eta).max(), np.abs(fd).max()
    j_norm = m_norm * (3 * vc * eta_max + theta0[4:6].max())
    d2 = j_norm * d1
    d3 = j_norm * d2 + m_norm * 4 * vc * d1**2
    bound = h**2 * (d3 / 24 + j_norm * d2 / 8)
    return float(np.abs(fd - acc).max()), float(bound)


@pytest.mark.parametrize("kind", ["payload-load", "payload-drop", "friction-fault"])
def test_plant_after_the_switch_is_the_changed_robot(kind: str) -> None:
    # Noise-free, 1 kHz: every interval starting at or after t_switch obeys the model with the "after"
    # parameters, computed independently here (with_payload / the CAD friction times 3), every interval
    # before it the "before" parameters -- and not the other way round (misfits of 1e-2 rad/s^2 and more).
    t_change = 3.0
    change = _changes(t_change)[kind]
    after = {
        "payload-load": TRUE.with_payload(LOAD),
        "payload-drop": TRUE,
        "friction-fault": TRUE.replace(F_v1=3 * TRUE.F_v1, F_d1=3 * TRUE.F_d1),
    }[kind]
    before = TRUE.with_payload(LOAD) if kind == "payload-drop" else TRUE
    theta_before, theta_after = model.base_parameters(before), model.base_parameters(after)
    log = simulate(before, NOMINAL, duration=6.0, change=change)
    assert np.all(log.eta_true > 0)  # sgn(eta) = +1 on every interval
    k_s = round(t_change * 1000)
    assert log.t[k_s] == pytest.approx(t_change, abs=1e-12)
    assert log.settings["change"]["t_switch"] == pytest.approx(t_change, abs=1e-12)
    n = len(log.t) - 1
    pre, post = np.arange(k_s), np.arange(k_s, n)
    assert np.abs(np.diff(log.eta, axis=0)[post]).max() * 1000 > 1.0  # the run does accelerate after T
    for rows, right, wrong in ((post, theta_after, theta_before), (pre, theta_before, theta_after)):
        err, bound = _acceleration_check(log, right, rows)
        assert 1e-7 < bound < 1e-4
        assert err <= bound, (err, bound)
        wrong_err, _ = _acceleration_check(log, wrong, rows)
        assert wrong_err > 100 * bound, (wrong_err, bound)
    # The switch is exactly at k_s: the single interval [t_{k_s - 1}, t_{k_s}] is the old plant's, the next
    # one the new plant's.
    for rows, right, wrong in ((np.array([k_s - 1]), theta_before, theta_after),
                               (np.array([k_s]), theta_after, theta_before)):  # fmt: skip
        err, bound = _acceleration_check(log, right, rows)
        assert err <= bound, (rows, err, bound)
        wrong_err, _ = _acceleration_check(log, wrong, rows)
        assert wrong_err > 100 * bound, (rows, wrong_err, bound)


def test_friction_fault_multiplies_the_chosen_parameters() -> None:
    cases = {
        ("right", "both"): {"F_v1", "F_d1"},
        ("left", "both"): {"F_v2", "F_d2"},
        ("right", "viscous"): {"F_v1"},
        ("left", "coulomb"): {"F_d2"},
    }
    for (wheel, terms), names in cases.items():
        change = PlantChange.friction_fault(1.0, TRUE, wheel, 2.5, terms)
        assert change.before is TRUE
        for key, value in TRUE.to_dict().items():
            expected = 2.5 * value if key in names else value
            assert getattr(change.after, key) == expected, (wheel, terms, key)
        assert change.detail == {"wheel": wheel, "factor": 2.5, "terms": terms, "parameters": sorted(
            names, key=["F_v1", "F_v2", "F_d1", "F_d2"].index)}  # fmt: skip
    # A factor 0 removes the friction; the base parameters record it.
    log = simulate(TRUE, NOMINAL, duration=2.0, change=PlantChange.friction_fault(1.0, TRUE, "left", 0.0))
    after = log.settings["change"]["after"]
    assert (after["Fv2"], after["Fd2"], after["Fv1"], after["Fd1"]) == (0.0, 0.0, TRUE.F_v1, TRUE.F_d1)
    assert log.settings["change"]["before"] == log.truth()["parameters"]


# -------------------------------------------------------------------------------------- settings, truth


def test_settings_record_the_change_and_reproduce_the_run() -> None:
    change = PlantChange.payload_drop(1.2345, TRUE, LOAD)
    log = simulate(change.before, NOMINAL, trajectory="reversing", duration=3.0, rate=500.0, noise=NOISE, seed=4,
                   change=change)  # fmt: skip
    s = json.loads(json.dumps(log.settings))  # JSON-serialisable
    c = s["change"]
    assert c["kind"] == "payload-drop"
    assert c["t"] == 1.2345
    assert c["t_switch"] == pytest.approx(1.235, abs=1e-12)
    assert c["switch_period"] == 1235
    assert c["before"] == pytest.approx(model.named_base(model.base_parameters(TRUE.with_payload(LOAD))), rel=1e-15)
    assert c["after"] == pytest.approx(model.named_base(model.base_parameters(TRUE)), rel=1e-15)
    assert c["physical_before"] == TRUE.with_payload(LOAD).to_dict()
    assert c["physical_after"] == TRUE.to_dict()
    assert c["payload"] == {"mass": 25.0, "x": 0.1, "y": -0.05, "inertia": 0.4}
    truth = log.truth()
    assert truth["parameters"] == c["before"]  # the truth's parameters are those at t = 0
    assert truth["settings"]["change"] == c
    again_change = PlantChange.from_dict(c)
    again = simulate(again_change.before, NOMINAL, trajectory=s["trajectory"], duration=s["duration"], rate=s["rate"],
                     noise=NoiseSettings(**s["noise"]), seed=s["seed"], substeps=s["substeps"],
                     change=again_change)  # fmt: skip
    for name in ARRAYS:
        np.testing.assert_array_equal(getattr(log, name), getattr(again, name), name)


# ------------------------------------------------------------------------------------------- validation


@pytest.mark.parametrize("t", [0.0, -1.0, float("nan"), float("inf"), "1", True, None])
def test_invalid_change_time(t) -> None:
    with pytest.raises(UsageError, match="change time"):
        PlantChange(t, TRUE, TRUE.with_payload(LOAD))


def test_invalid_changes() -> None:
    loaded = TRUE.with_payload(LOAD)
    with pytest.raises(UsageError, match="changes nothing"):
        PlantChange(1.0, TRUE, TRUE)
    with pytest.raises(UsageError, match="kind"):
        PlantChange(1.0, TRUE, loaded, kind="teleport")
    with pytest.raises(UsageError, match="detail"):
        PlantChange(1.0, TRUE, loaded, detail={"t": 3})
    with pytest.raises(UsageError, match="PhysicalParameters"):
        PlantChange(1.0, TRUE, TRUE.to_dict())  # type: ignore[arg-type]
    with pytest.raises(UsageError, match="Payload"):
        PlantChange.payload_load(1.0, TRUE, 25.0)  # type: ignore[arg-type]
    with pytest.raises(UsageError, match="wheel"):
        PlantChange.friction_fault(1.0, TRUE, "front", 2.0)
    with pytest.raises(UsageError, match="terms"):
        PlantChange.friction_fault(1.0, TRUE, "right", 2.0, "static")
    for factor in (1.0, -0.5, float("nan"), float("inf"), "2", True):
        with pytest.raises(UsageError, match="factor"):
            PlantChange.friction_fault(1.0, TRUE, "right", factor)  # type: ignore[arg-type]
    with pytest.raises(UsageError, match="are 0"):  # the nominal robot has no friction to multiply
        PlantChange.friction_fault(1.0, NOMINAL, "left", 2.0)
    change = PlantChange.payload_load(1.0, TRUE, LOAD)
    with pytest.raises(UsageError, match="before"):
        simulate(NOMINAL, NOMINAL, duration=2.0, change=change)
    with pytest.raises(UsageError, match="PlantChange"):
        simulate(TRUE, NOMINAL, duration=2.0, change={"t": 1.0})  # type: ignore[arg-type]
    # The switch must fall strictly inside the run: 1.9995 s switches at 2 s, the last sample of a 2 s run.
    for t in (2.0, 1.9995, 5.0):
        with pytest.raises(UsageError, match="last sample"):
            simulate(TRUE, NOMINAL, duration=2.0, change=PlantChange.payload_load(t, TRUE, LOAD))
    with pytest.raises(UsageError, match="after 0"):
        simulate(TRUE, NOMINAL, duration=2.0, change=PlantChange.payload_load(1e-13, TRUE, LOAD))
    assert simulate(TRUE, NOMINAL, duration=2.0, change=PlantChange.payload_load(1.999, TRUE, LOAD)).change


def test_option_parsers() -> None:
    assert parse_time("30", "--load-at") == 30.0
    assert parse_time(" 2.5e1 ", "--load-at") == 25.0
    for bad in ("abc", "", "0", "-3", "nan", "inf"):
        with pytest.raises(UsageError, match="--drop-at"):
            parse_time(bad, "--drop-at")
    assert parse_friction_fault("right:3") == ("right", 3.0, "both")
    assert parse_friction_fault("Left:0.5:Coulomb") == ("left", 0.5, "coulomb")
    assert parse_friction_fault("left:2:viscous") == ("left", 2.0, "viscous")
    for bad in ("right", "right:", "up:3", "right:x", "right:3:static", "right:3:both:x", "3:right", ""):
        with pytest.raises(UsageError, match="WHEEL:FACTOR"):
            parse_friction_fault(bad)


# ------------------------------------------------------------------------------------------------- CLI


def test_cli_payload_loaded_at_t_writes_log_and_truth_with_both_sets(tmp_path: Path) -> None:
    log = tmp_path / "load.csv"
    proc = wmrid("simulate", "-o", str(log), "--duration", "4", "--seed", "2", "--eta-noise", "0.01",
                 "--payload", "25@0.1,-0.05", "--payload-inertia", "0.4", "--load-at", "2.5")  # fmt: skip
    assert proc.returncode == 0, proc.stderr.decode()
    sidecar = json.loads(Path(str(log) + ".truth.json").read_text())
    unloaded = model.named_base(model.base_parameters(TRUE))
    loaded = model.named_base(model.base_parameters(TRUE.with_payload(LOAD)))
    change = sidecar["settings"]["change"]
    assert sidecar["parameters"] == pytest.approx(unloaded, rel=1e-15)
    assert change["before"] == pytest.approx(unloaded, rel=1e-15)
    assert change["after"] == pytest.approx(loaded, rel=1e-15)
    assert (change["kind"], change["t"], change["t_switch"]) == ("payload-load", 2.5, 2.5)
    assert change["payload"] == sidecar["payload"] == {"mass": 25.0, "x": 0.1, "y": -0.05, "inertia": 0.4}
    # The CSV (floats in repr precision) is exactly the library's run.
    frame = pd.read_csv(log)
    ref = simulate(TRUE, NOMINAL, duration=4.0, seed=2, noise=NoiseSettings(eta_std=0.01),
                   change=PlantChange.payload_load(2.5, TRUE, LOAD)).to_frame()  # fmt: skip
    for col in ("t", "eta_r", "eta_l", "tau_r", "tau_l"):
        np.testing.assert_array_equal(frame[col].to_numpy(), ref[col].to_numpy(), col)


def test_cli_drop_and_friction_fault_in_parquet_and_mcap_metadata(tmp_path: Path) -> None:
    from wmrid.io.mcap.reader import read_mcap

    bag = tmp_path / "drop.mcap"
    proc = wmrid("simulate", "-o", str(bag), "--duration", "3", "--payload", "25", "--drop-at", "1")
    assert proc.returncode == 0, proc.stderr.decode()
    meta = json.loads(read_mcap(str(bag)).metadata["wmrid"]["truth"])
    change = meta["settings"]["change"]
    assert change["kind"] == "payload-drop"
    assert change["t_switch"] == 1.0
    assert change["before"] == meta["parameters"]
    assert change["after"] == pytest.approx(model.named_base(model.base_parameters(TRUE)), rel=1e-15)
    assert json.loads(Path(str(bag) + ".truth.json").read_text()) == meta

    import pyarrow.parquet as pq

    table = tmp_path / "fault.parquet"
    proc = wmrid("simulate", "-o", str(table), "--duration", "3", "--friction-fault", "left:2:coulomb",
                 "--fault-at", "1.5")  # fmt: skip
    assert proc.returncode == 0, proc.stderr.decode()
    meta = json.loads(pq.read_schema(table).metadata[b"wmrid_truth"])
    change = meta["settings"]["change"]
    assert change["kind"] == "friction-fault"
    assert (change["wheel"], change["factor"], change["terms"], change["parameters"]) == ("left", 2.0, "coulomb",
                                                                                         ["F_d2"])  # fmt: skip
    assert change["after"]["Fd2"] == 2 * TRUE.F_d2
    assert {k: v for k, v in change["after"].items() if k != "Fd2"} == {
        k: v for k, v in change["before"].items() if k != "Fd2"
    }
    assert change["physical_after"]["F_d2"] == 2 * TRUE.F_d2


def test_cli_friction_fault_on_a_loaded_robot(tmp_path: Path) -> None:
    log = tmp_path / "both.csv"
    proc = wmrid("simulate", "-o", str(log), "--duration", "2", "--payload", "25@0.1,-0.05", "--friction-fault",
                 "right:3", "--fault-at", "1")  # fmt: skip
    assert proc.returncode == 0, proc.stderr.decode()
    sidecar = json.loads(Path(str(log) + ".truth.json").read_text())
    loaded = TRUE.with_payload(Payload(25.0, 0.1, -0.05))
    assert sidecar["parameters"] == pytest.approx(model.named_base(model.base_parameters(loaded)), rel=1e-15)
    after = loaded.replace(F_v1=3 * loaded.F_v1, F_d1=3 * loaded.F_d1)
    assert sidecar["settings"]["change"]["physical_after"] == after.to_dict()


@pytest.mark.parametrize(
    ("args", "needles"),
    [
        (["--load-at", "2"], ["--load-at", "--payload"]),
        (["--payload", "25", "--load-at", "abc"], ["--load-at", "seconds"]),
        (["--payload", "25", "--drop-at", "-1"], ["--drop-at", "> 0"]),
        (["--payload", "25", "--drop-at", "nan"], ["--drop-at"]),
        (["--payload", "25", "--load-at", "9"], ["--load-at", "end of the run"]),
        (["--payload", "25", "--load-at", "3.9999"], ["change time", "last sample"]),
        (["--payload", "25", "--load-at", "1", "--drop-at", "2"], ["one change per run"]),
        (["--payload", "25", "--load-at", "1", "--friction-fault", "right:2", "--fault-at", "2"], ["one change"]),
        (["--friction-fault", "right:3"], ["--fault-at"]),
        (["--fault-at", "2"], ["--friction-fault"]),
        (["--friction-fault", "up:3", "--fault-at", "2"], ["WHEEL:FACTOR"]),
        (["--friction-fault", "right:x", "--fault-at", "2"], ["WHEEL:FACTOR"]),
        (["--friction-fault", "right:3:static", "--fault-at", "2"], ["WHEEL:FACTOR"]),
        (["--friction-fault", "right:1", "--fault-at", "2"], ["--friction-fault", "factor"]),
        (["--friction-fault", "left:-2", "--fault-at", "2"], ["--friction-fault", "factor"]),
    ],
)
def test_cli_bad_change_options_exit_2_with_one_line(tmp_path: Path, args: list[str], needles: list[str]) -> None:
    log = tmp_path / "bad.csv"
    assert_clean_error(wmrid("simulate", "-o", str(log), "--duration", "4", *args), 2, *needles)
    assert not log.exists()
    assert not Path(str(log) + ".truth.json").exists()


def test_cli_help_documents_the_change_options() -> None:
    proc = wmrid("simulate", "--help")
    assert proc.returncode == 0
    text = " ".join(proc.stdout.decode().split())
    for needle in ("--load-at", "--drop-at", "--friction-fault", "--fault-at", "WHEEL:FACTOR[:TERMS]"):
        assert needle in text, needle


def test_a_fault_on_a_friction_the_plant_lacks_is_refused_naming_the_flag(tmp_path: Path) -> None:
    """The plant is checked before the run: a Coulomb fault on a robot whose Coulomb friction is 0 changes nothing,
    and the line names the flag as given."""
    robot = tmp_path / "frictionless.toml"
    text = (ROOT_DIR / "examples" / "paper_robot.toml").read_text()
    robot.write_text(text.replace("F_d1 = 0.045", "F_d1 = 0.0"))  # the plant (the CAD set) without it
    log = tmp_path / "fault.csv"
    done = wmrid(
        "simulate", "-o", str(log), "--duration", "4", "--robot", str(robot), "--friction-fault", "right:3:coulomb",
        "--fault-at", "1",
    )  # fmt: skip
    assert_clean_error(done, 2, "--friction-fault right:3:coulomb: friction fault: F_d1", "are 0 in the plant")
    assert not log.exists()
