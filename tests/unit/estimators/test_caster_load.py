"""The ``wheel+caster+load`` friction model (a ball caster's drag that follows its normal load) against computations
made here, independently of wmrid.model.dynamics.

* The load transfer itself: the MuJoCo engine's own contact normal force on the caster against the rigid-body statics
  written out here (the inertial forces' moment about the wheels' ground line, plus the wheels' spin).
* The drag with its load terms against -J^T Q of each caster's drag force D_k(t) u/|u| from hand kinematics
  (tests.unit.model.test_caster_model), the regression form g theta against M^-1 (tau - V - friction - drag), the
  implicit direct model (M + A(eta)) eta' = ... against its inverse and finite differences, the Jacobian of the
  intermediate parameters against central differences, the minimum-distance recovery.
* The observer's filters: a column c(eta) phi' carried without differentiating, against the exact filter integral
  computed here by Gauss-Legendre quadrature; the compiled kernel against the readable step (1e-12).
* End to end: a log integrated here with a drag that follows v' and w^2, identified (``--friction auto`` takes the
  load terms; on a log whose drag is constant it does not).

Every tolerance is stated, with the figure it was set from, in each test's docstring.
"""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from tests.open_loop import open_loop_log
from tests.unit.model.test_caster_model import (
    CASTER_X,
    CASTER_Y,
    ONE_CASTER,
    THREE_CASTERS,
    TRUTH,
    caster_drag,
    crossing,
    excitation,
    kinematics,
    random_theta0,
    speed_samples,
    synthetic_log,
)
from wmrid.estimators.observer.kernel import KIND_CASTER_GEOMETRY, _regressor_rows
from wmrid.estimators.observer.replay import kernel_kind, load_codes, replay
from wmrid.estimators.observer.settings import ObserverSettings
from wmrid.estimators.observer.step import initial_state, observer_step
from wmrid.model import dynamics as model, torques
from wmrid.model.base_params import direct_recovery, fit_base_parameters, jacobian_intermediate
from wmrid.model.dynamics import RegressorForm
from wmrid.model.robot import AMR_CAD, AMR_NOMINAL, PAPER_NOMINAL, Caster, Robot
from wmrid.pipeline.identify import identify

R, B = ONE_CASTER[0], ONE_CASTER[1]
LOAD1 = RegressorForm("general", caster=True, geometry=ONE_CASTER, load=("dv", "w2"))
LOAD3 = RegressorForm("general", caster=True, geometry=THREE_CASTERS, load=model.LOAD_SIGNALS)
LOAD_FORMS = {"1 caster, pitch": LOAD1, "3 casters, all four": LOAD3}


def signals(eta: np.ndarray, eta_dot: np.ndarray, r: float, b: float) -> dict[str, np.ndarray]:
    """The load signals v', w^2, v w, w' from the wheel speeds and accelerations (hand kinematics)."""
    v, w = kinematics(eta, r, b)
    dv, dw = kinematics(eta_dot, r, b)
    return {"dv": dv, "w2": w * w, "vw": v * w, "dw": dw}


def loaded_forces(theta0: np.ndarray, form: RegressorForm, eta: np.ndarray, eta_dot: np.ndarray) -> list:
    """D_k(t) = D_k + sum over the form's signals of D{k}{signal} x signal(t), per caster (n,) N."""
    big_k, s = form.n_casters, signals(eta, eta_dot, form.geometry[0], form.geometry[1])
    out = []
    for k in range(big_k):
        d = np.full(len(eta), theta0[8 + k])
        for j, name in enumerate(form.load):
            d = d + theta0[8 + big_k + k * len(form.load) + j] * s[name]
        out.append(d)
    return out


def random_load_theta0(rng: np.random.Generator, form: RegressorForm) -> np.ndarray:
    """theta0 with the drag forces D_k positive and the load terms of either sign."""
    theta0 = random_theta0(rng, form.n_base - 8)
    theta0[8 + form.n_casters :] = rng.normal(0.0, 0.5, form.n_base - 8 - form.n_casters)
    return theta0


# --- the form -------------------------------------------------------------------------------------------------------


