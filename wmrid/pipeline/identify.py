"""The identification of one log, step by step (:func:`identify_log`).

The route, each step a function that returns a record and re-enters nothing:

1. the options, checked when made (:class:`wmrid.estimators.options.ObserverOptions`), and what the payload needs;
2. the efforts' timing decided (:func:`wmrid.pipeline.timing.decide_timing`): split topics, or the timing check;
   when it finds a significant delay, or the user asks for one (``delay``), the delay is estimated (on the whole log,
   or window by window beyond the check's window) and applied (:func:`_delayed`: in memory, or piece by piece for a
   long stream), with a pass at the delay moved by its resolution for the timing term;
3. the observer's passes the friction model needs (:func:`wmrid.pipeline.friction.choose_friction`: one to three),
   run while step 2's timing check runs (:mod:`wmrid.pipeline.alongside`) and used unless it applies a delay;
4. the widenings: the unresolved delay (:func:`wmrid.pipeline.timing.carry_unresolved_delay`), the closed-loop check
   (:func:`wmrid.estimators.feedback.check`), the hold term of a slow log (:func:`wmrid.estimators.widening.
   with_hold_term`, a pass under foh);
5. every statement about the parameters made from the final numbers (:func:`wmrid.estimators.verdict.settle`).

The chosen method's fit, the combination with earlier results and the validation follow in
:func:`wmrid.api.identification.run_prepared`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, fields, replace
from typing import Any

from wmrid.core.errors import UsageError, WmridError, option
from wmrid.core.jit import warn_if_slow
from wmrid.core.wheel_log import LogStream, split_topics
from wmrid.estimators.delay import DELAY_RESOLUTION_S, SIGNIFICANT_S, significance_factor
from wmrid.estimators.feedback import check as feedback_check
from wmrid.estimators.findings import FrictionChoice, TimingCheck
from wmrid.estimators.observer.observe import delay_profile_form
from wmrid.estimators.options import ObserverOptions
from wmrid.estimators.result import IdentificationResult, LogLike
from wmrid.estimators.timing_check import apply_delay, in_pieces
from wmrid.estimators.verdict import settle
from wmrid.estimators.widening import with_hold_term, with_timing_term
from wmrid.model.robot import Robot
from wmrid.pipeline.alongside import Once, alongside
from wmrid.pipeline.friction import choose_friction
from wmrid.pipeline.timing import Timing, carry_unresolved_delay, decide_timing, observe_at, surveyed


@dataclass(frozen=True)
class Steps:
    """Which steps run beyond the observer's passes (wmrid's commands set them; the defaults run them all).

    load_terms : friction auto may take the casters' load terms (the methods that model them).  geometry : (r, b,
    x_1, y_1, ...) m, the casters' for the caster model when no robot lists them.  feedback : the closed-loop
    check.  switch : it may report IDIM/IDIM-IV instead of the observer (``--method auto``).  timing : time the
    efforts (split topics, the timing check, the hold and unresolved-delay terms) when no delay is given.
    """

    load_terms: bool = True
    geometry: tuple[float, ...] = ()
    feedback: bool = True
    switch: bool = True
    timing: bool = True

    def __post_init__(self) -> None:
        object.__setattr__(self, "geometry", tuple(float(v) for v in self.geometry))


OBSERVER_FIELDS = frozenset(f.name for f in fields(ObserverOptions))


def identify(log: LogLike | LogStream, robot: Robot | None = None, **settings: Any) -> IdentificationResult:
    """:func:`identify_log` with its options as keywords: those of :class:`ObserverOptions` (``friction`` defaults to
    "wheel" here), of :class:`Steps`, and ``progress``."""
    progress = settings.pop("progress", None)
    observer = {name: settings.pop(name) for name in list(settings) if name in OBSERVER_FIELDS}
    observer.setdefault("friction", "wheel")
    return identify_log(log, robot, ObserverOptions(**observer), Steps(**settings), progress)


def identify_log(
    log: LogLike | LogStream,
    robot: Robot | None,
    options: ObserverOptions,
    steps: Steps = Steps(),
    progress: Callable[[int, int], None] | None = None,
) -> IdentificationResult:
    """The base parameters of the robot that recorded ``log`` (the module's route).

    log : a :class:`wmrid.core.wheel_log.LogStream` (read in passes, in bounded memory, unless its efforts must be
    shifted), or a log in memory: t (n,) s strictly increasing, eta (n, 2) rad/s [right, left], tau (n, 2) N m.
    robot : the nominal values that start the estimate and centre the box (None: from the data and physics).
    ``progress(samples_done, samples)`` during the observer's passes."""
    _check_payload(robot, options.payload)
    if not isinstance(log, LogStream):  # a stream's length is known after its survey (_identified, _delayed)
        warn_if_slow(len(log.t))  # a long log without numba: how long it will take, and how to shorten it
    if options.delay is not None:
        try:
            return _settled(_delayed(log, robot, options, steps, progress), robot)
        except _WithinMisfit as within:  # --delay auto found one within the misfit: as stamped, as the default does
            undelayed, checked = replace(options, delay=None), replace(steps, timing=True)
            return _identified(log, robot, undelayed, checked, progress, within=str(within))
    return _identified(log, robot, options, steps, progress)


def _identified(
    log: LogLike | LogStream,
    robot: Robot | None,
    options: ObserverOptions,
    steps: Steps,
    progress: Callable[[int, int], None] | None,
    within: str | None = None,
) -> IdentificationResult:
    """:func:`identify_log` on the efforts as stamped, their timing checked (``steps.timing``).  ``within``: the
    warning of a delay already found within the log's misfit (``--delay auto``'s pass), not looked for again."""
    stream, sv = surveyed(log)
    if isinstance(log, LogStream):  # a log in memory was said at the start (identify_log)
        warn_if_slow(sv.n)
    chosen = Once(lambda: _choose(stream, sv, robot, options, steps, progress))
    timing = Timing()
    if steps.timing:
        # the friction models' passes run while the timing is checked (wmrid.pipeline.alongside), and serve unless it
        # applies a delay; split topics are timed first, unchecked
        meanwhile = None if split_topics(stream.notes) else chosen.run
        check = (log, stream, sv, robot, options, steps.geometry, steps.load_terms)
        timing = alongside(lambda: decide_timing(*check), meanwhile)
        if within is not None and (timing.split or timing.apply):
            timing = timing.within_misfit(within)
        elif timing.split or timing.apply:  # time the efforts by default
            try:
                timed = _settled(_delayed(log, robot, replace(options, delay="auto"), steps, progress, sv), robot)
            except _WithinMisfit as within:  # as stamped; the std carries the delay the log cannot rule out
                timing = timing.within_misfit(str(within))
            except WmridError as err:  # e.g. a hole IDIM's filter cannot bridge: as stamped, and say so
                timing = timing.failed(err)
            else:
                if timing.record is not None:  # the window's record, with what the timed run found (its hold term)
                    merged = timing.record.merged(timed.diagnostics.timing)
                    timed = replace(timed, diagnostics=replace(timed.diagnostics, timing=merged))
                return _settled(timed, robot)
    return _settled(_friction_and_terms(log, chosen(), robot, options, steps, timing), robot)


def _settled(result: IdentificationResult, robot: Robot | None) -> IdentificationResult:
    radius = None if robot is None else getattr(robot.nominal, "r", None)
    settled: IdentificationResult = settle(result, radius=None if radius is None else float(radius))
    return settled


def _check_payload(robot: Robot | None, payload: bool) -> None:
    if payload and robot is None:
        raise UsageError(
            f"{option('payload')} needs {option('robot')}: the payload is what the log shows beyond the unloaded robot"
        )
    if payload and robot is not None and not robot.physical:
        raise UsageError(
            f"{option('payload')} needs the robot's physical parameters (masses, inertias, geometry); "
            f"robot {robot.name!r} gives base parameters only"
        )


def _delayed(
    log: Any,
    robot: Robot | None,
    options: ObserverOptions,
    steps: Steps,
    progress: Callable[[int, int], None] | None,
    sv: Any = None,
) -> IdentificationResult:
    """The log's efforts read ``options.delay`` s earlier (the whole log in memory; piece by piece when it is a
    stream longer than the timing check's window, :func:`wmrid.estimators.timing_check.in_pieces`), then identified.
    "auto": the delay estimated on the whole log, or window by window beyond one window (the timing check's figure;
    :func:`wmrid.estimators.timing_check.apply_delay`, profiled with the richest friction model allowed); applied when
    significant, with the timing term: a pass at the delay moved by its resolution, whose change the std carries
    (:func:`wmrid.estimators.widening.with_timing_term`).  ``sv``: the log's survey when it was made."""
    delay = options.delay
    assert delay is not None, "_delayed is called with a delay (seconds or auto)"
    if isinstance(log, LogStream) and sv is None:
        sv = surveyed(log)[1]  # its length: a log longer than the timing check's window is shifted piece by piece
        warn_if_slow(sv.n)
    # read once when it is shifted in memory
    original = log if in_pieces(log) or not isinstance(log, LogStream) else log.read()
    profile = None
    if delay == "auto":
        auto_form = (sv if sv is not None and original is log else surveyed(original)[1]).form()
        profile = delay_profile_form(auto_form, options.friction, robot, steps.geometry, steps.load_terms)
    shifted, record, warnings = apply_delay(original, delay, options.torque_hold, options.control_rate, profile)
    applied = record.applied_s
    if delay == "auto" and applied:
        std = None if record.estimate is None else record.estimate.std_s
        assert std is not None, "an applied delay was estimated, with a finite std"
        step = max(DELAY_RESOLUTION_S, 2.0 * std)
        plain = replace(steps, feedback=False, timing=False)
        stream, sv = surveyed(shifted)
        undelayed = replace(options, delay=None)
        base = _friction_and_terms(
            shifted, _choose(stream, sv, robot, undelayed, plain, progress), robot, undelayed, plain, Timing()
        )
        base = _settled(base, robot)
        misfit = _misfit_delay(base, record)
        if misfit is not None:  # no larger than the log's misfit can make a delay appear: the caller keeps the efforts
            raise _WithinMisfit(misfit)
        at = replace(options, friction=base.form.friction, delay=applied + step)
        moved = observe_at(original, robot, at, steps.geometry)
        return _checked(with_timing_term(base, moved, record, warnings, step, robot), shifted, robot, steps)
    stream, sv = surveyed(shifted)
    chosen = Once(lambda: _choose(stream, sv, robot, options, steps, progress))
    timing = Timing(delay_record=record, delay_warnings=tuple(warnings))
    if steps.timing and delay == "auto":
        check = (shifted, stream, sv, robot, options, steps.geometry, steps.load_terms)
        noted = tuple(warnings)

        def decided() -> Timing:
            return decide_timing(*check, delay_record=record, delay_warnings=noted)

        timing = alongside(decided, chosen.run)  # the friction models' passes meanwhile
    return _friction_and_terms(shifted, chosen(), robot, options, steps, timing)


class _WithinMisfit(Exception):
    """:func:`_delayed` found the delay it was to apply within the log's misfit (:func:`_misfit_delay`; the message):
    its caller identifies the log as stamped, with the timing check's record, whose delay the std then carries
    (:func:`wmrid.pipeline.timing.carry_unresolved_delay`)."""


def _misfit_delay(result: IdentificationResult, record: Any) -> str | None:
    """The warning that the estimated delay applied to ``result``'s log is within what its misfit can make appear, or
    None when it stands.  The delay's std is its jackknife's, which sees the noise; where the log departs from the
    model (the structural test scaled every std by S), the profile's minimum also moves with the misfit, so the delay
    is judged against S times its std, as every estimate of that log is.  Measured: MuJoCo logs of the light AMR on
    a sinusoid with the casters' drag (no delay) had -0.97 +/- 0.19 ms applied at S 14, and the Coulomb friction beyond
    3 std unflagged in 20 of 20 logs; as stamped, S 19 and within 3 std."""
    unc = result.diagnostics.uncertainty
    model_error = None if unc is None else unc.model_error
    est = record.estimate
    if model_error is None or not model_error.applied or est is None or est.std_s is None:
        return None
    scale = float(model_error.scale or 1.0)
    bound = max(significance_factor(est.segments or 2) * est.std_s * scale, SIGNIFICANT_S)
    if abs(record.applied_s or 0.0) > bound:
        return None
    return (
        f"the efforts appear stamped {record.applied_s * 1e3:+.2f} +/- {est.std_s * 1e3:.2f} ms late, but the log "
        f"departs from the model (with that delay applied every std was scaled by S = {scale:.3g}), and a misfit can "
        f"make a delay appear: against S times its std it is not significant, so the efforts are used as stamped "
        f"(--delay {record.applied_s:.2g} applies it)"
    )


def _checked(result: IdentificationResult, log: Any, robot: Robot | None, steps: Steps) -> IdentificationResult:
    return feedback_check(result, log, robot, switch=steps.switch) if steps.feedback else result


def _choose(
    stream: LogStream,
    sv: Any,
    robot: Robot | None,
    options: ObserverOptions,
    steps: Steps,
    progress: Callable[[int, int], None] | None,
) -> tuple[IdentificationResult, FrictionChoice]:
    """The friction model's passes over ``stream`` (surveyed as ``sv``): :func:`wmrid.pipeline.friction.choose_friction`
    (the result, the record of the choice)."""
    return choose_friction(
        stream, sv, robot, options, geometry=steps.geometry, load_terms=steps.load_terms, progress=progress
    )


def _friction_and_terms(
    log: Any,
    chosen: tuple[IdentificationResult, FrictionChoice],
    robot: Robot | None,
    options: ObserverOptions,
    steps: Steps,
    timing: Timing,
) -> IdentificationResult:
    """The friction model chosen (``chosen``: :func:`_choose`'s), the timing's records and warnings, the
    unresolved-delay term, the closed-loop check and the hold term."""
    result, friction_record = chosen
    diagnostics = replace(result.diagnostics, friction=friction_record)
    if timing.record is not None:
        diagnostics = replace(diagnostics, timing=timing.record)
    warnings = (*timing.warnings, *result.warnings)
    if timing.delay_record is not None:
        diagnostics = replace(diagnostics, delay=timing.delay_record)
        warnings = (*timing.delay_warnings, *warnings)
    result = replace(result, diagnostics=diagnostics, warnings=warnings)
    rec = timing.record or TimingCheck()
    if result.estimate is not None:
        result = carry_unresolved_delay(result, rec, log, robot, options, steps.geometry)
    observer = result.estimate
    result = _checked(result, log, robot, steps)
    # a faster controller found and timed settles the hold; found but not timed (the re-run failed), it does not
    timed_controller = bool(rec.faster_controller) and not timing.warnings
    unknown_hold = options.torque_hold == "zoh" and options.control_rate is None and not timed_controller
    if rec.checked and rec.slow and unknown_hold and observer is not None:
        # a slow log whose controller rate is unknown: the truth lies between a hold at the log's rate (zoh) and a
        # controller much faster than the log (foh); that bracket, the std carries (the hold term)
        foh = replace(options, torque_hold="foh", friction=result.form.friction, delay=None)
        result = with_hold_term(result, observer, observe_at(log, robot, foh, steps.geometry), robot)
    return result
