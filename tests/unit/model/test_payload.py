"""Payload identification: the inversion of Eqs. (10)-(14) is exact, and all four quantities are identifiable."""

from __future__ import annotations

import numpy as np
import pytest

from wmrid.model import dynamics as model
from wmrid.model.payload import payload_from_base, payload_with_std
from wmrid.model.robot import BUILTIN_ROBOTS, Payload

CAD = BUILTIN_ROBOTS["paper"].cad


@pytest.mark.parametrize("seed", range(20))
def test_round_trip_recovers_any_payload(seed):
    rng = np.random.default_rng(seed)
    load = Payload(rng.uniform(0.5, 80), rng.uniform(-0.3, 0.4), rng.uniform(-0.2, 0.2), rng.uniform(0, 3))
    theta0 = model.base_parameters(CAD.with_payload(load))
    got = payload_from_base(theta0, CAD)
    np.testing.assert_allclose(got, [load.mass, load.x, load.y, load.inertia], rtol=1e-9, atol=1e-10)


def test_the_four_quantities_are_identifiable():
    # The map (m11, m12, m22, Vc) -> (m_L, x, y, I_L) has a full-rank Jacobian at a payload off the axle,
    # so none of the four is a combination the base parameters cannot separate.
    theta0 = model.base_parameters(CAD.with_payload(Payload(25.0, 0.1, -0.05, 0.4)))
    jac = np.zeros((4, 4))
    for j in range(4):
        step = 1e-7 * abs(theta0[j])
        up, down = theta0.copy(), theta0.copy()
        up[j] += step
        down[j] -= step
        jac[:, j] = (payload_from_base(up, CAD) - payload_from_base(down, CAD)) / (2 * step)
    assert np.linalg.matrix_rank(jac, tol=1e-9 * np.abs(jac).max()) == 4


def test_no_payload_gives_zero_mass():
    got = payload_from_base(model.base_parameters(CAD), CAD)
    np.testing.assert_allclose(got[[0, 3]], 0.0, atol=1e-10)


def test_delta_method_std_matches_monte_carlo():
    theta0 = model.base_parameters(CAD.with_payload(Payload(25.0, 0.1, -0.05, 0.4)))
    rel = np.array([1e-4, 3e-4, 1e-4, 2e-4, 0, 0, 0, 0])
    cov0 = np.diag((rel * np.abs(theta0)) ** 2)
    est = payload_with_std(theta0, cov0, CAD)
    rng = np.random.default_rng(0)
    draws = theta0 + rng.standard_normal((4000, 8)) * rel * np.abs(theta0)
    spread = np.std([payload_from_base(d, CAD) for d in draws], axis=0)
    # Linear to first order at these small errors; 4000 draws give the std to about 2 % (1 sigma).
    for i, name in enumerate(("mass", "x", "y", "inertia")):
        assert getattr(est, name)[1] == pytest.approx(spread[i], rel=0.08), name


def test_identify_finds_a_25_kg_payload_in_a_noisy_simulated_log(tmp_path):
    # Issue 4: mass within 1 %, x and y within 5 mm, inertia within 10 %, truth within the uncertainty.
    from types import SimpleNamespace

    from wmrid.pipeline.identify import identify
    from wmrid.sim.scenario import NoiseSettings
    from wmrid.sim.simulate import simulate

    load = Payload(25.0, 0.1, -0.05, 0.4)
    robot = BUILTIN_ROBOTS["paper"]
    noise = NoiseSettings(eta_std=0.01, tau_std=0.02, caster_std=0.05)
    sim = simulate(CAD.with_payload(load), robot.nominal, duration=40.0, noise=noise, seed=3)
    log = SimpleNamespace(t=sim.t, eta=sim.eta, tau=sim.tau, source="sim", notes=())
    result = identify(log, robot, payload=True)
    est = result.payload
    assert abs(est.mass[0] / 25.0 - 1) < 0.01
    assert abs(est.x[0] - 0.1) < 0.005
    assert abs(est.y[0] + 0.05) < 0.005
    assert abs(est.inertia[0] / 0.4 - 1) < 0.10
    factor = result.diagnostics.uncertainty.interval_factor["99.7%"]
    for name, truth in zip(("mass", "x", "y", "inertia"), (25.0, 0.1, -0.05, 0.4), strict=True):
        assert abs(getattr(est, name)[0] - truth) <= factor * getattr(est, name)[1], name
    assert result.to_dict()["payload"]["mass"]["unit"] == "kg"