def test_form_names_units_and_round_trip():
    """Base parameters D_1..D_K then D{k}{signal} caster-major; two columns (v part, w part) per parameter; the
    friction model's name; every new parameter has a unit; JSON round trip; without_load drops exactly them."""
    assert LOAD1.base_names[8:] == ("D1", "D1dv", "D1w2")
    assert LOAD3.base_names[8:11] == ("D1", "D2", "D3")
    assert LOAD3.base_names[11:15] == ("D1dv", "D1w2", "D1vw", "D1dw")
    assert LOAD3.n_base == 8 + 3 * 5
    assert LOAD3.n_columns == 8 + 2 * 3 * 5
    assert LOAD1.column_names[10:] == ("-drag1_v*dv", "-drag1_w*dv", "-drag1_v*w2", "-drag1_w*w2")
    assert LOAD1.caster_map == ((8, 8, 1), (9, 8, -1), (10, 9, 1), (11, 9, -1), (12, 10, 1), (13, 10, -1))
    assert LOAD1.derivative_columns == ((10, 0), (11, 0))
    assert LOAD3.derivative_columns == tuple(
        (8 + 6 + 2 * (4 * k + 3) + part, 1) if sig == 3 else (8 + 6 + 2 * 4 * k + part, 0)
        for k in range(3) for sig in (0, 3) for part in (0, 1)
    )  # fmt: skip
    assert LOAD1.friction == "wheel+caster+load"
    units = model.base_units()
    assert [units[n] for n in LOAD3.base_names[11:15]] == ["N s^2/m", "N s^2/rad^2", "N s^2/(m rad)", "N s^2/rad"]
    assert all(n in model.base_units("PWM") for n in LOAD3.base_names)
    for form in LOAD_FORMS.values():
        again = RegressorForm.from_dict(json.loads(json.dumps(form.to_dict())))
        assert again == form
        assert form.without_load() == RegressorForm("general", caster=True, geometry=form.geometry)
    for bad in ({"load": ("w2", "dv")}, {"load": ("x",)}, {"load": ("dv", "dv")}):
        with pytest.raises(ValueError, match="load signals"):
            RegressorForm("general", caster=True, geometry=ONE_CASTER, **bad)
    with pytest.raises(ValueError, match="load signals"):
        RegressorForm("general", caster=True, load=("dv",))
    assert model.load_signals(ONE_CASTER) == ("dv", "w2")
    assert model.load_signals(THREE_CASTERS) == model.LOAD_SIGNALS


# --- the drag, the regression form, the implicit direct model -------------------------------------------------------


@pytest.mark.parametrize("name", list(LOAD_FORMS))
def test_loaded_drag_matches_rigid_body_kinematics(name):
    """friction_torque(eta, theta0, form, eta_dot) minus the wheels' own friction equals -J^T Q of each caster's
    force -D_k(t) u/|u| with D_k(t) = D_k + sum L_ks s(t) computed here, on 450 speeds (random accelerations) x 5
    parameter sets: to 1e-12 of the largest drag torque (the same few products in another order; measured 1e-15)."""
    form = LOAD_FORMS[name]
    rng = np.random.default_rng(11)
    eta = speed_samples(rng)
    for _ in range(5):
        theta0 = random_load_theta0(rng, form)
        eta_dot = rng.normal(0.0, 20.0, size=eta.shape)
        expected = caster_drag(eta, form.geometry, loaded_forces(theta0, form, eta, eta_dot))[0]
        got = torques.friction_torque(eta, theta0, form, eta_dot) - (theta0[4:6] * eta + theta0[6:8] * np.sign(eta))
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12 * np.max(np.abs(expected)))
    with pytest.raises(ValueError, match="eta_dot"):
        torques.friction_torque(eta, theta0, form)


