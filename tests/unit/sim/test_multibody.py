"""Tests of the multibody prototype (wmrid.sim.multibody, ``wmrid simulate --engine mujoco``).

MuJoCo derives the robot's motion from bodies, joints and contacts; it knows nothing of Eqs. 9-14.  So
agreement with the reduced simulator, and a torque balance of the engine's own motion against
wmrid.model.dynamics, check those equations independently.  Every simulation here is at most 10 s at 1 kHz (about
1 s of wall time); the runs several tests share are module fixtures.
"""

from __future__ import annotations

import dataclasses
import json
import sys
from pathlib import Path

import mujoco
import numpy as np
import pandas as pd
import pytest

from wmrid.cli.app import main
from wmrid.core.errors import RobotFileError, UsageError
from wmrid.model import dynamics as model, torques
from wmrid.model.robot import BUILTIN_ROBOTS, Caster, Payload, PhysicalParameters, default_casters
from wmrid.model.robot_file import load_robot, robot_from_toml_text, robot_to_toml
from wmrid.sim import multibody as multibody_module
from wmrid.sim.multibody import simulate_multibody
from wmrid.sim.multibody_model import GRAVITY, INSTALL_HINT, MultibodySettings
from wmrid.sim.scenario import NoiseSettings
from wmrid.sim.simulate import _encoder_velocity, simulate

PAPER = BUILTIN_ROBOTS["paper"]
CAD = PAPER.cad
NOMINAL = PAPER.nominal
assert CAD is not None
H = 1e-3  # log period = control period at 1 kHz, s
FRICTIONLESS = MultibodySettings(caster_resistance=0.0)
PAYLOAD = Payload(mass=20.0, x=0.1, y=-0.05, inertia=0.3)


def weight(p: PhysicalParameters) -> float:
    """m g of the whole robot (platform, two wheels, two rotors), N."""
    return GRAVITY * (p.m_p + 2.0 * p.m_w + 2.0 * p.m_r)


def torque_residual(eta: np.ndarray, tau: np.ndarray, p: PhysicalParameters) -> np.ndarray:
    """tau[k] - (M (eta[k+1] - eta[k]) / h + V + F_v eta + F_d sgn eta at the midpoint), (n - 1, 2), N m.

    The torque is held over [t_k, t_k + h], so integrating Eq. (9) over that period gives EXACTLY
    M (eta[k+1] - eta[k]) / h = tau[k] - (mean over the period of V(eta) + F_v eta + F_d sgn eta): M is
    constant, so the average acceleration carries no discretisation error.  Only the mean of the velocity
    terms is approximated, by their value at the midpoint speed, an O(h^2) error (about 1e-6 N m on this
    robot, checked below on the reduced simulator's log, whose plant is Eq. (9) itself).
    """
    theta0 = model.base_parameters(p)
    acc = np.diff(eta, axis=0) / H
    mid = 0.5 * (eta[1:] + eta[:-1])
    return tau[:-1] - torques.wheel_torque(mid, acc, theta0)


def cli(capsys, *args: str) -> tuple[int, str, str]:
    """``wmrid ARGS`` in this process: (exit code, stdout, stderr)."""
    capsys.readouterr()
    with pytest.raises(SystemExit) as exc:
        main(list(args))
    captured = capsys.readouterr()
    return exc.value.code, captured.out, captured.err


def one_line_error(code: int, out: str, err: str, *needles: str) -> str:
    """Exit 2, nothing on stdout, exactly one stderr line (no traceback) holding every needle."""
    assert code == 2, err
    assert out == ""
    assert "Traceback" not in err
    lines = err.strip().splitlines()
    assert len(lines) == 1, err
    for needle in needles:
        assert needle in lines[0], (needle, lines[0])
    return lines[0]


@pytest.fixture(scope="module")
def frictionless():
    """10 s of the sinusoid on the multibody paper robot (CAD plant, nominal controller), frictionless casters."""
    return simulate_multibody(CAD, NOMINAL, settings=FRICTIONLESS, trajectory="sinusoid", duration=10.0)


@pytest.fixture(scope="module")
def reduced():
    """The same run on the reduced model (Eqs. 9-14, RK4)."""
    return simulate(CAD, NOMINAL, trajectory="sinusoid", duration=10.0)


