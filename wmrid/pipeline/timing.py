"""The efforts' timing against the speeds: what is decided before the observer runs (:func:`decide_timing`), the
observer's passes at another delay or hold that the widenings need (:func:`observe_at`), and the unresolved-delay
term (:func:`carry_unresolved_delay`).

Why it matters: efforts stamped late against the speeds (two topics, two clocks, a controller faster than the log)
bias the friction and inertia; the timing check estimates the delay on a window of the log, and the pipeline applies
it when it is significant (:mod:`wmrid.pipeline.identify`).
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from wmrid.core.errors import WmridError
from wmrid.core.wheel_log import LogStream, split_topics, stream_arrays
from wmrid.estimators.findings import DelayApplied, TimingCheck
from wmrid.estimators.observer.observe import delay_profile_form, observe
from wmrid.estimators.observer.survey import Survey, survey
from wmrid.estimators.options import ObserverOptions
from wmrid.estimators.result import IdentificationResult
from wmrid.estimators.timing_check import apply_delay, timing_check, unresolved_delay, unresolved_text
from wmrid.estimators.widening import with_unresolved_timing
from wmrid.model.robot import Robot

#: ``diagnostics.timing.why`` of a delay not applied because the log's misfit can make it appear.
WITHIN_MISFIT = "within the log's misfit: a delay that large can appear where the log departs from the model"


@dataclass(frozen=True)
class Timing:
    """What the pipeline knows about the efforts' timing when the friction models run.

    record : the timing check's (:func:`wmrid.estimators.timing_check.timing_check`, ``diagnostics.timing``), None
    when it did not run.  warnings : said before the result's own.  split : the efforts came from another topic than the
    speeds (:func:`wmrid.core.wheel_log.split_topics`).  delay_record, delay_warnings : the applied delay's
    (:func:`wmrid.estimators.timing_check.apply_delay`, ``diagnostics.delay``), None when none was asked for.
    """

    record: TimingCheck | None = None
    warnings: tuple[str, ...] = ()
    split: bool = False
    delay_record: DelayApplied | None = None
    delay_warnings: tuple[str, ...] = ()

    @property
    def apply(self) -> bool:
        """The check found a significant delay: time the efforts."""
        return self.record is not None and bool(self.record.apply)

    def within_misfit(self, text: str) -> Timing:
        """This timing, the check's delay not applied because the log's misfit can make it appear (``text`` says so):
        its record says apply false, so the std carries the delay as one the check did not resolve."""
        record = None if self.record is None else replace(self.record, apply=False, why=WITHIN_MISFIT)
        return replace(self, record=record, warnings=(*self.warnings, text))

    def failed(self, err: WmridError) -> Timing:
        """This timing, the efforts left as stamped because timing them failed with ``err``."""
        text = f"the efforts could not be timed against the speeds ({err}); used as stamped"
        return replace(self, warnings=(*self.warnings, text))


def surveyed(log: Any) -> tuple[LogStream, Survey]:
    """(``log`` as a stream, its survey: one pass, :func:`wmrid.estimators.observer.survey.survey`)."""
    stream = log if isinstance(log, LogStream) else stream_arrays(log)
    return stream, survey(stream, stream.source, stream.effort_unit)


def decide_timing(
    log: Any,
    stream: LogStream,
    sv: Survey,
    robot: Robot | None,
    options: ObserverOptions,
    geometry: tuple[float, ...],
    load_terms: bool,
    **delay: Any,
) -> Timing:
    """The timing of ``log`` (``stream``, surveyed as ``sv``): split topics, else the timing check on a window of
    the log, profiled with the richest friction model ``options.friction`` allows
    (:func:`wmrid.estimators.observer.observe.delay_profile_form`); its note (a delay the casters' drag explains) is a
    warning.  ``delay``: a :class:`Timing`'s delay_record and delay_warnings, kept."""
    if split_topics(stream.notes):
        return Timing(split=True, **delay)
    profile = delay_profile_form(sv.form(), options.friction, robot, tuple(geometry), load_terms)
    record = timing_check(log, options.torque_hold, options.control_rate, sv.n, sv.median_step, profile)
    warnings = (record.note,) if record.note else ()
    return Timing(record=record, warnings=warnings, **delay)


def observe_at(
    log: Any,
    robot: Robot | None,
    options: ObserverOptions,
    geometry: tuple[float, ...],
) -> IdentificationResult:
    """One pass of the observer over ``log`` with its efforts read ``options.delay`` s earlier (None: as stamped) and
    the friction model ``options.friction``: the other admissible reading a widening compares with (its estimate
    only: no payload)."""
    if options.delay is not None:
        if options.delay == "auto":
            raise ValueError("observe_at reads the log at a given delay, not 'auto'")
        log, _, _ = apply_delay(log, options.delay, options.torque_hold, options.control_rate, None)
    stream, sv = surveyed(log)
    return observe(stream, sv, robot, replace(options, payload=False), geometry)


def carry_unresolved_delay(
    result: IdentificationResult,
    record: TimingCheck,
    log: Any,
    robot: Robot | None,
    options: ObserverOptions,
    geometry: tuple[float, ...],
) -> IdentificationResult:
    """``result`` with the timing term of a delay the timing check could not resolve (:func:`wmrid.estimators.delay.
    unresolved_delay`), carried by the std (:func:`wmrid.estimators.widening.with_unresolved_timing`): the change of
    theta0 when the log is identified again with its efforts read that much earlier (:func:`observe_at`); for a log
    longer than the check's window (whose whole would have to be read into memory), that delay times the profile's
    least-squares slope (within a factor 0.8-1.9 of the observer's for the friction, measured on the light AMR).
    Unchanged when there is none to carry, and when the result models caster drag: the profile fits the wheels'
    friction only, and on a caster log its std measures that misfit rather than the timing (0.8 ms on a noise-free
    log that the caster model fits to 3.5e-5, which widened every std 50 times)."""
    est = result.estimate
    assert est is not None
    if result.form.caster:
        return result
    moved_delay = unresolved_delay(record, np.sqrt(np.maximum(np.diag(np.asarray(est.cov, dtype=float)), 0.0)))
    if moved_delay is None:
        return result
    theta0 = np.asarray(est.theta0, dtype=float)
    # a delay within the log's misfit was said when it was not applied (Timing.within_misfit): the std carries it
    text = "" if record.why == WITHIN_MISFIT else unresolved_text(record, moved_delay)
    if (record.samples_profiled or 0) < (record.of or 0) or (record.windows or 1) > 1:
        slope = np.zeros_like(theta0)
        slope[:8] = record.theta0_slope_per_s
        return with_unresolved_timing(result, moved_delay * slope, moved_delay, "the profile's slope", text, robot)
    try:
        moved = observe_at(log, robot, replace(options, friction=result.form.friction, delay=moved_delay), geometry)
    except WmridError:
        return result
    if moved.estimate is None or len(moved.estimate.theta0) != len(theta0):
        return result
    delta = np.asarray(moved.estimate.theta0, dtype=float) - theta0
    return with_unresolved_timing(result, delta, moved_delay, "identified again", text, robot)