@pytest.mark.parametrize("name", list(LOAD_FORMS))
def test_regression_form_and_the_implicit_direct_model(name):
    """g(eta, tau, eta') theta^T equals M^-1 (tau - V - friction - drag(eta, eta')) computed here (1e-12 of the
    largest |eta'|; measured 1e-15).  wheel_acceleration solves the implicit (M + A(eta)) eta' = tau - V - ...: its
    eta' is a fixed point of that (1e-10 of the largest |eta'|: a 2x2 solve; measured 1e-15) and wheel_torque gives
    tau back (1e-10 of max |tau|; measured 1e-15).  load_inertia is the derivative of the drag in eta' (central
    differences of step 10 rad/s^2, exact for an affine map up to the rounding of the torques, ~1e-16 of their size
    over the step: tolerance 1e-13 of the largest torque; measured 2e-17)."""
    form = LOAD_FORMS[name]
    rng = np.random.default_rng(12)
    eta = speed_samples(rng)
    for _ in range(5):
        theta0 = random_load_theta0(rng, form)
        theta0[8 + form.n_casters :] *= 1e-3  # a load term small beside the inertia (M + A stays invertible)
        tau = rng.normal(0.0, 2.0, size=eta.shape)
        eta_dot = rng.normal(0.0, 20.0, size=eta.shape)
        m = model.inverse_inertia(theta0)
        vc = theta0[3]
        coriolis = vc * np.stack([eta[:, 0] * eta[:, 1] - eta[:, 1] ** 2, eta[:, 0] * eta[:, 1] - eta[:, 0] ** 2], 1)
        wheel = theta0[4:6] * eta + theta0[6:8] * np.sign(eta)
        drag = caster_drag(eta, form.geometry, loaded_forces(theta0, form, eta, eta_dot))[0]
        expected = (tau - coriolis - wheel - drag) @ m.T
        theta = model.intermediate_parameters(theta0, form)
        got = model.regressor(eta, tau, form, eta_dot) @ theta.T
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12 * np.max(np.abs(expected)))
        acc = torques.wheel_acceleration(eta, tau, theta0, form)
        fixed = model.regressor(eta, tau, form, acc) @ theta.T
        np.testing.assert_allclose(fixed, acc, rtol=0, atol=1e-10 * np.max(np.abs(acc)))
        back = torques.wheel_torque(eta, acc, theta0, form)
        np.testing.assert_allclose(back, tau, rtol=0, atol=1e-10 * np.max(np.abs(tau)))
        a = torques.load_inertia(eta, theta0, form)
        size = np.max(np.abs(torques.friction_torque(eta, theta0, form, eta_dot)))
        for j in range(2):
            step = np.zeros(2)
            step[j] = 10.0
            diff = torques.friction_torque(eta, theta0, form, eta_dot + step) - torques.friction_torque(
                eta, theta0, form, eta_dot - step
            )
            np.testing.assert_allclose(diff / 20.0, a[:, :, j], rtol=0, atol=1e-13 * size)


@pytest.mark.parametrize("name", list(LOAD_FORMS))
def test_filter_regressor_holds_the_multipliers(name):
    """filter_regressor equals regressor except in the derivative columns, which hold c(eta) with c(eta) x phi' the
    regressor's (phi' = v' or w' from eta'; to 1e-14 of each column's largest entry: one product; measured exact)."""
    form = LOAD_FORMS[name]
    rng = np.random.default_rng(13)
    eta = speed_samples(rng)
    tau = rng.normal(0.0, 2.0, size=eta.shape)
    eta_dot = rng.normal(0.0, 20.0, size=eta.shape)
    full = model.regressor(eta, tau, form, eta_dot)
    held = model.filter_regressor(eta, tau, form)
    derivative = dict(form.derivative_columns)
    rates = kinematics(eta_dot, R, B) if form is LOAD1 else kinematics(eta_dot, *THREE_CASTERS[:2])
    for j in range(form.n_columns):
        expected = full[:, j]
        got = held[:, j] * rates[derivative[j]] if j in derivative else held[:, j]
        np.testing.assert_allclose(got, expected, rtol=0, atol=1e-14 * max(np.max(np.abs(expected)), 1e-300))
    with pytest.raises(ValueError, match="eta_dot"):
        model.regressor(eta, tau, form)


