"""``simulate --reference``: the closed loop tracking a reference drive given as samples (t, v, omega) -- trajectory
kind 2, a table on the control grid (wmrid.sim.reference) -- on both engines, through the library and the command
line."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np
import pytest
from scipy.interpolate import CubicSpline

from tests.cliutil import assert_clean_error, wmrid
from wmrid.api.simulation import simulate as api_simulate
from wmrid.core.errors import UsageError
from wmrid.io.reference_files import write_reference
from wmrid.model.robot import BUILTIN_ROBOTS
from wmrid.sim.closed_loop import KIND, closed_loop_kernel, reference_state, reference_wheel_speeds
from wmrid.sim.reference import Reference, pack_table, reference_table
from wmrid.sim.simulate import GAINS, TRAJECTORY_PARAMETERS, SimulatedLog, simulate

PAPER = BUILTIN_ROBOTS["paper"]
TRUE = PAPER.cad
NOMINAL = PAPER.nominal
assert TRUE is not None
#: The built-in reversing trajectory sampled as a plan would be: 50 Hz over 20 s.
SAMPLE_RATE = 50.0
REVERSING_SECONDS = 20.0
#: A drive that starts and ends at rest: v = V sin^2(pi t / T), omega = W sin(2 pi t / T) sin^2(pi t / T).
REST_SECONDS, REST_V, REST_W = 10.0, 0.5, 1.0


def _reversing_samples(rate: float = SAMPLE_RATE, duration: float = REVERSING_SECONDS) -> Reference:
    """v_r, w_r of the closed-form ``reversing`` at ``rate`` Hz, from :func:`reference_state` itself."""
    traj = np.array(list(TRAJECTORY_PARAMETERS["reversing"].values()))
    t = np.arange(round(duration * rate) + 1) / rate
    state = np.array([reference_state(KIND["reversing"], traj, s, 0.0, 0.0) for s in t])
    return Reference.from_arrays(t, state[:, 3], state[:, 4])


def _at_rest_columns(rate: float = SAMPLE_RATE) -> dict[str, np.ndarray]:
    t = np.arange(round(REST_SECONDS * rate) + 1) / rate
    s2 = np.sin(np.pi * t / REST_SECONDS) ** 2
    return {"t": t, "v": REST_V * s2, "omega": REST_W * np.sin(2 * np.pi * t / REST_SECONDS) * s2}


@pytest.fixture(scope="module")
def reversing_pair() -> tuple[SimulatedLog, SimulatedLog]:
    """The built-in reversing run and the run on its 50 Hz samples: both start on the reference with its speeds at
    t = 0 (the kernel puts the robot there), with the same seed, so they differ only by the reference's table."""
    builtin = simulate(TRUE, NOMINAL, trajectory="reversing", duration=REVERSING_SECONDS)
    tabled = simulate(TRUE, NOMINAL, reference=_reversing_samples())
    return builtin, tabled


@pytest.fixture(scope="module")
def at_rest() -> SimulatedLog:
    cols = _at_rest_columns()
    return simulate(TRUE, NOMINAL, reference=Reference.from_arrays(cols["t"], cols["v"], cols["omega"]))


# --------------------------------------------------------------------------------------------------- the table


def test_table_of_reversing_samples_matches_the_closed_form() -> None:
    """The spline through 50 Hz samples against the closed form on the 1 ms grid.  A cubic spline's error on a
    signal sampled every h is about h^4/384 |f''''| (value) and h^3/24 |f''''| (slope): h = 0.02 s and |w''''| =
    W (2 pi / 4.3)^4 = 3.6 rad/s^5 give 1.5e-9 rad/s and 1.2e-6 rad/s^2; the not-a-knot ends err up to ten times
    that in their last samples (observed: v 1.9e-9, w 1.3e-8, v' 6.1e-7, w' 4.2e-6).  The pose integrates those
    errors (phi 1.1e-9 rad, x, y 7e-10 m observed).  Tolerances: three to five times the observed."""
    traj = np.array(list(TRAJECTORY_PARAMETERS["reversing"].values()))
    period, n_rows = 1e-3, round(REVERSING_SECONDS / 1e-3) + 1
    table = reference_table(_reversing_samples(), period, n_rows)
    # the closed form's x_r, y_r come from the kernel's own quadrature: the built-in run's logged reference pose
    builtin = simulate(TRUE, NOMINAL, trajectory="reversing", duration=REVERSING_SECONDS)
    closed = np.array([reference_state(1, traj, k * period, 0.0, 0.0) for k in range(n_rows)])
    np.testing.assert_allclose(table[:, :2], builtin.reference[:, :2], rtol=0, atol=3e-9)
    for j, tol in zip(range(2, 7), (5e-9, 1e-8, 5e-8, 3e-6, 2e-5), strict=True):
        np.testing.assert_allclose(table[:, j], closed[:, j], rtol=0, atol=tol, err_msg=f"column {j}")
    assert table[0, :3].tolist() == [0.0, 0.0, 0.0]  # starts at the origin facing +x


