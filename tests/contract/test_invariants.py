"""Invariants of identification under transformations of the log whose effect on the parameters is known.

Every test compares two identifications of noise-free logs (so nothing but the estimator's own numerics
separates them) and states its tolerance next to it.  Relative differences are |a - b| / max(|a|, |b|).

1. Swapping the wheels (columns of eta and tau) mirrors the parameters: m11 <-> m22, Fv1 <-> Fv2,
   Fd1 <-> Fd2, m12 and Vc unchanged (derived and checked on the model below).
2. Keeping every other sample of a 1 kHz log (500 Hz) leaves them unchanged up to the O(h^2)
   discretisation error -- on a log whose torque really is what the hold model assumes.  Decimating the
   simulator's zero-order-hold torque drops torques its 1 kHz controller applied: with --control-rate
   1000 the unlogged ones are interpolated and the parameters stay within 1e-3; without, friction moves
   by 8-11 % (both tested).
3. Shifting t by a constant changes nothing beyond the rounding of t.
4. Scaling every torque by c scales M, Vc and friction by c (m by 1/c).
"""

from __future__ import annotations

import dataclasses
import math
from types import SimpleNamespace

import numpy as np
import pytest
from hypothesis import example, given, settings, strategies as st

from tests.open_loop import open_loop_log
from wmrid.estimators.result import REPORTED
from wmrid.model import dynamics as model, torques
from wmrid.model.robot import BUILTIN_ROBOTS, PAPER_CAD
from wmrid.pipeline.identify import identify
from wmrid.sim.simulate import simulate

PAPER = BUILTIN_ROBOTS["paper"]
TRAJECTORIES = ("sinusoid", "reversing")
#: Reported name -> its name after swapping the wheels (the rule derived in the model tests below).
_PAIRS = (("m11", "m22"), ("M11", "M22"), ("Fv1", "Fv2"), ("Fd1", "Fd2"))
MIRROR = {**dict(_PAIRS), **{b: a for a, b in _PAIRS}}
#: Exponent of c in each reported parameter when every torque is multiplied by c: m ~ 1/c, the rest ~ c.
TORQUE_POWER = {name: -1 if name.startswith("m") else 1 for name in REPORTED}
SWAP = np.array([[0.0, 1.0], [1.0, 0.0]])

#: Few examples, no deadline (a numba-compiled replay of 20 000 samples per example), reproducible draws.
FEW = settings(max_examples=5, deadline=None, derandomize=True, database=None)


def as_log(t, eta, tau, source="sim"):
    return SimpleNamespace(t=t, eta=eta, tau=tau, source=source, notes=())


def values(result) -> dict[str, float]:
    return {name: result.parameters[name][0] for name in REPORTED}


def rel(a: float, b: float) -> float:
    scale = max(abs(a), abs(b))
    return abs(a - b) / scale if scale > 0 else 0.0


@pytest.fixture(scope="module")
def sims():
    """Noise-free 20 s closed-loop logs at 1 kHz: the plant is the paper's CAD robot (d_y != 0, unequal
    friction: not symmetric), the controller knows the nominal one."""
    return {
        traj: simulate(PAPER.reference, PAPER.nominal, trajectory=traj, duration=20, seed=0) for traj in TRAJECTORIES
    }


@pytest.fixture(scope="module")
def baselines(sims):
    """Per trajectory: the log, its estimate without a robot, and with the paper robot (zoh and foh)."""
    out = {}
    for traj, sim in sims.items():
        log = as_log(sim.t, sim.eta, sim.tau)
        out[traj] = SimpleNamespace(
            log=log,
            sim=sim,
            free=values(identify(log, None)),
            robot=values(identify(log, PAPER)),
            robot_foh=values(identify(log, PAPER, torque_hold="foh", timing=False)),  # the h/2 sensitivity, uncorrected
        )
    return out


# --------------------------------------------------------------------------------------------------
# 1. Mirror: swapping the wheels.
#
# Swapping eta_1 <-> eta_2 and tau_1 <-> tau_2 is the reflection y -> -y of the body frame: forward
# motion is kept, turning is reversed, the right wheel becomes the left.  With P = [[0, 1], [1, 0]]
# (P = P^-1), multiplying Eq. (9) by P and writing eta' = P eta, tau' = P tau:
#     (P M P) eta'_dot + P V(eta) + (P F_v P) eta' + (P F_d P) sgn(eta') = tau'.
# So M' = P M P (M11 <-> M22, M12 kept; hence m' = P m P likewise), F' = P F P (Fv1 <-> Fv2, Fd1 <-> Fd2),
# and the Coriolis term must satisfy V'(eta') = P V(eta).  With model.coriolis_torque,
#     V(eta; Vc) = Vc [eta_1 eta_2 - eta_2^2, eta_1 eta_2 - eta_1^2],
#     V(P eta; Vc) = Vc [eta_1 eta_2 - eta_1^2, eta_1 eta_2 - eta_2^2] = P V(eta; Vc),
# i.e. the form is already swap-symmetric and Vc' = +Vc: Vc does NOT change sign (a sign change would give
# -P V(eta), wrong wherever V != 0).  Physically: Vc = (m_p d_x + 2 m_r c_x) r^3 / (4 b^2) depends on the
# x offsets only, which the reflection keeps; it flips d_y, which swaps M11 and M22 in Eqs. (10)-(12).
# The same holds for the opposite overall sign convention of V, so the rule does not depend on it.


