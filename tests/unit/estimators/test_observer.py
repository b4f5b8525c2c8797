"""The estimator (Eqs. 26-36): readable step, compiled kernel, and closed forms they must satisfy."""

from __future__ import annotations

import numpy as np
import pytest
from scipy import optimize, signal

from tests.open_loop import open_loop_log
from wmrid.estimators.observer.replay import replay
from wmrid.estimators.observer.settings import ObserverSettings
from wmrid.estimators.observer.step import foh_weights, initial_state, observer_step, project_to_box, substep_weights
from wmrid.model import dynamics as model
from wmrid.model.dynamics import RegressorForm
from wmrid.model.robot import PAPER_NOMINAL


def _settings(
    form: RegressorForm, alpha: float = 1e-3, k: float = 1.0, hold: str = "zoh", control_rate: float | None = None
) -> ObserverSettings:
    theta_init = model.intermediate_parameters(model.base_parameters(PAPER_NOMINAL), form)
    inf = np.full(theta_init.shape, np.inf)
    return ObserverSettings(
        form=form, theta_init=theta_init, theta_min=-inf, theta_max=inf, k=k, alpha=alpha, torque_hold=hold,
        control_rate=control_rate,
    )  # fmt: skip


def _reference_run(log, settings: ObserverSettings):
    state = initial_state(log.t[0], log.eta[0], log.tau[0], settings)
    errors = [state.e_prior]
    for i in range(1, len(log.t)):
        state = observer_step(state, log.t[i], log.eta[i], log.tau[i], settings)
        errors.append(state.e_prior)
    return state, np.array(errors)


@pytest.mark.parametrize("x", [1e-9, 1e-4, 0.0999999, 0.1, 0.1000001, 0.7, 5.0, 40.0])
def test_foh_weights_against_quadrature(x):
    # phi0 = int_0^1 exp(-x v) v dv, phi1 = int_0^1 exp(-x v) (1 - v) dv by 60-point Gauss-Legendre, exact to
    # rounding for these smooth integrands (the x = 40 integrand is smooth on [0, 1] too).
    a, phi0, phi1 = foh_weights(x)
    assert a == pytest.approx(np.exp(-x), rel=1e-15)
    nodes, weights = np.polynomial.legendre.leggauss(60)
    v = 0.5 * (nodes + 1)
    q0 = 0.5 * np.sum(weights * np.exp(-x * v) * v)
    q1 = 0.5 * np.sum(weights * np.exp(-x * v) * (1 - v))
    assert phi0 == pytest.approx(q0, rel=1e-13)
    assert phi1 == pytest.approx(q1, rel=1e-13)


@pytest.mark.parametrize("x", [1e-6, 0.01, 0.7, 5.0])
@pytest.mark.parametrize("m", [1, 2, 3, 10])
def test_substep_weights_against_quadrature_and_the_holds(x, m):
    # c0, c1 = int_0^h exp(-k (h - s)) (1 - j(s)/m, j(s)/m) ds with j(s) the sub-step index, by 60-point
    # Gauss-Legendre on each sub-step (exact to rounding: the integrand is smooth there).
    k, h = x / 1e-3, 1e-3
    c0, c1 = substep_weights(k, h, m)
    nodes, weights = np.polynomial.legendre.leggauss(60)
    q0 = q1 = 0.0
    for j in range(m):
        lo, hi = j * h / m, (j + 1) * h / m
        s = lo + (hi - lo) * 0.5 * (nodes + 1)
        integral = 0.5 * (hi - lo) * np.sum(weights * np.exp(-k * (h - s)))
        q0 += (1 - j / m) * integral
        q1 += (j / m) * integral
    assert c0 == pytest.approx(q0, rel=1e-12)
    assert c1 == pytest.approx(q1, rel=1e-12, abs=1e-300)
    _, phi0, phi1 = foh_weights(x)
    assert c0 + c1 == pytest.approx(h * (phi0 + phi1), rel=1e-12)  # the total weight of any hold
    if m == 1:
        assert c1 == 0.0  # one sub-step: the zero-order hold
    # m sub-steps approach the first-order hold as 1/m: the sub-step midpoints lag by h/(2m)
    assert abs(c1 - h * phi1) <= h / m + 1e-15


