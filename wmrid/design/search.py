"""The search for the drive that identifies the robot best: a seeded global start, then a local refinement.

Global: ``starts`` random coefficient sets (harmonic amplitudes falling as 1/sqrt(n), random phases, a random split of
the speed budget between v and w), each scaled by bisection to the largest size that keeps every limit, and any warm
start given (the plan designed without ``--given``); the best few by the criterion go on.  Local: SLSQP
(scipy.optimize) on all coefficients, the criterion made smooth (:meth:`Problem.smooth_objective`) and every limit an
inequality constraint.  Deterministic for a given seed.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.optimize import minimize

from wmrid.design.problem import Differentiated, Motion, Problem


@dataclass(frozen=True)
class SearchResult:
    """coefficients (2, N, 2); value : the criterion; feasible : every limit kept; evaluations : of the criterion."""

    coefficients: np.ndarray
    value: float
    feasible: bool
    evaluations: int
    starts: int


class _Cache:
    """Motion and covariance per coefficient vector, so that SLSQP's objective and constraints share one motion."""

    def __init__(self, problem: Problem) -> None:
        self.problem = problem
        self.key: bytes | None = None
        self.motion: Motion | None = None
        self.cov: np.ndarray | None = None
        self.evaluations = 0

    def at(self, x: np.ndarray) -> tuple[Motion, np.ndarray | None]:
        key = x.tobytes()
        if key != self.key:
            self.key = key
            self.motion = self.problem.motion_of(x.reshape(2, -1, 2))
            self.cov = None
        return self.motion, self.cov  # type: ignore[return-value]

    def covariance(self, x: np.ndarray) -> np.ndarray:
        motion, cov = self.at(x)
        if cov is None:
            try:
                cov = self.problem.covariance(motion)
            except np.linalg.LinAlgError:
                cov = np.full((len(self.problem.theta0),) * 2, np.inf)
            self.cov = cov
            self.evaluations += 1
        return cov


def constraint_values(problem: Problem, motion: Motion) -> np.ndarray:
    """1 - peak / bound for each limit and each separability constraint (>= 0: kept)."""
    ratios = [*problem.ratios(motion).values(), *problem.separation(motion).values()]
    return 1.0 - np.array(ratios)


#: How many of the best starts get a short refinement (a quarter of ``maxiter``), and how many of those are then
#: refined to the end.  Measured (search seeds 0-4, the paper robot's 30 s plan at 0.085 rad/s and 0.425 N m, the
#: light AMR's 60 s plan at the same noise): refining 4 left the worst relative std at 2.23-2.61 % (median 2.46 %)
#: and 13.2-15.0 % (median 13.8 %); refining 12 gave 2.22-2.48 % (median 2.23 %) and 13.1-14.6 % (median 13.2 %), in
#: about twice the time.  Polishing the best 3 instead of 1 bettered one paper seed in five (2.48 -> 2.35 %) for
#: half as much time again: the best 2 are polished.
REFINE = 12
POLISH = 2
#: The local search constrains every CONSTRAINT_STRIDE-th sample of the design grid (1: all of them; every other
#: one was tried: half the subproblem's size, but its optima then break the bound between samples and are refused).
CONSTRAINT_STRIDE = 1


def sample_constraints(problem: Problem, motion: Motion) -> np.ndarray:
    """1 - |value| / bound at every sample of every limited quantity (>= 0: kept): smooth in the coefficients, as
    SLSQP needs (the peaks alone jump from one sample to another)."""
    b = problem.bounds
    motion = motion.every(CONSTRAINT_STRIDE)
    parts = [np.abs(motion.eta).ravel() / b["max_wheel_speed"], np.abs(motion.deta).ravel() / b["max_wheel_accel"],
             np.abs(motion.pose[:, 0]) / b["area_x"], np.abs(motion.pose[:, 1]) / b["area_y"]]  # fmt: skip
    if "max_torque" in b:
        parts.append(np.abs(motion.tau).ravel() / b["max_torque"])
    if "max_speed" in b:
        parts.append(np.abs(motion.v) / b["max_speed"])
    if "max_turn_rate" in b:
        parts.append(np.abs(motion.w) / b["max_turn_rate"])
    return np.concatenate([1.0 - np.concatenate(parts), 1.0 - np.array(list(problem.separation(motion).values()))])


def largest_scale(problem: Problem, shape: np.ndarray, hi: float = 4.0) -> float:
    """The largest factor s in (0, hi] with every limit kept by s x shape (bisection, 24 steps; 0 when none is)."""

    def ok(s: float) -> bool:
        return max(problem.ratios(problem.motion_of(s * shape)).values()) <= 1.0

    if ok(hi):
        return hi
    lo, top = 0.0, hi
    for _ in range(24):
        mid = 0.5 * (lo + top)
        if ok(mid):
            lo = mid
        else:
            top = mid
    return lo


