"""``wmrid monitor``: replay a log against an identified model and report when the dynamics change.

The paper motivates identification with fault detection and unknown payloads; this is that use.  Given
base parameters identified earlier (``wmrid identify LOG0 -o RESULT.json``) and a new log, find the times
at which the robot stopped obeying the model (a payload loaded or dropped, a wheel whose friction rose),
with a test whose false-alarm rate is stated, and identify the robot again after each change.

Residual.  Every signal the inverse model needs is smoothed by a zero-phase Savitzky-Golay cubic over
``accel_window_s`` = 0.1 s (the wheel accelerations are its derivative, never a raw difference of noise;
see :mod:`wmrid.reporting.report`), and the torque residual of the model is taken at ``rate_hz`` = 50 Hz::

    r = tau - M eta_dot - V(eta) - F_v eta - F_d sgn(eta) = tau - Phi(eta, eta_dot) p,
    p = [M11, M12, M22, Vc, Fv1, Fv2, Fd1, Fd2]                                     (2 rows, 8 columns)

A change of the dynamics by dp adds Phi dp to r: a change has the regressor's structure.  The regressor
the test uses is smoothed over ``regressor_window_s`` = 0.5 s: its accelerations carry the derivative
noise of the speeds, which the residual carries too (times M), and with the residual's smoothing the two
would correlate and inflate the statistic (errors in variables; measured: a mean of about 100 instead
of 8 on unchanged logs).

Noise model.  The residual's noise is coloured (the smoothing, a caster disturbance lasting tenths of a
second, the closed loop), so a vector autoregression with q = ``noise_memory_s`` x rate lags (0.3 s: 15)
is fitted by least squares on the CALIBRATION SPAN, the first ``calibration_s`` = 10 s of the log, which is
ASSUMED UNCHANGED.  Residual and regressor columns pass through its whitening filter,
z_k = L^-1 (r_k - sum_i A_i r_k-i) with L L' the innovation covariance, so that without a change z is
white with unit covariance.  The calibration then grows: each time the tested span doubles (at 20, 40,
80 s ...) the noise model is fitted again on all of the log before that point.

Test.  On a window of whitened data the generalised likelihood ratio for "the parameters changed by an
unknown dp at the window's start" is S = c' (G + G P G)^-1 c, c = b - G dp0, G = sum X'X, b = sum X'z
(X the whitened regressor): an estimated model leaves a residual Phi dp of its own, which grows with the
window and is no change, so its error dp, normal with mean dp0 and covariance P, is part of the null
hypothesis.  For the given model, dp starts as normal(0, (2 x its reported standard errors)^2) (twice:
they leave out the closed-loop bias, and the JSON holds no correlations) and is updated (Bayes) with the
calibration span, which fixes the combinations the log's motion excites; for a model identified after a
change, dp is normal(0, 4 x its full covariance).  With P = 0 and dp0 = 0, S is the explained sum of
squares of a least-squares fit of z on X, chi-square with 8 degrees of freedom when nothing changed.  The
noise power at low frequency is itself estimated, from about dof = samples / lags degrees of freedom (an
autoregression's spectrum at frequency 0 has a relative variance of 4 q / n per wheel, Berk 1974), so
S / 8 is taken as F(8, dof).  Windows of 0.5, 1, 2, 4, 8 and 16 s (short ones see a large change at once,
long ones a small one), each tested every quarter of its length: 58,900 tests per hour of log at 50 Hz.
The threshold h is ``margin`` x 8 x the F(8, dof) quantile at p = ``false_alarm_rate`` / tests per hour:
the Bonferroni bound then keeps the expected number of false alarms per hour of log at most
``false_alarm_rate`` (default 0.1 per hour); h falls as the calibration grows (80 after the first 10 s,
60 after 20 s, towards 46 after minutes).  The law is approximate (the closed loop moves the regressor
with the disturbance; the tail is a little heavier than F in the first doublings), so ``margin`` = 1.1,
chosen by measurement: on 6.4 h of unchanged noisy closed-loop simulated logs, each monitored against a
model identified on another log, margin 1 gave 4.2, 0.78 and 0.31 false alarms per hour at stated rates of
10, 1 and 0.3 per hour, margin 1.1 gave 1.7, 0.16 and 0.  bench/accuracy/bench_monitor.py measures the defaults
(300 logs, 9.2 h: no false alarm; 1.2 per hour at a stated 10 per hour).

After an alarm.  The change time is the maximum-likelihood one, the start j maximising S(j, k) with k one
second (``locate_s``) past the alarm.  A new segment starts there: its model is identified
(:func:`wmrid.pipeline.identify.identify`, without a robot file) on its first ``calibration_s`` (again each time its
span doubles), its noise model is fitted on the same span from cross-fitted residuals (each half's
residual from the model identified on the other half, so that the noise model sees a model's estimation
error and not an in-sample fit), and the test restarts, so that a second change (the payload dropped
again) is found too.  When every change is found, each segment is identified on all of it, from its
change to the next change or the end of the log (time re-based to 0): those are the parameters reported.

Caster drag.  A model identified with ``--friction wheel+caster`` (its JSON ``theta.form``, read by
:meth:`wmrid.model.dynamics.RegressorForm.from_dict`) adds its caster columns to Phi: column j of ``form.caster_map``
adds theta0[param_j] col_j [1, pattern_j] to the wheel torques (:func:`wmrid.model.torques.friction_torque`),
smoothed as the other speed columns; p's drag entries are theta0's (as in
:func:`wmrid.estimators.regression.idim_rows.rows_from_features`), with their reported standard errors.  The test then
has len(p)
degrees of freedom, S / len(p) ~ F(len(p), dof).  After a change the segment is identified with
``friction="wheel+caster"`` and the model's caster positions (its ``form.geometry``) when it has them, else with the
two-term drag (Cv, Cw) (where the wheels never reverse, with wheel friction only; a warning says so).

Times: ``t`` of a change is s from the log's first sample; ``t_alarm`` is the time of the last log sample
the alarming test used (its window's end plus the smoothing's half-width, 0.25 s), when a monitor
running along the log would have raised the alarm.

Limits (stated, not hidden): changes inside a calibration span are not tested for (the first
``calibration_s`` of the log, and of each segment after a change), and two changes closer than that are not
told apart; the log must be evenly sampled (uneven logs are resampled linearly on their median step,
holes are refused); a change that does not show in the torque residual on the log's motion (friction of
a wheel that never turns) cannot be seen.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from wmrid.core.errors import NotIdentifiableError, UsageError, option
from wmrid.core.jit import warn_if_slow
from wmrid.estimators.options import ObserverOptions
from wmrid.estimators.records import LogInfo
from wmrid.model import dynamics as model
from wmrid.model.dynamics import THETA0_NAMES, RegressorForm
from wmrid.monitoring.glr import ModelError, NoiseModel, locate, window_grid, window_statistics
from wmrid.monitoring.monitor_result import Change, MonitorResult
from wmrid.monitoring.residuals import Signals, residual_signals, tidy
from wmrid.monitoring.settings import (
    MIN_IDENTIFY_S,
    MIN_ROWS_PER_COEFFICIENT,
    PRIOR_STD_FACTOR,
    MonitoredModel,
    MonitorSettings,
    caster_form,
    inertia_ok,
    named,
)


@dataclass(frozen=True)
class _Log:
    t: np.ndarray
    eta: np.ndarray
    tau: np.ndarray
    source: str
    notes: tuple[str, ...] = ()
    effort_unit: str = "N m"


def _segment_log(log: Any, t_start: float, t_end: float, unit: str) -> _Log:
    t = np.asarray(log.t) - log.t[0]
    keep = (t >= t_start - 1e-9) & (t <= t_end + 1e-9)
    t_seg = t[keep]
    return _Log(
        t=t_seg - t_seg[0] if len(t_seg) else t_seg, eta=np.asarray(log.eta)[keep], tau=np.asarray(log.tau)[keep],
        source=f"{log.source} [{t_start:.3f} s, {t_end:.3f} s]", effort_unit=unit,
    )  # fmt: skip


def _identify_span(log: Any, t_start: float, t_end: float, unit: str, friction: str = "wheel",
                   notes: list[str] | None = None, geometry: tuple[float, ...] = (),
                   observer: ObserverOptions | None = None):  # fmt: skip
    """(identification of log[t_start, t_end] (s from the log's start), None) or (None, why not).

    ``friction``: the given model's friction model.  ``wheel+caster`` is identified with the given model's caster
    positions ``geometry`` ((r, b, x_1, y_1, ...), its ``form.geometry``), else with the two-term caster model
    (Cv, Cw); where that is not identifiable (the wheels never stop or reverse: the drag then adds to the
    Coulomb friction) the wheel friction model is used instead, and why is appended to ``notes``.  ``observer``: the
    observer's settings (its friction, delay and payload aside: the model's friction, the log already shifted by any
    delay, no robot for a payload; default :class:`ObserverOptions`)."""
    # the identification pipeline (~0.25 s): only a span identified after a change
    from wmrid.pipeline.identify import Steps, identify_log

    base = observer if observer is not None else ObserverOptions()

    def identify(seg: Any, friction: str, geometry: tuple[float, ...] = ()) -> Any:
        options = replace(base, friction=friction, delay=None, payload=False)
        return identify_log(seg, None, options, Steps(geometry=geometry, feedback=False, timing=False))

    seg = _segment_log(log, t_start, t_end, unit)
    span = float(seg.t[-1]) if len(seg.t) else 0.0
    if len(seg.t) < 10 or span < MIN_IDENTIFY_S - 1e-9:
        return None, (
            f"only {span:.3g} s of log from {t_start:.3f} s: too little to identify (at least {MIN_IDENTIFY_S:g} s)"
        )
    try:
        try:
            result = identify(seg, friction, geometry)
        except NotIdentifiableError as err:
            if friction == "wheel":
                raise
            result = identify(seg, "wheel")
            if notes is not None:
                notes.append(
                    f"the log from {t_start:.3f} s to {t_end:.3f} s was identified with wheel friction only: the "
                    f"caster model was not identifiable there ({err})"
                )
    except NotIdentifiableError as err:
        return None, f"the log from {t_start:.3f} s to {t_end:.3f} s could not be identified: {err}"
    theta0 = result.estimate.theta0
    if not (np.all(np.isfinite(theta0)) and inertia_ok(theta0)):
        return None, f"the model identified from {t_start:.3f} s to {t_end:.3f} s is not physical"
    return result, None


@dataclass(frozen=True)
class _Model:
    """Base parameters theta0 (n,) and the prior covariance (n, n) of the error of p = [M11 M12 M22 Vc Fv1 Fv2 Fd1
    Fd2, caster drag]; ``update``: refine it with the calibration span (a given model, from another log), or not
    (a model identified on the calibration span itself, whose covariance already holds that data); ``form``: its
    caster model (None: wheel friction, n = 8)."""

    theta0: np.ndarray
    cov: np.ndarray
    update: bool
    form: RegressorForm | None = None


def _physical_jacobian(theta0: np.ndarray) -> np.ndarray:
    """d p / d theta0 (n, n): M = m^-1 gives dM = -M dm M; the others (Vc, friction, caster drag) are the same in
    both (:func:`wmrid.model.dynamics.invert_inertia_jacobian`)."""
    return model.invert_inertia_jacobian(theta0)


def _model_of_result(result: Any) -> _Model:
    """The model an identification found, with its full covariance (undetermined parameters: ten times their
    value as standard error, uncorrelated), times PRIOR_STD_FACTOR^2."""
    theta0 = np.asarray(result.estimate.theta0, dtype=float)
    cov0 = np.array(result.estimate.cov, dtype=float)
    bad = ~np.isfinite(np.diag(cov0))
    cov0[bad, :] = cov0[:, bad] = 0.0
    cov0[bad, bad] = (10.0 * np.maximum(np.abs(theta0[bad]), 1e-3)) ** 2
    cov0 = np.where(np.isfinite(cov0), cov0, 0.0)
    jac = _physical_jacobian(theta0)
    return _Model(theta0, PRIOR_STD_FACTOR**2 * (jac @ cov0 @ jac.T), update=False, form=caster_form(result.form))


class _Segment:
    """The test on one segment of the signals (from sample ``start`` to the end), its calibrations growing by
    doubling; ``fixed`` None: identify the model on the segment itself."""

    def __init__(self, mon: _Monitor, start: int, fixed: _Model | None) -> None:
        self.m, self.start, self.fixed = mon, start, fixed
        self.n = len(mon.sig.t) - start
        self.calibrations: list[dict[str, Any]] = []

    def _t(self, i: int) -> float:
        return float(self.m.sig.t[self.start + min(i, self.n - 1)])

    def calibrate(self, upto: int) -> tuple[_Model, NoiseModel]:
        """The model and the noise model from the segment's samples [0, upto)."""
        m = self.m
        a = self.start
        if self.fixed is not None:
            return self.fixed, NoiseModel.fit(
                [m.sig.residual(self.fixed.theta0, a, a + upto, self.fixed.form)], m.order
            )
        t0, t1 = self._t(0), self._t(upto - 1)
        result, problem = _identify_span(m.log, t0, t1, m.unit, m.friction, m.notes, m.geometry, m.observer)
        if result is None:
            raise _Stop(problem)
        fitted = _model_of_result(result)
        # Cross-fitting: each half's residual from the model identified on the other half, so that the noise
        # model sees the model's estimation error as the test will, not an in-sample fit.
        half = upto // 2
        tm = self._t(half)
        first, _ = _identify_span(m.log, t0, tm, m.unit, m.friction, m.notes, m.geometry, m.observer)
        second, _ = _identify_span(m.log, tm, t1, m.unit, m.friction, m.notes, m.geometry, m.observer)
        if first is not None and second is not None:
            spans = [m.sig.residual(second.estimate.theta0, a, a + half, caster_form(second.form)),
                     m.sig.residual(first.estimate.theta0, a + half, a + upto, caster_form(first.form))]  # fmt: skip
        else:
            spans = [m.sig.residual(fitted.theta0, a, a + upto, fitted.form)]
        try:
            return fitted, NoiseModel.fit(spans, m.order)
        except NotIdentifiableError as err:
            raise _Stop(f"the segment from {t0:.3f} s: {err}") from None

    def run(self):
        """The first alarm (change sample in the segment, Change) or None."""
        m, grid = self.m, self.m.grid
        n_cal = m.n_cal
        if self.n < n_cal + min(grid.windows) * grid.block:
            raise _Stop(
                f"the last {self._t(self.n - 1) - self._t(0):.3g} s from {self._t(0):.3f} s are shorter than the "
                f"calibration span ({m.settings.calibration_s:g} s) and a test window: not tested"
            )
        longest = max(grid.windows) * grid.block
        upto = n_cal
        while upto < self.n:
            nxt = min(2 * upto, self.n)
            fitted, noise = self.calibrate(upto)
            h = grid.threshold(noise.dof, len(fitted.theta0))
            err = ModelError(np.zeros(len(fitted.theta0)), fitted.cov)
            if fitted.update:  # what the calibration span says of the given model's error (Bayes, normal)
                z, x = m.whitened(fitted, noise, self.start + noise.order, self.start + upto)
                gram, proj = np.einsum("kip,kiq->pq", x, x), np.einsum("kip,ki->p", x, z)
                post = np.linalg.inv(np.linalg.inv(fitted.cov) + gram)
                err = ModelError(post @ proj, (post + post.T) / 2)
            lo = max(n_cal, (upto - longest) // grid.block * grid.block)
            z, x = m.whitened(fitted, noise, self.start + lo, self.start + nxt)
            tests = window_statistics(z, x, err, lo, grid, upto, nxt)
            alarm = None
            for width, ends, s in tests:
                over = np.flatnonzero(s > h)
                if len(over):
                    cand = (int(ends[over[0]]), -float(s[over[0]]), width)
                    alarm = cand if alarm is None or cand < alarm else alarm
            largest = max((float(s.max()) for _, _, s in tests), default=0.0)
            if alarm is not None:
                largest = max(float(s[ends <= alarm[0]].max(initial=0.0)) for _, ends, s in tests)
            self.calibrations.append({
                "t_start": self._t(0), "t_end": self._t(upto - 1), "lags": noise.order, "dof": noise.dof,
                "innovation_std": [float(v) for v in np.sqrt(np.diag(noise.cov))], "threshold": h,
                "tests_until": self._t(nxt - 1), "largest_statistic": largest,
            })  # fmt: skip
            if alarm is not None:
                end, neg_s, width = alarm
                lo_loc = max(n_cal, end - longest)
                hi_loc = min(self.n, end + m.after)
                z, x = m.whitened(fitted, noise, self.start + lo_loc, self.start + hi_loc)
                j = lo_loc + locate(z, x, err, end - lo_loc)
                t_alarm = min(self._t(end - 1) + m.sig.lookahead, m.duration)
                change = Change(t=self._t(j), t_alarm=t_alarm, statistic=-neg_s, threshold=h,
                                window_s=width / grid.rate)  # fmt: skip
                return j, change
            upto = nxt
        return None

    def to_dict(self, t_end: float) -> dict[str, Any]:
        return {"t_start": self._t(0), "t_end": t_end, "model": "given" if self.fixed is not None else "identified on "
                "the segment", "calibrations": self.calibrations}  # fmt: skip


class _Stop(Exception):
    """The segment cannot be tested further (why: the message)."""


class _Monitor:
    def __init__(
        self, log: Any, sig: Signals, settings: MonitorSettings, unit: str, friction: str = "wheel",
        geometry: tuple[float, ...] = (), observer: ObserverOptions | None = None,
    ) -> None:  # fmt: skip
        self.log, self.sig, self.settings, self.unit = log, sig, settings, unit
        self.grid = window_grid(settings, sig.rate)
        self.order = max(1, round(settings.noise_memory_s * sig.rate))
        self.n_cal = max(1, math.ceil(round(settings.calibration_s * sig.rate) / self.grid.block)) * self.grid.block
        self.after = round(settings.locate_s * sig.rate)
        self.duration = float(log.t[-1] - log.t[0])
        self.friction = friction
        self.geometry = geometry  # the model's caster positions (r, b, x_1, y_1, ...), () for none
        self.notes: list[str] = []  # fallbacks of re-identification (see _identify_span)
        self.observer = observer  # the re-identifications' observer settings

    def whitened(self, fitted: _Model, noise: NoiseModel, a: int, b: int) -> tuple[np.ndarray, np.ndarray]:
        """Whitened residual z (m, 2) and regressor x (m, 2, n) of signal samples [a, b) (from a - q for the
        filter's memory)."""
        q = noise.order
        residual = self.sig.residual(fitted.theta0, a - q, b, fitted.form)
        return noise.whiten(residual), noise.whiten(self.sig.phi_for(fitted.form, "test")[a - q : b])


def identification_settings(observer: ObserverOptions | None) -> dict[str, Any]:
    """The observer's settings the identifications after a change use (the defaults when none are given), for the
    JSON's "identification": its friction model is the model's, no delay (the log is shifted first), no payload."""
    options = observer if observer is not None else ObserverOptions()
    return {
        "form": options.form, "k": options.k, "alpha": options.alpha, "box_width": options.box_width,
        "torque_hold": options.torque_hold, "control_rate": options.control_rate,
    }  # fmt: skip


def monitor(
    log: Any, model_: MonitoredModel, settings: MonitorSettings | None = None, observer: ObserverOptions | None = None
) -> MonitorResult:
    """Replay ``log`` (t (n,) s, eta (n, 2) rad/s, tau (n, 2); source, notes, effort_unit) against ``model_``
    and report the changes of its dynamics (see the module docstring); ``observer``: the settings of the
    re-identifications after a change (see :func:`_identify_span`)."""
    started = time.perf_counter()
    warn_if_slow(len(log.t))  # the whole log, before the windows' identifications (each shorter than the threshold)
    settings = settings or MonitorSettings()
    source = getattr(log, "source", "log")
    unit = getattr(log, "effort_unit", "N m")
    if unit != model_.effort_unit:
        raise UsageError(
            f"{option('model')} {model_.source}: its parameters are for efforts in {model_.effort_unit}, but the "
            "log's effort "
            f"is in {unit}; identify and monitor with the same effort options"
        )
    sig = residual_signals(log.t, log.eta, log.tau, settings, source)
    friction = model_.friction
    geometry = () if model_.form is None else tuple(model_.form.geometry)
    mon = _Monitor(log, sig, settings, unit, friction, geometry, observer)
    duration = float(log.t[-1] - log.t[0])
    need = (MIN_ROWS_PER_COEFFICIENT * 2 + 2) * mon.order  # after a change the halves lose q samples each
    if mon.n_cal < need:
        raise UsageError(
            f"{option('calibration_s')} {settings.calibration_s:g} s: too short for the noise model ({mon.order} lags "
            "at "
            f"{sig.rate:.4g} Hz need at least {need / sig.rate:.3g} s)"
        )
    if len(sig.t) < mon.n_cal + min(mon.grid.windows) * mon.grid.block:
        raise NotIdentifiableError(
            f"{source}: the log lasts {duration:.3g} s, but monitoring needs more than the calibration span "
            f"({settings.calibration_s:g} s, assumed unchanged) plus a test window; record a longer log or lower "
            f"{option('calibration_s')}"
        )
    warnings: list[str] = [model_.doubt] if model_.doubt else []
    changes: list[Change] = []
    segments: list[dict[str, Any]] = []
    prior = np.diag((PRIOR_STD_FACTOR * model_.std) ** 2)
    seg = _Segment(mon, 0, _Model(model_.theta0, prior, update=True, form=caster_form(model_.form)))
    while True:
        try:
            found = seg.run()
        except _Stop as stop:
            warnings.append(str(stop))
            found = None
        if found is None:
            segments.append(seg.to_dict(float(sig.t[-1])))
            break
        j, change = found
        segments.append(seg.to_dict(change.t))
        changes.append(change)
        seg = _Segment(mon, seg.start + j, None)
    # Each segment after a change, identified on all of it.
    before, before_form = model_.theta0, caster_form(model_.form)
    for i, change in enumerate(changes):
        t_end = changes[i + 1].t if i + 1 < len(changes) else duration
        notes: list[str] = []
        result, problem = _identify_span(log, change.t, t_end, unit, friction, notes, geometry, observer)
        change.warnings.extend(notes)
        if result is None:
            change.warnings.append(problem)
            continue
        change.parameters = dict(result.table)
        change.segment = (change.t, t_end)
        change.warnings.extend(result.warnings)
        change.theta0 = result.estimate.theta0
        after_form = caster_form(result.form)
        if after_form != before_form and before_form is not None:
            change.warnings.append(
                f"identified with friction model {'wheel' if after_form is None else after_form.friction} "
                f"({', '.join((after_form.base_names if after_form else THETA0_NAMES)[8:]) or 'no caster drag'}), "
                f"not the model's ({', '.join(before_form.base_names[8:])}; the caster model was not identifiable "
                "on this segment): its friction and drag terms are not comparable"
            )
        after_named, before_named = named(change.theta0, after_form), named(before, before_form)
        # the caster drag's parameters are compared when both models have them (same caster model)
        drag = [name for name in after_named if name not in (*THETA0_NAMES, "M11", "M12", "M22")]
        change.relative_change = {
            name: (after_named[name] - before_named[name]) / abs(before_named[name]) if before_named[name] else None
            for name in (*THETA0_NAMES, "M11", "M12", "M22", *(n for n in drag if n in before_named))
        }
        before, before_form = change.theta0, after_form
    seen = set(warnings)
    for note in mon.notes:  # re-identifications that fell back to wheel friction (once each)
        if note not in seen:
            seen.add(note)
            warnings.append(note)
    log_info = LogInfo(
        samples=len(log.t), duration_s=duration, rate_hz=tidy(sig.log_rate),
        notes=(*getattr(log, "notes", ()), *sig.notes), effort_unit=unit,
    )  # fmt: skip
    return MonitorResult(
        source=source, model=model_, settings=settings, grid=mon.grid, noise_lags=mon.order,
        calibration_samples=mon.n_cal, changes=changes, segments=segments,
        log_info=log_info, warnings=warnings, seconds=time.perf_counter() - started,
        identification=identification_settings(observer),
    )  # fmt: skip
