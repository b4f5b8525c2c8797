"""Recover the base parameters theta0 (Eq. 21) from an estimate of the intermediate parameters theta.

theta (2 x p, 14 or 16 numbers) over-determines theta0 (8 numbers): V_c appears in both rows,
m12 and m21 are one number, and so on.  wmrid recovers theta0 by minimum distance: the theta0 whose
intermediate parameters f(theta0) (Eqs. 23-24) are closest to the estimate in the metric of the
estimate's own covariance C,

    theta0* = argmin (theta_hat - f(theta0))^T C^-1 (theta_hat - f(theta0)),

which weighs each relation by how well the log pins it.  The minimum is the structural mismatch: a
chi-square statistic with 2p - 8 degrees of freedom when the model holds and C is honest.  A large
value says the log violates the model (slip, unmodelled friction, wrong sign convention...).
Standard errors follow from the Jacobian at the optimum, (J^T C^-1 J)^-1.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy import optimize, stats

from wmrid.model import RegressorForm, intermediate_parameters, inverse_inertia


@dataclass(frozen=True)
class BaseFit:
    """theta0 (8,), its covariance (8, 8), the mismatch chi-square, its degrees of freedom and p-value."""

    theta0: np.ndarray
    cov: np.ndarray
    chi2: float
    dof: int
    p_value: float


def direct_recovery(theta: np.ndarray, form: RegressorForm) -> np.ndarray:
    """An unweighted, closed-form theta0 from theta (2, p): the start of the minimum-distance fit.

    m11 = theta_11, m22 = theta_22, m12 = (theta_12 + theta_21)/2; with M = m^-1, the products
    M [theta_13 theta_14; theta_23 theta_24] = V_c I and M [theta_15 theta_16; ...] = diag(F_v) are read
    off their diagonals; F_d likewise (paper form: F_d = s * M [theta_17; theta_27]).
    """
    m = np.array([[theta[0, 0], 0.5 * (theta[0, 1] + theta[1, 0])], [0.5 * (theta[0, 1] + theta[1, 0]), theta[1, 1]]])
    big_m = np.linalg.inv(m) if abs(np.linalg.det(m)) > 0 else np.linalg.pinv(m)
    vc = np.trace(big_m @ theta[:, 2:4]) / 2.0
    fv = np.diag(big_m @ theta[:, 4:6])
    if form.kind == "paper":
        fd = (big_m @ theta[:, 6]) * np.asarray(form.signs, dtype=float)
    else:
        fd = np.diag(big_m @ theta[:, 6:8])
    return np.array([m[0, 0], m[0, 1], m[1, 1], vc, fv[0], fv[1], fd[0], fd[1]])


def _whitener(cov: np.ndarray) -> np.ndarray:
    """W with W^T W = pinv(cov), dropping directions with eigenvalues below 1e-14 of the largest."""
    vals, vecs = np.linalg.eigh(0.5 * (cov + cov.T))
    keep = vals > max(vals.max(), 0.0) * 1e-14
    return (vecs[:, keep] / np.sqrt(vals[keep])).T


def fit_base_parameters(theta: np.ndarray, cov: np.ndarray, form: RegressorForm) -> BaseFit:
    """Minimum-distance theta0 from theta (2, p) with covariance cov (2p, 2p) of theta.ravel()."""
    theta = np.asarray(theta, dtype=float)
    start = direct_recovery(theta, form)
    whiten = _whitener(cov)
    target = theta.ravel()

    def residual(x: np.ndarray) -> np.ndarray:
        return whiten @ (intermediate_parameters(x, form).ravel() - target)

    # Parameter scaling by the start's magnitude keeps the problem well conditioned.
    x_scale = np.maximum(np.abs(start), 1e-6 * np.max(np.abs(start[:3])))
    sol = optimize.least_squares(residual, start, x_scale=x_scale, method="lm", xtol=1e-15, ftol=1e-15, gtol=1e-15)
    theta0 = sol.x
    jac = jacobian_intermediate(theta0, form)
    info = jac.T @ (whiten.T @ whiten) @ jac
    cov0 = np.linalg.pinv(info, rcond=1e-15, hermitian=True)
    chi2 = float(np.sum(residual(theta0) ** 2))
    dof = max(whiten.shape[0] - 8, 0)
    p_value = float(stats.chi2.sf(chi2, dof)) if dof > 0 else float("nan")
    return BaseFit(theta0=theta0, cov=0.5 * (cov0 + cov0.T), chi2=chi2, dof=dof, p_value=p_value)


def jacobian_intermediate(theta0: np.ndarray, form: RegressorForm) -> np.ndarray:
    """d vec(f(theta0)) / d theta0, (2p, 8), exact (f is bilinear in (m, [Vc, Fv, Fd]))."""
    p = form.n_columns
    jac = np.zeros((2 * p, 8))
    m = inverse_inertia(theta0)
    vc, fv1, fv2, fd1, fd2 = theta0[3:]
    # d m_ij / d (m11, m12, m22)
    dm = {0: np.array([[1.0, 0.0], [0.0, 0.0]]), 1: np.array([[0.0, 1.0], [1.0, 0.0]]), 2: np.array([[0.0, 0.0], [0.0, 1.0]])}
    s1, s2 = form.signs if form.kind == "paper" else (1, 1)
    for i in range(2):
        row = i * p
        for q, d in dm.items():
            di1, di2 = d[i]
            col = [di1, di2, di1 * vc, di2 * vc, di1 * fv1, di2 * fv2]
            col += [di1 * fd1 * s1 + di2 * fd2 * s2] if form.kind == "paper" else [di1 * fd1, di2 * fd2]
            jac[row : row + p, q] = col
        mi1, mi2 = m[i]
        jac[row + 2, 3], jac[row + 3, 3] = mi1, mi2
        jac[row + 4, 4] = mi1
        jac[row + 5, 5] = mi2
        if form.kind == "paper":
            jac[row + 6, 6], jac[row + 6, 7] = mi1 * s1, mi2 * s2
        else:
            jac[row + 6, 6], jac[row + 7, 7] = mi1, mi2
    return jac


def derived_with_std(theta0: np.ndarray, cov0: np.ndarray) -> dict[str, tuple[float, float]]:
    """Named base parameters plus M = m^-1, each (value, std) by the delta method (exact Jacobian of M)."""
    names = ("m11", "m12", "m22", "Vc", "Fv1", "Fv2", "Fd1", "Fd2")
    std0 = np.sqrt(np.clip(np.diag(cov0), 0.0, None))
    out = {n: (float(v), float(s)) for n, v, s in zip(names, theta0, std0)}
    m = inverse_inertia(theta0)
    big_m = np.linalg.inv(m)
    # dM = -M dm M for each of the three m entries
    jac = np.zeros((3, 8))
    basis = (np.array([[1.0, 0.0], [0.0, 0.0]]), np.array([[0.0, 1.0], [1.0, 0.0]]), np.array([[0.0, 0.0], [0.0, 1.0]]))
    for q, d in enumerate(basis):
        dbig = -big_m @ d @ big_m
        jac[:, q] = [dbig[0, 0], dbig[0, 1], dbig[1, 1]]
    cov_m = jac @ cov0 @ jac.T
    for idx, (name, value) in enumerate((("M11", big_m[0, 0]), ("M12", big_m[0, 1]), ("M22", big_m[1, 1]))):
        out[name] = (float(value), float(np.sqrt(max(cov_m[idx, idx], 0.0))))
    return out