def mirrored_base(theta0: np.ndarray) -> np.ndarray:
    """theta0 = [m11, m12, m22, Vc, Fv1, Fv2, Fd1, Fd2] of the wheel-swapped robot (the rule above)."""
    m11, m12, m22, vc, fv1, fv2, fd1, fd2 = theta0
    return np.array([m22, m12, m11, vc, fv2, fv1, fd2, fd1])


@settings(max_examples=30, deadline=None, derandomize=True, database=None)
@given(
    eta=st.lists(st.tuples(*[st.floats(-30.0, 30.0)] * 2), min_size=1, max_size=8).map(np.array),
    vc=st.floats(-2.0, 2.0).filter(lambda v: abs(v) > 1e-3),
)
@example(eta=np.array([[2.0, 1.0]]), vc=0.21)
def test_coriolis_term_under_wheel_swap_keeps_vc(eta, vc):
    # Exact products and differences of the same doubles: the swap identity holds to a few ulp of the
    # largest term, vc * 30^2; 1e-12 relative of it is ~1000 ulp of margin and still catches any real term.
    atol = 1e-12 * abs(vc) * max(1.0, float(np.max(eta**2)))
    swapped = torques.coriolis_torque(eta @ SWAP, vc)
    np.testing.assert_allclose(swapped, torques.coriolis_torque(eta, vc) @ SWAP, rtol=0, atol=atol)
    # The sign-change rule gives exactly the opposite torque, so it is wrong wherever V is not ~0.
    np.testing.assert_allclose(torques.coriolis_torque(eta @ SWAP, -vc), -swapped, rtol=0, atol=atol)
    big = np.abs(swapped).max(axis=1) > 1e3 * atol
    if big.any():  # where V is not ~0 (all-zero speeds give V = 0 under either rule)
        assert not np.allclose(torques.coriolis_torque(eta @ SWAP, -vc)[big], swapped[big], rtol=0, atol=atol)


def test_mirrored_robot_has_mirrored_base_parameters_and_dynamics():
    """The reflection on the physical parameters (d_y -> -d_y; c_y is the rotors' |y|; swap the wheels'
    friction) maps the base parameters by the rule, and the direct model commutes with the swap."""
    p = PAPER_CAD
    mirror = dataclasses.replace(p, d_y=-p.d_y, F_v1=p.F_v2, F_v2=p.F_v1, F_d1=p.F_d2, F_d2=p.F_d1)
    theta0, theta0_m = model.base_parameters(p), model.base_parameters(mirror)
    assert theta0[0] != pytest.approx(theta0[2], rel=1e-6)  # d_y != 0: the robot itself is not symmetric
    # Eqs. (10)-(12) and the inverse are a few dozen flops on O(1) numbers: 1e-13 relative is rounding.
    np.testing.assert_allclose(theta0_m, mirrored_base(theta0), rtol=1e-13, atol=0)
    assert theta0_m[3] == theta0[3]  # Vc: same expression of the same d_x, c_x -- bit for bit

    rng = np.random.default_rng(0)
    eta = rng.uniform(-10.0, 10.0, (200, 2))
    tau = rng.uniform(-5.0, 5.0, (200, 2))
    acc = torques.wheel_acceleration(eta, tau, theta0)
    acc_m = torques.wheel_acceleration(eta @ SWAP, tau @ SWAP, theta0_m)
    # Linear algebra on values up to ~1e3 rad/s^2: 1e-10 relative of the largest is rounding.
    atol = 1e-10 * float(np.abs(acc).max())
    np.testing.assert_allclose(acc_m, acc @ SWAP, rtol=0, atol=atol)
    wrong = theta0_m.copy()
    wrong[3] = -wrong[3]  # the "Vc changes sign" rule
    assert np.abs(torques.wheel_acceleration(eta @ SWAP, tau @ SWAP, wrong) - acc @ SWAP).max() > 1e3 * atol


