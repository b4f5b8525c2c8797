"""Identification as one call: :func:`identify` (one method, optionally validated on another log) and
:func:`compare` (every method on the same log).

Both take a log as a path (read with :class:`~wmrid.api.inputs.LogOptions`), a :class:`WheelLog` or a
:class:`LogStream`, and a robot as a built-in name, a file or a :class:`Robot`.  ``wmrid identify`` and ``wmrid
compare`` are these functions with their flags translated, so the two commands cannot drift apart.

Imports inside functions: start-up time (a front door: ``import wmrid`` and each function load only what that
function uses).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Sequence
from dataclasses import dataclass, replace
from functools import partial
from typing import TYPE_CHECKING, Any, Literal, TypeGuard, cast, overload

from wmrid.api.inputs import LogOptions, given_results, load_robot, open_log
from wmrid.api.settings_checks import (  # `X as X`: re-exported for the CLI, the report and the fleet
    CASTER_METHODS,
    CONTROL_RATE_METHODS as CONTROL_RATE_METHODS,
    LOAD_METHODS,
    check_control_rate,
    check_rotor_inertia as check_rotor_inertia,
    check_validation as check_validation,
    friction_model,
    no_two_stdin,
    settings_from as settings_from,
    settings_given as settings_given,
)
from wmrid.core.errors import UsageError, cannot_read, option
from wmrid.core.wheel_log import LogStream, WheelLog
from wmrid.estimators.options import MethodOptions, ObserverOptions
from wmrid.estimators.records import Validation
from wmrid.estimators.result import IdentificationResult
from wmrid.model.robot import Robot

if TYPE_CHECKING:  # the methods (numba kernels, ~0.3 s to import) load when compare runs, not with this module
    from wmrid.estimators.methods import Comparison

__all__ = ["CASTER_METHODS", "compare", "identify", "validate"]

LogInput = str | os.PathLike[str] | Sequence[str | os.PathLike[str]] | WheelLog | LogStream


def robot_for(
    robot: str | os.PathLike[str] | Robot | None, options: LogOptions | None, rotor_inertia: float | None
) -> Robot | None:
    """The robot, loaded with the log options' gear ratio and wheel radius (a URDF needs the gear ratio)."""
    if robot is None:
        return None
    opts = options or LogOptions()
    return load_robot(robot, gear_ratio=opts.gear_ratio, rotor_inertia=rotor_inertia, wheel_radius=opts.wheel_radius)


def load_truth(truth: dict[str, float] | str | os.PathLike[str] | None) -> dict[str, float] | None:
    """True base parameters by name: a dict as it is, or the "parameters" of a truth file (the simulator's
    sidecar ``LOG.truth.json``)."""
    if truth is None or isinstance(truth, dict):
        return truth
    import json

    from wmrid.runtime.atomic import register_input

    path = os.fspath(truth)
    register_input(path)
    try:
        with open(path, encoding="utf-8") as fh:
            return {k: float(v) for k, v in json.load(fh)["parameters"].items()}
    except OSError as err:
        raise UsageError(f"{option('truth', path)}: {cannot_read(err)}") from err
    except (ValueError, KeyError, TypeError, AttributeError, RecursionError) as err:
        raise UsageError(f"{option('truth', path)}: not a truth file {{'parameters': {{'m11': ...}}}} ({err})") from err


def _is_path(log: object) -> TypeGuard[str | os.PathLike[str] | Sequence[str | os.PathLike[str]]]:
    """A path, or several (the files of one recording)."""
    if isinstance(log, (list, tuple)):
        return bool(log) and all(isinstance(p, (str, os.PathLike)) for p in log)
    return isinstance(log, (str, os.PathLike))


def _given(log: Any) -> str:
    """A log as the caller named it: the path as given (the first of several, and how many more), else the source
    it was read from."""
    if _is_path(log) and isinstance(log, (list, tuple)):
        return os.fspath(log[0]) + (f" (+{len(log) - 1} more)" if len(log) > 1 else "")
    return os.fspath(log) if isinstance(log, (str, os.PathLike)) else str(getattr(log, "source", "log"))


@overload
def _log(log: LogInput, options: LogOptions | None, robot: Robot | None, whole: Literal[True]) -> WheelLog: ...
@overload
def _log(log: LogInput, options: LogOptions | None, robot: Robot | None, whole: bool) -> WheelLog | LogStream: ...
def _log(log: LogInput, options: LogOptions | None, robot: Robot | None, whole: bool) -> WheelLog | LogStream:
    """The log as a stream (``whole`` False) or in memory; a simulated log (``wmrid.simulate(...).log``) as the
    :class:`WheelLog` it stands for."""
    if hasattr(log, "to_wheel_log"):
        log = log.to_wheel_log()
    if _is_path(log):
        stream = open_log(log, options, robot=robot)
        return stream.read() if whole else stream
    if whole and isinstance(log, LogStream):
        return log.read()
    return cast("WheelLog | LogStream", log)  # not a path: a log already read (a stream only when not whole)