@pytest.mark.parametrize("name", list(LOAD_FORMS))
def test_jacobian_and_recovery(name):
    """jacobian_intermediate against central differences (step 1e-6 of the parameter's scale, f affine in each:
    tolerance 1e-7 of each column's largest entry; measured 1e-9); direct_recovery and the minimum-distance fit of
    exact intermediate parameters return theta0 to 1e-12 relative (measured 1e-15) with chi2 < 1e-18."""
    form = LOAD_FORMS[name]
    rng = np.random.default_rng(14)
    for _ in range(3):
        theta0 = random_load_theta0(rng, form)
        jac = jacobian_intermediate(theta0, form)
        for j in range(form.n_base):
            step = 1e-6 * (np.max(np.abs(theta0[:3])) if j < 3 else abs(theta0[j]))
            up, down = theta0.copy(), theta0.copy()
            up[j] += step
            down[j] -= step
            numeric = (model.intermediate_parameters(up, form) - model.intermediate_parameters(down, form)).ravel()
            numeric /= 2.0 * step
            np.testing.assert_allclose(jac[:, j], numeric, rtol=0, atol=1e-7 * np.max(np.abs(jac[:, j])))
        theta = model.intermediate_parameters(theta0, form)
        np.testing.assert_allclose(direct_recovery(theta, form), theta0, rtol=1e-12, atol=0)
        fit = fit_base_parameters(theta, np.eye(2 * form.n_columns), form)
        np.testing.assert_allclose(fit.theta0, theta0, rtol=1e-12, atol=0)
        assert fit.chi2 < 1e-18


# --- the observer's filters -----------------------------------------------------------------------------------------


def _settings(form: RegressorForm, k: float = 3.0, hold: str = "zoh") -> ObserverSettings:
    theta0 = np.concatenate([model.base_parameters(PAPER_NOMINAL), np.zeros(form.n_base - 8)])
    theta_init = model.intermediate_parameters(theta0, form)
    inf = np.full(theta_init.shape, np.inf)
    return ObserverSettings(
        form=form, theta_init=theta_init, theta_min=-inf, theta_max=inf, k=k, alpha=1e-3, torque_hold=hold
    )


@pytest.mark.parametrize("name", list(LOAD_FORMS))
def test_kernel_regressor_is_the_filter_regressor(name):
    """wmrid.estimators.observer.kernel._regressor_rows with the load codes equals filter_regressor on ~450 samples with
    the special
    speeds: to 1e-14 of each column's largest entry (the same arithmetic in the same order; measured exact).  Both
    with the drag's direction taken from the measured speeds and from other ones (the sign speeds,
    :mod:`wmrid.estimators.sign_speed`: here the measured speeds shuffled, so that direction and load signals
    differ)."""
    form = LOAD_FORMS[name]
    assert kernel_kind(form) == KIND_CASTER_GEOMETRY
    rng = np.random.default_rng(15)
    eta = speed_samples(rng)
    tau = rng.normal(0.0, 2.0, size=eta.shape)
    geom, load = np.array(form.geometry), load_codes(form)
    out = np.empty((len(eta), form.n_columns))
    for signs in (eta, eta[rng.permutation(len(eta))]):
        expected = model.filter_regressor(eta, tau, form, signs)
        scale = np.maximum(np.max(np.abs(expected), axis=0), 1e-300)
        _regressor_rows(out, eta, signs, tau, 0, KIND_CASTER_GEOMETRY, geom, load)
        assert np.all(np.abs(out - expected) <= 1e-14 * scale)