def test_table_lookup_interpolates_between_rows() -> None:
    """On the grid a row is returned as it is; between rows, the straight line between the two (times off the
    control grid); before the first and after the last row the end rows."""
    rng = np.random.Generator(np.random.PCG64(5))
    table = rng.standard_normal((11, 7))
    traj = pack_table(table, 0.1)
    k = KIND["reference"]
    for i in range(11):
        np.testing.assert_array_equal(reference_state(k, traj, i * 0.1, 0.0, 0.0), table[i])
    got = np.array(reference_state(k, traj, 0.325, 0.0, 0.0))
    np.testing.assert_allclose(got, 0.75 * table[3] + 0.25 * table[4], rtol=0, atol=1e-14)
    np.testing.assert_array_equal(reference_state(k, traj, -1.0, 0.0, 0.0), table[0])
    np.testing.assert_array_equal(reference_state(k, traj, 5.0, 0.0, 0.0), table[-1])
    r, b = 0.16, 0.23
    eta = reference_wheel_speeds(k, traj, np.array([0.325]), r, b)[0]
    np.testing.assert_allclose(eta, [(got[3] + b * got[4]) / r, (got[3] - b * got[4]) / r], rtol=1e-14)


def test_compiled_kernel_on_a_table_matches_its_python_twin() -> None:
    """The table path run as plain Python (numba's py_func) against the compiled kernel, as for the built-ins."""
    ref = _reversing_samples(duration=1.0)
    log = simulate(TRUE, NOMINAL, reference=ref, duration=0.05)
    n = len(log.t)
    traj = pack_table(reference_table(ref, 1e-3, n), 1e-3)
    plant_args = closed_loop_inputs()
    args = (2, traj, *plant_args, 1e-3, 4, n, 1, np.zeros((n, 2)), 0.0, 0.3)
    py = closed_loop_kernel.py_func(*args)
    jit = closed_loop_kernel(*args)
    for a, b in zip(py, jit, strict=True):
        np.testing.assert_allclose(b, a, rtol=1e-12, atol=1e-12)
    np.testing.assert_array_equal(jit[0], log.pose)


def closed_loop_inputs() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(plant, ctrl, gains) vectors of the paper robot, as :func:`wmrid.sim.simulate.plan_run` builds them."""
    from wmrid.model import dynamics as model

    theta0 = model.base_parameters(TRUE)
    m = model.inverse_inertia(theta0)
    big = model.inertia_matrix(NOMINAL)
    plant = np.array([m[0, 0], m[0, 1], m[1, 1], *theta0[3:8], TRUE.r, TRUE.b])
    ctrl = np.array([big[0, 0], big[0, 1], big[1, 1], model.coriolis_coefficient(NOMINAL), NOMINAL.F_v1,
                     NOMINAL.F_v2, NOMINAL.F_d1, NOMINAL.F_d2, NOMINAL.r, NOMINAL.b])  # fmt: skip
    gains = np.array([GAINS[k] for k in ("k1", "k2", "k3", "K")])
    return plant, ctrl, gains


# --------------------------------------------------------------------------------------------------- reduced engine


def test_reversing_from_samples_drives_as_the_builtin(reversing_pair: tuple[SimulatedLog, SimulatedLog]) -> None:
    """Both runs start identically (the table's row 0 is the closed form at t = 0: a spline passes through its
    samples), so the runs differ by the table's errors alone, which the controller passes on: the reference pose
    (7e-10 m, 1.1e-9 rad observed), the pose it drives (the same), the wheel speeds (2.6e-8 rad/s: the reference's
    and their feed-forward slopes) and the torques, which carry M (v_r', w_r') and so the slope errors, 4e-6 rad/s^2
    at the ends, times the controller's gains (1.2e-5 N m observed).  Tolerances: ten times the observed."""
    builtin, tabled = reversing_pair
    assert len(tabled.t) == len(builtin.t)  # the duration defaults to the reference's, 20 s
    np.testing.assert_array_equal(tabled.t, builtin.t)
    np.testing.assert_allclose(tabled.reference, builtin.reference, rtol=0, atol=1e-8)
    np.testing.assert_allclose(tabled.pose, builtin.pose, rtol=0, atol=1e-8)
    np.testing.assert_allclose(tabled.wheel_angle, builtin.wheel_angle, rtol=0, atol=1e-8)
    np.testing.assert_allclose(tabled.eta, builtin.eta, rtol=0, atol=3e-7)
    np.testing.assert_allclose(tabled.eta_ref, builtin.eta_ref, rtol=0, atol=3e-7)
    np.testing.assert_allclose(tabled.tau, builtin.tau, rtol=0, atol=1.2e-4)


