"""IDIM with the casters' drag (``wheel+caster``): unchanged without it, exact regression with it, recovery of
the drag on a noise-free log of the direct model, and on the MuJoCo multibody AMR through
``wmrid.estimators.methods``."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest
from scipy.integrate import solve_ivp

from tests.open_loop import open_loop_log
from wmrid.core.errors import NotIdentifiableError
from wmrid.estimators.methods import run
from wmrid.estimators.options import MethodOptions
from wmrid.estimators.regression import idim, idim_rows
from wmrid.model import dynamics as model, torques
from wmrid.model.robot import BUILTIN_ROBOTS, PAPER_CAD
from wmrid.pipeline.identify import identify

AMR = BUILTIN_ROBOTS["amr"]
#: Two casters at distinct places (not mirrored, so each has its own D): (x, y) m in the platform frame.
CASTERS = (0.35, 0.0, -0.3, 0.1)
GEOMETRIC = model.RegressorForm("general", caster=True, geometry=(PAPER_CAD.r, PAPER_CAD.b, *CASTERS))
TWO_TERM = model.RegressorForm("general", caster=True)
#: The drag forces D_1, D_2 (N) of the synthetic log: 0.064 and 0.04 N m at each wheel, the size of F_d.
DRAG = (0.8, 0.5)


def phi_of(theta0: np.ndarray) -> np.ndarray:
    """phi = [M11 M12 M22, theta0[3:]] (the caster parameters are the same in both)."""
    named = model.named_base(theta0[:8])
    return np.concatenate([[named["M11"], named["M12"], named["M22"]], theta0[3:]])


@pytest.fixture(scope="module")
def reversing_log():
    return open_loop_log(duration=5.0, reversing=True)


def assert_same_estimate(a, b):
    assert np.array_equal(a.theta0, b.theta0)
    assert np.array_equal(a.cov, b.cov)
    assert a.dof == b.dof
    assert a.warnings == b.warnings
    assert {k: v for k, v in a.diagnostics.items()} == {k: v for k, v in b.diagnostics.items()}


@pytest.mark.parametrize("weighted", [False, True])
def test_a_form_without_caster_changes_nothing(reversing_log, weighted):
    """Bit for bit: a form without caster drag (paper or general) is the same as no form at all."""
    log = reversing_log
    plain = idim.identify_idim(log.t, log.eta, log.tau, weighted=weighted)
    assert len(plain.theta0) == 8
    for form in (model.RegressorForm("general"), model.RegressorForm("paper"), None):
        assert_same_estimate(idim.identify_idim(log.t, log.eta, log.tau, weighted=weighted, form=form), plain)
    reg = idim_rows.idim_regression(log.t, log.eta, log.tau, form=model.RegressorForm("general"))
    assert reg.form is None
    assert reg.phi_names == idim_rows.PHI_NAMES
    assert reg.feature_names == idim_rows.FEATURE_NAMES
    assert np.array_equal(reg.rows(), idim_rows.idim_regression(log.t, log.eta, log.tau).rows())


@pytest.mark.parametrize("form", [GEOMETRIC, TWO_TERM], ids=["geometric", "two-term"])
def test_regression_rows_reproduce_the_inverse_model_with_caster_drag(form):
    """X phi = tau of :func:`wmrid.model.torques.wheel_torque` with the drag (columns sharing a parameter add up)."""
    rng = np.random.default_rng(3)
    eta = rng.normal(0.0, 2.0, (500, 2))
    eta_dot = rng.normal(0.0, 5.0, (500, 2))
    theta0 = np.concatenate([model.base_parameters(PAPER_CAD), [0.8, 0.5]])
    x = idim_rows.regressor_rows(eta, eta_dot, form)
    assert x.shape == (500, 2, form.n_base)
    expected = torques.wheel_torque(eta, eta_dot, theta0, form)
    np.testing.assert_allclose(x @ phi_of(theta0), expected, rtol=0, atol=1e-12 * np.abs(expected).max())
    assert idim_rows.phi_names(form) == ("M11", "M12", "M22", *form.base_names[3:])


def test_theta0_jacobian_is_the_identity_on_the_caster_parameters():
    theta0 = np.concatenate([model.base_parameters(PAPER_CAD), DRAG])
    phi = phi_of(theta0)
    np.testing.assert_allclose(idim.phi_to_theta0(phi), theta0, rtol=1e-13)
    jac = idim.theta0_jacobian(phi)
    assert jac.shape == (10, 10)
    num = np.empty((10, 10))
    for j in range(10):
        step = np.zeros(10)
        step[j] = 1e-6 * abs(phi[j])
        num[:, j] = (idim.phi_to_theta0(phi + step) - idim.phi_to_theta0(phi - step)) / (2 * step[j])
    np.testing.assert_allclose(jac, num, rtol=1e-7, atol=1e-12)
    np.testing.assert_array_equal(jac[8:, :], np.eye(10)[8:, :])
    np.testing.assert_array_equal(jac[:, 8:], np.eye(10)[:, 8:])


@pytest.fixture(scope="module")
def caster_log():
    """The paper's CAD robot with two casters' geometric drag, open loop, 30 s at 1 kHz, no noise: the direct
    model with the drag (:func:`wmrid.model.torques.wheel_acceleration`) integrated by DOP853 at rtol 1e-10.

    The torques are sums of cosines (zero-mean speeds, both wheels reverse 9-13 times, and turn both ways)
    sampled at the log's instants.  Not held between samples: a zero-order hold puts the applied torque half a
    sample behind its samples, which on this log alone biases IDIM's Fv1 by 5 % and D by 0.9 % (measured; the
    same log with the torque averaged over each sample's half steps is back to <= 0.006 %): that is the log's
    timing, not the filter, and integrating a held torque interval by interval costs 30 s.
    """
    theta0 = np.concatenate([model.base_parameters(PAPER_CAD), DRAG])

    def torque(t):
        return np.stack(
            [
                2.0 * np.cos(1.3 * t) + 0.6 * np.cos(3.1 * t + 0.4) + 0.3 * np.cos(5.3 * t),
                1.6 * np.cos(0.9 * t) + 0.5 * np.cos(2.3 * t + 1.0) + 0.3 * np.cos(4.7 * t + 2.0),
            ],
            axis=-1,
        )

    def rhs(s, y):
        return torques.wheel_acceleration(y[None, :], torque(s)[None, :], theta0, GEOMETRIC)[0]

    t = np.arange(30_001) * 1e-3
    sol = solve_ivp(rhs, (t[0], t[-1]), [0.0, 0.0], t_eval=t, rtol=1e-10, atol=1e-12, method="DOP853")
    assert sol.success
    return SimpleNamespace(t=t, eta=sol.y.T.copy(), tau=torque(t), theta0=theta0)


def assert_recovers_geometric(est, log, rtol=5e-4):
    """The checks an IDIM-regression method's estimate on ``caster_log`` passes: every base parameter (D1, D2
    included) and M within ``rtol``, phi named with the casters' drag forces, a finite positive covariance."""
    assert len(est.theta0) == GEOMETRIC.n_base == 10
    np.testing.assert_allclose(est.theta0, log.theta0, rtol=rtol)
    named = model.named_base(est.theta0[:8])
    np.testing.assert_allclose([named[n] for n in ("M11", "M12", "M22")], phi_of(log.theta0)[:3], rtol=rtol)
    assert tuple(est.diagnostics["phi"]) == (*idim_rows.PHI_NAMES, "D1", "D2")
    assert tuple(est.diagnostics["phi_std"]) == (*idim_rows.PHI_NAMES, "D1", "D2")
    assert est.diagnostics["phi"]["D1"] == est.theta0[8]
    assert np.all(np.isfinite(est.cov))
    assert np.all(np.diag(est.cov) > 0)


