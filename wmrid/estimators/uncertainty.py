"""Standard errors of the estimate that stay honest when residuals are coloured.

The estimator is a least-squares fit of u = w theta (see :mod:`wmrid.estimators.observer.step`), so at the end
theta_hat = P (alpha theta_0 + sum h w^T u), P = Gamma^-1, and theta_hat - theta = P sum h w^T r
with r the residual.  The residual carries coloured disturbances (a caster, slip) and, in closed
loop, the regressor responds to them, so successive terms are correlated over seconds and the
textbook sigma^2 P understates the spread many times over.

wmrid reports the delete-a-group jackknife over G contiguous segments of the log: the estimate is
recomputed with each segment left out, theta_(g) = (Gamma - A_g)^-1 (b - c_g), exactly and without a
second pass, from the per-block sums A_g = sum h w^T w and c_g = sum h w^T u that the compiled kernel
keeps; then Cov = (G - 1)/G sum_g (theta_(g) - mean)(theta_(g) - mean)^T.  Segments of 2 s (at least 10,
at most 40 of them) are long against the memory of the scores, and the t-statistic built on the
jackknife follows Student's t with G - 1 degrees of freedom, so intervals have a stated coverage
(:func:`interval_factor`).  Unlike a kernel (Newey-West) estimate of the score's long-run covariance,
the jackknife also sees how much the fit itself absorbs of a persistent disturbance, which matters on
short logs: on simulated noisy 40 s logs with a coloured caster disturbance in closed loop
(``bench/accuracy/bench_coverage.py``), Newey-West with Andrews' bandwidth understated the spread 2-4 times, an
equal-weighted-cosine estimate 1.2-1.6 times, the jackknife 1.0-1.4 times.

The Newey-West estimate (Bartlett kernel, Andrews' AR(1) bandwidth) is still used, for the weights of
the minimum-distance recovery of theta0 (:mod:`wmrid.model.base_params`): it is full rank, whereas the
jackknife has rank G - 1, and weights only affect efficiency, not the validity of the reported errors.
"""

from __future__ import annotations

import math

import numpy as np

#: Jackknife segment length (s) and bounds on the number of segments.
SEGMENT_SECONDS = 2.0
MIN_SEGMENTS = 10
MAX_SEGMENTS = 40


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


def segment_count(duration: float, n_blocks: int) -> int:
    """Number G of jackknife segments for a log of ``duration`` s cut into ``n_blocks`` blocks."""
    g = math.floor(duration / SEGMENT_SECONDS)
    g = min(max(g, MIN_SEGMENTS), MAX_SEGMENTS)
    return max(2, min(g, n_blocks))


def segments_of(block_mid: np.ndarray, duration: float) -> tuple[np.ndarray, int]:
    """(segment index (J,) of each block, G): the jackknife's G contiguous segments (:func:`segment_count`) of a
    log of ``duration`` s whose J blocks have mid-times ``block_mid`` (J,) in [0, 1] of the log."""
    n_seg = segment_count(duration, len(block_mid))
    return np.minimum((np.asarray(block_mid) * n_seg).astype(np.int64), n_seg - 1), n_seg


def jackknife_covariance(
    gamma: np.ndarray, theta: np.ndarray, blk_a: np.ndarray, blk_c: np.ndarray, segment: np.ndarray, n_segments: int
) -> np.ndarray:
    """Delete-a-group jackknife covariance (2p, 2p) of theta.ravel().

    gamma (p, p) the final Gamma, theta (2, p) the final unconstrained estimate (so gamma theta^T is the
    right-hand side of the normal equations), blk_a (J, p, p), blk_c (J, 2, p) per-block sums,
    segment (J,) the segment index of each block in [0, n_segments).
    """
    deltas = jackknife_deltas(gamma, theta, blk_a, blk_c, segment, n_segments)
    centred = deltas - deltas.mean(axis=0)
    return (n_segments - 1) / n_segments * (centred.T @ centred)


def jackknife_deltas(
    gamma: np.ndarray, theta: np.ndarray, blk_a: np.ndarray, blk_c: np.ndarray, segment: np.ndarray, n_segments: int
) -> np.ndarray:
    """theta_(g) - theta (G, 2p), ravelled: the estimate with segment g left out, exact from the block sums
    (arguments as :func:`jackknife_covariance`)."""
    rhs = gamma @ theta.T  # (p, 2)
    deltas = np.empty((n_segments, theta.size))
    for g in range(n_segments):
        sel = segment == g
        a_g = blk_a[sel].sum(axis=0)
        c_g = blk_c[sel].sum(axis=0)
        theta_g = np.linalg.solve(gamma - a_g, rhs - c_g.T).T
        deltas[g] = (theta_g - theta).ravel()
    return deltas


