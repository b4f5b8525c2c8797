"""The paper's observer-based adaptive estimator (Eqs. 26-36), one readable step at a time.

Continuous-time laws (k > 0, row vectors w, g of length p, one theta_i per wheel):

    w'        = g(eta, tau) - k w,                       w(t0) = 0                      (27)
    eta_hat'  = [g theta_hat_i] + k e + [w theta_hat_i']  e = eta - eta_hat              (26)
    xi_hat'   = -k xi_hat,                               xi_hat(t0) = e(t0)             (30)
    Gamma'    = w^T w,                                    Gamma(t0) = alpha I            (33)
    (Gamma^-1)' = -Gamma^-1 Gamma' Gamma^-1                                              (34)
    theta_hat_i' = Gamma^-1 w^T (e_i - xi_hat_i)                                         (35-36)

Discretisation at the log's own (possibly uneven) stamps t_n, h = t_{n+1} - t_n:

* Eqs. (26), (27), (30) are linear filters; they are solved EXACTLY over each step for inputs that vary
  linearly between samples (first-order hold), with theta_hat held over the step:
  x_{n+1} = a x_n + beta0 f_n + beta1 f_{n+1}, a = exp(-k h), beta_j = h phi_j(k h) (:func:`foh_weights`).
  The torque columns of g may instead be held from each sample to the next (zero-order hold,
  ``torque_hold="zoh"``, x_{n+1} = a x_n + (beta0 + beta1) f_n): that is what a digital controller
  applies, and it is exact for logs of commanded torque such as the paper's virtual prototype.  A
  measured, continuous effort (a filtered current) calls for ``"foh"``.
* A column c(eta) phi' of g whose phi' is a derivative (the ``wheel+caster+load`` model's drag that follows v'
  or w', :attr:`wmrid.model.dynamics.RegressorForm.derivative_columns`) is filtered without differentiating:
  over a step, c linear and phi linear, the filter's input is phi' (beta0 c_n + beta1 c_{n+1})
  (:func:`wmrid.model.dynamics.filter_regressor`), phi' being phi's rate over the PREVIOUS step,
  (phi_n - phi_{n-1}) / (t_n - t_{n-1}): phi' one step late (:data:`wmrid.model.dynamics.DERIVATIVE_LAG`).
  The change over this step would hold this sample's speed noise e_{n+1} at full weight (the 1/h cancels against
  beta ~ h), and the prediction error eta_{n+1} - eta_hat holds it too: the regressor's noise would correlate with
  the residual's and bias the estimate whatever the drag's true load terms (the paper robot's MuJoCo plan log,
  0.02 rad/s: the structural mismatch T2 532 on 17 dof with the load terms' truth zero, 112 one step late).
  Summed over steps the differences of phi telescope, so noise on phi enters the filtered column once, never
  amplified.  No expansion of M_eff(eta)^-1 is needed, as eta' appears linearly on the right of eta' = g theta
  (the implicit form).
* theta_hat then jumps at t_{n+1}; the term w theta_hat' of (26) integrates that jump exactly:
  eta_hat += w_{n+1} (theta_hat_{n+1} - theta_hat_n).
* Eqs. (33)-(36) are integrated implicitly (rectangle rule at t_{n+1}): Gamma_{n+1} = Gamma_n + h w^T w,
  Gamma^-1 by the Sherman-Morrison formula (the exact inverse, i.e. Eq. 34 solved exactly over the
  step), and the update uses Gamma_{n+1}^-1.  This is unconditionally stable for any alpha and step.

Consequences used by the tests: with eta_hat(t0) = eta(t0), e - xi_hat = u - w theta_hat, where
u = eta - eta_f and eta_f is eta low-passed by k/(s + k) (no acceleration is ever formed), and
Gamma_N theta_hat_N = alpha theta_hat_0 + sum_n h_n w_n^T u_n: the estimator is exactly a recursive
least-squares fit of u = w theta with prior weight alpha.  Hence, on data without disturbance,
theta_tilde_N = alpha Gamma_N^-1 theta_tilde_0, which is why the paper's alpha = 5000 converges slowly:
the error shrinks only once lambda_min(Gamma) >> alpha.

Projection (35-36).  The paper stops the update of a component outside [theta_min, theta_max]; an
estimate frozen that way can stay frozen for good.  wmrid keeps the recursion above unconstrained
(so nothing ever freezes) and reports the estimate projected onto the box in the Gamma metric,
argmin over the box of (theta - theta_hat)^T Gamma (theta - theta_hat): that is exactly the box-
constrained least-squares fit of all data so far, so it never leaves the box and it leaves the
boundary as soon as the data say so (:func:`project_to_box`).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from wmrid.estimators.observer.kernel import foh
from wmrid.estimators.observer.settings import ObserverSettings
from wmrid.model.dynamics import filter_regressor, platform_speeds


def substep_weights(k: float, h: float, m: int) -> tuple[float, float]:
    """(c0, c1): over a step of h s, the filter input int_0^h exp(-k (h - s)) tau(s) ds = c0 tau_n + c1 tau_{n+1}
    for a torque held over m equal sub-steps (a controller m times faster than the log) at the values
    tau_n + (j/m) (tau_{n+1} - tau_n), j = 0..m-1.  m = 1 is the zero-order hold; m -> inf tends to the
    first-order hold.  Closed form of each sub-step's integral, summed."""
    ends = h * np.arange(1, m + 1) / m
    # each sub-step's exp(-k (h - end)) (1 - exp(-k h / m)) / k, with expm1 so that small k h does not cancel
    weights = np.exp(-k * (h - ends)) * (-np.expm1(-k * h / m) / k) if k > 0 else np.full(m, h / m)
    frac = np.arange(m) / m
    return float(np.sum((1.0 - frac) * weights)), float(np.sum(frac * weights))


