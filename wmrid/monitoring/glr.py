"""The windowed generalised likelihood-ratio test on the torque residual: noise model, window grid, statistics, and
the change's location (:func:`window_statistics`, :func:`locate`)."""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from wmrid.core.errors import NotIdentifiableError
from wmrid.monitoring.residuals import tidy
from wmrid.monitoring.settings import DOF, MIN_ROWS_PER_COEFFICIENT, MonitorSettings


@dataclass(frozen=True)
class NoiseModel:
    """r_k = sum_i A_i r_k-i + e_k, e_k ~ N(0, cov): a vector autoregression of the residual (2 wheels).

    coeffs : (q, 2, 2) A_1 .. A_q.  cov : (2, 2) innovation covariance.  rows : equations it was fitted on.
    dof : degrees of freedom of its estimate of the low-frequency noise power, rows / q (an autoregression
    of order q on n samples estimates the spectrum at frequency 0 with a relative variance of 4 q / n per
    wheel, Berk 1974; two wheels halve it).
    """

    coeffs: np.ndarray
    cov: np.ndarray
    rows: int

    @property
    def order(self) -> int:
        return len(self.coeffs)

    @property
    def dof(self) -> float:
        return self.rows / self.order

    @classmethod
    def fit(cls, spans: list[np.ndarray], order: int) -> NoiseModel:
        """Least squares on the residual spans (each (n_i, 2); lags never cross from one span to another)."""
        lagged, target = [], []
        for r in spans:
            n = len(r)
            if n <= order:
                continue
            target.append(r[order:])
            lagged.append(np.hstack([r[order - i : n - i] for i in range(1, order + 1)]))  # (n - q, 2q)
        rows = sum(len(t) for t in target)
        if rows < MIN_ROWS_PER_COEFFICIENT * 2 * order:
            raise NotIdentifiableError(
                f"the calibration span holds {rows + order} residual samples, too few for a noise model with {order} "
                "lags"
            )
        z = np.concatenate(lagged)
        y = np.concatenate(target)
        coef, *_ = np.linalg.lstsq(z, y, rcond=None)  # (2q, 2): y = z @ coef
        innov = y - z @ coef
        cov = innov.T @ innov / (rows - 2 * order)
        coeffs = np.stack([coef[2 * i : 2 * i + 2].T for i in range(order)])
        return cls(coeffs=coeffs, cov=cov, rows=rows)

    def whiten(self, x: np.ndarray) -> np.ndarray:
        """L^-1 (x_k - sum_i A_i x_k-i) for k >= q: (m - q, 2, ...) from x (m, 2, ...), cov = L L'."""
        q = self.order
        m = len(x)
        out = x[q:].copy()
        for i in range(1, q + 1):
            out -= np.einsum("jl,kl...->kj...", self.coeffs[i - 1], x[q - i : m - i])
        inv_l = np.linalg.inv(np.linalg.cholesky(self.cov))
        return np.einsum("jl,kl...->kj...", inv_l, out)


@dataclass(frozen=True)
class WindowGrid:
    """The tests: windows and steps in blocks of ``block`` samples (at ``rate`` Hz), per-test false-alarm
    probability p_test = false_alarm_rate / tests_per_hour, and the margin on the threshold."""

    block: int
    windows: tuple[int, ...]
    steps: tuple[int, ...]
    rate: float
    p_test: float
    tests_per_hour: float
    margin: float

    def threshold(self, dof: float, n_params: int = DOF) -> float:
        """h with P(S > h / margin) = p_test for S / n ~ F(n, dof), n = ``n_params`` = len(p) (8 without caster
        drag): the chi2_n law of S with a noise power estimated on ``dof`` degrees of freedom (chi2_n itself for
        dof = inf)."""
        from scipy.stats import chi2, f  # scipy.stats (~0.6 s): only the threshold

        if not math.isfinite(dof):
            return self.margin * float(chi2.isf(self.p_test, n_params))
        return self.margin * n_params * float(f.isf(self.p_test, n_params, dof))

    def to_dict(self) -> dict[str, Any]:
        return {
            "windows_s": [tidy(w * self.block / self.rate) for w in self.windows],
            "steps_s": [tidy(s * self.block / self.rate) for s in self.steps],
            "tests_per_hour": self.tests_per_hour,
            "p_per_test": self.p_test,
        }


