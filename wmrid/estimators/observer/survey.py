"""One pass over a log: what identification must know before the replay, in bounded memory.

The replay needs, before its first sample, the regressor form (does each wheel keep one sign over the
whole log?), the number of samples (for the history and block layout), a start value for an unknown
robot, and the assurance that the log has no holes or impossible values.  :func:`survey` reads a
:class:`wmrid.core.wheel_log.LogStream` once, piece by piece, and keeps only running figures and a sparse sample.
"""

from __future__ import annotations

import math
from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from wmrid.core.errors import NotIdentifiableError
from wmrid.core.jit import kernel
from wmrid.estimators.sign_speed import mean_keeps_sign, sign_half_window
from wmrid.model.dynamics import RegressorForm
from wmrid.model.kernels import plain

#: Speeds (rad/s) or efforts beyond this magnitude are not what a robot logs (a unit or column error).
PLAUSIBLE_LIMIT = 1e12
#: Spacing (s) of the sparse sample kept for the data-driven start (differences over it give accelerations).
START_SPACING_S = 0.05
#: The sparse sample holds at most this many samples (2.6 MB; 54 min of log at START_SPACING_S): beyond, its spacing
#: doubles as often as needed (the first sample of each interval twice as long), so a survey's memory does not grow
#: with the log's length (an 8 h log held 23 MB per survey, and identify keeps three).
SPARSE_MOST = 65_536
#: The median step is exact while the log has at most this many distinct step values (a regular log has a
#: handful); beyond, it comes from a histogram of relative bucket width 2**-12 (0.024 %).
EXACT_STEPS = 4096
_BUCKETS_PER_OCTAVE = 4096
#: A wheel slower than this fraction of its 90th-percentile speed counts as slow.
LOW_SPEED_FRACTION = 0.1


#: A wheel whose effort never changes sign is called swapped with its speed (rather than a magnitude) when the
#: exchanged columns fit the one-wheel model to at least this R², and by this much more than as read.
SWAPPED_R2 = 0.8
SWAPPED_GAIN = 0.3


