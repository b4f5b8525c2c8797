"""Standard errors of the estimate that stay honest when residuals are coloured.

The estimator is a least-squares fit of u = w theta (see :mod:`wmrid.observer`), so at the end
theta_hat = P (alpha theta_0 + sum h w^T u), P = Gamma^-1, and theta_hat - theta = P sum h w^T r
with r the residual.  The residual is filtered by 1/(s + k) and carries coloured disturbances (a
caster, slip), so successive terms are strongly correlated and the textbook sigma^2 P understates
the spread.  wmrid uses the sandwich P S P with S the long-run covariance of the score
z = h w^T r, estimated by the Bartlett (Newey-West) kernel over short blocks of the log, with the
bandwidth chosen by Andrews' (1991) AR(1) plug-in rule.  The block sums come from the compiled
kernel, so nothing here scales with the number of samples.
"""

from __future__ import annotations

import numpy as np


def block_scores(blk_a: np.ndarray, blk_c: np.ndarray, theta: np.ndarray) -> np.ndarray:
    """Per-block scores z_j = sum h w^T (u - w theta), shape (J, 2p) for blk_a (J, p, p), blk_c (J, 2, p)."""
    fitted = np.einsum("jab,rb->jra", blk_a, theta)
    return (blk_c - fitted).reshape(blk_c.shape[0], -1)


def andrews_bandwidth(z: np.ndarray) -> float:
    """Bartlett-kernel bandwidth (in blocks) by Andrews' AR(1) plug-in, at least 1 and at most J/2."""
    n_blocks = z.shape[0]
    if n_blocks < 4:
        return 1.0
    num = 0.0
    den = 0.0
    for col in z.T:
        x0, x1 = col[:-1], col[1:]
        denom = float(x0 @ x0)
        if denom <= 0:
            continue
        rho = float(np.clip((x0 @ x1) / denom, -0.97, 0.97))
        sig2 = float(np.mean((x1 - rho * x0) ** 2))
        num += 4.0 * rho**2 * sig2**2 / ((1 - rho) ** 6 * (1 + rho) ** 2)
        den += sig2**2 / (1 - rho) ** 4
    if den <= 0:
        return 1.0
    alpha1 = num / den
    return float(np.clip(1.1447 * (alpha1 * n_blocks) ** (1.0 / 3.0), 1.0, n_blocks / 2.0))


def long_run_covariance(z: np.ndarray, bandwidth: float) -> np.ndarray:
    """Bartlett long-run covariance of the sum of z (J, q): sum_l (1 - |l|/L) Gamma_z(l), small-sample scaled."""
    n_blocks, q = z.shape
    zc = z - z.mean(axis=0)  # the scores sum to (almost) zero at the fit; centring guards the alpha prior
    s = zc.T @ zc
    lags = int(np.floor(bandwidth))
    for lag in range(1, lags + 1):
        weight = 1.0 - lag / (lags + 1.0)
        c = zc[lag:].T @ zc[:-lag]
        s += weight * (c + c.T)
    dof_scale = n_blocks / max(n_blocks - q, 1)
    return s * dof_scale


def sandwich_covariance(
    gamma_inv: np.ndarray, blk_a: np.ndarray, blk_c: np.ndarray, theta: np.ndarray
) -> tuple[np.ndarray, float]:
    """Covariance (2p, 2p) of theta.ravel() (theta (2, p)) and the bandwidth used (blocks)."""
    z = block_scores(blk_a, blk_c, theta)
    bandwidth = andrews_bandwidth(z)
    s = long_run_covariance(z, bandwidth)
    big_p = np.kron(np.eye(2), gamma_inv)
    cov = big_p @ s @ big_p
    return 0.5 * (cov + cov.T), bandwidth