def validate(
    result: IdentificationResult,
    log: LogInput,
    options: LogOptions | None = None,
    *,
    robot: Robot | None = None,
) -> IdentificationResult:
    """Validate ``result`` on another log of the same robot: the fit % per wheel of its model's simulated speeds.

    The model's wheel speeds are simulated open loop from ``log``'s efforts, each effort held as the result's
    observer held it (the predictor holds each logged effort over its whole step: a controller rate is not
    modelled, and the command line refuses ``--validate`` with ``--control-rate``, :func:`check_validation`).  The
    estimate is unchanged: validation only adds output.

    Parameters
    ----------
    result
        The identification to validate.
    log
        Another log of the same robot: a path, or a log already read.
    options
        How to read ``log`` (:class:`~wmrid.api.inputs.LogOptions`).
    robot
        The robot, which fills in the log's units as for :func:`identify`.

    Returns
    -------
    IdentificationResult
        ``result`` with its ``validation`` (:class:`~wmrid.estimators.records.Validation`) set.

    Raises
    ------
    UsageError
        ``log``'s effort is not in the unit of the identified model's.
    """
    from wmrid.model.predict import unsimulated, validation_fit

    other_log = _log(log, options, robot, whole=True)
    unit = result.log_info.effort_unit
    if other_log.effort_unit != unit:
        raise UsageError(
            f"{option('validate', _given(log))}: its effort is in {other_log.effort_unit}, "
            f"the identified model's in {unit}; give both logs in the same units"
        )
    assert result.estimate is not None  # identify's results carry one (a document from before schema 1 does not)
    theta0 = result.estimate.theta0
    form = result.form if len(theta0) == result.form.n_base else None
    definition = "fit = 100 (1 - ||eta - eta_hat|| / ||eta - mean(eta)||) per wheel over the whole log"
    why = unsimulated(form)
    if why:
        validation = Validation(other_log.source, len(other_log), definition, {"eta_r": None, "eta_l": None}, None, why)
        return replace(result, validation=validation, warnings=(*result.warnings, f"--validate: {why}"))
    torque_hold = result.settings.torque_hold
    fit = validation_fit(other_log.t, other_log.eta, other_log.tau, theta0, torque_hold, form=form)
    # the fits are floats (validation_fit's dict also holds the predictor's sentence)
    percent: dict[str, float | None] = {
        w: cast(float, fit[w]) if math.isfinite(cast(float, fit[w])) else None for w in ("eta_r", "eta_l")
    }
    validation = Validation(other_log.source, len(other_log), definition, percent, str(fit["predictor"]))
    return replace(result, validation=validation)


def identify(
    log: LogInput,
    robot: str | os.PathLike[str] | Robot | None = None,
    *,
    method: str = "auto",
    options: LogOptions | None = None,
    observer: ObserverOptions | None = None,
    fit: MethodOptions | None = None,
    given: Any = None,
    progress: Callable[[int, int], None] | None = None,
) -> IdentificationResult:
    """The base parameters [m11 m12 m22 Vc Fv1 Fv2 Fd1 Fd2] of the robot that recorded ``log``.

    Parameters
    ----------
    log
        A path (CSV, Parquet, MCAP, a bag; ``"-"`` standard input), read with ``options``, or a log already read
        (:class:`WheelLog`, :class:`LogStream`).
    robot
        A built-in name, a robot file (TOML; a URDF with ``options.gear_ratio``) or a :class:`Robot`
        (:func:`wmrid.load_robot`): the start value, the nominal/CAD values to compare with, and the defaults of the
        log's units.  None: a start value from the data.
    method
        "auto" (the observer, or the IDIM/IDIM-IV estimate when the closed-loop check finds the observer's biased by
        feedback, said in the first warning), "observer" (the paper's, always reported), "idim", "iv", "rls" or "oe"
        (:data:`wmrid.estimators.methods.METHODS`): a method named is the method reported.
    options
        How to read a log given as a path (:class:`~wmrid.api.inputs.LogOptions`; None: the defaults).
    observer
        The observer's options (:class:`~wmrid.estimators.options.ObserverOptions`: form, gains, box, hold, control
        rate, delay, friction model, payload); every method starts from the observer's run.
    fit
        The classical methods' options (:class:`~wmrid.estimators.options.MethodOptions`: cutoff, weighting,
        forgetting factor).
    given
        Results of earlier logs of the same robot (paths of saved results, ``wmrid identify --format json``, or
        :class:`IdentificationResult` objects; one or several): the result is this log's estimate combined with
        theirs (:mod:`wmrid.estimators.combination`; what ``wmrid plan --given`` predicts).
    progress
        Called as ``progress(done, total)``, in samples, while the observer replays the log.

    Returns
    -------
    IdentificationResult
        The result; ``result.parameters[name]`` is (value, std) in SI units.  :func:`validate` predicts another log
        with it.
    """
    prep = prepare(method, observer, fit, options=options, robot=robot)
    earlier = given_results(given)  # read (and refused) before the log
    # the observer streams the log; the classical methods filter and simulate the whole log
    wheel_log = _log(log, options, prep.robot, whole=prep.method != "observer")
    return run_prepared(wheel_log, prep, progress=progress, given=earlier)