@pytest.fixture(scope="module")
def resisting():
    """3 s as ``frictionless`` but with caster rolling resistance 0.05."""
    return simulate_multibody(CAD, NOMINAL, settings=MultibodySettings(caster_resistance=0.05), duration=3.0)


@pytest.fixture(scope="module")
def clean_short():
    """1 s with the default settings, seed 0, no noise."""
    return simulate_multibody(CAD, NOMINAL, duration=1.0)


@pytest.fixture(scope="module")
def default_run():
    """3 s with the default settings (floor friction 1, the casters' own resistance 0.015)."""
    return simulate_multibody(CAD, NOMINAL, duration=3.0)


# --- 1. agreement with the reduced model ---------------------------------------------------------------------


def test_multibody_agrees_with_the_reduced_model(frictionless, reduced):
    """The engine's closed loop follows the reduced model's: speeds within 1e-3 of their peak, torques within
    3e-3 of theirs, the pose within 2 mm and 2 mrad, over 10 s.

    Measured (MuJoCo 4.0.0, 10 s): max |d eta| = 0.0037 rad/s (5.0e-4 of the 7.46 rad/s peak), max |d tau| =
    0.018 N m (1.1e-3 of the 16.0 N m peak), pose 0.15 mm in x, 0.41 mm in y, 0.84 mrad in phi; over 40 s
    0.0041 rad/s and 0.020 N m.  The tolerances are about twice those.  With frictionless casters and no
    disturbance the engine's only physics outside Eqs. 9-14 is what remains: the soft (compliant) contacts
    (the tyres creep by ~2e-5 m/s and sink a few micrometres), the platform's pitch and roll compliance on
    the sprung caster with its centre of mass 5 cm above the axle (load transfer), the start on the reference
    after settling, and the integrators (MuJoCo's implicit-in-velocity 0.25 ms step against four RK4
    substeps per 1 ms).  A wrong term of M, V_c or the friction in either would show up far above this:
    the nominal parameters, 18-37 % off, leave a torque residual of 3 N m (next test).
    """
    assert frictionless.t.shape == reduced.t.shape
    np.testing.assert_array_equal(frictionless.t, reduced.t)
    np.testing.assert_array_equal(frictionless.reference, reduced.reference)  # the same reference, sample for sample
    assert frictionless.true == reduced.true == CAD
    eta_peak = np.abs(reduced.eta_true).max()
    tau_peak = np.abs(reduced.tau).max()
    assert eta_peak > 7.0  # the run is the paper's, with real excitation
    assert tau_peak > 15.0
    assert np.abs(frictionless.eta_true - reduced.eta_true).max() <= 1e-3 * eta_peak
    assert np.abs(frictionless.tau - reduced.tau).max() <= 3e-3 * tau_peak
    d_pose = np.abs(frictionless.pose - reduced.pose).max(axis=0)
    assert d_pose[0] <= 2e-3, d_pose  # x, m
    assert d_pose[1] <= 2e-3, d_pose  # y, m
    assert d_pose[2] <= 2e-3, d_pose  # phi, rad
    assert frictionless.settings["engine"] == "mujoco"
    assert frictionless.settings["multibody"]["engine"].startswith("mujoco ")


# --- 2. an independent check of M -------------------------------------------------------------------------------


