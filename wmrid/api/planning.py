"""``wmrid plan``: design the drive that identifies a robot (:func:`plan`); write it for the robot (:func:`write_plan`).

See :mod:`wmrid.design` for the method.  The robot's nominal set gives the model the plan is designed on; its
``[limits]`` table gives any limit not passed here; the noise is given, measured from an earlier log
(``noise_from``: wmrid's own noise-floor estimate, :class:`wmrid.estimators.noise_floor.NoiseFloor`, on its speeds and
efforts), or defaults (:data:`DEFAULT_ETA_NOISE`, :data:`DEFAULT_TAU_SHARE` of the torque scale, at
:data:`DEFAULT_LOG_RATE`).  ``given``: results of logs already identified (``wmrid identify --format json``), whose
information is added, so that the plan targets what they leave poorly determined.

Imports inside functions: start-up time (a front door: ``import wmrid`` and each function load only what that
function uses).
"""

from __future__ import annotations

import math
import os
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import Any, overload

import numpy as np

from wmrid.api.inputs import read_json_input
from wmrid.api.plan_given import _given
from wmrid.core.errors import UsageError, option
from wmrid.design.information import DEFAULT_K, SensorNoise
from wmrid.design.limits import DEFAULT_MARGIN, resolve_limits
from wmrid.design.plan import Plan, criterion_of, make_plan, plan_form, predicted_std
from wmrid.model.robot import BaseSet, Robot

__all__ = ["Plan", "plan", "predict_plan", "read_plan", "write_plan"]

#: Defaults of the noise the prediction assumes when neither given nor measured: rad/s on each wheel speed, and the
#: effort noise as a share of the torque scale (the torque limit, or the nominal torque at the acceleration limit),
#: per sample at DEFAULT_LOG_RATE Hz (ros2_control's joint_states commonly publishes at 50-100 Hz).
DEFAULT_ETA_NOISE = 0.01
DEFAULT_TAU_SHARE = 0.01
DEFAULT_LOG_RATE = 100.0


@overload
def _number(name: str, value: float, low: float = 0.0, strict: bool = True) -> float: ...
@overload
def _number(name: str, value: float | None, low: float = 0.0, strict: bool = True) -> float | None: ...
def _number(name: str, value: Any, low: float = 0.0, strict: bool = True) -> float | None:
    if value is None:
        return None
    ok = isinstance(value, (int, float)) and not isinstance(value, bool) and math.isfinite(value)
    if not ok or value < low or (strict and value == low):
        raise UsageError(f"{option(name, value)}: must be a number {'>' if strict else '>='} {low:g}")
    return float(value)


def measured_noise(log: Any, robot: Robot | None = None) -> tuple[float, float, float]:
    """(eta_std rad/s, tau_std N m, rate Hz) of a log: the white-noise floor of its speeds and its efforts (the
    larger wheel of each), and its median sample rate."""
    from wmrid.api.inputs import read_log
    from wmrid.estimators.noise_floor import NoiseFloor

    wheel_log = read_log(log, robot=robot)
    if wheel_log.effort_unit != "N m":
        raise UsageError(
            f"{option('noise_from', str(log))}: its efforts are in {wheel_log.effort_unit}, not N m; the plan's torque "
            "noise must be in N m (give the log's torque constant, or --tau-noise)"
        )
    sigmas = []
    for signal in (wheel_log.eta, wheel_log.tau):
        floor = NoiseFloor()
        floor.feed(np.asarray(signal, dtype=np.float64))
        sigma = floor.sigma()
        if not np.any(np.isfinite(sigma)):
            raise UsageError(f"{option('noise_from', str(log))}: too short or too still to measure its noise")
        sigmas.append(float(np.nanmax(sigma)))
    dt = np.diff(np.asarray(wheel_log.t, dtype=np.float64))
    rate = 1.0 / float(np.median(dt[dt > 0]))
    return sigmas[0], sigmas[1], rate


def footprint(robot: Robot) -> float:
    """m: how far the robot reaches from its axle midpoint: its wheels' contacts (the half track b) and its casters'
    contacts (a robot file's [[caster]] tables, else wmrid's default pair)."""
    from wmrid.model.robot import default_casters

    nominal = robot.nominal
    reach = float(nominal.b or 0.0)
    casters = robot.casters
    if casters is None and not isinstance(nominal, BaseSet):
        casters = default_casters(nominal)
    for caster in casters or ():
        reach = max(reach, math.hypot(caster.x, caster.y) + getattr(caster, "radius", 0.0))
    return reach


