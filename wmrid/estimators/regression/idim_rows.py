"""The IDIM regression: the inverse model's rows from zero-phase filtered speeds, accelerations and efforts, with the
filter's cutoff chosen from the log, decimation, and the effort's timing (:func:`idim_regression`).

Shared by IDIM (:mod:`wmrid.estimators.regression.idim`), IDIM-IV, RLS and the timing check."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from wmrid.core.choices import TorqueHold, values
from wmrid.core.errors import LogFormatError, NotIdentifiableError, UsageError, option
from wmrid.estimators.regression.idim_columns import raw_columns_into
from wmrid.estimators.regression.lowpass import butter_sos, filtfilt_extended, welch
from wmrid.model.dynamics import RegressorForm, caster_columns, invert_inertia_entries, platform_speeds
from wmrid.model.kernels import plain

#: Names of the IDIM parameters phi, in order (SI: kg m^2 for M and Vc, N m s/rad, N m).
PHI_NAMES = ("M11", "M12", "M22", "Vc", "Fv1", "Fv2", "Fd1", "Fd2")


#: Names of the filtered regression features, the columns of :attr:`IdimRegression.features`.
FEATURE_NAMES = ("a1", "a2", "c1", "c2", "eta1", "eta2", "sgn1", "sgn2")


#: Largest default cutoff (Hz) and the largest default cutoff as a fraction of the sample rate.
MAX_DEFAULT_CUTOFF_HZ = 10.0


DEFAULT_CUTOFF_FRACTION = 1.0 / 20.0


#: The default cutoff is this multiple of the velocities' bandwidth.
BANDWIDTH_FACTOR = 2.0


#: The velocities' bandwidth ends where their spectrum falls to this multiple of the noise floor.
BANDWIDTH_SNR = 10.0


#: The default cutoff keeps each end's dropped transient within this fraction of the log.
MAX_EDGE_FRACTION = 0.1


#: A cutoff below this (Hz) is flagged: the log rate or length leaves too little bandwidth.
LOW_CUTOFF_HZ = 1.0


#: Time stamps within this many mean steps of the uniform grid need no resampling.
UNEVEN_TOLERANCE = 1e-3


#: A step longer than this many mean steps is a hole.
MAX_STEP_RATIO = 5.0


#: Level to which the slowest filter pole must have decayed at the first kept sample.
EDGE_TOLERANCE = 1e-4


#: Decimation keeps the new Nyquist frequency at least this multiple of the cutoff.
DECIMATION_NYQUIST_FACTOR = 2.0


#: Fewest regression samples a fit accepts (after edges and decimation).
MIN_SAMPLES = 20


#: Which feature enters which row and column of the regressor: (row, phi column, feature index).
ROW_LAYOUT = (
    (0, 0, 0), (0, 1, 1), (0, 3, 2), (0, 4, 4), (0, 6, 6),
    (1, 1, 0), (1, 2, 1), (1, 3, 3), (1, 5, 5), (1, 7, 7),
)  # fmt: skip


@dataclass(frozen=True, eq=False)
class IdimRegression:
    """The filtered IDIM regression of a log: rows X phi = y, two per sample.

    t : (N,) s, times of the samples kept (after edges and decimation).
    features : (N, 8 + q) the filtered regressor columns, :data:`FEATURE_NAMES`: accelerations a_1, a_2
        (rad/s^2), Coriolis columns c_1 = eta_1 eta_2 - eta_2^2, c_2 = eta_1 eta_2 - eta_1^2 (rad^2/s^2),
        speeds eta_1, eta_2 (rad/s) and Coulomb columns sgn(eta_1), sgn(eta_2) (1); then the q caster
        columns of ``form`` (:attr:`feature_names`), none without caster drag.
    tau : (N, 2) N m, the filtered torques (the right-hand side y).
    cutoff_hz, order : the Butterworth low-pass; ``cutoff_rule`` says where the cutoff came from.
    rate_hz : sample rate of the (resampled) log; ``resampled``: whether it was interpolated onto it.
    decimation : k, every k-th filtered sample kept.  edge_seconds : dropped at each end.
    form : the caster-drag model (None: none); then ``features`` has the filtered caster columns
        (:func:`wmrid.model.dynamics.caster_columns`, in ``form.caster_map`` order) after the eight, and phi the caster
        parameters after the eight (:attr:`phi_names`).
    """

    t: np.ndarray
    features: np.ndarray
    tau: np.ndarray
    cutoff_hz: float
    order: int
    cutoff_rule: str
    rate_hz: float
    resampled: bool
    decimation: int
    edge_seconds: float
    form: RegressorForm | None = None
    #: (n, 2) N m: the filtered efforts on the whole uniform grid t_grid (n,) s, edges included, when asked for
    #: (``idim_regression(..., keep_effort=True)``): a shifted effort is this read at shifted times (the filter is
    #: time-invariant), which :func:`wmrid.estimators.delay.estimate_delay` uses instead of refiltering per candidate.
    effort_grid: np.ndarray | None = field(default=None, repr=False)
    t_grid: np.ndarray | None = field(default=None, repr=False)

    @property
    def caster_map(self) -> tuple[tuple[int, int, int], ...]:
        """(column, parameter, pattern) of each caster feature (``form.caster_map``), () without caster drag."""
        return _caster_map(self.form)

    @property
    def phi_names(self) -> tuple[str, ...]:
        """Names of phi: :data:`PHI_NAMES`, then the caster parameters (``form.base_names[8:]``)."""
        return phi_names(self.form)

    @property
    def feature_names(self) -> tuple[str, ...]:
        """Names of the columns of ``features``: :data:`FEATURE_NAMES`, then the caster columns."""
        if not self.caster_map:
            return FEATURE_NAMES
        assert self.form is not None
        return FEATURE_NAMES + tuple(name.lstrip("-") for name in self.form.column_names[8:])

    def rows(self, index: slice | np.ndarray = slice(None)) -> np.ndarray:
        """Regressor X (m, 2, p) of the selected samples: X[k, i] phi = tau[k, i] (p = 8 + caster parameters)."""
        return rows_from_features(self.features[index], self.caster_map)

    def scales(self) -> np.ndarray:
        """Physical scales (p,) of phi's regressor columns: :func:`phi_scales`, then :func:`caster_scales`."""
        base = phi_scales(self.features, self.cutoff_hz)
        return np.concatenate([base, caster_scales(self.form)]) if self.caster_map else base

    def info(self) -> dict[str, Any]:
        """The preprocessing choices, JSON-ready."""
        return {
            "cutoff_hz": float(self.cutoff_hz),
            "cutoff_rule": self.cutoff_rule,
            "filter": f"Butterworth order {self.order}, zero-phase (sosfiltfilt), parallel filtering",
            "rate_hz": float(self.rate_hz),
            "resampled": bool(self.resampled),
            "decimation": int(self.decimation),
            "edge_seconds": float(self.edge_seconds),
            "samples_used": len(self.t),
        }


