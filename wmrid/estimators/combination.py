"""Logs of one robot combined into one estimate: ``wmrid identify LOG --given run.json`` (``wmrid plan --given``
predicts that combination before the log is recorded).

Each log k gives base parameters x_k (n0,) with a reported covariance C_k (n0, n0) on dof_k degrees of freedom
(the jackknife's).  They are combined by weights W_k: where the log's method has a weighting covariance V_k (the
observer's Newey-West sandwich, estimated from every block of the log: steady), V_k^-1 scaled by one number, how
much larger C_k's variances are than V_k's (their geometric mean, which carries C_k's widening); else C_k's inverse
with its correlations shrunk (:func:`given_weight`):

    x = A sum_k W_k x_k,    Cov(x) = A (sum_k W_k C_k W_k) A,    A = (sum_k W_k)^-1,

exact for fixed weights and linear in each reported C_k.  Weights made from a jackknife covariance are themselves
noisy (few degrees of freedom), the more so the more of its entries they use, so each variance is widened
by what that adds, found by a parametric bootstrap of the weighting (:func:`weight_noise_factor`): the
combination's std is as honest as the logs' own.  A jackknife covariance is never inverted into information: with 9
degrees of freedom for 8 parameters (a 20 s log) its eigenvalues were 0.07-23 times the true covariance's
(``bench/studies/study_plan.py --sequential``, seed 100).  The combination's degrees of freedom: Welch-Satterthwaite per
parameter, the smallest of them reported.

Only what means the same in both logs is combined: the inertia (m11, m12, m22) and V_c always; the friction terms
only when both logs were identified with the same friction model (a log fitted without the casters' drag holds it
in F_d, and a drag that follows the load is another model again).
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from wmrid.core.errors import UsageError, option
from wmrid.estimators.findings import Combination, CombinedResult, Uncertainty
from wmrid.estimators.result import IdentificationResult, finite_or_none, reported_names
from wmrid.estimators.uncertainty import interval_factor
from wmrid.estimators.verdict import settle
from wmrid.model.base_params import derived_with_std
from wmrid.model.dynamics import default_base_names
from wmrid.model.payload import payload_with_std

__all__ = [
    "COMBINED_NOTE", "SHARED_ALWAYS", "combine", "combined_result", "given_weight", "shared_names",
    "weight_noise_factor",
]  # fmt: skip

#: Base parameters whose meaning does not depend on the friction model.
SHARED_ALWAYS = ("m11", "m12", "m22", "Vc")
#: The first warning of a combined result (the count and the files follow).
COMBINED_NOTE = "combined with"


def given_weight(cov: np.ndarray, dof: float | None) -> np.ndarray:
    """The weight (n, n) of an estimate whose reported covariance ``cov`` (n, n, finite, positive diagonal) has
    ``dof`` degrees of freedom (the jackknife's; None: exact): the inverse of cov with its correlations shrunk towards
    none, by Schafer & Strimmer's (2005) intensity lambda = sum_{i<j} var(r_ij) / sum_{i<j} r_ij^2, var(r_ij) =
    (1 - r_ij^2)^2 / dof.  Any fixed weight keeps the combination's covariance honest (module docstring); this one
    keeps most of what the correlations tell (a sinusoid pins F_v eta + F_d of each wheel, not F_v and F_d) without
    trusting the directions that few degrees of freedom cannot resolve (fewer degrees of freedom than parameters: no
    correlation at all, the covariance being singular)."""
    return _weights(np.asarray(cov, dtype=np.float64)[None], dof)[0]


def shared_names(theirs: Sequence[str], ours: Sequence[str]) -> tuple[str, ...]:
    """The base parameters of ``ours`` that a result with base parameters ``theirs`` determines in the same sense:
    all of them when the two lists are the same model (the same names), else the inertia and V_c."""
    if tuple(theirs) == tuple(ours):
        return tuple(ours)
    return tuple(n for n in SHARED_ALWAYS if n in theirs and n in ours)


@dataclass(frozen=True)
class Part:
    """One log's estimate over n0 parameters: theta0 (n0,), cov (n0, n0) its reported covariance, dof (None:
    exact), the indices ``used`` of the parameters it contributes (determined by it, and meaning the same as in the
    combination), and ``weight_cov`` (n0, n0) the steadier covariance its method's weighting implies
    (:attr:`wmrid.estimators.estimate.BaseEstimate.weight_cov`), or None."""

    theta0: np.ndarray
    cov: np.ndarray
    dof: int | None
    used: tuple[int, ...]
    weight_cov: np.ndarray | None = None

    def steady(self) -> np.ndarray | None:
        """The weighting covariance over ``used`` (m, m), where it is finite and positive definite; else None."""
        if self.weight_cov is None:
            return None
        idx = list(self.used)
        sub = np.asarray(self.weight_cov, dtype=np.float64)[np.ix_(idx, idx)]
        if not np.all(np.isfinite(sub)):
            return None
        sub = 0.5 * (sub + sub.T)
        vals = np.linalg.eigvalsh(sub)
        return sub if vals[0] > 1e-12 * vals[-1] > 0 else None

    def weight(self, covs: np.ndarray | None = None) -> np.ndarray:
        """W over ``used`` (m, m) made from the reported covariance, or a stack (B, m, m) from ``covs`` (B, m, m)
        (the bootstrap's draws of it).  With a weighting covariance V: V^-1 / c, c the geometric mean of the
        reported variances over V's (one number, steady: it carries the widening the reported std has, such as the
        model-error scale, over every parameter); else :func:`given_weight` of the reported covariance."""
        idx = list(self.used)
        stack = covs if covs is not None else np.asarray(self.cov, dtype=np.float64)[np.ix_(idx, idx)][None]
        steady = self.steady()
        if steady is None:
            out = _weights(stack, self.dof)
        else:
            ratio = np.exp(np.mean(np.log(np.einsum("bii->bi", stack) / np.diag(steady)), axis=1))
            out = np.linalg.inv(steady)[None] / ratio[:, None, None]
        return out if covs is not None else out[0]


def combine(
    parts: Sequence[Part], n0: int, weight_noise: bool = True
) -> tuple[np.ndarray, np.ndarray, int | None, tuple[int, ...]]:
    """(x (n0,), Cov (n0, n0), dof, the indices determined): the combination (module docstring), its covariance
    widened by :func:`weight_noise_factor` unless ``weight_noise`` is False (the weights then taken as fixed).  An
    index no part uses is left NaN, its covariance row and column NaN with +inf on the diagonal."""
    weight, spread, wx = np.zeros((n0, n0)), np.zeros((n0, n0)), np.zeros(n0)
    weights = []
    random_weights = False
    for part in parts:
        idx = list(part.used)
        if not idx:
            weights.append(None)
            continue
        sub = np.asarray(part.cov, dtype=np.float64)[np.ix_(idx, idx)]
        w = part.weight()
        random_weights |= part.dof is not None
        weight[np.ix_(idx, idx)] += w
        spread[np.ix_(idx, idx)] += w @ sub @ w
        wx[idx] += w @ np.asarray(part.theta0, dtype=np.float64)[idx]
        weights.append((w, sub))
    det = tuple(i for i in range(n0) if weight[i, i] > 0)
    x = np.full(n0, np.nan)
    cov = np.full((n0, n0), np.nan)
    np.fill_diagonal(cov, np.inf)
    if not det:
        return x, cov, None, det
    d = list(det)
    a = np.linalg.inv(weight[np.ix_(d, d)])
    x[d] = a @ wx[d]
    sub_cov = a @ spread[np.ix_(d, d)] @ a
    cov[np.ix_(d, d)] = 0.5 * (sub_cov + sub_cov.T)
    # Welch-Satterthwaite: var_j = sum_k v_kj, v_kj the share of log k (K_k C_k K_k^T, K_k = A W_k)
    shares, dofs = [], []
    for part, held in zip(parts, weights, strict=True):
        if held is None:
            continue
        w, sub = held
        gain = a[:, [d.index(i) for i in part.used]] @ w
        shares.append(np.diag(gain @ sub @ gain.T))
        dofs.append(part.dof)
    total = np.sum(shares, axis=0)
    contributing = sum(1 for part in parts if part.used)
    if weight_noise and random_weights and contributing > 1:  # one log alone: its own std, nothing to widen
        scale = np.sqrt(weight_noise_factor(parts, det))
        cov[np.ix_(d, d)] *= np.outer(scale, scale)
    if all(v is None for v in dofs):
        return x, cov, None, det
    # a log known exactly (dof None) adds no term to the denominator
    denom = np.sum([s * s / max(v, 1) for s, v in zip(shares, dofs, strict=True) if v is not None], axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        nu = np.where(denom > 0, total * total / denom, np.inf)
    smallest = float(np.min(nu))
    return x, cov, (math.floor(smallest) if math.isfinite(smallest) else max(v for v in dofs if v is not None)), det


#: Draws of the parametric bootstrap of :func:`weight_noise_factor` (its own spread on a variance ratio: 3 %).
WEIGHT_DRAWS = 2000


def _weights(covs: np.ndarray, dof: float | None) -> np.ndarray:
    """:func:`given_weight` of each of a stack of covariances (B, m, m)."""
    d = np.sqrt(np.einsum("bii->bi", covs))
    outer = d[:, :, None] * d[:, None, :]
    corr = covs / outer
    m = covs.shape[1]
    lam = np.zeros(len(covs))
    if dof is not None and m > 1:
        iu = np.triu_indices(m, 1)
        r = corr[:, iu[0], iu[1]]
        total = np.sum(r * r, axis=1)
        with np.errstate(divide="ignore", invalid="ignore"):
            lam = np.where(total > 0, np.minimum(1.0, np.sum((1.0 - r * r) ** 2, axis=1) / dof / total), 1.0)
        if dof < m:
            lam = np.ones(len(covs))
    shrunk = (1.0 - lam)[:, None, None] * corr + lam[:, None, None] * np.eye(m)
    weight = np.linalg.pinv(shrunk) / outer
    return 0.5 * (weight + np.swapaxes(weight, 1, 2))


def weight_noise_factor(parts: Sequence[Part], det: Sequence[int], seed: int = 0) -> np.ndarray:
    """(len(det),): how much more each combined parameter varies than its fixed-weight covariance says, because each
    log's weight was made from a covariance estimated on few degrees of freedom (for a scalar mean weighted by
    estimated variances that is Meier's (1953) 1 + 4 sum_k s_k (1 - s_k) / dof_k; with weight matrices it is larger).
    A parametric bootstrap of the weighting, the reported covariances taken as the truth: each log's covariance drawn
    again on its degrees of freedom (Wishart), its estimate from that truth, the weights made from the draw as
    :func:`combine` makes them; the variance of the combined estimate over the mean of the fixed-weight formula,
    WEIGHT_DRAWS draws, seeded; never below 1.  A log known exactly (dof None) keeps its weight.  Measured (30 seeds
    of ``bench/studies/study_plan.py --sequential 0.075,0.375``'s logs): with the fixed-weight formula alone the
    combined estimate's spread was 0.8-1.37 times its median reported std (rms z 0.89-1.40)."""
    rng = np.random.Generator(np.random.PCG64(seed))
    d = list(det)
    n, draws = len(d), WEIGHT_DRAWS
    weight, spread, wx = np.zeros((draws, n, n)), np.zeros((draws, n, n)), np.zeros((draws, n))
    for part in parts:
        if not part.used:
            continue
        idx = list(part.used)
        at = [d.index(i) for i in idx]
        cov = np.asarray(part.cov, dtype=np.float64)[np.ix_(idx, idx)]
        vals, vecs = np.linalg.eigh(0.5 * (cov + cov.T))
        root = vecs * np.sqrt(np.clip(vals, 0.0, None))
        x = rng.standard_normal((draws, len(idx))) @ root.T
        if part.dof is None:
            drawn = np.broadcast_to(cov, (draws, *cov.shape))
        else:
            z = root @ rng.standard_normal((draws, len(idx), int(part.dof)))
            drawn = z @ np.swapaxes(z, 1, 2) / part.dof
        w = part.weight(np.ascontiguousarray(drawn))
        rows = np.ix_(at, at)
        weight[:, rows[0], rows[1]] += w
        spread[:, rows[0], rows[1]] += w @ drawn @ w
        wx[:, at] += np.einsum("bij,bj->bi", w, x)
    a = np.linalg.pinv(weight)
    combined = np.einsum("bij,bj->bi", a, wx)
    formula = np.einsum("bii->bi", a @ spread @ a)
    factor = np.var(combined, axis=0, ddof=1) / np.mean(formula, axis=0)
    return np.maximum(factor, 1.0)


def combined_weighting(parts: Sequence[Part], det: Sequence[int], n0: int) -> np.ndarray:
    """(n0, n0): the weighting covariance of a combination, (sum_k W_k)^-1 over the parameters determined (NaN
    elsewhere, +inf on the diagonal): what a later combination weighs it by."""
    total = np.zeros((n0, n0))
    for part in parts:
        if part.used:
            idx = list(part.used)
            total[np.ix_(idx, idx)] += part.weight()
    out = np.full((n0, n0), np.nan)
    np.fill_diagonal(out, np.inf)
    d = list(det)
    if d:
        inv = np.linalg.inv(total[np.ix_(d, d)])
        out[np.ix_(d, d)] = 0.5 * (inv + inv.T)
    return out


def _determined(cov: np.ndarray, i: int) -> bool:
    value = cov[i, i]
    return bool(np.isfinite(value) and value > 0)


def combined_result(
    result: IdentificationResult, given: Sequence[tuple[IdentificationResult, str]], robot: Any = None
) -> IdentificationResult:
    """``result`` (one log's) combined with the results ``given`` ((result, where it came from) each): the estimate,
    its covariance and degrees of freedom become the combination's (module docstring), and every statement about
    them is made again from those numbers (:func:`wmrid.estimators.verdict.settle`).  ``diagnostics.combined``
    records the results combined, which parameters each gave, and this log's own estimate.  ``robot``: for a
    payload estimate, the unloaded robot."""
    est = result.estimate
    if est is None:
        raise ValueError("the result holds no estimate")
    names = result.form.base_names if len(est.theta0) == result.form.n_base else default_base_names(len(est.theta0))
    n0 = len(names)
    own_cov = np.asarray(est.cov, dtype=np.float64)
    parts = [Part(np.asarray(est.theta0, dtype=np.float64), own_cov, est.dof,
                  tuple(i for i in range(n0) if _determined(own_cov, i)), est.weight_cov)]  # fmt: skip
    unit = result.log_info.effort_unit
    records, partial = [], []
    for other, source in given:
        theirs_est = other.estimate
        if theirs_est is None:
            raise UsageError(f"{option('given', source)}: holds no estimate")
        their_unit = other.log_info.effort_unit
        if their_unit != unit:
            raise UsageError(
                f"{option('given', source)}: its efforts are in {their_unit}, this log's in {unit}; give results "
                "of logs in the same units"
            )
        theirs = (
            other.form.base_names
            if len(theirs_est.theta0) == other.form.n_base
            else default_base_names(len(theirs_est.theta0))
        )
        shared = shared_names(theirs, names)
        if len(shared) < n0:
            partial.append(source)
        their_cov = np.asarray(theirs_est.cov, dtype=np.float64)
        x, cov = np.zeros(n0), np.zeros((n0, n0))
        ours = [names.index(n) for n in shared if _determined(their_cov, theirs.index(n))]
        at = [theirs.index(names[i]) for i in ours]
        x[ours] = np.asarray(theirs_est.theta0, dtype=np.float64)[at]
        cov[np.ix_(ours, ours)] = their_cov[np.ix_(at, at)]
        weight_cov = None
        if theirs_est.weight_cov is not None:
            weight_cov = np.full((n0, n0), np.nan)
            weight_cov[np.ix_(ours, ours)] = np.asarray(theirs_est.weight_cov, dtype=np.float64)[np.ix_(at, at)]
        parts.append(Part(x, cov, theirs_est.dof, tuple(ours), weight_cov))
        records.append(CombinedResult(source=source, log=other.source, method=theirs_est.method, dof=theirs_est.dof,
                                      parameters=tuple(names[i] for i in ours)))  # fmt: skip
    x, cov, dof, det = combine(parts, n0)
    for i in range(n0):  # what no log determines stays as this log reported it
        if i not in det:
            x[i] = float(est.theta0[i])
    weighting = combined_weighting(parts, det, n0)
    combined_est = replace(est, theta0=x, cov=cov, dof=dof, segments=None, weight_cov=weighting)
    parameters = derived_with_std(x, cov, names)
    parameters = {name: parameters[name] for name in reported_names(result.form) if name in parameters}
    combined = Combination(
        results=tuple(records),
        this_log={name: {"value": v, "std": finite_or_none(s)} for name, (v, s) in result.parameters.items()},
        this_log_dof=est.dof,
        meaning="the estimate and std are this log's combined with the given results' by fixed weights (their "
        "covariances with correlations shrunk by their degrees of freedom); the covariance is the combination's, "
        "linear in each log's reported covariance; degrees of freedom by Welch-Satterthwaite",
    )  # fmt: skip
    uncertainty = result.diagnostics.uncertainty or Uncertainty()
    own_method = uncertainty.method or "this log's std"
    uncertainty = replace(
        uncertainty,
        dof=dof,
        interval_factor={
            "95%": interval_factor(0.95, dof) if dof else 1.959964,
            "99.7%": interval_factor(0.9973, dof) if dof else 2.999977,
        },
        combined=f"the combination of {len(records) + 1} logs' estimates (diagnostics.combined)",
        method=f"this log's ({own_method}) combined with {len(records)} earlier "
        f"result{'s' if len(records) != 1 else ''}'s by fixed weights, degrees of freedom by Welch-Satterthwaite",
        segments=None,  # the combination's are not one log's segments
    )
    diagnostics = replace(result.diagnostics, combined=combined, uncertainty=uncertainty)
    files = ", ".join(str(r.source) for r in records)
    note = f"{COMBINED_NOTE} {len(records)} earlier result{'s' if len(records) != 1 else ''} ({files}): the estimates "
    note += "and std are the combination; this log's own are in diagnostics.combined.this_log"
    warnings = [note]
    if partial:
        warnings.append(
            f"{', '.join(partial)}: identified with another friction model, so only the inertia and Vc are combined "
            "with it; the friction is this log's"
        )
    payload = result.payload
    if payload is not None and robot is not None:
        payload = payload_with_std(x, cov, robot.reference)
    return settle(replace(
        result, parameters=parameters, theta0_cov=cov, estimate=combined_est, diagnostics=diagnostics,
        warnings=(*warnings, *result.warnings), payload=payload,
    ))  # fmt: skip
