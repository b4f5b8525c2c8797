"""The wheel-speed sensors' white-noise level, measured from the log itself in bounded memory.

The observer's prediction error e = eta - eta_hat (:mod:`wmrid.estimators.observer.kernel`) is, where the model holds,
the speed sensors' noise and little else: the predictor follows the speeds with a slow gain, so
rms(e) ~ sigma.  Where the model fails -- wheels that slip, backlash, a current loop the model leaves out --
e grows far beyond sigma (docs/explanation/checks.md, "Slip and other gross misfit").  sigma itself comes
from the second differences d_i = eta_i - 2 eta_(i-1) + eta_(i-2): white noise of variance sigma^2 gives
E d^2 = 6 sigma^2, while a smooth motion adds only (h^2 eta'')^2, negligible at the rates robots log.

Bursts (a wheel that slips at every acceleration peak, a spike) must not raise sigma, so the level is the
median over windows of WINDOW second differences of their mean square, kept as a histogram of log-spaced
buckets (BUCKETS_PER_OCTAVE per factor of 2 in variance, 1.1 % in sigma): memory does not grow with the log.
"""

from __future__ import annotations

import numpy as np

from wmrid.core.jit import kernel
from wmrid.core.wheel_log import DERIVED_NOTE
from wmrid.model.kernels import plain


def derived_lag(notes) -> int:
    """The lag (samples) at which a log's speed noise is uncorrelated: the Savitzky-Golay window its reading notes
    name when the speeds were derived from positions (:data:`DERIVED_NOTE`), else 1 (measured speeds)."""
    for note in notes or ():
        if DERIVED_NOTE in note:
            digits = note.split(DERIVED_NOTE, 1)[1].split(" ", 1)[0]
            if digits.isdigit() and int(digits) >= 1:
                return int(digits)
    return 1


#: Second differences per window (the median of windows' mean squares is then unbiased within ~2 %).
WINDOW = 64
#: Histogram resolution: buckets per octave of variance.
BUCKETS_PER_OCTAVE = 32
#: Fewer windows than this and the level is not reported.
MIN_WINDOWS = 4


@kernel
def _window_variances(eta, prev, state, out):
    """One pass over a piece eta (k, 2): second differences at lag L = len(prev) // 2, d_i = eta_i - 2 eta_(i-L) +
    eta_(i-2L), continued from ``prev`` (2L, 2), a ring of the last 2L samples before the piece (``state[0]`` of them
    known, the oldest at ``state[6]``), summed in windows of WINDOW; each completed window's mean square / 6 goes to
    ``out`` (k // WINDOW + 1, 2).  state = [samples known (0-2L), open window's count, its two sums, two sums of
    eta^2, the ring's start].  Returns the number of windows completed."""
    size = prev.shape[0]
    lag = size // 2
    known = int(state[0])
    count = int(state[1])
    start = int(state[6])
    done = 0
    for i in range(eta.shape[0]):
        e0 = eta[i, 0]
        e1 = eta[i, 1]
        state[4] += e0 * e0
        state[5] += e1 * e1
        if known == size:
            old = start  # eta_(i-2L)
            mid = start + lag  # eta_(i-L), (start + lag) mod size without a division
            if mid >= size:
                mid -= size
            d0 = e0 - 2.0 * prev[mid, 0] + prev[old, 0]
            d1 = e1 - 2.0 * prev[mid, 1] + prev[old, 1]
            state[2] += d0 * d0
            state[3] += d1 * d1
            count += 1
            if count == WINDOW:
                out[done, 0] = state[2] / (6.0 * WINDOW)
                out[done, 1] = state[3] / (6.0 * WINDOW)
                done += 1
                count = 0
                state[2] = 0.0
                state[3] = 0.0
            prev[start, 0] = e0
            prev[start, 1] = e1
            start += 1
            if start == size:
                start = 0
        else:
            prev[known, 0] = e0
            prev[known, 1] = e1
            known += 1
    state[0] = known
    state[1] = count
    state[6] = start
    return done


class NoiseFloor:
    """Streaming estimate of each wheel's white speed noise sigma (rad/s) and of the speeds' rms.

    ``feed(eta)`` with consecutive pieces (k, 2) rad/s of one log, in order; ``sigma()`` (2,) rad/s, NaN for a
    wheel with fewer than MIN_WINDOWS windows that show any noise; ``rms()`` (2,) rad/s.  ``lag`` samples: the
    second differences' spacing; 1 for speeds measured sample by sample, whose noise is white.  Speeds a smoothing
    derivative made from positions (:func:`derived_lag`) carry noise correlated over its window, which lag-1
    differences see only a fraction of (about a third for a Savitzky-Golay cubic over 20 ms of a 2048-count
    encoder): at a lag of the window, the noise samples are uncorrelated again and E d^2 = 6 sigma^2, while a
    smooth motion adds (lag h)^4 eta''^2, which can only raise the level (the misfit check then errs towards
    silence, not towards a false flag).
    """

    def __init__(self, lag: int = 1) -> None:
        if not (isinstance(lag, int) and lag >= 1):
            raise ValueError(f"lag must be a whole number >= 1, got {lag!r}")
        self.lag = lag
        self._prev = np.zeros((2 * lag, 2))  # the last 2 lag samples seen (a ring)
        self._state = np.zeros(7)  # see _window_variances
        self._hist: list[dict[int, int]] = [{}, {}]
        self._windows = np.zeros(2, dtype=np.int64)  # per wheel: windows counted (positive, finite variance)
        self._n = 0

    def feed(self, eta: np.ndarray) -> None:
        eta = plain(eta)
        if len(eta) == 0:
            return
        out = np.empty((len(eta) // WINDOW + 1, 2))
        done = _window_variances(eta, self._prev, self._state, out)
        self._n += len(eta)
        if done:
            self._add(out[:done])

    def _add(self, variances: np.ndarray) -> None:
        """Count windows' variance estimates (w, 2) into each wheel's log-spaced histogram.

        A window whose second differences are all zero (a parked wheel, a speed held constant between encoder
        updates) says nothing about the noise, nor does a non-finite one: neither is counted, so a log parked
        most of the time still gives the noise of its moving part (or NaN when it never moves)."""
        for wheel in range(2):
            col = variances[:, wheel]
            col = col[np.isfinite(col) & (col > 0.0)]
            if not len(col):
                continue
            self._windows[wheel] += len(col)
            keys = np.floor(np.log2(col) * BUCKETS_PER_OCTAVE).astype(np.int64)
            unique, counts = np.unique(keys, return_counts=True)
            hist = self._hist[wheel]
            for key, count in zip(unique.tolist(), counts.tolist(), strict=True):
                hist[key] = hist.get(key, 0) + count

    def sigma(self) -> np.ndarray:
        """(2,) rad/s: per wheel, the noise level of the median window (the lower median for an even count), NaN
        with fewer than MIN_WINDOWS counted windows; always positive otherwise."""
        out = np.full(2, np.nan)
        for wheel, hist in enumerate(self._hist):
            if self._windows[wheel] < MIN_WINDOWS:
                continue
            keys = np.array(sorted(hist))
            cum = np.cumsum([hist[k] for k in keys])
            key = int(keys[np.searchsorted(cum, cum[-1] / 2.0)])
            out[wheel] = np.sqrt(2.0 ** ((key + 0.5) / BUCKETS_PER_OCTAVE))
        return out

    def rms(self) -> np.ndarray:
        """(2,) rad/s: root mean square of each wheel's speed."""
        return np.sqrt(self._state[4:6] / max(self._n, 1))
