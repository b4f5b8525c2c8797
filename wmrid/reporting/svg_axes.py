"""Axes of the SVG figures (:mod:`wmrid.reporting.svg`): where the ticks go and what they say.

Linear axes get "nice" ticks (steps of 1, 2 or 5 times a power of ten, as many as fit without their labels
touching), log axes ticks at decades labelled ``10⁻⁶`` (every second or third decade when they are dense; 1-2-5
within a decade when the axis spans less than two), date axes ticks on calendar units (years, months, half months,
weeks, days, hours, minutes, seconds) labelled ``2026-12-06``.  Dates are numbers here: days since 0001-01-01 00:00
(:func:`date_number`), so every date Python can hold, years 1 to 9999, has its place on the axis.

Text widths are estimated from DejaVu Sans' advance widths (the widest of the common sans-serif faces), so labels
placed apart by these estimates stay apart in any browser.
"""

from __future__ import annotations

import datetime as dt
import math
import sys

import numpy as np

#: Advance widths, in em, of DejaVu Sans (the widest common sans-serif face); other characters count as 0.65 em.
_WIDTHS = {
    **dict.fromkeys("0123456789", 0.636), " ": 0.318, ".": 0.318, ",": 0.318, ":": 0.337, ";": 0.337,
    "-": 0.361, "−": 0.838, "+": 0.838, "=": 0.838, "±": 0.838, "×": 0.838, "(": 0.39, ")": 0.39, "/": 0.337,
    "%": 0.95, "'": 0.275, "_": 0.5, "^": 0.838, "|": 0.337, "[": 0.39, "]": 0.39, "—": 1.0, "–": 0.5,
    "a": 0.613, "b": 0.635, "c": 0.55, "d": 0.635, "e": 0.615, "f": 0.352, "g": 0.635, "h": 0.634, "i": 0.278,
    "j": 0.278, "k": 0.579, "l": 0.278, "m": 0.974, "n": 0.634, "o": 0.612, "p": 0.635, "q": 0.635, "r": 0.411,
    "s": 0.521, "t": 0.392, "u": 0.634, "v": 0.592, "w": 0.818, "x": 0.592, "y": 0.592, "z": 0.525,
    "A": 0.684, "B": 0.686, "C": 0.698, "D": 0.77, "E": 0.632, "F": 0.575, "G": 0.775, "H": 0.752, "I": 0.295,
    "J": 0.295, "K": 0.656, "L": 0.557, "M": 0.863, "N": 0.748, "O": 0.787, "P": 0.603, "Q": 0.787, "R": 0.695,
    "S": 0.635, "T": 0.611, "U": 0.732, "V": 0.684, "W": 0.989, "X": 0.685, "Y": 0.611, "Z": 0.685,
    **dict.fromkeys("⁰¹²³⁴⁵⁶⁷⁸⁹⁻₀₁₂₃₄₅₆₇₈₉", 0.4),
}  # fmt: skip
_SUPERSCRIPT = str.maketrans("-0123456789", "⁻⁰¹²³⁴⁵⁶⁷⁸⁹")
#: Days from 0001-01-01 to 1970-01-01 (the date numbers' origin is the first day Python's dates can hold).
_EPOCH = dt.date(1970, 1, 1).toordinal() - 1
#: The date numbers an axis may show: 0001-01-01 00:00 to 9999-12-31 24:00.
DATE_RANGE = (0.0, float(dt.date(9999, 12, 31).toordinal()))
#: The largest finite float: limits stay within ±this, and spans are taken as ``hi / 2 - lo / 2`` (always finite).
FLOAT_MAX = sys.float_info.max
#: The smallest positive float (a subnormal): a log axis' limits stay within [this, :data:`FLOAT_MAX`].
FLOAT_TINY = math.ulp(0.0)


def pow10(k: float) -> float:
    """10^k as a float: inf beyond :data:`FLOAT_MAX` and 0 below the smallest subnormal (no OverflowError)."""
    try:
        return float(10.0**k)
    except OverflowError:
        return math.inf


def degenerate(lo: float, hi: float) -> bool:
    """Limits (lo <= hi) so close that no tick step separates them: within 1e-12 of their magnitude."""
    return hi / 2 - lo / 2 <= 0.5e-12 * max(abs(lo), abs(hi), 1e-300)


