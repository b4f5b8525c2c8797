"""Wheels that slip, and other errors the std cannot see: the prediction-error check (issue 11).

A slipping wheel biases every parameter by tens of per cent while the estimate stays steady along the log, so
neither the jackknife nor the structural test notices.  The observer's own prediction error does: where the
model holds it is the speed sensors' noise, which :class:`wmrid.estimators.noise_floor.NoiseFloor` measures from the
log's second differences.  Tested on MuJoCo multibody logs (a floor of friction 0.15 against a normal one)
and on wmrid's reduced simulator with a coloured disturbance in closed loop, which must not be flagged.
"""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest

from wmrid.cli.app import main
from wmrid.estimators.methods import run
from wmrid.estimators.model_error import MISFIT_FLOOR, MISFIT_RATIO, prediction_misfit
from wmrid.estimators.noise_floor import WINDOW, NoiseFloor
from wmrid.estimators.options import MethodOptions
from wmrid.model.robot import BUILTIN_ROBOTS
from wmrid.pipeline.identify import identify
from wmrid.sim.multibody import simulate_multibody
from wmrid.sim.multibody_model import MultibodySettings
from wmrid.sim.scenario import NoiseSettings
from wmrid.sim.simulate import simulate

AMR = BUILTIN_ROBOTS["amr"]
PAPER = BUILTIN_ROBOTS["paper"]
BASE = ("m11", "m12", "m22", "M11", "M12", "M22", "Vc", "Fv1", "Fv2", "Fd1", "Fd2")
#: rad/s, the physics benchmark's speed noise.
ETA_STD = 0.02


def as_log(sim, name="log"):
    return SimpleNamespace(t=np.array(sim.t), eta=np.array(sim.eta), tau=np.array(sim.tau), source=name, notes=())


def amr_log(floor: float):
    """The light AMR, 12 s sinusoid at 1 kHz, frictionless casters, speed noise 0.02 rad/s, torque noise 0.01 N m."""
    return simulate_multibody(
        AMR.cad, AMR.nominal, settings=MultibodySettings(caster_resistance=0.0, floor_friction=floor),
        duration=12.0, noise=NoiseSettings(eta_std=ETA_STD, tau_std=0.01), seed=3,
    )  # fmt: skip


@pytest.fixture(scope="module")
def slipping():
    sim = amr_log(0.15)
    assert sim.settings["multibody"]["max_slip_speed"] > 0.05  # the wheels really slip (creep is ~1e-4 m/s)
    return sim


@pytest.fixture(scope="module")
def gripping():
    return amr_log(1.0)


def reference_variances(eta: np.ndarray, lag: int = 1) -> np.ndarray:
    """Windows' mean squared second differences at ``lag`` / 6, (w, 2), written out with numpy from the whole log."""
    d2 = np.square(eta[2 * lag :] - 2.0 * eta[lag:-lag] + eta[: -2 * lag])
    full = len(d2) // WINDOW
    return d2[: full * WINDOW].reshape(full, WINDOW, 2).mean(axis=1) / 6.0


