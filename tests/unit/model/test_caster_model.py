"""The ``wheel+caster`` friction model against computations made here, independently of wmrid.model.dynamics.

* The caster columns from rigid-body kinematics written out by hand: each caster's contact velocity, its drag
  force, the generalised forces on (v, w) and the wheel torques through J^T; and a virtual-work check.
* The linear parameterisation (Eq. 22 with the caster columns) against M^-1 (tau - V - friction - drag) written
  out by hand, for the general form, the two-term (Cv, Cw) form and the geometric form with 1 and 3 casters.
* The exact Jacobian of the intermediate parameters against finite differences; the minimum-distance recovery.
* The compiled kernel's regressor against the readable one; RegressorForm's validation and names.
* End to end: a log integrated here (scipy, with the geometric caster drag) identified by the observer.

Every tolerance is stated, with the figure it was set from, in each test's docstring.
"""

from __future__ import annotations

import json
import math
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from wmrid.estimators.observer.kernel import (
    DRAG_SPEED as KERNEL_DRAG_SPEED,
    KIND_CASTER,
    KIND_CASTER_GEOMETRY,
    KIND_GENERAL,
    KIND_PAPER,
    _regressor_rows,
)
from wmrid.estimators.observer.observe import caster_geometry
from wmrid.estimators.observer.replay import kernel_kind
from wmrid.model import dynamics as model, torques
from wmrid.model.base_params import derived_with_std, direct_recovery, fit_base_parameters, jacobian_intermediate
from wmrid.model.dynamics import RegressorForm
from wmrid.model.robot import AMR_NOMINAL, Caster, Robot
from wmrid.pipeline.identify import identify

#: m/s: the speed below which a caster's drag direction is regularised, |u| -> sqrt(|u|^2 + DRAG_SPEED^2)
#: (restated here, not imported: test_drag_speed_is_one_millimetre_per_second checks the model agrees).
DRAG_SPEED = 1e-3
R, B = 0.08, 0.2  # m, wheel radius and half track of the test robot
ONE_CASTER = (R, B, -0.2, 0.0)  # a rear ball caster on the centre line
THREE_CASTERS = (R, B, 0.25, 0.1, -0.2, -0.05, 0.05, 0.18)  # off-centre casters, no two mirrored

GENERAL = RegressorForm("general")
TWO_TERM = RegressorForm("general", caster=True)
GEOM1 = RegressorForm("general", caster=True, geometry=ONE_CASTER)
GEOM3 = RegressorForm("general", caster=True, geometry=THREE_CASTERS)
FORMS = {"general": GENERAL, "two-term": TWO_TERM, "geometric-1": GEOM1, "geometric-3": GEOM3}
CASTER_FORMS = {k: v for k, v in FORMS.items() if v.caster}


# --- independent computations -----------------------------------------------------------------------------------


def kinematics(eta: np.ndarray, r: float, b: float) -> tuple[np.ndarray, np.ndarray]:
    """Forward speed v (m/s) and yaw rate w (rad/s) of the platform at O for wheel speeds eta (n, 2) [right, left]."""
    return r * (eta[:, 0] + eta[:, 1]) / 2.0, r * (eta[:, 0] - eta[:, 1]) / (2.0 * b)


def caster_drag(eta: np.ndarray, geometry: tuple[float, ...], forces) -> tuple[np.ndarray, np.ndarray]:
    """The casters' drag as the wheels feel it, from rigid-body kinematics.

    For each caster at (x, y): its contact moves at u = (v - w y, w x) (the velocity of O plus w x p); the drag
    is F = -D u/|u|_reg; its generalised forces on (v, w) are Q_v = F_x and Q_w = x F_y - y F_x (its moment
    about z at O).  The wheels receive J^T Q with [v, w] = J eta, J = [[r/2, r/2], [r/(2b), -r/(2b)]]; the model
    puts friction on the left of M eta' + ... = tau, so the friction torque is -J^T Q.
    Returns (friction torque (n, 2) N m, power of the drag forces sum_k F_k . u_k (n,) W).
    """
    r, b = geometry[0], geometry[1]
    v, w = kinematics(eta, r, b)
    jac = np.array([[r / 2.0, r / 2.0], [r / (2.0 * b), -r / (2.0 * b)]])
    torque = np.zeros_like(eta)
    power = np.zeros(len(eta))
    for k, d in enumerate(forces):
        x, y = geometry[2 + 2 * k], geometry[3 + 2 * k]
        ux, uy = v - w * y, w * x
        speed = np.sqrt(ux**2 + uy**2 + DRAG_SPEED**2)
        fx, fy = -d * ux / speed, -d * uy / speed
        q = np.stack([fx, x * fy - y * fx], axis=1)  # (n, 2): Q_v, Q_w
        torque -= q @ jac  # rows: (J^T Q)^T = Q^T J
        power += fx * ux + fy * uy
    return torque, power


