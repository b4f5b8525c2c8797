"""Changes across a robot's logs, and robots that stand out from their fleet: the statistics of ``wmrid fleet-report``.

Each robot's estimates over its logs (one value per log, in time order) are compared with its own baseline, the
first ``baseline`` logs: ``z_t = (x_t - mean) / s`` with the baseline's mean and standard deviation ``s`` (never less
than the median of those logs' own standard errors).  A change starting at log ``tau`` is tested at every log ``n``
with two alternatives over the logs ``tau..n``, both two-sided:

* a step (payload, configuration): ``S = (sum z_t)^2 / L``, L = n - tau + 1;
* a ramp (wear): ``R = (sum w_t z_t)^2 / sum w_t^2``, w_t = t - tau + 1;

and the robot's evidence at log n is the largest of them over the onsets ``tau`` within ``window`` logs and over its
:data:`MONITORED` parameters.  The first log where it passes the threshold ``h`` is the alarm, the onset ``tau`` that
maximised it the change's start.  ``h`` makes the probability that a robot whose parameters never change is flagged
anywhere in its history ``alpha`` (the stated false-alarm rate), for Gaussian log-to-log scatter independent between
logs and parameters; :func:`threshold` calibrates it by Monte Carlo (seeded), with the studentisation by a baseline of
``baseline`` logs inside.  Parameters correlated with each other make the real rate lower, heavier tails than
Gaussian make it higher: the report says so.

An alarm the following logs do not confirm (their mean back within 3 baseline std of the baseline while the alarm
log was beyond) is an odd log, listed but not a change; the scan then goes on without it.

Robots that stand out: each robot's baseline mean of each parameter against the other robots of the same model
(:func:`leave_one_out_t`), at a Bonferroni threshold (:func:`outlier_threshold`).
"""

from __future__ import annotations

import math
import warnings
from dataclasses import dataclass, field
from functools import lru_cache

import numpy as np

#: The parameters watched across logs: the inertia matrix M (what a payload changes), the Coriolis coefficient V_c
#: (a payload's x offset) and each wheel's viscous and Coulomb friction (what wear changes).
MONITORED = ("M11", "M12", "M22", "Vc", "Fv1", "Fv2", "Fd1", "Fd2")
#: Each wheel's friction torque at the robot's typical speed of that wheel, Fw = Fd + omega Fv (N m): watched besides
#: Fv and Fd when the table has the logs' speeds (:func:`friction_at`).
WHEEL_FRICTION = ("Fw1", "Fw2")
FRICTION = ("Fv1", "Fv2", "Fd1", "Fd2", *WHEEL_FRICTION)
WHEEL_OF = {"Fv1": "right", "Fd1": "right", "Fw1": "right", "Fv2": "left", "Fd2": "left", "Fw2": "left"}

#: Logs before the first that can be tested (a baseline needs a spread).
MIN_BASELINE = 5
#: Draws of the Monte Carlo calibration at its reference rate :data:`CALIBRATION_ALPHA`.
CALIBRATION_DRAWS = 4000
CALIBRATION_ALPHA = 0.05
CALIBRATION_SEED = 20150622
#: Monitored logs the calibration simulates at most; longer histories scale the number of chances linearly.
CALIBRATION_MAX_LOGS = 60
#: A change is flagged only when its fitted size also exceeds this many of the logs' own standard errors (the median
#: over the first ``baseline`` logs): significant against the log-to-log scatter and larger than one log can tell.
MIN_EFFECT_STDS = 2.0
#: Logs after an alarm that confirm (or not) a change.
CONFIRM_LOGS = 3


# ----------------------------------------------------------------------------------------------------------------
# The scan statistics


