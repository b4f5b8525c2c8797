"""The change test of ``wmrid monitor`` run along a stream (``wmrid live --monitor MODEL.json``).

:class:`LiveMonitor` is fed the wheel samples as they arrive and raises a :class:`LiveChange` as soon as the test
alarms.  It is the test of :mod:`wmrid.monitoring.monitor`, computed incrementally with the same functions:

* the residual's signals (:func:`wmrid.monitoring.residuals.residual_signals`) on each new stretch of samples, with
  the smoothing's half-width of context on each side, at the centres the whole log would have (every ``dec``-th
  sample from the first half-width on), so they are the whole log's signals;
* the noise model fitted on the first ``calibration_s`` (assumed unchanged) and again each time the tested span
  doubles, on exactly the span the offline monitor uses; the model's error updated (Bayes) on it as offline;
* the windows tested (:func:`wmrid.monitoring.glr.window_statistics`) as they end, each with the calibration the
  offline monitor gives it (a window ending in (upto, 2 upto] with the one fitted on [0, upto)), against the same
  threshold; an alarm at the first window over it, as offline.

So the live alarms are the offline monitor's alarms on the same samples (the first, exactly; later ones differ in
where a change is located: offline uses ``locate_s`` of data past the alarm, live what has come when it alarms).
The alarm is raised when the window's last sample plus the smoothing's half-width (0.25 s) has arrived.

After an alarm, once ``locate_s`` past the alarming window and FIT_S past the change have come, the change's time is
located as offline (:func:`wmrid.monitoring.glr.locate`), what changed is estimated (a least-squares fit of the whitened
residual on the regressor since the change: the payload's terms M11, M12, M22, Vc alone, or the friction terms alone,
when the others add less to the statistic than the test's own threshold for that many terms, else all; the parameters
that moved by more than 3 std; a payload's mass when the robot's geometry is known) and the alarm is raised; the test
starts again after the change, against a model identified on the segment's first ``calibration_s`` (cross-fitted noise
model, as offline).

Memory is bounded: the calibration stops growing at MAX_CALIBRATIONS doublings (320 s at the default 10 s; offline it
grows with the log), so the signals kept are at most that span plus the longest window; the raw samples kept are
the smoothing's context, and after a change the segment's span until its last calibration.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import SimpleNamespace
from typing import Any

import numpy as np

from wmrid.core.errors import NotIdentifiableError, UsageError, option
from wmrid.estimators.options import ObserverOptions
from wmrid.model.payload import payload_from_change
from wmrid.monitoring.glr import ModelError, NoiseModel, locate, window_grid, window_statistics
from wmrid.monitoring.live_change import LiveChange, PayloadMass
from wmrid.monitoring.monitor import _identify_span, _Model, _model_of_result
from wmrid.monitoring.residuals import residual_signals
from wmrid.monitoring.settings import (
    HOLE_FACTOR,
    PRIOR_STD_FACTOR,
    MonitoredModel,
    MonitorSettings,
    caster_form,
    p_names,
    physical_vector,
)

#: The calibration doubles at most this many times (then it stays: memory bounded).
MAX_CALIBRATIONS = 5
#: s of new samples gathered before the signals are extended (tests then run on every block that ended).
STRETCH_S = 0.25
#: A parameter "moved" when its estimated change exceeds this many standard errors.
MOVED_STD = 3.0
#: s of data after the located change that what changed is estimated from before the alarm is raised (measured on a
#: 25 kg payload loaded at 20 s of the paper scenario: from 0.3 s, 49 kg; from 2 s, within 10 %).
FIT_S = 2.0


@dataclass
class _Segment:
    """The test from signal sample ``start`` (a global index) on: ``fixed`` the given model (None: identified on the
    segment), the calibration in force (``upto`` samples of the segment, its noise model, error and threshold) and
    the tests done (window ends up to ``tested``, segment samples)."""

    start: int
    fixed: _Model | None
    upto: int = 0
    fitted: _Model | None = None
    noise: NoiseModel | None = None
    err: ModelError | None = None
    threshold: float = math.inf
    tested: int = 0
    calibrations: int = 0
    notes: list[str] = field(default_factory=list)


class LiveMonitor:
    """The change test along a stream against ``model`` (see the module docstring).

    geometry : (r, b) m, the robot's wheel radius and half-track, for a payload's mass (None: not estimated).
    observer : the observer's settings for the identifications after a change (as :func:`wmrid.monitoring.monitor.
    _identify_span` uses them: the model's friction, no delay, no payload).
    :meth:`feed` takes t (k,) s, eta (k, 2) rad/s, tau (k, 2) in the model's effort unit, in order, and returns the
    changes found.
    """

    def __init__(self, model: MonitoredModel, settings: MonitorSettings | None = None,
                 geometry: tuple[float, float] | None = None, effort_unit: str = "N m",
                 observer: ObserverOptions | None = None) -> None:  # fmt: skip
        if effort_unit != model.effort_unit:
            raise UsageError(
                f"{option('monitor')} {model.source}: its parameters are for efforts in {model.effort_unit}, but the "
                f"stream's effort is in {effort_unit}; identify and monitor with the same effort options"
            )
        self.model = model
        self.settings = settings or MonitorSettings()
        self.geometry = geometry
        self.form = caster_form(model.form)
        self.friction = model.friction
        self.caster_geometry = () if model.form is None else tuple(model.form.geometry)
        self.notes: list[str] = []  # why the monitor stopped, fallbacks of re-identification
        self.observer = observer  # the re-identifications' observer settings (friction, delay, payload aside)
        self.stopped = False
        # the raw stream (kept from raw index ``raw0``) and its grid, fixed on the first second
        self.raw_t: list[np.ndarray] = []
        self.raw_eta: list[np.ndarray] = []
        self.raw_tau: list[np.ndarray] = []
        self.raw0 = 0
        self.raw_n = 0  # raw samples received
        self.t_first: float | None = None
        self.step = 0.0
        self.dec = self.half = 0
        self.grid: Any = None
        # the signals at the test rate (kept from signal index ``sig0``)
        self.sig0 = 0
        self.sig_t = np.empty(0)
        self.sig_tau = np.empty((0, 2))
        self.sig_phi = np.empty((0, 2, len(p_names(self.form))))
        self.sig_test = np.empty((0, 2, len(p_names(self.form))))
        self.segment: _Segment | None = None
        self.pending: tuple[_Segment, int, float, int] | None = None  # an alarm waiting for FIT_S of data
        self.lookahead = 0.0

    # -- the signals ------------------------------------------------------------------------------------------------
    @property
    def sig_n(self) -> int:
        """Signal samples made so far (global count)."""
        return self.sig0 + len(self.sig_t)

    def _raw(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        if len(self.raw_t) > 1:
            self.raw_t = [np.concatenate(self.raw_t)]
            self.raw_eta = [np.concatenate(self.raw_eta)]
            self.raw_tau = [np.concatenate(self.raw_tau)]
        return self.raw_t[0], self.raw_eta[0], self.raw_tau[0]

    def _start(self) -> None:
        """Fix the grid from the first second of samples (the offline monitor takes the whole log's median step)."""
        t, _, _ = self._raw()
        self.step = float(np.median(np.diff(t)))
        s = self.settings
        self.dec = max(1, round(1.0 / self.step / s.rate_hz))
        w_res = max(5, round(s.accel_window_s / self.step) | 1)
        w_reg = max(5, round(s.regressor_window_s / self.step) | 1)
        self.half = max(w_res, w_reg) // 2
        self.lookahead = self.half * self.step
        self.grid = window_grid(s, 1.0 / self.step / self.dec)
        order = max(1, round(s.noise_memory_s * self.grid.rate))
        block = self.grid.block
        self.order = order
        self.n_cal = max(1, math.ceil(round(s.calibration_s * self.grid.rate) / block)) * block
        self.longest = max(self.grid.windows) * block
        prior = np.diag((PRIOR_STD_FACTOR * self.model.std) ** 2)
        self.segment = _Segment(0, _Model(self.model.theta0, prior, update=True, form=self.form))

    def _extend(self) -> None:
        """Signals at the centres whose smoothing windows have arrived."""
        t, eta, tau = self._raw()
        first = self.half + self.sig_n * self.dec  # the next centre, a raw index
        last = self.raw_n - 1 - self.half  # the last centre whose window has arrived
        if last < first:
            return
        a = first - self.half - self.raw0
        b = self.raw_n - self.raw0
        sig = residual_signals(t[a:b], eta[a:b], tau[a:b], self.settings, "stream")
        phi = sig.phi_for(self.form, "res")
        test = sig.phi_for(self.form, "test")
        self.sig_t = np.concatenate([self.sig_t, sig.t + float(t[a]) - self.t_first])
        self.sig_tau = np.concatenate([self.sig_tau, sig.tau])
        self.sig_phi = np.concatenate([self.sig_phi, phi])
        self.sig_test = np.concatenate([self.sig_test, test])

    def _trim(self) -> None:
        """Drop the raw samples and signals no test or calibration can need again."""
        seg = self.segment
        keep_sig = self.sig_n - self.longest - 4 * self.order - 2 * self.grid.block
        if seg is not None and seg.calibrations <= MAX_CALIBRATIONS:
            keep_sig = min(keep_sig, seg.start)
        keep_sig = max(keep_sig, self.sig0)
        if keep_sig - self.sig0 > 4 * self.grid.block * 50:
            cut = keep_sig - self.sig0
            self.sig_t, self.sig_tau = self.sig_t[cut:], self.sig_tau[cut:]
            self.sig_phi, self.sig_test = self.sig_phi[cut:], self.sig_test[cut:]
            self.sig0 = keep_sig
        # the next stretch's first sample, and the longest window's span before it (a change located there is
        # identified from the raw samples)
        keep_raw = (max(self.sig_n - self.longest - 2 * self.grid.block, 0)) * self.dec
        if seg is not None and seg.fixed is None and seg.calibrations <= MAX_CALIBRATIONS:
            keep_raw = min(keep_raw, self.half + seg.start * self.dec - self.half)
        cut = keep_raw - self.raw0
        if cut > 0:
            t, eta, tau = self._raw()
            self.raw_t, self.raw_eta, self.raw_tau = [t[cut:]], [eta[cut:]], [tau[cut:]]
            self.raw0 = keep_raw

    def _at(self, i: int) -> slice:
        """Global signal indices [i, ...) as a slice of the arrays kept."""
        return slice(i - self.sig0, None)

    def _residual(self, theta0: np.ndarray, form: Any, a: int, b: int) -> np.ndarray:
        """r (b - a, 2) of theta0 at global signal samples [a, b)."""
        phi = self.sig_phi[a - self.sig0 : b - self.sig0]
        if caster_form(form) is None and phi.shape[-1] > 8:
            phi = phi[..., :8]
        return self.sig_tau[a - self.sig0 : b - self.sig0] - phi @ physical_vector(theta0)

    def _whitened(self, fitted: _Model, noise: NoiseModel, a: int, b: int) -> tuple[np.ndarray, np.ndarray]:
        """Whitened residual (b - a, 2) and regressor (b - a, 2, n) at global signal samples [a, b)."""
        q = noise.order
        test = self.sig_test[a - q - self.sig0 : b - self.sig0]
        if caster_form(fitted.form) is None and test.shape[-1] > 8:
            test = test[..., :8]
        return noise.whiten(self._residual(fitted.theta0, fitted.form, a - q, b)), noise.whiten(test)

    # -- the test ---------------------------------------------------------------------------------------------------
    def _calibrate(self, seg: _Segment, upto: int) -> None:
        """The model, noise model, error and threshold of ``seg`` from its samples [0, upto)."""
        a = seg.start
        if seg.fixed is not None:
            fitted = seg.fixed
            noise = NoiseModel.fit([self._residual(fitted.theta0, fitted.form, a, a + upto)], self.order)
        else:
            fitted, noise = self._identified(seg, upto)
        err = ModelError(np.zeros(len(fitted.theta0)), fitted.cov)
        if fitted.update:  # what the calibration span says of the given model's error (Bayes, normal)
            z, x = self._whitened(fitted, noise, a + noise.order, a + upto)
            gram, proj = np.einsum("kip,kiq->pq", x, x), np.einsum("kip,ki->p", x, z)
            post = np.linalg.inv(np.linalg.inv(fitted.cov) + gram)
            err = ModelError(post @ proj, (post + post.T) / 2)
        seg.upto, seg.fitted, seg.noise, seg.err = upto, fitted, noise, err
        seg.threshold = self.grid.threshold(noise.dof, len(fitted.theta0))
        seg.calibrations += 1

    def _identified(self, seg: _Segment, upto: int) -> tuple[_Model, NoiseModel]:
        """A segment after a change: its model identified on [0, upto) and a cross-fitted noise model, as offline."""
        t, eta, tau = self._raw()
        t_rel = t - t[0]
        log = SimpleNamespace(t=t_rel, eta=eta, tau=tau, source="stream")
        offset = float(t[0]) - self.t_first  # s from the stream's first sample to the raw buffer's
        a = seg.start
        t0, t1 = self._t(a) - offset, self._t(a + upto - 1) - offset
        unit = self.model.effort_unit
        result, problem = _identify_span(
            log, t0, t1, unit, self.friction, self.notes, self.caster_geometry, self.observer
        )
        if result is None:
            raise NotIdentifiableError(problem)
        fitted = _model_of_result(result)
        half = upto // 2
        tm = self._t(a + half) - offset
        first, _ = _identify_span(log, t0, tm, unit, self.friction, self.notes, self.caster_geometry, self.observer)
        second, _ = _identify_span(log, tm, t1, unit, self.friction, self.notes, self.caster_geometry, self.observer)
        if first is not None and second is not None:
            spans = [self._residual(second.estimate.theta0, second.form, a, a + half),
                     self._residual(first.estimate.theta0, first.form, a + half, a + upto)]  # fmt: skip
        else:
            spans = [self._residual(fitted.theta0, fitted.form, a, a + upto)]
        return fitted, NoiseModel.fit(spans, self.order)

    def _t(self, i: int) -> float:
        return float(self.sig_t[i - self.sig0])

    def _test(self) -> bool:
        """Run the tests whose windows have ended; True at the first alarm (then :attr:`pending`)."""
        seg = self.segment
        n = self.sig_n - seg.start  # segment samples made
        grid = self.grid
        while True:
            if seg.upto == 0:
                if n < self.n_cal + min(grid.windows) * grid.block:
                    return False
                self._calibrate(seg, self.n_cal)
                seg.tested = self.n_cal
            nxt = 2 * seg.upto if seg.calibrations <= MAX_CALIBRATIONS else math.inf
            until = min(n, nxt)
            if until > seg.tested:
                lo = max(self.n_cal, (seg.tested - self.longest) // grid.block * grid.block)
                z, x = self._whitened(seg.fitted, seg.noise, seg.start + lo, seg.start + until)
                alarm = None
                for width, ends, s in window_statistics(z, x, seg.err, lo, grid, seg.tested, until):
                    over = np.flatnonzero(s > seg.threshold)
                    if len(over):
                        cand = (int(ends[over[0]]), -float(s[over[0]]), width)
                        alarm = cand if alarm is None or cand < alarm else alarm
                if alarm is not None:
                    self.pending = (seg, *alarm)
                    return True
                seg.tested = max(seg.tested, (until // grid.block) * grid.block)
            if n >= nxt and seg.tested >= nxt:
                self._calibrate(seg, int(nxt))
                continue
            return False

    def _raise(self, final: bool) -> LiveChange | None:
        """The pending alarm's change once ``locate_s`` past the alarming window and FIT_S past the change have come
        (or the stream ended): located as offline, what changed estimated, the test restarted after it."""
        seg, end, neg_s, width = self.pending
        n = self.sig_n - seg.start
        rate = self.grid.rate
        after = round(self.settings.locate_s * rate)
        if not final and n < end + after:
            return None
        lo = max(self.n_cal, end - self.longest)
        z, x = self._whitened(seg.fitted, seg.noise, seg.start + lo, seg.start + min(n, end + after))
        j = lo + locate(z, x, seg.err, end - lo)
        if not final and n - j < FIT_S * rate:
            return None
        z, x = self._whitened(seg.fitted, seg.noise, seg.start + j, seg.start + n)
        kind, moved, payload, fit_s = self._what_changed(seg, z, x)
        change = LiveChange(
            t=self._t(seg.start + j), t_alarm=self._t(seg.start + end - 1) + self.lookahead,
            t_raised=self._t(self.sig_n - 1) + self.lookahead, statistic=-neg_s, threshold=seg.threshold,
            window_s=width / rate, kind=kind, moved=moved, payload=payload, fit_s=fit_s,
        )  # fmt: skip
        self.pending = None
        self.segment = _Segment(seg.start + j, None)
        return change

    def _what_changed(self, seg: _Segment, z: np.ndarray, x: np.ndarray):
        """(kind, moved, payload, span s) from the whitened data since the change (module docstring)."""
        names = p_names(caster_form(seg.fitted.form))
        err = seg.err
        gram = np.einsum("kip,kiq->pq", x, x)
        centred = np.einsum("kip,ki->p", x, z) - gram @ err.mean
        dim = len(names)
        ridge = 1e-10 * np.trace(gram) * np.eye(dim) + 1e-300 * np.eye(dim)

        def fit(cols: list[int]) -> tuple[float, np.ndarray]:
            sub = np.ix_(cols, cols)
            delta = np.linalg.solve(gram[sub] + ridge[sub], centred[cols])
            return float(centred[cols] @ delta), delta

        everything = list(range(dim))
        explained, _ = fit(everything)
        kind, cols = "other", everything
        best = -math.inf
        for name, hyp in (("payload", [0, 1, 2, 3]), ("friction", [4, 5, 6, 7])):
            s_h, _ = fit(hyp)
            if explained - s_h <= self.grid.threshold(seg.noise.dof, dim - len(hyp)) and s_h > best:
                kind, cols, best = name, hyp, s_h
        _, delta = fit(cols)
        sub = np.ix_(cols, cols)
        cov = np.linalg.pinv(gram[sub] + ridge[sub]) + err.cov[sub]
        std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
        before = physical_vector(seg.fitted.theta0) + err.mean
        moved = {
            names[c]: (float(before[c]), float(before[c] + delta[i]), float(std[i]))
            for i, c in enumerate(cols)
            if abs(delta[i]) > MOVED_STD * std[i]
        }
        payload = None
        if kind == "payload" and self.geometry is not None:
            r, b = self.geometry
            mass = float(payload_from_change(before[:4], before[:4] + delta, r, b)[0])
            s = r**2 / (4.0 * b**2)
            coef = np.array([0.5, 1.0, 0.5, 0.0]) / (2.0 * s * b**2)  # mass = coef . dM (the payload module)
            payload = PayloadMass(mass, float(math.sqrt(max(coef @ cov @ coef, 0.0))))
        return kind, moved, payload, len(z) / self.grid.rate

    # -- feeding ----------------------------------------------------------------------------------------------------
    def feed(self, t: np.ndarray, eta: np.ndarray, tau: np.ndarray) -> list[LiveChange]:
        """Take the samples t (k,) s, eta (k, 2) rad/s, tau (k, 2) (after those fed before); the changes found."""
        if self.stopped or len(t) == 0:
            return []
        if self.t_first is None:
            self.t_first = float(t[0])
        if self.raw_n and self.step:
            gap = float(t[0]) - float(self.raw_t[-1][-1])
            if gap > HOLE_FACTOR * self.step:
                return self._stop(f"the stream has a hole of {gap:.3g} s at {float(t[0]) - self.t_first:.3f} s")
        self.raw_t.append(np.asarray(t, dtype=float))
        self.raw_eta.append(np.asarray(eta, dtype=float))
        self.raw_tau.append(np.asarray(tau, dtype=float))
        self.raw_n += len(t)
        if self.segment is None:
            if float(t[-1]) - self.t_first < 1.0:
                return []
            self._start()
        if (self.raw_n - 1 - self.half) - (self.half + self.sig_n * self.dec) < STRETCH_S / self.step:
            return []
        return self._run()

    def _run(self, final: bool = False) -> list[LiveChange]:
        found = []
        try:
            self._extend()
            while True:
                if self.pending is not None:
                    change = self._raise(final)
                    if change is None:
                        break
                    found.append(change)
                elif not self._test():
                    break
            self._trim()
        except NotIdentifiableError as err:
            return found + self._stop(str(err))
        return found

    def finish(self) -> list[LiveChange]:
        """At the stream's end: the alarm still waiting for data after its change, raised with what came."""
        if self.stopped or self.pending is None or self.segment is None:
            return []
        return self._run(final=True)

    def _stop(self, why: str) -> list[LiveChange]:
        self.stopped = True
        self.notes.append(f"monitoring stopped: {why}")
        return []