def two_term_drag(eta: np.ndarray, cv: float, cw: float) -> np.ndarray:
    """Cv sgn(eta_1 + eta_2) [1, 1] + Cw sgn(eta_1 - eta_2) [1, -1], N m, (n, 2)."""
    a = cv * np.sign(eta[:, 0] + eta[:, 1])
    c = cw * np.sign(eta[:, 0] - eta[:, 1])
    return np.stack([a + c, a - c], axis=1)


def expected_acceleration(eta: np.ndarray, tau: np.ndarray, theta0: np.ndarray, form: RegressorForm) -> np.ndarray:
    """eta_dot = m (tau - V - F_v eta - F_d sgn(eta) - caster drag), m = M^-1 = [[m11, m12], [m12, m22]]."""
    m11, m12, m22, vc, fv1, fv2, fd1, fd2 = theta0[:8]
    e1, e2 = eta[:, 0], eta[:, 1]
    coriolis = vc * np.stack([e1 * e2 - e2**2, e1 * e2 - e1**2], axis=1)
    wheel = np.stack([fv1 * e1 + fd1 * np.sign(e1), fv2 * e2 + fd2 * np.sign(e2)], axis=1)
    drag = np.zeros_like(eta)
    if form.caster and not form.geometry:
        drag = two_term_drag(eta, theta0[8], theta0[9])
    elif form.caster:
        drag = caster_drag(eta, form.geometry, theta0[8:])[0]
    rhs = tau - coriolis - wheel - drag
    return np.stack([m11 * rhs[:, 0] + m12 * rhs[:, 1], m12 * rhs[:, 0] + m22 * rhs[:, 1]], axis=1)


def wheel_friction(eta: np.ndarray, theta0: np.ndarray) -> np.ndarray:
    return theta0[4:6] * eta + theta0[6:8] * np.sign(eta)


def random_theta0(rng: np.random.Generator, n_extra: int) -> np.ndarray:
    """theta0 with a positive definite m (eigenvalues 5-45 1/(kg m^2)), friction and caster parameters."""
    a = rng.normal(size=(2, 2))
    m = 10.0 * a @ a.T + 5.0 * np.eye(2)
    return np.array(
        [m[0, 0], m[0, 1], m[1, 1], rng.normal(0.0, 0.01), *rng.uniform(0.001, 0.05, 2), *rng.uniform(0.01, 0.1, 2),
         *rng.uniform(0.05, 2.0, n_extra)]
    )  # fmt: skip


def n_extra(form: RegressorForm) -> int:
    return form.n_base - 8


def speed_samples(rng: np.random.Generator, n: int = 400) -> np.ndarray:
    """Wheel speeds (rad/s): random of both signs, plus the special cases -- standing still, one wheel still,
    turning on the spot (eta_1 = -eta_2), driving straight (eta_1 = eta_2), and speeds inside the drag's
    regularisation (contact speeds below DRAG_SPEED)."""
    random = rng.normal(0.0, 10.0, size=(n, 2))
    s = rng.normal(0.0, 10.0, size=8)
    special = [[0.0, 0.0], [s[0], 0.0], [0.0, s[1]], [s[2], -s[2]], [-s[3], s[3]], [s[4], s[4]], [s[5], s[5]],
               [1e-3, -1e-3], [2e-3, 5e-4], [-1e-4, 3e-4], [0.0, -0.0], [s[6], -s[6] * (1 + 1e-15)]]  # fmt: skip
    return np.vstack([random, np.array(special), rng.normal(0.0, 1e-2, size=(40, 2))])


# --- 1, 2: the caster columns -------------------------------------------------------------------------------------


def test_drag_speed_is_one_millimetre_per_second():
    """The regularisation speed restated in this file is the model's and the kernel's (exact equality)."""
    assert model.DRAG_SPEED == KERNEL_DRAG_SPEED == DRAG_SPEED


