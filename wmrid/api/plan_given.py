"""The results of logs already identified, as a plan's prior information (``wmrid plan --given``, :func:`_given`):
what ``wmrid identify --given`` will combine with the planned log's estimate.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from wmrid.api.inputs import given_results
from wmrid.core.errors import UsageError, option
from wmrid.design.information import GivenLogs
from wmrid.design.plan_records import GivenResult, GivenResults
from wmrid.estimators.combination import Part, shared_names


def _given(
    given: Any, names: tuple[str, ...], theta0: np.ndarray
) -> tuple[tuple[GivenLogs, GivenResults], np.ndarray] | tuple[None, np.ndarray]:
    """((the given logs (:class:`wmrid.design.information.GivenLogs`), what they are (:class:`GivenResults`)),
    theta0 updated) from saved results: each result's base covariance over the parameters it determines and means as
    the plan does (:func:`wmrid.estimators.combination.shared_names`), and its weight
    (:meth:`wmrid.estimators.combination.Part.weight`), summed: what ``wmrid identify --given`` will combine; the
    nominal values replaced by a result's estimate where it determines them to better than 10 %."""
    if given is None:
        return None, theta0
    weight = np.zeros((len(names), len(names)))
    spread = np.zeros((len(names), len(names)))
    theta0 = theta0.copy()
    sources = []
    for result, source in given_results(given):
        est = result.estimate
        if est is None:
            raise UsageError(f"{option('given', source)}: holds no estimate")
        their = result.form.base_names if len(est.theta0) == result.form.n_base else names[: len(est.theta0)]
        cov = np.asarray(est.cov, dtype=np.float64)
        shared = shared_names(their, names)  # a result of another friction model: its inertia and Vc only
        idx = [i for i, n in enumerate(their) if n in shared and np.isfinite(cov[i, i]) and cov[i, i] > 0]
        if not idx:
            continue
        sub = cov[np.ix_(idx, idx)]
        sub_weight = Part(np.asarray(est.theta0), cov, est.dof, tuple(idx), est.weight_cov).weight()
        where = [names.index(their[i]) for i in idx]
        weight[np.ix_(where, where)] += sub_weight
        spread[np.ix_(where, where)] += sub_weight @ sub @ sub_weight
        for i in idx:
            value, std = float(est.theta0[i]), math.sqrt(cov[i, i])
            if value != 0 and std < 0.1 * abs(value):
                theta0[names.index(their[i])] = value
        sources.append(GivenResult(source=source, log=result.source, method=est.method,
                                   parameters=tuple(their[i] for i in idx)))  # fmt: skip
    return (GivenLogs(weight, 0.5 * (spread + spread.T)), GivenResults(results=tuple(sources))), theta0
