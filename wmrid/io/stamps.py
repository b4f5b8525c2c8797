"""Time stamps to float64 seconds, exactly where float64 allows (:func:`seconds_from_stamps`).

``time_unit="auto"`` reads a floating-point column as seconds and an INTEGER column as integer nanoseconds (the ROS
convention), with a note; a floating-point column reaching 1e16 (1e13) is read as nanoseconds (microseconds) since the
epoch, since as seconds it would span 300,000 years, with a note.  Stamps keep their absolute value (as in the file)
while float64 resolves them to 1 ns or better, i.e. while the largest |t| < 2**23 s (about 97 days; float64 spacing
there is 2**-30 s < 1 ns).  Converted stamps beyond that (epoch stamps such as 1.7e18 ns) are stored relative to the
first stamp -- subtracted in exact integer arithmetic for integer columns, before any rounding.  A float column
already in seconds is kept exactly as in the file whatever its size: converting it loses nothing.
"""

from __future__ import annotations

import numpy as np

from wmrid.core.choices import TimeUnit, values

TIME_UNITS = values(TimeUnit)


NS_PER_UNIT = {"s": 1_000_000_000, "ms": 1_000_000, "us": 1_000, "ns": 1}


PER_SECOND = {"s": 1.0, "ms": 1e3, "us": 1e6, "ns": 1e9}


ABSOLUTE_LIMIT_S = float(2**23)  # float64 spacing below this is <= 2**-30 s < 1 ns


EPOCH_LIKE_S = 1e9  # stamps beyond this (2001 in s since the epoch; any ms/us/ns epoch time) are clock times


def seconds_from_stamps(stamps: np.ndarray, unit: str) -> tuple[np.ndarray, int | float | None]:
    """(t float64 s, offset) from stamps in ``unit`` ("s", "ms", "us", "ns"); offset is the stamp subtracted.

    Integer stamps are converted exactly relative to their first value when the absolute seconds would
    reach 2**23 s (float64 spacing > 1 ns), else absolutely; the division by 10**k is correctly rounded
    because the integer fits in 53 bits.  Float stamps in seconds are returned unchanged; other float
    stamps follow the same relative rule (the subtraction of nearby floats is exact).
    """
    if stamps.dtype.kind in "iu":
        ints = stamps.astype(np.int64) if stamps.dtype.kind == "u" else stamps
        per_s = NS_PER_UNIT["s"] // NS_PER_UNIT[unit]  # stamps per second
        largest = max(abs(int(ints[0])), abs(int(ints[-1])))
        if largest >= ABSOLUTE_LIMIT_S * per_s:
            offset = int(ints[0])
            return (ints - ints[0]).astype(np.float64) / float(per_s), offset
        return ints.astype(np.float64) / float(per_s), None
    floats = stamps.astype(np.float64, copy=False)
    if unit == "s":
        return floats, None
    per_s = PER_SECOND[unit]
    if max(abs(floats[0]), abs(floats[-1])) >= ABSOLUTE_LIMIT_S * per_s:
        return (floats - floats[0]) / per_s, float(floats[0])
    return floats / per_s, None


#: s: integer stamps read as nanoseconds whose samples are closer than this (a wheel log above 100 kHz) are refused:
#: they count a coarser unit (epoch milliseconds read as ns gave 1 ns steps and m11 = 0).
MIN_PLAUSIBLE_STEP_S = 1e-5


def implausible_step(name: str, tcol: str, step_s: float, first: float) -> str:
    """The message for integer stamps whose median step, read as ns, is ``step_s`` (``first``: the first stamp, as
    stored): the unit under which the first stamp is a date of this century (epoch time), else every unit that
    puts the step between 0.1 ms and 1 s (10 Hz to 10 kHz)."""
    count = step_s * 1e9
    scales = {"ms": 1e-3, "us": 1e-6, "s": 1.0}
    epoch = [u for u in scales if 9.46e8 <= first * scales[u] <= 4.1e9]  # the first stamp a date, 2000 to 2100
    plausible = [u for u, scale in scales.items() if 1e-4 <= count * scale <= 1.0]
    units = epoch or plausible
    if units:
        fix = " or ".join(f"--time-unit {u} ({1.0 / (count * scales[u]):.3g} Hz)" for u in units)
        fix = f"give {fix}" + (", which makes the first stamp a date since the Unix epoch" if epoch else "")
    else:
        fix = "give --time-unit s, ms or us for the unit it counts"
    return (
        f"{name}: time column {tcol!r} holds integers whose samples are {count:.4g} apart: as nanoseconds (the default "
        f"for integers) that is a {1.0 / max(step_s, 1e-300):.3g} Hz wheel log, which no robot logs; {fix}"
    )


def seconds(stamps: np.ndarray, unit: str, offset: int | float | None) -> np.ndarray:
    """Stamps in ``unit`` as float64 seconds, less ``offset`` (a stamp) when given; see :func:`seconds_from_stamps`."""
    if stamps.dtype.kind in "iu":
        per_s = NS_PER_UNIT["s"] // NS_PER_UNIT[unit]
        if offset is not None:
            return (stamps - int(offset)).astype(np.float64) / float(per_s)
        return stamps.astype(np.float64) / float(per_s)
    floats = stamps.astype(np.float64, copy=False)
    if unit == "s":
        return floats
    if offset is not None:
        return (floats - float(offset)) / PER_SECOND[unit]
    return floats / PER_SECOND[unit]
