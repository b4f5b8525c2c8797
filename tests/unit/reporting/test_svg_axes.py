"""The SVG figures' ticks (wmrid.reporting.svg_axes) against hand-computed cases: nice linear steps, compact labels,
log decades in superscript, calendar dates from year 1 to 9999."""

from __future__ import annotations

import datetime as dt

import numpy as np
import pytest
from hypothesis import assume, given, settings, strategies as st

from wmrid.reporting.svg_axes import (
    DATE_RANGE,
    date_number,
    date_ticks,
    linear_labels,
    linear_ticks,
    log_ticks,
    number_date,
    superscript,
    text_width,
)


@pytest.mark.parametrize(
    ("lo", "hi", "most", "ticks"),
    [
        (0.0, 7.3, 5, [0, 2, 4, 6]),  # step 1 gives 8 ticks, 2 gives 4
        (0.0, 7.3, 9, [0, 1, 2, 3, 4, 5, 6, 7]),
        (-2.4, 2.4, 6, [-2, -1, 0, 1, 2]),
        (0.0, 40.0, 9, [0, 5, 10, 15, 20, 25, 30, 35, 40]),
        (0.0, 40.0, 2, [0, 20, 40]),  # two ticks at least: 50 would give one
        (0.9, 2.1, 2, [1, 2]),
        (1.4045, 1.4063, 5, [1.4045, 1.405, 1.4055, 1.406]),
        (-0.000212, -0.000198, 4, [-0.00021, -0.000205, -0.0002]),
        (7.3, 0.0, 5, [0, 2, 4, 6]),  # limits in either order (an inverted axis)
    ],
)
def test_linear_ticks_hand_computed(lo, hi, most, ticks):
    got, step = linear_ticks(lo, hi, most)
    np.testing.assert_allclose(got, ticks, rtol=1e-12, atol=1e-15)
    assert step == pytest.approx(ticks[1] - ticks[0])


@settings(max_examples=200, deadline=None)
@given(
    lo=st.floats(-1e6, 1e6, allow_nan=False),
    span=st.floats(1e-9, 1e7),
    most=st.integers(2, 12),
)
def test_linear_ticks_are_nice_and_cover_the_range(lo, span, most):
    """1, 2 or 5 x 10^k; within the limits; no more than asked (or two when one step would give a single tick);
    at most one step from either end, so the labels span the data."""
    assume(span > 1e-9 * max(1.0, abs(lo)))  # narrower: a constant, widened by design
    hi = lo + span
    ticks, step = linear_ticks(lo, hi, most)
    mantissa = step / 10.0 ** np.floor(np.log10(step))
    assert min(abs(mantissa - m) for m in (1.0, 2.0, 5.0, 10.0)) < 1e-9
    assert len(ticks) >= 2
    if len(ticks) > most:  # more than asked only when the next step up would leave a single tick
        coarser = step * (2.5 if round(mantissa) == 2 else 2.0)
        assert np.floor(hi / coarser + 1e-9) - np.ceil(lo / coarser - 1e-9) + 1 < 2
    assert np.all(np.diff(ticks) > 0)
    ulps = 1e-12 * max(abs(lo), abs(hi))  # k x step rounds
    assert lo - 1e-9 * step - ulps <= ticks[0] <= lo + step * (1 + 1e-9) + ulps
    assert hi - step * (1 + 1e-9) - ulps <= ticks[-1] <= hi + 1e-9 * step + ulps
    np.testing.assert_allclose(ticks / step, np.round(ticks / step), atol=1e-6)


HUGE = 1.7976931348623157e308


@pytest.mark.parametrize(
    ("lo", "hi", "labels", "note"),
    [
        (-HUGE, HUGE, ["−1", "0", "1"], "×10³⁰⁸"),  # the span is beyond the floats
        (-8.5e307, 8.5e307, ["−5", "0", "5"], "×10³⁰⁷"),
        (HUGE / 2, HUGE, ["1.0", "1.2", "1.4", "1.6"], "×10³⁰⁸"),
    ],
)
def test_linear_ticks_at_the_ends_of_the_floats(lo, hi, labels, note):
    ticks, step = linear_ticks(lo, hi, 4)
    assert np.all(np.isfinite(ticks))
    assert np.all((ticks >= lo) & (ticks <= hi))
    assert linear_labels(ticks, step) == (labels, note)


@settings(max_examples=200, deadline=None)
@given(lo=st.floats(allow_nan=False, allow_infinity=False), hi=st.floats(allow_nan=False, allow_infinity=False))
def test_linear_ticks_of_any_finite_limits(lo, hi):
    ticks, step = linear_ticks(lo, hi, 5)
    assert len(ticks) >= 2
    assert np.all(np.isfinite(ticks))
    assert 0 < step < np.inf
    linear_labels(ticks, step)


