"""RLS with the casters' drag (``wheel+caster``): unchanged without it, recovery of the drag on a noise-free log
of the direct model, and on the MuJoCo multibody AMR with the observer's form."""

from __future__ import annotations

from types import SimpleNamespace

import numpy as np
import pytest

from tests.open_loop import open_loop_log
from tests.unit.estimators.test_idim_caster import (  # noqa: F401 (caster_log: a fixture)
    GEOMETRIC,
    TWO_TERM,
    assert_recovers_geometric,
    caster_log,
    phi_of,
)
from wmrid.estimators.regression import idim, idim_rows, rls
from wmrid.model import dynamics as model
from wmrid.model.robot import BUILTIN_ROBOTS
from wmrid.pipeline.identify import identify

AMR = BUILTIN_ROBOTS["amr"]


def same(a, b) -> bool:
    if isinstance(a, np.ndarray):
        return np.array_equal(a, b, equal_nan=True)
    return a == b


@pytest.mark.parametrize("forgetting", [1.0, 0.999])
def test_a_form_without_caster_changes_nothing(forgetting):
    """Bit for bit: estimate, covariance, diagnostics (but the kernel's wall time) and history."""
    log = open_loop_log(duration=5.0, reversing=True)

    def run(**kw):
        est, hist = rls.rls_run(log.t, log.eta, log.tau, forgetting=forgetting, history_points=200, **kw)
        diagnostics = {k: v for k, v in est.diagnostics.items() if k != "kernel_seconds"}
        return (est.theta0, est.cov, est.dof, est.warnings, diagnostics, hist.t, hist.phi, hist.theta0, hist.std)

    plain = run()
    assert len(plain[0]) == 8
    assert tuple(plain[4]["phi"]) == idim_rows.PHI_NAMES
    for form in (model.RegressorForm("general"), model.RegressorForm("paper"), None):
        got = run(form=form)
        assert all(same(a, b) for a, b in zip(got, plain, strict=True)), form


def test_recovers_the_geometric_caster_drag_on_a_noise_free_log(caster_log):  # noqa: F811
    """Every base parameter, D_1 and D_2 included, within 0.05 % (lambda = 1), and 0.2 % (lambda = 0.9995).

    Without forgetting RLS is batch least squares on the undecimated filtered regression (measured: within
    1e-12 of numpy's lstsq and of IDIM without decimation), so it carries only the filter's bias on this
    noise-free log, as IDIM: measured at most 0.017 % (D2; inertia <= 7e-4 %, Vc 0.002 %, friction
    <= 0.005 %); 0.05 % leaves a factor 3.  With lambda = 0.9995 (a 2 s window, the last 2 s weigh most):
    at most 0.057 % (Fv1), so 0.2 %.
    """
    log = caster_log
    est, hist = rls.rls_run(log.t, log.eta, log.tau, form=GEOMETRIC, history_points=500, torque_hold="foh")
    assert_recovers_geometric(est, log)
    assert est.cov.shape == (10, 10)
    assert est.dof == est.diagnostics["segments"] - 1
    # the history has the caster parameters too, and ends at the estimate
    assert hist.phi.shape[1] == hist.theta0.shape[1] == hist.std.shape[1] == 10
    np.testing.assert_allclose(hist.theta0[-1], est.theta0, rtol=1e-14)
    defined = np.all(np.isfinite(hist.phi), axis=1)
    np.testing.assert_allclose(hist.theta0[defined], idim.phi_to_theta0(hist.phi[defined]), rtol=1e-13)
    assert np.all(np.isfinite(hist.std[-1]))
    # batch least squares on the same rows (the caster columns mapped by idim)
    reg = idim_rows.idim_regression(log.t, log.eta, log.tau, decimate=False, form=GEOMETRIC)
    x = reg.rows()
    lstsq = np.linalg.lstsq(x.reshape(-1, x.shape[-1]), reg.tau.reshape(-1), rcond=None)[0]
    np.testing.assert_allclose(list(est.diagnostics["phi"].values()), lstsq, rtol=1e-9)

    tracking = rls.identify_rls(log.t, log.eta, log.tau, forgetting=0.9995, form=GEOMETRIC, torque_hold="foh")
    np.testing.assert_allclose(tracking.theta0, log.theta0, rtol=2e-3)
    assert tracking.diagnostics["uncertainty"].startswith("local")
    assert np.all(np.isfinite(tracking.std))
    # the two-term model on the same log runs too (its own names), but is not the drag law of this log
    two = rls.identify_rls(log.t, log.eta, log.tau, form=TWO_TERM, torque_hold="foh")
    assert tuple(two.diagnostics["phi"])[8:] == ("Cv", "Cw")


def test_rls_with_caster_drag_on_the_multibody_amr(amr_caster_log):
    """RLS (lambda = 1) with the observer's ``wheel+caster`` form on the MuJoCo AMR.

    Measured (seed 0, cutoff 2.34 Hz, no decimation): M11 +0.07 %, M12 +0.59 %, M22 +0.12 %, Vc +0.004 %
    (|z| <= 1.2); Fv1 -1.5 % (z -0.35), Fv2 +0.7 % (z 0.20), Fd1 -0.7 % (z -0.45), Fd2 -1.8 % (z -2.2);
    D1 +1.8 % (z 0.3) against the engine's drag: as IDIM.  Asserted: the inertia entries and Vc within 3 %,
    D1 within 10 %.
    """
    sim = amr_caster_log
    log = SimpleNamespace(t=np.array(sim.t), eta=np.array(sim.eta), tau=np.array(sim.tau), source="amr", notes=())
    observer = identify(log, AMR, friction="wheel+caster")
    assert observer.form.caster
    assert observer.form.n_casters == 1
    est = rls.identify_rls(log.t, log.eta, log.tau, form=observer.form)
    names = observer.form.base_names
    assert len(est.theta0) == observer.form.n_base == 9
    got = model.named_base(est.theta0, names)
    std = dict(zip(names, est.std, strict=True))
    std.update({k: est.diagnostics["phi_std"][k] for k in ("M11", "M12", "M22")})  # phi holds M itself
    truth = model.named_base(model.base_parameters(sim.true))
    # the mirrored pair (x = +-0.2 m, y = 0) has identical columns: one D, their total drag
    truth["D1"] = sum(c["mean_drag_force"] for c in sim.settings["multibody"]["casters"] if c["mean_drag_force"])
    errors = {
        name: (100.0 * (got[name] - truth[name]) / abs(truth[name]), (got[name] - truth[name]) / std[name])
        for name in ("M11", "M12", "M22", "Vc", "Fv1", "Fv2", "Fd1", "Fd2", "D1")
    }
    print("\nRLS wheel+caster on the multibody AMR: name error % z")
    for name, (err, z) in errors.items():
        print(f"  {name:4s} {err:+8.3f} {z:+6.2f}")
    for name in ("M11", "M12", "M22", "Vc"):
        assert abs(errors[name][0]) < 3.0, (name, errors[name])
    assert abs(errors["D1"][0]) < 10.0, errors["D1"]
    assert set(est.diagnostics["phi"]) == {*idim_rows.PHI_NAMES, "D1"}
