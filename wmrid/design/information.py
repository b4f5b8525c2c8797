"""The precision a drive will give, before anyone drives it: the covariance of the base parameters theta0 that
wmrid's observer-based estimator would report on a log of that motion with white sensor noise.

The estimator (:mod:`wmrid.estimators.observer.step`) is a least-squares fit of u = w theta per wheel, where
w' = g(eta, tau) - k w is the low-passed regressor (Eq. 27) and u = eta - eta_f, eta_f = k/(s + k) eta.  On a noisy
log (speed noise e_eta, effort noise e_tau, white, per sample) the residual of wheel i at the true theta is, to first
order in the noise (the regressor's columns hold the noisy eta and tau)::

    r_i = (1 - L) e_eta,i - (1 / k) L [ sum_j m_ij e_tau,j - sum_l c_il e_eta,l ],   c_il = sum_j m_ij D_jl

with L the unit-gain low-pass k/(s + k) in the observer's zero-order-hold discretisation and D = d(V + F_v eta)/d eta
the model's speed sensitivity.  The Coulomb columns are the sign of a MEASURED speed, a 20 ms centred mean of it
(:mod:`wmrid.estimators.sign_speed`; noise sigma_s = sigma / sqrt(n_w), :attr:`SensorNoise.sign_std`), which the noise
flips near standstill: the regressor is taken at its mean there (-erf(eta / (sqrt(2) sigma_s)), so a wheel crawling
near zero speed carries little information on F_d), and the flips are one more source, of std F_dj sqrt(1 - erf^2),
entering like effort noise (``coulomb``: the F_d assumed for them), with the intensity of flips that last as long as
the mean's noise keeps its sign (:attr:`SensorNoise.flip_intensity`: 15 times a white flip's at 1 kHz; checked
against a Monte Carlo of the estimator with those signs).

The estimate's error is Gamma^-1 sum_n h w_n^T r_n, Gamma = sum h w^T w: linear in the noise, so its covariance
follows exactly from the ADJOINT filters (the noise sample at m reaches the sum through z_m = h sum_n L[n, m] w_n,
the time-reversed filter of w), with no Monte Carlo.  The base parameters come from the
intermediate ones by the minimum-distance fit of :mod:`wmrid.model.base_params`, whose covariance with the best
weights is (J^T C^-1 J)^-1, J = d theta / d theta0 (complex-step derivative, exact).

Logs already identified (``plan --given``) enter as :class:`GivenLogs`: their estimate is combined with the planned
log's by fixed weights, and the combination's covariance is linear in their REPORTED covariance (a sandwich), never
its inverse: wmrid reports a jackknife covariance with few degrees of freedom (a 20 s log: 9, for 8 parameters),
whose inverse overstates the information in its weakest directions many times over (the seed-100 sinusoid of
``bench/studies/study_plan.py --sequential``: eigenvalues 0.07-23 of the true covariance's).

What this leaves out, and the reported std includes: a coloured disturbance (caster, slip), the controller's
response to noise (a simulator's controller sees the true state; a real one sees the noisy speeds), and
errors-in-variables bias.  The tests check the formula against a Monte Carlo of the same estimator's algebra and
against wmrid's own identification of simulated logs.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.special import erf

from wmrid.estimators.sign_speed import sign_half_window
from wmrid.model.dynamics import RegressorForm, caster_columns, intermediate_parameters, inverse_inertia, regressor

#: The estimator's default filter gain k, 1/s (``identify --k``).
DEFAULT_K = 10.0


@dataclass(frozen=True)
class SensorNoise:
    """White sensor noise of the log to be recorded: eta_std (rad/s) on each wheel speed and tau_std (N m) on each
    effort, per sample at ``rate`` Hz (the log's rate: the same noise at twice the rate carries twice the
    information)."""

    eta_std: float
    tau_std: float
    rate: float

    def to_dict(self) -> dict[str, float]:
        return {"eta_std": self.eta_std, "tau_std": self.tau_std, "rate": self.rate}

    @property
    def sign_window(self) -> int:
        """n_w: how many samples the speed the estimator takes its signs and drag directions from averages (a
        centred mean SIGN_WINDOW_S wide at the log's rate, :mod:`wmrid.estimators.sign_speed`; 1 at 50 Hz and
        slower)."""
        return 2 * sign_half_window(round(self.rate) + 1, 1.0) + 1

    @property
    def sign_std(self) -> float:
        """rad/s: the noise on that mean, eta_std / sqrt(n_w)."""
        return self.eta_std / math.sqrt(self.sign_window)

    @property
    def flip_intensity(self) -> float:
        """How much more a sign flip weighs than a white one, per sample: a flip lasts as long as the mean's noise
        keeps its sign, so the flips' sum over a stretch much longer than the window (the filter's 1/k) has the
        variance of white flips times sum_k (2/pi) arcsin(rho_k), rho_k = 1 - |k| / n_w the mean's autocorrelation
        (the arcsine law of the sign of a Gaussian pair; exact at a zero crossing, where the flips happen).  n_w = 1:
        1; 21 samples (1 kHz): 15.3."""
        n = self.sign_window
        lags = np.arange(-(n - 1), n)
        return float(np.sum(2.0 / math.pi * np.arcsin((n - np.abs(lags)) / n)))


@dataclass(frozen=True)
class GivenLogs:
    """Logs already identified, as the planned log's estimate will be combined with theirs: weight W (n0, n0) and
    spread S = sum_k W_k C_k W_k (n0, n0), C_k a log's reported covariance and W_k its weight
    (:meth:`wmrid.estimators.combination.Part.weight`, as ``wmrid identify --given`` weighs it).  The combined estimate
    (W + I)^-1 (sum_k W_k x_k + I x) of the planned log's x (information I) has the covariance
    (W + I)^-1 (S + I) (W + I)^-1 (:func:`combined_covariance`): exact for any fixed weights, and linear in the
    C_k, so an unbiased reported covariance gives an unbiased prediction.  W = S = C^-1 is the textbook sum of
    information.  Left out: the widening identify adds for the noise of its weights (5-13 % in variance on 20 s logs,
    :func:`wmrid.estimators.combination.weight_noise_factor`)."""

    weight: np.ndarray
    spread: np.ndarray

    @classmethod
    def information(cls, info: np.ndarray) -> GivenLogs:
        """Given logs known by their exact information (inverse covariance) ``info``: W = S = info."""
        info = np.asarray(info, dtype=np.float64)
        return cls(info, info)


def combined_covariance(info: np.ndarray, given: GivenLogs | None) -> np.ndarray:
    """Cov(theta0) (n0, n0) of the planned log's estimate (information ``info``) combined with the given logs'
    (:class:`GivenLogs`; None: the planned log alone, info^-1)."""
    if given is None:
        cov = np.linalg.inv(info)
    else:
        a = np.linalg.inv(given.weight + info)
        cov = a @ (given.spread + info) @ a
    return 0.5 * (cov + cov.T)


def sign_statistics(eta: np.ndarray, sigma: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(E, sd, dE/deta), each (n, 2): the measured sign sgn(eta + e) of a speed eta (rad/s) under white noise e of std
    sigma: its mean E = erf(eta / (sqrt(2) sigma)), its std sqrt(1 - E^2), and the mean's slope.  sigma = 0: the sign
    itself, std 0."""
    if sigma <= 0:
        return np.sign(eta), np.zeros_like(eta), np.zeros_like(eta)
    x = eta / (math.sqrt(2.0) * sigma)
    mean = erf(x)
    sd = np.sqrt(np.clip(1.0 - mean * mean, 0.0, None))
    slope = math.sqrt(2.0 / math.pi) / sigma * np.exp(-x * x)
    return mean, sd, slope


