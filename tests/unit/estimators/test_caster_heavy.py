"""Caster drag on a heavy robot and on the light AMR, every method (issue 28, item 6).

The 20-seed figures are bench/studies/study_caster_heavy.py's; these are one seed of each case.
"""

from __future__ import annotations

import numpy as np
import pytest

import wmrid
from wmrid.core.wheel_log import WheelLog
from wmrid.model import dynamics as model
from wmrid.sim.multibody_model import MultibodySettings

BASE = ("m11", "m12", "m22", "M11", "M12", "M22", "Vc", "Fv1", "Fv2", "Fd1", "Fd2")
INERTIA_VC = ("m11", "m12", "m22", "M11", "M12", "M22", "Vc")
FRICTION = ("Fv1", "Fv2", "Fd1", "Fd2")


def wheel_log(sim) -> WheelLog:
    """The simulated log with its reference's wheel speeds (the instruments of --method iv)."""
    return WheelLog(
        t=np.array(sim.t), eta=np.array(sim.eta), tau=np.array(sim.tau), source="multibody", reference=sim.eta_ref
    )


@pytest.mark.parametrize("method", ["idim", "rls", "iv"])
def test_light_amr_with_dragging_casters_every_method(amr_caster_log, method):
    """The light AMR (issue 11's case, its casters' positions from the robot) with --friction auto: the caster
    model is taken, inertia and Vc within 3 % (measured <= 0.6 %), friction within 10 % or within 3 std (measured
    <= 3.3 %).  The observer's own figures are tests/unit/estimators/test_honest_std.py's."""
    result = wmrid.identify(wheel_log(amr_caster_log), "amr", method=method)
    truth = model.named_base(model.base_parameters(amr_caster_log.true))
    assert result.form.friction == "wheel+caster"
    for name in INERTIA_VC:
        assert abs(result.parameters[name][0] / truth[name] - 1) < 0.03, name
    for name in FRICTION:
        value, std = result.parameters[name]
        assert abs(value / truth[name] - 1) < 0.10 or abs(value - truth[name]) < 3 * std, name


@pytest.mark.slow
def test_heavy_robot_with_dragging_casters_every_method():
    """The paper robot carrying 60 kg off-centre on a mu = 0.6 floor, ball casters of rolling resistance 0.015,
    reversing, sensor noise (seed 0 of bench/studies/study_caster_heavy.py): every method's every parameter within 3
    std or flagged (measured |z| <= 1.3), inertia and Vc within 3.6 % (output error; the others <= 0.3 %).  The front
    caster's load moves by 4 % with the acceleration (-52 N per m/s^2): its drag is not constant, but a reversing
    run accelerates as much as it brakes in each direction, so the part the constant-drag model leaves out does not
    bias the estimate."""
    run = wmrid.simulate(
        "paper", engine=MultibodySettings(floor_friction=0.6, caster_resistance=0.015), trajectory="reversing",
        payload=wmrid.Payload(60, 0.2, 0.1), noise=wmrid.NoiseSettings(eta_std=0.02, tau_std=0.05, seed=0),
    )  # fmt: skip
    truth = run.truth["parameters"]
    for method in ("auto", "idim", "rls", "oe", "iv"):
        result = wmrid.identify(run.log, "paper", method=method)
        flagged = set(result.diagnostics.flagged)
        for name in BASE:
            value, std = result.parameters[name]
            assert name in flagged or abs(value - truth[name]) <= 3 * std, (method, name, value, std, truth[name])
        for name in INERTIA_VC:
            assert abs(result.parameters[name][0] / truth[name] - 1) < 0.036, (method, name)


@pytest.mark.slow
def test_heavy_robot_with_both_casters_touching_idim_and_iv():
    """The same robot with the payload at 60@-0.2,0 (both casters touch and trade +-26 N per m/s^2), seed 7 of
    bench/studies/study_caster_heavy.py --payload 60@-0.2,0: IDIM's and IV's Fv1 is 23 % off (as every method's, the
    observer's 22 %).  One jackknife grid put its std at 5.7 % (z = 4.1, unflagged; RLS's grid, one segment more,
    9.3 %); averaged over the grid's shifts (wmrid.estimators.regression.idim.GRID_SHIFTS) it is 8.0 % (z = 2.9), and
    every parameter is within 3 std or flagged."""
    run = wmrid.simulate(
        "paper", engine=MultibodySettings(floor_friction=0.6, caster_resistance=0.015), trajectory="reversing",
        payload=wmrid.Payload(60, -0.2, 0), noise=wmrid.NoiseSettings(eta_std=0.02, tau_std=0.05, seed=7),
    )  # fmt: skip
    truth = run.truth["parameters"]
    for method in ("idim", "iv"):
        result = wmrid.identify(run.log, "paper", method=method)
        assert result.diagnostics.method.figures["grid_shifts"] > 1
        flagged = set(result.diagnostics.flagged)
        for name in BASE:
            value, std = result.parameters[name]
            assert name in flagged or abs(value - truth[name]) <= 3 * std, (method, name, value, std, truth[name])