@dataclass(frozen=True)
class Prepared:
    """What :func:`prepare` checked and loaded: the method, its options, the robot, the observer's options with the
    friction model settled."""

    method: str
    fit: MethodOptions
    robot: Robot | None
    observer: ObserverOptions
    #: the method was left to wmrid (``method="auto"``): the closed-loop check may report IDIM or IDIM-IV instead of
    #: the observer, and says so first; a method the user names is the method reported
    auto_method: bool = False
    #: why ``friction="auto"`` was settled before the log was read (a method that cannot model caster drag), or None
    friction_reason: str | None = None

    @property
    def friction(self) -> str:
        return self.observer.friction


def prepare(
    method: str = "auto",
    observer: ObserverOptions | None = None,
    fit: MethodOptions | None = None,
    *,
    options: LogOptions | None = None,
    robot: str | os.PathLike[str] | Robot | None = None,
    rotor_inertia: float | None = None,
    validating: bool = False,
) -> Prepared:
    """The checks :func:`identify` makes before it reads anything, in the command line's order (the method, the
    rotor inertia, the control rate where the method models it, the robot, the friction model); the options
    objects checked themselves when made.  ``rotor_inertia``: a URDF robot's (kg m^2, when it has no rotor links);
    ``validating``: a validation follows (:func:`check_validation`)."""
    from wmrid.estimators.methods import check_method

    observer = observer if observer is not None else ObserverOptions()
    fit = fit if fit is not None else MethodOptions()
    check_rotor_inertia(rotor_inertia)
    auto_method = method == "auto"
    method = "observer" if auto_method else check_method(method)
    check_control_rate(observer.control_rate, (method,), validating)
    robot_obj = robot_for(robot, options, rotor_inertia)
    friction = observer.friction
    model = friction_model(friction, (method,), validating, robot_obj)
    reason = None
    if friction == "auto" and model != "auto":
        reason = (
            f"{option('method', method)} cannot model caster drag"
            if method not in CASTER_METHODS
            else f"{option('method', method)} simulates the drag, which needs the casters' positions (a robot file "
            "with [[caster]] tables)"
        )
    return Prepared(method, fit, robot_obj, replace(observer, friction=model), auto_method, reason)


def run_prepared(
    wheel_log: WheelLog | LogStream,
    prep: Prepared,
    *,
    progress: Callable[[int, int], None] | None = None,
    given: Sequence[tuple[IdentificationResult, str]] = (),
) -> IdentificationResult:
    """:func:`identify` on a log already read, with what :func:`prepare` checked and loaded: the pipeline
    (:func:`wmrid.pipeline.identify.identify_log`), then the chosen method's fit, then the combination with
    ``given`` (earlier results already read, :func:`wmrid.api.inputs.given_results`)."""
    from wmrid.pipeline.identify import Steps, identify_log

    steps = Steps(
        load_terms=prep.method in LOAD_METHODS,  # the load terms only where the method models them
        feedback=prep.method == "observer",  # another method is reported as asked
        switch=prep.auto_method,
    )  # fmt: skip
    result = identify_log(wheel_log, prep.robot, prep.observer, steps, progress)
    if prep.friction_reason:
        from wmrid.estimators.findings import FrictionChoice

        friction_record = FrictionChoice(model=prep.friction, chosen_by="auto", reason=prep.friction_reason)
        result = replace(result, diagnostics=replace(result.diagnostics, friction=friction_record))
    if prep.method != "observer":
        from wmrid.estimators.methods import run

        result = run(prep.method, wheel_log, result, prep.fit, prep.robot)
    if given:
        from wmrid.estimators.combination import combined_result

        result = combined_result(result, given, robot=prep.robot)
    return result


