"""The pieces of an identification result's JSON form (:mod:`wmrid.estimators.result`): numbers that may be NaN or
inf as null and back, the method-neutral estimate, the history decimated to at most :data:`JSON_HISTORY_POINTS`
samples.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from wmrid.estimators.estimate import BaseEstimate

#: Points of the history kept in a JSON result (enough for the report's figures).
JSON_HISTORY_POINTS = 300


def history_dict(result: Any, max_points: int = JSON_HISTORY_POINTS) -> dict[str, Any]:
    """A compact history for JSON: t, theta (p names -> list), e_r, e_l, lambda_min, at most ``max_points``."""
    hist = result.history
    idx = np.unique(np.linspace(0, len(hist.t) - 1, min(max_points, len(hist.t))).round().astype(int))
    names = result.form.theta_names()
    flat = hist.theta[idx].reshape(len(idx), -1)
    return {
        "t": hist.t[idx].tolist(),
        "theta": {name: flat[:, j].tolist() for j, name in enumerate(names)},
        "e_r": hist.e[idx, 0].tolist(),
        "e_l": hist.e[idx, 1].tolist(),
        "lambda_min": hist.lambda_min[idx].tolist(),
    }


def finite_or_none(x: float) -> float | None:
    return float(x) if math.isfinite(x) else None


def estimate_dict(est: BaseEstimate, names: tuple[str, ...]) -> dict[str, Any]:
    """The method-neutral estimate as JSON: theta0 in ``names`` order with its full covariance (null where the log
    does not determine a parameter), the method and its degrees of freedom; the weighting covariance when the method
    has one (:attr:`BaseEstimate.weight_cov`)."""
    out = {
        "method": est.method,
        "names": list(names[: len(est.theta0)]),
        "theta0": [finite_or_none(v) for v in est.theta0],
        "covariance": [[finite_or_none(v) for v in row] for row in est.cov],
        "dof": est.dof,
    }
    if est.weight_cov is not None:
        out["weight_covariance"] = [[finite_or_none(v) for v in row] for row in est.weight_cov]
    return out


def floats(values: Any) -> np.ndarray:
    """A float array from JSON numbers, null read as NaN."""
    return np.array([math.nan if v is None else float(v) for v in values], dtype=float)


def box(values: dict[str, Any], names: Sequence[str], p: int, missing: float) -> np.ndarray:
    """(2, p) intermediate parameters from JSON numbers by name, null read as ``missing``."""
    return np.array([missing if values[n] is None else float(values[n]) for n in names], dtype=float).reshape(2, p)