def expected_regressor(
    eta: np.ndarray, tau: np.ndarray, form: RegressorForm, sigma: float, eta_dot: np.ndarray | None = None
) -> np.ndarray:
    """The regressor g(eta, tau) (n, p) the estimator will see on average: its Coulomb columns -sgn(eta_j) of the
    MEASURED speed, whose mean near standstill is -erf(eta_j / (sqrt(2) sigma)) rather than -sgn(eta_j).  A caster
    drag that follows the load (``form.load``) needs the motion's eta_dot (n, 2) rad/s^2 for its v' and w' columns.

    The casters' drag columns (``form.caster``) are taken at the true motion: the noise that reaches the estimate
    through them (their direction turns with the measured speeds, and the load terms' v' and w' are made from them)
    is left out of the prediction, as the flips of the two-term model's signs are."""
    g = regressor(eta, tau, form, eta_dot)
    if form.kind == "general" and sigma > 0:
        g[:, 6:8] = -sign_statistics(eta, sigma)[0]
    return g


def lowpass(x: np.ndarray, a: float) -> np.ndarray:
    """y_n = a y_{n-1} + (1 - a) x_{n-1}, y_0 = 0 along axis 0: the unit-gain zero-order-hold low-pass."""
    # scipy.signal (~0.8 s to import): only a prediction, not every import of the planner (``wmrid report`` asks it
    # whether its input is a plan)
    from scipy.signal import lfilter

    return lfilter([0.0, 1.0 - a], [1.0, -a], x, axis=0)