def scan(x: np.ndarray, window: int, first: int = 5):
    """Step and ramp F statistics of series ``x`` (..., T) at every end log n.

    For each end n and onset tau (first <= tau <= n, n - tau < window) the logs 0..n are fitted by least squares
    with a constant plus a step (1 from tau on) or a ramp (t - tau + 1 from tau on); the F statistic of the added
    term is ESS / (RSS / (n - 1)).  Returns (stat (..., T): the largest over onsets and both alternatives at each
    end, 0 before ``first``; onset (..., T) int: its tau; ramp (..., T) bool: whether the ramp gave it; effect
    (..., T): the fitted change at log n, in x's units: the step's height, or the ramp's rise over its L logs)."""
    x = np.asarray(x, dtype=float)
    total = x.shape[-1]
    head = x[..., : max(first, 1)]
    centre = head.mean(axis=-1, keepdims=True)
    scale = np.maximum(np.abs(x - centre).max(axis=-1, keepdims=True), 1e-300)
    u = (x - centre) / scale  # the F statistic is invariant to this; sums stay well conditioned
    zeros = np.zeros((*x.shape[:-1], 1))
    idx = np.arange(total, dtype=float)
    c0 = np.concatenate([zeros, np.cumsum(u, axis=-1)], axis=-1)
    c1 = np.concatenate([zeros, np.cumsum(u * idx, axis=-1)], axis=-1)
    c2 = np.concatenate([zeros, np.cumsum(u * u, axis=-1)], axis=-1)
    best = np.zeros(x.shape)
    onset = np.zeros(x.shape, dtype=np.int64)
    ramp = np.zeros(x.shape, dtype=bool)
    effect = np.zeros(x.shape)
    ends = np.arange(total)
    for lag in range(min(window, total)):  # L = lag + 1 logs from tau = end - lag
        e = ends[first + lag :]
        if e.size == 0:
            break
        tau = e - lag
        length = lag + 1
        count = e + 1.0
        sx = c0[..., e + 1]
        tss = c2[..., e + 1] - sx * sx / count
        s0 = sx - c0[..., tau]
        s1 = (c1[..., e + 1] - c1[..., tau]) - (tau - 1.0) * s0
        stats, effects = [], []
        for sgx, sg, sgg, rise in (
            (s0, float(length), float(length), 1.0),
            (s1, length * (length + 1) / 2.0, length * (length + 1) * (2 * length + 1) / 6.0, float(length)),
        ):
            denom = sgg - sg * sg / count
            cov = sgx - sg * sx / count
            ess = cov * cov / denom
            var = np.maximum(tss - ess, 0.0) / (count - 2.0)
            with np.errstate(divide="ignore", invalid="ignore"):
                stats.append(np.where(var > 0, ess / var, np.where(ess > 0, np.inf, 0.0)))
            effects.append(cov / denom * rise * scale)
        step, rmp = stats
        stat = np.maximum(step, rmp)
        better = stat > best[..., e]
        best[..., e] = np.where(better, stat, best[..., e])
        onset[..., e] = np.where(better, tau, onset[..., e])
        ramp[..., e] = np.where(better, rmp > step, ramp[..., e])
        effect[..., e] = np.where(better, np.where(rmp > step, effects[1], effects[0]), effect[..., e])
    return best, onset, ramp, effect


@lru_cache(maxsize=64)
def _null_maxima(total: int, first: int, window: int, params: int) -> np.ndarray:
    """Sorted maxima over a robot's history of the scan statistic under no change (Gaussian), one per draw."""
    rng = np.random.Generator(np.random.PCG64(CALIBRATION_SEED + 7919 * total + 104729 * first + window))
    out = np.empty(CALIBRATION_DRAWS)
    chunk = 500
    for start in range(0, CALIBRATION_DRAWS, chunk):
        k = min(chunk, CALIBRATION_DRAWS - start)
        stat = scan(rng.standard_normal((k, params, total)), window, first)[0]
        out[start : start + k] = stat.max(axis=(1, 2))
    return np.sort(out)


def _tail(h: np.ndarray | float, dof: float) -> np.ndarray:
    """P(F(1, dof) > h): the tail of one F statistic."""
    from scipy.stats import f  # scipy.stats (~0.6 s): only a fleet review

    return f.sf(h, 1, dof)


