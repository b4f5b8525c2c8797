"""The wheel speeds the Coulomb and caster-drag columns take their sign (direction) from: a short centred mean.

The regressor's sgn(eta) columns (Eqs. 15-17; the casters' -sgn(eta_1 +/- eta_2) and the direction of each caster's
drag) are a step function of a *measured* speed.  Where the true speed passes through zero more slowly than the
speed noise sigma, the measured sign flips at random for as long as |eta| < about 2 sigma: an errors-in-variables
bias, not noise, that the observer's standard error does not cover.  A caster's drag direction u/|u| is worse: its
mean under noise departs from the noise-free one as sigma^2 / |u|^2 wherever the caster's contact moves slowly,
not only within a band of zero.  On the paper robot (ball casters whose drag, 0.56 N m at each wheel when turning,
is twelve times the wheels' Coulomb friction) this is what made its MuJoCo plan logs fail (0.02 rad/s at 1 kHz):
with the drag computed from the true speeds and added to the efforts of a caster-free run, so that the model is
exact and only the measured directions err, the constant-drag model's structural mismatch was T2 51 (S 5.7) with
the measured speeds and T2 13 (S 1) with this mean.  Together with the load model's lagged derivative columns
(:data:`wmrid.model.dynamics.DERIVATIVE_LAG`) the real MuJoCo log goes from S 23.6 (every friction parameter
poorly determined) to S 1.0, every base parameter within 1.9 std of the truth.

A centred mean over 2H + 1 samples divides the noise by sqrt(2H + 1) and leaves the sign of a speed that is linear
over the window where it was (a zero crossing does not move), so the band of random signs narrows by that factor.
Only the sign-like columns see the mean: every other column, the predictor and the noise floor keep the measured
speeds.  H follows the log's rate, SIGN_WINDOW_S wide in all: short against any drive's reversal (a plan's
highest harmonic has a period of 2 s) and wide enough to matter at 1 kHz (21 samples, noise / 4.6); at 50 Hz and
slower H = 0, the measured speed itself.

The mean of a window is summed over the same samples in the same order however the log was cut into
pieces (:class:`SignSpeeds`), so a streamed log and the whole log give the same signs bit for bit.  Windows are cut
short at the log's two ends (the mean of the samples there is).
"""

from __future__ import annotations

from collections.abc import Iterable
from typing import Any

import numpy as np

from wmrid.core.jit import kernel

#: s: the full width of the centred mean.
SIGN_WINDOW_S = 0.02
#: The largest half-window, samples (a 50 kHz log): bounds the memory a streamed log holds back.
MAX_HALF_WINDOW = 500


def sign_half_window(n: int, duration: float) -> int:
    """H, samples: the half-width of the centred mean for a log of n samples over ``duration`` s (0 for a log slower
    than 1 / (SIGN_WINDOW_S / 2) = 100 Hz ... rounded: H = round(rate * SIGN_WINDOW_S / 2))."""
    if n < 2 or not duration > 0:
        return 0
    rate = (n - 1) / duration
    return int(min(MAX_HALF_WINDOW, max(0, round(0.5 * SIGN_WINDOW_S * rate))))


def _window_means(x: np.ndarray, h: int, left: int, right: int) -> np.ndarray:
    """Means (m, 2) of the windows of x (N, 2) centred on its rows left .. N - right - 1, ``left`` and ``right`` being
    the rows of context x holds before and after them; a window is cut short where x ends.  Each window is summed
    in one fixed order (oldest sample first, starting from 0.0), so the result does not depend on what else x
    holds."""
    x = np.ascontiguousarray(x, dtype=np.float64)
    return _window_means_kernel(x, int(h), int(left), int(right))


@kernel
def _window_means_kernel(x: np.ndarray, h: int, left: int, right: int) -> np.ndarray:  # pragma: no cover - compiled
    # the sums numpy's loop over the offsets -h .. h made (0.0 + x[i - h] + ... + x[i + h], in that order, cut at
    # the ends), at about a twentieth of its time on a 1 kHz log (2.7 s for an hour before)
    n = x.shape[0]
    m = max(n - right - left, 0)
    out = np.empty((m, 2))
    for j in range(m):
        i = left + j
        lo = max(i - h, 0)
        hi = min(i + h + 1, n)
        for c in range(2):
            total = 0.0
            for k in range(lo, hi):
                total += x[k, c]
            out[j, c] = total / (hi - lo)
    return out