@pytest.mark.parametrize("form", [GEOM1, GEOM3], ids=["1 caster", "3 casters"])
def test_geometric_drag_matches_rigid_body_kinematics(form):
    """friction_torque minus the wheels' own friction equals -J^T Q of each caster's drag force -D u/|u|, from
    the contact velocity u = (v - w y, w x) computed here, on 450 speeds x 5 random parameter sets: to 1e-12 of
    the largest drag torque in the batch (the two computations order the same dozen floating-point operations
    differently, and a_k + c_k can cancel; measured worst 8e-15 of the largest torque).

    Virtual work: the power of the drag forces, sum F_k . u_k, equals -tau_c . eta (tau_c the caster part of
    the friction torque, which opposes the motion), to 1e-12 of sum D_k |u_k| (the largest power any term can
    have; measured worst 5e-15 of the largest power); and it is never positive (a drag)."""
    rng = np.random.default_rng(1)
    eta = speed_samples(rng)
    for _ in range(5):
        theta0 = random_theta0(rng, n_extra(form))
        expected, power = caster_drag(eta, form.geometry, theta0[8:])
        got = torques.friction_torque(eta, theta0, form) - wheel_friction(eta, theta0)
        scale = np.max(np.abs(expected))
        assert scale > 0.01
        np.testing.assert_allclose(got, expected, rtol=1e-12, atol=1e-12 * scale)
        # virtual work, with the model's own torque
        v, w = kinematics(eta, R, B)
        bound = sum(d * np.hypot(v - w * form.geometry[3 + 2 * k], w * form.geometry[2 + 2 * k])
                    for k, d in enumerate(theta0[8:]))  # fmt: skip
        np.testing.assert_allclose(power, -np.sum(got * eta, axis=1), rtol=0, atol=1e-12 * np.max(bound))
        assert np.all(power <= 1e-15 * np.max(bound))


def test_geometric_drag_special_motions():
    """Hand-derived limits for one caster at (x, 0) behind the axle, D = 1 N, at contact speeds of 0.48-0.8 m/s,
    where the regularisation shortens the drag by (DRAG_SPEED/|u|)^2/2 <= 2.2e-6 relative (tolerance 1e-5):
    driving straight, the drag is D against v: each wheel feels (r/2) D sgn(v), no turning part;
    turning on the spot, the contact moves sideways at w x: the drag's moment about O is -D |x| sgn(w), each
    wheel feels +-(r/(2b)) D |x| sgn(w); standing still (u = 0) there is no drag at all (exactly 0)."""
    form = RegressorForm("general", caster=True, geometry=(R, B, -0.3, 0.0))
    theta0 = np.array([20.0, -2.0, 20.0, 0.0, 0.0, 0.0, 0.0, 0.0, 1.0])
    eta = np.array([[10.0, 10.0], [-7.0, -7.0], [10.0, -10.0], [-4.0, 4.0], [0.0, 0.0]])
    got = torques.friction_torque(eta, theta0, form)
    straight, turn = R / 2.0, R / (2.0 * B) * 0.3
    expected = np.array([[straight, straight], [-straight, -straight], [turn, -turn], [-turn, turn], [0.0, 0.0]])
    np.testing.assert_allclose(got, expected, rtol=1e-5, atol=0)
    assert np.all(got[-1] == 0.0)


def test_mirrored_casters_have_the_same_columns_and_merge():
    """Casters at (x, y) and (-x, y) have equal drag columns (their contacts' velocities mirror about the x
    axis): checked on the hand-written kinematics (the torques of D = 1 N at each, to 1e-15 relative: the same
    operations on mirrored inputs), and caster_geometry lists such a pair once (and a third caster apart)."""
    rng = np.random.default_rng(2)
    eta = speed_samples(rng)
    a = caster_drag(eta, (R, B, 0.3, 0.07), [1.0])[0]
    b = caster_drag(eta, (R, B, -0.3, 0.07), [1.0])[0]
    np.testing.assert_allclose(a, b, rtol=1e-15, atol=1e-15 * np.max(np.abs(a)))
    robot = Robot("r", AMR_NOMINAL, casters=(Caster(x=0.3, y=0.07), Caster(x=-0.3, y=0.07), Caster(x=0.1, y=-0.2)))
    assert caster_geometry(robot) == (R, B, 0.3, 0.07, 0.1, -0.2)


