"""wmrid.model.physical: the physical quantities from base parameters -- a round trip through Eqs. (10)-(14), the
covariance against sampling, undetermined inputs, and the refusals of robots no one can build."""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from wmrid.core.errors import UsageError
from wmrid.model import dynamics as dm
from wmrid.model.physical import DETERMINED, PLATFORM, PhysicalEstimate, physical_from_base
from wmrid.model.robot import BUILTIN_ROBOTS


@pytest.mark.parametrize("name", ["paper", "amr"])
def test_round_trip_recovers_the_robot_file(name):
    """Base parameters computed from Table 1 (Eqs. 10-14) give back m_p, d_x, d_y, I_p and the friction to rounding
    (1e-12 relative: a 2x2 inverse and a few sums)."""
    p = BUILTIN_ROBOTS[name].cad
    theta0 = dm.base_parameters(p)
    est = physical_from_base(theta0, np.diag((0.01 * theta0) ** 2), p)
    for key in ("m_p", "d_x", "d_y", "I_p", "F_v1", "F_v2", "F_d1", "F_d2"):
        assert est.quantities[key].value == pytest.approx(getattr(p, key), rel=1e-12, abs=1e-14)
        assert getattr(est.parameters, key) == pytest.approx(getattr(p, key), rel=1e-12, abs=1e-14)
    assert est.quantities["m"].value == pytest.approx(p.m_p + 2 * p.m_w + 2 * p.m_r, rel=1e-12)
    # and the identified robot rebuilds the same base parameters
    np.testing.assert_allclose(dm.base_parameters(est.parameters), theta0, rtol=1e-12)


@pytest.mark.parametrize("name", ["paper", "amr"])
def test_covariance_matches_sampling(name):
    """The delta-method covariance against 200,000 Gaussian draws of theta0 pushed through the same equations, at
    0.1 % relative std (where the map is nearly linear): each std within 1 % (the sampling error of a std from
    2e5 draws is 0.16 %; the rest is the map's curvature) and each correlation within 0.01."""
    p = BUILTIN_ROBOTS[name].cad
    theta0 = dm.base_parameters(p)
    rng = np.random.default_rng(7)
    a = rng.normal(size=(8, 8))
    corr = np.corrcoef(a @ a.T + 8 * np.eye(8))
    sd = 0.001 * np.abs(theta0)
    cov0 = corr * np.outer(sd, sd)
    est = physical_from_base(theta0, cov0, p)
    draws = rng.multivariate_normal(theta0, cov0, size=200_000)
    samples = np.array([_values(d, p) for d in draws[:200]])  # the module on 200 draws ...
    big = _values_vectorised(draws, p)  # ... and all 2e5 through an independent vectorised twin, checked against it
    np.testing.assert_allclose(big[:200], samples, rtol=1e-9, atol=1e-12)
    emp = np.cov(big.T)
    model_std = np.sqrt(np.diag(est.cov))
    np.testing.assert_allclose(np.sqrt(np.diag(emp)), model_std, rtol=0.01)
    emp_corr = emp / np.outer(np.sqrt(np.diag(emp)), np.sqrt(np.diag(emp)))
    model_corr = est.cov / np.outer(model_std, model_std)
    np.testing.assert_allclose(emp_corr, model_corr, atol=0.01)


def _values(theta0, p):
    est = physical_from_base(theta0, np.eye(len(theta0)), p)
    return np.array([est.quantities[n].value for n in est.names])


def _values_vectorised(theta0, p):
    """The module docstring's equations written out again, independently, over many draws."""
    m11, m12, m22, vc = theta0[:, 0], theta0[:, 1], theta0[:, 2], theta0[:, 3]
    det = m11 * m22 - m12**2
    big11, big12, big22 = m22 / det, -m12 / det, m11 / det
    s = p.r**2 / (4 * p.b**2)
    spin = p.I_w + p.k_r**2 * p.I_r
    mass = ((big11 + big22) / 2 - spin + big12) / (2 * s * p.b**2)
    inertia = ((big11 + big22) / 2 - spin - big12) / (2 * s)
    my = -(big11 - big22) / (4 * s * p.b)
    mx = vc * 4 * p.b**2 / p.r**3
    m_p = mass - 2 * p.m_w - 2 * p.m_r
    d_x = (mx - 2 * p.m_r * p.c_x) / m_p
    d_y = my / m_p
    rest = 2 * (p.I_wm + p.m_w * p.a**2) + 2 * (p.I_rm + p.m_r * (p.c_x**2 + p.c_y**2))
    i_p = inertia - m_p * (d_x**2 + d_y**2) - rest
    return np.column_stack([mass, inertia, my, mx, m_p, d_x, d_y, i_p, theta0[:, 4:]])


