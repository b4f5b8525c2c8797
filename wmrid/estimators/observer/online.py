"""The observer fed in pieces as they arrive, and its estimate with a standard error at any moment (``wmrid live``).

:class:`OnlineObserver` is a thin object around the same compiled kernel the offline replay runs
(:func:`wmrid.estimators.observer.kernel.observer_chunk`, started from the first sample exactly as
:func:`wmrid.estimators.observer.replay.replay_pieces` starts it), so after the same samples its estimate theta and
Gamma are those of the offline replay, bit for bit, however the samples were cut into pieces
(``tests/unit/api/test_live.py``). What differs is the bookkeeping around it, because the log's length is not known in
advance: no history, and the per-block sums of the normal equations kept over blocks of a fixed duration (min(0.1 s,
0.1/k), as offline), two neighbours merged into one (and the duration doubled) whenever MAX_BLOCKS are full, so memory
stays bounded however long the stream runs.

:func:`online_estimate` turns that state into base parameters with a standard error: the box projection, the
minimum-distance recovery of theta0 and the delete-a-segment jackknife over the blocks, as offline
(:mod:`wmrid.estimators.uncertainty`).  What the offline result adds on top and needs the whole log or a second run
is not in it: the widening for model error, discretisation (the half-rate replay), slow speeds, the closed-loop
check, the efforts' timing and hold, and the start sensitivity; the final result of ``wmrid live`` is the offline
``identify`` and has them.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wmrid.estimators.observer.kernel import observer_chunk, project_history_box
from wmrid.estimators.observer.replay import KernelState
from wmrid.estimators.observer.settings import ObserverSettings
from wmrid.estimators.result import reported_names
from wmrid.estimators.sign_speed import SignSpeeds
from wmrid.estimators.uncertainty import estimate_covariances
from wmrid.model.base_params import derived_with_std, fit_base_parameters
from wmrid.model.kernels import plain

#: The most blocks kept; past it neighbours are merged (the jackknife uses at most 40 segments).
MAX_BLOCKS = 4096


class OnlineObserver:
    """The observer's state, advanced by :meth:`feed` with pieces of t (k,) s, eta (k, 2) rad/s, tau (k, 2).

    ``theta`` (2, p) the unconstrained estimate, ``gamma``/``gamma_inv`` (p, p), ``n`` samples, ``t_first``/``t_last``
    s; the blocks' sums (J, p, p), (J, 2, p), (J, 2), (J, 2) and end times (J,) s are :meth:`blocks`.
    """

    def __init__(
        self, settings: ObserverSettings, block_seconds: float | None = None, sign_half_window: int = 0
    ) -> None:
        p = settings.form.n_columns
        self.settings = settings
        self.ks = KernelState.initial(settings)
        self.hold = settings.hold_code
        self.k = self.ks.k
        self.n = 0
        self.t_first = 0.0
        self.t_last = 0.0
        self.block_seconds = float(block_seconds or min(0.1, 0.1 / self.k))
        self._a = np.zeros((MAX_BLOCKS + 1, p, p))
        self._c = np.zeros((MAX_BLOCKS + 1, 2, p))
        self._uu = np.zeros((MAX_BLOCKS + 1, 2))
        self._ee = np.zeros((MAX_BLOCKS + 1, 2))
        self._end_t = np.zeros(MAX_BLOCKS + 1)
        self.closed = 0  # blocks closed; the open one is at index ``closed``
        self._open = False  # whether the open block holds a step
        self._bucket = 0  # the open block's bucket: floor((t - t_first) / block_seconds)
        # the kernel's history: one slot it never reaches (no history is kept online)
        self._hist_idx = np.array([-1], dtype=np.int64)
        # the sign columns' centred mean (wmrid.estimators.sign_speed): samples reach the kernel that many late
        self._signs = SignSpeeds(sign_half_window)
        #: (2,) the smallest and largest centred mean speed the sign columns have taken so far, rad/s
        self.sign_low = np.full(2, np.inf)
        self.sign_high = np.full(2, -np.inf)
        self._hist = (np.empty((1, 2, p)), np.empty((1, 2)), np.empty((1, p, p)))

    @property
    def theta(self) -> np.ndarray:
        """The current estimate (2, p)."""
        return self.ks.theta

    @property
    def gamma(self) -> np.ndarray:
        return self.ks.gamma

    @property
    def gamma_inv(self) -> np.ndarray:
        return self.ks.gamma_inv

    def feed(self, t: np.ndarray, eta: np.ndarray, tau: np.ndarray) -> None:
        """Advance over the samples t (k,) s (after every sample fed so far), eta (k, 2) rad/s, tau (k, 2); with a
        sign window of h samples the last h wait for their successors (or :meth:`finish`)."""
        if len(t):
            self._advance(*self._signs.feed(t, eta, tau))

    def finish(self) -> None:
        """Advance over the samples the sign window still holds back (the stream has ended)."""
        self._advance(*self._signs.finish())

    def _advance(self, t: np.ndarray, eta: np.ndarray, tau: np.ndarray, eta_sign: np.ndarray) -> None:

        if len(t) == 0:
            return
        t = np.ascontiguousarray(t, dtype=np.float64)
        eta = np.ascontiguousarray(eta, dtype=np.float64)
        tau = np.ascontiguousarray(tau, dtype=np.float64)
        eta_sign = np.ascontiguousarray(eta_sign, dtype=np.float64)
        np.minimum(self.sign_low, eta_sign.min(axis=0), out=self.sign_low)
        np.maximum(self.sign_high, eta_sign.max(axis=0), out=self.sign_high)
        ks = self.ks
        skip = 0
        if self.n == 0:  # the first sample starts the predictor and the filter, as in replay_pieces
            self.ks.start(t, eta, tau, eta_sign)
            self.t_first = float(t[0])
            skip = 1
        ts, es, us, ss = t[skip:], eta[skip:], tau[skip:], eta_sign[skip:]
        c = len(ts)
        if c:
            bucket = np.floor((ts - self.t_first) / self.block_seconds).astype(np.int64)
            if bucket[0] > self._bucket:  # the last piece ended a block
                self._close(bucket[0])
            # a block ends at a sample whose next sample is in a later bucket; the piece's last sample ends a call
            ends = np.flatnonzero(bucket[1:] > bucket[:-1])
            local = np.append(ends, c - 1) if (len(ends) == 0 or ends[-1] != c - 1) else ends
            offset = self.n + skip
            block_end = (offset + local).astype(np.int64)
            nb = len(block_end)
            p = ks.theta.shape[1]
            blk = (np.zeros((nb, p, p)), np.zeros((nb, 2, p)), np.zeros((nb, 2)), np.zeros((nb, 2)))
            cursor = np.zeros(2, dtype=np.int64)
            observer_chunk(
                plain(ts), plain(es), plain(ss), plain(us), offset, ks.kind, self.hold, ks.k, ks.st, ks.w, ks.g_prev,
                ks.theta, ks.gamma, ks.gamma_inv, self._hist_idx, *self._hist, block_end, *blk, cursor, ks.geom,
                ks.load,
            )  # fmt: skip
            for j in range(nb):
                i = self.closed
                self._a[i] += blk[0][j]
                self._c[i] += blk[1][j]
                self._uu[i] += blk[2][j]
                self._ee[i] += blk[3][j]
                self._end_t[i] = ts[local[j]]
                self._open = True
                if j < len(ends):  # a real block end (not only the end of this piece)
                    self._close(bucket[local[j] + 1])
        self.n += len(t)
        self.t_last = float(t[-1])

    def _close(self, next_bucket: int) -> None:
        """Close the open block; the next one holds bucket ``next_bucket``."""
        self._bucket = int(next_bucket)
        if not self._open:
            return
        self._open = False
        self.closed += 1
        if self.closed == MAX_BLOCKS:  # merge neighbours: blocks twice as long, memory bounded
            half = MAX_BLOCKS // 2
            for arr in (self._a, self._c, self._uu, self._ee):
                arr[:half] = arr[0:MAX_BLOCKS:2] + arr[1:MAX_BLOCKS:2]
                arr[half:] = 0.0
            self._end_t[:half] = self._end_t[1:MAX_BLOCKS:2]
            self._end_t[half:] = 0.0
            self.closed = half
            self.block_seconds *= 2.0
            self._bucket = int(next_bucket) // 2

    def blocks(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(blk_a (J, p, p), blk_c (J, 2, p), blk_uu (J, 2), blk_ee (J, 2), end times (J,) s), the open block last."""
        j = self.closed + (1 if self._open else 0)
        return self._a[:j], self._c[:j], self._uu[:j], self._ee[:j], self._end_t[:j]