def lowpass_adjoint(x: np.ndarray, a: float) -> np.ndarray:
    """The transpose of :func:`lowpass` as an operator on sequences: (L^T x)_m = (1 - a) sum_{n > m} a^(n-m-1) x_n."""
    return lowpass(x[::-1], a)[::-1]


def speed_sensitivity(eta: np.ndarray, theta0: np.ndarray) -> np.ndarray:
    """D (n, 2, 2): d(V_j + F_vj eta_j) / d eta_l along eta (n, 2) rad/s, N m s/rad."""
    vc, fv1, fv2 = theta0[3], theta0[4], theta0[5]
    e1, e2 = eta[:, 0], eta[:, 1]
    d = np.empty((len(eta), 2, 2))
    d[:, 0, 0] = vc * e2 + fv1
    d[:, 0, 1] = vc * (e1 - 2.0 * e2)
    d[:, 1, 0] = vc * (e2 - 2.0 * e1)
    d[:, 1, 1] = vc * e1 + fv2
    return d


def intermediate_jacobian(theta0: np.ndarray, form: RegressorForm) -> np.ndarray:
    """J (2p, n0) = d theta.ravel() / d theta0, by the complex step (theta is a polynomial in theta0: exact)."""
    theta0 = np.asarray(theta0, dtype=np.float64)
    step = 1e-30
    cols = []
    for i in range(len(theta0)):
        x = theta0.astype(complex)
        x[i] += 1j * step
        cols.append(np.imag(intermediate_parameters(x, form)).ravel() / step)
    return np.stack(cols, axis=1)


@dataclass(frozen=True)
class _Forward:
    """What the intermediate covariance is made of, kept for the gradient (:class:`CovarianceGradient`)."""

    a: float
    w: np.ndarray
    adj: np.ndarray
    c: np.ndarray
    zs: list[np.ndarray]
    qs: list[float]
    fd: np.ndarray
    score: np.ndarray
    gamma_inv: np.ndarray
    big: np.ndarray
    cov: np.ndarray
    gamma: np.ndarray


def _intermediate(eta, tau, h, theta0, form, noise, k, coulomb, eta_dot=None) -> _Forward:
    a = math.exp(-k * h)
    g = expected_regressor(eta, tau, form, noise.sign_std, eta_dot)
    w = lowpass(g, a) / k
    gamma = h * (w.T @ w)
    adj = lowpass_adjoint(w, a)  # (n, p)
    c, zs, qs, fd = noise_scores(w, adj, eta, h, theta0, noise, k, form, coulomb, eta_dot)
    score = sum(q * (z.T @ z) for q, z in zip(qs, zs, strict=True))
    inv = np.linalg.inv(gamma)
    big = np.kron(np.eye(2), inv)
    cov = big @ score @ big
    return _Forward(a, w, adj, c, zs, qs, fd, score, inv, big, 0.5 * (cov + cov.T), gamma)