def foh_weights(x: float) -> tuple[float, float, float]:
    """(a, phi0, phi1) for x = k h: exp(-x) and the first-order-hold weights divided by h.

    phi0(x) = int_0^1 exp(-x v) v dv = (1 - exp(-x)(1 + x)) / x^2, phi1(x) = (1 - exp(-x))/x - phi0(x),
    so that over one step of x' = -k x + f(t) with f linear: x_{n+1} = a x_n + h (phi0 f_n + phi1 f_{n+1}).
    A Taylor series is used for x < 0.1 where the closed form cancels (the compiled kernel's, one implementation:
    :func:`wmrid.estimators.observer.kernel.foh`).
    """
    a, phi0, phi1 = foh(float(x))
    return float(a), float(phi0), float(phi1)


@dataclass
class ObserverState:
    """State of the estimator after the sample at time t (all arrays float64).

    w (p,), eta_hat (2,) rad/s, xi_hat (2,) rad/s, gamma and gamma_inv (p, p), theta (2, p) the
    unconstrained estimate, g (p,) and eta (2,) of the last sample, e_prior (2,) rad/s the prediction
    error at the last sample before its update, eta_rate (2,) rad/s^2 eta's rate of change over the last step (what
    the next step's derivative columns take, :data:`wmrid.model.dynamics.DERIVATIVE_LAG`).
    """

    t: float
    eta: np.ndarray
    g: np.ndarray
    w: np.ndarray
    eta_hat: np.ndarray
    xi_hat: np.ndarray
    gamma: np.ndarray
    gamma_inv: np.ndarray
    theta: np.ndarray
    e_prior: np.ndarray = field(default_factory=lambda: np.zeros(2))
    eta_rate: np.ndarray = field(default_factory=lambda: np.zeros(2))


def initial_state(
    t0: float, eta0: np.ndarray, tau0: np.ndarray, settings: ObserverSettings, eta_sign0: np.ndarray | None = None
) -> ObserverState:
    """State at the first sample: w = 0, eta_hat = eta, xi_hat = e = 0, Gamma = alpha I (Eqs. 27, 30, 33).
    eta_sign0 (2,) rad/s: the speed its sign columns are taken from (:mod:`wmrid.estimators.sign_speed`; None: eta0)."""
    p = settings.form.n_columns
    eta0 = np.asarray(eta0, dtype=float)
    s0 = None if eta_sign0 is None else np.asarray(eta_sign0, dtype=float)[None, :]
    g0 = filter_regressor(eta0[None, :], np.asarray(tau0, dtype=float)[None, :], settings.form, s0)[0]
    return ObserverState(
        t=float(t0), eta=eta0.copy(), g=g0, w=np.zeros(p), eta_hat=eta0.copy(), xi_hat=np.zeros(2),
        gamma=settings.alpha * np.eye(p), gamma_inv=np.eye(p) / settings.alpha,
        theta=np.array(settings.theta_init, dtype=float),
    )  # fmt: skip


