"""The wheel-speed sensors' white-noise level, measured from the log itself in bounded memory.

The observer's prediction error e = eta - eta_hat (:mod:`wmrid.observer_kernel`) is, where the model holds,
the speed sensors' noise and little else: the predictor follows the speeds with a slow gain, so
rms(e) ~ sigma.  Where the model fails -- wheels that slip, backlash, a current loop the model leaves out --
e grows far beyond sigma (README "What the std covers when the model does not hold").  sigma itself comes
from the second differences d_i = eta_i - 2 eta_(i-1) + eta_(i-2): white noise of variance sigma^2 gives
E d^2 = 6 sigma^2, while a smooth motion adds only (h^2 eta'')^2, negligible at the rates robots log.

Bursts (a wheel that slips at every acceleration peak, a spike) must not raise sigma, so the level is the
median over windows of WINDOW second differences of their mean square, kept as a histogram of log-spaced
buckets (BUCKETS_PER_OCTAVE per factor of 2 in variance, 1.1 % in sigma): memory does not grow with the log.
"""

from __future__ import annotations

import numpy as np

#: Second differences per window (the median of windows' mean squares is then unbiased within ~2 %).
WINDOW = 64
#: Histogram resolution: buckets per octave of variance.
BUCKETS_PER_OCTAVE = 32
#: Fewer windows than this and the level is not reported.
MIN_WINDOWS = 4


class NoiseFloor:
    """Streaming estimate of each wheel's white speed noise sigma (rad/s) and of the speeds' rms.

    ``feed(eta)`` with consecutive pieces (k, 2) rad/s of one log, in order; ``sigma()`` (2,) rad/s, NaN when
    the log has fewer than MIN_WINDOWS windows; ``rms()`` (2,) rad/s.
    """

    def __init__(self) -> None:
        self._tail = np.empty((0, 2))  # the last two samples of the previous piece
        self._partial = np.zeros(2)  # sum of d^2 in the window being filled, and its count
        self._partial_count = 0
        self._hist: list[dict[int, int]] = [{}, {}]
        self._windows = 0
        self._sum_sq = np.zeros(2)
        self._n = 0

    def feed(self, eta: np.ndarray) -> None:
        eta = np.asarray(eta, dtype=np.float64)
        if len(eta) == 0:
            return
        self._sum_sq += np.einsum("ij,ij->j", eta, eta)
        self._n += len(eta)
        joined = np.concatenate((self._tail, eta))
        self._tail = joined[-2:].copy()
        if len(joined) < 3:
            return
        d2 = np.square(joined[2:] - 2.0 * joined[1:-1] + joined[:-2])
        start = 0
        if self._partial_count:  # complete the window left open by the previous piece
            take = min(WINDOW - self._partial_count, len(d2))
            self._partial += d2[:take].sum(axis=0)
            self._partial_count += take
            start = take
            if self._partial_count < WINDOW:
                return
            self._add(self._partial[None] / (6.0 * WINDOW))
            self._partial[:] = 0.0
            self._partial_count = 0
        rest = d2[start:]
        full = len(rest) // WINDOW
        if full:
            self._add(rest[: full * WINDOW].reshape(full, WINDOW, 2).mean(axis=1) / 6.0)
        tail = rest[full * WINDOW :]
        if len(tail):
            self._partial += tail.sum(axis=0)
            self._partial_count = len(tail)

    def _add(self, variances: np.ndarray) -> None:
        """Count windows' variance estimates (w, 2) into each wheel's log-spaced histogram."""
        self._windows += len(variances)
        with np.errstate(divide="ignore"):
            keys = np.floor(np.log2(variances) * BUCKETS_PER_OCTAVE)
        for wheel in range(2):
            col = keys[:, wheel]
            col = np.where(np.isfinite(col), col, np.iinfo(np.int32).min).astype(np.int64)  # zero: lowest bucket
            unique, counts = np.unique(col, return_counts=True)
            hist = self._hist[wheel]
            for key, count in zip(unique.tolist(), counts.tolist(), strict=True):
                hist[key] = hist.get(key, 0) + count

    def sigma(self) -> np.ndarray:
        """(2,) rad/s: the median window's noise level per wheel (NaN with fewer than MIN_WINDOWS windows)."""
        if self._windows < MIN_WINDOWS:
            return np.full(2, np.nan)
        out = np.empty(2)
        for wheel, hist in enumerate(self._hist):
            keys = np.array(sorted(hist))
            cum = np.cumsum([hist[k] for k in keys])
            key = int(keys[np.searchsorted(cum, cum[-1] / 2.0)])
            out[wheel] = 0.0 if key == np.iinfo(np.int32).min else np.sqrt(2.0 ** ((key + 0.5) / BUCKETS_PER_OCTAVE))
        return out

    def rms(self) -> np.ndarray:
        """(2,) rad/s: root mean square of each wheel's speed."""
        return np.sqrt(self._sum_sq / max(self._n, 1))