def text_width(text: str, size: float) -> float:
    """Estimated width (px) of ``text`` at font size ``size`` (px); of its longest line when it has several."""
    return max(sum(_WIDTHS.get(c, 0.65) for c in line) for line in text.split("\n")) * size


def superscript(n: int) -> str:
    """``n`` in superscript digits: ``-6`` -> ``⁻⁶``."""
    return str(n).translate(_SUPERSCRIPT)


def _minus(text: str) -> str:
    """A number's text with a true minus sign (U+2212), and no negative zero."""
    text = text.replace("-", "−")
    return text[1:] if text.startswith("−") and not text.strip("−0.") else text


# --------------------------------------------------------------------------------------------------
# Linear axes


def linear_ticks(lo: float, hi: float, max_ticks: int, min_step: float = 0.0) -> tuple[np.ndarray, float]:
    """Ticks within [lo, hi] at the smallest step 1, 2 or 5 x 10^k that gives at most ``max_ticks`` of them.

    Parameters
    ----------
    lo, hi
        The axis limits (any order, any finite floats; limits closer than :func:`degenerate` are widened by one
        unit of their magnitude).
    max_ticks
        The most ticks wanted (at least 2).
    min_step
        The finest step allowed (1: integers only, a count's axis).

    Returns
    -------
    ticks : (n,) float
        Multiples of the step within the limits, increasing; at least two, even when that takes more than
        ``max_ticks`` (a span of 1.2 from 0.9 with at most 2: 1.0, 1.5, 2.0), unless ``min_step`` leaves fewer (one
        integer between -0.5 and 0.5; none within the limits: none).
    step : float
        Their spacing.
    """
    lo, hi = min(lo, hi), max(lo, hi)
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return np.array([]), 1.0
    if degenerate(lo, hi):
        half = max(abs(lo), 1.0) * 0.5
        lo, hi = max(lo - half, -FLOAT_MAX), min(hi + half, FLOAT_MAX)
    half_span = hi / 2 - lo / 2  # finite even from -FLOAT_MAX to FLOAT_MAX
    max_ticks = max(2, int(max_ticks))
    exponent = math.floor(math.log10(half_span / max_ticks) + math.log10(2.0))
    steps = (m * pow10(k) for k in range(exponent - 1, exponent + 3) for m in (1.0, 2.0, 5.0))
    candidates = [c for c in steps if 0.0 < c < math.inf and c >= min_step] or [min_step]
    best = candidates[0]
    for step in candidates:  # finest first: the first that fits, or the coarsest that still gives two ticks
        n = math.floor(hi / step + 1e-9) - math.ceil(lo / step - 1e-9) + 1
        if n >= 2:
            best = step
        if n <= max_ticks:
            break
    first, last = math.ceil(lo / best - 1e-9), math.floor(hi / best + 1e-9)
    ticks = np.arange(first, last + 1) * best
    return np.where(np.abs(ticks) < 1e-9 * best, 0.0, ticks), best


def linear_labels(ticks: np.ndarray, step: float) -> tuple[list[str], str]:
    """Compact labels of linear ticks, and the note that completes them ("" or e.g. "×10⁻⁶", "×10⁻⁷ + 1.41").

    Values from 0.001 to 10^6 are written plainly with the decimals the step needs (0, 2.5, 5 -> "0.0", "2.5",
    "5.0"); beyond, the labels are scaled and the note gives the power of ten.  Ticks that differ only after the
    fifth significant digit are written relative to an offset the note adds back.
    """
    if len(ticks) == 0:
        return [], ""
    top = float(np.max(np.abs(ticks)))
    offset = 0.0
    if top / step >= 1e5:  # 1.4100000, 1.4100002, ...: relative to 1.41
        unit = pow10(math.ceil(math.log10(step * max(len(ticks) - 1, 1)) - 1e-9))
        offset = float(f"{math.floor(float(ticks[0]) / unit + 1e-6) * unit:.12g}")
    rel = np.where(np.abs(ticks - offset) < 1e-6 * step, 0.0, ticks - offset)
    top = float(np.max(np.abs(rel)))
    exponent = math.floor(math.log10(top)) if top > 0 else 0
    power = exponent if (exponent >= 6 or exponent <= -4) else 0
    scale = pow10(power)
    decimals = max(0, -math.floor(math.log10(step / scale) + 1e-9))
    labels = [_minus(f"{v / scale:.{decimals}f}") for v in rel]
    note = f"×10{superscript(power)}" if power else ""
    if offset:
        note += f" {'−' if offset < 0 else '+'} {abs(offset):.12g}"
    return labels, _minus(note.strip())