def centred_mean(eta: np.ndarray, h: int) -> np.ndarray:
    """eta (n, 2) rad/s averaged over 2h + 1 samples centred on each (cut short at the ends); eta itself for h = 0."""
    eta = np.asarray(eta, dtype=np.float64)
    if h <= 0 or len(eta) == 0:
        return eta
    return _window_means(eta, h, 0, 0)


class SignSpeeds:
    """:func:`centred_mean` over a log that arrives in pieces, each sample given out once its h successors came.

    :meth:`feed` takes consecutive pieces (t (k,), eta (k, 2), tau (k, 2)) and returns the samples that are now
    complete as (t, eta, tau, eta_sign), h samples behind; :meth:`finish` returns the last h (windows cut short).
    Memory: 2h samples held back.
    """

    def __init__(self, h: int) -> None:
        self.h = int(h)
        self._ctx = np.empty((0, 2))  # up to h samples before the first held one (the left side of its window)
        self._held: tuple[np.ndarray, np.ndarray, np.ndarray] = (np.empty(0), np.empty((0, 2)), np.empty((0, 2)))

    def feed(self, t: np.ndarray, eta: np.ndarray, tau: np.ndarray):
        """The samples complete after this piece: (t (m,), eta (m, 2), tau (m, 2), eta_sign (m, 2))."""
        eta = np.asarray(eta, dtype=np.float64)
        if self.h == 0:
            return t, eta, tau, eta
        ht, he, hu = self._held
        t_all = np.concatenate((ht, t))
        e_all = np.concatenate((he, eta))
        u_all = np.concatenate((hu, tau))
        ready = max(0, len(t_all) - self.h)
        x = np.concatenate((self._ctx, e_all))
        left = len(self._ctx)
        means = _window_means(x[: left + ready + self.h], self.h, left, self.h) if ready else np.empty((0, 2))
        self._ctx = x[max(0, left + ready - self.h) : left + ready]
        self._held = (t_all[ready:], e_all[ready:], u_all[ready:])
        return t_all[:ready], e_all[:ready], u_all[:ready], means

    def finish(self):
        """The samples still held back, with windows cut short at the log's end."""
        ht, he, hu = self._held
        if self.h == 0 or len(ht) == 0:
            return ht, he, hu, he
        x = np.concatenate((self._ctx, he))
        means = _window_means(x, self.h, len(self._ctx), 0)
        self._held = (np.empty(0), np.empty((0, 2)), np.empty((0, 2)))
        return ht, he, hu, means


def mean_keeps_sign(pieces: Iterable[Any], h: int) -> tuple[np.ndarray, np.ndarray]:
    """(2,) bool, per wheel: every centred mean speed over 2h + 1 samples is > 0; every one is < 0 (a second pass over
    ``pieces``, the means made as the sign columns make them: :class:`SignSpeeds`).  The pass stops as soon as each
    wheel has had a mean <= 0 and a mean >= 0 (then neither holds): a wheel that reverses settles it at its first
    reversal, so only a log whose means keep their sign is read to its end.  h = 0: both False (the mean is the
    measured speed, which the survey counted)."""
    positive, negative = np.zeros(2, dtype=bool), np.zeros(2, dtype=bool)
    if h == 0:
        return positive, negative
    not_pos, not_neg = np.zeros(2, dtype=bool), np.zeros(2, dtype=bool)  # some mean <= 0; some mean >= 0
    signs = SignSpeeds(h)

    def seen(mean: np.ndarray) -> None:
        not_pos[:] |= (mean <= 0).any(axis=0)
        not_neg[:] |= (mean >= 0).any(axis=0)

    for piece in pieces:
        if len(piece.t):
            seen(signs.feed(piece.t, np.asarray(piece.eta, dtype=np.float64), piece.tau)[3])
            if (not_pos & not_neg).all():
                return positive, negative
    seen(signs.finish()[3])
    return ~not_pos, ~not_neg