def test_settings_record_the_reference(reversing_pair: tuple[SimulatedLog, SimulatedLog]) -> None:
    _, tabled = reversing_pair
    s = tabled.settings
    assert s["trajectory"] == "reference"
    assert s["duration"] == REVERSING_SECONDS
    ref = _reversing_samples()
    params = s["trajectory_parameters"]
    assert params["file"] is None
    assert params["sha256"] == hashlib.sha256(ref.t.tobytes() + ref.v.tobytes() + ref.omega.tobytes()).hexdigest()
    assert params["samples"] == len(ref.t)
    json.dumps(tabled.truth())  # JSON-ready, as the truth file needs


def test_a_drive_from_rest_to_rest_is_tracked(at_rest: SimulatedLog) -> None:
    """v = V sin^2, omega = W sin(2 pi t / T) sin^2: the robot starts exactly at rest at the origin, follows the
    path within a millimetre and its wheels the reference's (v +/- b omega) / r within 0.3 % of their peak (3.6
    rad/s; observed 3.2e-3 rad/s, 0.33 mm, 2 mrad: near rest the controller has no authority over the heading, so
    the 2 mrad it lags while stopping stays), and stops."""
    log = at_rest
    assert log.settings["duration"] == REST_SECONDS
    assert len(log.t) == round(REST_SECONDS * 1000) + 1
    np.testing.assert_array_equal(log.pose[0], [0.0, 0.0, 0.0])
    np.testing.assert_array_equal(log.eta_true[0], [0.0, 0.0])
    assert np.hypot(*(log.reference[:, :2] - log.pose[:, :2]).T).max() < 1e-3
    assert np.abs(log.reference[:, 2] - log.pose[:, 2]).max() < 5e-3
    cols = _at_rest_columns()
    v = CubicSpline(cols["t"], cols["v"])(log.t)
    w = CubicSpline(cols["t"], cols["omega"])(log.t)
    want = np.c_[(v + TRUE.b * w) / TRUE.r, (v - TRUE.b * w) / TRUE.r]
    np.testing.assert_allclose(log.eta_true, want, rtol=0, atol=1e-2)
    assert np.abs(log.eta_true[-1]).max() < 1e-4  # stopped at the end


def test_a_shorter_duration_cuts_the_reference_and_a_longer_one_is_refused() -> None:
    ref = _reversing_samples(duration=2.0)
    short = simulate(TRUE, NOMINAL, reference=ref, duration=1.0, rate=100.0)
    assert short.t[-1] == pytest.approx(1.0)
    assert len(short.t) == 101
    with pytest.raises(UsageError, match=r"duration 3 s is longer than the reference \(2 s\)"):
        simulate(TRUE, NOMINAL, reference=ref, duration=3.0)
    with pytest.raises(UsageError, match="give one of them"):
        simulate(TRUE, NOMINAL, reference=ref, trajectory="reversing")
    with pytest.raises(UsageError, match="needs reference"):
        simulate(TRUE, NOMINAL, trajectory="reference")


def test_a_reference_not_starting_at_zero_starts_the_run(tmp_path: Path) -> None:
    """Times are counted from the reference's first sample: shifting the samples' clock changes nothing."""
    ref = _reversing_samples(duration=1.0)
    moved = Reference.from_arrays(ref.t + 100.0, ref.v, ref.omega)
    a = simulate(TRUE, NOMINAL, reference=ref, rate=100.0)
    b = simulate(TRUE, NOMINAL, reference=moved, rate=100.0)
    np.testing.assert_allclose(b.pose, a.pose, rtol=0, atol=1e-9)


@pytest.mark.parametrize("bad", [
    ({"t": [0.0, 1.0], "v": [0.0]}, "no 'omega'"),
    ((np.array([0.0, 1.0]), np.zeros(2), np.zeros(3)), "one length"),
    ((np.array([0.0, 0.0]), np.zeros(2), np.zeros(2)), "does not increase at sample 2"),
    ((np.array([0.0, 1.0]), np.array([0.0, np.nan]), np.zeros(2)), "v is NaN or infinite at sample 2"),
    ((np.array([0.0]), np.zeros(1), np.zeros(1)), "at least 2"),
    (42, "must be a file"),
], ids=["mapping", "lengths", "repeat", "nan", "one", "type"])  # fmt: skip
def test_library_reference_arrays_are_checked(bad: tuple) -> None:
    reference, needle = bad
    with pytest.raises(UsageError, match=needle):
        api_simulate("paper", trajectory=reference)