def test_engine_motion_balances_eq9_with_the_true_inertia_matrix(frictionless, reduced):
    """Eq. (9) with the CAD robot's M, V_c and friction balances the engine's torque to within 2e-3 of the
    peak torque, after the first 50 ms, and least squares on the engine's motion returns M11, M12, M22 and
    V_c within 1 % of Eqs. 10-14.

    The residual is computed exactly as the torque is held (see :func:`torque_residual`); on the reduced
    simulator's own log it is 1.2e-6 N m (the midpoint rule), so what remains on the engine's log is
    physics.  Measured: 0.013 N m after 50 ms (7.8e-4 of the 16 N m peak, against inertial torques
    M eta' up to 11 N m and Coriolis torques up to 7 N m); 0.095 N m at t = 0, decaying within a few ms,
    while the contacts re-settle after the robot is put on the reference with its speeds (hence the whole
    run's bound of 1 % of the peak).  Least squares (friction known) finds M and V_c within 0.16 %; the
    nominal parameters, 18-37 % off, leave a residual of 2.8-3.7 N m, about 90 times the tolerance (asserted:
    50 times), so the check has the power to see a wrong M.
    """
    exact = torque_residual(reduced.eta_true, reduced.tau, CAD)
    assert np.abs(exact).max() < 1e-5  # the method itself is exact to O(h^2)

    eta, tau = frictionless.eta_true, frictionless.tau
    tau_peak = np.abs(tau).max()
    residual = torque_residual(eta, tau, frictionless.true)
    assert np.abs(residual).max() <= 1e-2 * tau_peak
    assert np.abs(residual[50:]).max() <= 2e-3 * tau_peak
    wrong = PAPER.nominal.replace(F_v1=CAD.F_v1, F_v2=CAD.F_v2, F_d1=CAD.F_d1, F_d2=CAD.F_d2)
    assert np.abs(torque_residual(eta, tau, wrong)[50:]).max() >= 50 * 2e-3 * tau_peak

    # Least squares for (M11, M12, M22, Vc) with the friction known: the engine's own inertia matrix.
    theta0 = model.base_parameters(CAD)
    acc = np.diff(eta, axis=0)[50:] / H
    mid = (0.5 * (eta[1:] + eta[:-1]))[50:]
    rhs = (tau[:-1][50:] - torques.friction_torque(mid, theta0)).ravel()  # rows tau_1, tau_2, tau_1, ...
    e1, e2 = mid[:, 0], mid[:, 1]
    zero = np.zeros_like(e1)
    rows_1 = np.stack([acc[:, 0], acc[:, 1], zero, e1 * e2 - e2 * e2], axis=1)
    rows_2 = np.stack([zero, acc[:, 0], acc[:, 1], e1 * e2 - e1 * e1], axis=1)
    design = np.stack([rows_1, rows_2], axis=1).reshape(-1, 4)
    fit = np.linalg.lstsq(design, rhs, rcond=None)[0]
    big_m = model.inertia_matrix(CAD)
    truth = np.array([big_m[0, 0], big_m[0, 1], big_m[1, 1], model.coriolis_coefficient(CAD)])
    np.testing.assert_allclose(fit, truth, rtol=1e-2)


def test_mean_caster_load_is_the_static_moment_balance(frictionless):
    """With frictionless casters the platform's weight ahead of the axle rests on the front caster: its mean
    normal load is m g x_G / x_c (the first moment of the mass about the axle over the caster's reach), within
    4 %.

    Two wheels on the axle and two casters on the centre line are statically indeterminate, but with the
    centre of mass 15 cm ahead of the axle the rear caster stays off the ground (its mean load is 0), so the
    front one carries exactly the moment about the axle.  Measured: 201.9 N against 199.3 N (1.3 %, the
    difference from pitching under acceleration).  The engine knows the mass distribution only from the
    bodies built from Table 1, so this checks that build (d_x, the rotors' c_x, the masses) independently
    of Eqs. 10-14.
    """
    casters = frictionless.settings["multibody"]["casters"]
    moment = GRAVITY * (CAD.m_p * CAD.d_x + 2.0 * CAD.m_r * CAD.c_x)
    front = default_casters(CAD)[0]
    assert casters[0]["x"] == front.x > 0
    assert casters[0]["mean_normal_load"] == pytest.approx(moment / front.x, rel=0.04)
    assert casters[1]["mean_normal_load"] >= 0.0


def test_each_casters_load_is_logged(frictionless):
    """``caster_load`` holds each caster's normal force at every logged sample: read-only, never negative, its mean
    the truth's ``mean_normal_load``."""
    load = frictionless.caster_load
    casters = frictionless.settings["multibody"]["casters"]
    assert load.shape == (len(frictionless.t), len(casters))
    assert not load.flags.writeable
    assert np.all(load >= 0.0)
    np.testing.assert_allclose(load.mean(axis=0), [c["mean_normal_load"] for c in casters], rtol=1e-12, atol=1e-9)


# --- 3. payload -------------------------------------------------------------------------------------------------