@pytest.mark.parametrize("traj", TRAJECTORIES)
@FEW
@given(start=st.integers(0, 5000), length=st.integers(10_000, 15_000))
@example(start=0, length=15_000)
def test_swapping_wheels_mirrors_parameters(baselines, traj, start, length):
    # robot=None: the paper robot's nominal start and box are not those of its mirror image; the data
    # start (m11 = m22, all else 0) is swap-symmetric, so both runs see the same problem, permuted.
    log = baselines[traj].log
    sl = slice(start, start + length)
    est = values(identify(as_log(log.t[sl], log.eta[sl], log.tau[sl]), None))
    est_m = values(identify(as_log(log.t[sl], log.eta[sl, ::-1], log.tau[sl, ::-1]), None))
    # The swap is an exact permutation of every sum the estimator forms, so only the order of floating
    # point operations differs: ~n eps = 2e4 * 2.2e-16 = 4e-12 on well-determined quantities, amplified by
    # the poorer conditioning of friction (std/|value| 100x that of m).  Measured over the drawn windows:
    # <= 1e-12 (m, M, Vc), <= 9.1e-11 (friction); 1e-9 leaves 10x margin and is 1e4 below the smallest std.
    for name in REPORTED:
        assert rel(est_m[MIRROR.get(name, name)], est[name]) <= 1e-9, (name, est[name], est_m[MIRROR.get(name, name)])
    # Kept, not negated (the paper robot's Vc = +0.21 kg m^2).
    assert est["Vc"] > 0
    assert est_m["Vc"] > 0


# --------------------------------------------------------------------------------------------------
# 2. Resampling 1 kHz -> 500 Hz.


def test_resampling_a_smooth_torque_log_changes_parameters_by_o_h2():
    """Open-loop CAD robot under smooth torques (DOP853 at rtol 1e-11), identified with the first-order
    hold that matches a smooth torque, at 1 kHz and at every other sample.  (Not the reversing log: its
    Coulomb sgn(eta) jumps inside a step, which is an O(h) effect at each reversal.)"""
    log = open_loop_log(duration=20.0)
    truth = model.named_base(log.theta0)
    half = as_log(log.t[::2], log.eta[::2], log.tau[::2], source="500 Hz")
    fast = values(identify(log, PAPER, torque_hold="foh"))
    slow = values(identify(half, PAPER, torque_hold="foh"))
    err_fast = {n: rel(fast[n], truth[n]) for n in REPORTED}
    err_slow = {n: rel(slow[n], truth[n]) for n in REPORTED}
    # The justification of the bound, checked: the error is O(h^2) -- halving the rate multiplies it by
    # ~4 (measured 3.3-4.3 per parameter; O(h) would give 2).
    assert 3.0 <= float(np.median([err_slow[n] / err_fast[n] for n in REPORTED])) <= 5.5
    # The 1 kHz error is <= 5e-6 for every parameter (measured <= 2.2e-6, Fd1), so Richardson gives a
    # difference of ~3 x that, <= 1.5e-5; bound 2e-5 (measured 6.6e-6, Fd1), 1e4 below a real change.
    for name in REPORTED:
        assert err_fast[name] <= 5e-6, (name, err_fast[name])
        assert rel(slow[name], fast[name]) <= 2e-5, (name, fast[name], slow[name])


def _decimated(log, step: int, **options) -> dict[str, float]:
    """The robot-started parameters of every ``step``-th sample of ``log``."""
    return values(identify(as_log(log.t[::step], log.eta[::step], log.tau[::step]), PAPER, **options))


@pytest.mark.parametrize("traj", TRAJECTORIES)
def test_resampling_the_closed_loop_log_keeps_parameters_given_the_control_rate(baselines, traj):
    # Decimating the simulator's 1 kHz zero-order-hold torque to 500 Hz drops every other torque the
    # controller applied.  With --control-rate 1000 each 2 ms step is two held sub-steps, the unlogged one
    # interpolated between its logged neighbours: the input error is then the interpolation error,
    # O(h^2) (checked below: 4 times the step gives at least 3 times the difference of 2 times, where O(h)
    # would give 2, and stays within the bound scaled by h^2).  Measured difference from the 1 kHz estimate:
    # sinusoid 3.6e-4 (Fd2), reversing 2.7e-4 (5.3e-4 before the sign columns took a 20 ms centred mean of the
    # speeds) at twice the step, 2.9e-3 at 4 times; bound 1e-3, 10 times below what decimation does without the
    # control rate (>= 1e-2, next test).
    base = baselines[traj]
    diffs = []
    for step in (2, 4):
        slow = _decimated(base.log, step, control_rate=1000.0)
        diffs.append(max(rel(slow[n], base.robot[n]) for n in REPORTED))
    assert diffs[0] <= 1e-3, diffs
    assert diffs[1] / diffs[0] >= 3.0, diffs
    assert diffs[1] <= 4.0 * 1e-3, diffs


