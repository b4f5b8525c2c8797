"""``wmrid monitor`` against a caster-drag model (``identify --friction wheel+caster``): unchanged without it, the
caster columns in the inverse-dynamics regressor, no false alarm on the MuJoCo multibody AMR log it was identified
on, and a payload loaded mid-run found."""

from __future__ import annotations

import json
from types import SimpleNamespace

import numpy as np
import pytest

import wmrid.monitoring.monitor as mon
from wmrid.core.errors import UsageError
from wmrid.model import dynamics as model, torques
from wmrid.model.robot import BUILTIN_ROBOTS, Payload
from wmrid.monitoring import glr, residuals, settings as mon_settings
from wmrid.pipeline.identify import identify
from wmrid.sim.scenario import NoiseSettings, PlantChange
from wmrid.sim.simulate import simulate

AMR = BUILTIN_ROBOTS["amr"]
PAPER = BUILTIN_ROBOTS["paper"]
NOISE = NoiseSettings(eta_std=0.01, tau_std=0.02, caster_std=0.05)


def as_log(sim, name: str) -> SimpleNamespace:
    return SimpleNamespace(t=sim.t, eta=sim.eta, tau=sim.tau, source=name, notes=())


def spied_monitor(monkeypatch, log, model_):
    """monitor(log, model_) and every (z, x, [(width, ends, S)]) its window tests saw."""
    seen = []
    original = glr.window_statistics

    def spy(z, x, *args):
        out = original(z, x, *args)
        seen.append((z, x, out))
        return out

    monkeypatch.setattr(mon, "window_statistics", spy)
    result = mon.monitor(log, model_)
    monkeypatch.setattr(mon, "window_statistics", original)
    return result, seen


# ------------------------------------------------------------------------------------------ wheel friction


def test_a_wheel_friction_model_is_monitored_as_before(monkeypatch) -> None:
    """Bit for bit: a result whose form says ``wheel`` is the same as one without a form (the JSON of before the
    caster model), on every whitened residual, regressor and statistic array, with eight columns, the threshold
    of F(8, dof), and r = tau - Phi p with the eight wheel columns.  (Measured when this was written: the whole
    result, its statistic arrays included, identical to the code before the caster model.)"""
    data = json.loads(json.dumps(identify(as_log(simulate(PAPER.cad, PAPER.nominal, duration=20.0, noise=NOISE,
                                                          seed=11), "id"), PAPER).to_dict()))  # fmt: skip
    assert data["theta"]["form"]["friction"] == "wheel"
    old = json.loads(json.dumps(data))
    del old["theta"]["form"]
    log = as_log(simulate(PAPER.cad, PAPER.nominal, duration=24.0, noise=NOISE, seed=12), "run")
    runs = []
    for d in (data, old):
        m = mon_settings.model_from_dict(d, "m.json")
        assert m.form is None
        assert len(m.theta0) == len(m.std) == 8
        runs.append(spied_monitor(monkeypatch, log, m))
    (res_a, seen_a), (res_b, seen_b) = runs
    da, db = res_a.to_dict(), res_b.to_dict()
    da.pop("seconds"), db.pop("seconds")
    assert da == db
    assert da["detector"]["dof"] == 8
    assert "form" not in da["model"]
    assert len(seen_a) == len(seen_b) > 0
    for (za, xa, oa), (zb, xb, ob) in zip(seen_a, seen_b, strict=True):
        assert xa.shape[-1] == 8
        assert np.array_equal(za, zb)
        assert np.array_equal(xa, xb)
        for (wa, ea, sa), (wb, eb, sb) in zip(oa, ob, strict=True):
            assert wa == wb
            assert np.array_equal(ea, eb)
            assert np.array_equal(sa, sb)
    grid = res_a.grid
    assert grid.threshold(50.0) == grid.threshold(50.0, 8)
    # the residual is the eight-column one
    sig = residuals.residual_signals(log.t, log.eta, log.tau, mon_settings.MonitorSettings())
    m = mon_settings.model_from_dict(data, "m.json")
    assert sig.phi_for(None) is sig.phi
    assert sig.phi_for(model.RegressorForm("general"), "test") is sig.phi_test
    assert np.array_equal(sig.residual(m.theta0), sig.tau - sig.phi @ mon_settings.physical_vector(m.theta0))


# ------------------------------------------------------------------------------------------ caster drag


@pytest.fixture(scope="module")
def amr_caster_json(amr_caster_log) -> dict:
    log = as_log(amr_caster_log, "amr.csv")
    return json.loads(json.dumps(identify(log, AMR, friction="wheel+caster").to_dict()))


