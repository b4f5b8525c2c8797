"""Replay a log through the compiled estimator, chunk by chunk (a thin object around the kernel).

The chunks let the CLI show progress and keep per-call work bounded; the result does not depend on
the chunk size (tests check this).
"""

from __future__ import annotations

import threading
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any

import numpy as np

from wmrid.estimators.noise_floor import NoiseFloor
from wmrid.estimators.observer.kernel import KIND_CASTER, KIND_CASTER_GEOMETRY, KIND_GENERAL, KIND_PAPER, observer_chunk
from wmrid.estimators.observer.settings import ObserverSettings
from wmrid.estimators.sign_speed import SignSpeeds
from wmrid.model.dynamics import LOAD_SIGNALS, filter_regressor
from wmrid.model.kernels import plain

CHUNK = 262_144

#: Whether identify may use a second thread: the half-rate run, and the timing check alongside the observer's passes
#: (:mod:`wmrid.pipeline.alongside`); one identify then uses two cores.  A process that shares the machine's cores with
#: others doing the same (``wmrid fleet``'s workers, one per core) turns it off (:func:`one_thread`): there the second
#: thread only competes for a busy core (+6-10 % per log, measured).
_SECOND_THREAD = True


def one_thread(on: bool = True) -> None:
    """Run identify on the caller's thread alone (``on``: the half-rate replay inline, the timing check before the
    observer's passes), or on two (the default)."""
    global _SECOND_THREAD
    _SECOND_THREAD = not on


#: Blocks of :func:`one_thread_within` entered and not yet left, in any thread.
_one_thread_blocks = 0
_blocks_lock = threading.Lock()


@contextmanager
def one_thread_within() -> Iterator[None]:
    """Within, identify runs on the caller's thread alone (:func:`one_thread`), whatever the process's setting, which
    stays; overlapping blocks (other threads) keep it so until the last one ends."""
    global _one_thread_blocks
    with _blocks_lock:
        _one_thread_blocks += 1
    try:
        yield
    finally:
        with _blocks_lock:
            _one_thread_blocks -= 1


def second_thread() -> bool:
    """Whether identify may run a second pass on a second thread (:func:`one_thread`, :func:`one_thread_within`)."""
    return _SECOND_THREAD and _one_thread_blocks == 0


@dataclass(frozen=True)
class ReplayOutput:
    """What one replay produced.

    theta (2, p) unconstrained estimate; gamma, gamma_inv (p, p); eta_hat (2,) rad/s;
    hist_idx (m,) sample indices with hist_theta (m, 2, p), hist_e (m, 2) rad/s, hist_gamma (m, p, p);
    hist_t (m,) and block_t (J,) the times (s) of the history samples and of the block ends;
    block_end (J,) and per-block sums blk_a (J, p, p), blk_c (J, 2, p), blk_uu (J, 2), blk_ee (J, 2)
    (see :func:`wmrid.estimators.observer.kernel.observer_chunk`).
    """

    theta: np.ndarray
    gamma: np.ndarray
    gamma_inv: np.ndarray
    eta_hat: np.ndarray
    hist_idx: np.ndarray
    hist_theta: np.ndarray
    hist_e: np.ndarray
    hist_gamma: np.ndarray
    block_end: np.ndarray
    blk_a: np.ndarray
    blk_c: np.ndarray
    blk_uu: np.ndarray
    blk_ee: np.ndarray
    hist_t: np.ndarray
    block_t: np.ndarray
    theta_half: np.ndarray | None = None  # (2, p) the estimate from every other sample (twice the step), or None
    blk_slow: np.ndarray | None = None  # (J,) bool: the block holds a sample where a wheel is slower than low_speed
    noise_sigma: np.ndarray | None = None  # (2,) rad/s: the speeds' white-noise level (wmrid.estimators.noise_floor)
    eta_rms: np.ndarray | None = None  # (2,) rad/s: the speeds' root mean square


def layout(n: int, duration: float, k: float, max_history: int) -> tuple[np.ndarray, np.ndarray]:
    """History sample indices (m,) and block end indices (J,) for a log of n samples over ``duration`` s.

    Blocks last about min(0.1 s, 0.1/k): well below the residual correlation time 1/k, so the long-run
    covariance sees the correlation; at most 16384 blocks.
    """
    hist = np.unique(np.linspace(0, n - 1, max(1, min(n, max_history))).round().astype(np.int64))
    block_time = min(0.1, 0.1 / k)
    n_blocks = int(min(max(duration / block_time, 1), 16384, max(n - 1, 1)))
    ends = np.unique(np.linspace(0, n - 1, n_blocks + 1).round().astype(np.int64)[1:])
    return hist, ends