def test_two_term_model():
    """geometry=(): friction_torque minus the wheel friction is Cv sgn(e1+e2)[1,1] + Cw sgn(e1-e2)[1,-1]; its
    regressor columns are exactly -sgn(e1+e2), -sgn(e1-e2).  Tolerance: exact with no wheel friction (sums of
    +-Cv and +-Cw only), 1e-15 of the torque with wheel friction (one rounding in the subtraction)."""
    rng = np.random.default_rng(3)
    eta = speed_samples(rng)
    theta0 = random_theta0(rng, 2)
    expected = two_term_drag(eta, theta0[8], theta0[9])
    got = torques.friction_torque(eta, theta0, TWO_TERM) - wheel_friction(eta, theta0)
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-15 * np.max(np.abs(torques.friction_torque(eta, theta0))))
    bare = theta0.copy()
    bare[4:8] = 0.0
    assert np.array_equal(torques.friction_torque(eta, bare, TWO_TERM), expected)
    assert np.array_equal(torques.friction_torque(eta, bare), expected)  # form None: the two-term model
    g = model.regressor(eta, np.zeros_like(eta), TWO_TERM)
    assert np.array_equal(g[:, 8], -np.sign(eta[:, 0] + eta[:, 1]))
    assert np.array_equal(g[:, 9], -np.sign(eta[:, 0] - eta[:, 1]))


# --- 3: the linear parameterisation -----------------------------------------------------------------------------


@pytest.mark.parametrize("name", list(FORMS))
def test_regressor_times_theta_is_the_direct_model(name):
    """g(eta, tau) theta^T (Eq. 22 with the caster columns) equals M^-1 (tau - V - friction - drag) computed
    here, and so does wheel_acceleration(..., form); wheel_torque inverts it.  Random theta0 (positive definite
    m), speeds of both signs with the special cases, torques up to ~5 N m.  Tolerance 1e-12 of the largest
    |eta_dot| in the batch: both sides sum ~10 products of size up to |m| |tau| ~ 200 rad/s^2 in different
    orders (measured worst 6e-16 of the largest); the inverse to 1e-12 of max |tau| (measured 2e-15)."""
    form = FORMS[name]
    rng = np.random.default_rng(4)
    eta = speed_samples(rng)
    for _ in range(5):
        theta0 = random_theta0(rng, n_extra(form))
        tau = rng.normal(0.0, 2.0, size=eta.shape)
        expected = expected_acceleration(eta, tau, theta0, form)
        scale = np.max(np.abs(expected))
        theta = model.intermediate_parameters(theta0, form)
        assert theta.shape == (2, form.n_columns)
        via_regressor = model.regressor(eta, tau, form) @ theta.T
        np.testing.assert_allclose(via_regressor, expected, rtol=0, atol=1e-12 * scale)
        direct = torques.wheel_acceleration(eta, tau, theta0, form)
        np.testing.assert_allclose(direct, expected, rtol=0, atol=1e-12 * scale)
        back = torques.wheel_torque(eta, direct, theta0, form)
        np.testing.assert_allclose(back, tau, rtol=0, atol=1e-12 * np.max(np.abs(tau)))


# --- 4, 5: the minimum-distance recovery --------------------------------------------------------------------------


@pytest.mark.parametrize("name", list(CASTER_FORMS))
def test_jacobian_against_central_differences(name):
    """jacobian_intermediate against central differences of intermediate_parameters, step 1e-6 of each
    parameter (for m11, m12, m22: of m's largest entry, as m12 can be near 0): f is affine in each single
    parameter (bilinear in m and the rest), so the difference has no truncation error, only rounding
    ~eps |f| / step; tolerance 1e-7 of each column's largest entry (measured worst 1e-9, from Vc ~ 1e-3; a step
    of 1e-6 |m12| would give 2.5e-7 when m12 happens to be ~0.01)."""
    form = CASTER_FORMS[name]
    rng = np.random.default_rng(5)
    for _ in range(5):
        theta0 = random_theta0(rng, n_extra(form))
        jac = jacobian_intermediate(theta0, form)
        assert jac.shape == (2 * form.n_columns, form.n_base)
        for j in range(form.n_base):
            step = 1e-6 * (np.max(np.abs(theta0[:3])) if j < 3 else abs(theta0[j]))
            up, down = theta0.copy(), theta0.copy()
            up[j] += step
            down[j] -= step
            diff = (model.intermediate_parameters(up, form) - model.intermediate_parameters(down, form)).ravel()
            numeric = diff / (2.0 * step)
            np.testing.assert_allclose(
                jac[:, j], numeric, rtol=0, atol=1e-7 * np.max(np.abs(jac[:, j])), err_msg=str(j)
            )