# --------------------------------------------------------------------------------------------------
# Log axes


def log_ticks(lo: float, hi: float, max_ticks: int) -> tuple[np.ndarray, list[str], np.ndarray]:
    """Major ticks (labelled), their labels and minor ticks of a log10 axis from ``lo`` to ``hi`` (> 0).

    Parameters
    ----------
    lo, hi
        The axis limits, positive.
    max_ticks
        The most labelled ticks wanted.

    Returns
    -------
    major : (n,) float
        Decades 10^k within the limits (every second, third, ... decade when more would not fit); when fewer than
        two decades fall within the limits, 1, 2 and 5 times the decades.
    labels : list of str
        ``10⁻⁶`` for decades; a 1-2-5 tick plainly (0.002, 50) between 0.001 and 10^5, else ``2×10⁻⁶``.
    minor : (m,) float
        2..9 x 10^k within the limits when the decades are labelled one by one, else none.
    """
    lo, hi = min(lo, hi), max(lo, hi)
    if not (lo > 0 and math.isfinite(lo) and math.isfinite(hi)):
        return np.array([]), [], np.array([])
    k0, k1 = math.ceil(math.log10(lo) - 1e-9), math.floor(math.log10(hi) + 1e-9)
    max_ticks = max(2, int(max_ticks))
    if k1 - k0 + 1 >= 2:
        every = max(1, math.ceil((k1 - k0 + 1) / max_ticks))
        ks = [k for k in range(k0, k1 + 1) if k % every == 0]
        major = np.array([pow10(k) for k in ks])
        labels = [f"10{superscript(k)}" for k in ks]
        minor = np.array([]) if every > 1 else _log_minor(lo, hi)
        return major, labels, minor
    values = [m * pow10(k) for k in range(k0 - 1, k1 + 2) for m in (1.0, 2.0, 5.0)]
    major = np.array([v for v in values if lo * (1 - 1e-9) <= v <= hi * (1 + 1e-9) and v < math.inf])
    if len(major) < 2:  # less than a factor of 2.5: linear ticks on the log axis
        ticks, step = linear_ticks(lo, hi, max_ticks)
        ticks = ticks[(ticks > 0) & (ticks >= lo * (1 - 1e-9)) & (ticks <= hi * (1 + 1e-9))]
        if len(ticks) or not len(major):  # (none among the few subnormals near 1e-323: the 1-2-5 tick)
            labels, note = linear_labels(ticks, step)
            if note:  # no room for a note on a log axis: each value in full, 1.15×10⁸
                labels = [_scientific(v, step) for v in ticks]
            return ticks, labels, np.array([])
    return major, [_log_value(v) for v in major], _log_minor(lo, hi, one=False)


def _log_value(v: float) -> str:
    """A 1-2-5 value on a log axis: plainly between 0.001 and 10^5, else as m×10ⁿ."""
    if 1e-3 <= v < 1e5:
        return f"{v:.10g}"
    k = math.floor(math.log10(v) + 1e-9)
    m = round(pow10(math.log10(v) - k))  # (not v / 10^k: 10^-324 is 0)
    if m == 10:  # 1e-323, a subnormal, is 9.88e-324
        m, k = 1, k + 1
    return (f"{m}×" if m != 1 else "") + f"10{superscript(k)}"


def _scientific(v: float, step: float) -> str:
    """A positive value with the decimals that ``step`` needs, plainly between 0.001 and 10^5 (1.4100002), else as
    m×10ⁿ (1.15×10⁸ in steps of 5×10⁶)."""
    if 1e-3 <= v < 1e5:
        return f"{v:.{max(0, -math.floor(math.log10(step) + 1e-9))}f}"
    k = math.floor(math.log10(v) + 1e-12)
    decimals = max(0, -math.floor(math.log10(step) - k + 1e-9))
    return f"{pow10(math.log10(v) - k):.{decimals}f}×10{superscript(k)}"


