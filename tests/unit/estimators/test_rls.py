"""Recursive least squares (wmrid.estimators.regression.rls): equal to batch LS without forgetting, tracking with it,
the
history."""

from __future__ import annotations

import json

import numpy as np
import pytest

from tests.open_loop import open_loop_log
from wmrid.core.errors import NotIdentifiableError, UsageError
from wmrid.estimators.regression import idim, idim_rows, rls
from wmrid.model import dynamics as model, torques
from wmrid.model.robot import BUILTIN_ROBOTS, PAPER_CAD
from wmrid.sim.scenario import NoiseSettings
from wmrid.sim.simulate import simulate


@pytest.fixture(scope="module")
def noisy_closed_loop():
    """The benchmarks' noisy closed-loop log: paper robot (CAD true, nominal in the controller), 40 s at 1 kHz."""
    r = BUILTIN_ROBOTS["paper"]
    noise = NoiseSettings(eta_std=0.01, tau_std=0.02, caster_std=0.05)
    return simulate(r.cad, r.nominal, trajectory="sinusoid", duration=40.0, rate=1000.0, noise=noise, seed=1)


@pytest.fixture(scope="module")
def reversing_log():
    return open_loop_log(duration=20.0, reversing=True)


def batch_ls(reg: idim_rows.IdimRegression) -> np.ndarray:
    """Ordinary least squares (numpy lstsq, SVD) of phi on the stacked rows of a regression."""
    return np.linalg.lstsq(reg.rows().reshape(-1, 8), reg.tau.reshape(-1), rcond=None)[0]


def test_no_forgetting_equals_batch_least_squares(smooth_log, reversing_log, noisy_closed_loop):
    # Exact initialisation (no prior) makes the final RLS estimate the LS one up to the rounding of the
    # covariance recursion.  Measured max relative differences: 1e-9 (5 s smooth log, whose weak Coulomb
    # directions start ill-conditioned), 3e-10 (reversing), 1e-11 (noisy closed loop).
    for log, decimate in ((smooth_log, False), (reversing_log, False), (noisy_closed_loop, False), (smooth_log, True)):
        reg = idim_rows.idim_regression(log.t, log.eta, log.tau, decimate=decimate)
        est, hist = rls.rls_on_regression(reg, forgetting=1.0)
        phi = np.array(list(est.diagnostics["phi"].values()))
        np.testing.assert_allclose(phi, batch_ls(reg), rtol=1e-8)
        np.testing.assert_allclose(hist.phi[-1], phi, rtol=1e-14)
        np.testing.assert_allclose(est.theta0, idim.phi_to_theta0(phi), rtol=1e-14)


def test_no_forgetting_on_the_noisy_closed_loop_log(noisy_closed_loop):
    # Measured (seed 1, default cutoff 4.9 Hz, no decimation): errors in M11, M12, M22, Vc of
    # -0.04 %, -0.31 %, -0.14 %, -0.51 %, as batch IDIM.
    sim = noisy_closed_loop
    est = rls.identify_rls(sim.t, sim.eta, sim.tau)
    truth = model.base_parameters(sim.true)
    got, want = model.named_base(est.theta0), model.named_base(truth)
    for name in ("M11", "M12", "M22", "Vc"):
        assert abs(got[name] / want[name] - 1) < 0.05, name
    assert est.method == "rls"
    assert est.dof == est.diagnostics["segments"] - 1
    assert est.diagnostics["uncertainty"].startswith("delete-a-segment jackknife")
    batch = idim.identify_idim(sim.t, sim.eta, sim.tau, decimate=False)
    np.testing.assert_allclose(est.theta0, batch.theta0, rtol=1e-8)
    np.testing.assert_allclose(est.std, batch.std, rtol=1e-6)  # the same jackknife
    json.dumps(est.diagnostics)


