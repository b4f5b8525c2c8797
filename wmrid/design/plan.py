"""``wmrid plan``: the drive that identifies a robot, as a typed, JSON round-tripping :class:`Plan`.

:func:`make_plan` sets up the design problem (:mod:`wmrid.design.problem`) from the robot's nominal base parameters,
the limits and the sensor noise, searches it (:mod:`wmrid.design.search`) on a coarse grid, and predicts the
precision of the result on the log's own grid (its rate, at most :data:`FINE_GRID` Hz), together with the same
prediction for two baselines of the same duration within the same limits (:mod:`wmrid.design.baselines`): the paper's
sinusoid and the back-and-forth ``reversing`` drive of ``wmrid simulate`` (each slowed down uniformly when it would
break a limit; the area is not imposed on them, and whether they leave it is said).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from wmrid.core.errors import UsageError, option
from wmrid.design.baselines import baseline_forecast, baseline_motion as baseline_motion
from wmrid.design.excitation import RAMP_SECONDS, Excitation, pose_along
from wmrid.design.information import DEFAULT_K, GivenLogs, SensorNoise
from wmrid.design.limits import LIMIT_NAMES, Limits
from wmrid.design.plan_records import (
    BaselineForecast,
    Criterion,
    GivenResults,
    LimitUse,
    PlanSettings,
    PredictedStd,
    ReferenceSamples,
    Separability,
    WheelSpread,
)
from wmrid.design.problem import CORRELATION, CRITERIA, DIRECTION_SHARE, FLOOR_SHARE, Motion, Problem
from wmrid.design.search import SearchResult, search
from wmrid.model.dynamics import RegressorForm, load_signals

SCHEMA = 1
#: Hz of the grid the search runs on (the plan's signals stay under 1 Hz) and the finest grid of the final prediction.
SEARCH_GRID = 20.0
FINE_GRID = 1000.0
#: Base period aimed at, s (the plan's duration holds a whole number of them) and harmonics per channel.
PERIOD_SECONDS = 12.0
HARMONICS = 6
#: Shortest plan, s: its ramps from and back to rest take 2 s each, and each wheel must still turn both ways.
MIN_DURATION = 10.0
#: Longest plan ``--duration auto`` will design, s.
MAX_AUTO_DURATION = 600.0
#: Criterion names as said to a user.
CRITERION_TEXT = {"worst": "largest relative std", "d": "D-optimal (geometric mean)", "a": "A-optimal (rms)"}
BASELINES = ("sinusoid", "reversing")


@dataclass(frozen=True)
class Plan:
    """A planned drive and what it predicts (:func:`wmrid.plan`).

    All in SI units; the parts are the records of :mod:`wmrid.design.plan_records`.

    Attributes
    ----------
    robot
        The robot's name.
    r
        m, the nominal wheel radius.
    b
        m, the nominal half track.
    limits
        The limits the drive keeps (:class:`Limits`).
    noise
        The sensor noise the prediction assumes (:class:`SensorNoise`).
    excitation
        The reference (:class:`Excitation`).
    settings
        :class:`PlanSettings`: duration, period, harmonics, rate of the written reference, seed, criterion, friction,
        k, the search's statistics.
    predicted
        Base parameter name -> :class:`PredictedStd` (std in the parameter's unit; relative = std / scale).
    criterion
        :class:`Criterion`: its value and the worst parameter.
    limits_used
        Limit name -> :class:`LimitUse` (share = peak / limit).
    baselines
        Name -> :class:`BaselineForecast`.
    margins
        :class:`Separability`: time each wheel spends in each direction, its speed spread, the correlation of v and w.
    given
        :class:`GivenResults`: the logs already identified whose information was added (None: none).
    warnings
        Sentences.
    """

    robot: str
    r: float
    b: float
    limits: Limits
    noise: SensorNoise
    excitation: Excitation
    settings: PlanSettings
    predicted: dict[str, PredictedStd]
    criterion: Criterion
    limits_used: dict[str, LimitUse]
    baselines: dict[str, BaselineForecast]
    margins: Separability
    given: GivenResults | None = None
    warnings: tuple[str, ...] = field(default=())

    @property
    def form(self) -> RegressorForm:
        """The regressor form the prediction is for (``settings.friction``, the casters' geometry when given)."""
        return plan_form(self.settings.friction or "wheel", tuple(self.settings.caster_geometry or ()))

    @property
    def value(self) -> float:
        """The criterion's value (a share: ``criterion.value``)."""
        return float(self.criterion.value)  # type: ignore[arg-type]  # checked a number when read

    @property
    def worst(self) -> str:
        """The base parameter with the largest predicted relative std, of those the criterion counts
        (``criterion.worst``)."""
        return str(self.criterion.worst)

    def samples(self, rate: float | None = None) -> ReferenceSamples:
        """The reference at ``rate`` Hz and its predicted pose.

        Parameters
        ----------
        rate
            Hz (None: the plan's ``settings.rate``).

        Returns
        -------
        ReferenceSamples
            t, v, omega, eta_r, eta_l, x, y, phi.
        """
        rate = float(rate or self.settings.rate)  # type: ignore[arg-type]
        n = round(self.excitation.duration * rate) + 1
        t = np.linspace(0.0, self.excitation.duration, n)
        v, w, _, _ = self.excitation.evaluate(t)
        # the pose on a fine grid (at least 200 Hz), read at the plan's rate
        every = max(1, math.ceil(200.0 / rate))
        fine = np.linspace(0.0, self.excitation.duration, (n - 1) * every + 1)
        vf, wf, _, _ = self.excitation.evaluate(fine)

        pose = pose_along(fine, vf, wf)[::every]
        return ReferenceSamples(
            t=t, v=v, omega=w, eta_r=(v + self.b * w) / self.r, eta_l=(v - self.b * w) / self.r,
            x=pose[:, 0], y=pose[:, 1], phi=pose[:, 2],
        )  # fmt: skip

    def to_dict(self) -> dict[str, Any]:
        """The plan's JSON (what ``wmrid plan -o plan.json`` writes and :meth:`from_dict` reads)."""
        return {
            "schema": SCHEMA, "kind": "plan", "robot": self.robot, "r": self.r, "b": self.b,
            "criterion": self.criterion.to_dict(), "predicted": {n: p.to_dict() for n, p in self.predicted.items()},
            "limits": self.limits.to_dict(), "limits_used": {n: u.to_dict() for n, u in self.limits_used.items()},
            "baselines": {n: b.to_dict() for n, b in self.baselines.items()}, "margins": self.margins.to_dict(),
            "noise": self.noise.to_dict(), "settings": self.settings.to_dict(), "excitation": self.excitation.to_dict(),
            "given": None if self.given is None else self.given.to_dict(), "warnings": list(self.warnings),
        }  # fmt: skip

    @classmethod
    def from_dict(cls, data: dict[str, Any], source: str = "plan") -> Plan:
        if not isinstance(data, dict) or data.get("kind") != "plan":
            raise UsageError(f'{source}: not a plan written by wmrid plan (no "kind": "plan")')
        if data.get("schema", 0) > SCHEMA:
            raise UsageError(f"{source}: a plan of schema {data['schema']}, newer than this wmrid reads ({SCHEMA})")
        try:
            noise = data["noise"]
            criterion = Criterion.from_dict(data["criterion"])
            float(criterion.value)  # type: ignore[arg-type]  # a number (TypeError, ValueError otherwise)
            given = data.get("given")
            return cls(
                robot=data["robot"], r=float(data["r"]), b=float(data["b"]), limits=Limits.from_dict(data["limits"]),
                noise=SensorNoise(float(noise["eta_std"]), float(noise["tau_std"]), float(noise["rate"])),
                excitation=Excitation.from_dict(data["excitation"]), settings=PlanSettings.from_dict(data["settings"]),
                predicted={n: PredictedStd.from_dict(p) for n, p in data["predicted"].items()}, criterion=criterion,
                limits_used={n: LimitUse.from_dict(u) for n, u in data["limits_used"].items()},
                baselines={n: BaselineForecast.from_dict(b) for n, b in data["baselines"].items()},
                margins=Separability.from_dict(data["margins"]),
                given=None if given is None else GivenResults.from_dict(given),
                warnings=tuple(data.get("warnings", ())),
            )  # fmt: skip
        except (AttributeError, KeyError, TypeError, ValueError) as err:
            raise UsageError(f"{source}: not a valid plan ({type(err).__name__}: {err})") from None


def plan_form(friction: str, geometry: tuple[float, ...] = ()) -> RegressorForm:
    """The regressor form a plan predicts for: ``friction`` "wheel", "wheel+caster" (each caster's drag with the
    casters' ``geometry`` (r, b, x_1, y_1, ...) m, the two-term Cv, Cw without) or "wheel+caster+load" (the geometric
    drag that follows the load; needs the geometry)."""
    if friction == "wheel":
        return RegressorForm("general")
    if not geometry:
        return RegressorForm("general", caster=True)
    return RegressorForm("general", caster=True, geometry=geometry,
                         load=load_signals(geometry) if friction == "wheel+caster+load" else ())  # fmt: skip


def period_for(duration: float) -> float:
    """The base period (s): the duration split into a whole number of periods near :data:`PERIOD_SECONDS`."""
    return duration / max(1, round(duration / PERIOD_SECONDS))


def predicted_std(
    problem: Problem, theta0: np.ndarray, cov: np.ndarray, names: tuple[str, ...]
) -> dict[str, PredictedStd]:
    """Base parameter name -> its :class:`PredictedStd` from the predicted covariance ``cov`` (n, n) of ``problem``
    (nominal ``theta0`` (n,)): the parameters past ``problem.judged`` are not counted."""
    rel = problem.relative_std(cov)
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    return {
        name: PredictedStd(nominal=float(theta0[i]), scale=float(problem.scales[i]),
                           scale_from=problem.scale_sources[i], std=float(std[i]), relative=float(rel[i]),
                           counted=i < problem.judged)
        for i, name in enumerate(names)
    }  # fmt: skip


def criterion_of(name: str, value: float, predicted: dict[str, PredictedStd]) -> Criterion:
    """The :class:`Criterion` ``name`` at ``value``, its worst parameter the counted one of ``predicted`` with the
    largest relative std."""
    counted = [n for n, p in predicted.items() if p.in_criterion]
    worst = max(counted, key=lambda n: predicted[n].relative)  # type: ignore[arg-type,return-value]
    return Criterion(name=name, text=CRITERION_TEXT[name], value=value, worst=worst)


def _limits_used(problem: Problem, motion: Motion) -> dict[str, LimitUse]:
    peaks = motion.peaks()
    out = {}
    for name in LIMIT_NAMES:
        limit = problem.limits.limit(name)
        out[name] = LimitUse(
            limit=limit, bound=problem.bounds.get(name), peak=peaks[name],
            share=None if limit is None else peaks[name] / limit, unit=LIMIT_NAMES[name][0],
        )  # fmt: skip
    return out


#: Share of the wheel speed limit under which a wheel counts as near standstill (``margins[wheel]["near_zero_share"]``,
#: over the time between the ramps; a warning above NEAR_ZERO_WARN).
NEAR_ZERO = 0.03
NEAR_ZERO_WARN = 0.05


def separability(motion: Motion, wheel_speed_limit: float, interior: np.ndarray) -> Separability:
    """What lets the log tell the parameters apart: per wheel, the share of time it turns forward faster than a tenth
    of the wheel speed limit and backward likewise (the search keeps each >= DIRECTION_SHARE), and its speed
    magnitude's 10th/50th/90th percentiles while doing so (rad/s) -- F_v and F_d separate when each wheel runs at
    several speeds in both directions; the correlation of v and w and of |v| and |w| (m12 and Vc need them to vary
    independently; the search keeps |corr(v, w)| <= CORRELATION); and the share of the time between the ramps each wheel
    spends within NEAR_ZERO of the limit from standstill."""
    wheels = []
    for j in range(2):  # right, left
        eta = motion.eta[:, j]
        moving = np.abs(eta) > 0.1 * wheel_speed_limit
        speed = np.abs(eta[moving]) if np.any(moving) else np.zeros(1)
        wheels.append(WheelSpread(
            forward_share=float(np.mean(eta > 0.1 * wheel_speed_limit)),
            backward_share=float(np.mean(eta < -0.1 * wheel_speed_limit)),
            speed_percentiles=tuple(float(v) for v in np.percentile(speed, [10, 50, 90])),
            near_zero_share=float(np.mean(np.abs(eta[interior]) < NEAR_ZERO * wheel_speed_limit)),
        ))  # fmt: skip
    return Separability(
        threshold=0.1 * wheel_speed_limit, direction_share_min=DIRECTION_SHARE, corr_max=CORRELATION,
        right=wheels[0], left=wheels[1], corr_v_w=float(np.corrcoef(motion.v, motion.w)[0, 1]),
        corr_abs_v_abs_w=float(np.corrcoef(np.abs(motion.v), np.abs(motion.w))[0, 1]),
    )  # fmt: skip


def _problem(
    theta0: np.ndarray, form: RegressorForm, r: float, b: float, limits: Limits, noise: SensorNoise, duration: float,
    grid: float, criterion: str, given_info: GivenLogs | None, k: float,
) -> Problem:  # fmt: skip
    return Problem(
        theta0, form, r, b, limits, noise, duration=duration, period=period_for(duration), harmonics=HARMONICS,
        ramp=min(RAMP_SECONDS, duration / 4.0), grid=grid, k=k, criterion=criterion, given_info=given_info,
    )  # fmt: skip


def make_plan(
    robot_name: str, theta0: np.ndarray, r: float, b: float, limits: Limits, noise: SensorNoise, *,
    duration: float | None = 60.0, target_std: float | None = None, rate: float = 50.0, seed: int = 0,
    criterion: str = "worst", friction: str = "wheel", k: float = DEFAULT_K,
    given: tuple[GivenLogs, GivenResults] | None = None, progress: Any = None,
    geometry: tuple[float, ...] = (), drag: tuple[float, ...] = (),
) -> Plan:  # fmt: skip
    """Design and predict a plan (module docstring).

    theta0 : (8,) nominal base parameters; r, b : nominal wheel radius and half track (m).  duration : s, or None
    with ``target_std`` (a share, e.g. 0.02): the shortest plan (in whole base periods, at most
    :data:`MAX_AUTO_DURATION`) predicted to reach it.  rate : Hz of the written reference.  friction : the model
    identify will fit, which the prediction is made for: ``wheel``, ``wheel+caster`` (with ``geometry`` (r, b, x_1,
    y_1, ...) m: each caster's drag D_k, nominal ``drag`` N per caster of the geometry; without: the two-term
    Cv, Cw) or ``wheel+caster+load`` (the geometric model whose drag follows the load).  given : (the logs already
    identified, :class:`wmrid.design.information.GivenLogs` over the prediction's parameters, description).
    progress : called with a sentence per stage, or None.
    """
    if criterion not in CRITERIA:
        raise UsageError(f"{option('criterion', criterion)}: choose one of {', '.join(CRITERIA)}")
    if friction not in ("wheel", "wheel+caster", "wheel+caster+load"):
        raise UsageError(
            f"{option('friction', friction)}: a plan models wheel, wheel+caster or wheel+caster+load friction"
        )
    if friction == "wheel+caster+load" and not geometry:
        raise UsageError(
            f"{option('friction', friction)} needs the casters' positions (the robot file's [[caster]] tables)"
        )
    form = plan_form(friction, geometry)
    if form.geometry and len(drag) != form.n_casters:
        raise ValueError(f"drag holds {len(drag)} values for {form.n_casters} casters")
    theta0 = np.asarray(theta0, dtype=np.float64)[:8]
    theta0 = np.concatenate([theta0, np.asarray(drag, dtype=np.float64), np.zeros(form.n_base - 8 - len(drag))])
    given_info = None if given is None else given[0]
    say = progress or (lambda _text: None)
    started = time.perf_counter()

    def design(length: float) -> tuple[Problem, Problem, SearchResult, float, Motion, np.ndarray]:
        problem = _problem(theta0, form, r, b, limits, noise, length, SEARCH_GRID, criterion, given_info, k)
        try:
            warm: tuple[np.ndarray, ...] = ()
            if given_info is not None:  # the plan that ignores them is a start (never worse on the search grid)
                bare = _problem(theta0, form, r, b, limits, noise, length, SEARCH_GRID, criterion, None, k)
                warm = (search(bare, seed=seed).coefficients,)
            found = search(problem, seed=seed, warm=warm)
        except ValueError:
            raise UsageError(_infeasible(limits, r, b)) from None
        fine = _problem(theta0, form, r, b, limits, noise, length, min(noise.rate, FINE_GRID), criterion,
                        given_info, k)  # fmt: skip
        motion = fine.motion_of(found.coefficients)
        cov = fine.covariance(motion)
        return problem, fine, found, fine.criterion_value(cov), motion, cov

    if duration is None:
        if target_std is None:
            raise UsageError(f"{option('duration', 'auto')} needs {option('target_std')}")
        length = 30.0
        say(f"trial plan of {length:g} s")
        problem, fine, found, value, motion, cov = design(length)
        for _ in range(6):
            if value <= target_std:
                break
            need = length * (value / target_std) ** 2 * 1.05
            if need > MAX_AUTO_DURATION:
                raise UsageError(
                    f"{option('target_std', f'{100 * target_std:g}')}: not reachable within {MAX_AUTO_DURATION:g} s "
                    f"(a {length:g} s plan predicts {100 * value:.3g} %, and the std falls only as 1/sqrt(duration)); "
                    "allow faster motion (the limits) or less noise, or aim for a larger std"
                )
            length = PERIOD_SECONDS * math.ceil(need / PERIOD_SECONDS)
            say(f"plan of {length:g} s")
            problem, fine, found, value, motion, cov = design(length)
        else:
            raise UsageError(f"{option('target_std')}: no plan up to {length:g} s reached it ({100 * value:.3g} %)")
    else:
        if not (isinstance(duration, (int, float)) and math.isfinite(duration) and duration >= MIN_DURATION):
            raise UsageError(f"{option('duration', f'{duration:g}')}: a plan lasts at least {MIN_DURATION:g} s")
        say(f"plan of {duration:g} s")
        problem, fine, found, value, motion, cov = design(float(duration))
    if not found.feasible:
        raise UsageError(_inseparable(problem.duration))

    predicted = predicted_std(fine, theta0, cov, form.base_names)
    say("baselines")
    baselines = {name: baseline_forecast(fine, name, theta0, form, value) for name in BASELINES}
    warnings = []
    if limits.max_torque is None:
        warnings.append(
            f"no torque limit given ({option('max_torque')} or the robot file's [limits]): the plan's torques reach "
            f"{motion.peaks()['max_torque']:.3g} N m on the nominal model"
        )
    floors = [n for n, src in zip(form.base_names, fine.scale_sources, strict=True) if src == "floor"]
    if floors:
        warnings.append(
            f"the robot file's nominal {', '.join(floors)} {'is' if len(floors) == 1 else 'are'} 0 or small (its "
            f"effect under {100 * FLOOR_SHARE:g} % of the torque scale): {'its' if len(floors) == 1 else 'their'} "
            "relative std is taken against that floor (see 'scale'), so it is smaller than the std over the value"
        )
    interior = (fine.t > fine.ramp) & (fine.t < fine.duration - fine.ramp)
    for j, wheel in enumerate(("right", "left")):
        share = float(np.mean(np.abs(motion.eta[interior, j]) < NEAR_ZERO * limits.max_wheel_speed))
        if share > NEAR_ZERO_WARN:
            warnings.append(
                f"the {wheel} wheel spends {100 * share:.0f} % of the drive within "
                f"{NEAR_ZERO * limits.max_wheel_speed:.2g} rad/s of standstill, where it may stick and its measured "
                "sign flips with the noise: both bias the Coulomb friction the estimator fits (measured on simulated "
                "plans: F_d up to 4-5 std off), beyond what the predicted std covers"
            )
    if target_std is not None and value > target_std:
        warnings.append(f"the plan predicts {100 * value:.3g} %, above the target {100 * target_std:g} %")
    settings = PlanSettings(
        duration=problem.duration, period=problem.period, harmonics=HARMONICS, ramp=problem.ramp,
        rate=float(rate), seed=int(seed), criterion=criterion, friction=friction,
        caster_geometry=tuple(form.geometry), k=k,
        target_std=target_std, search_grid=SEARCH_GRID, prediction_grid=fine.t.size / fine.duration,
        starts=found.starts, evaluations=found.evaluations,
        seconds=time.perf_counter() - started, parameter_names=tuple(form.base_names),
    )  # fmt: skip
    return Plan(
        robot=robot_name, r=float(r), b=float(b), limits=limits, noise=noise,
        excitation=Excitation(problem.duration, problem.period, found.coefficients, problem.ramp), settings=settings,
        predicted=predicted, criterion=criterion_of(criterion, value, predicted),
        limits_used=_limits_used(fine, motion), baselines=baselines,
        margins=separability(motion, limits.max_wheel_speed, interior), given=None if given is None else given[1],
        warnings=tuple(warnings),
    )  # fmt: skip


def _inseparable(duration: float) -> str:

    return (
        f"no {duration:g} s drive found that keeps the limits and still separates the parameters (each wheel forward "
        f"and backward at least {100 * DIRECTION_SHARE:.0f} % of the time, |corr(v, w)| <= {CORRELATION:g}); give a "
        "longer --duration or wider limits"
    )


def _infeasible(limits: Limits, r: float, b: float) -> str:
    bounds = limits.bounds()
    return (
        f"no drive found within the limits: the area {limits.area[0]:g} m x {limits.area[1]:g} m leaves "
        f"{bounds['area_x']:.2g} m x {bounds['area_y']:.2g} m from the start after the margin, for wheel speeds up to "
        f"{bounds['max_wheel_speed']:.3g} rad/s ({bounds['max_wheel_speed'] * r:.3g} m/s at the rim); give a larger "
        f"{option('area')} or check the limits"
    )