def test_payload_is_carried_by_the_engine(frictionless):
    """A payload carried throughout: the log's truth is ``cad.with_payload(payload)``, and the engine moves
    that heavier robot.

    * Eq. (9) with the LOADED truth balances the torque within 3e-3 of the peak (measured 0.016 N m,
      1.1e-3 of 14.6 N m); with the unloaded truth it is off by 1.95 N m (120 times more; asserted 30): the engine's
      inertia is the loaded one.
    * More mass needs more torque for the same reference: the RMS wheel torques rise from 5.69/6.71 N m
      to 6.55/7.52 N m (asserted: by more than 5 %).
    * The front caster's mean load follows the new first moment (payload 10 cm ahead of the axle):
      240.8 N against the static 236.0 N (asserted within 4 %, as in the unloaded test).
    """
    loaded = simulate_multibody(CAD, NOMINAL, settings=FRICTIONLESS, duration=3.0, payload=PAYLOAD)
    assert loaded.true == CAD.with_payload(PAYLOAD)
    unloaded_tau = frictionless.tau[: len(loaded.t)]  # the same run unloaded (its first 3 s; see the determinism test)

    tau_peak = np.abs(loaded.tau).max()
    right = torque_residual(loaded.eta_true, loaded.tau, loaded.true)[50:]
    wrong = torque_residual(loaded.eta_true, loaded.tau, CAD)[50:]
    assert np.abs(right).max() <= 3e-3 * tau_peak
    assert np.abs(wrong).max() >= 30 * np.abs(right).max()

    rms_loaded = np.sqrt(np.mean(loaded.tau**2, axis=0))
    rms_unloaded = np.sqrt(np.mean(unloaded_tau**2, axis=0))
    assert np.all(rms_loaded > 1.05 * rms_unloaded), (rms_loaded, rms_unloaded)

    p = loaded.true
    moment = GRAVITY * (p.m_p * p.d_x + 2.0 * p.m_r * p.c_x)
    front = loaded.settings["multibody"]["casters"][0]
    assert front["mean_normal_load"] == pytest.approx(moment / front["x"], rel=0.04)


def test_payload_truth_via_the_cli(tmp_path, capsys):
    """``wmrid simulate --engine mujoco --payload`` writes the LOADED robot as the truth (exactly, from JSON)."""
    log = tmp_path / "loaded.csv"
    code, _, err = cli(
        capsys, "simulate", "-o", str(log), "--engine", "mujoco", "--duration", "1",
        "--payload", "20@0.1,-0.05", "--payload-inertia", "0.3",
    )  # fmt: skip
    assert code == 0, err
    truth = json.loads(Path(str(log) + ".truth.json").read_text())
    loaded = CAD.with_payload(PAYLOAD)
    assert truth["physical"] == loaded.to_dict()
    assert truth["parameters"] == pytest.approx(model.named_base(model.base_parameters(loaded)), rel=1e-12)
    assert truth["payload"] == {"mass": 20.0, "x": 0.1, "y": -0.05, "inertia": 0.3}
    assert truth["settings"]["engine"] == "mujoco"


# --- 4. caster resistance ---------------------------------------------------------------------------------------


def test_caster_resistance_costs_torque(frictionless, resisting):
    """Caster rolling resistance 0.05 against 0: the wheels need more torque, about r x (resistance x caster
    load); the settings record what was used; the casters' mean loads are positive (the rear one is 0 without
    resistance) and together less than the weight.

    Measured over 3 s: mean torque rise 0.42 N m (right) and 1.02 N m (left); their sum over r is 9.0 N,
    0.89 of the drag 0.05 x 203 N the front caster's mean load implies (less than 1, as the ball's drag points
    against its contact's velocity, not always straight back).  Asserted: both rises > 0.2 N m, the ratio in
    [0.6, 1.1].  Caster loads: 203 N and 0 N with and without resistance (the rear ball is off the ground, the
    centre of mass being 15 cm ahead of the axle; see the static-balance test), less than the 696 N weight.
    """
    n = len(resisting.t)
    rise = (resisting.tau - frictionless.tau[:n]).mean(axis=0)
    assert np.all(rise > 0.2), rise
    assert np.abs(resisting.tau - frictionless.tau[:n]).max() > 1.0

    w = weight(CAD)
    for run, used in ((frictionless, 0.0), (resisting, 0.05)):
        casters = run.settings["multibody"]["casters"]
        assert len(casters) == 2
        assert all(c["resistance_used"] == used for c in casters)
        assert all(c["resistance"] == 0.015 for c in casters)  # the robot's own value, overridden
        loads = [c["mean_normal_load"] for c in casters]
        assert loads[0] > 0.0, loads
        assert loads[1] >= 0.0, loads
        assert sum(loads) < w, (loads, w)
        assert run.settings["multibody"]["caster_resistance"] == used
    loads = [c["mean_normal_load"] for c in resisting.settings["multibody"]["casters"]]
    drag = 0.05 * sum(loads)
    assert 0.6 <= rise.sum() / CAD.r / drag <= 1.1, (rise, drag)


