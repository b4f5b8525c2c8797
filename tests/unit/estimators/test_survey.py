"""The survey (wmrid.estimators.observer.survey): one pass over a log in pieces gives the figures numpy computes on the
whole
arrays, whatever the pieces."""

from __future__ import annotations

import itertools
from types import SimpleNamespace

import numpy as np
import pytest
from locations import ROOT_DIR

from wmrid.core.errors import NotIdentifiableError
from wmrid.estimators.observer.survey import EXACT_STEPS, START_SPACING_S, survey


def _log(n: int = 5000, seed: int = 0, uneven: bool = False, reversing: bool = True):
    """A seeded random log: t (n,) s (1 ms steps, or uneven ones), eta (n, 2) rad/s, tau (n, 2) N m."""
    rng = np.random.default_rng(seed)
    steps = rng.uniform(0.5e-3, 1.5e-3, n - 1) if uneven else np.full(n - 1, 1e-3)
    t = 10.0 + np.concatenate(([0.0], np.cumsum(steps)))
    eta = rng.normal(0.3 if reversing else 5.0, 1.0, (n, 2))
    tau = rng.normal(0.1, 1.0, (n, 2))
    return t, eta, tau


def _pieces(t, eta, tau, size: int):
    return [
        SimpleNamespace(t=t[i : i + size], eta=eta[i : i + size], tau=tau[i : i + size]) for i in range(0, len(t), size)
    ]


@pytest.mark.parametrize("size", [1, 7, 1000, 5000])
def test_the_figures_are_numpys_on_the_whole_arrays(size):
    t, eta, tau = _log()
    sv = survey(_pieces(t, eta, tau, size), "log.csv")
    steps = np.diff(t)
    assert sv.n == len(t)
    assert (sv.t_first, sv.t_last) == (t[0], t[-1])
    assert sv.min_step == steps.min()
    assert sv.max_step == steps.max()
    assert sv.max_step_after == t[int(np.argmax(steps))]
    assert sv.median_step == np.median(steps)  # exact: few distinct steps
    np.testing.assert_array_equal(sv.speed_pos, (eta > 0).sum(axis=0))
    np.testing.assert_array_equal(sv.speed_neg, (eta < 0).sum(axis=0))
    np.testing.assert_array_equal(sv.effort_pos, (tau > 0).sum(axis=0))
    np.testing.assert_array_equal(sv.effort_neg, (tau < 0).sum(axis=0))
    np.testing.assert_array_equal(sv.opposing, (tau * eta < 0).sum(axis=0))
    # sums in another order: equal to rounding (n = 5000 terms of size ~1: 1e-12 relative is generous)
    np.testing.assert_allclose(sv.power, (tau * eta).sum(axis=0), rtol=1e-12)
    np.testing.assert_allclose(sv.abs_power, np.abs(tau * eta).sum(axis=0), rtol=1e-12)
    # the sparse sample: the first sample of each START_SPACING_S of time
    bucket = np.floor((t - t[0]) / START_SPACING_S)
    first = np.concatenate(([True], bucket[1:] != bucket[:-1]))
    np.testing.assert_array_equal(sv.sparse_t, t[first])
    np.testing.assert_array_equal(sv.sparse_eta, eta[first])


def test_the_median_of_many_distinct_steps_comes_from_the_histogram_to_its_stated_width():
    """Uneven steps (every one distinct, beyond EXACT_STEPS): the median within the histogram's relative bucket
    width 2**-12 (0.024 %), the same whatever the pieces."""
    t, eta, tau = _log(n=3 * EXACT_STEPS, uneven=True)
    whole = survey(_pieces(t, eta, tau, len(t)), "log")
    cut = survey(_pieces(t, eta, tau, 777), "log")
    assert whole.median_step == cut.median_step
    assert whole.median_step == pytest.approx(np.median(np.diff(t)), rel=2.0**-12)


@pytest.mark.parametrize(
    ("signs", "kind"), [((1, 1), "paper"), ((-1, 1), "paper"), ((-1, -1), "paper"), ((1, 0), "general")]
)
def test_the_form_follows_the_wheels_signs(signs, kind):
    """The paper's form when each wheel keeps one strict sign (as model.choose_form on the whole log); a wheel that
    turns the other way for 0.2 s (longer than the sign columns' 20 ms mean) needs the general form."""
    t, _, tau = _log(reversing=False)
    eta = np.abs(np.random.default_rng(1).normal(5.0, 1.0, (len(t), 2))) + 0.1
    eta = eta * np.array([s if s else 1 for s in signs])
    if signs[1] == 0:
        eta[100:300, 1] = -eta[100:300, 1]  # 0.2 s the other way
    form = survey(_pieces(t, eta, tau, 999), "log").form()
    assert form.kind == kind
    if kind == "paper":
        assert form.signs == signs


@pytest.mark.parametrize("size", [1, 999, 5000])
def test_a_speed_that_dips_across_zero_within_the_sign_mean_keeps_the_paper_form(size):
    """Samples the other way that the 20 ms centred mean of the sign columns does not follow (a coarse encoder's
    derived speed where the true speed is slow): the columns keep one sign, so the form is the paper's, whatever the
    pieces; the mean's counts are made only when the measured speed does not keep one sign.  A one-shot iterator
    cannot be read twice: its survey keeps the measured signs' answer (general)."""
    t, _, tau = _log(reversing=False)
    eta = np.abs(np.random.default_rng(1).normal(5.0, 1.0, (len(t), 2))) + 0.1
    eta[100, 1] = -eta[100, 1]  # one sample the other way
    eta[2000:2004, 0] = -0.5  # four
    sv = survey(_pieces(t, eta, tau, size), "log")
    assert not any(sv.positive)
    assert sv.sign_pos.all()
    assert not sv.sign_neg.any()
    assert sv.form().kind == "paper"
    assert sv.form().signs == (1, 1)
    clean = survey(_pieces(t, np.abs(eta), tau, size), "log")
    assert clean.form().kind == "paper"
    assert not clean.sign_pos.any()
    assert survey(iter(_pieces(t, eta, tau, size)), "log").form().kind == "general"