@pytest.mark.parametrize(
    ("reversing", "uneven", "hold", "control_rate"),
    [
        (False, False, "zoh", None), (False, True, "zoh", None), (True, False, "zoh", None),
        (True, True, "foh", None), (False, True, "zoh", 3300.0),
    ],
    ids=["paper-form", "uneven-steps", "general", "general-uneven-foh", "uneven-control-rate"],
)  # fmt: skip
def test_kernel_agrees_with_readable_step(reversing, uneven, hold, control_rate):
    log = open_loop_log(duration=2.0, reversing=reversing, uneven=uneven)
    form = model.choose_form(log.eta)
    assert form.kind == ("general" if reversing else "paper")
    settings = _settings(form, hold=hold, control_rate=control_rate)
    ref_state, ref_e = _reference_run(log, settings)
    out = replay(log.t, log.eta, log.tau, settings, max_history=len(log.t), chunk=777)
    # Same arithmetic, different order of a few sums: agreement to 1e-12 relative to the parameter scale.
    scale = np.max(np.abs(ref_state.theta))
    np.testing.assert_allclose(out.theta, ref_state.theta, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(out.gamma, ref_state.gamma, rtol=1e-12)
    np.testing.assert_allclose(
        out.gamma_inv, ref_state.gamma_inv, rtol=0, atol=1e-12 * np.max(np.abs(ref_state.gamma_inv))
    )
    np.testing.assert_allclose(out.hist_e, ref_e, rtol=0, atol=1e-12 * np.max(np.abs(log.eta)))


def test_chunk_size_does_not_change_the_result(smooth_log):
    settings = _settings(model.choose_form(smooth_log.eta))
    a = replay(smooth_log.t, smooth_log.eta, smooth_log.tau, settings, chunk=100_000)
    b = replay(smooth_log.t, smooth_log.eta, smooth_log.tau, settings, chunk=333)
    np.testing.assert_array_equal(a.theta, b.theta)
    np.testing.assert_array_equal(a.blk_c, b.blk_c)


@pytest.mark.parametrize("hold", ["zoh", "foh"])
def test_estimator_is_recursive_least_squares_in_closed_form(smooth_log, hold):
    """Gamma_N theta_N = alpha theta_0 + sum h w^T u with w, u built independently by scipy.signal.lsim.

    w = g filtered by 1/(s + k) and u = eta - eta_f, eta_f = eta filtered by k/(s + k), with
    first-order-hold input (lsim's interp=True), the torque columns zero-order hold (interp=False) under
    "zoh", zero initial state except eta_f(0) = eta(0).
    """
    log = smooth_log
    k, alpha = 1.0, 1e-3
    form = model.choose_form(log.eta)
    settings = _settings(form, alpha=alpha, k=k, hold=hold)
    g = model.regressor(log.eta, log.tau, form)
    lowpass = signal.lti([1.0], [1.0, k])
    w = np.stack(
        [signal.lsim(lowpass, g[:, j], log.t, interp=not (hold == "zoh" and j < 2))[1] for j in range(g.shape[1])],
        axis=1,
    )
    eta_f = np.stack(
        [
            signal.lsim(signal.StateSpace(-k, k, 1.0, 0.0), log.eta[:, r], log.t, X0=[log.eta[0, r]], interp=True)[1]
            for r in range(2)
        ],
        axis=1,
    )
    u = log.eta - eta_f
    h = np.diff(log.t)
    gamma = alpha * np.eye(g.shape[1]) + (w[1:] * h[:, None]).T @ w[1:]
    rhs = alpha * settings.theta_init.T + (w[1:] * h[:, None]).T @ u[1:]
    expected = np.linalg.solve(gamma, rhs).T
    out = replay(log.t, log.eta, log.tau, settings)
    # lsim's matrix exponential and our FOH weights agree to ~1e-15 per step; the solve amplifies by cond.
    np.testing.assert_allclose(out.gamma, gamma, rtol=1e-9)
    np.testing.assert_allclose(out.theta, expected, rtol=1e-7, atol=1e-9)


def test_error_decays_as_alpha_over_gamma(long_smooth_log):
    """Without disturbance theta_hat - theta = alpha Gamma^-1 (theta_0 - theta) (up to the O(h^2) hold error).

    This is why the paper's alpha = 5000 barely moves from the start on a 40 s log.  The open-loop log's
    torques are smooth functions of time, so they vary linearly between samples to O(h^2): "foh".
    """
    log = long_smooth_log
    form = model.choose_form(log.eta)
    truth = model.intermediate_parameters(log.theta0, form)
    for alpha in (1e-6, 1.0, 5000.0):
        settings = _settings(form, alpha=alpha, hold="foh")
        out = replay(log.t, log.eta, log.tau, settings)
        predicted = truth + alpha * np.linalg.solve(out.gamma, (settings.theta_init - truth).T).T
        # The first-order-hold error of the filters is O(h^2): measured 3.9e-7 of the parameter scale at
        # h = 1 ms and 9.9e-8 at 0.5 ms; 1e-6 leaves room for platform rounding, no more.
        np.testing.assert_allclose(out.theta, predicted, rtol=0, atol=1e-6 * np.max(np.abs(truth)))


def test_projection_is_the_box_constrained_quadratic_minimum():
    rng = np.random.default_rng(7)
    for _ in range(20):
        a = rng.normal(size=(7, 7))
        gamma = a @ a.T + 0.1 * np.eye(7)
        theta = rng.normal(size=(2, 7))
        lo, hi = -0.5 * np.ones((2, 7)), 0.5 * np.ones((2, 7))
        got = project_to_box(theta, gamma, lo, hi)
        assert np.all(got >= lo)
        assert np.all(got <= hi)
        for i in range(2):
            res = optimize.minimize(
                lambda x, i=i, th=theta, g=gamma: (x - th[i]) @ g @ (x - th[i]), np.zeros(7), bounds=[(-0.5, 0.5)] * 7,
                method="L-BFGS-B", options={"ftol": 1e-15, "gtol": 1e-12, "maxiter": 10_000},
            )  # fmt: skip
            cost = (got[i] - theta[i]) @ gamma @ (got[i] - theta[i])
            assert cost <= res.fun + 1e-9 * max(1.0, res.fun)


def test_projection_never_freezes():
    # Inside the box the projection is the identity; outside it is on the boundary; back inside it follows again.
    gamma = np.diag([1.0, 2.0, 3.0])
    lo, hi = np.zeros((1, 3)), np.ones((1, 3))
    path = [np.array([[0.5, 0.5, 0.5]]), np.array([[1.5, 0.5, -1.0]]), np.array([[0.25, 0.75, 0.5]])]
    out = [project_to_box(p, gamma, lo, hi) for p in path]
    np.testing.assert_array_equal(out[0], path[0])
    np.testing.assert_allclose(out[1], [[1.0, 0.5, 0.0]], atol=1e-12)
    np.testing.assert_array_equal(out[2], path[2])


def test_settings_are_validated():
    form = RegressorForm("paper")
    good = _settings(form)
    with pytest.raises(ValueError, match="k"):
        ObserverSettings(
            form=form, theta_init=good.theta_init, theta_min=good.theta_min, theta_max=good.theta_max, k=0.0
        )
    with pytest.raises(ValueError, match="alpha"):
        ObserverSettings(
            form=form, theta_init=good.theta_init, theta_min=good.theta_min, theta_max=good.theta_max, alpha=-1
        )
    with pytest.raises(ValueError, match="outside the box"):
        ObserverSettings(
            form=form, theta_init=good.theta_init, theta_min=good.theta_init + 1, theta_max=good.theta_init + 2
        )


def test_compiled_projection_matches_the_bounded_least_squares_reference():
    # Independent computation: scipy's BVLS on the Cholesky form of the same quadratic.
    from wmrid.estimators.observer.kernel import project_row_box

    rng = np.random.default_rng(7)
    for _ in range(500):
        p = int(rng.integers(2, 9))
        a = rng.standard_normal((p + 3, p)) * np.exp(rng.uniform(-3, 3, p))  # badly scaled columns
        gamma = a.T @ a
        x0 = 3.0 * rng.standard_normal(p)
        lo = rng.uniform(-2.0, 0.5, p)
        hi = lo + rng.uniform(0.1, 3.0, p)
        lo[rng.random(p) < 0.2] = -np.inf
        hi[rng.random(p) < 0.2] = np.inf
        got = np.empty(p)
        assert project_row_box(x0, gamma, lo, hi, got) >= 0
        ref = project_to_box(x0[None], gamma, lo[None], hi[None])[0]
        assert np.all(got >= lo)
        assert np.all(got <= hi)

        def objective(x, x0=x0, gamma=gamma):
            return (x - x0) @ gamma @ (x - x0)

        # The reference stops at BVLS's tolerance; the active-set answer is never worse than it.
        assert objective(got) <= objective(ref) * (1 + 1e-12) + 1e-300


def test_compiled_projection_leaves_interior_points_alone():
    from wmrid.estimators.observer.kernel import project_history_box

    theta = np.random.default_rng(1).uniform(-1, 1, (5, 2, 7))
    gamma = np.broadcast_to(np.eye(7), (5, 7, 7)).copy()
    out = np.empty_like(theta)
    project_history_box(theta, gamma, np.full((2, 7), -2.0), np.full((2, 7), 2.0), out)
    np.testing.assert_array_equal(out, theta)