def compare(
    log: LogInput,
    robot: str | os.PathLike[str] | Robot | None = None,
    *,
    methods: tuple[str, ...] | list[str] | None = None,
    options: LogOptions | None = None,
    observer: ObserverOptions | None = None,
    fit: MethodOptions | None = None,
    validate: LogInput | None = None,
    truth: dict[str, float] | str | os.PathLike[str] | None = None,
    stage: Callable[[str], None] | None = None,
) -> Comparison:
    """Every method in ``methods`` on the same log: estimates, standard errors, flags, errors, fit, run time.

    Each method identifies the same friction model; the observer's own estimate is shown as it is (no closed-loop
    substitution).

    Parameters
    ----------
    log
        The log, as for :func:`identify`: a path read with ``options``, or a log already read.
    robot
        The robot, as for :func:`identify`.
    methods
        The methods to run (None: all of :data:`wmrid.estimators.methods.METHODS`).
    options
        How to read ``log`` and ``validate`` when they are paths (:class:`~wmrid.api.inputs.LogOptions`).
    observer
        The observer's options, as for :func:`identify` (every method starts from the observer's run; with
        ``observer.payload`` each row has its payload).
    fit
        The classical methods' options, as for :func:`identify`.
    validate
        Another log of the same robot, on which each method's fit is computed (None: none).
    truth
        The true base parameters by name, or the path of a truth file (the simulator's sidecar ``LOG.truth.json``,
        whose "parameters" are read): each method's errors are against them (None: no errors).
    stage
        Called with what the comparison does now (reading the log, each method), for a progress display.

    Returns
    -------
    Comparison
        Every method's row (:class:`~wmrid.estimators.methods.Comparison`); its ``to_dict`` is the document
        ``wmrid compare --format json`` prints.

    Raises
    ------
    UsageError
        ``methods`` names no method, or ``validate``'s effort is not in the unit of ``log``'s.
    """
    from wmrid.estimators.methods import METHODS, check_method, compare as run_compare
    from wmrid.pipeline.identify import Steps, identify_log

    observer = observer if observer is not None else ObserverOptions()
    fit = fit if fit is not None else MethodOptions()
    names = tuple(check_method(m.strip()) for m in (METHODS if methods is None else methods) if m.strip())
    if not names:
        raise UsageError(f"{option('methods')} names no method; give e.g. observer,idim")
    validating = validate is not None
    check_control_rate(observer.control_rate, names, validating)
    no_two_stdin(log, validate, option("log"))
    truth = load_truth(truth)
    robot_obj = robot_for(robot, options, None)
    # every method with the friction model identify --method NAME would use: the ones that model caster drag share
    # the observer's (auto: chosen by its drag test); output error without the casters' positions cannot simulate the
    # two-term drag and is run on the wheel-friction model, which its row says
    drag_methods = tuple(m for m in names if m != "oe") or names
    friction = observer.friction
    friction_ = friction_model(friction, drag_methods, validating, robot_obj)
    say = stage or (lambda text: None)
    say("reading the log")
    wheel_log = _log(log, options, robot_obj, whole=True)
    other = None
    if validate is not None:
        other = _log(validate, options, robot_obj, whole=True)
        if other.effort_unit != wheel_log.effort_unit:
            raise UsageError(
                f"{option('validate', _given(validate))}: its effort is in {other.effort_unit}, "
                f"{option('log')}'s in {wheel_log.effort_unit}; give both logs in the same units"
            )
    say("the observer's run")
    # the observer's column is identify --method observer's: the closed-loop check widens it, never swaps it
    load_terms = all(m in LOAD_METHODS for m in names)  # the other methods share the observer's model
    observed = identify_log(
        wheel_log, robot_obj, replace(observer, friction=friction_), Steps(load_terms=load_terms, switch=False)
    )
    wheel_only = "oe" in names and friction_model(friction, ("oe",), validating, robot_obj) != observed.form.friction
    run = partial(run_compare, other=other, truth=truth, stage=stage, robot=robot_obj)
    if not wheel_only:
        return run(wheel_log, observed, fit, names)
    shared = tuple(m for m in names if m != "oe")
    first = run(wheel_log, observed, fit, shared) if shared else None
    say("the observer's run with wheel friction (for oe)")
    plain = identify_log(wheel_log, robot_obj, replace(observer, friction="wheel"), Steps(feedback=False))
    oe = run(wheel_log, plain, fit, ("oe",))
    said = (
        f"friction: wheel, not the observer's {observed.form.friction}: output error simulates the drag, which needs "
        "the casters' positions (a robot file with [[caster]] tables)"
    )
    row = replace(oe.methods["oe"], warnings=(said, *oe.methods["oe"].warnings))
    shared_rows = first.methods if first is not None else {}  # no first run: oe is the only method
    rows = {m: (row if m == "oe" else shared_rows[m]) for m in names}
    return replace(first or oe, methods=rows)