@dataclass(frozen=True)
class OnlineEstimate:
    """Base parameters from the observer's state so far: ``parameters`` {name: (value, std)} in SI units (std: the
    jackknife over contiguous segments, before the offline widening terms), ``segments`` the jackknife's, ``dof``."""

    parameters: dict[str, tuple[float, float]]
    segments: int
    dof: int


def online_estimate(obs: OnlineObserver) -> OnlineEstimate | None:
    """The estimate of ``obs`` with its jackknife std (module docstring), or None while the samples do not determine
    one (too few, or a singular system)."""
    duration = obs.t_last - obs.t_first
    if obs.n < 20 or duration <= 0:
        return None
    s = obs.settings
    blk_a, blk_c, _, _, end_t = obs.blocks()
    if len(end_t) < 2:
        return None
    starts = np.concatenate(([obs.t_first], end_t[:-1]))
    mid = (0.5 * (starts + end_t) - obs.t_first) / duration
    try:
        with np.errstate(all="ignore"):
            theta_cov, weight_cov, unc = estimate_covariances(
                obs.gamma, obs.gamma_inv, obs.theta, blk_a, blk_c, mid, duration
            )
            theta = np.empty_like(obs.theta)
            # writable copies of the settings' read-only box, as observe passes its own: one compiled kernel
            lo, hi = np.array(s.theta_min), np.array(s.theta_max)
            project_history_box(obs.theta[None], obs.gamma[None], lo, hi, theta[None])
            fit = fit_base_parameters(theta, weight_cov, s.form, report_cov=theta_cov, report_dof=unc["dof"])
            named = derived_with_std(fit.theta0, fit.cov, s.form.base_names)
    except (np.linalg.LinAlgError, ValueError, FloatingPointError, ZeroDivisionError):
        return None
    if not all(np.isfinite(v) for v, _ in named.values()):
        return None
    parameters = {name: named[name] for name in reported_names(s.form) if name in named}
    return OnlineEstimate(parameters=parameters, segments=int(unc["segments"]), dof=int(unc["dof"]))