@lru_cache(maxsize=256)
def threshold(alpha: float, total: int, first: int, window: int, params: int = len(MONITORED)) -> float:
    """The alarm threshold h for a robot with ``total`` logs scanned from log ``first`` on: the probability that
    the scan statistic passes h anywhere in the history of a robot without change is ``alpha``.

    Calibrated by Monte Carlo (:data:`CALIBRATION_DRAWS` seeded draws of Gaussian logs) at
    :data:`CALIBRATION_ALPHA`, which gives the effective number of independent chances K = alpha_ref / P(F(1, d) >
    h_ref), d = total - 2; a smaller alpha solves K P(F(1, d) > h) = alpha (the tail of a maximum of K F
    statistics).  A history longer than :data:`CALIBRATION_MAX_LOGS` logs has proportionally more chances."""
    from scipy.optimize import brentq  # scipy.optimize (~0.3 s): only a fleet review

    if not 0 < alpha < 1:
        raise ValueError(f"alpha must be in (0, 1), got {alpha}")
    # at least two windows of scanned logs are simulated, whatever the baseline (a baseline of 55 left 5 of 60)
    n_cal = min(total, max(CALIBRATION_MAX_LOGS, first + 2 * window))
    maxima = _null_maxima(n_cal, first, min(window, n_cal), params)
    if alpha >= CALIBRATION_ALPHA and total <= CALIBRATION_MAX_LOGS:
        return float(np.quantile(maxima, 1 - alpha))
    dof = first - 1.0  # the fewest residual degrees of freedom (the first end, n = first) set the tail
    h_ref = float(np.quantile(maxima, 1 - CALIBRATION_ALPHA))
    chances = CALIBRATION_ALPHA / float(_tail(h_ref, dof)) * max(1.0, (total - first) / (n_cal - first))
    return float(brentq(lambda h: chances * _tail(h, dof) - alpha, 1e-6, 1e9, xtol=1e-9))


#: The ramp length (logs) the sensitivity statement uses: wear reaching its size over this many logs.
SENSITIVITY_RAMP_LOGS = 10


@lru_cache(maxsize=256)
def detectable(h: float, baseline: int, length: int, kind: str) -> float:
    """The size of a change, in units of the log-to-log standard deviation, that the scan flags at least half the
    time by the time it has lasted ``length`` logs after ``baseline`` unchanged logs: a step of that height
    (``kind`` "step"), or a ramp that has risen by that much over its ``length`` logs ("ramp").

    At the end log n = baseline + length - 1 with the onset at ``baseline``, the statistic of that alternative is
    noncentral F(1, n - 1) with noncentrality (effect / rise)^2 (S_gg - S_g^2 / (n + 1)) in the units of the scatter,
    S_g and S_gg the sums of the alternative's regressor and of its square (:func:`scan`); the effect whose F has
    median h is returned.  The scan also tries the other onsets, ends and the other alternative, so the chance of a
    flag is at least one half (``tests/unit/fleets/test_fleet_changes.py`` measures it by Monte Carlo)."""
    from scipy.optimize import brentq  # scipy.optimize (~0.3 s): only a fleet review
    from scipy.stats import ncf  # scipy.stats (~0.6 s): only a fleet review

    if length < 1 or baseline < 2:
        raise ValueError("detectable: length >= 1 and baseline >= 2 logs")
    count = float(baseline + length)
    g = np.ones(length) if kind == "step" else np.arange(1.0, length + 1.0)
    denom = float(g @ g - g.sum() ** 2 / count)
    rise = 1.0 if kind == "step" else float(length)
    dof = count - 2.0
    lam = brentq(lambda nc: float(ncf.median(1, dof, nc)) - h, 1e-9, 1e7, xtol=1e-10)
    return rise * math.sqrt(lam / denom)