def plan(
    robot: str | os.PathLike[str] | Robot = "paper",
    *,
    duration: float | str = 60.0,
    target_std: float | None = None,
    rate: float = 50.0,
    seed: int = 0,
    max_wheel_speed: float | None = None,
    max_wheel_accel: float | None = None,
    max_torque: float | None = None,
    max_speed: float | None = None,
    max_turn_rate: float | None = None,
    area: str | tuple[float, float] | None = None,
    margin: float = DEFAULT_MARGIN,
    eta_noise: float | None = None,
    tau_noise: float | None = None,
    log_rate: float | None = None,
    noise_from: str | os.PathLike[str] | None = None,
    criterion: str = "worst",
    friction: str = "auto",
    given: str | os.PathLike[str] | Sequence[str | os.PathLike[str]] | None = None,
    k: float = DEFAULT_K,
    progress: Callable[[str], None] | None = None,
) -> Plan:
    """Design the drive that identifies ``robot`` best within the limits and predict its precision (``wmrid plan``).

    The limits are in SI units; a limit left None is the robot file's ``[limits]``, else the default of
    :mod:`wmrid.design.limits`.  The noise is given (``eta_noise``, ``tau_noise`` per sample at ``log_rate`` Hz),
    measured from ``noise_from``, or the defaults: :data:`DEFAULT_ETA_NOISE` rad/s, :data:`DEFAULT_TAU_SHARE` of the
    torque scale, at :data:`DEFAULT_LOG_RATE` Hz.

    Parameters
    ----------
    robot
        A built-in name, a robot file or a :class:`Robot`; its nominal set is planned on.
    duration
        s, or "auto" with ``target_std``: the shortest plan predicted to bring every base parameter's relative std
        below it.
    target_std
        Percent (e.g. 2 for 2 %): the largest relative std wanted, with ``duration="auto"``.
    rate
        Hz, the rate of the written reference.
    seed
        Seed of the search's random starts, >= 0.
    max_wheel_speed
        rad/s, the wheel speed limit.
    max_wheel_accel
        rad/s^2, the wheel acceleration limit.
    max_torque
        N m per wheel, the torque limit (torques from the nominal model).
    max_speed
        m/s, the forward speed limit.
    max_turn_rate
        rad/s, the turn rate limit.
    area
        The floor area, ``"WxH"`` or (W, H), m, centred on the start (the robot at rest facing +x).
    margin
        The share of each limit kept free, in [0, 0.9).
    eta_noise
        rad/s per sample, the white noise on each wheel speed.
    tau_noise
        N m per sample, the white noise on each effort.
    log_rate
        Hz, the rate of the log to be recorded (None: ``noise_from``'s, else :data:`DEFAULT_LOG_RATE`).
    noise_from
        An earlier log of this robot to measure the noise (and log rate) from, instead of ``eta_noise`` and
        ``tau_noise``.
    criterion
        "worst" (largest relative std), "d" (D-optimal) or "a" (A-optimal).
    friction
        The model identify will fit, which the prediction is for: "auto" (a robot file with [[caster]] tables:
        "wheel+caster+load", what ``identify --friction auto`` chooses when the casters' drag shows; else "wheel"),
        "wheel", "wheel+caster" (each caster's drag with their positions, the two-term Cv, Cw without) or
        "wheel+caster+load".
    given
        Saved results of logs already identified (``wmrid identify --format json``), whose information is added, so
        that the plan targets what they leave poorly determined.
    k
        The estimator's gain the prediction assumes (``identify --k``).
    progress
        Called with a sentence per stage of the design, or None.

    Returns
    -------
    Plan
        The planned drive and its predicted precision.

    Raises
    ------
    UsageError
        A number out of its range, ``duration="auto"`` without ``target_std``, ``noise_from`` with noise levels, both
        noise levels 0, a robot without r and b, or a friction model the robot cannot have.
    """
    from wmrid.api.inputs import load_robot
    from wmrid.model.dynamics import base_parameters

    # every number is checked before anything is read or searched
    seed = int(_number("seed", seed, 0.0, strict=False))
    rate = _number("rate", rate)
    given_limits = {"max_wheel_speed": max_wheel_speed, "max_wheel_accel": max_wheel_accel, "max_torque": max_torque,
                    "max_speed": max_speed, "max_turn_rate": max_turn_rate}  # fmt: skip
    for name, value in given_limits.items():
        _number(name, value)
    ok = isinstance(margin, (int, float)) and not isinstance(margin, bool) and 0.0 <= margin < 0.9
    if not ok:
        raise UsageError(f"{option('margin', margin)}: must be a share in [0, 0.9)")
    _number("eta_noise", eta_noise, strict=False)
    _number("tau_noise", tau_noise, strict=False)
    _number("log_rate", log_rate)
    _number("target_std", target_std)
    robot_obj = load_robot(robot)
    nominal = robot_obj.nominal
    r, b = nominal.r, nominal.b
    if r is None or b is None:  # a base set without them (physical parameters always have both)
        raise UsageError(
            f"{option('robot', robot_obj.name)}: a plan needs the wheel radius r and half track b (the [nominal_base] "
            "table gives neither)"
        )
    limits = resolve_limits(
        r, dict(robot_obj.limits), margin=margin, footprint=footprint(robot_obj), area=area, **given_limits
    )
    # a base set gives its theta0 (what base_parameters returns for one)
    theta0 = np.asarray(base_parameters(nominal), dtype=np.float64)
    big_m = np.linalg.inv(np.array([[theta0[0], theta0[1]], [theta0[1], theta0[2]]]))
    tau_scale = limits.max_torque or float(np.max(np.sum(np.abs(big_m), axis=1))) * limits.max_wheel_accel
    if noise_from is not None:
        if eta_noise is not None or tau_noise is not None:
            raise UsageError(f"{option('noise_from')} measures the noise: give it or the noise levels, not both")
        eta_std, tau_std, measured_rate = measured_noise(noise_from, robot_obj)
        log_rate = log_rate or measured_rate
        noise_source = f"measured from {os.fspath(noise_from)}"
    else:
        eta_std = DEFAULT_ETA_NOISE if eta_noise is None else _number("eta_noise", eta_noise, strict=False)
        tau_std = DEFAULT_TAU_SHARE * tau_scale if tau_noise is None else _number("tau_noise", tau_noise, strict=False)
        noise_source = "given" if eta_noise is not None and tau_noise is not None else "default" if (
            eta_noise is None and tau_noise is None) else "given in part, default in part"  # fmt: skip
    log_rate = DEFAULT_LOG_RATE if log_rate is None else _number("log_rate", log_rate)
    if eta_std == 0 and tau_std == 0:
        raise UsageError(
            f"{option('eta_noise')} and {option('tau_noise')} are both 0: a noise-free log has no std to plan"
        )
    noise = SensorNoise(float(eta_std), float(tau_std), float(log_rate))
    length: float | None
    if isinstance(duration, str) and duration.strip().lower() == "auto":
        if target_std is None:
            raise UsageError(f"{option('duration', 'auto')} needs {option('target_std', 'PCT')}")
        length = None
    else:
        try:
            length = float(duration)
        except (TypeError, ValueError):
            raise UsageError(f"{option('duration', duration)}: a number of seconds, or auto") from None
        from wmrid.design.plan import MIN_DURATION

        if not math.isfinite(length) or length < MIN_DURATION:
            raise UsageError(f"{option('duration', duration)}: a plan lasts at least {MIN_DURATION:g} s")
    share = None
    if target_std is not None:
        share = _number("target_std", target_std) / 100.0
    friction, geometry, drag = _friction(friction, robot_obj)
    form = plan_form(friction, geometry)
    names = form.base_names
    start = np.concatenate([theta0, drag, np.zeros(len(names) - 8 - len(drag))])
    given_info, theta0 = _given(given, names, start)
    result = make_plan(
        robot_obj.name, theta0[:8], r, b, limits, noise, duration=length, target_std=share, rate=rate, seed=seed,
        criterion=criterion, friction=friction, k=k, given=given_info, progress=progress, geometry=geometry,
        drag=tuple(theta0[8 : 8 + len(drag)]),
    )  # fmt: skip
    return replace(result, settings=replace(result.settings, noise_source=noise_source))