def test_caster_resistance_does_not_move_the_weight_off_the_wheels(frictionless, resisting):
    """A drag of 0.05 x ~200 N on the front caster can shift at most a few newtons of load between wheels and
    casters (its moment, ~10 N x 0.2 m, over the caster's 0.53 m reach).  So the casters' total mean load
    should differ from its frictionless value by less than 10 % of the weight (the module's docstring: the
    sprung casters let "the driven wheels keep most of the load and their traction").

    With the drag as MuJoCo contact friction on the sliding sphere, the contacts chattered: 436 N on the casters
    (202 N frictionless) and wheel loads down to 0; the drag is now an applied force on a frictionless contact.
    """
    total = [
        sum(c["mean_normal_load"] for c in run.settings["multibody"]["casters"]) for run in (frictionless, resisting)
    ]
    assert abs(total[1] - total[0]) <= 0.1 * weight(CAD), total


# --- 5. floor friction ------------------------------------------------------------------------------------------


def test_low_floor_friction_lets_the_wheels_slip(default_run):
    """Floor friction 0.05 against the default 1.0: the largest slip speed (body speed minus the wheels'
    rim speed) is over 1 m/s against under 0.1 m/s, and at least 50 times larger.

    Measured over 3 s: 6.1 m/s at 0.05 (the controller spins the wheels up, the robot cannot follow),
    2.4e-5 m/s at 1.0.
    """
    slippery = simulate_multibody(CAD, NOMINAL, settings=MultibodySettings(floor_friction=0.05), duration=3.0)
    assert slippery.settings["multibody"]["floor_friction"] == 0.05
    grip = default_run.settings["multibody"]["max_slip_speed"]
    slip = slippery.settings["multibody"]["max_slip_speed"]
    assert grip < 0.1, grip
    assert slip > 1.0, slip
    assert slip > 50 * grip


# --- 6. torque limit --------------------------------------------------------------------------------------------


def test_torque_limit_clips_every_logged_torque():
    """--torque-limit 2: every logged |tau| <= 2 N m (the applied, clipped torque is logged), and the limit
    binds (measured: 95 % of the samples sit at +-2 N m, as the paper robot needs up to 16 N m)."""
    clipped = simulate_multibody(CAD, NOMINAL, settings=MultibodySettings(torque_limit=2.0), duration=3.0)
    assert np.abs(clipped.tau).max() <= 2.0
    assert np.mean(np.abs(clipped.tau) == 2.0) > 0.5
    assert clipped.settings["multibody"]["torque_limit"] == 2.0


@pytest.mark.parametrize(
    "options",
    [{"floor_friction": 0.0}, {"floor_friction": -1.0}, {"caster_resistance": -0.1}, {"torque_limit": 0.0},
     {"substeps": 0}, {"floor_friction": float("nan")}],
)  # fmt: skip
def test_bad_multibody_settings_are_usage_errors(options):
    with pytest.raises(UsageError):
        MultibodySettings(**options)


# --- 7. determinism and noise -----------------------------------------------------------------------------------

ARRAYS = ("t", "eta", "tau", "pose", "wheel_angle", "reference", "disturbance", "eta_true")


def assert_same_log(a, b) -> None:
    for name in ARRAYS:
        np.testing.assert_array_equal(getattr(a, name), getattr(b, name), err_msg=name)