def observer_step(
    state: ObserverState,
    t: float,
    eta: np.ndarray,
    tau: np.ndarray,
    settings: ObserverSettings,
    eta_sign: np.ndarray | None = None,
) -> ObserverState:
    """Advance the estimator to a new sample (t s, eta (2,) rad/s, tau (2,) N m). Pure: returns a new state.
    eta_sign (2,) rad/s: the speed the sign columns are taken from (:mod:`wmrid.estimators.sign_speed`; None: eta)."""
    h = t - state.t
    if not h > 0:
        raise ValueError(f"time must increase: {state.t} -> {t}")
    k = settings.k
    a, phi0, phi1 = foh_weights(k * h)
    b0, b1 = h * phi0, h * phi1
    eta = np.asarray(eta, dtype=float)
    s = None if eta_sign is None else np.asarray(eta_sign, dtype=float)[None, :]
    g = filter_regressor(eta[None, :], np.asarray(tau, dtype=float)[None, :], settings.form, s)[0]
    theta = state.theta

    g_in = b0 * state.g + b1 * g  # the filters' input over the step (first-order hold) ...
    if settings.torque_hold == "zoh" and settings.control_rate is None:
        g_in[:2] = (b0 + b1) * state.g[:2]  # ... with the torques held
    elif settings.torque_hold == "zoh":  # ... held over the controller's sub-steps
        c0, c1 = substep_weights(k, h, max(1, round(h * settings.control_rate)))
        g_in[:2] = c0 * state.g[:2] + c1 * g[:2]
    derivative = settings.form.derivative_columns
    if derivative:  # ... and c(eta) phi' as c linear times phi' = (phi change) / h (dynamics.filter_regressor)
        # the previous step's change: this step's carries this sample's noise, as the prediction error does
        rates = platform_speeds(state.eta_rate, settings.form.geometry[0], settings.form.geometry[1])
        for col, which in derivative:
            g_in[col] = rates[which] * (b0 * state.g[col] + b1 * g[col])
    w = a * state.w + g_in  # (27)
    eta_hat = a * state.eta_hat + theta @ g_in + k * (b0 * state.eta + b1 * eta)  # (26)
    xi_hat = a * state.xi_hat  # (30)
    e_prior = eta - eta_hat

    gamma = state.gamma + h * np.outer(w, w)  # (33)
    pw = state.gamma_inv @ w  # (34) by Sherman-Morrison
    gamma_inv = state.gamma_inv - np.outer(pw, pw) / (1.0 / h + w @ pw)
    gamma_inv = 0.5 * (gamma_inv + gamma_inv.T)

    gain = h * (gamma_inv @ w)  # (35)-(36)
    d_theta = np.outer(e_prior - xi_hat, gain)
    theta_new = theta + d_theta
    eta_hat = eta_hat + d_theta @ w  # the w theta_hat' term of (26)
    return ObserverState(
        t=float(t), eta=eta, g=g, w=w, eta_hat=eta_hat, xi_hat=xi_hat,
        gamma=gamma, gamma_inv=gamma_inv, theta=theta_new, e_prior=e_prior, eta_rate=(eta - state.eta) / h,
    )  # fmt: skip


def project_to_box(theta: np.ndarray, gamma: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """argmin over lo <= x <= hi of (x - theta)^T Gamma (x - theta), per row of theta (2, p).

    An exact active-set solution of the box-constrained quadratic (p is 7 or 8).  Returns theta
    itself when it lies inside the box.
    """
    out = np.array(theta, dtype=float)
    for i in range(out.shape[0]):
        out[i] = _project_row(out[i], gamma, lo[i], hi[i])
    return out


def _project_row(x0: np.ndarray, gamma: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    if np.all(x0 >= lo) and np.all(x0 <= hi):
        return x0.copy()
    from scipy.optimize import lsq_linear  # scipy.optimize (~0.3 s): only an estimate outside its bounds

    # (x - x0)^T Gamma (x - x0) = |L^T (x - x0)|^2 with Gamma = L L^T; scale columns for conditioning.
    scale = np.sqrt(np.maximum(np.diag(gamma), 1e-300))
    g_scaled = gamma / np.outer(scale, scale)
    lower = np.linalg.cholesky(g_scaled + 1e-14 * np.eye(len(x0)))
    a_mat = lower.T
    y0 = x0 * scale
    res = lsq_linear(a_mat, a_mat @ y0, bounds=(lo * scale, hi * scale), method="bvls", tol=1e-14)
    return np.clip(res.x / scale, lo, hi)