def predict_plan(
    plan: Plan | str | os.PathLike[str],
    robot: str | os.PathLike[str] | Robot,
    *,
    friction: str | None = None,
    given: Any = None,
) -> Plan:
    """The precision a drive already planned gives, predicted again without searching again.

    ``plan``'s drive is predicted for the model identify will fit to its log and for the logs identified since.

    Parameters
    ----------
    plan
        The plan: a :class:`Plan`, or a saved one's path.
    robot
        The robot the plan was made for (a built-in name, a robot file or a :class:`Robot`; its casters for a
        friction model with caster drag).
    friction
        The model identify will fit, as for :func:`plan` ("auto", "wheel", "wheel+caster", "wheel+caster+load";
        None: the plan's own), e.g. "wheel" for a log without caster drag.
    given
        Saved results of logs already identified (paths, or results; one or several), whose information is added as
        :func:`plan` adds it.

    Returns
    -------
    Plan
        The plan with ``predicted``, ``criterion``, ``given`` and ``settings.friction`` of the new prediction; the
        drive, its limits, noise and ``baselines`` are the plan's own.
    """
    from wmrid.api.inputs import load_robot
    from wmrid.design.plan import FINE_GRID, _problem

    if not isinstance(plan, Plan):
        plan = read_plan(plan)
    robot_obj = load_robot(robot)
    model, geometry, drag = _friction(friction or plan.settings.friction or "wheel", robot_obj)
    form = plan_form(model, geometry)
    names = form.base_names
    start = np.array([float(plan.predicted[n].nominal) for n in names[:8]])  # type: ignore[arg-type]
    theta0 = np.concatenate([start, drag, np.zeros(len(names) - 8 - len(drag))])
    given_info, theta0 = _given(given, names, theta0)
    duration = plan.excitation.duration
    criterion = plan.settings.criterion or "worst"
    fine = _problem(
        theta0, form, plan.r, plan.b, plan.limits, plan.noise, duration, min(plan.noise.rate, FINE_GRID),
        criterion, None if given_info is None else given_info[0],
        DEFAULT_K if plan.settings.k is None else plan.settings.k,
    )  # fmt: skip
    cov = fine.covariance(fine.motion_of(np.asarray(plan.excitation.coefficients, dtype=np.float64)))
    predicted = predicted_std(fine, theta0, cov, names)
    settings = replace(plan.settings, friction=model, caster_geometry=tuple(form.geometry), parameter_names=names)
    return replace(
        plan, predicted=predicted, criterion=criterion_of(criterion, fine.criterion_value(cov), predicted),
        settings=settings, given=None if given_info is None else given_info[1],
    )  # fmt: skip