def test_derivative_column_is_the_exact_filter():
    """The readable step's filtered regressor w of a column c(eta) phi' (phi = v, and phi = w) equals the filter
    integral int exp(-k (t - s)) c(s) phi'(s - h_prev) ds of the samples' linear interpolants, phi' taken one step late
    (DERIVATIVE_LAG: phi's rate over the previous step; 0 over the first), computed here by 8-point Gauss-Legendre on
    each step (exact: on a step c is linear, phi' constant, the weight an exponential, smooth) over 2 s of a
    reversing log, uneven steps: to 1e-10 of the column's filtered size (the recursion and the quadrature add ~2000
    terms in different orders; measured 1e-14).  No derivative of the speeds was formed: with c constant (driving
    straight at v > 0: c = r/2) the same integral is, one step late, phi - exp(-k t) phi_0 - k (filtered phi) of the
    speeds delayed by a step: to 1e-5 (c = (r/2) v / sqrt(v^2 + DRAG_SPEED^2) is constant to DRAG_SPEED^2 / (2 v^2)
    < 2e-6 here)."""
    log = open_loop_log(duration=2.0, reversing=True, uneven=True)
    form = LOAD3
    settings = _settings(form)
    state = initial_state(log.t[0], log.eta[0], log.tau[0], settings)
    mult = model.filter_regressor(log.eta, log.tau, form)
    nodes, weights = np.polynomial.legendre.leggauss(8)
    filt = np.zeros(form.n_columns)
    k = settings.k
    r, b = form.geometry[:2]
    for i in range(1, len(log.t)):
        state = observer_step(state, log.t[i], log.eta[i], log.tau[i], settings)
        t0, t1 = log.t[i - 1], log.t[i]
        h = t1 - t0
        s = t0 + 0.5 * h * (nodes + 1.0)
        frac = (s - t0) / h
        if i == 1:
            rates = kinematics(np.zeros((1, 2)), r, b)
        else:
            rates = kinematics((log.eta[i - 1] - log.eta[i - 2])[None, :] / (t0 - log.t[i - 2]), r, b)
        for col, which in form.derivative_columns:
            c = (1.0 - frac) * mult[i - 1, col] + frac * mult[i, col]
            filt[col] = (
                np.exp(-k * h) * filt[col] + 0.5 * h * np.sum(weights * np.exp(-k * (t1 - s)) * c) * rates[which][0]
            )
    for col, _ in form.derivative_columns:
        assert abs(state.w[col] - filt[col]) <= 1e-10 * max(abs(filt[col]), 1e-3 * np.max(np.abs(mult[:, col])))
    # c constant: straight driving forwards, the pitch column -(r/2) v' (one caster on the centre line, 1 m/s scale)
    t = np.linspace(0.0, 2.0, 801)
    speed = 10.0 + 3.0 * np.sin(2.0 * t)
    eta = np.column_stack([speed, speed])
    tau = np.zeros_like(eta)
    settings = _settings(LOAD1)
    state = initial_state(t[0], eta[0], tau[0], settings)
    v = R * speed
    v_late = np.concatenate([[v[0]], v[:-1]])  # phi one step late (an even grid): the first step's rate is 0
    v_filt = 0.0
    for i in range(1, len(t)):
        state = observer_step(state, t[i], eta[i], tau[i], settings)
        h = t[i] - t[i - 1]
        s = t[i - 1] + 0.5 * h * (nodes + 1.0)
        lin = v_late[i - 1] + (s - t[i - 1]) / h * (v_late[i] - v_late[i - 1])
        v_filt = np.exp(-k * h) * v_filt + 0.5 * h * np.sum(weights * np.exp(-k * (t[i] - s)) * lin)
    c = -0.5 * R * v[0] / np.sqrt(v[0] ** 2 + model.DRAG_SPEED**2)
    expected = c * (v_late[-1] - np.exp(-k * (t[-1] - t[0])) * v_late[0] - k * v_filt)
    assert state.w[10] == pytest.approx(expected, rel=1e-5)  # c = (r/2) v/sqrt(v^2 + DRAG_SPEED^2) moves by < 2e-6


@pytest.mark.parametrize("hold", ["zoh", "foh"])
def test_kernel_agrees_with_readable_step(hold):
    """The compiled replay and the readable step on a reversing, uneven 2 s log with the three-caster load form
    (all four signals): theta, Gamma, Gamma^-1 and the prediction errors to 1e-12 of their scale, as for every form
    (tests/unit/estimators/test_observer.py)."""
    log = open_loop_log(duration=2.0, reversing=True, uneven=True)
    settings = _settings(LOAD3, hold=hold)
    state = initial_state(log.t[0], log.eta[0], log.tau[0], settings)
    errors = [state.e_prior]
    for i in range(1, len(log.t)):
        state = observer_step(state, log.t[i], log.eta[i], log.tau[i], settings)
        errors.append(state.e_prior)
    out = replay(log.t, log.eta, log.tau, settings, max_history=len(log.t), chunk=777)
    scale = np.max(np.abs(state.theta))
    np.testing.assert_allclose(out.theta, state.theta, rtol=0, atol=1e-12 * scale)
    np.testing.assert_allclose(out.gamma, state.gamma, rtol=1e-12)
    np.testing.assert_allclose(out.gamma_inv, state.gamma_inv, rtol=0, atol=1e-12 * np.max(np.abs(state.gamma_inv)))
    np.testing.assert_allclose(out.hist_e, np.array(errors), rtol=0, atol=1e-12 * np.max(np.abs(log.eta)))