def _caster_map(form: RegressorForm | None) -> tuple[tuple[int, int, int], ...]:
    return form.caster_map if form is not None and form.caster else ()


def phi_names(form: RegressorForm | None = None) -> tuple[str, ...]:
    """Names of phi for ``form``: :data:`PHI_NAMES`, then its caster parameters (none without caster drag)."""
    if not _caster_map(form):
        return PHI_NAMES
    assert form is not None
    return PHI_NAMES + tuple(form.base_names[8:])


def caster_scales(form: RegressorForm | None) -> np.ndarray:
    """Physical scales (q,) of the caster parameters' regressor columns: the most each can be per unit parameter.

    Two-term model: 1 (a sign, like the Coulomb columns).  Geometric model: D_k's entry in either wheel's row
    is a_k +/- c_k with |a_k| <= r/2 and |c_k| <= (r/(2b)) |(x_k, y_k)| (:func:`wmrid.model.dynamics.caster_columns`),
    so the scale is the sum of its columns' bounds (a load term's: its caster's, per unit of its signal).  Empty without
    caster drag.
    """
    cmap = _caster_map(form)
    if not cmap:
        return np.zeros(0)
    assert form is not None
    out = np.zeros(len(phi_names(form)) - 8)
    big_k = form.n_casters
    for _, param, pattern in cmap:
        if not form.geometry:
            bound = 1.0
        else:  # caster k = param - 8 (its load terms' k: see RegressorForm.caster_map): a_k pattern +1, c_k -1
            k = param - 8 if param < 8 + big_k else (param - 8 - big_k) // len(form.load)
            r, b = form.geometry[0], form.geometry[1]
            x, y = form.geometry[2 * k + 2], form.geometry[2 * k + 3]
            bound = 0.5 * r if pattern == 1 else r / (2.0 * b) * math.hypot(x, y)
        out[param - 8] += bound
    return out


