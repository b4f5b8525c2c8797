"""wmrid plan's design layer (issue 29): the predicted covariance against a Monte Carlo of the same estimator, its
Jacobian against finite differences, the reference's closed forms, limits, determinism, and bad requests."""

from __future__ import annotations

import math

import numpy as np
import pytest

from wmrid.core.errors import UsageError
from wmrid.design.excitation import Basis, Excitation, pose_along, ramp
from wmrid.design.information import (
    SensorNoise,
    intermediate_covariance,
    intermediate_jacobian,
    lowpass,
    lowpass_adjoint,
    predicted_covariance,
)
from wmrid.design.limits import Limits, parse_area, resolve_limits
from wmrid.model import dynamics as d, torques
from wmrid.model.robot import PAPER_CAD

THETA0 = d.base_parameters(PAPER_CAD)
GENERAL = d.RegressorForm("general")


def _motion(duration: float = 10.0, rate: float = 100.0):
    """A smooth reversing motion of the paper robot: eta (n, 2) rad/s, tau (n, 2) N m (inverse dynamics), h s."""
    t = np.arange(int(duration * rate) + 1) / rate
    v = 0.6 * np.sin(2 * np.pi * t / 5.0) * np.sin(np.pi * t / duration)
    w = 1.2 * np.sin(2 * np.pi * t / 3.1 + 0.4) * np.sin(np.pi * t / duration)
    dv = np.gradient(v, t)
    dw = np.gradient(w, t)
    eta = np.stack([(v + PAPER_CAD.b * w) / PAPER_CAD.r, (v - PAPER_CAD.b * w) / PAPER_CAD.r], axis=1)
    deta = np.stack([(dv + PAPER_CAD.b * dw) / PAPER_CAD.r, (dv - PAPER_CAD.b * dw) / PAPER_CAD.r], axis=1)
    return eta, torques.wheel_torque(eta, deta, THETA0), 1.0 / rate


def test_jacobian_matches_finite_differences():
    """The complex-step Jacobian of the intermediate parameters agrees with central differences (relative 1e-6:
    the differences' truncation error at a step of 1e-6 relative is ~1e-12, their rounding ~1e-10)."""
    for form in (GENERAL, d.RegressorForm("general", caster=True), d.RegressorForm("paper", (1, 1))):
        theta0 = np.concatenate([THETA0, [0.05, 0.02][: form.n_base - 8]])
        jac = intermediate_jacobian(theta0, form)
        num = np.empty_like(jac)
        for i in range(len(theta0)):
            step = 1e-6 * max(abs(theta0[i]), 1e-3)
            up, down = theta0.copy(), theta0.copy()
            up[i] += step
            down[i] -= step
            num[:, i] = (d.intermediate_parameters(up, form) - d.intermediate_parameters(down, form)).ravel() / (
                2 * step
            )
        assert np.allclose(jac, num, rtol=1e-6, atol=1e-9 * np.max(np.abs(jac)))


def test_adjoint_is_the_transpose_of_the_lowpass():
    """<L x, y> = <x, L^T y> for random sequences (to rounding)."""
    rng = np.random.Generator(np.random.PCG64(1))
    x, y = rng.standard_normal((500, 3)), rng.standard_normal((500, 3))
    a = math.exp(-0.1)
    assert np.sum(lowpass(x, a) * y) == pytest.approx(np.sum(x * lowpass_adjoint(y, a)), rel=1e-12)