@pytest.mark.parametrize("name", list(CASTER_FORMS))
def test_exact_theta_recovers_theta0(name):
    """direct_recovery of exact intermediate parameters returns theta0 to 1e-12 relative (it inverts a 2x2 m
    and averages; measured 3e-16).  fit_base_parameters with the identity and with a diagonal covariance
    ~theta^2 returns theta0 to 1e-12 (measured 2e-16), misfit chi2 ~ 0 (< 1e-18: rounding of a 2p-vector of
    size ~50 in metrics of scale 1 to 1e6; measured <= 1.3e-29) and dof = 2p - n0."""
    form = CASTER_FORMS[name]
    rng = np.random.default_rng(6)
    p, n0 = form.n_columns, form.n_base
    for _ in range(5):
        theta0 = random_theta0(rng, n_extra(form))
        theta = model.intermediate_parameters(theta0, form)
        np.testing.assert_allclose(direct_recovery(theta, form), theta0, rtol=1e-12, atol=0)
        for cov in (np.eye(2 * p), np.diag(theta.ravel() ** 2 + 1e-6)):
            fit = fit_base_parameters(theta, cov, form)
            np.testing.assert_allclose(fit.theta0, theta0, rtol=1e-12, atol=0)
            assert fit.chi2 < 1e-18
            assert fit.dof == 2 * p - n0
            assert fit.cov.shape == fit.gain.shape[:1] * 2 == (n0, n0)


# --- 6: the compiled kernel ---------------------------------------------------------------------------------------


def test_kernel_kinds():
    """kernel_kind maps each form to its kernel regressor."""
    assert kernel_kind(RegressorForm("paper")) == KIND_PAPER
    assert kernel_kind(GENERAL) == KIND_GENERAL
    assert kernel_kind(TWO_TERM) == KIND_CASTER
    assert kernel_kind(GEOM1) == kernel_kind(GEOM3) == KIND_CASTER_GEOMETRY


@pytest.mark.parametrize("name", list(FORMS))
def test_kernel_regressor_is_the_model_regressor(name):
    """wmrid.estimators.observer.kernel._regressor_rows (compiled) equals model.regressor on ~450 samples, including
    standing
    still, one wheel still, eta_1 = -eta_2, eta_1 = eta_2 and contact speeds below DRAG_SPEED: to 1e-14 of
    each column's largest entry (the same arithmetic in the same order; measured: bit-identical)."""
    form = FORMS[name]
    rng = np.random.default_rng(7)
    eta = speed_samples(rng)
    tau = rng.normal(0.0, 2.0, size=eta.shape)
    expected = model.regressor(eta, tau, form)
    kind = kernel_kind(form)
    geom = np.array(form.geometry, dtype=np.float64)
    got = np.empty_like(expected)
    # the sign speeds are the speeds themselves here; rows from the 3rd sample on, then the first 3
    _regressor_rows(got[3:], eta, eta, tau, 3, kind, geom, np.zeros(0, dtype=np.int64))
    _regressor_rows(got[:3], eta, eta, tau, 0, kind, geom, np.zeros(0, dtype=np.int64))
    scale = np.maximum(np.max(np.abs(expected), axis=0), 1e-300)
    assert np.all(np.abs(got - expected) <= 1e-14 * scale)


# --- 7, 8: the form and the reported names ------------------------------------------------------------------------


def test_form_validation():
    """Caster drag needs the general form; geometry is (r, b, x_1, y_1, ...) with at least one caster, caster
    form only; geometry entries are stored as floats."""
    with pytest.raises(ValueError, match="general form"):
        RegressorForm("paper", caster=True)
    with pytest.raises(ValueError, match="geometry"):
        RegressorForm("general", caster=True, geometry=(R, B, 0.1))  # odd length
    with pytest.raises(ValueError, match="geometry"):
        RegressorForm("general", caster=True, geometry=(R, B, 0.1, 0.0, 0.2))  # odd length
    with pytest.raises(ValueError, match="geometry"):
        RegressorForm("general", caster=True, geometry=(R, B))  # no caster
    with pytest.raises(ValueError, match="geometry"):
        RegressorForm("general", caster=False, geometry=ONE_CASTER)  # geometry without caster drag
    form = RegressorForm("general", caster=True, geometry=(1, 2, 3, 4))
    assert form.geometry == (1.0, 2.0, 3.0, 4.0)
    assert all(type(v) is float for v in form.geometry)