# --- the load transfer in the MuJoCo prototype ----------------------------------------------------------------------


def test_engine_normal_force_follows_the_rigid_body_statics():
    """The light AMR's CAD robot on the MuJoCo prototype (its centre of mass behind the axle, so it stands on the
    rear caster and the wheels; the front caster stays off the ground), 6 s of the sinusoid at 1 kHz, noise-free.
    The engine's contact normal force on the rear caster, at every sample, is fitted here by least squares on
    1, v', w^2, v w, w' (v, w from the true wheel speeds, v' and w' by a 41-sample Savitzky-Golay derivative).
    Statics written out here: the caster at x_c balances the moment about the wheels' ground line of the bodies'
    inertial forces, sum_i m_i H_i a_x,i with a_x,i = v' - x_i w^2 at height H_i (platform at r + cg_height, wheels
    and rotors at r), and of the wheels' spin 2 I_w v'/r (the rotors' spin is the joints' armature, which acts on
    no body), so dN/dv' = -(sum m_i H_i + 2 I_w / r) / x_c and dN/dw^2 = (m_p H_p d_x + 2 m_r r c_x) / x_c.
    Asserted: the front caster carries nothing; the fit leaves < 2 % of the normal force's variation (measured
    0.5 %); dN/dv' within 1 % of the statics (measured 0.04 % on the 60 s plan), dN/dw^2 within 3 % (measured 0.4 %);
    the lateral terms v w, w' below 2 % of the pitch's in their effect (the caster is on the centre line)."""
    pytest.importorskip("mujoco")
    from scipy.signal import savgol_filter

    from wmrid.sim import multibody

    p = AMR_CAD
    casters = multibody.default_casters(p)
    settings = multibody.MultibodySettings()
    rec = []
    original = multibody._Plant.caster_normals

    def recording(plant):
        out = original(plant)
        rec.append(out.copy())
        return out

    multibody._Plant.caster_normals = recording
    try:
        sim = multibody.simulate_multibody(
            p, p, casters=casters, settings=settings, trajectory="sinusoid", duration=6.0, rate=1000.0
        )
    finally:
        multibody._Plant.caster_normals = original
    normals = np.array(rec)
    front, rear = (0, 1) if casters[0].x > 0 else (1, 0)
    assert np.all(normals[:, front] == 0.0)
    t, eta = np.asarray(sim.t), np.asarray(sim.eta_true)
    v, w = kinematics(eta, p.r, p.b)
    dv, dw = (savgol_filter(x, 41, 3, deriv=1, delta=t[1] - t[0]) for x in (v, w))
    x = np.column_stack([np.ones_like(v), dv, w * w, v * w, dw])
    keep = slice(50, -50)  # the derivative's edges
    coef, *_ = np.linalg.lstsq(x[keep], normals[keep, rear], rcond=None)
    resid = normals[keep, rear] - x[keep] @ coef
    assert np.std(resid) < 0.02 * np.std(normals[keep, rear])
    x_c = casters[rear].x
    h_p = p.r + settings.cg_height
    dn_dv = -(p.m_p * h_p + 2 * p.m_w * p.r + 2 * p.m_r * p.r + 2 * p.I_w / p.r) / x_c
    dn_dw2 = (p.m_p * h_p * p.d_x + 2 * p.m_r * p.r * p.c_x) / x_c
    assert coef[1] == pytest.approx(dn_dv, rel=0.01)
    assert coef[2] == pytest.approx(dn_dw2, rel=0.03)
    pitch = np.std(x[keep, 1:3] @ coef[1:3])
    assert np.std(x[keep, 3:5] @ coef[3:5]) < 0.02 * pitch


# --- end to end -----------------------------------------------------------------------------------------------------

#: The load terms of the synthetic log: the rear caster's drag (0.35 N at rest) moves by 0.13 N per m/s^2 and by
#: 0.005 N per (rad/s)^2, the light AMR's on the MuJoCo prototype (0.015 x its 8.58 kg and 0.31 kg m).
LOAD_TRUTH = {"D1dv": 0.13, "D1w2": 0.005}