def test_same_seed_same_log_bit_for_bit(frictionless, default_run, clean_short):
    """Two runs with the same seed and noise are identical bit for bit; another seed differs; a shorter
    noise-free run is the longer one's first samples bit for bit (the loop is causal, which the payload and
    caster tests rely on)."""
    noise = NoiseSettings(eta_std=0.01, tau_std=0.05, caster_std=0.05)
    a = simulate_multibody(CAD, NOMINAL, duration=1.0, noise=noise, seed=7)
    b = simulate_multibody(CAD, NOMINAL, duration=1.0, noise=noise, seed=7)
    assert_same_log(a, b)
    assert a.settings == b.settings
    c = simulate_multibody(CAD, NOMINAL, duration=1.0, noise=noise, seed=8)
    assert not np.array_equal(a.eta, c.eta)
    assert not np.array_equal(a.disturbance, c.disturbance)

    short = simulate_multibody(CAD, NOMINAL, settings=FRICTIONLESS, duration=3.0)
    n = len(short.t)
    for name in ARRAYS:
        np.testing.assert_array_equal(getattr(short, name), getattr(frictionless, name)[:n], err_msg=name)
    n = len(a.t)
    for name in ARRAYS:
        np.testing.assert_array_equal(getattr(clean_short, name), getattr(default_run, name)[:n], err_msg=name)


def test_noise_is_that_of_the_reduced_simulator(clean_short):
    """Measurement noise enters the log only, from the same streams as the reduced simulator's; the caster
    disturbance is the same Ornstein-Uhlenbeck sequence and enters the plant; encoder quantisation likewise.

    Exact (bit for bit) where the arithmetic is the same: log = true + std x the seed's standard normals
    (drawn eta, then tau, then the disturbance's innovations).
    """
    seed, n = 3, 1001
    clean = clean_short
    noisy = simulate_multibody(CAD, NOMINAL, duration=1.0, noise=NoiseSettings(eta_std=0.01, tau_std=0.05), seed=seed)
    rng = np.random.Generator(np.random.PCG64(seed))
    eta_z = rng.standard_normal((n, 2))
    tau_z = rng.standard_normal((n, 2))
    for name in ("eta_true", "pose", "wheel_angle", "reference"):  # the plant never saw the noise
        np.testing.assert_array_equal(getattr(noisy, name), getattr(clean, name), err_msg=name)
    np.testing.assert_array_equal(noisy.eta, clean.eta_true + 0.01 * eta_z)
    np.testing.assert_array_equal(noisy.tau, clean.tau + 0.05 * tau_z)
    np.testing.assert_array_equal(noisy.disturbance, 0.0)
    reduced_noisy = simulate(CAD, NOMINAL, duration=1.0, noise=NoiseSettings(eta_std=0.01, tau_std=0.05), seed=seed)
    np.testing.assert_array_equal(reduced_noisy.eta, reduced_noisy.eta_true + 0.01 * eta_z)  # the same rule there

    caster = NoiseSettings(caster_std=0.2, caster_time=0.3)
    disturbed = simulate_multibody(CAD, NOMINAL, duration=1.0, noise=caster, seed=seed)
    reduced_disturbed = simulate(CAD, NOMINAL, duration=1.0, noise=caster, seed=seed)
    np.testing.assert_array_equal(disturbed.disturbance, reduced_disturbed.disturbance)
    assert np.abs(disturbed.disturbance).max() > 0.1
    np.testing.assert_array_equal(disturbed.eta, disturbed.eta_true)  # not a measurement noise
    assert not np.array_equal(disturbed.eta_true, clean.eta_true)  # but a torque on the plant
    assert disturbed.settings["noise"] == reduced_disturbed.settings["noise"] == caster.to_dict()

    cpr = 4096
    quantised = simulate_multibody(CAD, NOMINAL, duration=1.0, noise=NoiseSettings(encoder_cpr=cpr))
    counts = quantised.eta * H / (2.0 * np.pi / cpr)
    np.testing.assert_allclose(counts, np.round(counts), atol=1e-6)
    np.testing.assert_array_equal(quantised.eta, _encoder_velocity(quantised.wheel_angle, quantised.eta_true, cpr, H))
    assert np.abs(quantised.eta - quantised.eta_true).max() <= 2.0 * np.pi / cpr / H + 0.05


# --- 8. casters in robot files ----------------------------------------------------------------------------------