@dataclass
class Survey:
    """Figures of a whole log, gathered piece by piece.

    n : samples.  t_first, t_last : s.  median_step : s, the median time step (exact while the log has at
    most EXACT_STEPS distinct steps, else to 0.024 %; never dependent on how the log was cut into pieces).
    min_step, max_step : s; max_step_after : s, the time before the largest step.
    positive, negative (properties) : (2,) bool, whether every speed of the wheel is > 0 (< 0).
    sparse_t (m,) s, sparse_eta (m, 2) rad/s, sparse_tau (m, 2): the first sample of each START_SPACING_S
    interval of time from t_first (of each 2^k times that interval for the least k that keeps m <= SPARSE_MOST:
    ``sparse_spacing`` s).
    Per wheel (2,): speed_pos, speed_neg, effort_pos, effort_neg counts of samples > 0 and < 0; power,
    abs_power, opposing, driving: sums of tau eta, |tau eta| and the counts of tau eta < 0 and > 0
    (:meth:`signal_warnings`); speed_max, effort_max: the largest |eta| (rad/s) and |tau|; effort_fractional: the
    count of efforts that are not whole numbers (PWM counts are: :meth:`scales`).
    """

    source: str
    effort_unit: str = "N m"
    n: int = 0
    t_first: float = 0.0
    t_last: float = 0.0
    median_step: float = 0.0
    min_step: float = np.inf
    max_step: float = 0.0
    max_step_after: float = 0.0
    sparse_t: np.ndarray = field(default_factory=lambda: np.empty(0))
    sparse_eta: np.ndarray = field(default_factory=lambda: np.empty((0, 2)))
    sparse_tau: np.ndarray = field(default_factory=lambda: np.empty((0, 2)))
    sparse_spacing: float = START_SPACING_S
    speed_pos: np.ndarray = field(default_factory=lambda: np.zeros(2))
    speed_neg: np.ndarray = field(default_factory=lambda: np.zeros(2))
    #: (2,) bool: every centred mean speed of the wheel (:mod:`wmrid.estimators.sign_speed`, the speed the sign columns
    #: take) is > 0; is < 0.  Found only when the measured speed of some wheel does not keep one strict sign.
    #: Speeds derived from a coarse encoder dip across zero where the true speed is slow but never reverses (512
    #: counts/rev at 1 kHz: to -0.49 rad/s where the true speed is 0.7): the mean keeps its sign, so the sign columns
    #: of the general form are two constants, the same column twice, and the log's direction is the paper form's.
    sign_pos: np.ndarray = field(default_factory=lambda: np.zeros(2, dtype=bool))
    sign_neg: np.ndarray = field(default_factory=lambda: np.zeros(2, dtype=bool))
    effort_neg: np.ndarray = field(default_factory=lambda: np.zeros(2))
    effort_pos: np.ndarray = field(default_factory=lambda: np.zeros(2))
    power: np.ndarray = field(default_factory=lambda: np.zeros(2))
    abs_power: np.ndarray = field(default_factory=lambda: np.zeros(2))
    opposing: np.ndarray = field(default_factory=lambda: np.zeros(2))
    driving: np.ndarray = field(default_factory=lambda: np.zeros(2))
    speed_max: np.ndarray = field(default_factory=lambda: np.zeros(2))
    effort_max: np.ndarray = field(default_factory=lambda: np.zeros(2))
    effort_fractional: np.ndarray = field(default_factory=lambda: np.zeros(2))
    #: wheel -> :meth:`_swapped`'s answer, made once (the units check and the signal warnings both ask)
    _swap_memo: dict[int, tuple[float, float] | None] = field(default_factory=dict, repr=False, compare=False)

    @property
    def duration(self) -> float:
        return self.t_last - self.t_first

    @property
    def positive(self) -> np.ndarray:
        """(2,) bool: every speed of the wheel is > 0."""
        return self.speed_pos == self.n

    @property
    def negative(self) -> np.ndarray:
        """(2,) bool: every speed of the wheel is < 0."""
        return self.speed_neg == self.n

    def form(self) -> RegressorForm:
        """The paper's form when each wheel keeps one strict sign (as :func:`wmrid.model.dynamics.choose_form`): the
        measured speed's, or that of the short centred mean the sign columns take (:attr:`sign_pos`)."""
        positive = self.positive | self.sign_pos
        negative = self.negative | self.sign_neg
        if self.n and all(positive | negative):
            return RegressorForm("paper", tuple(1 if p else -1 for p in positive))  # type: ignore[arg-type]
        return RegressorForm("general")

    def low_speed(self) -> np.ndarray:
        """(2,) rad/s: per wheel, LOW_SPEED_FRACTION of the 90th percentile of |eta| over the sparse sample;
        below it a wheel counts as slow (the friction check of :func:`wmrid.estimators.model_error.slow_speed_term`)."""
        if len(self.sparse_eta) == 0:
            return np.zeros(2)
        return LOW_SPEED_FRACTION * np.percentile(np.abs(self.sparse_eta), 90, axis=0)

    def data_start(self, form: RegressorForm) -> np.ndarray:
        """A start for an unknown robot, (2, p): m11 = m22 = a robust acceleration-per-torque ratio, all else 0.

        The ratio (95th percentile of |eta_dot| over that of |tau|, eta_dot by differences over about
        START_SPACING_S, both over the sparse sample) only sets the order of magnitude; with the default
        small alpha the start is forgotten within the first seconds of an exciting log.
        """
        theta = np.zeros((2, form.n_columns))
        if len(self.sparse_t) > 1:
            acc = np.abs(np.diff(self.sparse_eta, axis=0) / np.diff(self.sparse_t)[:, None])
            for i in range(2):
                a95 = float(np.percentile(acc[:, i], 95))
                t95 = float(np.percentile(np.abs(self.sparse_tau[:, i]), 95))
                if a95 > 0 and t95 > 0:
                    theta[i, i] = a95 / t95
        return theta

    def scales(self) -> dict[str, Any]:
        """The signals' magnitudes, for the units check (:mod:`wmrid.estimators.plausibility`): {"speed_max" (2,)
        rad/s, "effort_max" (2,), "effort_whole": every effort a whole number, "rate_hz", "duration_s",
        "effort_unit"}."""
        return {
            "speed_max": [float(v) for v in self.speed_max],
            "effort_max": [float(v) for v in self.effort_max],
            "effort_whole": bool(self.n > 0 and not np.any(self.effort_fractional)),
            "rate_hz": float(1.0 / self.median_step) if self.median_step > 0 else None,
            "duration_s": float(self.duration),
            "effort_unit": self.effort_unit,
            "swapped": [self._swapped(i) is not None for i in range(2)],
        }

    def _one_signed(self, i: int) -> float | None:
        """The share of wheel ``i``'s samples turning the other way when its effort never changes sign while its
        speed does (more than 5 % of them), else None."""
        other_way = min(self.speed_neg[i], self.speed_pos[i]) / max(self.n, 1)
        if other_way > 0.05 and (self.effort_neg[i] == 0 or self.effort_pos[i] == 0):
            return float(other_way)
        return None

    def _swapped(self, i: int) -> tuple[float, float] | None:
        """(R² as read, R² exchanged) when wheel ``i``'s effort never changes sign while its speed does and the two
        fit the model far better exchanged (SWAPPED_R2, SWAPPED_GAIN): speed and effort columns given the other way
        round; else None."""
        if i not in self._swap_memo:
            fits = self._orientation_fit(i) if self._one_signed(i) is not None else None
            swapped = fits is not None and fits[1] >= SWAPPED_R2 and fits[1] - fits[0] >= SWAPPED_GAIN
            self._swap_memo[i] = fits if swapped else None
        return self._swap_memo[i]

    def signal_warnings(self) -> list[str]:
        """Warnings about the signals themselves: an effort that never changes sign while the speed does (a
        magnitude, not a signed effort), and an effort that mostly opposes the speed (a sign convention)."""
        out = []
        opposing = [self._opposes(i) for i in range(2)]
        for i, wheel in enumerate(("right", "left")):
            other_way = self._one_signed(i)
            if other_way is not None:
                fits = self._swapped(i)
                if fits is not None:
                    out.append(
                        f"the {wheel} wheel's effort never changes sign while its speed does, and the two fit the "
                        f"model far better exchanged (R² {fits[1]:.2f} against {fits[0]:.2f} as read): the speed and "
                        "effort columns (or topics) look swapped; check --columns"
                    )
                    continue
                out.append(
                    f"the {wheel} wheel's effort never changes sign while its speed does "
                    f"({100 * other_way:.0f} % of samples the other way): the log holds a magnitude "
                    "(e.g. an unsigned current), not a signed effort, so the model does not apply; give it the sign "
                    "of the motor's drive"
                )
            if opposing[i] is None:
                continue
            share, power = opposing[i]
            if all(opposing):
                fix = "--flip-effort changes the sign of both wheels' efforts"
            else:
                fix = (
                    "only this wheel's: negate its effort in the log (--flip-effort flips both wheels, and "
                    "--mirror-left flips a wheel's speed with its effort, which leaves their product as it is)"
                )
            out.append(
                f"the {wheel} wheel's effort mostly opposes its speed ({100 * share:.0f} % of the samples with "
                f"power; mean power {power:.3g} {self.effort_unit} rad/s < 0): its sign is probably reversed "
                f"against the speed's; {fix}"
            )
        return out

    def _orientation_fit(self, i: int) -> tuple[float, float] | None:
        """(R² as read, R² exchanged) of wheel ``i``'s effort regressed on both wheels' speeds and their derivatives
        (the model's inertia and viscous terms, Eq. 20, plus a constant) on the sparse samples (one per
        START_SPACING_S), and of its speed on both efforts and their derivatives; None when too few samples.  An
        effort follows the speeds' derivatives; exchanged columns fit the other way round."""
        t = self.sparse_t
        if len(t) < 20 or np.any(np.diff(t) <= 0):
            return None

        def r2(x: np.ndarray, y: np.ndarray) -> float:
            a = np.column_stack([np.gradient(x, t, axis=0), x, np.ones(len(t))])
            coef, *_ = np.linalg.lstsq(a, y, rcond=None)
            spread = float(np.sum((y - y.mean()) ** 2))
            return 1.0 - float(np.sum((y - a @ coef) ** 2)) / spread if spread > 0 else 0.0

        with np.errstate(all="ignore"):
            return r2(self.sparse_eta, self.sparse_tau[:, i]), r2(self.sparse_tau, self.sparse_eta[:, i])

    def _opposes(self, i: int) -> tuple[float, float] | None:
        """(share of the samples with power where effort opposes speed, mean power) of wheel ``i`` when its effort
        mostly opposes its speed, else None.  Braking makes the power negative for a while; a reversed sign makes it
        negative almost always.  The share counts the samples with power (a wheel at rest, or no effort, says
        nothing about the sign)."""
        n = max(self.n, 1)
        power, scale = self.power[i] / n, self.abs_power[i] / n
        working = self.opposing[i] + self.driving[i]
        share = self.opposing[i] / working if working else 0.0
        if scale > 0 and power < -0.5 * scale and share > 0.75:
            return float(share), float(power)
        return None