def interval_factor(coverage: float, dof: int) -> float:
    """Half-width of a central ``coverage`` interval in standard errors: Student's t quantile with ``dof``."""
    from scipy.special import stdtrit  # scipy.special (~0.15 s): loaded at the first interval, not on import

    return float(stdtrit(dof, 0.5 + coverage / 2.0))


def estimate_covariances(
    gamma: np.ndarray,
    gamma_inv: np.ndarray,
    theta: np.ndarray,
    blk_a: np.ndarray,
    blk_c: np.ndarray,
    block_mid: np.ndarray,
    duration: float,
) -> tuple[np.ndarray, np.ndarray, dict]:
    """Covariances (2p, 2p) of theta.ravel() (theta (2, p), unconstrained): (reported, weighting, details).

    reported: the jackknife over segments; weighting: the Newey-West sandwich P S P (full rank);
    details: ``dof`` = G - 1, ``segments`` = G, ``bandwidth_blocks``.  block_mid (J,) are the blocks'
    mid-times in [0, 1] of the log.
    """
    segment, n_seg = segments_of(block_mid, duration)
    reported = jackknife_covariance(gamma, theta, blk_a, blk_c, segment, n_seg)
    z = block_scores(blk_a, blk_c, theta)
    bandwidth = andrews_bandwidth(z)
    big_p = np.kron(np.eye(2), gamma_inv)
    weighting = big_p @ long_run_covariance(z, bandwidth) @ big_p
    details = {"dof": n_seg - 1, "segments": n_seg, "bandwidth_blocks": bandwidth}
    return 0.5 * (reported + reported.T), 0.5 * (weighting + weighting.T), details


#: The filter w forgets with exp(-k t): a block's samples still weigh 5 % after 3/k s.
FILTER_MEMORY = 3.0


def slow_speed_difference(
    gamma: np.ndarray,
    theta: np.ndarray,
    blk_a: np.ndarray,
    blk_c: np.ndarray,
    blk_slow: np.ndarray,
    segment: np.ndarray,
    n_segments: int,
    spill_blocks: int,
) -> dict | None:
    """The estimate without the slow-wheel parts of the log, its difference from the full one, and that
    difference's jackknife covariance.

    Friction near zero speed rarely follows F_v eta + F_d sgn(eta): real wheels stick, and friction rises
    smoothly through zero.  Where the log's wheels slow down or reverse, that error biases the estimate
    in the same way all along the log, so the jackknife cannot see it.  The estimate with those parts left
    out (every block holding a sample below the low speed, ``blk_slow``, with the ``spill_blocks`` after it
    in which the filter still remembers it) is exact from the block sums, as the jackknife is:
    theta_x = (Gamma - A_x)^-1 (Gamma theta^T - c_x).  When the model holds, theta_x - theta is noise; its
    covariance comes from the same delete-a-segment jackknife, applied to the difference.

    Returns None when no block (or every block) is left out; else {"delta": (2p,), "cov": (2p, 2p),
    "cov_without": (2p, 2p) the jackknife covariance of theta_x itself, "fraction": share of blocks left out,
    "left_out": (J,) bool, those blocks}.
    """
    nb = len(blk_slow)
    if not np.any(blk_slow):
        return None
    left_out = blk_slow.copy()
    for lag in range(1, spill_blocks + 1):
        left_out[lag:] |= blk_slow[:-lag]
    if left_out.all() or left_out.sum() > 0.8 * nb:
        return None
    rhs = gamma @ theta.T
    a_x = blk_a[left_out].sum(axis=0)
    c_x = blk_c[left_out].sum(axis=0)
    try:
        theta_x = np.linalg.solve(gamma - a_x, rhs - c_x.T).T
        deltas = np.empty((n_segments, theta.size))
        xs = np.empty((n_segments, theta.size))
        for g in range(n_segments):
            sel = segment == g
            keep = sel & ~left_out
            a_g, c_g = blk_a[sel].sum(axis=0), blk_c[sel].sum(axis=0)
            a_gk, c_gk = blk_a[keep].sum(axis=0), blk_c[keep].sum(axis=0)
            full_g = np.linalg.solve(gamma - a_g, rhs - c_g.T).T
            x_g = np.linalg.solve(gamma - a_x - a_gk, rhs - c_x.T - c_gk.T).T
            deltas[g] = (x_g - full_g).ravel()
            xs[g] = x_g.ravel()
    except np.linalg.LinAlgError:
        return None
    scale = (n_segments - 1) / n_segments
    centred = deltas - deltas.mean(axis=0)
    cov = scale * (centred.T @ centred)
    centred_x = xs - xs.mean(axis=0)
    cov_x = scale * (centred_x.T @ centred_x)
    return {
        "delta": (theta_x - theta).ravel(), "cov": 0.5 * (cov + cov.T), "cov_without": 0.5 * (cov_x + cov_x.T),
        "fraction": float(left_out.mean()), "left_out": left_out,
    }  # fmt: skip