CASTER_TABLES = """
[[caster]]
x = 0.45
kind = "swivel"
radius = 0.04
trail = 0.04
resistance = 0.01

[[caster]]
x = -0.5
y = 0.0
kind = "ball"
radius = 0.03
resistance = 0.02
"""


#: The paper robot without its built-in casters, for robot files that list their own.
BARE_PAPER = dataclasses.replace(PAPER, casters=None)


def paper_file(extra: str) -> str:
    """The paper robot's TOML (no casters) with ``extra`` appended (after [cad]: so [[caster]] tables, not
    top-level keys)."""
    return robot_to_toml(BARE_PAPER) + extra


def test_robot_file_casters_parse_and_round_trip(tmp_path):
    robot = robot_from_toml_text(paper_file(CASTER_TABLES), "casters.toml")
    assert robot.casters == (
        Caster(x=0.45, kind="swivel", radius=0.04, trail=0.04, resistance=0.01),
        Caster(x=-0.5, y=0.0, kind="ball", radius=0.03, resistance=0.02),
    )
    assert robot.cad == CAD
    assert robot.nominal == NOMINAL
    assert robot_from_toml_text(robot_to_toml(robot), "again.toml") == robot
    path = tmp_path / "casters.toml"
    path.write_text(robot_to_toml(robot), encoding="utf-8")
    assert load_robot(str(path)) == robot
    assert robot_from_toml_text(robot_to_toml(BARE_PAPER), "none.toml").casters is None
    assert robot_from_toml_text(robot_to_toml(PAPER), "builtin.toml") == PAPER  # the built-in casters round-trip


@pytest.mark.parametrize(
    ("tables", "needles"),
    [
        ("[[caster]]\nx = 0.5\nwheel_radius = 0.03\n", ("[[caster]] 1", "unknown key(s) wheel_radius", "known:")),
        (
            '[[caster]]\nx = 0.5\n[[caster]]\nx = -0.5\nkind = "omni"\n',
            ("[[caster]] 2", "kind", "ball, swivel", "omni"),
        ),
        ("[[caster]]\ny = 0.1\n", ("[[caster]] 1", "needs x")),
        ("[[caster]]\nx = 0.5\nradius = -0.02\n", ("[[caster]] 1", "radius")),
        ('[[caster]]\nx = "front"\n', ("[[caster]] 1", "x")),
        ("caster = 3\n", ("[[caster]] tables",)),  # a top-level key, not tables
        ("caster = [1, 2]\n", ("[[caster]] tables",)),
    ],
)
def test_bad_caster_tables_are_one_line_robot_file_errors(tables, needles):
    with pytest.raises(RobotFileError) as exc:
        robot_from_toml_text(
            paper_file("\n" + tables) if tables.startswith("[[") else tables + robot_to_toml(BARE_PAPER), "bad.toml"
        )
    message = str(exc.value)
    assert "\n" not in message
    assert message.startswith("bad.toml")
    for needle in needles:
        assert needle in message, (needle, message)


def test_swivel_caster_robot_runs_and_stays_on_the_ground(monkeypatch):
    """A robot file with a swivel caster in front and a ball behind simulates 3 s; the platform's origin O
    stays at the wheel-centre height r within 2 mm at every engine step (measured: 3 micrometres below, the
    contacts' compliance), and the swivel caster carries load (measured 278 N mean, the ball 0 N: the
    centre of mass is ahead of the axle).  The platform's height is read from the engine itself, through a
    wrapper of mujoco.mj_step.
    """
    robot = robot_from_toml_text(paper_file(CASTER_TABLES), "casters.toml")
    heights = []

    class RecordingMujoco:
        def __getattr__(self, name):
            return getattr(mujoco, name)

        def mj_step(self, m, d, nstep=1):
            mujoco.mj_step(m, d, nstep)
            heights.append(d.qpos[m.jnt_qposadr[m.joint("base").id] + 2])

    monkeypatch.setattr(multibody_module, "import_mujoco", RecordingMujoco)
    sim = simulate_multibody(robot.cad, robot.nominal, casters=robot.casters, duration=3.0)
    assert len(heights) == 1 + 3000 * 4  # the settling, then one call per engine step (the ball drag is per step)
    z = np.array(heights)
    assert np.abs(z - CAD.r).max() <= 2e-3, (z.min(), z.max())
    casters = sim.settings["multibody"]["casters"]
    assert [c["kind"] for c in casters] == ["swivel", "ball"]
    assert casters[0]["mean_normal_load"] > 0.25 * weight(CAD)
    assert np.abs(sim.pose[:, :2] - sim.reference[:, :2]).max() < 0.01  # still tracking: within 1 cm


