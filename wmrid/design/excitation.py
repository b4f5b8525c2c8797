"""The planned reference: forward speed v(t) (m/s) and turn rate w(t) (rad/s) as band-limited periodic series.

Each channel is a Fourier series on the base period P (the plan's duration divided into whole periods, Swevers et
al. 1997, FloBaRoID), multiplied by a ramp that brings the robot from rest and back to rest::

    v(t) = s(t) sum_{n=1..N} (a_n sin(2 pi n t / P) + b_n (cos(2 pi n t / P) - 1))
    s(t) = ramp(t / T_r) ramp((T - t) / T_r),   ramp(x) = x^3 (10 - 15 x + 6 x^2) for x in [0, 1], 1 beyond

The series has no mean term, so the platform's speed averages out over a period; the ``cos - 1`` form makes each
term vanish at t = 0.  The quintic ramp has zero first and second derivative at its ends, so v, v' and v'' are
all 0 at t = 0 and at t = T: the robot starts and stops at rest, with no step in acceleration or jerk.

Everything here is closed form: v, v' from the series and the ramp by the product rule; the wheel speeds
eta = [(v + b w) / r, (v - b w) / r] and their derivatives; the pose by integrating phi' = w, x' = v cos phi,
y' = v sin phi by the trapezoid rule on the evaluation grid (:func:`pose_along`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Default length of the ramps from and back to rest, s.
RAMP_SECONDS = 2.0


def ramp(x: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(s, ds/dx) of the quintic smoothstep s = x^3 (10 - 15 x + 6 x^2), clipped to [0, 1] outside x in [0, 1]."""
    x = np.clip(x, 0.0, 1.0)
    s = x**3 * (10.0 - 15.0 * x + 6.0 * x * x)
    ds = 30.0 * x * x * (1.0 - x) ** 2
    return s, ds


@dataclass(frozen=True)
class Excitation:
    """A two-channel band-limited reference (see the module docstring).

    duration : T, s.  period : P, s (T is a whole number of periods).  coefficients : (2, N, 2): channel (0: v in
    m/s, 1: w in rad/s), harmonic n = 1..N, (a_n, b_n).  ramp : T_r, s.
    """

    duration: float
    period: float
    coefficients: np.ndarray
    ramp: float = RAMP_SECONDS

    def __post_init__(self) -> None:
        coef = np.array(self.coefficients, dtype=np.float64)
        if coef.ndim != 3 or coef.shape[0] != 2 or coef.shape[2] != 2:
            raise ValueError(f"coefficients must have shape (2, N, 2), got {coef.shape}")
        coef.setflags(write=False)
        object.__setattr__(self, "coefficients", coef)

    @property
    def harmonics(self) -> int:
        return self.coefficients.shape[1]

    def evaluate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(v m/s, w rad/s, v' m/s^2, w' rad/s^2), each (n,), at times t (n,) s."""
        basis = Basis(np.asarray(t, dtype=np.float64), self.duration, self.period, self.harmonics, self.ramp)
        return basis.signals(self.coefficients)

    def to_dict(self) -> dict:
        return {
            "duration": self.duration, "period": self.period, "ramp": self.ramp,
            "harmonics": self.harmonics, "coefficients": self.coefficients.tolist(),
        }  # fmt: skip

    @classmethod
    def from_dict(cls, data: dict) -> Excitation:
        return cls(float(data["duration"]), float(data["period"]), np.array(data["coefficients"]), float(data["ramp"]))


class Basis:
    """The series' basis on a fixed grid, so that many coefficient sets are evaluated by two matrix products.

    t : (n,) s.  ``phi`` (n, 2N): sin and cos - 1 of each harmonic; ``dphi`` their time derivatives;
    ``s``, ``ds`` (n,): the ramp and its derivative.
    """

    def __init__(self, t: np.ndarray, duration: float, period: float, harmonics: int, ramp_s: float) -> None:
        self.t = t
        omega = 2.0 * math.pi / period * np.arange(1, harmonics + 1)
        arg = np.outer(t, omega)
        sin, cos = np.sin(arg), np.cos(arg)
        self.phi = np.concatenate([sin, cos - 1.0], axis=1)
        self.dphi = np.concatenate([cos * omega, -sin * omega], axis=1)
        up, dup = ramp(t / ramp_s)
        down, ddown = ramp((duration - t) / ramp_s)
        self.s = up * down
        self.ds = dup / ramp_s * down - up * ddown / ramp_s

    def signals(self, coefficients: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(v, w, v', w') (n,) each for coefficients (2, N, 2)."""
        flat = np.concatenate([coefficients[:, :, 0], coefficients[:, :, 1]], axis=1)  # (2, 2N): a then b
        series = self.phi @ flat.T  # (n, 2)
        dseries = self.dphi @ flat.T
        value = self.s[:, None] * series
        slope = self.ds[:, None] * series + self.s[:, None] * dseries
        return value[:, 0], value[:, 1], slope[:, 0], slope[:, 1]


def wheel_motion(
    v: np.ndarray, w: np.ndarray, dv: np.ndarray, dw: np.ndarray, r: float, b: float
) -> tuple[np.ndarray, np.ndarray]:
    """(eta (n, 2) rad/s, eta' (n, 2) rad/s^2) of the wheels [right, left] for platform speed v (m/s), turn rate w
    (rad/s) and their derivatives: eta = [(v + b w) / r, (v - b w) / r] (wheel radius r, half track b, m)."""
    eta = np.stack([(v + b * w) / r, (v - b * w) / r], axis=1)
    deta = np.stack([(dv + b * dw) / r, (dv - b * dw) / r], axis=1)
    return eta, deta


def pose_along(t: np.ndarray, v: np.ndarray, w: np.ndarray) -> np.ndarray:
    """The pose (n, 3): x (m), y (m), phi (rad) of the axle midpoint along v (m/s), w (rad/s) sampled at the evenly
    spaced t (n,) s, starting at the origin facing +x: phi by the trapezoid rule (w is smooth), x and y by the
    trapezoid rule on v cos phi, v sin phi (second order in the step; a 50 Hz grid errs by under 1 mm over a
    minute of a plan's motions, checked against a 1 kHz grid in the tests)."""
    h = np.diff(t)
    phi = np.concatenate([[0.0], np.cumsum(0.5 * h * (w[1:] + w[:-1]))])
    vx, vy = v * np.cos(phi), v * np.sin(phi)
    x = np.concatenate([[0.0], np.cumsum(0.5 * h * (vx[1:] + vx[:-1]))])
    y = np.concatenate([[0.0], np.cumsum(0.5 * h * (vy[1:] + vy[:-1]))])
    return np.stack([x, y, phi], axis=1)
