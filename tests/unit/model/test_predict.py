"""Tests of the validation predictor (wmrid.model.predict), each against an independent computation."""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from tests.open_loop import open_loop_log
from wmrid.core.errors import UsageError
from wmrid.model import dynamics as model, torques
from wmrid.model.predict import MAX_STEP, fit_percent, simulate_segments, simulate_speeds, validation_fit
from wmrid.model.robot import PAPER_CAD, PAPER_NOMINAL

THETA_CAD = model.base_parameters(PAPER_CAD)


def _rhs(theta0: np.ndarray, torque):
    def rhs(t, y):
        return torques.wheel_acceleration(y[None, :], torque(t)[None, :], theta0)[0]

    return rhs


def _per_interval(t, tau, theta0, eta0, hold):
    """solve_ivp (DOP853, rtol 1e-12) interval by interval, the torque held or linear within each."""
    out = [np.asarray(eta0, dtype=float)]
    for k in range(t.size - 1):
        t0, t1 = t[k], t[k + 1]
        if hold == "zoh":

            def torque(_s, k=k):
                return tau[k]

        else:

            def torque(s, k=k, t0=t0, t1=t1):
                return tau[k] + (s - t0) / (t1 - t0) * (tau[k + 1] - tau[k])

        sol = solve_ivp(_rhs(theta0, torque), (t0, t1), out[-1], method="DOP853", rtol=1e-12, atol=1e-13)
        out.append(sol.y[:, -1])
    return np.array(out)


def _smooth_log(dt: float, duration: float, seed: int):
    """Uneven sample times around dt, smooth positive torques keeping both wheels turning forward."""
    rng = np.random.default_rng(seed)
    t = np.concatenate([[0.0], np.cumsum(rng.uniform(0.6 * dt, 1.4 * dt, round(duration / dt)))])
    tau = np.stack([1.2 + 0.8 * np.sin(1.3 * t), 1.0 + 0.7 * np.sin(0.9 * t + 1) + 0.3 * np.sin(2.3 * t)], axis=1)
    return t, tau


# ------------------------------------------------------------------------------------ integration


@pytest.mark.parametrize("hold", ["zoh", "foh"])
def test_matches_solve_ivp_per_interval(hold: str) -> None:
    # A 100 Hz uneven log, 2 s, wheels at 3-6.6 rad/s (no sign change, so Eq. (20) is smooth within each
    # interval).  The predictor takes ceil(dt / 1 ms) RK4 substeps: global error ~ h^4 |eta^(5)| ~ 1e-13
    # here (the dynamics' rates are below 1 1/s); DOP853 at rtol 1e-12 on values <= 7 rad/s adds ~1e-11.
    # 1e-9 rad/s leaves room for both (observed: 1.3e-14) and catches any difference in how the torque is
    # held (zoh and foh differ by 3.4e-3 rad/s here).
    t, tau = _smooth_log(1e-2, 2.0, seed=3)
    eta0 = [3.0, 3.5]
    ref = _per_interval(t, tau, THETA_CAD, eta0, hold)
    got = simulate_speeds(t, tau, THETA_CAD, eta0, torque_hold=hold)
    assert np.abs(got - ref).max() < 1e-9
    other = simulate_speeds(t, tau, THETA_CAD, eta0, torque_hold="foh" if hold == "zoh" else "zoh")
    assert np.abs(other - ref).max() > 1e-4


def test_matches_continuous_torque_log_with_foh() -> None:
    # The shared open-loop log (DOP853 at rtol 1e-11 with the torque as a smooth function of time) sampled
    # at 1 kHz: linear interpolation of the torque is off by dt^2 / 8 |tau''| ~ 4e-7 N m, which through the
    # near-integrator dynamics (m ~ 0.8) over 5 s gives ~1e-6 rad/s; the zoh reading lags by dt / 2 and
    # is off by ~5e-4 rad/s (observed 2.2e-7 and 5.6e-4).
    log = open_loop_log()
    foh = simulate_speeds(log.t, log.tau, log.theta0, log.eta[0], torque_hold="foh")
    zoh = simulate_speeds(log.t, log.tau, log.theta0, log.eta[0], torque_hold="zoh")
    assert np.abs(foh - log.eta).max() < 2e-6
    assert 1e-4 < np.abs(zoh - log.eta).max() < 2e-3


