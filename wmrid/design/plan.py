"""``wmrid plan``: the drive that identifies a robot, as a typed, JSON round-tripping :class:`Plan`.

:func:`make_plan` sets up the design problem (:mod:`wmrid.design.problem`) from the robot's nominal base parameters,
the limits and the sensor noise, searches it (:mod:`wmrid.design.search`) on a coarse grid, and predicts the
precision of the result on the log's own grid (its rate, at most :data:`FINE_GRID` Hz), together with the same
prediction for two baselines of the same duration within the same limits: the paper's sinusoid and the back-and-forth
``reversing`` drive of ``wmrid simulate`` (each slowed down uniformly when it would break a limit; the area is not
imposed on them, and whether they leave it is said).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from wmrid.core.errors import UsageError, option
from wmrid.design.excitation import RAMP_SECONDS, Excitation, pose_along
from wmrid.design.information import DEFAULT_K, GivenLogs, SensorNoise
from wmrid.design.limits import LIMIT_NAMES, Limits
from wmrid.design.problem import CORRELATION, CRITERIA, DIRECTION_SHARE, FLOOR_SHARE, Motion, Problem
from wmrid.design.search import search
from wmrid.model.dynamics import RegressorForm, choose_form, load_signals

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
    """A planned drive and what it predicts (all SI).

    robot : its name; r, b : m (nominal).  limits : :class:`Limits`.  noise : :class:`SensorNoise`.  excitation : the
    reference (:class:`Excitation`).  settings : duration, period, harmonics, rate (Hz of the written reference),
    seed, criterion, friction, k, the search's statistics.  predicted : name -> {nominal, scale, scale_from, std,
    relative} for each base parameter (std in the parameter's unit; relative = std / scale).  value : the criterion.
    limits_used : limit name -> {limit, bound, peak, share} (share = peak / limit).  baselines : name -> {value,
    relative, worst, slowed_by, leaves_area, peaks}.  margins : what makes the parameters separable (time each
    wheel spends in each direction, its speed spread, the correlation of v and w).  given : the logs already
    identified whose information was added (None).  warnings : sentences.
    """

    robot: str
    r: float
    b: float
    limits: Limits
    noise: SensorNoise
    excitation: Excitation
    settings: dict[str, Any]
    predicted: dict[str, dict[str, Any]]
    value: float
    limits_used: dict[str, dict[str, float | None]]
    baselines: dict[str, dict[str, Any]]
    margins: dict[str, Any]
    given: dict[str, Any] | None = None
    warnings: tuple[str, ...] = field(default=())

    @property
    def form(self) -> RegressorForm:
        """The regressor form the prediction is for (``settings["friction"]``, the casters' geometry when given)."""
        return plan_form(self.settings.get("friction", "wheel"), tuple(self.settings.get("caster_geometry") or ()))

    @property
    def worst(self) -> str:
        """The base parameter with the largest predicted relative std (of those the criterion counts)."""
        counted = [n for n, v in self.predicted.items() if v.get("counted", True)]
        return max(counted, key=lambda n: self.predicted[n]["relative"])

    def samples(self, rate: float | None = None) -> dict[str, np.ndarray]:
        """The reference at ``rate`` Hz (default: the plan's): t (s), v (m/s), omega (rad/s), eta_r, eta_l (rad/s,
        the wheel-speed set-points, nominal r and b), x, y (m), phi (rad) of the predicted pose."""
        rate = float(rate or self.settings["rate"])
        n = round(self.excitation.duration * rate) + 1
        t = np.linspace(0.0, self.excitation.duration, n)
        v, w, _, _ = self.excitation.evaluate(t)
        # the pose on a fine grid (at least 200 Hz), read at the plan's rate
        every = max(1, math.ceil(200.0 / rate))
        fine = np.linspace(0.0, self.excitation.duration, (n - 1) * every + 1)
        vf, wf, _, _ = self.excitation.evaluate(fine)

        pose = pose_along(fine, vf, wf)[::every]
        return {
            "t": t, "v": v, "omega": w, "eta_r": (v + self.b * w) / self.r, "eta_l": (v - self.b * w) / self.r,
            "x": pose[:, 0], "y": pose[:, 1], "phi": pose[:, 2],
        }  # fmt: skip

    def to_dict(self) -> dict[str, Any]:
        return {
            "schema": SCHEMA, "kind": "plan", "robot": self.robot, "r": self.r, "b": self.b,
            "criterion": {"name": self.settings["criterion"], "text": CRITERION_TEXT[self.settings["criterion"]],
                          "value": self.value, "worst": self.worst},
            "predicted": self.predicted, "limits": self.limits.to_dict(), "limits_used": self.limits_used,
            "baselines": self.baselines, "margins": self.margins, "noise": self.noise.to_dict(),
            "settings": self.settings, "excitation": self.excitation.to_dict(), "given": self.given,
            "warnings": list(self.warnings),
        }  # fmt: skip

    @classmethod
    def from_dict(cls, data: dict[str, Any], source: str = "plan") -> Plan:
        if not isinstance(data, dict) or data.get("kind") != "plan":
            raise UsageError(f'{source}: not a plan written by wmrid plan (no "kind": "plan")')
        if data.get("schema", 0) > SCHEMA:
            raise UsageError(f"{source}: a plan of schema {data['schema']}, newer than this wmrid reads ({SCHEMA})")
        try:
            noise = data["noise"]
            return cls(
                robot=data["robot"], r=float(data["r"]), b=float(data["b"]), limits=Limits.from_dict(data["limits"]),
                noise=SensorNoise(float(noise["eta_std"]), float(noise["tau_std"]), float(noise["rate"])),
                excitation=Excitation.from_dict(data["excitation"]), settings=dict(data["settings"]),
                predicted=data["predicted"], value=float(data["criterion"]["value"]),
                limits_used=data["limits_used"], baselines=data["baselines"], margins=data["margins"],
                given=data.get("given"), warnings=tuple(data.get("warnings", ())),
            )  # fmt: skip
        except (KeyError, TypeError, ValueError) as err:
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


def _limits_used(problem: Problem, motion: Motion) -> dict[str, dict[str, float | None]]:
    peaks = motion.peaks()
    out = {}
    for name in LIMIT_NAMES:
        limit = problem.limits.limit(name)
        out[name] = {
            "limit": limit, "bound": problem.bounds.get(name), "peak": peaks[name],
            "share": None if limit is None else peaks[name] / limit, "unit": LIMIT_NAMES[name][0],
        }  # fmt: skip
    return out


#: Share of the wheel speed limit under which a wheel counts as near standstill (``margins[wheel]["near_zero_share"]``,
#: over the time between the ramps; a warning above NEAR_ZERO_WARN).
NEAR_ZERO = 0.03
NEAR_ZERO_WARN = 0.05


def separability(motion: Motion, wheel_speed_limit: float, interior: np.ndarray) -> dict[str, Any]:
    """What lets the log tell the parameters apart: per wheel, the share of time it turns forward faster than a tenth
    of the wheel speed limit and backward likewise (the search keeps each >= DIRECTION_SHARE), and its speed
    magnitude's 10th/50th/90th percentiles while doing so (rad/s) -- F_v and F_d separate when each wheel runs at
    several speeds in both directions; the correlation of v and w and of |v| and |w| (m12 and Vc need them to vary
    independently; the search keeps |corr(v, w)| <= CORRELATION); and the share of the time between the ramps each wheel
    spends within NEAR_ZERO of the limit from standstill."""
    out: dict[str, Any] = {"threshold": 0.1 * wheel_speed_limit, "direction_share_min": DIRECTION_SHARE,
                           "corr_max": CORRELATION}  # fmt: skip
    for j, wheel in enumerate(("right", "left")):
        eta = motion.eta[:, j]
        moving = np.abs(eta) > 0.1 * wheel_speed_limit
        speed = np.abs(eta[moving]) if np.any(moving) else np.zeros(1)
        out[wheel] = {
            "forward_share": float(np.mean(eta > 0.1 * wheel_speed_limit)),
            "backward_share": float(np.mean(eta < -0.1 * wheel_speed_limit)),
            "speed_percentiles": [float(v) for v in np.percentile(speed, [10, 50, 90])],
            "near_zero_share": float(np.mean(np.abs(eta[interior]) < NEAR_ZERO * wheel_speed_limit)),
        }
    out["corr_v_w"] = float(np.corrcoef(motion.v, motion.w)[0, 1])
    out["corr_abs_v_abs_w"] = float(np.corrcoef(np.abs(motion.v), np.abs(motion.w))[0, 1])
    return out


def baseline_motion(problem: Problem, name: str, area: bool = True) -> tuple[Motion, float]:
    """(motion, factor): the ``wmrid simulate`` trajectory ``name`` over the plan's duration on ``problem``'s grid,
    slowed down uniformly (speeds times factor <= 1) until it keeps every limit (``area``: the area too)."""
    from wmrid.sim.closed_loop import KIND  # the simulator's built-in trajectories: only a plan's baselines
    from wmrid.sim.simulate import TRAJECTORY_PARAMETERS  # the simulator (~30 ms): only a plan's baselines

    traj = np.array(list(TRAJECTORY_PARAMETERS[name].values()), dtype=np.float64)
    v, w, dv, dw = _reference_signals(KIND[name], traj, problem.t).T
    ratios = problem.ratios(problem.motion_from(problem.t, v, w, dv, dw))
    factor = 1.0
    for _ in range(40):
        worst = max(r for n, r in ratios.items() if area or not n.startswith("area"))
        if worst <= 1.0 + 1e-9:
            break
        factor *= 0.999 / worst if worst > 1.0 else 1.0
        ratios = problem.ratios(problem.motion_from(problem.t, factor * v, factor * w, factor * dv, factor * dw))
    return problem.motion_from(problem.t, factor * v, factor * w, factor * dv, factor * dw), factor


def _reference_signals(kind: int, traj: np.ndarray, t: np.ndarray) -> np.ndarray:
    """(n, 4): v, w, v', w' of a built-in trajectory at times t (compiled: a 1 kHz minute is 60,000 calls)."""
    # the simulator's reference (its numba kernels, cached on disk with them): only a plan's baselines
    from wmrid.sim.closed_loop import reference_signals

    return reference_signals(kind, traj, np.ascontiguousarray(t, dtype=np.float64))


def _problem(theta0, form, r, b, limits, noise, duration, grid, criterion, given_info, k) -> Problem:
    return Problem(
        theta0, form, r, b, limits, noise, duration=duration, period=period_for(duration), harmonics=HARMONICS,
        ramp=min(RAMP_SECONDS, duration / 4.0), grid=grid, k=k, criterion=criterion, given_info=given_info,
    )  # fmt: skip


def make_plan(
    robot_name: str, theta0: np.ndarray, r: float, b: float, limits: Limits, noise: SensorNoise, *,
    duration: float | None = 60.0, target_std: float | None = None, rate: float = 50.0, seed: int = 0,
    criterion: str = "worst", friction: str = "wheel", k: float = DEFAULT_K,
    given: tuple[GivenLogs, dict[str, Any]] | None = None, progress: Any = None,
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

    def design(length: float):
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

    rel = fine.relative_std(cov)
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    predicted = {
        name: {"nominal": float(theta0[i]), "scale": float(fine.scales[i]), "scale_from": fine.scale_sources[i],
               "std": float(std[i]), "relative": float(rel[i]), "counted": i < fine.judged}
        for i, name in enumerate(form.base_names)
    }  # fmt: skip
    say("baselines")
    baselines = {name: _baseline(fine, name, theta0, form, value) for name in BASELINES}
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
    settings = {
        "duration": problem.duration, "period": problem.period, "harmonics": HARMONICS, "ramp": problem.ramp,
        "rate": float(rate), "seed": int(seed), "criterion": criterion, "friction": friction,
        "caster_geometry": list(form.geometry), "k": k,
        "target_std": target_std, "search_grid": SEARCH_GRID, "prediction_grid": fine.t.size / fine.duration,
        "starts": found.starts, "evaluations": found.evaluations,
        "seconds": time.perf_counter() - started, "parameter_names": list(form.base_names),
    }  # fmt: skip
    return Plan(
        robot=robot_name, r=float(r), b=float(b), limits=limits, noise=noise,
        excitation=Excitation(problem.duration, problem.period, found.coefficients, problem.ramp), settings=settings,
        predicted=predicted, value=value, limits_used=_limits_used(fine, motion), baselines=baselines,
        margins=separability(motion, limits.max_wheel_speed, interior), given=None if given is None else given[1],
        warnings=tuple(warnings),
    )  # fmt: skip


def _baseline(fine: Problem, name: str, theta0: np.ndarray, form: RegressorForm, value: float) -> dict[str, Any]:
    """The prediction for baseline ``name`` within every limit (the area included: that is the comparison), and
    with the area ignored (how it would do on an open floor), on the plan's fine grid.  Each is predicted under the
    model identify fits to that log: the plan's, except that wheels that never reverse get the paper's form and no
    caster drag (it cannot be told from F_d there), so the drag's parameters are then undetermined (inf) and not
    counted."""
    out: dict[str, Any] = {}
    for area in (True, False):
        motion, factor = baseline_motion(fine, name, area=area)
        base_form = choose_form(motion.eta)
        if base_form.kind == "general":
            base_form = form
        n = base_form.n_base
        given = fine.given_info
        if given is not None and n < len(theta0):
            given = GivenLogs(given.weight[:n, :n], given.spread[:n, :n])
        problem = Problem(
            theta0[:n], base_form, fine.r, fine.b, fine.limits, fine.noise, duration=fine.duration,
            period=fine.period, harmonics=fine.harmonics, ramp=fine.ramp, grid=fine.t.size / fine.duration, k=fine.k,
            criterion=fine.criterion, given_info=given,
        )  # fmt: skip
        rel = np.full(len(theta0), math.inf)
        try:
            cov = problem.covariance(motion)
            rel[:n], crit = problem.relative_std(cov), problem.criterion_value(cov)
        except np.linalg.LinAlgError:
            crit = math.inf
        counted = rel[: min(n, fine.judged)]
        entry = {
            "value": crit, "relative": dict(zip(form.base_names, map(float, rel), strict=True)),
            "worst": form.base_names[int(np.argmax(counted))], "slowed_by": factor, "peaks": motion.peaks(),
            "improvement": crit / value if value > 0 else math.inf, "friction": base_form.friction,
        }  # fmt: skip
        if area:
            out.update(entry)
        else:
            ratios = fine.ratios(motion)
            entry["leaves_area"] = bool(max(ratios["area_x"], ratios["area_y"]) > 1.0 / (1.0 - fine.limits.margin))
            out["area_ignored"] = entry
    return out


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