def window_grid(settings: MonitorSettings, rate: float) -> WindowGrid:
    """The windows on the residual's sample grid, each tested every 1/steps_per_window of its length."""
    shortest = min(settings.windows_s)
    block = max(1, round(shortest * rate / settings.steps_per_window))
    windows = tuple(sorted({max(1, round(w * rate / block)) for w in settings.windows_s}))
    steps = tuple(max(1, round(w / settings.steps_per_window)) for w in windows)
    tests_per_hour = sum(3600.0 * rate / (s * block) for s in steps)
    p_test = settings.false_alarm_rate / tests_per_hour
    return WindowGrid(block, windows, steps, rate, p_test, tests_per_hour, settings.margin)


@dataclass(frozen=True)
class ModelError:
    """What is known of the model's own error dp (p = [M11 M12 M22 Vc Fv1 Fv2 Fd1 Fd2, caster drag]) on a segment:
    normal with mean ``mean`` (n,) and covariance ``cov`` (n, n); the residual holds Phi dp even without a change."""

    mean: np.ndarray
    cov: np.ndarray


def _glr(gram: np.ndarray, proj: np.ndarray, err: ModelError) -> np.ndarray:
    """S = c' (G + G P G)^-1 c, c = b - G dp_mean, for stacks G (k, n, n), b (k, n): the GLR statistic when the
    model's own error, normal (dp_mean, P), is part of the null hypothesis (c = X'e + G (dp - dp_mean) then has
    covariance G + G P G); a relative ridge of 1e-10 for directions a window does not excite."""
    n = gram.shape[-1]
    ridge = 1e-10 * np.trace(gram, axis1=1, axis2=2)[:, None, None] * np.eye(n) + 1e-300 * np.eye(n)
    cov = gram + ridge + gram @ err.cov @ gram
    centred = proj - gram @ err.mean
    sol = np.linalg.solve(cov, centred[..., None])[..., 0]
    return np.einsum("kp,kp->k", centred, sol)


def window_statistics(z: np.ndarray, x: np.ndarray, err: ModelError, lo: int, grid: WindowGrid, after: int,
                      upto: int):  # fmt: skip
    """The tests whose window lies in the whitened data z (m, 2), x (m, 2, n) -- z[0] being sample ``lo`` of the
    segment, a whole number of blocks -- and ends in (after, upto]: per window length, (width in samples,
    window ends (exclusive, segment samples), statistics S)."""
    first_block = lo // grid.block
    usable = (lo + len(z)) // grid.block - first_block
    out = []
    if usable < min(grid.windows):
        return out
    n = usable * grid.block
    dim = x.shape[-1]
    xb = x[:n].reshape(usable, grid.block, 2, dim)
    zb = z[:n].reshape(usable, grid.block, 2)
    gram = np.concatenate([np.zeros((1, dim, dim)), np.cumsum(np.einsum("nbip,nbiq->npq", xb, xb), axis=0)])
    proj = np.concatenate([np.zeros((1, dim)), np.cumsum(np.einsum("nbip,nbi->np", xb, zb), axis=0)])
    for width, step in zip(grid.windows, grid.steps, strict=True):
        ends = np.arange(width, usable + 1)  # in blocks from first_block
        absolute = (first_block + ends) * grid.block
        keep = ((first_block + ends) % step == 0) & (absolute > after) & (absolute <= upto)
        ends = ends[keep]
        if len(ends) == 0:
            continue
        s = _glr(gram[ends] - gram[ends - width], proj[ends] - proj[ends - width], err)
        out.append((width * grid.block, (first_block + ends) * grid.block, s))
    return out


def locate(z: np.ndarray, x: np.ndarray, err: ModelError, upto: int) -> int:
    """The maximum-likelihood change sample: the j < ``upto`` maximising S(j, len(z)), the GLR statistic of the
    whitened data from j to the end (indices into z)."""
    gram_rev = np.cumsum(np.einsum("kip,kiq->kpq", x, x)[::-1], axis=0)[::-1]  # sums from j to the end
    proj_rev = np.cumsum(np.einsum("kip,ki->kp", x, z)[::-1], axis=0)[::-1]
    upto = max(1, min(upto, len(z)))
    return int(np.argmax(_glr(gram_rev[:upto], proj_rev[:upto], err)))
