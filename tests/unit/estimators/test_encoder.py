"""Speeds derived from encoder positions (issue 28, item 5): IDIM's filter chosen from the noise's effect, the
closed-loop check's attribution, and the reported estimate, on the paper sinusoid logged as a positions-only MCAP
of a 2048-count/rev encoder (tests/encoder_log.py).  The figures over seeds and at 512 counts/rev:
``bench/studies/study_encoder.py`` (docs/how-to/positions-only.md)."""

from __future__ import annotations

import numpy as np
import pytest

import wmrid
from tests.encoder_log import encoder_mcap
from wmrid.estimators import feedback
from wmrid.estimators.regression import idim
from wmrid.model.dynamics import THETA0_NAMES
from wmrid.model.robot import BUILTIN_ROBOTS
from wmrid.pipeline.identify import identify

JUDGED = ("m11", "m12", "m22", "M11", "M12", "M22", "Vc")


@pytest.fixture(scope="module")
def encoder_log(tmp_path_factory):
    """Paper sinusoid, 40 s at 1 kHz, no sensor noise; positions quantised to 2048 counts/rev (seed 0)."""
    run = wmrid.simulate("paper", noise=wmrid.NoiseSettings(seed=0))
    path = encoder_mcap(tmp_path_factory.mktemp("enc") / "encoder.mcap", run.log, 2048, seed=0)
    return path, run.truth["parameters"]


def test_the_reported_estimate_is_within_one_percent_and_honest(encoder_log):
    """Defaults, the MCAP's positions only: inertia entries and Vc within 1 % (the issue's criterion; measured
    0.02 % here, at most 0.05 % over 10 seeds), truth within 3 std or flagged, no spurious effort delay applied
    (the delay check's regression is IDIM's, whose 10 Hz band carried the noise's bias: -1.1 ms before), and the
    closed-loop check does not replace the observer."""
    path, truth = encoder_log
    result = wmrid.identify(str(path), "paper")
    assert any("derived from wheel positions" in note for note in result.log_info.notes)
    assert result.method == "observer"
    assert not result.diagnostics.feedback.applied
    assert result.diagnostics.delay is None or result.diagnostics.delay.applied_s == 0.0
    flagged = set(result.diagnostics.flagged or ())
    for name in JUDGED:
        value, std = result.parameters[name]
        assert abs(value / truth[name] - 1) < 0.01, name
        assert abs(value - truth[name]) <= 3 * std or name in flagged, name
    # the noise floor is taken at the derivative's window: the smoothed quantisation noise is no misfit, so nothing
    # is flagged and the verdict is not "in doubt" (every parameter was, before; wmrid.estimators.noise_floor)
    assert flagged == set()
    assert not result.diagnostics.uncertainty.model_error.prediction_misfit.applied
    assert all(g.status != "in doubt" for g in result.verdict.groups), result.verdict


def test_idim_lowers_its_default_cutoff_while_the_estimate_moves_with_it(encoder_log):
    """The spectral rule picks 10 Hz (the Savitzky-Golay derivative low-passes the quantisation noise, so the floor
    above rate / 4 is far below it at 50 Hz); there the estimate moves with the cutoff (errors in variables), so it
    is lowered (to 5 Hz) and the inertia comes within 0.1 % (measured 0.02 %; 0.5 % at 10 Hz).  A given cutoff is
    kept as given."""
    path, truth = encoder_log
    log = wmrid.read_log(str(path))
    t, eta, tau = (np.asarray(a) for a in (log.t, log.eta, log.tau))
    est = idim.identify_idim(t, eta, tau)
    steps = est.diagnostics["cutoff_lowered"]
    assert steps[0]["from_hz"] == 10.0
    assert est.diagnostics["cutoff_hz"] == pytest.approx(10.0 / np.sqrt(2.0) ** len(steps))
    assert "lowered" in est.diagnostics["cutoff_rule"]
    named = dict(zip(THETA0_NAMES, est.theta0, strict=True))
    for name in ("m11", "m12", "m22", "Vc"):
        assert abs(named[name] / truth[name] - 1) < 1e-3, name
    given = idim.identify_idim(t, eta, tau, cutoff_hz=10.0)
    assert given.diagnostics["cutoff_hz"] == 10.0
    assert "cutoff_lowered" not in given.diagnostics


def test_a_difference_explained_by_idims_filter_is_not_called_feedback(encoder_log, monkeypatch):
    """Without the lowering (IDIM at 10 Hz, as before), IDIM's own cutoff check measures how its estimate moves with
    its filter; with that term in the difference's variance the check keeps the observer (widened: 1.2 std of the
    difference) and names the term it counted.  Without it, the same difference read as feedback (5.0 std, gate
    3.8) and IDIM, the worse estimate, was reported, as in the issue."""
    monkeypatch.setattr(idim, "MAX_LOWERINGS", 0)
    path, _ = encoder_log
    log = wmrid.read_log(str(path))
    checked = identify(log, BUILTIN_ROBOTS["paper"])
    record = checked.diagnostics.feedback
    assert checked.method == "observer"
    assert record.checked
    assert not record.applied
    assert "cutoff" in record.other_systematic
    monkeypatch.setattr(feedback, "systematic_variance", lambda other: (np.zeros(len(other.theta0)), []))
    unaware = identify(log, BUILTIN_ROBOTS["paper"])
    assert unaware.diagnostics.feedback.applied
    assert unaware.method == "idim"


def test_a_coarse_encoders_speed_that_dips_below_zero_keeps_the_paper_form(tmp_path):
    """512 counts/rev at 1 kHz: the speed derived from the positions dips to about -0.5 rad/s where the true speed
    (never below 0.7 rad/s) is slowest, so the measured speed does not keep one sign; the 20 ms centred mean the sign
    columns take does.  The general form's two sign columns were then the same constant twice, the log's information
    singular along them, and identify refused the log as "not excited" (the speeds "barely vary") on 7 of 10 seeds;
    the survey now chooses the form by the sign the columns take (paper), and the estimate is within 0.5 %."""
    from wmrid.estimators.observer.survey import survey

    run = wmrid.simulate("paper", noise=wmrid.NoiseSettings(seed=1))
    truth = run.truth["parameters"]
    path = encoder_mcap(tmp_path / "encoder512.mcap", run.log, 512, seed=1)
    log = wmrid.read_log(str(path))
    assert np.asarray(log.eta).min() < 0 < np.asarray(run.log.to_frame()[["eta_r", "eta_l"]]).min()
    sv = survey([log], "encoder512")
    assert not all(sv.positive | sv.negative)
    assert sv.form().kind == "paper"
    assert sv.form().signs == (1, 1)
    assert sv.sign_pos.all()
    result = wmrid.identify(str(path), "paper")
    assert result.form.kind == "paper"
    assert all(g.status == "determined" for g in result.verdict.groups), result.verdict
    for name in JUDGED:
        assert abs(result.parameters[name][0] / truth[name] - 1) < 0.005, name
