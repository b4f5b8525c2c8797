"""identify() end to end on logs with a known truth: forms, signs, excitation warnings, history."""

from __future__ import annotations

import numpy as np
import pytest
from locations import ROOT_DIR

from tests.open_loop import open_loop_log
from wmrid.estimators.result import REPORTED
from wmrid.model.dynamics import THETA0_NAMES
from wmrid.model.robot import BUILTIN_ROBOTS
from wmrid.pipeline.identify import identify

PAPER = BUILTIN_ROBOTS["paper"]


def relative_errors(result, theta0):
    return {n: abs(result.parameters[n][0] - v) / abs(v) for n, v in zip(THETA0_NAMES, theta0, strict=True)}


def test_left_wheel_always_backwards_uses_the_paper_form_with_its_sign():
    # Turning on the spot, right wheel forward, left wheel backward all the time.  Open loop this is
    # unstable (the centre of mass sits ahead of the axle), so a proportional speed loop holds it.
    def torque(t, eta):
        ref = np.array([2.0 + np.sin(1.3 * t) + 0.3 * np.sin(3.1 * t), -2.0 - 0.8 * np.sin(0.9 * t + 1)])
        return 5.0 * (ref - eta)

    log = open_loop_log(duration=20.0, torque=torque, eta0=[2.0, -2.0], feedback=True)
    assert np.all(log.eta[:, 0] > 0)
    assert np.all(log.eta[:, 1] < 0)
    result = identify(log, PAPER, torque_hold="foh")  # the torque is smooth: first-order hold is exact to O(h^2)
    assert result.form.kind == "paper"
    assert result.form.signs == (1, -1)
    errors = relative_errors(result, log.theta0)
    # Noise-free, 20 s: the estimate is exact up to the O(h^2) discretisation of the filters.
    assert max(errors.values()) < 1e-3, errors


def test_reversing_wheels_use_the_general_form():
    log = open_loop_log(duration=20.0, reversing=True)
    result = identify(log, PAPER, torque_hold="foh")
    assert result.form.kind == "general"
    errors = relative_errors(result, log.theta0)
    assert max(errors.values()) < 1e-3, errors


def test_a_log_with_constant_torques_is_refused():
    # Constant torques: the torque columns are constant like the Coulomb column, so no base parameter can
    # be told apart from the others; identify refuses with a clear error (exit code 1 in the CLI).
    from wmrid.core.errors import NotIdentifiableError

    log = open_loop_log(duration=10.0, torque=lambda t: np.array([1.0, 0.8]), eta0=[3.0, 3.0])
    with pytest.raises(NotIdentifiableError, match="does not excite the dynamics"):
        identify(log, PAPER)


def test_result_has_every_reported_parameter_with_a_finite_std(smooth_log):
    result = identify(smooth_log, PAPER)
    assert list(result.parameters) == list(REPORTED)
    for name, (value, std) in result.parameters.items():
        assert np.isfinite(value), name
        assert np.isfinite(std), name
        assert std > 0, name


def test_history_is_decimated_projected_and_ends_at_the_result(smooth_log):
    result = identify(smooth_log, PAPER, max_history=500)
    hist = result.history
    assert len(hist.t) == 500
    assert hist.theta.shape == (500, 2, result.form.n_columns)
    lo, _hi = result.diagnostics_box if hasattr(result, "diagnostics_box") else (None, None)
    assert np.all(np.diff(hist.t) > 0)
    # Gamma only grows; eigvalsh is accurate to about eps * lambda_max
    assert np.all(np.diff(hist.lambda_min) >= -1e-13 * result.diagnostics.lambda_max_gamma)
    np.testing.assert_allclose(hist.theta[-1], result.theta, rtol=1e-12, atol=1e-15)
    assert lo is None or np.all(hist.theta >= lo)


def test_unknown_robot_starts_from_the_data_and_converges(long_smooth_log):
    result = identify(long_smooth_log, None, torque_hold="foh")
    assert "from the data" in result.start_source
    errors = relative_errors(result, long_smooth_log.theta0)
    assert max(errors.values()) < 1e-3, errors


@pytest.mark.parametrize("k", [1.0, 10.0])
def test_paper_alpha_keeps_the_start_and_says_so(long_smooth_log, k):
    result = identify(long_smooth_log, PAPER, alpha=5000.0, k=k, torque_hold="foh")
    assert any("start value, not the data, sets them" in w for w in result.warnings)


def test_the_half_rate_run_inline_equals_it_on_its_thread():
    # wmrid fleet's workers run it on the caller's thread (estimators.replay.one_thread); same numbers, bit for bit
    from wmrid.api.identification import identify as api_identify
    from wmrid.estimators.observer import replay

    sample = str(ROOT_DIR / "sample_logs" / "paper_sinusoid.csv")
    threaded = api_identify(sample, "paper").to_dict()
    replay.one_thread()
    try:
        inline = api_identify(sample, "paper").to_dict()
    finally:
        replay.one_thread(False)
    assert inline == threaded