def intermediate_covariance(
    eta: np.ndarray, tau: np.ndarray, h: float, theta0: np.ndarray, form: RegressorForm, noise: SensorNoise,
    k: float = DEFAULT_K, coulomb: np.ndarray | None = None, eta_dot: np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """(C (2p, 2p), Gamma (p, p)): the covariance of the intermediate estimate theta.ravel() and the information
    matrix Gamma = sum h w^T w, for a log of eta (n, 2) rad/s and tau (n, 2) N m on an even grid of step h s
    (eta_dot (n, 2) rad/s^2: for a caster drag that follows the load, :func:`expected_regressor`).

    The grid need not be the log's: the noise is scaled to the same intensity (variance x time step), so a coarser
    grid gives the same answer while the motion is smooth on it."""
    fwd = _intermediate(eta, tau, h, theta0, form, noise, k, coulomb, eta_dot)
    return fwd.cov, fwd.gamma


def noise_scores(
    w: np.ndarray,
    adj: np.ndarray,
    eta: np.ndarray,
    h: float,
    theta0: np.ndarray,
    noise: SensorNoise,
    k: float,
    form: RegressorForm,
    coulomb: np.ndarray | None = None,
    eta_dot: np.ndarray | None = None,
) -> tuple[np.ndarray, list[np.ndarray], list[float], np.ndarray]:
    """(c (n, 2, 2), z per noise source (n, 2p) x 4, intensity per source): how each white noise sample reaches the
    estimator's score sum h w^T r (module docstring): the speed noise of wheels 1 and 2 (through u and the regressor's
    speed columns, c_il = sum_j m_ij D_jl), then their effort noise (through the effort columns).  The intensity is
    the per-sample variance at the log's rate on this grid, sigma^2 / (rate h).  With speed noise and the general
    form, two more sources: each wheel's sign flips (std F_dj sqrt(1 - E^2), ``coulomb`` = F_d, default theta0's),
    through the Coulomb columns as effort noise goes through the effort columns; the last value returned is F_d
    (2,) as used.  With the casters' geometric model, D also holds the drag's slope across the speed noise
    (:func:`drag_secant`): the drag's direction is taken from the measured speeds.  eta_dot (n, 2) rad/s^2: for a
    drag that follows the load."""
    m = inverse_inertia(theta0)
    sens = speed_sensitivity(eta, theta0)
    if form.geometry and noise.eta_std > 0:
        sens = sens + drag_secant(eta, eta_dot, theta0, form, noise.sign_std)
    c = m[None, :, 0, None] * sens[:, None, 0, :] + m[None, :, 1, None] * sens[:, None, 1, :]
    p = w.shape[1]
    zs: list[np.ndarray] = []
    for src in range(2):
        z = np.empty((len(w), 2 * p))
        for i in range(2):
            part = (c[:, i, src] / k)[:, None] * adj
            if i == src:
                part = part + (w - adj)
            z[:, i * p : (i + 1) * p] = h * part
        zs.append(z)
    for src in range(2):
        zs.append(np.concatenate([-h * m[i, src] / k * adj for i in range(2)], axis=1))
    q_eta = noise.eta_std**2 / (noise.rate * h)
    q_tau = noise.tau_std**2 / (noise.rate * h)
    qs = [q_eta, q_eta, q_tau, q_tau]
    fd = np.abs(np.asarray(theta0[6:8] if coulomb is None else coulomb, dtype=np.float64))
    if form.kind == "general" and noise.eta_std > 0:
        _, sd, _ = sign_statistics(eta, noise.sign_std)
        for src in range(2):
            zs.append(np.concatenate([(-h * m[i, src] / k * fd[src] * sd[:, src])[:, None] * adj for i in range(2)],
                                     axis=1))  # fmt: skip
            qs.append(noise.flip_intensity / (noise.rate * h))
    return c, zs, qs, fd


def base_covariance(
    cov_theta: np.ndarray, theta0: np.ndarray, form: RegressorForm, jac: np.ndarray | None = None
) -> np.ndarray:
    """Cov(theta0) (n0, n0) of the minimum-distance recovery from an intermediate estimate of covariance cov_theta
    (2p, 2p): (J^T C^-1 J)^-1 (weights C^-1, as :mod:`wmrid.model.base_params` uses); ``jac``: J when known."""
    jac = intermediate_jacobian(theta0, form) if jac is None else jac
    info = jac.T @ np.linalg.solve(cov_theta, jac)
    cov = np.linalg.inv(info)
    return 0.5 * (cov + cov.T)


def predicted_covariance(
    eta: np.ndarray, tau: np.ndarray, h: float, theta0: np.ndarray, form: RegressorForm, noise: SensorNoise,
    k: float = DEFAULT_K, jac: np.ndarray | None = None, coulomb: np.ndarray | None = None,
    eta_dot: np.ndarray | None = None,
) -> np.ndarray:  # fmt: skip
    """Cov(theta0) (n0, n0) that the estimator would reach on a log of this motion with this noise (module doc);
    ``jac``: :func:`intermediate_jacobian` when already known; ``coulomb``: the F_d (2,) of the sign flips; eta_dot
    (n, 2) rad/s^2: the motion's wheel accelerations, for a caster drag that follows the load."""
    cov_theta, _ = intermediate_covariance(eta, tau, h, theta0, form, noise, k, coulomb, eta_dot)
    return base_covariance(cov_theta, theta0, form, jac)


class CovarianceGradient:
    """The predicted Cov(theta0) of :func:`predicted_covariance` (with a given information added) and the gradient of
    a scalar function of it with respect to the motion (eta, tau): reverse-mode differentiation of the same algebra,
    step by step (checked against finite differences in the tests), so that the search needs one forward and one
    backward pass per gradient instead of one forward pass per coefficient.

    ``forward()`` computes and keeps what ``backward(g0)`` needs; g0 = dJ/dCov(theta0) (n0, n0).
    """

    def __init__(self, theta0: np.ndarray, form: RegressorForm, noise: SensorNoise, k: float, jac: np.ndarray,
                 given: GivenLogs | None = None, coulomb: np.ndarray | None = None) -> None:  # fmt: skip
        self.theta0, self.form, self.noise, self.k, self.jac, self.given = theta0, form, noise, k, jac, given
        self.coulomb = coulomb
        self.m = inverse_inertia(theta0)

    def forward(self, eta: np.ndarray, tau: np.ndarray, h: float, eta_dot: np.ndarray | None = None) -> np.ndarray:
        """Cov(theta0) along eta (n, 2) rad/s, tau (n, 2) N m on a grid of step h s (eta_dot (n, 2) rad/s^2: for a
        caster drag that follows the load)."""
        fwd = _intermediate(eta, tau, h, self.theta0, self.form, self.noise, self.k, self.coulomb, eta_dot)
        c_inv = np.linalg.inv(fwd.cov)
        info = self.jac.T @ c_inv @ self.jac
        cov0 = combined_covariance(info, self.given)
        self._keep = (fwd, h, c_inv, cov0, eta, info, eta_dot)
        return cov0

    def backward(self, g0: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(dJ/deta (n, 2), dJ/dtau (n, 2), dJ/deta_dot (n, 2)) for g0 = dJ/dCov(theta0), symmetric (the last is
        zero unless the casters' drag follows the load)."""
        fwd, h, c_inv, cov0, eta, info, eta_dot = self._keep
        a, w, adj, c, qs, zs, fd = fwd.a, fwd.w, fwd.adj, fwd.c, fwd.qs, fwd.zs, fwd.fd
        score, inv, big, p = fwd.score, fwd.gamma_inv, fwd.big, fwd.w.shape[1]
        sigma = self.noise.sign_std
        flips = self.form.kind == "general" and sigma > 0
        mean, sd, slope = sign_statistics(eta, sigma)
        g_sd = np.zeros_like(eta)
        k, m = self.k, self.m
        g0 = 0.5 * (g0 + g0.T)
        if self.given is None:
            g_info = -cov0 @ g0 @ cov0  # cov0 = info^-1
        else:  # cov0 = A (S + info) A, A = (W + info)^-1: dA = -A d(info) A
            aw = np.linalg.inv(self.given.weight + info)
            mid = (self.given.spread + info) @ aw
            g_info = aw @ g0 @ aw - aw @ mid @ g0 @ aw - aw @ g0 @ mid.T @ aw
        g_c = -c_inv @ self.jac @ g_info @ self.jac.T @ c_inv  # info = J^T C^-1 J
        g_score = big @ g_c @ big  # C = B S B
        g_big = g_c @ big @ score + score @ big @ g_c
        g_inv = g_big[:p, :p] + g_big[p:, p:]  # B = I2 (x) Gamma^-1
        g_gamma = -inv @ g_inv @ inv
        g_w = 2.0 * h * (w @ g_gamma)  # Gamma = h w^T w
        g_adj = np.zeros_like(adj)
        g_c_il = np.zeros_like(c)  # (n, 2, 2)
        for src in range(len(zs)):
            gz = 2.0 * qs[src] * (zs[src] @ g_score)  # S = sum q z^T z
            for i in range(2):
                block = gz[:, i * p : (i + 1) * p]
                if src < 2:
                    g_c_il[:, i, src] += (h / k) * np.sum(block * adj, axis=1)
                    g_adj += (h * c[:, i, src] / k)[:, None] * block
                    if i == src:
                        g_w += h * block
                        g_adj -= h * block
                elif src < 4:
                    g_adj += (-h * m[i, src - 2] / k) * block
                else:  # sign flips of wheel j: z = -(h / k) m_ij F_dj sd_j adj
                    j = src - 4
                    scale = -h * m[i, j] / k * fd[j]
                    g_adj += (scale * sd[:, j])[:, None] * block
                    g_sd[:, j] += scale * np.sum(block * adj, axis=1)
        g_w += lowpass(g_adj, a)  # adj = L^T w: its adjoint is L
        g_g = lowpass_adjoint(g_w, a) / k  # w = L g / k
        # g = regressor(eta, tau): [tau1, tau2, eta2^2 - eta1 eta2, eta1^2 - eta1 eta2, -eta1, -eta2, -sgn, -sgn, ...]
        e1, e2 = eta[:, 0], eta[:, 1]
        g_tau = g_g[:, 0:2].copy()
        g_eta = np.empty_like(eta)
        g_eta[:, 0] = -g_g[:, 2] * e2 + g_g[:, 3] * (2.0 * e1 - e2) - g_g[:, 4]
        g_eta[:, 1] = g_g[:, 2] * (2.0 * e2 - e1) - g_g[:, 3] * e1 - g_g[:, 5]
        if flips:  # the Coulomb columns -E(eta) and the flips' std sqrt(1 - E^2)
            g_eta -= g_g[:, 6:8] * slope
            with np.errstate(divide="ignore", invalid="ignore"):
                d_sd = np.where(sd > 1e-12, -mean * slope / sd, 0.0)
            g_eta += g_sd * d_sd
        # c_il = sum_j m_ij D_jl(eta); D's entries are linear in eta (Vc) plus constants (F_v)
        g_d = np.einsum("ij,nil->njl", m, g_c_il)  # dJ/dD_jl
        vc = self.theta0[3]
        g_eta[:, 0] += vc * (g_d[:, 0, 1] - 2.0 * g_d[:, 1, 0] + g_d[:, 1, 1])
        g_eta[:, 1] += vc * (g_d[:, 0, 0] - 2.0 * g_d[:, 0, 1] + g_d[:, 1, 0])
        g_deta = np.zeros_like(eta)
        if self.form.geometry and sigma > 0:  # D also holds the drag's secant: its slopes by the complex step
            step = 1e-30
            for j in range(2):
                x = eta.astype(complex)
                x[:, j] += 1j * step
                slope = np.imag(drag_secant(x, eta_dot, self.theta0, self.form, sigma)) / step
                g_eta[:, j] += np.einsum("njl,njl->n", g_d, slope)
                if self.form.derivative_columns and eta_dot is not None:
                    y = eta_dot.astype(complex)
                    y[:, j] += 1j * step
                    slope = np.imag(drag_secant(eta, y, self.theta0, self.form, sigma)) / step
                    g_deta[:, j] += np.einsum("njl,njl->n", g_d, slope)
        if self.form.geometry:  # the casters' drag columns -caster_columns(eta, eta_dot), after the 8 wheel columns
            d_eta, d_deta = caster_slopes(eta, eta_dot, self.form)
            g_cols = g_g[:, 8:]
            g_eta -= np.einsum("nq,nqj->nj", g_cols, d_eta)
            g_deta -= np.einsum("nq,nqj->nj", g_cols, d_deta)
        return g_eta, g_tau, g_deta


def caster_slopes(
    eta: np.ndarray, eta_dot: np.ndarray | None, form: RegressorForm
) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """(d col / d eta, d col / d eta_dot), each (n, q, 2): the slopes of the geometric caster model's columns
    (:func:`wmrid.model.dynamics.caster_columns`, q of them) along eta (n, 2) rad/s and eta_dot (n, 2) rad/s^2 (needed
    when the drag follows the load).  d/d eta by the complex step (the columns are analytic in eta: exact); a load
    column drag x v' or drag x w' is linear in eta_dot, its slope the drag column times dv/deta_dot = r/2 [1, 1] or
    dw/deta_dot = r/(2b) [1, -1]."""
    step = 1e-30
    d_eta = np.empty((len(eta), len(form.caster_map), 2))
    for j in range(2):
        x = eta.astype(complex)
        x[:, j] += 1j * step
        d_eta[:, :, j] = np.imag(caster_columns(x, form, eta_dot)) / step
    d_deta = np.zeros_like(d_eta)
    if form.derivative_columns:
        r, b = form.geometry[0], form.geometry[1]
        slope = {0: np.array([0.5 * r, 0.5 * r]), 1: np.array([r / (2.0 * b), -r / (2.0 * b)])}
        multiplier = caster_columns(eta, form, multiplier=True)
        for col, signal in form.derivative_columns:
            q = col - 8
            d_deta[:, q, :] = multiplier[:, q, None] * slope[signal]
    return d_eta, d_deta


def _drag_weights(theta0: np.ndarray, form: RegressorForm) -> np.ndarray:
    """(q, 2): the wheel torques per unit of each caster column, theta0[param] [1, pattern] (``form.caster_map``)."""
    return np.array([[theta0[param], theta0[param] * pattern] for _, param, pattern in form.caster_map])


def drag_secant(
    eta: np.ndarray, eta_dot: np.ndarray | None, theta0: np.ndarray, form: RegressorForm, sigma: float
) -> np.ndarray:  # fmt: skip
    """(n, 2, 2) N m s/rad: how speed noise of std sigma (rad/s) moves the geometric caster model's wheel torques
    sum_q theta0[param_q] col_q(eta) [1, pattern_q] when their direction is taken from the measured speeds: the
    secant (drag(eta + sigma e_l) - drag(eta - sigma e_l)) / (2 sigma) along each wheel l.  Far from a stop it is
    the drag's slope (small); where a caster's contact crawls within the noise the measured direction swings, and
    the secant is as large as the drag over the noise (a sign flip of the drag, as the wheels' Coulomb columns
    have), without the slope's 1 / speed blow-up.  Analytic in eta (and eta_dot): :meth:`CovarianceGradient.backward`
    differentiates it by the complex step."""
    weights = _drag_weights(theta0, form)
    out = np.empty((*eta.shape, 2), dtype=np.result_type(eta, eta_dot if eta_dot is not None else 0.0, float))
    for ell in range(2):
        up, down = eta.copy(), eta.copy()
        up[:, ell] += sigma
        down[:, ell] -= sigma
        diff = (caster_columns(up, form, eta_dot) - caster_columns(down, form, eta_dot)) / (2.0 * sigma)
        out[:, :, ell] = diff @ weights
    return out


def drag_slopes(
    eta: np.ndarray, eta_dot: np.ndarray | None, theta0: np.ndarray, form: RegressorForm
) -> tuple[np.ndarray, np.ndarray]:  # fmt: skip
    """(d drag / d eta, d drag / d eta_dot), each (n, 2, 2) N m s/rad and N m s^2/rad: the slopes of the geometric
    caster model's wheel torques sum_q theta0[param_q] col_q [1, pattern_q] (:func:`caster_slopes`)."""
    d_eta, d_deta = caster_slopes(eta, eta_dot, form)
    weights = _drag_weights(theta0, form)
    return np.einsum("qi,nqj->nij", weights, d_eta), np.einsum("qi,nqj->nij", weights, d_deta)