def random_shape(problem: Problem, rng: np.random.Generator) -> np.ndarray:
    """A random coefficient set (2, N, 2): amplitudes ~ 1/sqrt(n) with random phases; the channels normalised to the
    speed each could use alone (r eta_max for v, r eta_max / b for w) and split by a random angle."""
    n = problem.harmonics
    amp = rng.standard_normal((2, n)) / np.sqrt(np.arange(1, n + 1))
    phase = rng.uniform(0.0, 2.0 * math.pi, (2, n))
    coef = np.stack([amp * np.cos(phase), amp * np.sin(phase)], axis=2)
    v, w, _, _ = problem.basis.signals(coef)
    alpha = rng.uniform(0.25, 0.5 * math.pi - 0.25)
    v_full = problem.r * problem.limits.max_wheel_speed
    coef[0] *= math.cos(alpha) * v_full / max(float(np.max(np.abs(v))), 1e-12)
    coef[1] *= math.sin(alpha) * v_full / problem.b / max(float(np.max(np.abs(w))), 1e-12)
    return coef


def search(
    problem: Problem,
    seed: int = 0,
    starts: int = 32,
    refine: int = REFINE,
    maxiter: int = 120,
    polish: int = POLISH,
    warm: tuple[np.ndarray, ...] = (),
) -> SearchResult:
    """Design the coefficients (module docstring).  ``starts`` random starts and the ``warm`` ones (coefficient sets
    (2, N, 2), e.g. the plan designed without the logs already identified: the result is then never worse than
    them), the best ``refine`` refined briefly, the best ``polish`` of those to the end."""
    rng = np.random.Generator(np.random.PCG64(seed))
    cache = _Cache(problem)
    candidates: list[tuple[float, np.ndarray]] = []
    for _ in range(starts):
        shape = random_shape(problem, rng)
        s = largest_scale(problem, shape)
        if s <= 0:
            continue
        x = (s * shape).ravel()
        value = problem.smooth_objective(cache.covariance(x))
        if math.isfinite(value):
            # a start that breaks a separability constraint ranks after those that keep them, and is refined only
            # towards a drive that keeps them
            kept = bool(np.all(constraint_values(problem, cache.at(x)[0]) >= -1e-6))
            candidates.append((value if kept else value + 1e3, x))
    for coef in warm:
        x = np.asarray(coef, dtype=np.float64).ravel()
        value = problem.smooth_objective(cache.covariance(x))
        if math.isfinite(value) and bool(np.all(constraint_values(problem, cache.at(x)[0]) >= -1e-6)):
            candidates.append((value, x))
    if not candidates:
        raise ValueError("no random start keeps every limit")
    candidates.sort(key=lambda item: item[0])

    def fun(x: np.ndarray) -> float:
        value = problem.smooth_objective(cache.covariance(x))
        return value if math.isfinite(value) else 1e6

    def cons(x: np.ndarray) -> np.ndarray:
        motion, _ = cache.at(x)
        return constraint_values(problem, motion)

    def sample_cons(x: np.ndarray) -> np.ndarray:
        motion, _ = cache.at(x)
        return sample_constraints(problem, motion)

    diff = Differentiated(problem)

    def refined(value0: float, x0: np.ndarray, iterations: int) -> tuple[float, np.ndarray]:
        """SLSQP from x0 for at most ``iterations`` (analytic gradients of the objective and of every constraint);
        x0 itself when the result is worse or leaves the limits."""
        scale = float(np.max(np.abs(x0)))

        def objective(z: np.ndarray) -> tuple[float, np.ndarray]:
            value, grad = diff.objective(z * scale)
            cache.evaluations += 1
            return value, grad * scale

        try:
            out = minimize(
                objective, x0 / scale, jac=True, method="SLSQP",
                constraints=[{"type": "ineq", "fun": lambda z: sample_cons(z * scale),
                              "jac": lambda z: diff.constraint_jacobian(z * scale, CONSTRAINT_STRIDE) * scale}],
                options={"maxiter": iterations, "ftol": 1e-9},
            )  # fmt: skip
            x = out.x * scale
        except (ValueError, np.linalg.LinAlgError):
            return value0, x0
        if not bool(np.all(cons(x) >= -1e-6)):
            return value0, x0
        value = fun(x)
        return (value, x) if value < value0 else (value0, x0)  # an infeasible start's value carries 1e3

    # a short refinement of the best few, then a long one of the best of them
    short = sorted((refined(v, x, maxiter // 4) for v, x in candidates[:refine]), key=lambda item: item[0])
    best = min((refined(*item, maxiter) for item in short[:polish]), key=lambda item: item[0])
    coef = best[1].reshape(2, -1, 2)
    motion, _ = cache.at(best[1])
    feasible = bool(np.all(constraint_values(problem, motion) >= -1e-6))
    return SearchResult(coef, problem.criterion_value(cache.covariance(best[1])), feasible, cache.evaluations, starts)