def replay(
    t: np.ndarray,
    eta: np.ndarray,
    tau: np.ndarray,
    settings: ObserverSettings,
    *,
    max_history: int = 20000,
    chunk: int = CHUNK,
    progress: Callable[[int], None] | None = None,
    sign_half_window: int = 0,
) -> ReplayOutput:
    """Run the estimator over t (n,) s, eta (n, 2) rad/s, tau (n, 2) N m; ``progress(samples_done)``;
    ``sign_half_window``: see :func:`replay_pieces`."""
    t = np.ascontiguousarray(t, dtype=np.float64)
    eta = np.ascontiguousarray(eta, dtype=np.float64)
    tau = np.ascontiguousarray(tau, dtype=np.float64)
    pieces = ((t[i : i + chunk], eta[i : i + chunk], tau[i : i + chunk]) for i in range(0, len(t), chunk))
    return replay_pieces(
        pieces, len(t), float(t[-1] - t[0]), settings, max_history=max_history, progress=progress,
        sign_half_window=sign_half_window,
    )  # fmt: skip


def kernel_kind(form) -> int:
    """The compiled kernel's regressor kind for ``form`` (:mod:`wmrid.estimators.observer.kernel`)."""

    if form.kind == "paper":
        return KIND_PAPER
    if form.caster:
        return KIND_CASTER_GEOMETRY if form.geometry else KIND_CASTER
    return KIND_GENERAL


def load_codes(form) -> np.ndarray:
    """The kernel's load codes (L,) int64 of ``form`` (indices into :data:`wmrid.model.dynamics.LOAD_SIGNALS`)."""

    return np.array([LOAD_SIGNALS.index(x) for x in form.load], dtype=np.int64)


@dataclass
class KernelState:
    """The compiled observer's running state for one settings (what :func:`wmrid.estimators.observer.kernel.
    observer_chunk` carries from piece to piece): the kernel kind, caster geometry and load codes of the form, the
    gain k, the predictor/filter state st (9,), the filters w, g_prev (p,), theta (2, p), Gamma and its inverse
    (p, p).  Shared by the full-rate replay, its half-rate twin and the online observer."""

    form: Any
    kind: int
    geom: np.ndarray
    load: np.ndarray
    k: float
    st: np.ndarray
    w: np.ndarray
    g_prev: np.ndarray
    theta: np.ndarray
    gamma: np.ndarray
    gamma_inv: np.ndarray

    @classmethod
    def initial(cls, settings: ObserverSettings) -> KernelState:
        form = settings.form
        p = form.n_columns
        return cls(
            form=form, kind=kernel_kind(form), geom=np.array(form.geometry, dtype=np.float64),
            load=load_codes(form), k=float(settings.k), st=np.zeros(9), w=np.zeros(p), g_prev=np.zeros(p),
            theta=np.array(settings.theta_init, dtype=float), gamma=settings.alpha * np.eye(p),
            gamma_inv=np.eye(p) / settings.alpha,
        )  # fmt: skip

    def start(self, t: np.ndarray, eta: np.ndarray, tau: np.ndarray, eta_sign: np.ndarray) -> None:
        """Start the predictor and the filter at the first sample (t (k,), eta, tau, eta_sign (k, 2), k >= 1)."""
        self.st[:] = [t[0], eta[0, 0], eta[0, 1], eta[0, 0], eta[0, 1], 0.0, 0.0, 0.0, 0.0]
        self.g_prev[:] = filter_regressor(eta[:1], tau[:1], self.form, eta_sign[:1])[0]