def test_form_sizes_and_names():
    """Columns and base parameters of the three variants: 8 / 8 + 2 (Cv, Cw) / 8 + K (D1..DK)."""
    wheel_cols = ("tau_1", "tau_2", "eta_2^2-eta_1*eta_2", "eta_1^2-eta_1*eta_2", "-eta_1", "-eta_2",
                  "-sgn(eta_1)", "-sgn(eta_2)")  # fmt: skip
    assert (GENERAL.n_columns, GENERAL.n_base, GENERAL.n_casters) == (8, 8, 0)
    assert GENERAL.base_names == model.THETA0_NAMES
    assert GENERAL.column_names == wheel_cols
    assert GENERAL.friction == "wheel"
    assert (TWO_TERM.n_columns, TWO_TERM.n_base, TWO_TERM.n_casters) == (10, 10, 0)
    assert TWO_TERM.base_names == (*model.THETA0_NAMES, "Cv", "Cw")
    assert TWO_TERM.column_names == (*wheel_cols, "-sgn(eta_1+eta_2)", "-sgn(eta_1-eta_2)")
    for form, k in ((GEOM1, 1), (GEOM3, 3)):
        assert (form.n_columns, form.n_base, form.n_casters) == (8 + 2 * k, 8 + k, k)
        assert form.base_names == (*model.THETA0_NAMES, *[f"D{i}" for i in range(1, k + 1)])
        assert form.column_names == (*wheel_cols, *[f"-drag{i}_{part}" for i in range(1, k + 1) for part in "vw"])
        assert form.caster_map == tuple(
            item for i in range(k) for item in ((8 + 2 * i, 8 + i, 1), (9 + 2 * i, 8 + i, -1))
        )
        assert len(form.theta_names()) == 2 * form.n_columns
        assert form.friction == "wheel+caster"
        assert all(name in model.THETA0_UNITS and model.THETA0_UNITS[name] == "N" for name in form.base_names[8:])


@pytest.mark.parametrize("name", list(FORMS))
def test_to_dict_is_json_and_names_the_friction(name):
    """to_dict survives a JSON round trip unchanged, names the friction model and, for the geometric model,
    r, b and each caster's position."""
    form = FORMS[name]
    data = form.to_dict()
    assert json.loads(json.dumps(data)) == data
    assert data["friction"] == form.friction
    assert data["columns"] == list(form.column_names)
    if form.geometry:
        geometry = data["caster_geometry"]
        assert (geometry["r"], geometry["b"]) == (R, B)
        assert geometry["casters"] == [list(form.geometry[2 + 2 * k : 4 + 2 * k]) for k in range(form.n_casters)]
    else:
        assert "caster_geometry" not in data


@pytest.mark.parametrize("name", list(CASTER_FORMS))
def test_derived_with_std_reports_the_caster_parameters(name):
    """derived_with_std with form.base_names returns each caster parameter (Cv, Cw or D1..DK) with its value
    and std = sqrt(cov_jj) exactly, besides the base parameters and M."""
    form = CASTER_FORMS[name]
    rng = np.random.default_rng(8)
    theta0 = random_theta0(rng, n_extra(form))
    a = rng.normal(size=(form.n_base, form.n_base))
    cov0 = 1e-6 * a @ a.T
    out = derived_with_std(theta0, cov0, form.base_names)
    assert set(out) == {*form.base_names, "M11", "M12", "M22"}
    for j, name_j in enumerate(form.base_names):
        assert out[name_j] == (theta0[j], math.sqrt(cov0[j, j]))
    big_m = np.linalg.inv(model.inverse_inertia(theta0))
    assert out["M12"][0] == pytest.approx(big_m[0, 1], rel=1e-12)


# --- 9: end to end --------------------------------------------------------------------------------------------------

TRUTH = {"m11": 26.0, "m12": -3.9, "m22": 25.0, "Vc": -0.0015, "Fv1": 0.004, "Fv2": 0.005, "Fd1": 0.02, "Fd2": 0.025,
         "D1": 0.35}  # fmt: skip
CASTER_X, CASTER_Y = -0.2, 0.0


def excitation(t):
    """Wheel torques (N m): sums of sines at incommensurate frequencies; both wheels reverse, and the robot
    drives, turns and turns on the spot."""
    t = np.asarray(t, dtype=float)
    return np.stack([
        0.3 * np.sin(0.9 * t) + 0.16 * np.sin(2.3 * t + 0.4) + 0.08 * np.sin(5.1 * t + 1.0),
        0.3 * np.sin(0.7 * t + 1.2) + 0.16 * np.sin(2.9 * t + 2.0) + 0.08 * np.sin(4.3 * t + 0.3),
    ], axis=-1)  # fmt: skip