def rows_from_features(features: np.ndarray, caster_map: tuple[tuple[int, int, int], ...] = ()) -> np.ndarray:
    """Regressor X (n, 2, p) for phi from features (n, 8 + q) ordered as :data:`FEATURE_NAMES`, then q caster
    columns mapped by ``caster_map`` (``RegressorForm.caster_map``: column j adds to phi[param] in row 1 and
    pattern x itself in row 2).  p = 8 + the caster parameters."""
    n_phi = 8 + len({param for _, param, _ in caster_map})
    x = np.zeros((features.shape[0], 2, n_phi))
    for row, col, feat in ROW_LAYOUT:
        x[:, row, col] = features[:, feat]
    for j, (_, param, pattern) in enumerate(caster_map):
        x[:, 0, param] += features[:, 8 + j]
        x[:, 1, param] += pattern * features[:, 8 + j]
    return x


def raw_features(eta: np.ndarray, eta_dot: np.ndarray, form: RegressorForm | None = None) -> np.ndarray:
    """Unfiltered features (n, 8 + q) (:data:`FEATURE_NAMES`, then ``form``'s q caster columns) from eta (n, 2)
    rad/s and eta_dot (n, 2) rad/s^2."""
    e1, e2 = eta[:, 0], eta[:, 1]
    cols = [eta_dot, e1 * e2 - e2 * e2, e1 * e2 - e1 * e1, eta, np.sign(eta)]
    if _caster_map(form):
        assert form is not None
        cols.append(caster_columns(eta, form, eta_dot))
    return np.column_stack(cols)


def regressor_rows(eta: np.ndarray, eta_dot: np.ndarray, form: RegressorForm | None = None) -> np.ndarray:
    """Exact (unfiltered) IDIM regressor X (n, 2, p): Eq. (9) (with ``form``'s caster drag) reads
    X[k] phi = tau[k], phi named by :func:`phi_names`."""
    return rows_from_features(raw_features(eta, eta_dot, form), _caster_map(form))


def cutoff_bounds(rate_hz: float, duration: float, order: int = 4) -> tuple[float, float]:
    """(f_lo, f_hi) Hz of the default cutoff for a log of ``duration`` s at ``rate_hz``.

    f_hi = min(:data:`MAX_DEFAULT_CUTOFF_HZ`, rate / 20); f_lo the cutoff whose :func:`edge_seconds` is
    :data:`MAX_EDGE_FRACTION` of the duration, at most f_hi.
    """
    f_hi = min(MAX_DEFAULT_CUTOFF_HZ, DEFAULT_CUTOFF_FRACTION * rate_hz)
    f_lo = edge_seconds(1.0, order) / (MAX_EDGE_FRACTION * max(duration, 1e-300))
    return min(f_lo, f_hi), f_hi


def velocity_bandwidth(eta: np.ndarray, rate_hz: float) -> float:
    """f_s (Hz): the highest frequency where a wheel speed's spectrum exceeds BANDWIDTH_SNR x its noise floor.

    eta (n, 2) rad/s on a uniform grid at ``rate_hz``.  Welch's estimate with a Blackman-Harris window
    (sidelobes below -92 dB, so strong slow components do not leak far), linear detrending, segments of
    at most 8 s and at least 4 of them (averaging makes a noise bin 10 times above the floor improbable:
    with 8 dof its chance is below 1e-12); the floor is the median spectrum above rate / 4.  The Nyquist
    frequency when the floor is 0 (a noise-free log).
    """
    n = len(eta)
    nper = 2 ** max(3, math.floor(math.log2(max(8, min(n / 4.0, 8.0 * rate_hz)))))
    nper = min(nper, n)
    freq, psd = welch(eta, rate_hz, nper)
    top = 0.0
    for j in range(eta.shape[1]):
        floor = float(np.median(psd[freq >= rate_hz / 4.0, j]))
        above = np.flatnonzero(psd[:, j] > BANDWIDTH_SNR * floor)
        if len(above):
            top = max(top, float(freq[above[-1]]))
    return top


def default_cutoff(eta: np.ndarray, rate_hz: float, order: int = 4) -> float:
    """The default low-pass cutoff (Hz): BANDWIDTH_FACTOR x :func:`velocity_bandwidth`, within :func:`cutoff_bounds`.

    eta (n, 2) rad/s on a uniform grid at ``rate_hz``.  See the module docstring for the reasons.
    """
    f_lo, f_hi = cutoff_bounds(rate_hz, (len(eta) - 1) / rate_hz, order)
    return float(np.clip(BANDWIDTH_FACTOR * velocity_bandwidth(eta, rate_hz), f_lo, f_hi))


