"""Identification of a whole log: settings from the robot or the data, the compiled replay, the result.

Pure with respect to files: takes arrays (a :class:`WheelLog`-like object) and returns a frozen
:class:`IdentificationResult`; the CLI does the reading and printing.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any, Literal

import numpy as np

from wmrid.core.choices import Friction, values
from wmrid.core.errors import NotIdentifiableError, UsageError, WmridError, option
from wmrid.core.wheel_log import LogStream, stream_arrays
from wmrid.estimators.diagnostics import (
    AUTO_NO_REVERSAL,
    AUTO_P,
    START_RELEVANT,
    caster_drag_test,
    control_rate_check,
    diagnose,
    start_sensitivity,
    torque_unexcited,
    unexcited_parameters,
)
from wmrid.estimators.estimate import BaseEstimate, SegmentEstimates
from wmrid.estimators.model_error import (
    misfit_text,
    record_widening,
    widen,
)
from wmrid.estimators.noise_floor import derived_lag
from wmrid.estimators.observer import ObserverSettings
from wmrid.estimators.observer_kernel import project_history_box
from wmrid.estimators.replay import replay_pieces
from wmrid.estimators.result import History, IdentificationResult, LogLike, ObserverRun, finite_or_none, reported_names
from wmrid.estimators.sign_speed import sign_half_window
from wmrid.estimators.survey import Survey, survey
from wmrid.estimators.uncertainty import estimate_covariances, interval_factor, jackknife_deltas, segments_of
from wmrid.estimators.widening import carry_unresolved_delay, with_hold_term, with_timing_term
from wmrid.model import dynamics as model
from wmrid.model.base_params import derived_with_std, fit_base_parameters, weighting_covariance
from wmrid.model.dynamics import RegressorForm
from wmrid.model.robot import Robot

#: A time step longer than GAP_FACTOR median steps (and GAP_MIN_S) is a hole the estimator cannot bridge.
GAP_FACTOR = 1000.0


GAP_MIN_S = 1.0


#: What the standard errors do not cover, with the coverage measured in simulation (bench/bench_coverage.py).
CLOSED_LOOP_CAVEAT = (
    "in closed loop a coloured disturbance (a caster, the floor) reaches the efforts through the controller and "
    "biases the observer's inertia entries and Vc; the closed-loop check (diagnostics.feedback, "
    "wmrid.feedback) compares it with IDIM (IDIM-IV when the log has the reference) and reports that "
    "one when they differ beyond "
    "noise, else widens the std by the difference when a disturbance shows (light 14 kg AMR, 0.02 N m disturbance: "
    "m11, m22, Vc within 3 std in 97 % of 40 s logs and 100 % of 160 s logs, was 70-82 %)"
)


def caster_geometry(robot: Robot) -> tuple[float, ...]:
    """(r, b, x_1, y_1, ...) for the geometric caster model of ``robot`` (nominal r, b; its casters).

    Two casters at (x, y) and (-x, y) have the same drag columns (their contacts' velocities mirror each
    other about the platform's x axis), so the log can only tell their total drag: they are merged into one
    parameter, listed once (casters within 1 mm of such a pair count as one).
    """
    seen: list[tuple[float, float]] = []
    for c in robot.casters or ():
        key = (abs(c.x), c.y)
        if not any(abs(key[0] - s[0]) < 1e-3 and abs(key[1] - s[1]) < 1e-3 for s in seen):
            seen.append(key)
    return (robot.nominal.r, robot.nominal.b, *[v for key in seen for v in key])


def delay_profile_form(
    auto: RegressorForm, friction: str, robot: Robot | None, geometry: tuple[float, ...], load_terms: bool
) -> RegressorForm | None:
    """The friction model the efforts' delay is profiled with (:func:`wmrid.estimators.delay.estimate_delay`): the
    richest that ``friction`` lets identify choose for this log (``auto``: the survey's form), None for the wheels'
    friction alone (``--friction wheel``, or wheels that never stop or reverse, where no caster drag can be told).

    Why: a drag the profile does not model is fitted by shifting the efforts.  On the paper robot's MuJoCo plan log
    (ball casters whose drag is about five times the wheels' Coulomb friction, speed noise 0.02 rad/s) the wheels'
    model put the efforts 18.5 +/- 2.4 ms late, "significant", and identify applied it: every parameter poorly
    determined (S 132; F_v2 off by -190 %).  With the casters' two-term model the same log gives 0.7 +/- 0.9 ms, with
    their load model 0.04 +/- 0.11 ms (the simulator has no delay)."""
    if friction == "wheel" or auto.kind == "paper":
        return None
    geom = caster_geometry(robot) if robot is not None and robot.casters else tuple(geometry)
    load = bool(geom) and (friction == "wheel+caster+load" or (friction == "auto" and load_terms))
    return resolve_form(auto, "auto", True, geom, load)


def resolve_form(
    auto: RegressorForm,
    choice: Literal["auto", "paper", "general"],
    caster: bool = False,
    geometry: tuple[float, ...] = (),
    load: bool = False,
) -> RegressorForm:
    """The regressor form: ``auto`` picks ``auto`` (the paper form when each wheel keeps one sign); caster drag
    needs the general form (``geometry``: see :class:`wmrid.model.dynamics.RegressorForm`; ``load``: the drag
    follows the casters' load, :func:`wmrid.model.dynamics.load_signals`, which needs the geometry)."""
    if load and not geometry:
        raise UsageError(
            f"{option('friction', 'wheel+caster+load')} needs the casters' positions (the robot file's [[caster]] "
            "tables)"
        )
    if caster:
        if choice == "paper":
            raise UsageError(
                f"{option('friction', 'wheel+caster')} needs the general form ({option('form', 'general')} or auto), "
                "not "
                "paper"
            )
        signals = model.load_signals(geometry) if load else ()
        return RegressorForm("general", caster=True, geometry=geometry, load=signals)
    if choice == "auto":
        return auto
    if choice == "paper":
        if auto.kind != "paper":
            raise UsageError(
                f"{option('form', 'paper')} needs each wheel to keep one strict sign over the log, but a wheel stops "
                "or "
                f"reverses; use {option('form', 'general')} (or auto)"
            )
        return auto
    if choice == "general":
        return RegressorForm("general")
    raise UsageError(f"{option('form')} must be auto, paper or general, got {choice!r}")


def default_box(
    theta_init: np.ndarray, form: RegressorForm, width: float, from_robot: bool
) -> tuple[np.ndarray, np.ndarray]:
    """The parameter box [theta_min, theta_max], (2, p) each.

    Physics first: the diagonal of m = M^-1 is positive, and so are m_11 F_v1, m_22 F_v2 (and, in the
    general form, m_11 F_d1, m_22 F_d2).  With a robot file the box is also centred on the nominal
    intermediate parameters with half-width ``width`` times max(|theta_ij|, m_ii) -- a sanity box, wide
    enough never to bind on a robot near its description.  Without one, only the signs are bounded.
    """
    lo = np.full(theta_init.shape, -np.inf)
    hi = np.full(theta_init.shape, np.inf)
    if from_robot and math.isfinite(width):
        for i in range(2):
            floor = abs(theta_init[i, i])
            half = width * np.maximum(np.abs(theta_init[i]), floor)
            lo[i] = theta_init[i] - half
            hi[i] = theta_init[i] + half
    lo[0, 0] = max(lo[0, 0], 0.0)
    lo[1, 1] = max(lo[1, 1], 0.0)
    lo[0, 4] = max(lo[0, 4], 0.0)
    lo[1, 5] = max(lo[1, 5], 0.0)
    if form.kind == "general":
        lo[0, 6] = max(lo[0, 6], 0.0)
        lo[1, 7] = max(lo[1, 7], 0.0)
    return lo, hi


def identify(log: LogLike | LogStream, robot: Robot | None = None, **settings: Any) -> IdentificationResult:
    """Identify the base parameters of the robot that recorded ``log`` (:func:`identify_log`, whose keywords it
    takes), with every statement about them made from the final numbers (:func:`wmrid.estimators.verdict.settle`):
    the warnings' std, the flags, the units check against ``robot``, the verdict."""
    from wmrid.estimators.verdict import settle

    result = identify_log(log, robot, **settings)
    radius = None if robot is None else getattr(robot.nominal, "r", None)
    return settle(result, radius=None if radius is None else float(radius))


def identify_log(
    log: LogLike | LogStream,
    robot: Robot | None = None,
    *,
    form: Literal["auto", "paper", "general"] = "auto",
    k: float = 10.0,
    alpha: float = 1e-10,
    box_width: float = 10.0,
    max_history: int = 20000,
    torque_hold: Literal["zoh", "foh"] = "zoh",
    progress: Callable[[int, int], None] | None = None,
    payload: bool = False,
    control_rate: float | None = None,
    friction: Literal["wheel", "wheel+caster", "wheel+caster+load", "auto"] = "wheel",
    load_terms: bool = True,
    geometry: tuple[float, ...] = (),
    delay: float | Literal["auto"] | None = None,
    feedback: bool = True,
    timing: bool = True,
    switch: bool = True,
) -> IdentificationResult:
    """Identify the base parameters of the robot that recorded ``log``.

    log : a :class:`wmrid.core.wheel_log.LogStream` (read in two passes, a survey and the replay, in bounded
    memory), or a log in memory with t (n,) s strictly increasing, eta (n, 2) rad/s [right, left],
    tau (n, 2) N m.
    ``robot`` gives the nominal values that start the estimate and centre the box (as in the paper);
    without it the start and box come from the data and physics (see :meth:`wmrid.estimators.survey.Survey.data_start`,
    :func:`default_box`).
    ``payload``: also estimate the payload the robot carries, against the robot's unloaded parameters
    (its CAD set, else nominal; :mod:`wmrid.model.payload`).  ``progress(samples_done, samples)`` during the replay.
    ``control_rate`` : Hz, the rate of the controller that held the effort, when the log is slower
    (see :class:`wmrid.estimators.observer.ObserverSettings`).  ``friction``: ``wheel`` (Eqs. 15-17) or ``wheel+caster``
    (also the casters' rolling drag, :func:`wmrid.model.dynamics.caster_columns`: with the robot's casters
    (``robot.casters``) one drag force D_k per caster, else the two-term Cv, Cw; general form only), or
    ``auto``: both, and the caster model when a Wald test puts its drag off zero at p < AUTO_P (never on a log
    whose wheels keep one sign); with the casters' positions and ``load_terms``, then also ``wheel+caster+load``
    (the drag follows the casters' normal load as it accelerates, :func:`wmrid.model.dynamics.caster_columns`),
    taken when a Wald test puts its load terms off zero at p < AUTO_P.  ``diagnostics["friction"]`` states the
    model and why.
    ``geometry`` : (r, b, x_1, y_1, ...) m, the geometric caster model's when no robot lists casters (a
    saved model's ``form.geometry``, say; :func:`caster_geometry` builds it from a robot, whose casters win).
    ``delay`` : s, how late the efforts are stamped against the speeds (two topics, two clocks): they are read
    that much earlier (:func:`wmrid.estimators.idim_regression.shifted`; the log is then read into memory);
    ``"auto"``: estimated
    from the log (:func:`wmrid.estimators.delay.estimate_delay`) and applied when significant; None: as stamped,
    unless the
    reading notes say the efforts came from another topic than the speeds (:func:`wmrid.core.wheel_log.split_topics`),
    then ``"auto"`` (with ``timing``).
    ``diagnostics["delay"]`` states what was estimated and applied.
    ``feedback`` : run the closed-loop check (:func:`wmrid.estimators.feedback.check`): when the observer's estimate
    differs
    from IDIM's (IDIM-IV's, when the log has the wheel-speed reference) beyond noise, report that one instead, with a
    warning first (``switch``; else keep the observer's, its std widened by the difference, and say so);
    ``diagnostics["feedback"]`` states what was compared.  ``timing`` : without ``delay``, time the efforts
    by default: split topics (above), and the timing check (:func:`wmrid.estimators.delay.timing_check`,
    ``diagnostics["timing"]``): a delay estimated significant is applied as by ``delay="auto"`` (whose warning names
    --control-rate when a controller faster than the log explains it); on a log slower than 400 Hz whose hold is
    unknown, the std carries the difference between zoh and foh (the hold term).  A log that cannot be timed is used
    as stamped, with a warning.
    """
    if friction not in FRICTION_CHOICES:
        raise UsageError(f"{option('friction')} must be one of {', '.join(FRICTION_CHOICES)}, got {friction!r}")

    timing_record: dict[str, Any] | None = None  # the timing check's, when it runs (below)

    def checked(result: IdentificationResult, log_read: Any) -> IdentificationResult:
        if not feedback:
            return result
        from wmrid.estimators.feedback import check

        return check(result, log_read, robot, switch=switch)

    if payload and robot is None:
        raise UsageError(
            f"{option('payload')} needs {option('robot')}: the payload is what the log shows beyond the unloaded robot"
        )
    if payload and not robot.physical:
        raise UsageError(
            f"{option('payload')} needs the robot's physical parameters (masses, inertias, geometry); "
            f"robot {robot.name!r} gives base parameters only"
        )
    check_box_width(box_width)
    delay_record = None
    delay_warnings: list[str] = []
    if delay is not None:
        from wmrid.estimators.delay import DELAY_RESOLUTION_S, apply_delay

        original = log.read() if isinstance(log, LogStream) else log  # read once: shifting needs the whole log
        profile = None
        if delay == "auto":
            whole = stream_arrays(original)
            profile = delay_profile_form(
                survey(whole, whole.source, whole.effort_unit).form(), friction, robot, tuple(geometry), load_terms
            )  # fmt: skip
        log, delay_record, delay_warnings = apply_delay(original, delay, torque_hold, control_rate, profile)
        applied = delay_record["applied_s"]
        if delay == "auto" and applied:
            # the timing term: identify again at the delay moved by its uncertainty; what that moves, the std carries
            step = max(DELAY_RESOLUTION_S, 2.0 * delay_record["std_s"])
            common = {
                "form": form, "k": k, "alpha": alpha, "box_width": box_width, "max_history": max_history,
                "torque_hold": torque_hold, "payload": payload, "control_rate": control_rate, "geometry": geometry,
            }  # fmt: skip
            base = identify(log, robot, friction=friction, feedback=False, timing=False, progress=progress, **common)
            moved = identify(
                original, robot, friction=base.form.friction, delay=applied + step, feedback=False, timing=False,
                **common,
            )  # fmt: skip
            return checked(with_timing_term(base, moved, delay_record, delay_warnings, step, robot), log)
    stream = log if isinstance(log, LogStream) else stream_arrays(log)
    sv = survey(stream, stream.source, stream.effort_unit)  # one survey pass, whichever models are fitted
    timing_warnings: list[str] = []
    if timing and (delay is None or (delay == "auto" and not (delay_record or {}).get("applied_s"))):
        from wmrid.core.wheel_log import split_topics
        from wmrid.estimators.delay import timing_check

        split = split_topics(stream.notes)
        if not split:
            profile = delay_profile_form(sv.form(), friction, robot, tuple(geometry), load_terms)
            timing_record = timing_check(log, torque_hold, control_rate, sv.n, sv.median_step, profile)
            if timing_record.get("note"):  # a delay the wheels' model alone shows, explained by the casters' drag
                timing_warnings.append(timing_record["note"])
        # efforts and speeds from two topics, or a significant delay: time the efforts by default
        if delay is None and (split or (timing_record or {}).get("apply")):
            try:
                timed = identify(
                    log, robot, form=form, k=k, alpha=alpha, box_width=box_width, max_history=max_history,
                    torque_hold=torque_hold, progress=progress, payload=payload, control_rate=control_rate,
                    friction=friction, geometry=geometry, delay="auto", feedback=feedback, switch=switch,
                )  # fmt: skip
            except WmridError as err:  # e.g. a hole IDIM's filter cannot bridge: as stamped, and say so
                timing_warnings.append(f"the efforts could not be timed against the speeds ({err}); used as stamped")
            else:
                if timing_record is None:
                    return timed
                # the window's record, with what the timed run found on the whole log (e.g. its hold term)
                merged = {**timing_record, **(timed.diagnostics.get("timing") or {})}
                return replace(timed, diagnostics={**timed.diagnostics, "timing": merged})

    def run(caster: bool, load: bool = False) -> IdentificationResult:
        try:
            return _identify(
                stream, sv, robot, form, k, alpha, box_width, max_history, torque_hold, progress, payload,
                control_rate, caster, geometry, load,
            )  # fmt: skip
        except np.linalg.LinAlgError as err:
            raise NotIdentifiableError(
                f"{stream.source}: the log does not support an estimate (a singular system: {err}); it is too short, "
                "not exciting enough, or its units or time stamps are wrong (check the notes of wmrid inspect)"
            ) from err

    def finish(result: IdentificationResult, friction_record: dict[str, Any]) -> IdentificationResult:
        result = _with_friction(result, friction_record)
        if timing_record is not None:
            result = replace(result, diagnostics={**result.diagnostics, "timing": timing_record})
        if timing_warnings:
            result = replace(result, warnings=tuple(timing_warnings) + tuple(result.warnings))
        if delay_record is not None:
            diagnostics = {**result.diagnostics, "delay": delay_record}
            result = replace(result, diagnostics=diagnostics, warnings=tuple(delay_warnings) + tuple(result.warnings))
        rec = timing_record or {}
        if result.estimate is not None:
            result = carry_unresolved_delay(result, rec, log, robot, form, k, alpha, box_width, max_history,
                                             torque_hold, control_rate, geometry)  # fmt: skip
        observer = result.estimate
        result = checked(result, log)
        # a faster controller found and timed settles the hold; found but not timed (the re-run failed), it does not
        timed_controller = bool(rec.get("faster_controller")) and not timing_warnings
        unknown_hold = torque_hold == "zoh" and control_rate is None and not timed_controller
        if rec.get("checked") and rec.get("slow") and unknown_hold and observer is not None:
            # a slow log whose controller rate is unknown: the truth lies between a hold at the log's rate (zoh)
            # and a controller much faster than the log (foh); that bracket, the std carries (the hold term)
            other = identify(
                log, robot, form=form, k=k, alpha=alpha, box_width=box_width, max_history=max_history,
                torque_hold="foh", payload=False, friction=result.form.friction, geometry=geometry, feedback=False,
                timing=False,
            )  # fmt: skip
            result = with_hold_term(result, observer, other, robot)
        return result

    if friction != "auto":
        result = run(friction != "wheel", friction == "wheel+caster+load")
        return finish(result, {"model": friction, "chosen_by": "--friction"})
    wheel = run(False)
    if wheel.form.kind == "paper":
        return finish(wheel, {"model": "wheel", "chosen_by": "auto", "reason": AUTO_NO_REVERSAL})
    try:
        caster = run(True)
    except NotIdentifiableError as err:
        return finish(wheel, {"model": "wheel", "chosen_by": "auto", "reason": f"caster model failed: {err}"})
    choice = caster_drag_test(caster)
    significant = choice["p_value"] < AUTO_P
    chosen = caster if significant and not choice["negative"] else wheel
    reason = f"the caster drag ({choice['text']}) differs from zero at p = {choice['p_value']:.2g}" + (
        f" < {AUTO_P:g}" if significant else f" >= {AUTO_P:g}: not shown by this log"
    )
    if significant and choice["negative"]:
        reason += (
            f", but {', '.join(choice['negative'])} would push the robot, which no caster does: not a caster's drag "
            "(a sign, a unit, or an effect neither model has), so the wheel model is kept"
        )
    record = {"model": chosen.form.friction, "chosen_by": "auto", "reason": reason, **choice}
    if chosen is caster and caster.form.geometry and load_terms:
        chosen, record = _with_load(chosen, record, lambda: run(True, True))
    return finish(chosen, record)


def _with_load(
    caster: IdentificationResult, record: dict[str, Any], run_load: Callable[[], IdentificationResult]
) -> tuple[IdentificationResult, dict[str, Any]]:
    """``--friction auto`` after the caster model was chosen: the ``wheel+caster+load`` model too, taken when a Wald
    test puts its load terms off zero at p < AUTO_P (:func:`caster_drag_test` on them) and the log departs from it
    no more than from the caster model (its model-error scale S, :func:`wmrid.estimators.model_error.widen`, not
    larger); the record says why.

    The second condition guards against load terms that fit something else and move the fit away from the model
    instead of towards it.  (The case that motivated it -- the paper robot's MuJoCo plan log at 0.02 rad/s: D1dv
    -0.91 N s^2/m for the engine's -0.43, S 189 where the caster model had 133 -- was a delay the timing check had
    invented from the casters' drag, :func:`delay_profile_form`; profiled with the drag, the same log takes the load
    model with S 1.0 and D1dv -0.48.)"""
    try:
        loaded = run_load()
    except NotIdentifiableError as err:
        return caster, {**record, "load": {"taken": False, "reason": f"load model failed: {err}"}}
    test = caster_drag_test(loaded, loaded.form.base_names[8 + loaded.form.n_casters :])
    scale = [r.diagnostics["uncertainty"]["model_error"]["scale"] for r in (caster, loaded)]
    shown = test["p_value"] < AUTO_P
    taken = shown and scale[1] <= scale[0]
    reason = f"the drag's load terms ({test['text']}) differ from zero at p = {test['p_value']:.2g}" + (
        f" < {AUTO_P:g}" if shown else f" >= {AUTO_P:g}: not shown by this log"
    )
    if shown and not taken:
        reason += (
            f", but the log departs further from that model (model-error scale {scale[1]:.3g} against the caster "
            f"model's {scale[0]:.3g}), so the caster model is kept"
        )
    test = {key: test[key] for key in ("statistic", "dof", "p_value")}
    load = {"taken": taken, "reason": reason, "scale": scale[1], "caster_scale": scale[0], **test}
    if not taken:
        return caster, {**record, "load": load}
    return loaded, {**record, "model": loaded.form.friction, "load": load}


#: Friction models of :func:`identify`: ``auto`` lets the log decide between the other two.
FRICTION_CHOICES = (*values(Friction, without=("auto",)), "auto")


def _with_friction(result: IdentificationResult, friction: dict[str, Any]) -> IdentificationResult:
    """``result`` with its friction model and how it was chosen in ``diagnostics["friction"]``."""
    return replace(result, diagnostics={**result.diagnostics, "friction": friction})


def _identify(
    stream: LogStream,
    sv: Survey,
    robot,
    form,
    k,
    alpha,
    box_width,
    max_history,
    torque_hold,
    progress,
    payload,
    control_rate,
    caster=False,
    given_geometry: tuple[float, ...] = (),
    load: bool = False,
) -> IdentificationResult:
    started = time.perf_counter()
    source = stream.source
    effort_unit = stream.effort_unit
    n = sv.n
    if n < 10:
        raise NotIdentifiableError(f"{source}: only {n} samples; identification needs at least 10")
    if sv.max_step > max(GAP_FACTOR * sv.median_step, GAP_MIN_S):
        raise NotIdentifiableError(
            f"{source}: the log has a hole: time jumps by {sv.max_step:.6g} s after t = {sv.max_step_after:.6g} s "
            f"(the median step is {sv.median_step:.3g} s), and the estimator cannot bridge it; cut the log into its "
            "continuous parts and identify each"
        )
    hold_warnings = control_rate_check(control_rate, sv, source)
    units = model.base_units(effort_unit)
    early_warnings = []
    unit_reference: dict[str, Any] = {}  # the robot's values for the units check when its efforts are not N m
    if robot is not None and effort_unit != "N m":
        early_warnings.append(
            f"the effort is in {effort_unit}, not N m, so robot '{robot.name}' (in SI units) neither starts the "
            "estimate nor is compared with it; the start comes from the data"
        )
        unit_reference["nominal"] = model.named_base(model.base_parameters(robot.nominal))
        if robot.cad is not None:
            unit_reference["CAD"] = model.named_base(model.base_parameters(robot.cad))
        robot = None
    geometry: tuple[float, ...] = tuple(given_geometry)
    if caster and robot is not None and robot.casters:
        geometry = caster_geometry(robot)
    if caster and sv.form().kind == "paper":
        raise NotIdentifiableError(
            f"{source}: neither wheel ever stops or reverses, so the casters' drag cannot be told from the wheels' "
            f"Coulomb friction (it adds to it); identify with {option('friction', 'wheel')}, or record a log that "
            "reverses and "
            "turns on the spot"
        )
    chosen = resolve_form(sv.form(), form, caster, geometry, load)
    n0 = chosen.n_base
    if robot is not None:
        start0 = np.concatenate([model.base_parameters(robot.nominal), np.zeros(n0 - 8)])  # no caster drag known
        theta_init = model.intermediate_parameters(start0, chosen)
        start_source = f"nominal parameters of robot '{robot.name}'"
    else:
        theta_init = sv.data_start(chosen)
        start_source = "from the data (unknown robot): m11 = m22 = robust |eta_dot|/|tau| ratio, all else 0"
    lo, hi = default_box(theta_init, chosen, box_width, robot is not None)
    settings = ObserverSettings(
        form=chosen, theta_init=theta_init, theta_min=lo, theta_max=hi, k=k, alpha=alpha, torque_hold=torque_hold,
        control_rate=control_rate,
    )  # fmt: skip

    duration = sv.duration
    tick = None if progress is None else (lambda done: progress(done, n))
    with np.errstate(over="ignore", invalid="ignore"):
        out = replay_pieces(
            ((p.t, p.eta, p.tau) for p in stream), n, duration, settings, max_history=max_history, progress=tick,
            half_rate=True, low_speed=sv.low_speed(), noise_lag=derived_lag(stream.notes),
            sign_half_window=sign_half_window(n, duration),
        )  # fmt: skip
    theta_u, gamma, gamma_inv = out.theta, out.gamma, out.gamma_inv
    finite = all(np.all(np.isfinite(a)) for a in (theta_u, gamma, gamma_inv, out.blk_a, out.blk_c))
    if not finite:
        raise NotIdentifiableError(f"{source}: the estimate diverged to non-finite values; check the log's units")

    theta = np.empty_like(theta_u)
    project_history_box(theta_u[None], gamma[None], lo, hi, theta[None])
    block_mid = 0.5 * (np.concatenate(([sv.t_first], out.block_t[:-1])) + out.block_t) - sv.t_first
    theta_cov, weight_cov, unc = estimate_covariances(
        gamma, gamma_inv, theta_u, out.blk_a, out.blk_c, block_mid / max(duration, 1e-300), duration
    )
    fit = fit_base_parameters(theta, weight_cov, chosen, report_cov=theta_cov, report_dof=unc["dof"])
    sens = start_sensitivity(gamma, gamma_inv, alpha, theta_init, theta_u, fit.gain)
    std_data = np.sqrt(np.clip(np.diag(fit.cov), 0.0, None))
    undetermined = [
        j for j in range(n0) if sens[j] > std_data[j] and sens[j] > START_RELEVANT * abs(fit.theta0[j])
    ]  # fmt: skip
    unexcited = unexcited_parameters(gamma, alpha, theta_u, fit)
    undetermined = sorted(set(undetermined) | set(unexcited))
    if len(unexcited) == n0 or torque_unexcited(gamma, alpha):
        raise NotIdentifiableError(
            f"{source}: the log does not excite the dynamics (no base parameter is determined by it: the wheel "
            "speeds and efforts barely vary); record a log that accelerates, brakes and turns"
        )
    cov0, inflation = widen(
        fit, theta, out, gamma, theta_u, lo, hi, weight_cov, chosen, block_mid, duration, k
    )  # fmt: skip
    cov0 = cov0 + np.diag(sens**2)
    for j in undetermined:
        cov0[j, :] = cov0[:, j] = np.nan
        cov0[j, j] = np.inf
    parameters = derived_with_std(fit.theta0, cov0, chosen.base_names)
    parameters = {name: parameters[name] for name in reported_names(chosen)}

    lam_hist = np.linalg.eigvalsh(out.hist_gamma)[:, 0]
    h_theta = np.empty_like(out.hist_theta)
    project_history_box(out.hist_theta, out.hist_gamma, lo, hi, h_theta)
    history = History(t=out.hist_t - sv.t_first, theta=h_theta, e=out.hist_e, lambda_min=lam_hist)

    diagnostics, warnings = diagnose(
        gamma, alpha, chosen, fit, parameters, theta_cov, sens, undetermined, lo, hi, units, theta, inflation
    )
    warnings = early_warnings + hold_warnings + sv.signal_warnings() + warnings
    if inflation["prediction_misfit"]["applied"]:
        warnings.insert(0, misfit_text(inflation["prediction_misfit"]))
    dof = unc["dof"]
    diagnostics["uncertainty"] = {
        "method": "delete-a-segment jackknife over contiguous segments of the log",
        "segments": unc["segments"],
        "dof": dof,
        "interval_factor": {"95%": interval_factor(0.95, dof), "99.7%": interval_factor(0.9973, dof)},
        "meaning": "value +/- interval_factor * std covers the truth with that probability (Student t, dof) when "
        "the disturbances do not feed back into the efforts",
        "caveat": CLOSED_LOOP_CAVEAT,
        "blocks": len(out.block_end),
        "block_seconds": float(duration / len(out.block_end)),
    }
    record_widening(diagnostics, inflation, parameters, [chosen.base_names[j] for j in undetermined])
    rms_e = np.sqrt(out.blk_ee.sum(axis=0) / duration) if duration > 0 else np.zeros(2)
    diagnostics["prediction_error_rms"] = {"eta_r": float(rms_e[0]), "eta_l": float(rms_e[1]), "unit": "rad/s"}
    log_info = {
        "samples": n,
        "duration_s": duration,
        "rate_hz": float(1.0 / sv.median_step),
        "uneven_steps": bool(sv.max_step - sv.min_step > 1e-6 * sv.median_step),
        "notes": list(stream.notes),
        "effort_unit": effort_unit,
        "scales": sv.scales(),
    }
    payload_est = None
    if payload and robot is not None:
        from wmrid.model.payload import payload_with_std

        payload_est = payload_with_std(fit.theta0, cov0, robot.reference)
    nominal = reference = None
    if robot is not None:
        nominal = model.named_base(model.base_parameters(robot.nominal))
        if robot.cad is not None:
            reference = model.named_base(model.base_parameters(robot.cad))
            for name in getattr(robot, "unknown_cad", ()):  # not given by the robot's source: no value, not 0
                reference[name] = None
        if getattr(robot, "assumed", ()):  # what the robot file left out (said with every result that uses it)
            diagnostics = {**diagnostics, "robot_assumed": list(robot.assumed)}
    if unit_reference:  # in N m-based units: ratios only (wmrid.estimators.plausibility, effort_free)
        diagnostics = {**diagnostics, "robot_values": unit_reference}
    # the jackknife's leave-one-segment-out estimates, theta0 to first order (fit.gain): for comparing methods
    segment, n_seg = segments_of(block_mid / max(duration, 1e-300), duration)
    deltas = jackknife_deltas(gamma, theta_u, out.blk_a, out.blk_c, segment, n_seg)
    loo = SegmentEstimates(float(sv.t_first), float(duration), fit.theta0[None, :] + deltas @ fit.gain.T)
    return IdentificationResult(
        source=source, form=chosen, parameters=parameters, theta0_cov=fit.cov, diagnostics=diagnostics,
        warnings=tuple(warnings), log_info=log_info,
        observer=ObserverRun(
            settings=settings, start_source=start_source, theta=theta, theta_unconstrained=theta_u,
            theta_cov=theta_cov, history=history,
        ),
        nominal=nominal, reference=reference, units=units, payload=payload_est,
        estimate=BaseEstimate(
            "observer", fit.theta0.copy(), cov0, dof=dof, seconds=time.perf_counter() - started, segments=loo,
            weight_cov=weighting_covariance(fit.gain, weight_cov, cov0),
        ),
    )  # fmt: skip


#: Diagnostics that describe the observer's run on the log (kept, and listed as such, under another method).
OBSERVER_DIAGNOSTICS = (
    "lambda_min_gamma", "lambda_max_gamma", "condition_number_scaled", "weakest_directions", "undetermined",
    "not_separable", "at_box_boundary", "start_sensitivity", "structural_mismatch", "prediction_error_rms",
)  # fmt: skip


def with_estimate(result: IdentificationResult, est: BaseEstimate, robot: Robot | None = None) -> IdentificationResult:
    """``result`` (the observer's run on a log) reporting another method's estimate ``est`` of the same log.

    The parameters, their standard errors, the payload and the warnings about the estimate become the
    method's; what describes the log (notes, excitation, the observer's history and intermediate
    parameters, kept as the observer's) stays.  ``diagnostics["method"]`` holds the method's own
    figures and ``diagnostics["observer_parameters"]`` the observer's estimate for comparison.
    """
    inflation = dict(result.diagnostics.get("uncertainty", {}).get("model_error", {"scale": 1.0, "applied": False}))
    inflation.pop("meaning", None)
    # The model-error scale and the low-speed difference are evidence about the log and the model, so they carry
    # over to another method: the log departs from the same model (and in the same slow parts) whichever method
    # reads it.  The discretisation term is the observer's own replay and does not.
    # A method that refits itself without the slow parts (IDIM, wmrid.estimators.idim_checks) uses its own difference
    # instead of the observer's, and its other alternative fit (another filter cutoff) the same way.
    slow = inflation.get("slow_speed") or {}
    own = est.diagnostics.get("checks") or {}
    if own.get("slow_speed"):
        slow = {**own["slow_speed"], "method": est.method}
    if inflation.get("discretisation"):
        inflation["discretisation"] = {**inflation["discretisation"], "applied": False, "observer_only": True}
    if slow:
        inflation["slow_speed"] = {**slow, "fragile": []}
    if own.get("cutoff"):
        inflation["filter"] = {**own["cutoff"], "method": est.method}
    cov = np.array(est.cov, dtype=float) * inflation["scale"] ** 2  # the same log departs from the same model
    timing = (result.diagnostics.get("delay") or {}).get("timing_term") or (
        (result.diagnostics.get("timing") or {}).get("timing_term") or {}
    )
    terms = [slow, inflation.get("filter") or {}]
    if timing.get("widened"):  # the efforts' timing is as uncertain whichever method reads them
        terms.append({"applied": True, "delta": timing["delta"]})
    for term in terms:
        if term.get("applied") and term.get("delta") is not None and len(term["delta"]) == len(est.theta0):
            delta = np.asarray(term["delta"], dtype=float)
            cov = cov + np.outer(delta, delta)
    form = result.form if len(est.theta0) == result.form.n_base else RegressorForm("general")
    parameters = derived_with_std(np.asarray(est.theta0, dtype=float), cov, form.base_names)
    parameters = {name: parameters[name] for name in reported_names(form)}
    diagnostics = dict(result.diagnostics)
    diagnostics["observer_parameters"] = {name: {"value": v, "std": finite_or_none(e)} for name, (v, e) in
                                          result.parameters.items()}  # fmt: skip
    diagnostics["method"] = {"name": est.method, "seconds": est.seconds, "dof": est.dof, **est.diagnostics}
    diagnostics["from_observer"] = [k for k in OBSERVER_DIAGNOSTICS if k in diagnostics]
    dof = est.dof
    diagnostics["uncertainty"] = {
        "method": est.diagnostics.get("uncertainty", f"standard errors of method {est.method}"),
        "segments": est.diagnostics.get("segments"),
        "dof": dof,
        "interval_factor": {
            "95%": interval_factor(0.95, dof) if dof else 1.959964,
            "99.7%": interval_factor(0.9973, dof) if dof else 2.999977,
        },
        "meaning": "value +/- interval_factor * std covers the truth with that probability when the disturbances "
        "do not feed back into the efforts",
        "caveat": CLOSED_LOOP_CAVEAT,
    }
    # the per-parameter warnings (poorly determined, impossible values) are made by settle, from these numbers
    base_names = form.base_names
    undetermined = [name for name in base_names if not math.isfinite(parameters[name][1])]
    record_widening(diagnostics, inflation, parameters, undetermined)
    warnings = [*result.warnings, *est.warnings]
    payload_est = None
    if result.payload is not None and robot is not None:
        from wmrid.model.payload import payload_with_std

        payload_est = payload_with_std(np.asarray(est.theta0, dtype=float), cov, robot.reference)
    from wmrid.estimators.verdict import settle

    return settle(replace(
        result, parameters=parameters, theta0_cov=cov, diagnostics=diagnostics, warnings=tuple(warnings),
        payload=payload_est, method=est.method, estimate=replace(est, cov=cov),
    ))  # fmt: skip


def check_box_width(box_width: float) -> None:
    """Refuse a box half-width that is not a number > 0 (inf: no box)."""
    if not (isinstance(box_width, (int, float)) and box_width > 0):  # NaN fails too
        raise UsageError(f"{option('box_width')} must be a number > 0 (inf: no box), got {box_width!r}")