def test_substep_count_does_not_matter_at_log_rate() -> None:
    # RK4 at h = 1 ms versus 0.1 ms on the paper robot: the step is far below the dynamics' time scales.
    t, tau = _smooth_log(1e-3, 3.0, seed=4)
    a = simulate_speeds(t, tau, THETA_CAD, [2.0, 2.0])
    b = simulate_speeds(t, tau, THETA_CAD, [2.0, 2.0], max_step=1e-4)
    assert MAX_STEP == 1e-3
    assert np.abs(a - b).max() < 1e-11


def test_zoh_closed_form_decoupled() -> None:
    # m12 = 0 and Vc = 0 decouple the wheels; with the speed kept positive, each interval with torque
    # tau[k] held has eta(t_k + s) = (eta_k - u/Fv) exp(-m Fv s) + u/Fv, u = tau[k] - Fd.
    theta0 = np.array([0.8, 0.0, 0.6, 0.0, 0.05, 0.08, 0.1, 0.2])
    rng = np.random.default_rng(7)
    t = np.concatenate([[0.0], np.cumsum(rng.uniform(0.002, 0.05, 300))])
    tau = rng.uniform(0.3, 1.5, (t.size, 2))  # piecewise constant, above the Coulomb level: no stop
    got = simulate_speeds(t, tau, theta0, [1.0, 0.5], torque_hold="zoh")
    m = np.array([theta0[0], theta0[2]])
    fv, fd = theta0[4:6], theta0[6:8]
    exact = np.empty_like(got)
    exact[0] = [1.0, 0.5]
    for k in range(t.size - 1):
        u = tau[k] - fd
        exact[k + 1] = (exact[k] - u / fv) * np.exp(-m * fv * (t[k + 1] - t[k])) + u / fv
    assert np.all(exact > 0)
    # RK4 with h <= 1 ms on rates m Fv <= 0.05 1/s: relative error ~ (m Fv h)^4, nothing but round-off.
    assert np.abs(got - exact).max() < 1e-11 * np.abs(exact).max()


# ------------------------------------------------------------------------------ zero speed (Coulomb)

DECOUPLED = np.array([0.8, 0.0, 0.7, 0.0, 0.05, 0.03, 0.2, 0.15])  # m1 Fv1 = 0.04 1/s, Fd1 = 0.2 N m


def _decay(eta0: float, u: float, s):
    """Decoupled wheel 1: eta(s) with net constant torque u (N m) from eta0 (closed form)."""
    m, fv = DECOUPLED[0], DECOUPLED[4]
    return (eta0 - u / fv) * np.exp(-m * fv * s) + u / fv


def _zero_time(eta0: float, u: float) -> float:
    m, fv = DECOUPLED[0], DECOUPLED[4]
    return math.log((eta0 - u / fv) / (-u / fv)) / (m * fv)


def test_braking_below_coulomb_level_stops_and_stays() -> None:
    # Torque 0.5 Fd1 against a forward-turning wheel: it slows to exactly 0 at t* (closed form) and, the
    # net torque being below Fd1, stays there (no reversal, no chattering).
    t = np.arange(3001) * 1e-3
    tau = np.zeros((t.size, 2))
    tau[:, 0] = 0.1
    tau[:, 1] = 1.0
    got = simulate_speeds(t, tau, DECOUPLED, [0.2, 2.0])
    u = 0.1 - DECOUPLED[6]
    t_stop = _zero_time(0.2, u)
    assert 1.0 < t_stop < 2.5
    exact = np.where(t < t_stop, _decay(0.2, u, t), 0.0)
    assert np.abs(got[:, 0] - exact).max() < 1e-12
    assert np.all(got[t > t_stop, 0] == 0.0)
    # The other wheel is unaffected (decoupled): its own closed form with u = 1 - Fd2.
    m2, fv2, u2 = DECOUPLED[2], DECOUPLED[5], 1.0 - DECOUPLED[7]
    assert np.abs(got[:, 1] - ((2.0 - u2 / fv2) * np.exp(-m2 * fv2 * t) + u2 / fv2)).max() < 1e-12