class _HalfRate:
    """A second estimator run on every other sample (global indices 0, 2, 4, ...): the same log at twice the step.

    It makes the same assumption about the effort between samples as the full-rate run (held over each step
    of the log, linear, or held by a controller at --control-rate).

    The difference between the two final estimates is a Richardson estimate of the replay's discretisation
    error (:func:`wmrid.estimators.model_error.discretisation_error`).  It keeps only its own state: no history,
    one block.
    """

    def __init__(self, n: int, duration: float, settings: ObserverSettings) -> None:
        p = settings.form.n_columns
        self.n = (n + 1) // 2
        self.ks = KernelState.initial(settings)
        # An effort held over each step of the log is, at twice the step, an effort held by a controller at
        # the log's rate, the dropped sample interpolated (see ObserverSettings.control_rate): the same
        # assumption about the effort, so the two runs differ by their step only.  Whether the effort really
        # is held over a whole step of the log cannot be told from the log; --control-rate says when it is not.
        self.hold = settings.hold_code
        if self.hold == 0.0 and duration > 0:
            self.hold = (n - 1) / duration
        last = np.array([max(self.n - 1, 1)], dtype=np.int64)
        self.hist_idx, self.block_end = last, last.copy()
        self.hist_theta = np.empty((1, 2, p))
        self.hist_e = np.empty((1, 2))
        self.hist_gamma = np.empty((1, p, p))
        self.blk = (np.zeros((1, p, p)), np.zeros((1, 2, p)), np.zeros((1, 2)), np.zeros((1, 2)))
        self.cursor = np.zeros(2, dtype=np.int64)
        self.done = 0  # decimated samples consumed

    def feed(self, t: np.ndarray, eta: np.ndarray, tau: np.ndarray, eta_sign: np.ndarray, start: int) -> None:
        """Samples with global indices start .. start + len(t) - 1; only the even ones are used (their sign speeds
        are the full-rate run's: the same centred mean of the measured speeds)."""

        first = start % 2  # offset of the first even global index within this piece
        t, eta, tau, eta_sign = t[first::2], eta[first::2], tau[first::2], eta_sign[first::2]
        if len(t) == 0 or self.n < 2:
            return
        skip = 0
        ks = self.ks
        if self.done == 0:
            ks.start(t, eta, tau, eta_sign)
            skip = 1
        if len(t) > skip:
            observer_chunk(
                plain(t[skip:]), plain(eta[skip:]), plain(eta_sign[skip:]), plain(tau[skip:]),
                self.done + skip, ks.kind, self.hold, ks.k, ks.st, ks.w, ks.g_prev, ks.theta, ks.gamma, ks.gamma_inv,
                self.hist_idx, self.hist_theta, self.hist_e, self.hist_gamma, self.block_end, *self.blk,
                self.cursor, ks.geom, ks.load,
            )  # fmt: skip
        self.done += len(t)