def test_covariance_matches_a_monte_carlo_of_the_estimator():
    """The intermediate estimate's covariance from the adjoint filters against 400 noisy replays of the same
    least-squares estimator (forward filters, the noise in the regressor's columns and in u): each std within 15 %
    (the Monte Carlo's own spread on a std from 400 draws is 3.5 %; the formula drops second-order terms of the
    noise, about 1 % here), and the base parameters' too."""
    eta, tau, h = _motion()
    noise = SensorNoise(eta_std=0.01, tau_std=0.05, rate=1.0 / h)
    k = 10.0
    cov, _ = intermediate_covariance(eta, tau, h, THETA0, GENERAL, noise, k)
    a = math.exp(-k * h)
    theta_true = d.intermediate_parameters(THETA0, GENERAL)
    rng = np.random.Generator(np.random.PCG64(7))
    draws = []
    for _ in range(400):
        eta_n = eta + noise.eta_std * rng.standard_normal(eta.shape)
        tau_n = tau + noise.tau_std * rng.standard_normal(tau.shape)
        w = lowpass(d.regressor(eta_n, tau_n, GENERAL), a) / k
        u = eta_n - lowpass(eta_n, a)
        theta = np.linalg.solve(w.T @ w, w.T @ u).T  # (2, p)
        draws.append((theta - theta_true).ravel())
    mc = np.cov(np.array(draws).T)
    ratio = np.sqrt(np.diag(mc) / np.diag(cov))
    assert np.all(np.abs(ratio - 1.0) < 0.15), ratio
    base = predicted_covariance(eta, tau, h, THETA0, GENERAL, noise, k)
    jac = intermediate_jacobian(THETA0, GENERAL)
    gain = np.linalg.solve(jac.T @ np.linalg.solve(cov, jac), jac.T @ np.linalg.inv(cov))
    base_mc = gain @ mc @ gain.T
    assert np.all(np.abs(np.sqrt(np.diag(base_mc) / np.diag(base)) - 1.0) < 0.15)


def test_covariance_scales_with_noise_intensity_not_grid():
    """The same motion and noise intensity on a grid twice as coarse gives nearly the same covariance (the
    discretisation of the k = 10 1/s filter at 50 vs 100 Hz: within 12 %), and four times the effort noise variance
    per sample gives four times the covariance."""
    eta, tau, h = _motion(rate=100.0)
    noise = SensorNoise(0.01, 0.05, 100.0)
    fine = predicted_covariance(eta, tau, h, THETA0, GENERAL, noise)
    coarse = predicted_covariance(eta[::2], tau[::2], 2 * h, THETA0, GENERAL, noise)
    assert np.all(np.abs(np.sqrt(np.diag(coarse) / np.diag(fine)) - 1.0) < 0.12)
    # effort noise alone enters linearly; speed noise also sets how often the measured sign flips near standstill
    quiet = predicted_covariance(eta, tau, h, THETA0, GENERAL, SensorNoise(0.0, 0.05, 100.0))
    louder = predicted_covariance(eta, tau, h, THETA0, GENERAL, SensorNoise(0.0, 0.1, 100.0))
    assert np.allclose(louder, 4.0 * quiet, rtol=1e-9)


def test_reference_starts_and_ends_at_rest_and_derivatives_are_exact():
    """v, w and their derivatives are 0 at both ends; v' and w' agree with a central difference of v and w (the
    product rule with the ramp); the ramp is the quintic smoothstep."""
    rng = np.random.Generator(np.random.PCG64(3))
    exc = Excitation(24.0, 12.0, rng.standard_normal((2, 6, 2)), ramp=2.0)
    t = np.linspace(0.0, 24.0, 24001)
    v, w, dv, dw = exc.evaluate(t)
    for x in (v, w, dv, dw):
        assert abs(x[0]) < 1e-12
        assert abs(x[-1]) < 1e-9
    assert np.allclose(dv[1:-1], (v[2:] - v[:-2]) / (2e-3), atol=1e-5 * np.max(np.abs(dv)))
    assert np.allclose(dw[1:-1], (w[2:] - w[:-2]) / (2e-3), atol=1e-5 * np.max(np.abs(dw)))
    s, ds = ramp(np.array([0.0, 0.5, 1.0]))
    assert s.tolist() == [0.0, 0.5, 1.0]
    assert (ds[0], ds[2]) == (0.0, 0.0)
    assert Excitation.from_dict(exc.to_dict()).coefficients.tolist() == exc.coefficients.tolist()


