"""One design problem: a robot's nominal model, the limits, the sensor noise, the base period and harmonics; the
motion a set of coefficients produces, how close it comes to each limit, and its predicted precision.

The motion is the reference itself: the controller that tracks it (the simulator's, on the nominal model) follows a
reference that starts on the robot at rest exactly, so on the nominal model the wheel speeds are the reference's and
the torques are the inverse dynamics tau = M eta' + V(eta) + F_v eta + F_d sgn(eta) of the nominal base parameters.
A real robot departs from it by its model error and the controller's tracking error; the limits keep a margin for
both (:data:`wmrid.design.limits.DEFAULT_MARGIN`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from wmrid.core.choices import Criterion, values
from wmrid.design.excitation import Basis, pose_along, wheel_motion
from wmrid.design.information import (
    DEFAULT_K,
    CovarianceGradient,
    GivenLogs,
    SensorNoise,
    combined_covariance,
    drag_slopes,
    intermediate_jacobian,
    predicted_covariance,
    speed_sensitivity,
)
from wmrid.design.limits import Limits
from wmrid.model.dynamics import RegressorForm
from wmrid.model.torques import wheel_torque

#: Criteria: the largest relative std of the base parameters (default), D-optimality (the geometric mean of the
#: relative covariance's eigenvalues, as a std: det^(1/2n)) and A-optimality (the rms of the relative stds).
CRITERIA = values(Criterion)

#: Separability built in (constraints of the search, not hopes): each wheel spends at least DIRECTION_SHARE of the
#: time turning forward faster than a tenth of the wheel speed limit, and as much backward (a smooth count: a logistic
#: step a twentieth of the limit wide), so that F_v and F_d separate in each direction; and |corr(v, w)| stays at most
#: CORRELATION (m12 and Vc need v and w to vary independently).
DIRECTION_SHARE = 0.2
CORRELATION = 0.5

#: Share of the nominal value's scale below which a parameter's nominal value counts as unknown (0 in a robot file
#: whose friction is not known): its relative std is then taken against a floor (:func:`parameter_scales`).
FLOOR_SHARE = 0.02


@dataclass(frozen=True)
class Motion:
    """A motion on the design grid: t (n,) s; v m/s, w rad/s, dv, dw (n,); eta (n, 2) rad/s, deta (n, 2) rad/s^2,
    tau (n, 2) N m (nominal inverse dynamics); pose (n, 3) x m, y m, phi rad."""

    t: np.ndarray
    v: np.ndarray
    w: np.ndarray
    dv: np.ndarray
    dw: np.ndarray
    eta: np.ndarray
    deta: np.ndarray
    tau: np.ndarray
    pose: np.ndarray

    def every(self, stride: int) -> Motion:
        """The motion at every ``stride``-th sample (the pose integrated on the full grid, then sampled)."""
        if stride == 1:
            return self
        sl = slice(None, None, stride)
        return Motion(self.t[sl], self.v[sl], self.w[sl], self.dv[sl], self.dw[sl], self.eta[sl], self.deta[sl],
                      self.tau[sl], self.pose[sl])  # fmt: skip

    def peaks(self) -> dict[str, float]:
        """name -> the largest value of each limited quantity (:data:`wmrid.design.limits.LIMIT_NAMES`)."""
        return {
            "max_wheel_speed": float(np.max(np.abs(self.eta))), "max_wheel_accel": float(np.max(np.abs(self.deta))),
            "max_torque": float(np.max(np.abs(self.tau))), "max_speed": float(np.max(np.abs(self.v))),
            "max_turn_rate": float(np.max(np.abs(self.w))), "area_x": float(np.max(np.abs(self.pose[:, 0]))),
            "area_y": float(np.max(np.abs(self.pose[:, 1]))),
        }  # fmt: skip


def parameter_scales(theta0: np.ndarray, names: tuple[str, ...], r: float, limits: Limits,
                     tau_scale: float) -> tuple[np.ndarray, list[str]]:  # fmt: skip
    """(scale (n0,), source per parameter): what each base parameter's std is relative to.

    Its nominal value when that is substantial; else a floor from the robot's own scales, so that an unknown (0)
    friction or a Coriolis coefficient near 0 still gets a meaningful target: for m12 a twentieth of
    sqrt(m11 m22); for Vc, F_v, F_d the value whose torque at the plan's wheel speed limit is FLOOR_SHARE of the
    torque scale ``tau_scale`` (N m: the torque limit, or the nominal torque at the acceleration limit)."""
    eta_max = limits.max_wheel_speed
    floors = {
        "m11": 0.0, "m22": 0.0, "m12": 0.05 * math.sqrt(abs(theta0[0] * theta0[2])),
        "Vc": FLOOR_SHARE * tau_scale / eta_max**2,
        "Fv1": FLOOR_SHARE * tau_scale / eta_max, "Fv2": FLOOR_SHARE * tau_scale / eta_max,
        "Fd1": FLOOR_SHARE * tau_scale, "Fd2": FLOOR_SHARE * tau_scale,
    }  # fmt: skip
    scale, source = [], []
    for name, value in zip(names, theta0, strict=True):
        floor = floors.get(name, FLOOR_SHARE * tau_scale)  # caster drag: N m at the wheel
        if abs(value) >= floor and value != 0:
            scale.append(abs(float(value)))
            source.append("nominal value")
        else:
            scale.append(floor)
            source.append("floor")
    return np.array(scale), source


class Problem:
    """A design problem on an even grid (see the module docstring).

    theta0 : (n0,) nominal base parameters; form : the regressor form (general; caster columns with the
    wheel+caster model); r, b : m; limits; noise; duration, period : s; harmonics : N per channel; ramp : s;
    grid : Hz of the design grid; k : the estimator's gain (1/s); criterion : one of :data:`CRITERIA`;
    given_info : logs already identified (:class:`wmrid.design.information.GivenLogs`; an (n0, n0) array: their
    exact information), or None.
    """

    def __init__(
        self, theta0: np.ndarray, form: RegressorForm, r: float, b: float, limits: Limits, noise: SensorNoise, *,
        duration: float, period: float, harmonics: int, ramp: float, grid: float, k: float = DEFAULT_K,
        criterion: str = "worst", given_info: GivenLogs | np.ndarray | None = None,
    ) -> None:  # fmt: skip
        self.theta0 = np.asarray(theta0, dtype=np.float64)
        self.form, self.r, self.b, self.limits, self.noise = form, r, b, limits, noise
        self.duration, self.period, self.harmonics, self.ramp, self.k = duration, period, harmonics, ramp, k
        self.criterion = criterion
        if given_info is not None and not isinstance(given_info, GivenLogs):
            given_info = GivenLogs.information(given_info)
        self.given_info = given_info
        n = round(duration * grid) + 1
        self.t = np.linspace(0.0, duration, n)
        self.h = duration / (n - 1)
        self.basis = Basis(self.t, duration, period, harmonics, ramp)
        self.bounds = limits.bounds()
        big_m = np.linalg.inv(np.array([[self.theta0[0], self.theta0[1]], [self.theta0[1], self.theta0[2]]]))
        if limits.max_torque is not None:
            self.tau_scale = limits.max_torque
        else:
            self.tau_scale = float(np.max(np.sum(np.abs(big_m), axis=1))) * limits.max_wheel_accel
        self.jac = intermediate_jacobian(self.theta0, form)
        self.scales, self.scale_sources = parameter_scales(self.theta0, form.base_names, r, limits, self.tau_scale)
        #: N m: the Coulomb friction the sign flips near standstill are sized with (its scale when the nominal is 0)
        self.coulomb = self.scales[6:8].copy()
        #: how many of the base parameters the criterion counts: all but a caster load model's terms (the drag's
        #: change with the platform's accelerations: nuisance parameters, not the robot's model)
        self.judged = form.n_base - form.n_casters * len(form.load)

    def motion_of(self, coefficients: np.ndarray, basis: Basis | None = None) -> Motion:
        """The motion (:class:`Motion`) of coefficients (2, N, 2) on this problem's grid (or on ``basis``'s)."""
        basis = basis or self.basis
        v, w, dv, dw = basis.signals(coefficients)
        return self.motion_from(basis.t, v, w, dv, dw)

    def motion_from(self, t: np.ndarray, v: np.ndarray, w: np.ndarray, dv: np.ndarray, dw: np.ndarray) -> Motion:
        """The motion of a reference given as samples (a baseline, a read plan)."""
        eta, deta = wheel_motion(v, w, dv, dw, self.r, self.b)
        # the search's own forms (wheel, two-term casters of nominal 0) need no drag; a geometric caster model's
        # nominal drag is in the efforts the prediction sees
        tau = wheel_torque(eta, deta, self.theta0, self.form) if self.form.geometry else wheel_torque(
            eta, deta, self.theta0[:8])  # fmt: skip
        return Motion(t, v, w, dv, dw, eta, deta, tau, pose_along(t, v, w))

    def ratios(self, motion: Motion) -> dict[str, float]:
        """name -> peak / bound for each limit that is set (<= 1: kept, margin included)."""
        peaks = motion.peaks()
        return {name: peaks[name] / bound for name, bound in self.bounds.items()}

    def separation(self, motion: Motion) -> dict[str, float]:
        """name -> value / bound of the separability constraints (<= 1: kept; see :data:`DIRECTION_SHARE`)."""
        top = self.limits.max_wheel_speed
        out = {}
        for j, wheel in enumerate(("right", "left")):
            for sign, way in ((1.0, "forward"), (-1.0, "backward")):
                share = float(np.mean(0.5 * (1.0 + np.tanh((sign * motion.eta[:, j] - 0.1 * top) / (0.025 * top)))))
                out[f"{way}_{wheel}"] = DIRECTION_SHARE / max(share, 1e-9)
        v, w = motion.v - motion.v.mean(), motion.w - motion.w.mean()
        corr = float(v @ w) / max(math.sqrt(float(v @ v) * float(w @ w)), 1e-300)
        out["corr_v_w"] = abs(corr) / CORRELATION
        return out

    def covariance(self, motion: Motion) -> np.ndarray:
        """Predicted Cov(theta0) (n0, n0) along the motion, combined with the given logs'
        (:func:`wmrid.design.information.combined_covariance`)."""
        h = float(motion.t[1] - motion.t[0])
        cov = predicted_covariance(motion.eta, motion.tau, h, self.theta0, self.form, self.noise, self.k, self.jac,
                                   self.coulomb, motion.deta if self.form.load else None)  # fmt: skip
        if self.given_info is None:
            return cov
        return combined_covariance(np.linalg.inv(cov), self.given_info)

    def relative_std(self, cov: np.ndarray) -> np.ndarray:
        """(n0,) predicted std / scale of each base parameter."""
        return np.sqrt(np.clip(np.diag(cov), 0.0, None)) / self.scales

    def criterion_value(self, cov: np.ndarray) -> float:
        """The criterion (:data:`CRITERIA`), as a relative std (smaller is better)."""
        rel = self.relative_std(cov)[: self.judged]
        if not np.all(np.isfinite(rel)):
            return math.inf
        if self.criterion == "worst":
            return float(np.max(rel))
        if self.criterion == "a":
            return float(np.sqrt(np.mean(rel**2)))
        sub = slice(0, self.judged)
        scaled = cov[sub, sub] / np.outer(self.scales[sub], self.scales[sub])
        sign, logdet = np.linalg.slogdet(scaled)
        return float(np.exp(logdet / (2 * len(rel)))) if sign > 0 else math.inf

    def objective_sensitivity(self, cov: np.ndarray) -> np.ndarray:
        """d(smooth objective)/d cov (n0, n0), symmetric: what :class:`Differentiated` back-propagates (zero on the
        parameters the criterion does not count)."""
        n = self.judged
        sub, scales = cov[:n, :n], self.scales[:n]
        diag = np.clip(np.diag(sub), 1e-300, None)
        if self.criterion == "worst":
            rel16 = (diag / scales**2) ** 8
            part = np.diag(rel16 / (2.0 * diag * np.sum(rel16)))
        elif self.criterion == "a":
            rel2 = diag / scales**2
            part = np.diag(1.0 / (2.0 * n * np.mean(rel2) * scales**2))
        else:
            part = np.linalg.inv(sub) / (2.0 * n)
        out = np.zeros_like(cov)
        out[:n, :n] = part
        return out

    def smooth_objective(self, cov: np.ndarray) -> float:
        """What the local search minimises: the log of the criterion, the max made smooth (a 16-norm) so that its
        gradient does not jump between parameters."""
        if self.criterion != "worst":
            value = self.criterion_value(cov)
            return math.log(value) if math.isfinite(value) and value > 0 else math.inf
        rel = self.relative_std(cov)[: self.judged]
        top = float(np.max(rel))
        if not (math.isfinite(top) and top > 0):
            return math.inf
        return math.log(top) + math.log(float(np.sum((rel / top) ** 16))) / 16.0


def _cumtrapz(y: np.ndarray, h: float) -> np.ndarray:
    """The running trapezoid integral along axis 0, starting at 0 (the pose's integration, :func:`pose_along`)."""
    out = np.zeros_like(y)
    out[1:] = np.cumsum(0.5 * h * (y[1:] + y[:-1]), axis=0)
    return out


class Differentiated:
    """A problem's motion with its Jacobians with respect to the coefficients x = coefficients.ravel() (4N,), for
    the search's gradients: eta, deta, tau (n, 2, 4N) and the pose's x, y (n, 4N); the criterion's gradient by
    :class:`wmrid.design.information.CovarianceGradient`."""

    def __init__(self, problem: Problem) -> None:
        self.problem = problem
        basis, n = problem.basis, problem.harmonics
        perm = np.array([ab * n + j for j in range(n) for ab in (0, 1)])  # x-local (harmonic, a/b) -> basis column
        self.p = basis.s[:, None] * basis.phi[:, perm]
        self.dp = basis.ds[:, None] * basis.phi[:, perm] + basis.s[:, None] * basis.dphi[:, perm]
        zero = np.zeros_like(self.p)
        r, b = problem.r, problem.b
        self.j_eta = np.stack([np.hstack([self.p, b * self.p]), np.hstack([self.p, -b * self.p])], axis=1) / r
        self.j_deta = np.stack([np.hstack([self.dp, b * self.dp]), np.hstack([self.dp, -b * self.dp])], axis=1) / r
        self.j_v, self.j_w = np.hstack([self.p, zero]), np.hstack([zero, self.p])
        theta0 = problem.theta0
        self.big_m = np.linalg.inv(np.array([[theta0[0], theta0[1]], [theta0[1], theta0[2]]]))
        self.grad = CovarianceGradient(theta0, problem.form, problem.noise, problem.k, problem.jac, problem.given_info,
                                       problem.coulomb)  # fmt: skip

    def tau_jacobian(self, motion: Motion) -> np.ndarray:
        pb = self.problem
        d = speed_sensitivity(motion.eta, pb.theta0)  # (n, 2, 2)
        big_m = np.broadcast_to(self.big_m, d.shape)
        if pb.form.geometry:  # the casters' nominal drag is in the efforts (Problem.motion_from)
            d_eta, d_deta = drag_slopes(motion.eta, motion.deta, pb.theta0, pb.form)
            d, big_m = d + d_eta, big_m + d_deta
        return np.einsum("nij,njx->nix", big_m, self.j_deta) + np.einsum("nil,nlx->nix", d, self.j_eta)

    def objective(self, x: np.ndarray) -> tuple[float, np.ndarray]:
        """(the smooth objective, its gradient (4N,)) at x."""
        pb = self.problem
        motion = pb.motion_of(x.reshape(2, -1, 2))
        try:
            cov = self.grad.forward(motion.eta, motion.tau, pb.h, motion.deta if pb.form.load else None)
        except np.linalg.LinAlgError:
            return 1e6, np.zeros_like(x)
        value = pb.smooth_objective(cov)
        if not math.isfinite(value):
            return 1e6, np.zeros_like(x)
        g0 = pb.objective_sensitivity(cov)
        g_eta, g_tau, g_deta = self.grad.backward(g0)
        j_tau = self.tau_jacobian(motion)
        return value, (np.einsum("ni,nix->x", g_eta, self.j_eta) + np.einsum("ni,nix->x", g_tau, j_tau)
                       + np.einsum("ni,nix->x", g_deta, self.j_deta))  # fmt: skip

    def constraint_jacobian(self, x: np.ndarray, stride: int = 1) -> np.ndarray:
        """d(sample constraints)/dx, rows in the order of :func:`wmrid.design.search.sample_constraints` (which
        takes every ``stride``-th sample; the separability constraints use them all)."""
        pb = self.problem
        full = pb.motion_of(x.reshape(2, -1, 2))
        b = pb.bounds
        h = pb.h
        nx = x.size
        sl = slice(None, None, stride)
        motion = full.every(stride)
        j_eta, j_deta = self.j_eta[sl], self.j_deta[sl]
        rows = [
            -(np.sign(motion.eta)[:, :, None] * j_eta).reshape(-1, nx) / b["max_wheel_speed"],
            -(np.sign(motion.deta)[:, :, None] * j_deta).reshape(-1, nx) / b["max_wheel_accel"],
        ]
        phi = full.pose[:, 2]
        j_phi = _cumtrapz(self.j_w, h)
        cos, sin = np.cos(phi)[:, None], np.sin(phi)[:, None]
        v = full.v[:, None]
        j_x = _cumtrapz(self.j_v * cos - v * sin * j_phi, h)[sl]
        j_y = _cumtrapz(self.j_v * sin + v * cos * j_phi, h)[sl]
        rows += [-np.sign(motion.pose[:, 0])[:, None] * j_x / b["area_x"],
                 -np.sign(motion.pose[:, 1])[:, None] * j_y / b["area_y"]]  # fmt: skip
        if "max_torque" in b:
            j_tau = self.tau_jacobian(full)[sl]
            rows.append(-(np.sign(motion.tau)[:, :, None] * j_tau).reshape(-1, nx) / b["max_torque"])
        if "max_speed" in b:
            rows.append(-np.sign(motion.v)[:, None] * self.j_v[sl] / b["max_speed"])
        if "max_turn_rate" in b:
            rows.append(-np.sign(motion.w)[:, None] * self.j_w[sl] / b["max_turn_rate"])
        motion = full
        top = pb.limits.max_wheel_speed
        for j in range(2):
            for sign in (1.0, -1.0):
                z = (sign * motion.eta[:, j] - 0.1 * top) / (0.025 * top)
                share = float(np.mean(0.5 * (1.0 + np.tanh(z))))
                d_share = np.mean(
                    (0.5 * (1.0 - np.tanh(z) ** 2) * sign / (0.025 * top))[:, None] * self.j_eta[:, j, :], axis=0
                )
                rows.append((DIRECTION_SHARE / max(share, 1e-9) ** 2 * d_share)[None, :])
        vc, wc = motion.v - motion.v.mean(), motion.w - motion.w.mean()
        sv, sw = float(vc @ vc), float(wc @ wc)
        norm = math.sqrt(max(sv * sw, 1e-300))
        corr = float(vc @ wc) / norm
        jv, jw = self.j_v - self.j_v.mean(axis=0), self.j_w - self.j_w.mean(axis=0)
        d_corr = (wc @ jv + vc @ jw) / norm - corr * ((vc @ jv) / max(sv, 1e-300) + (wc @ jw) / max(sw, 1e-300))
        rows.append((-np.sign(corr) / CORRELATION * d_corr)[None, :])
        return np.vstack(rows)