def crossing(j: int, direction: float):
    """A terminal solve_ivp event: wheel j's speed crosses zero in ``direction``."""

    def event(t, y, signs):
        return y[j]

    event.terminal, event.direction = True, direction
    return event


def synthetic_log(duration: float = 30.0, dt: float = 1e-3, rtol: float = 1e-10) -> SimpleNamespace:
    """The direct model with one caster's drag, integrated here by scipy's DOP853 (rtol 1e-10, atol 1e-12).

    The torque is smooth (identified with torque_hold="foh", whose linear interpolation of it is 2e-6 relative
    off).  The wheels' Coulomb terms are discontinuous at a reversal, so the integration stops at each wheel's
    zero crossing (an event) and restarts with that wheel's sign frozen to the direction it crosses in (checked:
    the wheel does not stick, the net torque carries it through).
    """
    th = TRUTH
    m = np.array([[th["m11"], th["m12"]], [th["m12"], th["m22"]]])
    fv, fd = np.array([th["Fv1"], th["Fv2"]]), np.array([th["Fd1"], th["Fd2"]])
    geometry = (R, B, CASTER_X, CASTER_Y)

    def rhs(t, y, signs):
        e1, e2 = y
        coriolis = th["Vc"] * np.array([e1 * e2 - e2 * e2, e1 * e2 - e1 * e1])
        drag = caster_drag(y[None, :], geometry, [th["D1"]])[0][0]
        return m @ (excitation(t) - coriolis - fv * y - fd * signs - drag)

    t_eval = np.arange(round(duration / dt) + 1) * dt
    eta = np.empty((len(t_eval), 2))
    y, t0, done, reversals = np.array([0.3, -0.2]), 0.0, 0, 0
    signs = np.sign(y)
    while True:
        events = [crossing(j, -signs[j]) for j in range(2)]
        sol = solve_ivp(rhs, (t0, t_eval[-1]), y, method="DOP853", rtol=rtol, atol=1e-12, t_eval=t_eval[done:],
                        events=events, args=(signs,))  # fmt: skip
        assert sol.success, sol.message
        eta[done : done + len(sol.t)] = sol.y.T
        done += len(sol.t)
        if sol.status == 0:
            break
        j = 0 if len(sol.t_events[0]) else 1
        t0, y = sol.t_events[j][0], sol.y_events[j][0].copy()
        y[j] = 0.0
        signs = signs.copy()
        signs[j] = 0.0
        signs[j] = np.sign(rhs(t0, y, signs)[j])
        assert signs[j] != 0.0, "a wheel stops with zero acceleration"
        assert np.sign(rhs(t0, y, signs)[j]) == signs[j], "a wheel sticks"
        reversals += 1
    assert done == len(t_eval)
    return SimpleNamespace(t=t_eval, eta=eta, tau=excitation(t_eval), source="synthetic", notes=(), reversals=reversals)


@pytest.fixture(scope="module")
def caster_log():
    return synthetic_log()


@pytest.fixture(scope="module")
def caster_robot():
    """Nominal r = 0.08 m, b = 0.2 m (the light AMR's guesses) and the caster at (-0.2, 0)."""
    return Robot(name="synthetic", nominal=AMR_NOMINAL, casters=(Caster(x=CASTER_X, y=CASTER_Y),))


def test_synthetic_log_is_exciting_and_accurate(caster_log):
    """The log the end-to-end tests use: both wheels reverse (9 reversals in 30 s; the wheels span -18.8..15.3 and
    -17.2..9.7 rad/s), the robot turns on the spot (|eta_1 + eta_2| < |eta_1 - eta_2|/4 at a yaw rate above 1.6 rad/s:
    2.8 % of the log) and drives near-straight (13 %); speeds up to 19 rad/s (v up to 1 m/s, w to 4 rad/s).
    Integration error: a 5 s run at rtol 1e-10 against rtol 1e-12 differs by at most 1e-8 rad/s (measured
    1.6e-9; 3.7e-9 over 30 s), 1e-10 of the speeds."""
    eta = caster_log.eta
    assert caster_log.reversals >= 6
    for j in range(2):
        assert eta[:, j].min() < -15.0
        assert eta[:, j].max() > 8.0
    spin = (np.abs(eta[:, 0] + eta[:, 1]) < 0.25 * np.abs(eta[:, 0] - eta[:, 1])) & (
        np.abs(eta[:, 0] - eta[:, 1]) > 8.0
    )
    straight = np.abs(eta[:, 0] - eta[:, 1]) < 0.1 * np.abs(eta[:, 0] + eta[:, 1])
    assert spin.mean() > 0.015
    assert straight.mean() > 0.05
    assert np.max(np.abs(eta)) < 25.0
    coarse, fine = synthetic_log(5.0), synthetic_log(5.0, rtol=1e-12)
    assert np.max(np.abs(coarse.eta - fine.eta)) < 1e-8