def test_pose_integration_converges():
    """The trapezoid pose on a 50 Hz grid is within 1 mm of a 2 kHz one over a 24 s plan."""
    rng = np.random.Generator(np.random.PCG64(4))
    coef = 0.2 * rng.standard_normal((2, 6, 2))
    poses = []
    for rate in (50.0, 2000.0):
        t = np.linspace(0.0, 24.0, int(24 * rate) + 1)
        v, w, _, _ = Basis(t, 24.0, 12.0, 6, 2.0).signals(coef)
        poses.append(pose_along(t, v, w)[-1])
    assert np.max(np.abs(poses[0][:2] - poses[1][:2])) < 1e-3


def test_limits_from_flags_file_and_defaults():
    limits = resolve_limits(0.16, {"max_torque": 12.0, "area": (3.0, 2.0)}, max_wheel_speed=5.0)
    assert (limits.max_wheel_speed, limits.sources["max_wheel_speed"]) == (5.0, "flag")
    assert (limits.max_torque, limits.sources["max_torque"]) == (12.0, "robot file")
    assert limits.max_wheel_accel == pytest.approx(1.0 / 0.16)
    assert limits.sources["max_wheel_accel"] == "default"
    assert limits.area == (3.0, 2.0)
    assert Limits.from_dict(limits.to_dict()) == limits
    assert parse_area("6x3.5") == (6.0, 3.5)
    for bad in ("4", "4x", "0x3", "ax3", "-1x2"):
        with pytest.raises(UsageError, match="area"):
            parse_area(bad)
    with pytest.raises(UsageError, match="max_torque"):
        resolve_limits(0.16, {}, max_torque=-1.0)
    with pytest.raises(UsageError, match="too small for the robot"):
        resolve_limits(0.16, {}, area=(0.5, 0.5), footprint=0.3)


#: The paper robot's two ball casters (0.25 m fore and aft: one geometric drag parameter) whose drag follows the load.
CASTER_LOAD = d.RegressorForm("general", caster=True, geometry=(PAPER_CAD.r, PAPER_CAD.b, 0.25, 0.0),
                              load=("dv", "w2"))  # fmt: skip


@pytest.mark.parametrize(
    ("criterion", "friction"),
    [("worst", "wheel"), ("d", "wheel"), ("a", "wheel"), ("worst", "wheel+caster+load"), ("d", "wheel+caster+load")],
)
def test_search_gradients_match_finite_differences(criterion: str, friction: str) -> None:
    """The analytic gradient of the search's objective (reverse mode through the predicted covariance, combined
    with a given log's) and the Jacobian of its sample constraints agree with central differences: relative 1e-5 of
    the largest entry (observed 2e-6 with the casters' drag, 3e-7 without; the differences' own error at a step of 1e-5
    is ~1e-7, at 1e-6 their rounding showed 2e-5).  With the casters'
    drag that follows the load, the drag's columns turn with the motion and its nominal force is in the efforts."""
    from wmrid.design.information import GivenLogs
    from wmrid.design.plan import _problem
    from wmrid.design.problem import Differentiated
    from wmrid.design.search import largest_scale, random_shape, sample_constraints

    form = GENERAL if friction == "wheel" else CASTER_LOAD
    theta0 = np.concatenate([THETA0, [4.0, -0.4, 0.05][: form.n_base - 8]])
    n0 = len(theta0)
    # a given log combined by a weight that is not its inverse covariance (the general sandwich)
    weight = np.diag(1.0 / (0.01 * np.abs(theta0) + 1e-3) ** 2)
    corr = 0.3 ** np.abs(np.subtract.outer(np.arange(n0), np.arange(n0)))
    cov = 1.7 * np.sqrt(np.linalg.inv(weight)) @ corr @ np.sqrt(np.linalg.inv(weight))
    given = GivenLogs(weight, weight @ cov @ weight)
    limits = resolve_limits(PAPER_CAD.r, {}, max_torque=20.0, footprint=0.56)
    noise = SensorNoise(0.02, 0.05, 1000.0)
    pb = _problem(theta0, form, PAPER_CAD.r, PAPER_CAD.b, limits, noise, 24.0, 20.0, criterion, given, 10.0)
    rng = np.random.Generator(np.random.PCG64(0))
    coef = random_shape(pb, rng)
    x = (coef * largest_scale(pb, coef)).ravel()
    diff = Differentiated(pb)
    _, grad = diff.objective(x)
    jac = diff.constraint_jacobian(x)
    num, num_jac = np.zeros_like(grad), np.zeros_like(jac)
    for i in range(x.size):
        step = 1e-5 * max(abs(x[i]), 1e-3)
        up, down = x.copy(), x.copy()
        up[i] += step
        down[i] -= step
        num[i] = (diff.objective(up)[0] - diff.objective(down)[0]) / (2 * step)
        c_up = sample_constraints(pb, pb.motion_of(up.reshape(2, -1, 2)))
        c_down = sample_constraints(pb, pb.motion_of(down.reshape(2, -1, 2)))
        num_jac[:, i] = (c_up - c_down) / (2 * step)
    assert np.max(np.abs(grad - num)) < 1e-5 * np.max(np.abs(num))
    # rows whose quantity sits at a kink of |q| (a sign change within the step) are left out
    rows = np.max(np.abs(jac), axis=1) > 1e-6 * np.max(np.abs(jac))
    assert np.max(np.abs(jac[rows] - num_jac[rows])) < 1e-4 * np.max(np.abs(num_jac))