def loaded_log(duration: float = 30.0, dt: float = 1e-3, rtol: float = 1e-10) -> SimpleNamespace:
    """tests.unit.model.test_caster_model.synthetic_log's robot and torques with the drag D_1 + D1dv v' + D1w2 w^2,
    integrated
    here by DOP853 with the same stops at each wheel's reversal.  The drag's v' term makes the model implicit:
    (M + L (r/2) c [1, 1]) eta' = tau - V - F - (D_1 + D1w2 w^2) c, c the drag's wheel torques per newton (hand
    kinematics), solved as a 2x2 system at each evaluation."""
    th = TRUTH
    big_m = np.linalg.inv(np.array([[th["m11"], th["m12"]], [th["m12"], th["m22"]]]))
    fv, fd = np.array([th["Fv1"], th["Fv2"]]), np.array([th["Fd1"], th["Fd2"]])
    geometry = (R, B, CASTER_X, CASTER_Y)

    def rhs(t, y, signs):
        e1, e2 = y
        coriolis = th["Vc"] * np.array([e1 * e2 - e2 * e2, e1 * e2 - e1 * e1])
        per_newton = caster_drag(y[None, :], geometry, [1.0])[0][0]
        w = R * (e1 - e2) / (2.0 * B)
        force = th["D1"] + LOAD_TRUTH["D1w2"] * w * w
        lhs = big_m + LOAD_TRUTH["D1dv"] * np.outer(per_newton, [0.5 * R, 0.5 * R])
        return np.linalg.solve(lhs, excitation(t) - coriolis - fv * y - fd * signs - force * per_newton)

    t_eval = np.arange(round(duration / dt) + 1) * dt
    eta = np.empty((len(t_eval), 2))
    y, t0, done = np.array([0.3, -0.2]), 0.0, 0
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
        assert np.sign(rhs(t0, y, signs)[j]) == signs[j], "a wheel sticks"
    return SimpleNamespace(t=t_eval, eta=eta, tau=excitation(t_eval), source="synthetic", notes=())


@pytest.fixture(scope="module")
def robot():
    return Robot(name="synthetic", nominal=AMR_NOMINAL, casters=(Caster(x=CASTER_X, y=CASTER_Y),))


@pytest.fixture(scope="module")
def load_log():
    return loaded_log()


def test_identify_recovers_the_load_terms(load_log, robot):
    """friction auto on the noise-free log whose drag follows the load: the caster model, then its load terms
    (Wald p < 1e-3), every base parameter and D1 within 1e-3 relative of the truth and the load terms within 1 %
    (measured: worst base 2e-5, D1dv 1e-4, D1w2 4e-4), each within 3 std."""
    result = identify(load_log, robot, friction="auto", torque_hold="foh")
    assert result.form.friction == "wheel+caster+load"
    assert result.form.base_names[8:] == ("D1", "D1dv", "D1w2")
    record = result.diagnostics.friction
    assert record.load.taken
    assert record.load.p_value < 1e-3
    for name, truth in {**TRUTH, **LOAD_TRUTH}.items():
        value, std = result.parameters[name]
        tol = 1e-2 if name in LOAD_TRUTH else 1e-3
        assert abs(value - truth) <= tol * abs(truth), (name, value, truth)
        assert abs(value - truth) <= 3.0 * std, (name, value, truth, std)


def test_constant_drag_keeps_the_caster_model(robot):
    """On tests.unit.model.test_caster_model's log, whose drag does not follow the load, friction auto keeps
    wheel+caster:
    the load terms are not shown (measured p = 0.6), and the estimate is that of friction="wheel+caster"."""
    log = synthetic_log()
    result = identify(log, robot, friction="auto", torque_hold="foh")
    assert result.form.friction == "wheel+caster"
    assert not result.diagnostics.friction.load.taken
    plain = identify(log, robot, friction="wheel+caster", torque_hold="foh")
    assert result.parameters == plain.parameters


def test_the_load_model_needs_the_casters_positions():
    """friction="wheel+caster+load" without casters' positions is refused in one line."""
    from wmrid.core.errors import UsageError

    log = open_loop_log(duration=2.0, reversing=True)
    with pytest.raises(UsageError, match="casters' positions"):
        identify(log, None, friction="wheel+caster+load")