@pytest.mark.parametrize("lag", [1, 2, 21])
def test_noise_floor_kernel_matches_a_numpy_reference_however_the_log_is_cut(lag):
    """The compiled pass, fed in pieces of 1, 1, 1, 62, 1, 64, 570 ... samples, gives the windows' variances of
    the whole log written out with numpy, to 1e-12 relative (the sums differ only in rounding), and the same
    count of windows and speed rms; at lag 1 (measured speeds) and at a derivative's window (derived speeds)."""
    from wmrid.estimators.noise_floor import _window_variances

    rng = np.random.default_rng(4)
    eta = np.cumsum(rng.normal(0, 0.1, (5000, 2)), axis=0) + rng.normal(0, 0.02, (5000, 2))
    prev, state = np.zeros((2 * lag, 2)), np.zeros(7)
    got = []
    for piece in np.array_split(eta, np.cumsum([1, 1, 1, 62, 1, 64, 570, 3])):
        out = np.empty((len(piece) // WINDOW + 1, 2))
        got.append(out[: _window_variances(np.ascontiguousarray(piece), prev, state, out)])
    expected = reference_variances(eta, lag)
    got = np.concatenate(got)
    assert got.shape == expected.shape
    np.testing.assert_allclose(got, expected, rtol=1e-12)
    np.testing.assert_allclose(np.sqrt(state[4:6] / len(eta)), np.sqrt(np.mean(eta**2, axis=0)), rtol=1e-12)


def test_derived_speeds_are_measured_at_the_derivatives_window():
    """Speeds a Savitzky-Golay derivative made from 2048-count encoder angles: their noise is correlated over the
    derivative's window (autocorrelation 0.80 at lag 1, within 0.02 of 0 from lag 21), so lag-1 second
    differences see about a third of it (0.026 of 0.075 rad/s), and the misfit check flagged every encoder log
    (issue 28).  At the window's lag the floor sees 0.66 of the noise's rms, measured directly as the derived
    speeds' difference from the derivative of the unquantised angles: the rest is the median of windows, below
    their mean because the quantisation noise's level changes with the speed along the log.  Pinned: at least
    1.8 times the lag-1 level and between 0.5 and 1.15 of the rms (the misfit check's gate is 2)."""
    from wmrid.estimators.noise_floor import derived_lag
    from wmrid.io.signals import speed_from_position

    rng = np.random.default_rng(7)
    t = np.arange(40_000) * 1e-3
    angle = np.column_stack([5 * t + 3 * np.sin(t), 4 * t - 2 * np.cos(0.8 * t)])
    step = 2 * np.pi / 2048
    counted = np.floor(angle / step + rng.uniform(0, 1, 2)) * step
    speed, note = speed_from_position(t, counted)
    true, _ = speed_from_position(t, angle)
    noise = np.sqrt(np.mean((speed - true) ** 2, axis=0))
    lag = derived_lag([note])
    assert lag == 21  # 20 ms at 1 kHz, made odd
    floor, white = NoiseFloor(lag), NoiseFloor()
    floor.feed(speed)
    white.feed(speed)
    assert np.all(floor.sigma() >= 1.8 * white.sigma())
    assert np.all((floor.sigma() > 0.5 * noise) & (floor.sigma() < 1.15 * noise))
    assert derived_lag(["wheel speeds read as m/s at the rim"]) == 1


def test_noise_floor_measures_white_noise_on_a_smooth_motion():
    """sigma of white noise on a 1 kHz sinusoidal speed, to 4 %: the median of 64-sample windows' mean squares
    sits ~1 % below their mean (about 30 effective degrees of freedom) and the histogram buckets are 1.1 % wide;
    the 1,562 windows' spread adds ~0.5 %.  The result does not depend on how the log is cut into pieces."""
    rng = np.random.default_rng(0)
    t = np.arange(100_000) * 1e-3
    eta = np.column_stack([5 * np.sin(2 * t), 3 + np.cos(0.7 * t)]) + rng.normal(0, [0.02, 0.005], (len(t), 2))
    whole = NoiseFloor()
    whole.feed(eta)
    assert whole.sigma() == pytest.approx([0.02, 0.005], rel=0.04)
    assert whole.rms() == pytest.approx(np.sqrt(np.mean(eta**2, axis=0)), rel=1e-12)
    cut = NoiseFloor()
    for piece in np.array_split(eta, [1, 2, 3, 70, 5000, 5001, 77_777]):
        cut.feed(piece)
    assert np.array_equal(cut.sigma(), whole.sigma())


def test_noise_floor_ignores_bursts_and_parked_wheels():
    """Spikes in a tenth of the windows (a wheel that slips at each acceleration peak) leave the median level
    within 10 % of the noise, where a mean would be many times it.  Windows of a parked wheel (speeds exactly 0,
    as encoders report a standstill) say nothing about the noise and are not counted: a log parked 60 % of the
    time still gives the noise of its moving part, and one never moving gives NaN, not 0."""
    rng = np.random.default_rng(1)
    eta = rng.normal(0, 0.01, (64_000, 2))
    burst = np.zeros(len(eta), dtype=bool)
    for start in range(0, len(eta), 10 * WINDOW):
        burst[start : start + WINDOW] = True
    eta[burst] += rng.normal(0, 0.5, (burst.sum(), 2))
    floor = NoiseFloor()
    floor.feed(eta)
    assert floor.sigma() == pytest.approx([0.01, 0.01], rel=0.1)
    parked = np.zeros((100_000, 2))
    parked[60_000:] = 1.0 + rng.normal(0, 0.02, (40_000, 2))
    floor = NoiseFloor()
    floor.feed(parked)
    assert floor.sigma() == pytest.approx([0.02, 0.02], rel=0.05)
    still = NoiseFloor()
    still.feed(np.zeros((10_000, 2)))
    assert np.all(np.isnan(still.sigma()))


def test_noise_floor_needs_min_windows():
    """MIN_WINDOWS windows of WINDOW second differences need MIN_WINDOWS * WINDOW + 2 samples: one fewer gives
    NaN; so do logs of 0 to 3 samples."""
    from wmrid.estimators.noise_floor import MIN_WINDOWS

    rng = np.random.default_rng(2)
    eta = rng.normal(0, 0.01, (MIN_WINDOWS * WINDOW + 2, 2))
    enough, short = NoiseFloor(), NoiseFloor()
    enough.feed(eta)
    short.feed(eta[:-1])
    assert np.all(np.isfinite(enough.sigma()))
    assert np.all(np.isnan(short.sigma()))
    for n in range(4):
        tiny = NoiseFloor()
        tiny.feed(eta[:n])
        assert np.all(np.isnan(tiny.sigma()))


def test_prediction_misfit_thresholds():
    """Applied only when a wheel's prediction error exceeds MISFIT_RATIO times its noise and MISFIT_FLOOR of its
    speed's rms: a noise-free log well predicted is not flagged however small its noise floor; a wheel whose
    noise is unknown (NaN, or 0) is not judged; the figures reported are the worst applied wheel's."""
    rms = np.array([10.0, 10.0])
    assert not prediction_misfit(np.array([0.03, 0.02]), np.array([0.02, 0.02]), rms)["applied"]
    hit = prediction_misfit(np.array([0.02, 0.2]), np.array([0.02, 0.02]), rms)
    assert hit["applied"]
    assert hit["wheel"] == 1
    assert hit["ratio"] == pytest.approx(10.0)
    assert hit["share"] == pytest.approx(0.02)
    tiny = prediction_misfit(np.array([1e-5, 1e-5]), np.array([1e-9, 1e-9]), rms)
    assert not tiny["applied"]
    assert tiny["ratio"] > MISFIT_RATIO
    assert prediction_misfit(np.array([2 * MISFIT_FLOOR * 10, 0.0]), np.array([1e-9, 1e-9]), rms)["applied"]
    assert not prediction_misfit(np.array([0.2, 0.2]), np.array([0.0, np.nan]), rms)["applied"]
    assert prediction_misfit(np.array([0.2, 0.2]), np.full(2, np.nan), rms)["ratio"] is None


def test_a_gap_in_the_log_is_not_slip():
    """The prediction error is taken per sample, as the noise is: the catch-up after a 0.5 s dropout (identify
    bridges holes up to 1 s) must not count for the whole gap.  Time-weighted, a 0.5 s gap in this 20 s log gave
    a ratio of 2.4 and flagged it; per sample the ratio stays near 1."""
    noise = NoiseSettings(eta_std=0.01, tau_std=0.02)
    sim = simulate(PAPER.cad, PAPER.nominal, duration=20, noise=noise, seed=0)
    keep = (sim.t <= 10.0) | (sim.t >= 10.5)
    log = SimpleNamespace(t=sim.t[keep], eta=sim.eta[keep], tau=sim.tau[keep], source="gap", notes=())
    misfit = identify(log, PAPER).diagnostics.prediction_misfit
    assert not misfit.applied
    assert misfit.ratio < 1.3


def test_slipping_wheels_flag_every_parameter(slipping):
    """Floor friction 0.15: the estimate is off by tens of per cent and the std alone does not cover it
    (measured on 40 s logs: M12 49 % off at z 3.5 unflagged before this check).  The prediction error is many
    times the noise (11-35 on the benchmark's slipping logs; 12 s here), so every parameter is flagged, the
    first warning says why, and IDIM on the same log inherits the flags."""
    result = identify(as_log(slipping), AMR, feedback=False)
    misfit = result.diagnostics.uncertainty.model_error.prediction_misfit
    assert misfit.applied
    assert misfit.ratio > 5
    assert misfit.noise_rms == pytest.approx([ETA_STD, ETA_STD], rel=0.1)
    assert set(result.diagnostics.flagged) == set(BASE)
    assert result.warnings[0].startswith("the model predicts the ")
    assert "slip" in result.warnings[0]
    idim = run("idim", as_log(slipping), result, MethodOptions(), AMR)
    assert set(idim.diagnostics.flagged) == set(BASE)
    assert any(w.startswith("the model predicts the ") for w in idim.warnings)


def test_gripping_wheels_are_not_flagged_by_it(gripping):
    """The same robot and motion on a normal floor: the prediction error is the sensor noise (ratio 1.02-1.11 on
    the benchmark's logs), well under MISFIT_RATIO."""
    result = identify(as_log(gripping), AMR)
    misfit = result.diagnostics.uncertainty.model_error.prediction_misfit
    assert not misfit.applied
    assert 0.9 < misfit.ratio < 1.3
    assert not any(w.startswith("the model predicts the ") for w in result.warnings)


def test_a_closed_loop_disturbance_is_not_flagged():
    """wmrid's reduced simulator with the coloured caster disturbance (0.05 N m, 0.3 s) inside the feedback loop:
    the model holds apart from the disturbance, which the jackknife covers; the ratio was 1.08."""
    noise = NoiseSettings(eta_std=0.01, tau_std=0.02, caster_std=0.05, caster_time=0.3)
    sim = simulate(PAPER.cad, PAPER.nominal, duration=20, noise=noise, seed=0)
    misfit = identify(as_log(sim), PAPER).diagnostics.prediction_misfit
    assert not misfit.applied
    assert misfit.ratio < 1.3


@pytest.mark.slow  # the CLI's view of a flag the library tests check (4 s)
def test_cli_json_and_table_show_the_flag(slipping, tmp_path, capsys):
    """Through the CLI: the JSON carries the check's figures and flags every parameter; the terminal table and the
    report mark the flagged parameters (!) and state the warning."""
    path = tmp_path / "slip.csv"
    np.savetxt(
        path, np.column_stack([slipping.t, slipping.eta, slipping.tau]), delimiter=",",
        header="t,eta_r,eta_l,tau_r,tau_l", comments="",
    )  # fmt: skip
    with pytest.raises(SystemExit) as err:
        main(["identify", str(path), "--robot", "amr", "--friction", "wheel", "--format", "json"])
    assert err.value.code == 0
    out = json.loads(capsys.readouterr().out)
    assert out["diagnostics"]["uncertainty"]["model_error"]["prediction_misfit"]["applied"]
    assert set(out["diagnostics"]["flagged"]) >= set(BASE)
    with pytest.raises(SystemExit) as err:
        main(["identify", str(path), "--robot", "amr", "--friction", "wheel", "--format", "table"])
    assert err.value.code == 0
    captured = capsys.readouterr()
    assert "wheel's speed to" in captured.out + captured.err
    assert "! flagged" in captured.out
    report = tmp_path / "r.md"
    with pytest.raises(SystemExit) as err:
        main(["report", str(path), "--robot", "amr", "--friction", "wheel", "-o", str(report)])
    assert err.value.code == 0
    text = report.read_text()
    assert "! flagged" in text
    assert "wheel's speed to" in text