@pytest.mark.parametrize(
    ("lo", "hi", "most", "labels", "note"),
    [
        (0.0, 7.3, 9, ["0", "1", "2", "3", "4", "5", "6", "7"], ""),
        (0.0, 1.0, 6, ["0.0", "0.2", "0.4", "0.6", "0.8", "1.0"], ""),
        (-2.4, 2.4, 6, ["−2", "−1", "0", "1", "2"], ""),  # a true minus sign, no "−0"
        (1e-7, 9e-7, 5, ["2", "4", "6", "8"], "×10⁻⁷"),
        (0.0, 3e6, 4, ["0", "1", "2", "3"], "×10⁶"),
        (1.41, 1.4100012, 4, ["0", "5", "10"], "×10⁻⁷ + 1.41"),  # digits past the fifth: an offset
        (1.4045, 1.4063, 5, ["1.4045", "1.4050", "1.4055", "1.4060"], ""),
    ],
)
def test_linear_labels_are_compact(lo, hi, most, labels, note):
    assert linear_labels(*linear_ticks(lo, hi, most)) == (labels, note)


def test_log_ticks_at_decades_in_superscript():
    major, labels, minor = log_ticks(1e-6, 1e2, 10)
    np.testing.assert_allclose(major, [10.0**k for k in range(-6, 3)])
    assert labels == ["10⁻⁶", "10⁻⁵", "10⁻⁴", "10⁻³", "10⁻²", "10⁻¹", "10⁰", "10¹", "10²"]
    assert len(minor) == 8 * 8  # 2..9 in each of the 8 decades between
    assert np.all((minor > 1e-6) & (minor < 1e2))


def test_log_ticks_thin_out_dense_decades():
    major, labels, minor = log_ticks(1e-12, 1e2, 5)  # 15 decades, 5 labels at most: every third
    assert labels == ["10⁻¹²", "10⁻⁹", "10⁻⁶", "10⁻³", "10⁰"]
    assert len(major) == 5
    assert len(minor) == 0


@pytest.mark.parametrize(
    ("lo", "hi", "labels"),
    [
        (1e-300, 1e300, ["10⁻²⁵⁸", "10⁻¹⁷²", "10⁻⁸⁶", "10⁰", "10⁸⁶", "10¹⁷²", "10²⁵⁸"]),  # 10^300: OverflowError
        (5e-324, 1.0, ["10⁻²⁸²", "10⁻²³⁵", "10⁻¹⁸⁸", "10⁻¹⁴¹", "10⁻⁹⁴", "10⁻⁴⁷", "10⁰"]),  # from the least subnormal
        (1.1e308, HUGE, [f"1.{d}×10³⁰⁸" for d in range(1, 8)]),  # 2×10³⁰⁸ is inf: linear steps, each in full
        (1.1e-7, 1.9e-7, ["1.2×10⁻⁷", "1.4×10⁻⁷", "1.6×10⁻⁷", "1.8×10⁻⁷"]),  # (were 1.2 ... without the ×10⁻⁷)
        (1.41, 1.4100012, [f"1.41000{d:02d}" for d in range(0, 13, 2)]),  # (were 0 ... 12 without the + 1.41)
        (5e-324, 1.5e-323, ["10⁻³²³"]),  # three floats: 5e-324, 1e-323 (which is 9.88e-324), 1.5e-323
    ],
)
def test_log_ticks_at_the_ends_of_the_floats(lo, hi, labels):
    major, got, minor = log_ticks(lo, hi, 7)
    assert got == labels
    assert np.all(np.isfinite(major))
    assert np.all((major >= lo * (1 - 1e-9)) & (major <= hi))
    assert np.all(np.isfinite(minor))


def test_log_ticks_within_a_decade():
    major, labels, minor = log_ticks(0.03, 0.2, 5)  # one decade tick only: 1-2-5
    np.testing.assert_allclose(major, [0.05, 0.1, 0.2])
    assert labels == ["0.05", "0.1", "0.2"]
    assert set(np.round(minor, 6)) == {0.03, 0.04, 0.06, 0.07, 0.08, 0.09}
    major, labels, _ = log_ticks(2e-7, 9e-7, 5)
    assert labels == ["2×10⁻⁷", "5×10⁻⁷"]
    major, labels, _ = log_ticks(0.031, 0.049, 5)  # less than a factor 2.5: linear steps
    assert labels == ["0.035", "0.040", "0.045"]
    assert log_ticks(0.0, 1.0, 5)[0].size == 0  # nothing positive to show: no ticks, no error


def _days(*args: int) -> float:
    return date_number(dt.datetime(*args))