def _log_minor(lo: float, hi: float, one: bool = True) -> np.ndarray:
    """Minor ticks m x 10^k within [lo, hi]; ``one``: the majors are the decades only (else 1, 2 and 5 too)."""
    k0, k1 = math.floor(math.log10(lo)), math.ceil(math.log10(hi))
    if k1 - k0 > 12:
        return np.array([])
    values = np.array([m * pow10(k) for k in range(k0, k1 + 1) for m in (3, 4, 6, 7, 8, 9, *((2, 5) if one else ()))])
    return np.sort(values[(values >= lo) & (values <= hi)])


# --------------------------------------------------------------------------------------------------
# Date axes


def date_number(when: dt.datetime) -> float:
    """``when`` (naive: UTC; aware: converted to UTC) as days since 0001-01-01 00:00 (float)."""
    if when.tzinfo is not None:
        when = when.astimezone(dt.timezone.utc).replace(tzinfo=None)
    seconds = when.hour * 3600 + when.minute * 60 + when.second + when.microsecond / 1e6
    return float(when.toordinal() - 1) + seconds / 86400.0


def number_date(x: float) -> dt.datetime:
    """The date of a date number (:func:`date_number`), clipped to the dates Python holds."""
    x = min(max(float(x), DATE_RANGE[0]), DATE_RANGE[1] - 1e-6)
    day = math.floor(x)
    seconds = round((x - day) * 86400.0)
    return dt.datetime.fromordinal(day + 1) + dt.timedelta(seconds=min(seconds, 86399))


#: Calendar steps, finest first: (unit, count, approximate length in days).
_DATE_STEPS = (
    *[("second", n, n / 86400) for n in (1, 2, 5, 10, 15, 30)],
    *[("minute", n, n / 1440) for n in (1, 2, 5, 10, 15, 30)],
    *[("hour", n, n / 24) for n in (1, 2, 3, 6, 12)],
    ("day", 1, 1.0), ("day", 2, 2.0), ("week", 1, 7.0), ("halfmonth", 1, 15.0),
    *[("month", n, 30.4 * n) for n in (1, 2, 3, 4, 6)],
    *[("year", n, 365.25 * n) for n in (1, 2, 5, 10, 20, 50, 100, 200, 500, 1000, 2000, 2500, 5000)],
)  # fmt: skip


def _calendar_ticks(unit: str, n: int, lo: dt.datetime, hi: dt.datetime) -> list[dt.datetime]:
    """Dates from ``lo`` to ``hi`` on the calendar step (unit, n)."""
    if unit in ("year", "month", "halfmonth", "week"):
        out = []
        for year in range(lo.year, hi.year + 1):
            if unit == "year":
                if year % n == 0:
                    out.append(dt.datetime(year, 1, 1))
                continue
            months = range(1, 13, n) if unit == "month" else range(1, 13)
            days = (1,) if unit == "month" else (1, 15) if unit == "halfmonth" else (1, 8, 15, 22)
            out += [dt.datetime(year, m, d) for m in months for d in days]
        return [d for d in out if lo <= d <= hi]
    seconds = {"second": 1, "minute": 60, "hour": 3600, "day": 86400}[unit] * n
    origin = dt.datetime(lo.year, lo.month, lo.day)
    first = math.ceil((lo - origin).total_seconds() / seconds)
    last = math.floor((hi - origin).total_seconds() / seconds)
    return [origin + dt.timedelta(seconds=k * seconds) for k in range(first, last + 1)]


def _day(when: dt.datetime) -> str:
    return f"{when.year:04d}-{when.month:02d}-{when.day:02d}"


def _date_label(when: dt.datetime, unit: str, short: bool = False) -> str:
    if unit == "year":
        return f"{when.year:04d}"
    if unit == "month":
        return _day(when)[:7]
    if unit in ("halfmonth", "week", "day"):
        return _day(when)[5:] if short else _day(when)
    clock = f"{when.hour:02d}:{when.minute:02d}" + (f":{when.second:02d}" if unit == "second" else "")
    return clock