def test_recovers_the_geometric_caster_drag_on_a_noise_free_log(caster_log):
    """Every base parameter, D_1 and D_2 included, within 0.05 %.

    On a noise-free log parallel filtering leaves only the filter's bias (the sampled sign changes, the
    derivative, the edges): measured at most 0.017 % (D2; inertia <= 7e-4 %, Vc 0.002 %, friction <= 0.006 %)
    at the default cutoff (10 Hz) and at most 0.018 % over cutoffs of 2-20 Hz; 0.05 % leaves a factor 3.
    The wheel-only model on the same log is off by 0.3-0.6 % on M and 100-570 % on friction.
    """
    log = caster_log
    est = idim.identify_idim(log.t, log.eta, log.tau, form=GEOMETRIC, torque_hold="foh")
    assert_recovers_geometric(est, log)
    reg = idim_rows.idim_regression(log.t, log.eta, log.tau, form=GEOMETRIC)
    assert reg.features.shape[1] == 8 + 4
    assert reg.feature_names[8:] == ("drag1_v", "drag1_w", "drag2_v", "drag2_w")
    assert np.all(reg.scales()[8:] > 0)
    # without the drag in the model it is absorbed elsewhere: the caster model is what makes the fit exact
    wheel_only = idim.identify_idim(log.t, log.eta, log.tau, torque_hold="foh")
    assert np.max(np.abs(wheel_only.theta0[4:] / log.theta0[4:8] - 1)) > 0.5