def test_date_ticks_on_calendar_units():
    lo, hi = _days(2025, 12, 30), _days(2026, 2, 11)  # 40 logs from 2026-01-01, 5 % margins
    ticks, labels = date_ticks(lo, hi, 400.0, 12.0)
    assert labels == ["2026-01-01", "2026-01-15", "2026-02-01"]  # half months
    np.testing.assert_allclose(ticks, [_days(2026, 1, 1), _days(2026, 1, 15), _days(2026, 2, 1)])
    _, labels = date_ticks(lo, hi, 150.0, 12.0)  # a narrow panel: months
    assert labels == ["2026-01", "2026-02"]
    _, labels = date_ticks(_days(2026, 3, 1, 8), _days(2026, 3, 1, 14), 500.0, 12.0)  # hours, the day once
    assert labels[0] == "08:00\n2026-03-01"
    assert labels[1:3] == ["09:00", "10:00"]
    _, labels = date_ticks(_days(2026, 3, 1, 22), _days(2026, 3, 2, 2), 300.0, 12.0)  # the day, where it changes
    assert labels == ["22:00\n2026-03-01", "23:00", "00:00\n2026-03-02", "01:00", "02:00"]
    _, labels = date_ticks(_days(1990, 1, 1), _days(2030, 1, 1), 300.0, 12.0)
    assert labels == ["1990", "2000", "2010", "2020", "2030"]


def test_date_ticks_shorten_days_in_a_narrow_panel():
    """Whole dates would leave one tick in 150 px: month-day, the year under the first tick and where it changes."""
    _, labels = date_ticks(_days(2, 12, 25, 22), _days(2, 12, 28, 2), 150.0, 9.5)
    assert labels == ["12-26\n0002", "12-27", "12-28"]
    _, labels = date_ticks(_days(2026, 12, 30), _days(2027, 1, 2), 90.0, 9.5)
    assert labels == ["12-30\n2026", "01-01\n2027"]


@pytest.mark.parametrize(
    ("lo", "hi", "expected"),
    [
        (_days(1, 1, 1), _days(1, 1, 4), "0001-01-01"),  # year 1 written with four digits
        (_days(9999, 12, 1), DATE_RANGE[1] + 30.0, "12-01\n9999"),  # beyond the last date: no ticks (half the axis)
        (DATE_RANGE[0] - 5.0, DATE_RANGE[1] + 5.0, "2000"),  # the whole range: millennia
    ],
)
def test_date_ticks_at_the_ends_of_the_calendar(lo, hi, expected):
    ticks, labels = date_ticks(lo, hi, 300.0, 12.0)
    assert expected in labels
    assert len(ticks) >= 2
    assert np.all((ticks >= DATE_RANGE[0]) & (ticks <= DATE_RANGE[1]))


@pytest.mark.parametrize(
    ("length", "labels"),
    [
        (300.0, ["2000", "4000", "6000", "8000"]),
        (200.0, ["2000", "4000", "6000", "8000"]),
        (125.0, ["0001-01-01", "9999-12-31"]),  # 2000-year steps: four ticks where three fit; no fallback: none
        (70.0, ["0001-01-01", "9999-12-31"]),
        (40.0, ["0001", "9999"]),
        (20.0, []),  # not even two years fit
    ],
)
def test_date_ticks_over_the_whole_calendar(length, labels):
    ticks, got = date_ticks(DATE_RANGE[0], DATE_RANGE[1], length, 9.5)
    assert got == labels
    if labels and len(labels[0]) > 4:  # the first and last dates
        np.testing.assert_allclose(ticks, [DATE_RANGE[0], DATE_RANGE[1]], atol=1e-5)


def test_date_ticks_of_an_axis_reaching_beyond_the_calendar():
    """The margins of logs dated 0001-01-01 and 9999-12-31 reach beyond the calendar: the ticks stay within it, and
    the labels are spaced by the px of the whole axis."""
    margin = 0.05 * DATE_RANGE[1]
    ticks, labels = date_ticks(-margin, DATE_RANGE[1] + margin, 138.0, 9.5)
    assert labels == ["0001-01-01", "9999-12-31"]
    ticks, labels = date_ticks(-margin, DATE_RANGE[1] + margin, 180.0, 9.5)
    assert labels == ["2500", "5000", "7500"]  # 2000 years: 33 px apart, where a label takes 36
    assert np.all((ticks >= 0) & (ticks <= DATE_RANGE[1]))
    assert date_ticks(-100.0, -10.0, 300.0, 12.0)[1] == []  # before year 1: no ticks


def test_date_numbers_round_trip():
    for when in (dt.datetime(1, 1, 1), dt.datetime(2026, 12, 6, 13, 45, 7), dt.datetime(9999, 12, 31, 23, 59, 59)):
        assert number_date(date_number(when)) == when
    aware = dt.datetime(2026, 12, 6, 12, tzinfo=dt.timezone(dt.timedelta(hours=2)))
    assert number_date(date_number(aware)) == dt.datetime(2026, 12, 6, 10)  # aware: as UTC
    assert number_date(-100.0) == dt.datetime(1, 1, 1)


def test_text_width_and_superscript():
    assert superscript(-6) == "⁻⁶"
    assert superscript(12) == "¹²"
    assert text_width("0000", 10.0) == pytest.approx(4 * 6.36)
    assert text_width("wide\nw", 10.0) == text_width("wide", 10.0)  # the longest line
    assert text_width("WWW", 12.0) > text_width("iii", 12.0)