def test_undetermined_friction_leaves_the_mass_determined():
    """A friction entry the log does not determine (NaN row, inf diagonal) makes only that quantity undetermined."""
    p = BUILTIN_ROBOTS["paper"].cad
    theta0 = dm.base_parameters(p)
    cov0 = np.diag((0.01 * theta0) ** 2)
    cov0[6, :] = cov0[:, 6] = np.nan
    cov0[6, 6] = np.inf
    est = physical_from_base(theta0, cov0, p)
    assert est.quantities["F_d1"].std == np.inf
    assert all(np.isfinite(est.quantities[n].std) for n in (*DETERMINED, *PLATFORM, "F_d2"))
    cov0 = np.diag((0.01 * theta0) ** 2)
    cov0[3, :] = cov0[:, 3] = np.nan
    cov0[3, 3] = np.inf
    est = physical_from_base(theta0, cov0, p)  # Vc undetermined: the first moment along and d_x, I_p with it
    assert {n for n in est.names if est.quantities[n].std == np.inf} == {"mp_dx", "d_x", "I_p"}


def test_json_round_trip():
    p = BUILTIN_ROBOTS["amr"].cad
    theta0 = dm.base_parameters(p)
    cov0 = np.diag((0.01 * theta0) ** 2)
    cov0[7, :] = cov0[:, 7] = np.nan
    cov0[7, 7] = np.inf
    est = physical_from_base(theta0, cov0, p)
    back = PhysicalEstimate.from_dict(json.loads(json.dumps(est.to_dict())))
    assert back.quantities == est.quantities
    assert back.parameters == est.parameters
    np.testing.assert_array_equal(np.isfinite(back.cov), np.isfinite(est.cov))
    np.testing.assert_allclose(back.cov[np.isfinite(est.cov)], est.cov[np.isfinite(est.cov)], rtol=0)


@pytest.mark.parametrize(
    ("change", "says"),
    [
        (lambda t: np.array([t[0], 2 * np.sqrt(t[0] * t[2]), *t[2:]]), "not positive definite"),
        (lambda t: np.concatenate([t[:3] * 5.0, t[3:]]), "not more than the robot file's wheels"),
        (lambda t: np.concatenate([_inverse_entries(1.45, 0.99 * 1.45, 1.45), t[3:]]), "yaw inertia .* not positive"),
    ],
    ids=["indefinite", "too-light", "inertia"],
)
def test_refuses_robots_no_one_can_build(change, says):
    """Indefinite M; a total mass below the file's wheels and rotors (m five times too small: a unit slip); M11 = M22 =
    1.45, M12 = 0.99 M11 (a yaw inertia about O below zero, as an M12 of the wrong sign can give)."""
    p = BUILTIN_ROBOTS["paper"].cad
    theta0 = change(dm.base_parameters(p))
    with pytest.raises(UsageError, match=says):
        physical_from_base(theta0, np.diag((0.01 * theta0) ** 2), p)


def _inverse_entries(a11, a12, a22):
    inv = np.linalg.inv([[a11, a12], [a12, a22]])
    return np.array([inv[0, 0], inv[0, 1], inv[1, 1]])


def test_platform_inertia_below_zero_is_refused():
    """A file whose wheels' centres of mass sit 1 m from O (a = 1 m, 2 m_w a^2 = 10 kg m^2) needs more yaw inertia
    than the identified I (about 5.5 kg m^2 beyond the platform's offset) holds."""
    p = BUILTIN_ROBOTS["paper"].cad
    theta0 = dm.base_parameters(p)
    wide = dataclasses.replace(p, a=1.0)
    with pytest.raises(UsageError, match=r"I_p = .* is negative"):
        physical_from_base(theta0, np.diag((0.01 * theta0) ** 2), wide)
