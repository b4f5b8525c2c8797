"""Recover the base parameters theta0 (Eq. 21) from an estimate of the intermediate parameters theta.

theta (2 x p, 14 or 16 numbers) over-determines theta0 (8 numbers): V_c appears in both rows,
m12 and m21 are one number, and so on.  wmrid recovers theta0 by minimum distance: the theta0 whose
intermediate parameters f(theta0) (Eqs. 23-24) are closest to the estimate in the metric of the
estimate's own covariance C,

    theta0* = argmin (theta_hat - f(theta0))^T C^-1 (theta_hat - f(theta0)),

which weighs each relation by how well the log pins it.  The fit is linear to first order,
theta0* - theta0 = G (theta_hat - theta), G = (J^T W J)^-1 J^T W with W = C^-1 and J the Jacobian at the
optimum, so the covariance of theta0* is G C_r G^T for whatever covariance C_r of theta_hat is reported
(the sandwich: valid even when the weights C are not the best estimate of the spread).

The misfit rho = theta_hat - f(theta0*) is the structural mismatch.  With the reported covariance a
jackknife estimate on B degrees of freedom (:mod:`wmrid.estimators.uncertainty`), T^2 = rho^T pinv(C_rho) rho over the
d = rank(C_rho) <= 2p - 8 directions the fit leaves is Hotelling's statistic, and
(B - d + 1) T^2 / (B d) ~ F(d, B - d + 1) when the model holds.  A small p-value says the log violates the
model (slip, unmodelled friction, a wrong sign convention...).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from wmrid.model.dynamics import RegressorForm, default_base_names, intermediate_parameters, inverse_inertia


@dataclass(frozen=True)
class BaseFit:
    """theta0 (8,), its covariance (8, 8), and the structural-mismatch test.

    chi2 is the misfit in the metric of the weights (Hotelling's T^2 when a reported covariance with
    ``report_dof`` is given), dof its number of directions d, p_value its p-value (nan when d = 0).
    """

    theta0: np.ndarray
    cov: np.ndarray
    chi2: float
    dof: int
    p_value: float
    gain: np.ndarray  # (8, 2p): d theta0* / d theta_hat.ravel() at the optimum
    report_dof: int | None = None  # B, the reported covariance's degrees of freedom (None: chi-square test)


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
    base = [m[0, 0], m[0, 1], m[1, 1], vc, fv[0], fv[1], fd[0], fd[1]] + [0.0] * (form.n_base - 8)
    counts = [0] * form.n_base
    for col, param, pattern in form.caster_map:  # [theta_1c, theta_2c] = m [1, pattern]^T theta0[param]
        base[param] += float(np.array([1.0, pattern]) @ big_m @ theta[:, col]) / 2.0
        counts[param] += 1
    for param in range(8, form.n_base):
        base[param] /= max(counts[param], 1)
    return np.array(base)


def recover_history(theta: np.ndarray, form: RegressorForm) -> np.ndarray:
    """The base parameters (n, form.n_base) of each of n intermediate estimates theta (n, 2, p), by
    :func:`direct_recovery` (a history's trajectory: the reported estimate is the minimum-distance fit)."""
    theta = np.asarray(theta, dtype=float)
    with np.errstate(all="ignore"):
        return np.array([direct_recovery(th, form) for th in theta]).reshape(len(theta), -1)


def _whitener(cov: np.ndarray) -> np.ndarray:
    """W with W^T W = pinv(cov), dropping directions with eigenvalues below 1e-14 of the largest."""
    vals, vecs = np.linalg.eigh(0.5 * (cov + cov.T))
    keep = vals > max(vals.max(), 0.0) * 1e-14
    return (vecs[:, keep] / np.sqrt(vals[keep])).T


def fit_base_parameters(
    theta: np.ndarray,
    cov: np.ndarray,
    form: RegressorForm,
    *,
    report_cov: np.ndarray | None = None,
    report_dof: int | None = None,
) -> BaseFit:
    """Minimum-distance theta0 from theta (2, p), weighted by ``cov`` (2p, 2p) of theta.ravel().

    ``report_cov`` (default ``cov``) is the covariance of theta.ravel() to propagate; ``report_dof``
    its degrees of freedom when it is a jackknife estimate (None: a chi-square test in the weights' metric).
    """
    from scipy.special import chdtrc, fdtrc  # scipy.special (~0.15 s): only when base parameters are fitted

    theta = np.asarray(theta, dtype=float)
    start = direct_recovery(theta, form)
    whiten = _whitener(cov)
    target = theta.ravel()

    n0 = form.n_base
    theta0 = gauss_newton(start, whiten, target, form)
    jac = jacobian_intermediate(theta0, form)
    weight = whiten.T @ whiten
    info = jac.T @ weight @ jac
    info_inv = np.linalg.pinv(info, rcond=1e-15, hermitian=True)
    gain = info_inv @ jac.T @ weight  # (8, 2p): d theta0* / d theta_hat
    reported = cov if report_cov is None else report_cov
    cov0 = gain @ reported @ gain.T
    misfit = target - intermediate_parameters(theta0, form).ravel()
    if report_dof is None:
        chi2 = float(np.sum((whiten @ misfit) ** 2))
        dof = max(whiten.shape[0] - n0, 0)
        p_value = float(chdtrc(dof, chi2)) if dof > 0 else float("nan")
    else:
        leave = np.eye(len(target)) - jac @ gain  # misfit = leave @ (theta_hat - theta) to first order
        cov_misfit = leave @ reported @ leave.T
        chi2, dof = _hotelling(misfit, cov_misfit, max_rank=min(len(target) - n0, report_dof))
        big_b = report_dof
        if dof > 0 and big_b - dof + 1 > 0:
            p_value = float(fdtrc(dof, big_b - dof + 1, (big_b - dof + 1) * chi2 / (big_b * dof)))
        else:
            p_value = float("nan")
    return BaseFit(
        theta0=theta0, cov=0.5 * (cov0 + cov0.T), chi2=chi2, dof=dof, p_value=p_value, gain=gain, report_dof=report_dof
    )


def gauss_newton(start: np.ndarray, whiten: np.ndarray, target: np.ndarray, form: RegressorForm) -> np.ndarray:
    """argmin_x |whiten (f(x) - target)|^2 by Gauss-Newton with the exact Jacobian and step halving.

    f is bilinear in (m, [Vc, Fv, Fd]) and the start (:func:`direct_recovery`) is already close, so a
    handful of iterations reach rounding level.  (scipy.optimize.least_squares gives the same answer;
    a test checks it.  This loop avoids importing scipy.optimize, a third of ``wmrid identify``'s start-up.)
    """
    x = np.array(start, dtype=float)

    def cost(v: np.ndarray) -> float:
        return float(np.sum((whiten @ (intermediate_parameters(v, form).ravel() - target)) ** 2))

    current = cost(x)
    for _ in range(100):
        r = whiten @ (intermediate_parameters(x, form).ravel() - target)
        a = whiten @ jacobian_intermediate(x, form)
        step = np.linalg.lstsq(a, -r, rcond=None)[0]
        for _ in range(30):
            trial = x + step
            new = cost(trial)
            if new <= current:
                break
            step = 0.5 * step
        else:
            break
        done = np.all(np.abs(step) <= 1e-15 * np.maximum(np.abs(x), 1e-300)) or current - new <= 1e-15 * current
        x, current = trial, new
        if done:
            break
    return x


def _hotelling(misfit: np.ndarray, cov: np.ndarray, max_rank: int) -> tuple[float, int]:
    """rho^T pinv(C) rho over the leading ``max_rank`` eigen-directions of C above 1e-12 of the largest."""
    vals, vecs = np.linalg.eigh(0.5 * (cov + cov.T))
    order = np.argsort(vals)[::-1][: max(max_rank, 0)]
    keep = [i for i in order if vals[i] > max(vals.max(), 0.0) * 1e-12]
    if not keep:
        return 0.0, 0
    proj = vecs[:, keep].T @ misfit
    return float(np.sum(proj**2 / vals[keep])), len(keep)


def jacobian_intermediate(theta0: np.ndarray, form: RegressorForm) -> np.ndarray:
    """d vec(f(theta0)) / d theta0, (2p, n0), exact (f is bilinear in (m, [Vc, Fv, Fd, Cv, Cw]))."""
    p = form.n_columns
    jac = np.zeros((2 * p, form.n_base))
    m = inverse_inertia(theta0)
    vc, fv1, fv2, fd1, fd2 = theta0[3:8]
    caster_map = form.caster_map
    # d m_ij / d (m11, m12, m22)
    dm = {
        0: np.array([[1.0, 0.0], [0.0, 0.0]]),
        1: np.array([[0.0, 1.0], [1.0, 0.0]]),
        2: np.array([[0.0, 0.0], [0.0, 1.0]]),
    }
    s1, s2 = form.signs if form.kind == "paper" else (1, 1)
    for i in range(2):
        row = i * p
        for q, d in dm.items():
            di1, di2 = d[i]
            col = [di1, di2, di1 * vc, di2 * vc, di1 * fv1, di2 * fv2]
            col += [di1 * fd1 * s1 + di2 * fd2 * s2] if form.kind == "paper" else [di1 * fd1, di2 * fd2]
            col += [(di1 + pattern * di2) * theta0[param] for _, param, pattern in caster_map]
            jac[row : row + p, q] = col
        mi1, mi2 = m[i]
        jac[row + 2, 3], jac[row + 3, 3] = mi1, mi2
        jac[row + 4, 4] = mi1
        jac[row + 5, 5] = mi2
        if form.kind == "paper":
            jac[row + 6, 6], jac[row + 6, 7] = mi1 * s1, mi2 * s2
        else:
            jac[row + 6, 6], jac[row + 7, 7] = mi1, mi2
        for c, param, pattern in caster_map:
            jac[row + c, param] = mi1 + pattern * mi2
    return jac


def derived_with_std(
    theta0: np.ndarray, cov0: np.ndarray, names: tuple[str, ...] | None = None
) -> dict[str, tuple[float, float]]:
    """Named base parameters plus M = m^-1, each (value, std) by the delta method (exact Jacobian of M).

    ``names`` of theta0's entries (default: the eight base parameters, then Cv, Cw)."""
    if names is None:
        names = default_base_names(len(theta0))
    std0 = np.sqrt(np.clip(np.diag(cov0), 0.0, None))  # inf stays inf: a parameter the log does not determine
    out = {n: (float(v), float(s)) for n, v, s in zip(names, theta0, std0, strict=True)}
    m = inverse_inertia(theta0)
    big_m = np.linalg.inv(m)
    # dM = -M dm M for each of the three m entries
    jac = np.zeros((3, len(theta0)))
    basis = (np.array([[1.0, 0.0], [0.0, 0.0]]), np.array([[0.0, 1.0], [1.0, 0.0]]), np.array([[0.0, 0.0], [0.0, 1.0]]))
    for q, d in enumerate(basis):
        dbig = -big_m @ d @ big_m
        jac[:, q] = [dbig[0, 0], dbig[0, 1], dbig[1, 1]]
    finite = np.all(np.isfinite(cov0[:3, :3]))
    cov_m = jac @ np.where(np.isfinite(cov0), cov0, 0.0) @ jac.T
    for idx, (name, value) in enumerate((("M11", big_m[0, 0]), ("M12", big_m[0, 1]), ("M22", big_m[1, 1]))):
        std = float(np.sqrt(max(cov_m[idx, idx], 0.0))) if finite else math.inf
        out[name] = (float(value), std)
    return out


def weighting_covariance(gain: np.ndarray, weight_cov: np.ndarray, cov0: np.ndarray) -> np.ndarray:
    """(n0, n0): the Newey-West covariance of theta (2p, 2p) through the minimum-distance gain (n0, 2p), G W G^T;
    a parameter the reported covariance ``cov0`` leaves undetermined (a non-finite diagonal) is left so here too
    (NaN row and column, +inf on the diagonal)."""
    out = gain @ weight_cov @ gain.T
    out = 0.5 * (out + out.T)
    bad = ~np.isfinite(np.diag(cov0)) | ~np.isfinite(np.diag(out))
    out[bad, :] = np.nan
    out[:, bad] = np.nan
    out[bad, bad] = np.inf
    return out