def test_forgetting_tracks_a_step_in_viscous_friction(reversing_log):
    # The same motion, with the torques the true model needs when F_v1 doubles at t = 10 s (exact
    # accelerations, Eq. 9).  lambda = 0.999: a window of 1000 samples = 1 s.  Five windows after the step
    # the old data weigh e^-5.  Measured there: F_v1 0.020021 (0.1 % off), M and Vc within 0.3 %, the left
    # wheel's friction (weakly excited in that stretch) still 11 % (F_v2) and 9 % (F_d2) off; at the end
    # of the log (9.6 windows) everything within 2.7e-4.  Plain RLS (lambda = 1) ends at 0.0167.
    log = reversing_log
    acc = torques.wheel_acceleration(log.eta, log.tau, log.theta0)
    after = log.theta0.copy()
    after[4] *= 2.0
    tau = np.where((log.t >= 10.0)[:, None], torques.wheel_torque(log.eta, acc, after), log.tau)
    hist = rls.rls_history(log.t, log.eta, tau, forgetting=0.999, torque_hold="foh")
    assert len(hist.t) <= rls.HISTORY_POINTS
    before = np.searchsorted(hist.t, 9.5)
    five = np.searchsorted(hist.t, 15.0)
    np.testing.assert_allclose(hist.theta0[before], log.theta0, rtol=0.01)
    assert abs(hist.theta0[five, 4] / after[4] - 1) < 0.01
    np.testing.assert_allclose(hist.theta0[five, :4], after[:4], rtol=0.01)
    np.testing.assert_allclose(hist.theta0[five], after, rtol=0.2)
    np.testing.assert_allclose(hist.theta0[-1], after, rtol=1e-3)
    plain = rls.identify_rls(log.t, log.eta, tau, torque_hold="foh")
    assert 0.013 < plain.theta0[4] < 0.018


def test_forgetting_std_is_local_and_its_dof_the_batches(noisy_closed_loop):
    sim = noisy_closed_loop
    est = rls.identify_rls(sim.t, sim.eta, sim.tau, forgetting=0.9995)
    d = est.diagnostics
    assert d["window_samples"] == pytest.approx(2000.0)
    assert d["window_seconds"] == pytest.approx(2.0)
    assert d["effective_samples"] == pytest.approx(1.9995 / 0.0005, rel=1e-3)
    assert est.dof == d["batches"] - 1
    assert d["uncertainty"].startswith("local")
    plain = rls.identify_rls(sim.t, sim.eta, sim.tau)
    assert np.all(est.std > plain.std)  # 2 s of data against 40 s
    assert np.all(np.isfinite(est.std))
    json.dumps(d)


def test_history_before_and_after_the_start(smooth_log):
    est, hist = rls.rls_run(
        smooth_log.t, smooth_log.eta, smooth_log.tau, forgetting=1.0, history_points=100, torque_hold="foh"
    )
    reg = idim_rows.idim_regression(smooth_log.t, smooth_log.eta, smooth_log.tau, decimate=False)
    assert len(hist.t) <= 100
    assert hist.t[-1] == reg.t[-1]
    assert np.all(np.diff(hist.t) > 0)
    start = est.diagnostics["init_seconds"] + reg.t[0]
    assert np.all(np.isnan(hist.theta0[hist.t < start]))
    defined = hist.t >= start
    assert np.all(np.isfinite(hist.theta0[defined]))
    np.testing.assert_allclose(hist.theta0[defined], idim.phi_to_theta0(hist.phi[defined]), rtol=1e-13)
    np.testing.assert_allclose(hist.theta0[-1], model.base_parameters(PAPER_CAD), rtol=1e-4)


def test_forgetting_does_not_wind_up_when_excitation_stops(reversing_log):
    # 30 s of constant speeds after the exciting part: P would grow by 0.999^-30000 = 1e13 without the cap.
    log = reversing_log
    n = 30000
    eta_c = np.tile(log.eta[-1], (n, 1))
    tau_c = torques.wheel_torque(eta_c, np.zeros_like(eta_c), log.theta0)
    t = np.concatenate([log.t, log.t[-1] + 1e-3 * np.arange(1, n + 1)])
    est, hist = rls.rls_run(
        t, np.vstack([log.eta, eta_c]), np.vstack([log.tau, tau_c]), forgetting=0.999, torque_hold="foh"
    )
    assert est.diagnostics["forgetting_capped"] > 20000
    assert np.all(np.isfinite(est.theta0))
    assert np.all(np.isfinite(hist.theta0[hist.t > 5.0]))


def test_not_identifiable_and_bad_forgetting(smooth_log):
    t = np.arange(5001) * 1e-3
    eta = np.tile([3.0, 2.5], (len(t), 1))
    tau = np.tile([1.0, 0.8], (len(t), 1))
    with pytest.raises(NotIdentifiableError, match="does not excite the dynamics"):
        rls.identify_rls(t, eta, tau)
    for bad in (0.0, 1.5, float("nan"), True, "0.9"):
        with pytest.raises(UsageError, match="forgetting"):
            rls.identify_rls(smooth_log.t, smooth_log.eta, smooth_log.tau, forgetting=bad)