def test_identify_recovers_the_caster_drag(caster_log, caster_robot):
    """identify(friction="wheel+caster") with the robot's caster position, on the noise-free log above:
    every base parameter and D1 within 1e-3 relative of the truth (measured worst 3.5e-5, Fd2; D1 2.7e-5; the
    inertia entries <= 1.1e-5), each within 3 of its reported std (measured |z| <= 1.23, m22; the std is
    not widened here, structural p = 0.12), every std below 1 % of its value (measured worst: D1 0.02 %), so
    that D1 is far off zero (measured 5900 std; asserted > 1000).

    (On other noise-free excitations the structural test may reject a well-specified log -- with 1.5x these
    torque amplitudes: p = 0.001, std widened 39x -- as the sampled log departs from the observer's
    continuous model by discretisation alone, e.g. a Coulomb sign flipping between samples; friction="wheel"
    on a log without caster drag does the same, so that is not specific to the caster model.)"""
    result = identify(caster_log, caster_robot, friction="wheel+caster", torque_hold="foh")
    assert result.form == RegressorForm("general", caster=True, geometry=(R, B, abs(CASTER_X), CASTER_Y))
    assert result.form.base_names[8:] == ("D1",)
    for name, truth in TRUTH.items():
        value, std = result.parameters[name]
        assert abs(value - truth) <= 1e-3 * abs(truth), (name, value, truth)
        assert abs(value - truth) <= 3.0 * std, (name, value, truth, std)
        assert std < 0.01 * abs(truth), (name, std)
    assert result.parameters["D1"][0] > 1000.0 * result.parameters["D1"][1]


def test_wheel_only_model_is_biased_on_a_caster_log(caster_log, caster_robot):
    """friction="wheel" on the same log folds the caster drag (r/2 x 0.35 N = 0.014 N m per wheel driving
    straight, 70 % of Fd1) into the wheels' friction: the log does carry the drag, visibly.  Measured: Fv and Fd
    18-27 % off, m11 0.7 %; asserted: some base parameter more than 5 % off (50x the caster model's 1e-3)."""
    result = identify(caster_log, caster_robot, friction="wheel", torque_hold="foh")
    assert result.form == GENERAL
    worst = max(abs(result.parameters[n][0] / truth - 1.0) for n, truth in TRUTH.items() if n != "D1")
    assert worst > 0.05


def test_wheel_only_model_std_is_honest_or_flagged(caster_log, caster_robot):
    """friction="wheel" on the caster log: the structural-mismatch diagnostics flag it (diagnostics["inflated"]
    non-empty) or the (widened) std keeps each truth within 3 std -- the docs' promise for model errors the
    log reveals (this one it reveals: the caster model fits it to 3.5e-5 and puts D1 5900 std off zero).

    Until issue 12 this failed (a strict xfail): the structural test has little power here (p = 0.26 on a
    jackknife of 14 dof) and Fv1, Fv2, Fd1, Fd2, Vc lay 6.2, 6.3, 4.0, 4.0, 3.2 std off, unflagged.  The closed-loop
    check (wmrid.estimators.feedback) now sees the prediction error at 2300 times the noise and widens by its term:
    every parameter is marked inflated, Fv1, Fv2 still 4.4 and 4.8 std off (the mark says the std does not cover
    all)."""
    result = identify(caster_log, caster_robot, friction="wheel", torque_hold="foh")
    z = {n: (result.parameters[n][0] - truth) / result.parameters[n][1] for n, truth in TRUTH.items() if n != "D1"}
    assert result.diagnostics.feedback.disturbance
    assert result.diagnostics.inflated or max(abs(v) for v in z.values()) <= 3.0, (
        result.diagnostics.uncertainty.model_error.p_value,
        z,
    )