def friction_at(
    omega: float, fv: np.ndarray, fd: np.ndarray, fv_std: np.ndarray, fd_std: np.ndarray, corr: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """A wheel's friction torque at speed ``omega`` (rad/s), Fw = Fd + omega Fv (N m), for each log (arrays (T,)),
    and its standard error from the two estimates' standard errors and their correlation ``corr`` (NaN where a log
    does not give it).

    A log determines Fv and Fd badly apart (their estimates correlate at -0.9 to -0.99 when the wheel's speed keeps
    away from zero: a higher Fv with a lower Fd fits almost as well) and their sum at the log's mean speed well: in
    linear regression the prediction at the regressor's mean is the best determined.  On the multibody prototype's
    logs Fv and Fd scatter by 3-29 % from log to log and Fw by 0.7-1.7 % (docs/how-to/fleet-dask.md)."""
    var = fd_std**2 + (omega * fv_std) ** 2 + 2.0 * omega * corr * fv_std * fd_std
    return fd + omega * fv, np.sqrt(np.clip(var, 0.0, None))


# ----------------------------------------------------------------------------------------------------------------
# One robot's history


@dataclass
class Change:
    """A change found in one robot's history.

    parameters : the parameters whose statistic passed the threshold at the alarm or later, the strongest first.
    onset / alarm : indices (into the robot's logs) of the change's first log and of the log where it was first
    flagged.  kind : "step" or "ramp".  evidence : the largest statistic over the threshold (> 1).  before :
    {parameter: mean of the logs before the onset}.  after : {parameter: mean of the last :data:`CONFIRM_LOGS` logs
    (a step: of all logs from the onset)}.  rate_per_day : {parameter: slope from the onset on, relative to
    ``before`` per day} (a ramp).  confirmed : the logs after the alarm agree (None: the alarm is on the robot's
    latest log)."""

    parameters: list[str]
    onset: int
    alarm: int
    kind: str
    evidence: float
    before: dict[str, float]
    after: dict[str, float]
    rate_per_day: dict[str, float]
    confirmed: bool | None

    def relative(self, name: str) -> float:
        """(after - before) / |before| of one parameter (inf when before is 0)."""
        b = self.before[name]
        return (self.after[name] - b) / abs(b) if b != 0 else math.inf


@dataclass
class RobotHistory:
    """One robot's analysis: the threshold h, the change (at most one: the first; the robot's history after it is a
    new baseline), odd logs (indices), the largest statistic / h seen (``evidence``: > 1 flags), and a note when the
    robot has too few logs to test."""

    logs: int
    threshold: float
    changes: list[Change] = field(default_factory=list)
    odd_logs: list[int] = field(default_factory=list)
    evidence: float = 0.0
    note: str | None = None


def _kind(x: np.ndarray, tau: int) -> str:
    """ "ramp" or "step": which of the two fits the whole series x (k, n) better from onset ``tau`` on (summed over its
    k parameters; a tie is a step)."""
    n = x.shape[1]
    t = np.arange(n)
    rss = []
    for g in ((t >= tau).astype(float), np.where(t >= tau, t - tau + 1.0, 0.0)):
        design = np.column_stack([np.ones(n), g])
        coef, *_ = np.linalg.lstsq(design, x.T, rcond=None)
        rss.append(float(((x.T - design @ coef) ** 2 / np.maximum(x.var(axis=1), 1e-300)).sum()))
    return "ramp" if rss[1] < rss[0] * (1 - 1e-9) else "step"


def analyse_robot(
    values: np.ndarray,
    stds: np.ndarray,
    days: np.ndarray | None = None,
    *,
    names: tuple[str, ...] = MONITORED,
    baseline: int = 10,
    window: int = 30,
    alpha: float = 0.001,
    unfloored: tuple[str, ...] = (),
) -> RobotHistory:
    """Changes in one robot's logs: ``values`` and ``stds`` (T, P) in time order, columns ``names``, finite (pass only
    usable logs); ``days`` (T,) their times in days (for rates; default the log index).

    Logs from ``baseline`` on are scanned (:func:`scan`, module docstring) at the threshold of false-alarm
    probability ``alpha`` over the robot's history (:func:`threshold`); a change also has to exceed
    :data:`MIN_EFFECT_STDS` times the median of the first logs' own standard errors (which only removes alarms: the
    rate stays at most ``alpha``), except for the parameters ``unfloored``: those whose standard error holds an
    error common to all the robot's logs (the model error of :data:`WHEEL_FRICTION`), which a change between logs
    does not have to beat."""
    values = np.asarray(values, dtype=float)
    stds = np.asarray(stds, dtype=float)
    total = values.shape[0]
    days = np.arange(total, dtype=float) if days is None else np.asarray(days, dtype=float)
    if baseline < MIN_BASELINE:
        raise ValueError(f"baseline must be >= {MIN_BASELINE} logs, got {baseline}")
    if total < baseline + 1:
        return RobotHistory(total, math.inf, note=f"{total} logs: too few to test for changes (the baseline is the "
                            f"first {baseline} logs)")  # fmt: skip
    known = np.where(np.isfinite(stds[:baseline]), stds[:baseline], np.nan)
    with np.errstate(all="ignore"), warnings.catch_warnings():
        warnings.simplefilter("ignore", RuntimeWarning)  # a parameter no log gave a std for: no floor
        floor = np.nanmedian(known, axis=0)
    floor = np.where(np.isfinite(floor), floor, 0.0)
    floor = np.where([n in unfloored for n in names], 0.0, floor)
    h = threshold(alpha, total, baseline, window, len(names))
    hist = RobotHistory(total, h)
    keep = np.ones(total, dtype=bool)  # odd logs are dropped from the scan
    while True:
        idx = np.flatnonzero(keep)
        x = values[idx].T  # (P, n)
        first = int(np.searchsorted(idx, baseline))
        stat, onset, _, effect = scan(x, window, first)
        # a change must also exceed each log's own uncertainty: twice the median std of the first logs
        stat = np.where(np.abs(effect) > MIN_EFFECT_STDS * floor[:, None], stat, 0.0)
        overall = stat.max(axis=0)
        hist.evidence = max(hist.evidence, float(overall.max() / h))
        over = np.flatnonzero(overall > h)
        if over.size == 0:
            return hist
        a = int(over[0])
        p_best = int(np.argmax(stat[:, a]))
        tau = int(onset[p_best, a])
        pre = x[:, :tau]
        mean, sd = pre.mean(axis=1), np.maximum(pre.std(axis=1, ddof=1), floor)
        later = np.arange(a + 1, min(a + 1 + CONFIRM_LOGS, x.shape[1]))
        alarm_z = (x[:, a] - mean) / sd
        if tau == a and later.size:  # one log alone: do the next ones agree?
            back = np.abs((x[:, later].mean(axis=1) - mean) / sd) < 3.0
            beyond = np.abs(alarm_z) > 3.0
            if np.any(beyond) and np.all(back[beyond]):
                hist.odd_logs.append(int(idx[a]))
                keep[idx[a]] = False
                continue
        # the parameters that pass at the alarm or at any later log (a slower one joins as the change grows)
        later_max = stat[:, a:].max(axis=1)
        passed = [int(p) for p in np.argsort(-later_max) if later_max[p] > h]
        kind = _kind(x[passed], tau)
        seg = x[:, tau:]
        after = seg[:, -CONFIRM_LOGS:].mean(axis=1) if kind == "ramp" else seg.mean(axis=1)
        rate = np.zeros(len(names))
        t_seg = days[idx[tau:]]
        if seg.shape[1] >= 2 and np.ptp(t_seg) > 0:
            slope = np.polyfit(t_seg, seg.T, 1)[0]
            rate = np.where(mean != 0, slope / np.abs(np.where(mean != 0, mean, 1.0)), np.inf)
        confirmed = None
        if later.size:
            sign = np.sign(alarm_z[passed])
            confirmed = bool(np.all(np.sign(((x[:, later].mean(axis=1) - mean) / sd)[passed]) == sign))
        hist.changes.append(Change(
            [names[p] for p in passed], int(idx[tau]), int(idx[a]), kind, float(stat[p_best, a] / h),
            dict(zip(names, mean.tolist(), strict=True)), dict(zip(names, after.tolist(), strict=True)),
            dict(zip(names, rate.tolist(), strict=True)), confirmed,
        ))  # fmt: skip
        return hist


# ----------------------------------------------------------------------------------------------------------------
# The fleet


def leave_one_out_t(levels: np.ndarray) -> np.ndarray:
    """t (N, P): each robot's level against the mean and standard deviation of the other N - 1 robots, per
    parameter: (x_i - mean_others) / (sd_others sqrt(1 + 1/(N - 1))), Student's t with N - 2 degrees of freedom for
    Gaussian unit-to-unit spread.  Another outlier among the others widens their sd (fewer flags, never more)."""
    levels = np.asarray(levels, dtype=float)
    n = levels.shape[0]
    total = levels.sum(axis=0)
    mean_o = (total - levels) / (n - 1)
    sq = (levels * levels).sum(axis=0)
    var_o = np.maximum((sq - levels * levels - (n - 1) * mean_o * mean_o) / (n - 2), 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        t = (levels - mean_o) / np.sqrt(var_o * (1 + 1 / (n - 1)))
    return np.where(np.isnan(t), 0.0, t)


def outlier_threshold(alpha: float, robots: int, params: int = len(MONITORED)) -> float:
    """The |t| over which a robot stands out: Bonferroni over the ``robots`` x ``params`` two-sided tests of
    :func:`leave_one_out_t`, so that a fleet with Gaussian unit-to-unit spread has any robot flagged with
    probability at most ``alpha`` (Monte Carlo with 10 robots, 8 parameters, alpha 0.001: 9.45 exact, 9.49 here)."""
    from scipy.stats import t  # scipy.stats (~0.6 s): only a fleet review

    return float(t.isf(alpha / (2 * robots * params), robots - 2))