def test_an_implausible_value_stops_the_survey_naming_its_time():
    t, eta, tau = _log()
    eta[1234, 1] = np.nan
    with pytest.raises(NotIdentifiableError, match=r"log.csv: a wheel speed of nan rad/s at t = 11.234 s"):
        survey(_pieces(t, eta, tau, 500), "log.csv")
    t, eta, tau = _log()
    tau[10, 0] = 1e13
    with pytest.raises(NotIdentifiableError, match=r"an effort of 1e\+13 PWM"):
        survey(_pieces(t, eta, tau, 500), "log.csv", "PWM")


def test_an_effort_that_opposes_its_speed_is_named_with_the_fix():
    t, eta, tau = _log(reversing=False)
    tau = -np.abs(tau) * np.sign(eta)  # always against the speed
    warnings = survey(_pieces(t, eta, tau, 1000), "log").signal_warnings()
    assert len(warnings) == 2
    assert all("mostly opposes its speed" in w and "--flip-effort" in w for w in warnings)
    assert survey(_pieces(t, eta, -tau, 1000), "log").signal_warnings() == []


def test_swapped_speed_and_effort_columns_are_named_not_called_an_unsigned_current():
    """Issue 28: the bundled log read with its speed and effort columns exchanged (the speeds never change sign, the
    torques do) was diagnosed as 'an unsigned current'; the exchanged columns fit the model far better (R² 0.97
    against 0.31), and the warning says the columns look swapped.  Real unsigned currents (the BorealTC and DRIVE
    huskies, tests/contract/test_readme_real_logs.py) fit no better exchanged and keep the magnitude warning."""

    import wmrid
    from wmrid.core.wheel_log import stream_arrays

    sample = ROOT_DIR / "sample_logs" / "paper_sinusoid.csv"
    log = wmrid.read_log(sample, columns="t=t,eta_r=tau_r,eta_l=tau_l,tau_r=eta_r,tau_l=eta_l")
    warnings = survey(stream_arrays(log), "log").signal_warnings()
    assert len(warnings) == 2
    assert all("look swapped; check --columns" in w for w in warnings), warnings
    assert not any("magnitude" in w for w in warnings)


def test_the_sparse_sample_stays_bounded_and_does_not_depend_on_the_pieces(monkeypatch):
    """The survey's sparse sample (one sample per START_SPACING_S, for the data-driven start and the slow-speed
    threshold) held 23 MB for an 8 h log, three times over in identify; past SPARSE_MOST samples its spacing doubles
    (cut here to 100: a 20 s log of 400 intervals keeps the first sample of each 0.2 s, level 2).  The samples kept are
    the first of each interval counted from the first sample, however the log is cut into pieces."""
    from types import SimpleNamespace

    import wmrid.estimators.observer.survey as survey_module

    monkeypatch.setattr(survey_module, "SPARSE_MOST", 100)
    rng = np.random.default_rng(3)
    t = np.cumsum(rng.uniform(0.0005, 0.0015, 20_000))
    eta = 1.0 + rng.standard_normal((len(t), 2)) * 0.1
    tau = rng.standard_normal((len(t), 2))
    results = []
    for cuts in ([], [7], sorted(rng.choice(np.arange(1, len(t)), 50, replace=False).tolist())):
        bounds = [0, *cuts, len(t)]
        pieces = [SimpleNamespace(t=t[a:b], eta=eta[a:b], tau=tau[a:b]) for a, b in itertools.pairwise(bounds)]
        results.append(survey_module.survey(pieces, "s"))
    first = results[0]
    assert len(first.sparse_t) <= 100
    assert first.sparse_spacing == pytest.approx(0.05 * 4)
    interval = np.floor((t - t[0]) / 0.05).astype(np.int64) >> 2
    expected = np.flatnonzero(interval != np.concatenate(([-1], interval[:-1])))
    np.testing.assert_array_equal(first.sparse_t, t[expected])
    for other in results[1:]:
        np.testing.assert_array_equal(other.sparse_t, first.sparse_t)
        np.testing.assert_array_equal(other.sparse_eta, first.sparse_eta)
        np.testing.assert_array_equal(other.sparse_tau, first.sparse_tau)


def test_the_sign_means_pass_stops_at_the_first_reversal_of_each_wheel():
    """The second pass (only when a wheel's measured speed does not keep one sign) reads a reversing log only up to
    the piece where each wheel has had a mean <= 0 and one >= 0: a usual general-form log pays a few pieces, not a
    second whole read (a 1 h reversing log: 0.09 -> 0.28 s in memory, and a stream read from its file again, before)."""

    class Counted(list):
        reads = 0

        def __iter__(self):
            for piece in super().__iter__():
                Counted.reads += 1
                yield piece

    t, _, tau = _log(reversing=False)
    eta = np.abs(np.random.default_rng(1).normal(5.0, 1.0, (len(t), 2))) + 0.1
    eta[200:400] = -eta[200:400]  # both wheels reverse for 0.2 s early in the log
    pieces = Counted(_pieces(t, eta, tau, 100))
    sv = survey(pieces, "log")
    assert sv.form().kind == "general"
    assert not sv.sign_pos.any()
    assert not sv.sign_neg.any()
    assert Counted.reads == len(pieces) + 3  # the survey's pass, then pieces 0-2 (the reversal starts in piece 2)