def survey(pieces: Iterable, source: str, effort_unit: str = "N m") -> Survey:
    """One pass over ``pieces`` (objects with t (k,) s, eta (k, 2) rad/s, tau (k, 2)), in time order.

    Raises :class:`NotIdentifiableError` at the first sample that is not finite or beyond PLAUSIBLE_LIMIT.
    """
    sv = Survey(source=source, effort_unit=effort_unit)
    exact: dict[float, int] | None = {}
    hist: dict[int, int] = {}
    prev_t = None
    last_bucket = -1
    sparse = _Sparse()
    # per wheel: speeds > 0, < 0; efforts < 0, > 0; power, |power|, opposing, driving samples; max |eta|, max |tau|,
    # efforts that are not whole numbers
    acc = np.zeros(22)
    for piece in pieces:
        t, eta, tau = piece.t, piece.eta, piece.tau
        k = len(t)
        if k == 0:
            continue
        if _piece_stats(plain(eta), plain(tau), PLAUSIBLE_LIMIT, acc) >= 0:
            _raise_implausible(t, eta, tau, source, effort_unit)
        steps = np.diff(t) if prev_t is None else np.diff(t, prepend=prev_t)
        if sv.n == 0:
            sv.t_first = float(t[0])
        if len(steps):
            exact = _count_steps(steps, exact, hist)
            j = int(np.argmax(steps))
            if steps[j] > sv.max_step:
                sv.max_step = float(steps[j])
                sv.max_step_after = float(t[j] if prev_t is None else (prev_t if j == 0 else t[j - 1]))
            sv.min_step = min(sv.min_step, float(steps.min()))
        # the first sample of each START_SPACING_S of time: the same samples however the log is cut
        bucket = np.floor((t - sv.t_first) / START_SPACING_S).astype(np.int64)
        keep = bucket != np.concatenate(([last_bucket], bucket[:-1]))
        last_bucket = int(bucket[-1])
        sparse.add(bucket[keep], t[keep], eta[keep], tau[keep])  # boolean indexing copies: no view keeps the piece
        sv.n += k
        prev_t = float(t[-1])
        sv.t_last = prev_t
    sv.speed_pos, sv.speed_neg = acc[0:2].copy(), acc[2:4].copy()
    sv.effort_neg, sv.effort_pos = acc[4:6].copy(), acc[6:8].copy()
    sv.power, sv.abs_power, sv.opposing = acc[8:10].copy(), acc[10:12].copy(), acc[12:14].copy()
    sv.driving = acc[14:16].copy()
    sv.speed_max, sv.effort_max, sv.effort_fractional = acc[16:18].copy(), acc[18:20].copy(), acc[20:22].copy()
    sv.median_step = _median_step(exact, hist)
    if sv.n and not all(sv.positive | sv.negative) and iter(pieces) is not pieces:  # a log that can be read again
        sv.sign_pos, sv.sign_neg = mean_keeps_sign(pieces, sign_half_window(sv.n, sv.duration))
    if sparse.parts:
        sv.sparse_t, sv.sparse_eta, sv.sparse_tau = sparse.arrays()
        sv.sparse_spacing = START_SPACING_S * 2**sparse.level
    return sv