# --------------------------------------------------------------------------------------------------- MuJoCo engine


def test_mujoco_engine_tracks_a_reference_file(tmp_path: Path) -> None:
    """The multibody prototype on the first 4 s of the rest-to-rest drive, read from an MCAP file (about 2 s of
    wall time): it starts at rest, follows within 2 mm (observed 0.86 mm) and its wheels the reference's within
    0.02 rad/s (observed 6e-3: tyre creep and the casters' drag, which the reduced model lacks)."""
    path = tmp_path / "plan.mcap"
    write_reference(path, _at_rest_columns())
    run = api_simulate("paper", engine="mujoco", duration=4.0, trajectory=path)
    log = run.log
    assert log.settings["engine"] == "mujoco"
    assert log.settings["trajectory"] == "reference"
    assert log.settings["trajectory_parameters"]["sha256"] == hashlib.sha256(path.read_bytes()).hexdigest()
    assert len(log.t) == 4001
    np.testing.assert_allclose(log.eta_true[0], [0.0, 0.0], atol=1e-9)
    assert np.hypot(*(log.reference[:, :2] - log.pose[:, :2]).T).max() < 2e-3
    cols = _at_rest_columns()
    v = CubicSpline(cols["t"], cols["v"])(log.t)
    w = CubicSpline(cols["t"], cols["omega"])(log.t)
    want = np.c_[(v + TRUE.b * w) / TRUE.r, (v - TRUE.b * w) / TRUE.r]
    np.testing.assert_allclose(log.eta_true, want, rtol=0, atol=2e-2)


# --------------------------------------------------------------------------------------------------- command line


def test_cli_simulates_a_csv_reference(tmp_path: Path) -> None:
    plan = tmp_path / "plan.csv"
    cols = _at_rest_columns()
    write_reference(plan, {k: v[: round(2.0 * SAMPLE_RATE) + 1] for k, v in cols.items()})  # the first 2 s
    out = tmp_path / "drive.csv"
    proc = wmrid("simulate", "-o", out, "--reference", plan, "--rate", "100")
    assert proc.returncode == 0, proc.stderr.decode()
    assert "(201 samples)" in " ".join(proc.stderr.decode().split())  # rich wraps the line at 100 columns
    import pandas as pd

    frame = pd.read_csv(out)
    assert len(frame) == 201
    assert frame["t"].iloc[-1] == pytest.approx(2.0)
    truth = json.loads(Path(str(out) + ".truth.json").read_text())
    settings = truth["settings"]
    assert settings["trajectory"] == "reference"
    assert settings["trajectory_parameters"]["file"] == str(plan)
    assert settings["trajectory_parameters"]["sha256"] == hashlib.sha256(plan.read_bytes()).hexdigest()
    # the same reference through the library, bit for bit
    again = api_simulate("paper", rate=100.0, trajectory=plan)
    np.testing.assert_array_equal(frame["x"].to_numpy(), again.log.pose[:, 0])


def test_cli_refuses_bad_reference_use(tmp_path: Path) -> None:
    plan = tmp_path / "plan.csv"
    write_reference(plan, _at_rest_columns())
    out = str(tmp_path / "drive.csv")
    assert_clean_error(
        wmrid("simulate", "-o", out, "--reference", plan, "--trajectory", "reversing"),
        2, "--reference and --trajectory reversing", "give one of them",
    )  # fmt: skip
    assert_clean_error(
        wmrid("simulate", "-o", out, "--reference", plan, "--duration", "12"),
        2, "--duration 12 s is longer than the reference", str(plan), "(10 s)",
    )  # fmt: skip
    assert_clean_error(wmrid("simulate", "-o", out, "--reference", tmp_path / "nowhere.csv"), 2, "does not exist")
    bad = tmp_path / "bad.csv"
    bad.write_text("t,v\n0,0\n1,0\n")
    assert_clean_error(wmrid("simulate", "-o", out, "--reference", bad), 2, str(bad), "no column 'omega'")
    assert_clean_error(
        wmrid("simulate", "-o", out, "--reference-topic", "/cmd_vel"), 2, "--reference-topic needs --reference"
    )
    assert_clean_error(wmrid("simulate", "-o", plan, "--reference", plan, "--force"), 2, "it is the input")
    assert not Path(out).exists()