def test_reversal_locates_the_zero_crossing() -> None:
    # Torque -2 Fd1: the wheel brakes with u1 = tau - Fd1 to 0 at t*, then turns backwards with
    # u2 = tau + Fd1.  The crossing is located within the substep, so the closed form holds to round-off
    # on both sides (an unlocated crossing would be off by ~Fd1 m h ~ 1e-4 rad/s).
    t = np.arange(1501) * 1e-3
    tau = np.zeros((t.size, 2))
    tau[:, 0] = -0.4
    tau[:, 1] = 1.0
    got = simulate_speeds(t, tau, DECOUPLED, [0.3, 2.0])
    u1, u2 = -0.4 - 0.2, -0.4 + 0.2
    t_zero = _zero_time(0.3, u1)
    assert 0.4 < t_zero < 0.9
    exact = np.where(t < t_zero, _decay(0.3, u1, t), _decay(0.0, u2, t - t_zero))
    assert np.abs(got[:, 0] - exact).max() < 1e-12
    assert got[-1, 0] < -0.1


def test_breakaway_from_rest_on_a_ramp() -> None:
    # At rest, torque ramping as c t (foh): held until c t reaches Fd1 at t_b, then eta' + a eta = m c s
    # with s = t - t_b, so eta = (m c / a) (s - (1 - exp(-a s)) / a), a = m Fv1.  Breakaway is checked at
    # substep starts, late by at most one substep h when the excess torque is still ~c h: bound m c h^2
    # (8e-7 rad/s; observed 1.0e-7).
    c = 1.0
    t = np.arange(1001) * 1e-3
    tau = np.stack([c * t, np.zeros_like(t)], axis=1)
    got = simulate_speeds(t, tau, DECOUPLED, [0.0, 0.0], torque_hold="foh")
    m, fv, fd = DECOUPLED[0], DECOUPLED[4], DECOUPLED[6]
    a = m * fv
    s = np.clip(t - fd / c, 0.0, None)
    exact = (m * c / a) * (s - (1.0 - np.exp(-a * s)) / a)
    assert np.abs(got[:, 0] - exact).max() < m * c * 1e-6
    assert np.all(got[t <= fd / c, 0] == 0.0)
    assert np.all(got[:, 1] == 0.0)  # wheel 2 has no torque at all: stays at rest


def test_both_wheels_at_rest_under_small_torques() -> None:
    # Coupled paper robot, torques oscillating below the Coulomb levels and Vc (eta = 0): nothing moves.
    theta0 = THETA_CAD.copy()
    t = np.arange(2001) * 1e-3
    tau = np.stack([0.03 * np.sin(5 * t), 0.025 * np.cos(3 * t)], axis=1)  # |tau_j| < Fd_j = 0.045, 0.04
    got = simulate_speeds(t, tau, theta0, [0.0, 0.0], torque_hold="foh")
    assert np.all(got == 0.0)


def test_coupled_wheel_sticks_while_the_other_turns() -> None:
    # Inertia coupling (m12 != 0) and Vc: wheel 1, unpowered, brakes to rest while wheel 2 keeps turning.
    # Reference: solve_ivp on Eq. (20) until eta_1 = 0 (event), then on the constrained dynamics eta_1 = 0,
    # M22 eta_2' = tau_2 - V_2 - Fv2 eta_2 - Fd2 (V_2 = 0 at eta_1 = 0).  The scenario is valid only if the
    # holding friction f1 = tau_1 + Vc eta_2^2 - M12 eta_2' stays within [-Fd1, Fd1]: checked.
    theta0 = np.array([0.8, 0.24, 0.74, 0.21, 0.01, 0.015, 0.5, 0.04])
    big_m = np.linalg.inv(model.inverse_inertia(theta0))
    t = np.arange(4001) * 1e-3
    tau = np.zeros((t.size, 2))
    tau[:, 1] = 0.1
    got = simulate_speeds(t, tau, theta0, [0.3, 1.0])

    def full(_s, y):
        return torques.wheel_acceleration(y[None, :], tau[:1], theta0)[0]

    def hit(_s, y):
        return y[0]

    hit.terminal = True
    hit.direction = -1
    first = solve_ivp(full, (0, t[-1]), [0.3, 1.0], method="DOP853", rtol=1e-12, atol=1e-13, events=hit)
    t_stop = float(first.t_events[0][0])
    assert 0.2 < t_stop < 3.0

    def constrained(_s, y):
        e2 = y[0]
        return [(0.1 - theta0[5] * e2 - theta0[7]) / big_m[1, 1]]

    second = solve_ivp(constrained, (t_stop, t[-1]), [first.y_events[0][0][1]], method="DOP853", rtol=1e-12,
                       atol=1e-13, dense_output=True)  # fmt: skip
    before = t < t_stop
    phase1 = solve_ivp(full, (0, t_stop), [0.3, 1.0], method="DOP853", rtol=1e-12, atol=1e-13, t_eval=t[before])
    exact = np.zeros_like(got)
    exact[before] = phase1.y.T
    exact[~before, 1] = second.sol(t[~before])[0]
    e2 = exact[~before, 1]
    a2 = (0.1 - theta0[5] * e2 - theta0[7]) / big_m[1, 1]
    hold = theta0[3] * e2**2 - big_m[0, 1] * a2
    assert np.all(np.abs(hold) < theta0[6])
    # The only approximation beyond RK4 is the crossing location (regula falsi to ~1e-13 of a step);
    # observed 4e-12 rad/s.
    assert np.abs(got - exact).max() < 1e-9
    assert np.all(got[~before, 0] == 0.0)