#: ``plan --friction`` choices.
FRICTIONS = ("auto", "wheel", "wheel+caster", "wheel+caster+load")


def _friction(friction: str, robot: Robot) -> tuple[str, tuple[float, ...], tuple[float, ...]]:
    """(friction model, caster geometry (r, b, x_1, y_1, ...) m or (), each geometric caster's nominal drag N): what
    ``plan --friction`` means for ``robot``.  The nominal drag of a caster is its rolling resistance times its load
    at rest (least-norm statics; mirrored casters, which the log cannot tell apart, summed)."""
    if friction not in FRICTIONS:
        raise UsageError(f"{option('friction', friction)}: choose one of {', '.join(FRICTIONS)}")
    from wmrid.estimators.observer.observe import caster_geometry

    casters = tuple(robot.casters or ())
    if friction == "auto":
        friction = "wheel+caster+load" if casters else "wheel"
    if friction == "wheel" or not casters:
        if friction == "wheel+caster+load":
            raise UsageError(
                f"{option('friction', friction)} needs the casters' positions (the robot file's [[caster]] tables)"
            )
        return friction, (), ()
    if isinstance(robot.nominal, BaseSet):
        raise UsageError(
            f"{option('friction', friction)}: the casters' drag needs the robot's masses (a [nominal] table of "
            "physical parameters), not a [nominal_base] table; or plan with --friction wheel"
        )
    from wmrid.sim.multibody_model import static_loads

    geometry = caster_geometry(robot)
    loads = static_loads(robot.nominal, casters)[2:]
    drag = [0.0] * ((len(geometry) - 2) // 2)
    for caster, load in zip(casters, loads, strict=True):
        for k in range(len(drag)):
            if abs(abs(caster.x) - geometry[2 + 2 * k]) < 1e-3 and abs(caster.y - geometry[3 + 2 * k]) < 1e-3:
                drag[k] += caster.resistance * max(float(load), 0.0)
                break
    return friction, geometry, tuple(drag)


def read_plan(path: str | os.PathLike[str]) -> Plan:
    """A plan saved as JSON (``wmrid plan -o plan.json`` or ``--format json``).

    Parameters
    ----------
    path
        The saved plan's path.

    Returns
    -------
    Plan
        The plan.
    """
    source = os.fspath(path)
    return Plan.from_dict(read_json_input(source, source, "a plan"), source)


#: Suffixes :func:`write_plan` writes: the reference (csv, parquet, mcap) or the prediction (json).
PLAN_SUFFIXES = (".csv", ".parquet", ".mcap", ".json")


def check_plan_output(path: str | os.PathLike[str]) -> None:
    """UsageError unless ``path``'s suffix is one :func:`write_plan` writes (checked before the plan is made)."""
    target = os.fspath(path)
    if Path(target).suffix.lower() not in PLAN_SUFFIXES:
        raise UsageError(f"{option('output', target)}: give a file ending in {', '.join(PLAN_SUFFIXES)}")


def write_plan(
    result: Plan, path: str | os.PathLike[str], *, topic: str = "/cmd_vel", stamped: bool = False, force: bool = False
) -> None:
    """Write a plan in the format the suffix of ``path`` names, atomically.

    Parameters
    ----------
    result
        The plan (:func:`plan`).
    path
        The output: ``.json`` the prediction (:meth:`Plan.to_dict`); ``.csv`` or ``.parquet`` the reference at the
        plan's rate (t, v, omega, eta_r, eta_l, x, y, phi); ``.mcap`` a ROS 2 recording of
        geometry_msgs/msg/Twist on ``topic``.
    topic
        The topic of an ``.mcap`` reference.
    stamped
        Write TwistStamped instead of Twist (``.mcap``).
    force
        Overwrite an existing file (else it is kept).

    Raises
    ------
    UsageError
        ``path`` has none of the suffixes above.
    OutputExistsError
        ``path`` exists and ``force`` is not given.
    """
    from wmrid.runtime.atomic import write_json

    target = os.fspath(path)
    check_plan_output(target)
    suffix = Path(target).suffix.lower()
    if suffix == ".json":
        write_json(target, result.to_dict(), force=force)
        return
    from wmrid.io.reference_files import write_reference

    # a stamped plan carries zero stamps: ros2_control's diff_drive_controller drops a TwistStamped older than its
    # cmd_vel_timeout (0.5 s) and re-stamps only a zero one, and ros2 bag play keeps the stamps as written
    write_reference(target, result.samples().columns(), topic=topic, stamped=stamped, zero_stamps=stamped, force=force)


def plan_document(path: str | os.PathLike[str]) -> Plan | None:
    """The plan saved at ``path`` when it is one (a JSON document with ``"kind": "plan"``), else None (another saved
    result, a log): how ``wmrid report`` tells a plan from the rest."""
    source = os.fspath(path)
    if source == "-" or not source.lower().endswith(".json") or not os.path.isfile(source):
        return None
    try:
        with open(source, encoding="utf-8") as fh:
            head = fh.read(4096)
    except (OSError, UnicodeDecodeError):
        return None
    if '"kind": "plan"' not in head and '"kind":"plan"' not in head:
        return None
    return read_plan(source)


def write_plan_report(result: Plan, path: str | os.PathLike[str], *, force: bool = False) -> None:
    """The plan's report by suffix: ``.html`` (self-contained, with figures), ``.md`` or ``.json`` (the plan)."""
    from wmrid.reporting.plan_report import to_html, to_markdown
    from wmrid.runtime.atomic import atomic_write_text, write_json

    target = os.fspath(path)
    suffix = Path(target).suffix.lower()
    if suffix in (".html", ".htm"):
        atomic_write_text(target, to_html(result), force=force)
    elif suffix == ".md":
        atomic_write_text(target, to_markdown(result), force=force)
    elif suffix == ".json":
        write_json(target, result.to_dict(), force=force)
    else:
        raise UsageError(f"-o {target}: a plan's report is .html, .md or .json")
