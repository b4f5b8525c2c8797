"""The validation predictor and the output-error method with the casters' drag (geometric model): unchanged
without it, the noise-free direct model reproduced, theta0 with D recovered, and OE on the MuJoCo multibody AMR."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from tests.open_loop import open_loop_log
from tests.unit.estimators.test_idim_caster import GEOMETRIC, TWO_TERM, caster_log  # noqa: F401  (caster_log: a fixture)
from wmrid.core.errors import UsageError
from wmrid.estimators.output_error import identify_oe
from wmrid.model import dynamics as model, torques
from wmrid.model.predict import simulate_segments, simulate_speeds, validation_fit
from wmrid.model.robot import BUILTIN_ROBOTS, PAPER_CAD
from wmrid.pipeline.identify import identify

AMR = BUILTIN_ROBOTS["amr"]


@pytest.fixture(scope="module")
def reversing_log():
    log = open_loop_log(duration=3.0, reversing=True)
    log.theta0 = log.theta0.copy()
    log.theta0[6:8] = [0.3, 0.2]  # Coulomb friction, so that the wheels' zero crossings are events
    return log


@pytest.mark.parametrize("hold", ["zoh", "foh"])
def test_without_caster_drag_nothing_changes(reversing_log, hold):
    """Bit for bit: no form, a form without caster drag (paper or general), and the geometric model with every
    D = 0 give the same speeds (the drag's branch adds exactly 0)."""
    log = reversing_log
    plain = simulate_speeds(log.t, log.tau, log.theta0, log.eta[0], torque_hold=hold)
    starts = np.array([0, 700, 1900])
    segments = simulate_segments(log.t, log.tau, log.theta0, log.eta, starts, torque_hold=hold, max_step=3e-4)
    for form in (model.RegressorForm("general"), model.RegressorForm("paper")):
        got = simulate_speeds(log.t, log.tau, log.theta0, log.eta[0], torque_hold=hold, form=form)
        assert np.array_equal(got, plain)
        got = simulate_segments(log.t, log.tau, log.theta0, log.eta, starts, torque_hold=hold, max_step=3e-4, form=form)
        assert np.array_equal(got, segments)
        assert validation_fit(log.t, log.eta, log.tau, log.theta0, hold, form=form) == validation_fit(
            log.t, log.eta, log.tau, log.theta0, hold
        )
    no_drag = np.concatenate([log.theta0, [0.0, 0.0]])
    assert np.array_equal(simulate_speeds(log.t, log.tau, no_drag, log.eta[0], torque_hold=hold, form=GEOMETRIC), plain)


def test_output_error_without_caster_drag_unchanged(reversing_log):
    log = reversing_log
    start = log.theta0 * 1.05
    plain = identify_oe(log.t, log.eta, log.tau, start)
    general = identify_oe(log.t, log.eta, log.tau, start, form=model.RegressorForm("general"))
    assert np.array_equal(general.theta0, plain.theta0)
    assert np.array_equal(general.cov, plain.cov)
    assert general.diagnostics.keys() == plain.diagnostics.keys()
    assert "parameter_names" not in plain.diagnostics


def test_predictor_reproduces_the_direct_model_with_caster_drag(caster_log):  # noqa: F811
    """The noise-free 30 s log of the direct model with two casters' drag (DOP853, rtol 1e-10): simulated open loop
    from the sampled torques with foh, the true theta0 (D included) gives the speeds within 1e-6 rad/s.

    Measured: max 5.1e-7 rad/s (RMS 1.9e-7) at max_step 1 ms and the same at 0.25 ms, so it is the linear
    interpolation of the continuous torque, not the integration; without the drag in the model, 0.65 rad/s.
    """
    log = caster_log
    sim = simulate_speeds(log.t, log.tau, log.theta0, log.eta[0], torque_hold="foh", form=GEOMETRIC)
    assert np.max(np.abs(sim - log.eta)) < 1e-6
    wheel_only = simulate_speeds(log.t, log.tau, log.theta0[:8], log.eta[0], torque_hold="foh")
    assert np.max(np.abs(wheel_only - log.eta)) > 0.3
    fit = validation_fit(log.t, log.eta, log.tau, log.theta0, "foh", form=GEOMETRIC)
    assert fit["eta_r"] > 99.999
    assert fit["eta_l"] > 99.999
    assert "casters' rolling drag" in fit["predictor"]


def test_a_wheel_held_by_coulomb_friction_against_the_drag():
    """The drag is part of the torque Coulomb friction must hold: wheel 1 braked by -0.6 N m while wheel 2 drives
    stops and stays stopped; its holding friction (tau - the inverse model with the drag, at eta_1' = 0) is within
    F_d1 = 0.3 N m (measured -0.21 to -0.01), whereas without the drag's share it would reach -0.45 N m: a mode
    choice ignoring the drag would release the wheel backwards."""
    theta0 = np.concatenate([model.base_parameters(PAPER_CAD), [3.0, 2.0]])
    theta0[6:8] = [0.3, 0.3]
    t = np.arange(3001) * 1e-3
    tau = np.stack([np.full_like(t, -0.6), 1.5 + 0.5 * np.sin(2 * t)], axis=1)
    eta = simulate_speeds(t, tau, theta0, np.array([0.3, 0.0]), torque_hold="foh", max_step=2.5e-4, form=GEOMETRIC)
    rest = eta[:, 0] == 0.0
    first = int(np.argmax(rest))
    assert 0 < first < 1000
    assert np.all(rest[first:])
    inner = np.zeros_like(rest)
    inner[first + 1 : -1] = True
    assert np.all(eta[inner, 1] > 0.2)  # wheel 2 turning: the casters move and drag
    eta_dot = np.gradient(eta, t, axis=0)
    holding = tau[inner, 0] - torques.wheel_torque(eta, eta_dot, theta0, GEOMETRIC)[inner, 0]
    assert np.all(np.abs(holding) <= theta0[6])
    without_drag = tau[inner, 0] - torques.wheel_torque(eta, eta_dot, theta0[:8])[inner, 0]
    assert np.min(without_drag) < -theta0[6]
    turning = np.zeros_like(rest)
    turning[1 : first - 1] = True
    acc = torques.wheel_acceleration(eta, tau, theta0, GEOMETRIC)
    np.testing.assert_allclose(eta_dot[turning], acc[turning], atol=1e-5)


def test_output_error_recovers_the_caster_drag_on_a_noise_free_log(caster_log):  # noqa: F811
    """From every parameter 10 % off (uniform draws, seed 0), OE (foh, 0.5 s segments) returns theta0, D_1 and D_2
    included, within 0.01 %: measured at most 0.0014 % (Fv1; D 1e-4 %), in 5 evaluations, about 1.2 s."""
    log = caster_log
    rng = np.random.default_rng(0)
    start = log.theta0 * (1.0 + 0.1 * rng.uniform(-1.0, 1.0, log.theta0.size))
    est = identify_oe(log.t, log.eta, log.tau, start, torque_hold="foh", form=GEOMETRIC)
    assert est.theta0.shape == est.std.shape == (10,)
    assert est.cov.shape == (10, 10)
    assert est.diagnostics["parameter_names"] == list(GEOMETRIC.base_names)
    assert est.diagnostics["converged"]
    np.testing.assert_allclose(est.theta0, log.theta0, rtol=1e-4)
    assert np.all(np.diag(est.cov) > 0)


def test_two_term_caster_model_is_refused(reversing_log):
    log = reversing_log
    theta0 = np.concatenate([log.theta0, [0.05, 0.02]])
    calls = [
        lambda: simulate_speeds(log.t, log.tau, theta0, log.eta[0], form=TWO_TERM),
        lambda: simulate_segments(log.t, log.tau, theta0, log.eta, np.array([0]), form=TWO_TERM),
        lambda: validation_fit(log.t, log.eta, log.tau, theta0, form=TWO_TERM),
        lambda: identify_oe(log.t, log.eta, log.tau, theta0, form=TWO_TERM),
    ]
    refusal = r"model the caster drag only with the casters' positions \(\[\[caster\]\]"
    for call in calls:
        with pytest.raises(UsageError, match=refusal):
            call()
    with pytest.raises(UsageError, match=r"shape \(10,\)"):
        simulate_speeds(log.t, log.tau, log.theta0, log.eta[0], form=GEOMETRIC)
    with pytest.raises(UsageError, match=r"shape \(10,\)"):
        identify_oe(log.t, log.eta, log.tau, log.theta0, form=GEOMETRIC)
    with pytest.raises(UsageError, match=r"shape \(8,\)"):
        simulate_speeds(log.t, log.tau, theta0, log.eta[0])


def test_output_error_with_caster_drag_on_the_multibody_amr(amr_caster_log):
    """OE (zoh, the default) from the observer's ``wheel+caster`` estimate on the MuJoCo AMR log.

    Measured (seed 0), error % (z): M11 +0.30, M12 +0.52, M22 -0.35, Vc -0.47 (|z| <= 2.0); Fv1 +0.27 (0.05),
    Fv2 +1.46 (0.40), Fd1 +0.40 (0.12), Fd2 -1.30 (-0.57); D1 +1.56 % (0.19) against the engine's mean drag.
    The observer's start: M within 0.6 %, Vc +0.14 %, Fv1 +2.9 %, Fv2 +4.0 %, Fd1 -0.8 %, Fd2 -2.1 %, D1 +1.1 %.
    Asserted: inertia entries and Vc within 3 %, D1 within 10 %.
    """
    sim = amr_caster_log
    log = SimpleNamespace(t=np.array(sim.t), eta=np.array(sim.eta), tau=np.array(sim.tau), source="amr", notes=())
    observer = identify(log, AMR, friction="wheel+caster")
    form = observer.form
    assert form.geometry
    assert form.n_base == 9
    est = identify_oe(log.t, log.eta, log.tau, np.asarray(observer.estimate.theta0), form=form)
    assert est.theta0.shape == (9,)
    assert est.cov.shape == (9, 9)
    truth = model.named_base(model.base_parameters(sim.true))
    truth["D1"] = sum(c["mean_drag_force"] for c in sim.settings["multibody"]["casters"] if c["mean_drag_force"])
    got = model.named_base(est.theta0[:8])
    got["D1"] = float(est.theta0[8])
    names = ("M11", "M12", "M22", "Vc", "Fv1", "Fv2", "Fd1", "Fd2", "D1")
    errors = {name: 100.0 * (got[name] - truth[name]) / abs(truth[name]) for name in names}
    print("\nOE wheel+caster on the multibody AMR: name error %")
    for name, err in errors.items():
        print(f"  {name:4s} {err:+8.3f}")
    for name in ("M11", "M12", "M22", "Vc"):
        assert abs(errors[name]) < 3.0, (name, errors[name])
    assert abs(errors["D1"]) < 10.0, errors["D1"]
