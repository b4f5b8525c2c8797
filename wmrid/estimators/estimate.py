"""The result every identification method returns: base parameters with their covariance.

The observer (:mod:`wmrid.estimators.observer.observe`), IDIM least squares (:mod:`wmrid.estimators.regression.idim`),
recursive least squares
(:mod:`wmrid.estimators.regression.rls`) and output error (:mod:`wmrid.estimators.output_error`) all end in a
:class:`BaseEstimate`, so
that reports, ``wmrid compare`` and ``wmrid monitor`` are blind to the method.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import numpy as np

from wmrid.model.dynamics import default_base_names


@dataclass(frozen=True, eq=False)
class SegmentEstimates:
    """The estimate with each of G equal contiguous segments of the log left out in turn (the jackknife's).

    t0 : s, start of the segment grid; duration : s, its length (segment g covers [t0 + g d / G, t0 + (g+1) d / G)
    with d = duration); loo : (G, n0) theta0 with segment g left out.  Two methods' estimates on the same grid give
    the jackknife of their difference (:func:`wmrid.estimators.feedback.difference_test`).
    """

    t0: float
    duration: float
    loo: np.ndarray

    @property
    def grid(self) -> tuple[float, float, int]:
        """(t0, duration, G): the grid, to fit another method on the same segments."""
        return self.t0, self.duration, int(self.loo.shape[0])


@dataclass(frozen=True)
class BaseEstimate:
    """Base parameters theta0 = [m11 m12 m22 Vc Fv1 Fv2 Fd1 Fd2 (Cv Cw)] found by one method.

    Attributes
    ----------
    method
        The method's name ("observer", "idim", "iv", "rls", "oe").
    theta0
        (8,), or longer with the caster drag (Cv, Cw or D_1..D_K), in the model's units (SI for torque logs; see
        :func:`wmrid.model.dynamics.base_units`).
    cov
        (n0, n0) covariance of theta0; a row/column of NaN with +inf on the diagonal marks a parameter the log does
        not determine.
    dof
        Degrees of freedom of the standard errors (Student t intervals), or None for normal ones.
    seconds
        s, the wall time the method took.
    diagnostics
        Method-specific figures (JSON-ready).
    warnings
        Plain-English warnings about this estimate.
    segments
        The leave-one-segment-out estimates behind the jackknife std, when the method keeps them.
    weight_cov
        (n0, n0) the covariance the method's own weighting implies (the observer's Newey-West sandwich through the
        minimum-distance fit), estimated from every block of the log and so far steadier than ``cov``: what another
        log's estimate is combined with this one by (:mod:`wmrid.estimators.combination`); None when the method has
        none.  Not a std to report (it leaves out what the jackknife covers).
    """

    method: str
    theta0: np.ndarray
    cov: np.ndarray
    dof: int | None = None
    seconds: float = 0.0
    diagnostics: dict[str, Any] = field(default_factory=dict)
    warnings: tuple[str, ...] = ()
    segments: SegmentEstimates | None = field(default=None, repr=False, compare=False)
    weight_cov: np.ndarray | None = field(default=None, repr=False, compare=False)

    def __post_init__(self) -> None:
        n0 = np.shape(self.theta0)[0] if np.ndim(self.theta0) == 1 else -1
        if n0 < 8:
            raise ValueError(f"BaseEstimate.theta0 must have shape (8,) or longer, got {np.shape(self.theta0)}")
        if np.shape(self.cov) != (n0, n0):
            raise ValueError(f"BaseEstimate.cov must have shape ({n0}, {n0}), got {np.shape(self.cov)}")

    @property
    def std(self) -> np.ndarray:
        """(n0,) standard errors (inf where the log does not determine the parameter)."""
        std: np.ndarray = np.sqrt(np.clip(np.diag(self.cov), 0.0, None))
        return std

    def named(self, names: tuple[str, ...] | None = None) -> dict[str, tuple[float, float]]:
        """The base parameters by name.

        Parameters
        ----------
        names
            Their names (None: the eight, then Cv, Cw; give a form's ``base_names`` for a geometric caster model).

        Returns
        -------
        dict
            Name -> (value, std).
        """
        if names is None:
            names = default_base_names(len(self.theta0))
        return {n: (float(v), float(s)) for n, v, s in zip(names, self.theta0, self.std, strict=True)}