def date_ticks(lo: float, hi: float, length: float, size: float) -> tuple[np.ndarray, list[str]]:
    """Ticks of a date axis: the finest calendar step whose labels fit ``length`` px at font size ``size`` px.

    Parameters
    ----------
    lo, hi
        The axis limits, date numbers (:func:`date_number`); the ticks are within years 1 to 9999 (the axis may
        reach beyond: its margins).
    length, size
        The axis' length and the labels' font size, px.

    Returns
    -------
    ticks : (n,) float
        Date numbers of the ticks: on a calendar step, two or more when the axis spans a second or more; where no
        step fits two, the first and last dates of the axis (within the calendar), when their labels fit; else one
        tick, when only the coarsest step fits; else none.
    labels : list of str
        ``2026``, ``2026-12`` or ``2026-12-06`` by the step.  Where whole dates would leave fewer than two ticks,
        ``12-06`` with the year on a second line under the first tick and wherever the year changes; within a day,
        ``14:30`` (or ``14:30:05``) with the date on a second line under the first tick and wherever the day changes.
        The first and last dates as days, months or years, the finest whose two labels fit.
    """
    lo, hi = min(lo, hi), max(lo, hi)
    px_per_day = length / max(hi - lo, 1.0 / 86400)
    lo, hi = max(lo, DATE_RANGE[0]), min(hi, DATE_RANGE[1] - 1e-6)
    if hi < lo:  # the axis lies beyond the calendar
        return np.array([]), []
    span = max(hi - lo, 1.0 / 86400)
    length = span * px_per_day  # the calendar's part of the axis
    start, end = number_date(lo), number_date(hi)
    found = _date_step(start, end, span, length, size, short=False)
    if found is None or len(found[2]) < 2:
        found = _date_step(start, end, span, length, size, short=True) or found
    if found is None or len(found[2]) < 2:
        ends = _end_labels(start, end, (hi - lo) * px_per_day, size)
        if ends is not None:
            return np.array([lo, hi]), ends
    if found is None:
        return np.array([]), []
    unit, short, dates = found
    short = short and unit in ("halfmonth", "week", "day")
    labels = [_date_label(d, unit, short) for d in dates]
    for i, d in enumerate(dates):
        if unit in ("second", "minute", "hour") and (i == 0 or d.date() != dates[i - 1].date()):
            labels[i] += "\n" + _day(d)
        if short and (i == 0 or d.year != dates[i - 1].year):
            labels[i] += f"\n{d.year:04d}"
    return np.array([date_number(d) for d in dates]), labels


def _end_labels(start: dt.datetime, end: dt.datetime, gap: float, size: float) -> list[str] | None:
    """The labels of the first and last dates of an axis, ``gap`` px apart: as days, months or years, the finest that
    tells them apart and fits; None when none does."""
    for unit in ("day", "month", "year"):
        first, last = _date_label(start, unit), _date_label(end, unit)
        if first != last and gap >= max(text_width(first, size), text_width(last, size)) + 1.2 * size:
            return [first, last]
    return None


_SAMPLES = {"year": "0000", "month": "0000-00", "second": "00:00:00", "minute": "00:00", "hour": "00:00"}


def _date_step(
    start: dt.datetime, end: dt.datetime, span: float, length: float, size: float, *, short: bool
) -> tuple[str, bool, list[dt.datetime]] | None:
    """(unit, ``short``, dates) of the finest calendar step whose labels (``short``: days as ``12-06``) fit
    ``length`` px with two ticks or more; else the finest that fits with one; None when nothing fits."""
    fallback: tuple[str, bool, list[dt.datetime]] | None = None
    for unit, n, days in _DATE_STEPS:
        if span / days > 60:  # far too many: not even listed
            continue
        sample = _SAMPLES.get(unit, "00-00" if short else "0000-00-00")
        room = text_width(sample, size) + 1.2 * size
        dates = _calendar_ticks(unit, n, start, end)
        gaps = np.diff([date_number(d) for d in dates]) * length / span if len(dates) > 1 else np.array([length])
        if unit in ("second", "minute", "hour"):  # the date under the ticks where the day changes: once a day
            room = max(room, (text_width("0000-00-00", size) + 1.2 * size) * days)
        if len(dates) <= max(2, int(length // room)) and gaps.min() >= room:
            if len(dates) >= 2:
                return unit, short, dates
            if dates and fallback is None:
                fallback = (unit, short, dates)
    return fallback