def test_caster_drag_not_told_from_coulomb_friction_is_refused_by_name(smooth_log):
    """Both wheels always forward: the two-term model's Cv column sgn(eta_1 + eta_2) = 1 is the Coulomb columns'
    too, so Fd1 + Cv and Fd2 + Cv are all the log determines; the refusal names them and says why."""
    with pytest.raises(NotIdentifiableError) as err:
        idim.identify_idim(smooth_log.t, smooth_log.eta, smooth_log.tau, form=TWO_TERM)
    text = str(err.value)
    assert "Fd1, Fd2, Cv undetermined" in text
    assert "Cw" not in text.split("undetermined")[0]
    assert "caster drag is told from the wheels' Coulomb friction only where" in text


def test_idim_with_caster_drag_on_the_multibody_amr(amr_caster_log):
    """``--method idim`` on the observer's ``wheel+caster`` result: IDIM models the drag too.

    Measured (seed 0): M11 +0.07 %, M12 +0.59 %, M22 +0.11 %, Vc +0.002 % (|z| <= 1.1); Fv1 -1.5 % (z -0.35),
    Fv2 +0.7 % (z 0.19), Fd1 -0.7 % (z -0.46), Fd2 -1.8 % (z -2.1); D1 0.3545 +/- 0.021 N against the engine's
    0.348 N (+1.8 %, z 0.3).  Asserted: the inertia entries and Vc within 3 %, D1 within 10 %.
    """
    sim = amr_caster_log
    log = SimpleNamespace(t=np.array(sim.t), eta=np.array(sim.eta), tau=np.array(sim.tau), source="amr", notes=())
    observer = identify(log, AMR, friction="wheel+caster", feedback=False)
    assert observer.form.caster
    assert observer.form.n_casters == 1
    result = run("idim", log, observer, MethodOptions(), AMR)
    assert result.method == "idim"
    assert len(result.estimate.theta0) == observer.form.n_base == 9
    truth = model.named_base(model.base_parameters(sim.true))
    # the mirrored pair (x = +-0.2 m, y = 0) has identical columns: one D, their total drag
    truth["D1"] = sum(c["mean_drag_force"] for c in sim.settings["multibody"]["casters"] if c["mean_drag_force"])
    errors = {}
    for name in ("M11", "M12", "M22", "Vc", "Fv1", "Fv2", "Fd1", "Fd2", "D1"):
        value, std = result.parameters[name]
        errors[name] = (100.0 * (value - truth[name]) / abs(truth[name]), (value - truth[name]) / std)
    print("\nIDIM wheel+caster on the multibody AMR: name error % z")
    for name, (err, z) in errors.items():
        print(f"  {name:4s} {err:+8.3f} {z:+6.2f}")
    for name in ("M11", "M12", "M22", "Vc"):
        assert abs(errors[name][0]) < 3.0, (name, errors[name])
    assert abs(errors["D1"][0]) < 10.0, errors["D1"]
    assert set(result.diagnostics.method.figures["phi"]) == {*idim_rows.PHI_NAMES, "D1"}


def test_compare_identifies_the_caster_model_with_every_method(amr_caster_log, tmp_path, capsys):
    """``wmrid compare --friction wheel+caster``: every method reports the casters' drag force D1 (N) next to the
    wheel friction, and ``--friction wheel`` none; IDIM's values, std (model-error widenings included) and flags
    are those ``identify --method idim`` reports.  The multibody AMR's log, written as CSV, through the CLI."""
    import json

    from wmrid.cli.app import main

    path = tmp_path / "amr.csv"
    sim = amr_caster_log
    np.savetxt(
        path, np.column_stack([sim.t, sim.eta, sim.tau]), delimiter=",", header="t,eta_r,eta_l,tau_r,tau_l",
        comments="",
    )  # fmt: skip
    for friction, has_drag in (("wheel+caster", True), ("wheel", False)):
        with pytest.raises(SystemExit) as err:
            main([
                "compare", str(path), "--robot", "amr", "--methods", "observer,idim,rls,oe", "--friction", friction,
                "--format", "json",
            ])  # fmt: skip
        assert err.value.code == 0
        out = json.loads(capsys.readouterr().out)
        for name in ("observer", "idim", "rls", "oe"):
            assert ("D1" in out["methods"][name]["parameters"]) == has_drag, (friction, name)
            assert "flagged" in out["methods"][name]
    # the std and flags are those of ``identify --method idim``: the library's run() on the same arrays
    log = SimpleNamespace(t=sim.t, eta=sim.eta, tau=sim.tau, source="amr", notes=())
    observer = identify(log, AMR, friction="wheel", feedback=False)
    idim_result = run("idim", log, observer, MethodOptions(), AMR)
    for key, (value, std) in idim_result.parameters.items():
        entry = out["methods"]["idim"]["parameters"][key]
        assert entry["value"] == pytest.approx(value, rel=1e-9)
        assert entry["std"] == pytest.approx(std, rel=1e-9)
    assert out["methods"]["idim"]["flagged"] == list(idim_result.diagnostics.flagged)