def test_sign_flips_near_standstill_cost_information():
    """A wheel crawling within the speed noise of standstill says little about its Coulomb friction: the measured
    sign's mean is erf(eta / (sqrt(2) sigma)) and it flips with std sqrt(1 - erf^2) (checked against 20,000 draws),
    and the predicted std of F_d grows by more than half when the speed noise grows from 0.001 to 0.05 rad/s on a
    motion that dwells near zero."""
    from wmrid.design.information import sign_statistics

    rng = np.random.Generator(np.random.PCG64(2))
    eta = np.array([[0.0, 0.01], [0.02, -0.03], [0.05, 0.2]])
    mean, sd, _ = sign_statistics(eta, 0.02)
    draws = np.sign(eta[None] + 0.02 * rng.standard_normal((20000, *eta.shape)))
    assert np.allclose(draws.mean(axis=0), mean, atol=0.02)
    assert np.allclose(draws.std(axis=0), sd, atol=0.02)
    e, _, h = _motion()
    slow = e * 0.05  # the same motion, 20 times slower: much of it within a few sigma of standstill
    tau = torques.wheel_torque(slow, np.gradient(slow, h, axis=0), THETA0)
    fd = []
    for sigma in (0.001, 0.05):
        cov = predicted_covariance(slow, tau, h, THETA0, GENERAL, SensorNoise(sigma, 0.05, 100.0))
        fd.append(np.sqrt(cov[6, 6]))
    assert fd[1] > 1.5 * fd[0]