class _Sparse:
    """The sparse sample as it is gathered: the first sample of each interval of START_SPACING_S * 2**level s (an
    interval's index: its START_SPACING_S bucket >> level), at most SPARSE_MOST of them; the level rises when more
    come.  The same samples however the log is cut (the buckets are counted from t_first)."""

    def __init__(self) -> None:
        self.level = 0
        self.parts: list[tuple[np.ndarray, ...]] = []  # (bucket, t, eta, tau) kept, in time order
        self.count = 0
        self.last = -1  # the interval of the last sample kept

    def add(self, bucket: np.ndarray, t: np.ndarray, eta: np.ndarray, tau: np.ndarray) -> None:
        """The first samples of their START_SPACING_S buckets (``bucket``: their indices, increasing)."""
        part = self._firsts((bucket, t, eta, tau))
        if len(part[0]):
            self.parts.append(part)
            self.count += len(part[0])
            self.last = int(part[0][-1] >> self.level)
        while self.count > SPARSE_MOST:
            self.level += 1
            whole = tuple(np.concatenate(column) for column in zip(*self.parts, strict=True))
            self.last = -1
            self.parts = [self._firsts(whole)]
            self.count = len(self.parts[0][0])
            self.last = int(self.parts[0][0][-1] >> self.level)

    def _firsts(self, part: tuple[np.ndarray, ...]) -> tuple[np.ndarray, ...]:
        """Of ``part``'s samples, the first of each interval at this level not already kept."""
        interval = part[0] >> self.level
        keep = interval != np.concatenate(([self.last], interval[:-1]))
        return tuple(column[keep] for column in part)

    def arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(t (m,), eta (m, 2), tau (m, 2)) of the samples kept."""
        return tuple(np.concatenate([part[i] for part in self.parts]) for i in (1, 2, 3))  # type: ignore[return-value]


def _count_steps(steps: np.ndarray, exact: dict[float, int] | None, hist: dict[int, int]) -> dict[float, int] | None:
    """Count ``steps``: exactly while there are at most EXACT_STEPS distinct values, then (None is returned)
    in the histogram ``hist``, into which the exact counts are moved when they overflow."""
    if exact is not None:
        for value, count in zip(*np.unique(steps, return_counts=True), strict=True):
            exact[float(value)] = exact.get(float(value), 0) + int(count)
        if len(exact) <= EXACT_STEPS:
            return exact
        values = np.fromiter(exact, dtype=float, count=len(exact))
        counts = np.fromiter(exact.values(), dtype=np.int64, count=len(exact))
        _add_to_histogram(values, counts, hist)
        return None
    _add_to_histogram(steps, np.ones(len(steps), dtype=np.int64), hist)
    return None


def _add_to_histogram(values: np.ndarray, counts: np.ndarray, hist: dict[int, int]) -> None:
    mantissa, exponent = np.frexp(values)  # values = mantissa 2**exponent, mantissa in [0.5, 1)
    keys = exponent.astype(np.int64) * _BUCKETS_PER_OCTAVE + np.floor((mantissa - 0.5) * 2 * _BUCKETS_PER_OCTAVE)
    unique, where = np.unique(keys.astype(np.int64), return_inverse=True)
    for key, count in zip(unique, np.bincount(where, weights=counts), strict=True):
        hist[int(key)] = hist.get(int(key), 0) + int(count)


def _median_step(exact: dict[float, int] | None, hist: dict[int, int]) -> float:
    """The median of the counted steps (as numpy.median: the mean of the two middle ones for an even count)."""
    if exact is not None:
        if not exact:
            return 0.0
        values = np.array(sorted(exact))
        cum = np.cumsum([exact[v] for v in values])
        total = int(cum[-1])
        lo = values[np.searchsorted(cum, (total - 1) // 2 + 1)]
        hi = values[np.searchsorted(cum, total // 2 + 1)]
        return float(0.5 * (lo + hi))
    keys = np.array(sorted(hist))
    cum = np.cumsum([hist[k] for k in keys])
    key = int(keys[np.searchsorted(cum, cum[-1] / 2.0)])
    exponent, sub = divmod(key, _BUCKETS_PER_OCTAVE)
    return float(np.ldexp(0.5 + (sub + 0.5) / (2 * _BUCKETS_PER_OCTAVE), exponent))  # the bucket's middle


def _raise_implausible(t: np.ndarray, eta: np.ndarray, tau: np.ndarray, source: str, effort_unit: str) -> None:
    for arr, what, unit in ((eta, "a wheel speed", "rad/s"), (tau, "an effort", effort_unit)):
        with np.errstate(invalid="ignore"):
            bad = ~np.isfinite(arr) | (np.abs(arr) > PLAUSIBLE_LIMIT)
        if bad.any():
            i = int(np.argmax(bad.any(axis=1)))
            raise NotIdentifiableError(
                f"{source}: {what} of {arr[i][bad[i]][0]:.3g} {unit} at t = {t[i]:.6g} s is not a number a "
                "robot logs; check the log's units and columns"
            )


@kernel
def _piece_stats(eta, tau, limit, acc):
    """One pass over a piece, eta and tau (k, 2): adds to acc (22,) the counts, sums and maxima of :class:`Survey`
    (see survey()); returns the first row holding a non-finite or implausible value, or -1."""
    for i in range(eta.shape[0]):
        for w in range(2):
            e = eta[i, w]
            u = tau[i, w]
            if not (abs(e) <= limit and abs(u) <= limit):  # also NaN
                return i
            if e > 0:
                acc[w] += 1
            elif e < 0:
                acc[2 + w] += 1
            if u < 0:
                acc[4 + w] += 1
            elif u > 0:
                acc[6 + w] += 1
            prod = u * e
            acc[8 + w] += prod
            acc[10 + w] += abs(prod)
            if prod < 0:
                acc[12 + w] += 1
            elif prod > 0:
                acc[14 + w] += 1
            acc[16 + w] = max(acc[16 + w], abs(e))
            acc[18 + w] = max(acc[18 + w], abs(u))
            if u != math.floor(u):
                acc[20 + w] += 1
    return -1