def test_a_robot_that_cannot_stand_is_an_error():
    """With no caster the paper robot (centre of mass 15 cm ahead of the axle) cannot stand on its two wheels.
    Measured: |tau| > 100 N m from t = 0.01 s, 1.2e10 N m and 2.7e5 rad/s by 2.2 s, where MuJoCo resets the
    state to the origin (the pose jumps 35 m); the loop's check (NaN speed, |z| > 10 r + 1 m) first fires at
    2.324 s.  Now refused at once; a platform that tips (tilt > 0.3 rad) or a MuJoCo bad-acceleration warning
    also stops the run with a UsageError.
    """
    with pytest.raises(UsageError):
        simulate_multibody(CAD, NOMINAL, casters=(), duration=1.0)


# --- 9. the command line ----------------------------------------------------------------------------------------


def test_cli_simulate_mujoco_writes_a_log_that_identifies(tmp_path, capsys):
    """``wmrid simulate --engine mujoco`` writes the log and its truth (engine mujoco); ``wmrid identify`` reads
    it (exit 0) and finds M within 15 % of the truth from these 2 s (measured: M11 1.7 %, M12 0.3 %,
    M22 5.8 %, with the default casters' unmodelled drag and no noise; the friction terms absorb that drag
    and are not checked)."""
    log = tmp_path / "mb.csv"
    code, out, err = cli(capsys, "simulate", "-o", str(log), "--engine", "mujoco", "--duration", "2")
    assert code == 0, err
    assert out == ""
    assert "wrote" in err
    frame = pd.read_csv(log)
    assert len(frame) == 2001
    assert {"t", "eta_r", "eta_l", "tau_r", "tau_l"} <= set(frame.columns)
    truth = json.loads(Path(str(log) + ".truth.json").read_text())
    assert truth["settings"]["engine"] == "mujoco"
    assert truth["settings"]["multibody"]["engine"].startswith("mujoco ")
    assert truth["physical"] == CAD.to_dict()
    assert truth["robot"] == "paper"

    code, out, err = cli(capsys, "identify", str(log), "--robot", "paper", "--format", "json")
    assert code == 0, err
    result = json.loads(out)
    for name in ("M11", "M12", "M22"):
        value = result["parameters"][name]["value"]
        assert value == pytest.approx(truth["parameters"][name], rel=0.15), name
    assert all(np.isfinite(entry["value"]) for entry in result["parameters"].values())


@pytest.mark.parametrize(
    "option", [("--floor-friction", "0.5"), ("--caster-resistance", "0.02"), ("--torque-limit", "5")]
)
def test_cli_multibody_options_need_the_mujoco_engine(tmp_path, capsys, option):
    log = tmp_path / "reduced.csv"
    code, out, err = cli(capsys, "simulate", "-o", str(log), "--duration", "1", *option)
    one_line_error(code, out, err, option[0], "--engine mujoco")
    assert list(tmp_path.iterdir()) == []


# --- 10. MuJoCo missing -----------------------------------------------------------------------------------------


def test_missing_mujoco_says_how_to_install_it(tmp_path, capsys, monkeypatch):
    """``sys.modules["mujoco"] = None`` makes ``import mujoco`` raise ImportError, as on a machine without it."""
    monkeypatch.setitem(sys.modules, "mujoco", None)
    log = tmp_path / "mb.csv"
    code, out, err = cli(capsys, "simulate", "-o", str(log), "--engine", "mujoco", "--duration", "1")
    one_line_error(code, out, err, "pip install", "--engine mujoco")
    assert list(tmp_path.iterdir()) == []
    with pytest.raises(UsageError, match="pip install") as exc:
        simulate_multibody(CAD, NOMINAL, duration=1.0)
    assert str(exc.value) == INSTALL_HINT