def replay_pieces(
    pieces: Iterable[tuple[np.ndarray, np.ndarray, np.ndarray]],
    n: int,
    duration: float,
    settings: ObserverSettings,
    *,
    max_history: int = 20000,
    progress: Callable[[int], None] | None = None,
    half_rate: bool = False,
    low_speed: np.ndarray | None = None,
    noise_lag: int = 1,
    sign_half_window: int = 0,
) -> ReplayOutput:
    """Run the estimator over a log given as consecutive pieces (t (k,) s, eta (k, 2) rad/s, tau (k, 2)).

    n : the log's samples (the pieces must add up to it); duration : t_last - t_first, s.  Memory: one
    piece plus the history and block sums, whatever n.  ``progress(samples_done)`` after each piece.
    ``half_rate``: also run the estimator on every other sample (``ReplayOutput.theta_half``).
    ``low_speed`` (2,) rad/s: mark the blocks where |eta_i| < low_speed[i] for a wheel (``ReplayOutput.blk_slow``).
    ``noise_lag`` samples: the spacing of the noise floor's second differences (:class:`wmrid.estimators.noise_floor.
    NoiseFloor`; 1 for measured speeds, the derivative's window for speeds derived from positions).
    ``sign_half_window`` samples: the sign columns take the sign of a centred mean of the speeds over twice this
    plus one (:mod:`wmrid.estimators.sign_speed`; 0: of the measured speeds; not taken for the paper form, which has
    none); the pieces then reach the kernel that many samples late, the last ones when the pieces end.
    """

    p = settings.form.n_columns
    hist_idx, block_end = layout(n, duration, settings.k, max_history)
    m, nb = len(hist_idx), len(block_end)
    ks = KernelState.initial(settings)
    hist_theta = np.empty((m, 2, p))
    hist_e = np.empty((m, 2))
    hist_gamma = np.empty((m, p, p))
    hist_t = np.empty(m)
    block_t = np.empty(nb)
    blk_a = np.zeros((nb, p, p))
    blk_c = np.zeros((nb, 2, p))
    blk_uu = np.zeros((nb, 2))
    blk_ee = np.zeros((nb, 2))
    cursor = np.zeros(2, dtype=np.int64)
    hold = settings.hold_code
    half = _HalfRate(n, duration, settings) if half_rate and n >= 20 else None
    blk_slow = None if low_speed is None else np.zeros(nb, dtype=bool)
    floor = NoiseFloor(noise_lag)

    # The half-rate run goes on a second thread (its compiled kernel releases the GIL), one piece behind at most;
    # the pieces reach it in order, so its result does not depend on the timing.
    pool = None
    pending = None
    if half is not None and _SECOND_THREAD:
        pool = ThreadPoolExecutor(max_workers=1, thread_name_prefix="wmrid-half-rate")
    # the paper form has no sign column (each wheel keeps one sign): no speeds to average for one
    signs = SignSpeeds(0 if settings.form.kind == "paper" else sign_half_window)
    done = 0

    def advance(t: np.ndarray, eta: np.ndarray, tau: np.ndarray, es: np.ndarray) -> None:
        nonlocal done, pending
        k = len(t)
        if k == 0:
            return
        t = np.ascontiguousarray(t, dtype=np.float64)
        eta = np.ascontiguousarray(eta, dtype=np.float64)
        tau = np.ascontiguousarray(tau, dtype=np.float64)
        es = np.ascontiguousarray(es, dtype=np.float64)
        for idx, out in ((hist_idx, hist_t), (block_end, block_t)):
            lo, hi = np.searchsorted(idx, [done, done + k])
            out[lo:hi] = t[idx[lo:hi] - done]
        if half is not None and pool is None:
            half.feed(t, eta, tau, es, done)
        elif half is not None:  # on its thread, while this one runs the full-rate kernel on the same piece
            if pending is not None:
                pending.result()
            pending = pool.submit(half.feed, t, eta, tau, es, done)
        skip = 0
        if done == 0:  # the first sample starts the predictor and the filter
            ks.start(t, eta, tau, es)
            if hist_idx[0] == 0:
                hist_theta[0], hist_e[0], hist_gamma[0] = ks.theta, 0.0, ks.gamma
                cursor[0] = 1
            skip = 1
        observer_chunk(
            plain(t[skip:]), plain(eta[skip:]), plain(es[skip:]), plain(tau[skip:]), done + skip, ks.kind, hold, ks.k,
            ks.st, ks.w, ks.g_prev, ks.theta, ks.gamma, ks.gamma_inv, hist_idx, hist_theta, hist_e, hist_gamma,
            block_end, blk_a, blk_c, blk_uu, blk_ee, cursor, ks.geom, ks.load,
        )  # fmt: skip
        floor.feed(eta)
        if blk_slow is not None:
            slow = np.flatnonzero(np.any(np.abs(eta) < low_speed, axis=1))
            if len(slow):
                blk_slow[np.minimum(np.searchsorted(block_end, done + slow), nb - 1)] = True
        done += k
        if progress is not None:
            progress(done)

    try:
        for t, eta, tau in pieces:
            if len(t):
                advance(*signs.feed(t, eta, tau))
        advance(*signs.finish())
        if pending is not None:
            pending.result()
    finally:
        if pool is not None:
            pool.shutdown(wait=True)
    if done != n:
        raise ValueError(f"replay_pieces: the pieces hold {done} samples, not n = {n}")
    return ReplayOutput(
        theta=ks.theta, gamma=ks.gamma, gamma_inv=ks.gamma_inv, eta_hat=ks.st[3:5].copy(), hist_idx=hist_idx,
        hist_theta=hist_theta, hist_e=hist_e, hist_gamma=hist_gamma, block_end=block_end, blk_a=blk_a,
        blk_c=blk_c, blk_uu=blk_uu, blk_ee=blk_ee, hist_t=hist_t, block_t=block_t,
        theta_half=None if half is None else half.ks.theta.copy(), blk_slow=blk_slow, noise_sigma=floor.sigma(),
        eta_rms=floor.rms(),
    )  # fmt: skip