def edge_seconds(cutoff_hz: float, order: int) -> float:
    """Seconds at each end of a log where the zero-phase filter's transient lives.

    The slowest pole of a Butterworth low-pass of ``order`` at ``cutoff_hz`` decays at
    sigma = 2 pi f_c sin(pi / (2 order)) 1/s; the transient is below :data:`EDGE_TOLERANCE` after
    ln(1 / EDGE_TOLERANCE) / sigma.
    """
    sigma = 2.0 * math.pi * cutoff_hz * math.sin(math.pi / (2 * order))
    return math.log(1.0 / EDGE_TOLERANCE) / sigma


def decimation_factor(rate_hz: float, cutoff_hz: float) -> int:
    """k = floor(rate / (2 DECIMATION_NYQUIST_FACTOR f_c)), at least 1: the new Nyquist is >= 2 f_c."""
    return max(1, math.floor(rate_hz / (2.0 * DECIMATION_NYQUIST_FACTOR * cutoff_hz) + 1e-9))


def _check_arrays(t: np.ndarray, eta: np.ndarray, tau: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    t = np.asarray(t, dtype=np.float64)
    eta = np.asarray(eta, dtype=np.float64)
    tau = np.asarray(tau, dtype=np.float64)
    n = t.shape[0] if t.ndim == 1 else -1
    if t.ndim != 1 or eta.shape != (n, 2) or tau.shape != (n, 2):
        raise UsageError(f"expected t (n,), eta (n, 2), tau (n, 2); got {t.shape}, {eta.shape}, {tau.shape}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(eta)) and np.all(np.isfinite(tau))):
        raise LogFormatError("the log holds non-finite values (NaN or inf) in t, eta or tau")
    if n < 2 or np.any(np.diff(t) <= 0):
        raise LogFormatError("the time stamps must be strictly increasing (and at least 2 samples)")
    return t, eta, tau


def _five_point_derivative(x: np.ndarray, dt: float, rows: np.ndarray) -> np.ndarray:
    """d x / d t (m, c) at ``rows`` (m,) of x (n, c) on a uniform grid: 5-point central differences, second-order ones
    at the ends (computed at the rows asked for only: the values are those of the whole derivative)."""
    if len(x) >= 5 and (len(rows) == 0 or (rows.min() >= 2 and rows.max() < len(x) - 2)):
        return (x[rows - 2] - 8.0 * x[rows - 1] + 8.0 * x[rows + 1] - x[rows + 2]) / (12.0 * dt)
    d = np.gradient(x, dt, axis=0, edge_order=2) if len(x) >= 3 else np.zeros_like(x)
    if len(x) >= 5:
        d[2:-2] = (x[:-4] - 8.0 * x[1:-3] + 8.0 * x[3:-1] - x[4:]) / (12.0 * dt)
    return d[rows]


def idim_regression(
    t: np.ndarray,
    eta: np.ndarray,
    tau: np.ndarray,
    cutoff_hz: float | None = None,
    decimate: bool = True,
    *,
    order: int = 4,
    form: RegressorForm | None = None,
    effort_delay: float = 0.0,
    keep_effort: bool = False,
) -> IdimRegression:
    """Preprocess a log into the filtered IDIM regression (see the module docstring for every choice).

    t : (n,) s strictly increasing (uneven steps are resampled); eta : (n, 2) rad/s [right, left];
    tau : (n, 2) N m.  cutoff_hz : low-pass cutoff, default :func:`default_cutoff`; must be below the
    Nyquist frequency.  decimate : keep every :func:`decimation_factor`-th sample.  order : Butterworth order.
    form : with caster drag (``form.caster``), the caster columns are filtered alongside and appended.
    effort_delay : s, how far the effort acting on the robot lags its samples (:func:`effort_delay`, plus any
    timing fault; negative: it leads them): the efforts are read that much earlier (:func:`shifted`) before
    filtering.  keep_effort : also keep the filtered efforts on the whole grid (:attr:`IdimRegression.effort_grid`).
    Raises UsageError for bad arguments, LogFormatError for unusable time stamps, NotIdentifiableError
    when the log is too short for the filter.
    """
    t, eta, tau = _check_arrays(t, eta, tau)
    if isinstance(order, bool) or not isinstance(order, (int, np.integer)) or not 1 <= order <= 12:
        raise UsageError(f"filter order must be a whole number in 1..12, got {order!r}")
    n = len(t)
    steps = np.diff(t)
    dt = (t[-1] - t[0]) / (n - 1)
    if steps.max() > MAX_STEP_RATIO * dt:
        k = int(np.argmax(steps))
        raise LogFormatError(
            f"the log has a hole: time jumps by {steps[k]:.6g} s after t = {t[k]:.6g} s (mean step {dt:.3g} s), "
            "which filtering cannot bridge; cut the log into its continuous parts"
        )
    grid = t[0] + dt * np.arange(n)
    grid[-1] = t[-1]
    resampled = bool(np.max(np.abs(t - grid)) > UNEVEN_TOLERANCE * dt)
    if resampled:
        eta = np.column_stack([np.interp(grid, t, eta[:, j]) for j in range(2)])
        tau = np.column_stack([np.interp(grid, t, tau[:, j]) for j in range(2)])
        t = grid
    rate = 1.0 / dt
    if not (math.isfinite(effort_delay) and abs(effort_delay) <= MAX_EFFORT_SHIFT_S):
        raise UsageError(f"effort delay {effort_delay!r} s must be within +/-{MAX_EFFORT_SHIFT_S:g} s")
    if effort_delay != 0:
        tau = shifted(t, tau, effort_delay)
    if cutoff_hz is None:
        band = velocity_bandwidth(eta, rate)
        f_lo, f_hi = cutoff_bounds(rate, t[-1] - t[0], order)
        cutoff = float(np.clip(BANDWIDTH_FACTOR * band, f_lo, f_hi))
        rule = (
            f"default: {BANDWIDTH_FACTOR:g} x the speeds' bandwidth {band:.3g} Hz, within [{f_lo:.3g}, {f_hi:.3g}] Hz"
        )
    else:
        cutoff = float(cutoff_hz)
        rule = "given"
        if not math.isfinite(cutoff) or not 0.0 < cutoff < 0.5 * rate:
            raise UsageError(f"cutoff {cutoff_hz!r} Hz must be > 0 and below the Nyquist frequency {0.5 * rate:g} Hz")
    edge_s = edge_seconds(cutoff, order)
    edge = math.ceil(edge_s * rate)
    k = decimation_factor(rate, cutoff) if decimate else 1
    keep = np.arange(edge, n - edge, k)
    if len(keep) < MIN_SAMPLES:
        raise NotIdentifiableError(
            f"the log is too short for IDIM: {n} samples ({t[-1] - t[0]:.3g} s) leave {len(keep)} after dropping "
            f"{edge_s:.3g} s of filter transient at each end (cutoff {cutoff:g} Hz); it needs at least {MIN_SAMPLES}"
        )

    sos = butter_sos(order, cutoff, rate)
    pad = min(edge, n - 1)
    form = form if _caster_map(form) else None
    caster_raw = caster_columns(eta, form, multiplier=True) if form is not None else np.empty((n, 0))
    ext = np.empty((n + 2 * pad, 8 + caster_raw.shape[1]))  # the columns side by side, room for the odd extension
    raw_columns_into(plain(eta), plain(tau), ext[pad : pad + n])
    ext[pad : pad + n, 8:] = caster_raw  # from the unfiltered speeds like sgn(eta_i), filtered like every column
    del caster_raw
    filt = filtfilt_extended(sos, ext, pad)  # (n, 8 + q)
    acc = _five_point_derivative(filt[:, 0:2], dt, keep)
    kept = filt[keep]
    features = np.column_stack([acc, kept[:, [2, 3, 0, 1, 4, 5]]])
    if form is not None:
        caster = kept[:, 8:]
        if form.derivative_columns:  # c(eta) phi': the filtered multiplier c times phi' of the filtered speeds
            rates = platform_speeds(acc, form.geometry[0], form.geometry[1])
            for col, which in form.derivative_columns:
                caster[:, col - 8] *= rates[which]
        features = np.column_stack([features, caster])
    kept_effort = {"effort_grid": filt[:, 6:8].copy(), "t_grid": t.copy()} if keep_effort else {}
    return IdimRegression(
        t=t[keep], features=features, tau=kept[:, 6:8], cutoff_hz=cutoff, order=int(order),
        cutoff_rule=rule, rate_hz=rate, resampled=resampled, decimation=k, edge_seconds=edge_s, form=form,
        **kept_effort,
    )  # fmt: skip


#: The largest effort shift (s) idim_regression applies: a timing fault, not a different log.
MAX_EFFORT_SHIFT_S = 1.0


def shifted(t: np.ndarray, x: np.ndarray, delay: float) -> np.ndarray:
    """x (n, k) read ``delay`` s earlier, x(t - delay), by linear interpolation between its samples at t (n,) s
    (held at the first and last sample beyond the log's ends)."""
    x = np.asarray(x, dtype=np.float64)
    return np.column_stack([np.interp(t - delay, t, x[:, j]) for j in range(x.shape[1])])


def effort_delay(t: np.ndarray, torque_hold: str = "zoh", control_rate: float | None = None) -> float:
    """How far (s) the effort acting on the robot lags its logged samples, for IDIM's regression.

    A controller holds each effort until its next update (zero-order hold).  The staircase it applies is, within
    the filter's band, the effort delayed by half a hold period, and IDIM pairs the effort with the speeds'
    derivative at the sample time.  Left out, that half step biased the friction identified on multibody logs by
    -0.5 to -9 % (reversing at 1 kHz, noise-free; the inertia by 0.01 %); read half a step earlier, +0.2 to +1.6 %,
    as the observer, which models the hold (:class:`wmrid.estimators.observer.settings.ObserverSettings`).
    ``torque_hold``: "zoh"
    (held over each logged step: half the median step t (n,) s), "foh" (linear between samples: 0);
    ``control_rate`` Hz: held by a controller at that rate (half its period), whatever the log's rate.
    """
    if torque_hold not in values(TorqueHold):
        raise UsageError(f"{option('torque_hold')} must be zoh or foh, got {torque_hold!r}")
    if control_rate is not None:
        return 0.5 / float(control_rate)
    if torque_hold == "foh" or len(t) < 2:
        return 0.0
    return 0.5 * float(np.median(np.diff(np.asarray(t, dtype=np.float64))))


def phi_scales(features: np.ndarray, cutoff_hz: float) -> np.ndarray:
    """Physical column scales (8,) of phi's regressor columns, to judge excitation in a unit-free way.

    With s the rms filtered wheel speed (rad/s): accelerations s 2 pi f_c (the most a signal of that size
    carries through the filter), Coriolis s^2, speeds s, Coulomb 1.  A column much smaller than its scale
    (a constant speed's numerically-zero acceleration) then counts as unexcited, as it should.
    """
    s = float(np.sqrt(np.mean(features[:, 4:6] ** 2)))
    s = s if s > 0 else 1.0
    acc = s * 2.0 * math.pi * cutoff_hz
    return np.array([acc, acc, acc, s * s, s, s, 1.0, 1.0])


#: theta0 from IDIM's phi (the inertia entries inverted).
phi_to_theta0 = invert_inertia_entries


def segment_factors(
    rows: np.ndarray, tau: np.ndarray, weights: np.ndarray, seg: np.ndarray, g: int, keep: np.ndarray | None = None
) -> list[np.ndarray]:
    """Triangular factors R_g (p + 1, p + 1) of [X y] per segment (see
    :func:`wmrid.estimators.regression.idim.jackknife_from_factors`).

    rows (N, 2, p), tau (N, 2), weights (2,) per wheel, seg (N,) in [0, g); keep (N,) bool: rows used.
    """
    p = rows.shape[2]
    out = []
    for i in range(g):
        sel = seg == i
        if keep is not None:
            sel &= keep
        x = rows[sel] * weights[None, :, None]
        y = tau[sel] * weights[None, :]
        out.append(qr_r(np.column_stack([x.reshape(-1, p), y.reshape(-1)])))
    return out


def qr_r(a: np.ndarray) -> np.ndarray:
    """R (c, c) of the QR factorisation of a (m, c), zero-padded when m < c."""
    r = np.linalg.qr(a, mode="r")
    if r.shape[0] < a.shape[1]:
        r = np.vstack([r, np.zeros((a.shape[1] - r.shape[0], a.shape[1]))])
    return r


def solve_r(r: np.ndarray) -> np.ndarray:
    """phi (p,) from the stacked triangular factors (.., p + 1) of [X y]."""
    from scipy.linalg import solve_triangular  # start-up time: scipy.linalg only when IDIM runs

    p = r.shape[1] - 1
    big = qr_r(r)
    return solve_triangular(big[:p, :p], big[:p, p])