def test_a_caster_model_is_read_with_its_drag(amr_caster_json) -> None:
    m = mon_settings.model_from_dict(amr_caster_json, "amr.json")
    assert m.form is not None
    assert m.form.caster
    assert m.form.geometry
    names = m.form.base_names
    assert len(names) > 8
    assert len(m.theta0) == len(m.std) == len(names)
    for i, name in enumerate(names[8:], start=8):  # p's drag entries are theta0's, and so are their std
        assert m.theta0[i] == amr_caster_json["parameters"][name]["value"]
        assert m.std[i] == amr_caster_json["parameters"][name]["std"]
    broken = json.loads(json.dumps(amr_caster_json))
    del broken["theta"]["form"]["kind"]
    with pytest.raises(UsageError, match="caster-drag form"):
        mon_settings.model_from_dict(broken, "broken.json")


def test_the_caster_columns_are_the_drag_torque_smoothed(amr_caster_log, amr_caster_json) -> None:
    """Phi p's drag part is the model's caster drag torque (:func:`wmrid.model.torques.friction_torque`) smoothed as
    the other speed columns: the Savitzky-Golay smoothing is linear."""
    log = amr_caster_log
    m = mon_settings.model_from_dict(amr_caster_json, "amr.json")
    settings = mon_settings.MonitorSettings()
    sig = residuals.residual_signals(log.t, log.eta, log.tau, settings)
    phi = sig.phi_for(m.form)
    assert phi.shape[1:] == (2, len(m.theta0))
    assert np.array_equal(phi[:, :, :8], sig.phi)
    assert sig.phi_for(m.form, "test").shape == phi.shape
    drag = torques.friction_torque(log.eta, m.theta0, m.form) - torques.friction_torque(log.eta, m.theta0[:8])
    step = float(np.median(np.diff(log.t)))
    window = residuals._odd_window(settings.accel_window_s, step)
    half = max(window, residuals._odd_window(settings.regressor_window_s, step)) // 2
    centres = np.arange(half, len(log.t) - half, max(1, round(1.0 / step / settings.rate_hz)))
    expected = np.column_stack([residuals._savgol_at(drag[:, j], window, 0, step, centres) for j in range(2)])
    np.testing.assert_allclose(phi[:, :, 8:] @ m.theta0[8:], expected, rtol=1e-10, atol=1e-12)


def test_no_false_alarm_on_the_log_the_caster_model_came_from(amr_caster_log, amr_caster_json) -> None:
    m = mon_settings.model_from_dict(amr_caster_json, "amr.json")
    result = mon.monitor(as_log(amr_caster_log, "amr.csv"), m)
    assert result.changes == []
    det = result.to_dict()["detector"]
    n = len(m.theta0)
    assert det["dof"] == n
    assert f"F({n}, dof)" in det["threshold"]["rule"]
    assert result.to_dict()["model"]["form"]["friction"] == "wheel+caster"
    for cal in result.segments[0]["calibrations"]:
        assert cal["largest_statistic"] < cal["threshold"]


@pytest.mark.slow  # a second multibody run and a monitor over it: 7 s
def test_a_payload_loaded_mid_run_is_found(amr_caster_json) -> None:
    """5 kg loaded at 20 s on the multibody AMR, against the caster model of the unloaded robot (measured: the
    change placed at 20.05 s, alarm at 20.40 s, statistic 495 against a threshold of 86; M11 +26 %).  The span
    after the change is identified with the model's caster positions."""
    from wmrid.sim.multibody import simulate_multibody
    from wmrid.sim.multibody_model import MultibodySettings

    load = Payload(5.0, 0.0, 0.0, 0.05)
    sim = simulate_multibody(
        AMR.cad, AMR.nominal, casters=AMR.casters, settings=MultibodySettings(caster_resistance=0.015),
        trajectory="reversing", rate=200, noise=NoiseSettings(eta_std=0.02, tau_std=0.002), seed=1, duration=26.0,
        payload=load, change=PlantChange.payload_load(20.0, AMR.cad, load),
    )  # fmt: skip
    t_switch = sim.settings["change"]["t_switch"]
    result = mon.monitor(as_log(sim, "loaded.csv"), mon_settings.model_from_dict(amr_caster_json, "amr.json"))
    assert len(result.changes) == 1
    found = result.changes[0]
    assert t_switch <= found.t_alarm <= t_switch + 2.0
    assert found.t == pytest.approx(t_switch, abs=0.2)
    assert found.relative_change["M11"] > 0.05  # identified again after the change, heavier
    # with the model's own caster positions (one drag force per caster), not the two-term drag
    assert "D1" in found.parameters
    assert "Cv" not in found.parameters
