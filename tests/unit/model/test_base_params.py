"""Recovering theta0 from theta (Eq. 21 from Eqs. 23-24)."""

from __future__ import annotations

import numpy as np
import pytest

from wmrid.model import dynamics as model
from wmrid.model.base_params import derived_with_std, direct_recovery, fit_base_parameters, jacobian_intermediate
from wmrid.model.dynamics import RegressorForm
from wmrid.model.robot import PAPER_CAD

FORMS = [RegressorForm("paper"), RegressorForm("paper", (-1, 1)), RegressorForm("general")]


@pytest.mark.parametrize("form", FORMS, ids=["paper", "paper-left-backwards", "general"])
def test_exact_theta_gives_exact_theta0(form):
    theta0 = model.base_parameters(PAPER_CAD)
    theta = model.intermediate_parameters(theta0, form)
    np.testing.assert_allclose(direct_recovery(theta, form), theta0, rtol=1e-13)
    cov = np.diag((1e-4 * np.abs(theta.ravel()) + 1e-9) ** 2)
    fit = fit_base_parameters(theta, cov, form)
    np.testing.assert_allclose(fit.theta0, theta0, rtol=1e-10)
    assert fit.chi2 < 1e-12
    assert fit.dof == 2 * form.n_columns - 8


@pytest.mark.parametrize("form", FORMS, ids=["paper", "paper-left-backwards", "general"])
def test_jacobian_against_central_differences(form):
    theta0 = model.base_parameters(PAPER_CAD)
    jac = jacobian_intermediate(theta0, form)
    num = np.empty_like(jac)
    for j in range(8):
        step = 1e-6 * max(abs(theta0[j]), 1e-3)
        up, down = theta0.copy(), theta0.copy()
        up[j] += step
        down[j] -= step
        num[:, j] = (model.intermediate_parameters(up, form) - model.intermediate_parameters(down, form)).ravel() / (
            2 * step
        )
    # f is bilinear, so central differences are exact up to rounding (~1e-10 relative at this step).
    np.testing.assert_allclose(jac, num, rtol=1e-7, atol=1e-10)


def test_covariance_matches_monte_carlo():
    """Delta-method std of theta0 and of M = m^-1 against the spread of refits of perturbed theta."""
    form = RegressorForm("paper")
    theta0 = model.base_parameters(PAPER_CAD)
    theta = model.intermediate_parameters(theta0, form)
    rng = np.random.default_rng(11)
    sd = 1e-4 * np.abs(theta.ravel()) + 1e-7
    cov = np.diag(sd**2)
    fit = fit_base_parameters(theta, cov, form)
    derived = derived_with_std(fit.theta0, fit.cov)
    draws = []
    for _ in range(400):
        noisy = theta + (rng.normal(size=theta.size) * sd).reshape(theta.shape)
        refit = fit_base_parameters(noisy, cov, form)
        d = derived_with_std(refit.theta0, refit.cov)
        draws.append([d[n][0] for n in ("m11", "m12", "m22", "Vc", "Fv1", "Fd2", "M11", "M12", "M22")])
    spread = np.std(draws, axis=0, ddof=1)
    predicted = np.array([derived[n][1] for n in ("m11", "m12", "m22", "Vc", "Fv1", "Fd2", "M11", "M12", "M22")])
    # 400 draws: the sample std has a relative standard error of 1/sqrt(2 * 399) = 3.5 %; allow 4 of them.
    np.testing.assert_allclose(spread, predicted, rtol=0.14)


def test_inconsistent_theta_gives_large_mismatch():
    form = RegressorForm("paper")
    theta = model.intermediate_parameters(model.base_parameters(PAPER_CAD), form)
    bad = theta.copy()
    bad[1, 0] *= 1.2  # m21 != m12
    cov = np.diag((1e-4 * np.abs(theta.ravel())) ** 2)
    fit = fit_base_parameters(bad, cov, form)
    assert fit.p_value < 1e-6


@pytest.mark.parametrize("form", FORMS, ids=["paper", "paper-left-backwards", "general"])
def test_gauss_newton_matches_scipy_least_squares(form):
    from scipy.optimize import least_squares

    from wmrid.model.base_params import _whitener, gauss_newton

    rng = np.random.default_rng(11)
    theta = model.intermediate_parameters(model.base_parameters(PAPER_CAD), form)
    noisy = theta * (1 + 0.01 * rng.standard_normal(theta.shape))  # not of the model's form
    cov = np.diag((1e-3 * np.abs(theta.ravel()) + 1e-6) ** 2)
    whiten = _whitener(cov)
    start = direct_recovery(noisy, form)
    got = gauss_newton(start, whiten, noisy.ravel(), form)

    def residual(x):
        return whiten @ (model.intermediate_parameters(x, form).ravel() - noisy.ravel())

    ref = least_squares(residual, start, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15).x
    np.testing.assert_allclose(got, ref, rtol=1e-9)
    assert np.sum(residual(got) ** 2) <= np.sum(residual(ref) ** 2) * (1 + 1e-12)


def test_weighting_covariance_is_the_weights_own_information_inverse():
    """G W G^T with G the minimum-distance gain for the weights W (theta's covariance) is (J^T W^-1 J)^-1, the
    closed form (to 1e-8 relative); a parameter the reported covariance leaves undetermined stays so."""
    from wmrid.model.base_params import weighting_covariance

    form = RegressorForm("general")
    theta0 = model.base_parameters(PAPER_CAD)
    theta = model.intermediate_parameters(theta0, form)
    rng = np.random.default_rng(3)
    a = rng.normal(size=(theta.size, theta.size))
    weights = (a @ a.T / theta.size + np.eye(theta.size)) * 1e-8
    fit = fit_base_parameters(theta, weights, form)
    jac = jacobian_intermediate(fit.theta0, form)
    closed = np.linalg.inv(jac.T @ np.linalg.solve(weights, jac))
    out = weighting_covariance(fit.gain, weights, fit.cov)
    np.testing.assert_allclose(out, closed, rtol=1e-8, atol=1e-8 * np.max(np.abs(closed)))
    cov0 = fit.cov.copy()
    cov0[2, 2] = np.inf
    held = weighting_covariance(fit.gain, weights, cov0)
    assert held[2, 2] == np.inf
    assert np.isnan(held[2, 0])
    assert np.isnan(held[0, 2])
