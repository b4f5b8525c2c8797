"""One pass of the observer over a log (:func:`observe`): the settings from the robot or the data, the compiled
replay, the estimate and its uncertainty, the result.  It decides nothing about the log (which friction model, which
delay, which checks): :mod:`wmrid.pipeline.identify` does, and runs it once per model and timing it needs.

Pure with respect to files: takes a :class:`wmrid.core.wheel_log.LogStream` and its survey, returns a frozen
:class:`IdentificationResult`.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import replace
from typing import Any, Literal

import numpy as np

from wmrid.core.errors import NotIdentifiableError, UsageError, option
from wmrid.core.wheel_log import LogStream
from wmrid.estimators.diagnostics import (
    START_RELEVANT,
    control_rate_check,
    diagnose,
    start_sensitivity,
    torque_unexcited,
    unexcited_parameters,
)
from wmrid.estimators.estimate import BaseEstimate, SegmentEstimates
from wmrid.estimators.findings import PredictionErrorRms, Uncertainty
from wmrid.estimators.model_error import (
    misfit_text,
    record_widening,
    widen,
)
from wmrid.estimators.noise_floor import derived_lag
from wmrid.estimators.observer.kernel import project_history_box
from wmrid.estimators.observer.replay import replay_pieces
from wmrid.estimators.observer.settings import ObserverSettings
from wmrid.estimators.observer.survey import Survey
from wmrid.estimators.options import ObserverOptions
from wmrid.estimators.records import LogInfo
from wmrid.estimators.result import History, IdentificationResult, ObserverRun, reported_names
from wmrid.estimators.sign_speed import sign_half_window
from wmrid.estimators.uncertainty import estimate_covariances, interval_factor, jackknife_deltas, segments_of
from wmrid.model import dynamics as model
from wmrid.model.base_params import derived_with_std, fit_base_parameters, weighting_covariance
from wmrid.model.dynamics import RegressorForm
from wmrid.model.payload import payload_with_std
from wmrid.model.robot import Robot

#: A time step longer than GAP_FACTOR median steps (and GAP_MIN_S) is a hole the estimator cannot bridge.
GAP_FACTOR = 1000.0


GAP_MIN_S = 1.0


#: What the standard errors do not cover, with the coverage measured in simulation (bench/accuracy/bench_coverage.py).
CLOSED_LOOP_CAVEAT = (
    "in closed loop a coloured disturbance (a caster, the floor) reaches the efforts through the controller and "
    "biases the observer's inertia entries and Vc; the closed-loop check compares the observer with IDIM (IDIM-IV "
    "when the log has the reference), reports that one when they differ beyond noise, and otherwise widens the std "
    "by their difference (diagnostics.feedback; measured in docs/explanation/checks.md)"
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


#: The friction models :func:`observe` runs: (caster drag, its load terms).
MODELS = {"wheel": (False, False), "wheel+caster": (True, False), "wheel+caster+load": (True, True)}


def observe(
    stream: LogStream,
    sv: Survey,
    robot: Robot | None,
    options: ObserverOptions,
    geometry: tuple[float, ...] = (),
    progress: Callable[[int, int], None] | None = None,
) -> IdentificationResult:
    """One replay of the observer over ``stream`` (surveyed as ``sv``, :func:`wmrid.estimators.observer.survey.survey`)
    with
    ``options`` as they are: its friction model named (not "auto"), its delay already applied to the log (the
    pipeline's business).  ``robot`` starts the estimate and centres the box (None: the data, physics); ``geometry``
    (r, b, x_1, y_1, ...) m the casters' when no robot lists them (a saved model's); ``progress(samples_done,
    samples)``.

    Raises :class:`NotIdentifiableError` for a log that supports no estimate (too short, a hole, not excited, a
    singular system, a divergence)."""
    if options.friction not in MODELS:
        raise ValueError(f"observe runs one friction model, not {options.friction!r}")
    caster, load = MODELS[options.friction]
    try:
        return _observe(stream, sv, robot, options, caster, load, geometry, progress)
    except np.linalg.LinAlgError as err:
        raise NotIdentifiableError(
            f"{stream.source}: the log does not support an estimate (a singular system: {err}); it is too short, "
            "not exciting enough, or its units or time stamps are wrong (check the notes of wmrid inspect)"
        ) from err


def _observe(
    stream: LogStream,
    sv: Survey,
    robot: Robot | None,
    options: ObserverOptions,
    caster: bool,
    load: bool,
    given_geometry: tuple[float, ...],
    progress: Callable[[int, int], None] | None,
) -> IdentificationResult:
    form, k, alpha, box_width = options.form, options.k, options.alpha, options.box_width
    torque_hold, control_rate, max_history = options.torque_hold, options.control_rate, options.max_history
    payload = options.payload
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
    uncertainty = Uncertainty(
        method="delete-a-segment jackknife over contiguous segments of the log",
        segments=unc["segments"],
        dof=dof,
        interval_factor={"95%": interval_factor(0.95, dof), "99.7%": interval_factor(0.9973, dof)},
        meaning="value +/- interval_factor * std covers the truth with that probability (Student t, dof) when "
        "the disturbances do not feed back into the efforts",
        caveat=CLOSED_LOOP_CAVEAT,
        blocks=len(out.block_end),
        block_seconds=float(duration / len(out.block_end)),
    )
    diagnostics = replace(diagnostics, uncertainty=uncertainty)
    diagnostics = record_widening(diagnostics, inflation, parameters, [chosen.base_names[j] for j in undetermined])
    rms_e = np.sqrt(out.blk_ee.sum(axis=0) / duration) if duration > 0 else np.zeros(2)
    rms = PredictionErrorRms(eta_r=float(rms_e[0]), eta_l=float(rms_e[1]), unit="rad/s")
    diagnostics = replace(diagnostics, prediction_error_rms=rms)
    log_info = LogInfo(
        samples=n, duration_s=duration, rate_hz=float(1.0 / sv.median_step),
        uneven_steps=bool(sv.max_step - sv.min_step > 1e-6 * sv.median_step), notes=tuple(stream.notes),
        effort_unit=effort_unit, scales=sv.scales(),
    )  # fmt: skip
    payload_est = None
    if payload and robot is not None:
        payload_est = payload_with_std(fit.theta0, cov0, robot.reference)
    nominal = reference = None
    if robot is not None:
        nominal = model.named_base(model.base_parameters(robot.nominal))
        if robot.cad is not None:
            reference = model.named_base(model.base_parameters(robot.cad))
            for name in getattr(robot, "unknown_cad", ()):  # not given by the robot's source: no value, not 0
                reference[name] = None
        if getattr(robot, "assumed", ()):  # what the robot file left out (said with every result that uses it)
            diagnostics = replace(diagnostics, robot_assumed=tuple(robot.assumed))
    if unit_reference:  # in N m-based units: ratios only (wmrid.estimators.plausibility, effort_free)
        diagnostics = replace(diagnostics, robot_values=unit_reference)
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