def test_flips_of_the_centred_mean_sign_match_a_monte_carlo() -> None:
    """The estimator takes its signs from a 20 ms centred mean of the speeds (:mod:`wmrid.estimators.sign_speed`):
    at 1 kHz its noise is 4.6 times smaller, but a flip lasts as long as the mean's noise keeps its sign.  On a slow
    reversing motion with speed noise 0.05 rad/s (the Coulomb flips then dominate F_d's std), 300 replays of the
    least-squares estimator with those signs: the F_d entries' std within 15 % of the prediction (the Monte
    Carlo's own spread: 4 %), every entry within 20 % (at this speed noise the second-order terms the formula drops
    move the V_c entries by up to 16 %, measured).  Modelling the flips as white, sample by sample, as the
    prediction did before, would overstate F_d's information: those entries' Monte Carlo std is 0.49-0.78 of it."""
    from wmrid.estimators.sign_speed import centred_mean

    class WhiteFlips(SensorNoise):
        @property
        def sign_std(self) -> float:
            return self.eta_std

        @property
        def flip_intensity(self) -> float:
            return 1.0

    eta, _, h = _motion(duration=6.0, rate=1000.0)
    slow = 0.1 * eta
    tau = torques.wheel_torque(slow, np.gradient(slow, h, axis=0), THETA0)
    noise, k = SensorNoise(0.05, 0.002, 1000.0), 10.0
    cov, _ = intermediate_covariance(slow, tau, h, THETA0, GENERAL, noise, k)
    white, _ = intermediate_covariance(slow, tau, h, THETA0, GENERAL, WhiteFlips(0.05, 0.002, 1000.0), k)
    a, half = math.exp(-k * h), (noise.sign_window - 1) // 2
    theta_true = d.intermediate_parameters(THETA0, GENERAL)
    rng = np.random.Generator(np.random.PCG64(7))
    draws = []
    for _ in range(300):
        eta_n = slow + noise.eta_std * rng.standard_normal(slow.shape)
        g = d.regressor(eta_n, tau + noise.tau_std * rng.standard_normal(tau.shape), GENERAL)
        g[:, 6:8] = -np.sign(centred_mean(eta_n, half))
        w = lowpass(g, a) / k
        theta = np.linalg.solve(w.T @ w, w.T @ (eta_n - lowpass(eta_n, a))).T
        draws.append((theta - theta_true).ravel())
    mc = np.diag(np.cov(np.array(draws).T))
    coulomb = [6, 7, 14, 15]
    ratio = np.sqrt(mc / np.diag(cov))
    assert np.all(np.abs(ratio[coulomb] - 1.0) < 0.15), ratio
    assert np.all(np.abs(ratio - 1.0) < 0.2), ratio
    assert np.max(np.sqrt(mc / np.diag(white))[coulomb]) < 0.85


def test_given_logs_combine_by_a_sandwich() -> None:
    """A given log's estimate combined with the planned log's by fixed weights: the combination's covariance is
    (W + I)^-1 (W C W + I) (W + I)^-1, the textbook (C^-1 + I)^-1 when W = C^-1, and the weight of a covariance with
    few degrees of freedom shrinks its correlations (none when the degrees of freedom are unknown)."""
    from wmrid.design.information import GivenLogs, combined_covariance
    from wmrid.estimators.combination import given_weight

    rng = np.random.Generator(np.random.PCG64(3))
    a, b = rng.normal(size=(8, 8)), rng.normal(size=(8, 8))
    cov, info = a @ a.T + 0.1 * np.eye(8), b @ b.T + 0.1 * np.eye(8)
    weight = np.diag(1.0 / np.diag(cov))
    k1 = np.linalg.solve(weight + info, weight)
    k2 = np.linalg.solve(weight + info, info)
    direct = k1 @ cov @ k1.T + k2 @ np.linalg.inv(info) @ k2.T
    np.testing.assert_allclose(combined_covariance(info, GivenLogs(weight, weight @ cov @ weight)), direct,
                               rtol=1e-9, atol=1e-12)  # fmt: skip
    textbook = np.linalg.inv(np.linalg.inv(cov) + info)
    np.testing.assert_allclose(combined_covariance(info, GivenLogs.information(np.linalg.inv(cov))), textbook,
                               rtol=1e-8, atol=1e-12)  # fmt: skip
    np.testing.assert_allclose(given_weight(cov, None), np.linalg.inv(cov), rtol=1e-8, atol=1e-10)
    d = np.sqrt(np.diag(cov))
    shrunk = np.linalg.inv(given_weight(cov, 9)) / np.outer(d, d)
    corr = cov / np.outer(d, d)
    off = ~np.eye(8, dtype=bool)
    lam = 1.0 - shrunk[off] / corr[off]
    assert np.allclose(lam, lam[0])
    assert 0.0 < lam[0] < 1.0
    np.testing.assert_allclose(np.diag(shrunk), 1.0)