@pytest.mark.parametrize("traj", TRAJECTORIES)
def test_without_the_control_rate_a_decimated_zoh_log_biases_friction(baselines, traj):
    # Why --control-rate exists: holding each logged torque over the whole 2 ms replaces the dropped
    # sample's torque by its predecessor, an O(h) input error (a ~0.5 ms torque lag) that moves the
    # friction terms by 8-11 % (measured), while the inertia terms stay within 0.03 %.
    base = baselines[traj]
    slow = _decimated(base.log, 2)
    assert max(rel(slow[n], base.robot[n]) for n in ("Fv1", "Fv2", "Fd1", "Fd2")) > 1e-2
    assert max(rel(slow[n], base.robot[n]) for n in ("m11", "m12", "m22", "M11", "M12", "M22")) < 1e-3


# --------------------------------------------------------------------------------------------------
# 3. Time shift.


@pytest.mark.parametrize("traj", TRAJECTORIES)
@FEW
@given(offset=st.floats(0.0, 2.0e9))
@example(offset=1000.0)
@example(offset=1.7e9)
def test_time_shift_changes_nothing_but_rounding(baselines, traj, offset):
    # The robot only starts the estimate and is identical in both runs: kept.
    base = baselines[traj]
    log = base.log
    shifted = values(identify(as_log(log.t + offset, log.eta, log.tau), PAPER))
    # t + offset rounds each stamp by <= ulp/2, so each step's length moves by <= 1 ulp (2.4e-7 s at
    # 1.7e9 s, 2.3e-13 s at 1000 s), a relative timing error of <= ulp/h.  The most a timing change can do
    # is measured on the same log: zoh -> foh shifts the torque by h/2 and moves parameter k by S_k
    # (friction ~0.15, m ~1e-3).  So a shift moves k by <= S_k * (ulp/(h/2)) = 2 S_k ulp/h, plus 1e-10
    # for the arithmetic (the wheel swap, an exact permutation, measured <= 9.1e-11).  Measured <= 0.4 of
    # this bound (sinusoid Fv1 at 1.7e9 s: 1.2e-6 against 2.9e-6); at 1000 s: 3e-11 against >= 1e-10.
    h = float(np.median(np.diff(log.t)))
    ulp_ratio = float(np.spacing(log.t[-1] + offset)) / h
    for name in REPORTED:
        s_k = rel(base.robot_foh[name], base.robot[name])
        tol = 2.0 * s_k * ulp_ratio + 1e-10
        assert rel(shifted[name], base.robot[name]) <= tol, (name, offset, base.robot[name], shifted[name], tol)


# --------------------------------------------------------------------------------------------------
# 4. Torque scaling.


@pytest.mark.parametrize("traj", TRAJECTORIES)
@FEW
@given(c=st.floats(0.1, 10.0))
@example(c=0.1)
@example(c=10.0)
def test_scaling_torques_scales_parameters(baselines, traj, c):
    # robot=None: the paper robot's nominal start and box do not scale with c (at c = 10 its nominal
    # values are 10x off, at the box's edge); the data start (|eta_dot|/|tau| ratio) scales as 1/c.
    base = baselines[traj]
    log = base.log
    scaled = identify(as_log(log.t, log.eta, log.tau * c), None)
    # Eq. (9) is homogeneous: c tau is explained by c M, c Vc, c F exactly.  Two parts of the estimator are
    # (by design) not scale-equivariant and each moves the answer within its statistical uncertainty:
    # the alpha I start weight (its pull on the torque columns grows as 1/c^2; measured <= 1.2 x
    # wmrid's start_sensitivity, i.e. <= 0.048 std at c = 0.1) and the Andrews plug-in bandwidth of the
    # Newey-West weights of the minimum-distance step (an unnormalised sum over score columns: reversing
    # log 84.4 -> 83.9 blocks at c = 1.39, a floor() jump; weights only affect efficiency; measured
    # 0.018 std, 1e-6 relative on Fv1).  Bound: 0.1 reported std (undetectable by any log) + 1e-9 for the
    # arithmetic.  On the sinusoid 0.1 std is 1e-8 relative for m, 1e-6 for friction: still tight.
    for name in REPORTED:
        value, std = scaled.parameters[name]
        expected = base.free[name] * c ** TORQUE_POWER[name]
        assert math.isfinite(std)
        assert abs(value - expected) <= 0.1 * std + 1e-9 * abs(expected), (name, c, expected, value, std)