# ------------------------------------------------------------------------------------- segments


def test_segments_restart_from_the_measured_speed() -> None:
    t, tau = _smooth_log(1e-3, 3.0, seed=5)
    eta = np.random.default_rng(1).uniform(1.0, 3.0, (t.size, 2))
    starts = np.array([0, 700, 1900])
    got = simulate_segments(t, tau, THETA_CAD, eta, starts, torque_hold="foh")
    for a, b in zip(starts, [*starts[1:], t.size], strict=True):
        alone = simulate_speeds(t[a:b], tau[a:b], THETA_CAD, eta[a], torque_hold="foh")
        # The last sample of a segment uses tau[b] under foh; compare the samples before the next restart.
        np.testing.assert_array_equal(got[a:b], alone)


# ------------------------------------------------------------------------------------- fit


def test_fit_percent_hand_values() -> None:
    y = np.array([[1.0, 2.0], [2.0, 2.0], [3.0, 2.0], [4.0, 2.0]])
    y_hat = np.array([[1.0, 1.0], [2.0, 2.0], [3.0, 2.0], [5.0, 2.0]])
    fit = fit_percent(y, y_hat)
    # ||y - y_hat|| = 1, ||y - mean|| = sqrt(2.25 + 0.25 + 0.25 + 2.25) = sqrt(5); the constant column: NaN.
    assert fit[0] == pytest.approx(100.0 * (1.0 - 1.0 / math.sqrt(5.0)), abs=1e-12)
    assert math.isnan(fit[1])
    col = y[:, 0]
    assert fit_percent(col, col) == pytest.approx(100.0)
    assert fit_percent(col, np.full(4, col.mean())) == pytest.approx(0.0)
    assert fit_percent(col, 2 * col.mean() - col) == pytest.approx(-100.0)  # mirrored: twice the spread


def test_validation_fit_true_model_and_wrong_model() -> None:
    log = open_loop_log()
    right = validation_fit(log.t, log.eta, log.tau, log.theta0, torque_hold="foh")
    wrong = validation_fit(log.t, log.eta, log.tau, model.base_parameters(PAPER_NOMINAL), torque_hold="foh")
    assert right["eta_r"] > 99.999
    assert right["eta_l"] > 99.999
    # The nominal robot (no friction, M 18-37 % off) over 5 s: observed fits 40.0 and 37.2 % (true: 99.99999).
    assert wrong["eta_r"] < 60.0
    assert wrong["eta_l"] < 60.0
    assert "foh" in right["predictor"]
    assert set(right) == {"eta_r", "eta_l", "predictor"}


# ------------------------------------------------------------------------------------- inputs


def test_bad_inputs_are_usage_errors() -> None:
    t, tau = _smooth_log(1e-3, 0.1, seed=6)
    with pytest.raises(UsageError, match="strictly increasing"):
        simulate_speeds(t[::-1].copy(), tau, THETA_CAD, [1.0, 1.0])
    with pytest.raises(UsageError, match="zoh or foh"):
        simulate_speeds(t, tau, THETA_CAD, [1.0, 1.0], torque_hold="linear")
    with pytest.raises(UsageError, match="shape"):
        simulate_speeds(t, tau[:, :1], THETA_CAD, [1.0, 1.0])
    with pytest.raises(UsageError, match="finite"):
        simulate_speeds(t, tau, np.full(8, np.nan), [1.0, 1.0])
    with pytest.raises(UsageError, match="starts"):
        simulate_segments(t, tau, THETA_CAD, np.ones((t.size, 2)), np.array([1, 5]))
