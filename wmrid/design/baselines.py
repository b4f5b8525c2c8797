"""A plan's baselines: the built-in trajectories of ``wmrid simulate`` (:data:`wmrid.design.plan.BASELINES`) over
the plan's duration, slowed down uniformly until they keep the limits (:func:`baseline_motion`), and the precision
each is predicted to give (:func:`baseline_forecast`), for :func:`wmrid.design.plan.make_plan` to compare with.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from wmrid.design.information import GivenLogs
from wmrid.design.plan_records import BaselineForecast, OpenFloorForecast
from wmrid.design.problem import Motion, Problem
from wmrid.model.dynamics import RegressorForm, choose_form


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

    out: np.ndarray = reference_signals(kind, traj, np.ascontiguousarray(t, dtype=np.float64))
    return out


def baseline_forecast(
    fine: Problem, name: str, theta0: np.ndarray, form: RegressorForm, value: float
) -> BaselineForecast:
    """The prediction for baseline ``name`` within every limit (the area included: that is the comparison), and
    with the area ignored (how it would do on an open floor), on the plan's fine grid.  Each is predicted under the
    model identify fits to that log: the plan's, except that wheels that never reverse get the paper's form and no
    caster drag (it cannot be told from F_d there), so the drag's parameters are then undetermined (inf) and not
    counted."""
    within, _ = _forecast(fine, name, theta0, form, value, area=True)
    open_floor, motion = _forecast(fine, name, theta0, form, value, area=False)
    ratios = fine.ratios(motion)
    leaves = bool(max(ratios["area_x"], ratios["area_y"]) > 1.0 / (1.0 - fine.limits.margin))
    return BaselineForecast(**within, area_ignored=OpenFloorForecast(**open_floor, leaves_area=leaves))


def _forecast(
    fine: Problem, name: str, theta0: np.ndarray, form: RegressorForm, value: float, area: bool
) -> tuple[dict[str, Any], Motion]:
    """(the figures of a :class:`~wmrid.design.plan_records.DriveForecast`, the motion) of baseline ``name`` slowed
    down for the limits (``area``: the area too) (:func:`baseline_forecast`)."""
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
    figures = {
        "value": crit, "relative": dict(zip(form.base_names, map(float, rel), strict=True)),
        "worst": form.base_names[int(np.argmax(counted))], "slowed_by": factor, "peaks": motion.peaks(),
        "improvement": crit / value if value > 0 else math.inf, "friction": base_form.friction,
    }  # fmt: skip
    return figures, motion
