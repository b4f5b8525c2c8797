"""The paper's virtual prototype (Sec. 4-5) as a fast, seeded closed-loop simulator.

A differential-drive robot with the TRUE parameters tracks a reference trajectory under a
Fierro & Lewis (1995) backstepping controller that only knows the NOMINAL parameters; the log it
produces is what the identification in the rest of wmrid consumes, and ``SimulatedLog.truth()``
is what it should find.

Conventions (the paper's, SI units): eta = [eta_1, eta_2] = [right, left] wheel angular velocity
(rad/s), tau = [tau_1, tau_2] wheel torque (N m), pose (x m, y m, phi rad) of the axle midpoint O.

Plant (true parameters, Eqs. 7, 9)::

    x' = r/2 (eta_1 + eta_2) cos phi,  y' = r/2 (eta_1 + eta_2) sin phi,  phi' = r/(2b) (eta_1 - eta_2)
    theta' = eta
    M eta' + V(eta) + F_v eta + F_d sgn(eta) + tau_d = tau          (sgn(0) = 0)

integrated with classical RK4, ``substeps`` steps per control period, torque tau and caster
disturbance tau_d held constant over each control period (zero-order hold).

Controller, every control period T (1 ms, the paper's sampling time; 1/rate when rate > 1 kHz), on the
TRUE state (measurement noise only enters the log):

* tracking error in the robot frame, e = R(phi)^T (q_r - q), e3 = wrap(phi_r - phi) in [-pi, pi);
* kinematic control (Fierro & Lewis 1995, Eq. 12)::

      v_c = v_r cos e3 + k1 e1
      w_c = w_r + k2 v_r e2 + k3 |v_r| sin e3

  With v_r >= 0 (the ``sinusoid``) this is exactly Fierro & Lewis' law; ``|v_r|`` in the last term keeps
  the Lyapunov derivative -k1 e1^2 - (k3/k2) |v_r| sin^2 e3 non-positive when the reference drives
  backwards (``reversing``), where the textbook law would be unstable in e3.
* wheel-speed references with the NOMINAL r, b: eta_c = [(v_c + b w_c)/r, (v_c - b w_c)/r];
* eta_c' ANALYTICALLY: v_c', w_c' by the chain rule with the reference's v_r', w_r' and the error
  dynamics e1' = w e2 - v + v_r cos e3, e2' = -w e1 + v_r sin e3, e3' = w_r - w, where (v, w) are computed
  from the measured eta with the nominal r, b (no backward difference, so no start-up transient);
* computed torque with the NOMINAL parameters (including the nominal friction, 0 for the paper robot)::

      tau = M_nom (eta_c' + K (eta_c - eta)) + V_nom(eta) + F_v,nom eta + F_d,nom sgn(eta)

Gains (:data:`GAINS`): k1 = 3 1/s, k2 = 25 1/m^2, k3 = 10 1/m (linearised lateral error dynamics
s^2 + k3 v_r s + k2 v_r^2: critically damped, natural frequency 5 v_r rad/s), K = 50 1/s (wheel-speed
loop, a 20 ms time constant, well above the kinematic loop and well below the 1 kHz control rate).

Trajectories (:data:`TRAJECTORY_PARAMETERS`), both start at the origin with the robot ON the
reference and its wheel speeds equal to the reference's (computed with the TRUE r, b):

* ``sinusoid`` (the paper's Fig. 5): the path y = A sin(2 pi x / lambda) travelled with a forward speed
  x'(t) = v0 + dv sin(2 pi t / P), i.e. x_r(t) = v0 t + dv P / (2 pi) (1 - cos(2 pi t / P)); with
  A = 0.5 m, lambda = 3 m, v0 = 0.5 m/s, dv = 0.3 m/s, P = 7 s the curvature reaches 2.19 1/m
  (b kappa = 0.50) so the wheels differ by up to a factor 3, both stay strictly positive (about
  0.8 rad/s at the slowest, on the default paper robot), and speed, turning rate and both
  accelerations vary on two incommensurate periods (P and lambda / v0 = 6 s): all 7 columns of Eq. (25)
  are excited.  phi_r = atan2(y_r', x_r'); v_r, w_r and their derivatives are closed-form.
* ``reversing``: v_r(t) = V sin(2 pi t / P_v), w_r(t) = W sin(2 pi t / P_w) with V = 0.4 m/s,
  P_v = 6 s, W = 0.8 rad/s, P_w = 4.3 s; |b w_r| <= 0.18 m/s < V, so both wheels reverse near every zero
  of v_r (twice per 6 s).  phi_r(t) = W P_w / (2 pi) (1 - cos(2 pi t / P_w)) is closed-form; x_r, y_r
  are the integrals of v_r cos phi_r, v_r sin phi_r, integrated in the kernel by RK4 (Simpson's rule,
  since the integrand depends on t only) on the plant's substep grid (error far below 1e-9 m).

A reference drive given as samples (t, v, omega) -- ``simulate --reference plan.csv``, e.g. a plan of ``wmrid plan``
-- is trajectory kind 2: ``settings["trajectory"]`` is ``"reference"`` and ``settings["trajectory_parameters"]`` its
file, SHA-256, samples and duration; the kernel looks the reference state up in a table on the control grid built
from cubic splines of v and omega (:mod:`wmrid.sim.reference`, which states the interpolation and integration
errors).  It starts at the origin facing +x, the robot on it with its speeds (at rest when v(0) = omega(0) = 0); the
run lasts the reference's length unless a shorter duration is given.

Noise (:class:`NoiseSettings`): a ``numpy.random.Generator(PCG64(seed))`` draws, in this order and
always (so each stream depends on the seed and sizes only), standard normals for the velocity noise
(n, 2), the torque noise (n, 2) and the caster innovations (n_ctrl, 2).  The caster disturbance tau_d
is an Ornstein-Uhlenbeck process per wheel, sampled exactly on the control grid
(d_{k+1} = a d_k + sigma sqrt(1 - a^2) z_{k+1}, a = exp(-T / caster_time), d_0 = sigma z_0, so it is
stationary from t = 0) and held over each control period; it enters the plant only.

Plant change (:class:`PlantChange`, optional): the plant's parameters switch once during the run, from
``change.before`` (= ``true``) to ``change.after`` -- a payload loaded or dropped, a wheel's friction
multiplied by a factor.  Rule: the switch happens at the start of control period k_s, the first one whose
start time k T is >= the requested time t_c, i.e. k_s = ceil(t_c / T) (t_c / T within 1e-9 of a whole
number counts as that number, so a t_c on the control grid switches exactly there); the plant integrates
[k T, (k + 1) T] with ``before`` for k < k_s and with ``after`` for k >= k_s.  The state (and so every
logged value) at t <= k_s T is bit for bit that of the run without the change; the controller keeps its
NOMINAL parameters throughout, and the random streams are drawn as without a change.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import TYPE_CHECKING

import numpy as np

from wmrid.core.choices import Trajectory, values
from wmrid.core.errors import UsageError, option
from wmrid.core.wheel_log import WheelLog
from wmrid.model import dynamics as model
from wmrid.model.robot import PhysicalParameters

if TYPE_CHECKING:
    import pandas
from wmrid.runtime.limits import ENV, describe, memory_budget
from wmrid.sim.closed_loop import KIND, check_finite, closed_loop_kernel, reference_wheel_speeds
from wmrid.sim.reference import TABLE_BYTES_PER_CONTROL_STEP, Reference, pack_table, reference_table
from wmrid.sim.scenario import NoiseSettings, PlantChange, check_seed, positive_number

#: Control period used whenever the log rate is at most 1 kHz (the paper's sampling time), s.
CONTROL_PERIOD = 1e-3


#: Names of the built-in reference trajectories.
TRAJECTORIES = values(Trajectory)
#: The trajectory name of a run that tracks a given reference (:class:`wmrid.sim.reference.Reference`).
REFERENCE = "reference"
#: Duration of a run on a built-in trajectory when none is given, s.
DEFAULT_DURATION = 40.0


#: Parameters of each trajectory (SI units); see the module docstring for the formulas.
TRAJECTORY_PARAMETERS: dict[str, dict[str, float]] = {
    "sinusoid": {"A": 0.5, "wavelength": 3.0, "v0": 0.5, "dv": 0.3, "speed_period": 7.0},
    "reversing": {"V": 0.4, "v_period": 6.0, "W": 0.8, "w_period": 4.3},
}


#: Controller gains: k1 (1/s), k2 (1/m^2), k3 (1/m) kinematic; K (1/s) wheel-speed loop.
GAINS: dict[str, float] = {"k1": 3.0, "k2": 25.0, "k3": 10.0, "K": 50.0}


@dataclass(frozen=True, eq=False)
class SimulatedLog:
    """A simulated log (read-only arrays) with the truth it was generated from.

    t : (n,) s, starting at 0, spacing 1/rate.
    eta : (n, 2) rad/s, logged wheel velocities [right, left] (with noise / quantisation).
    tau : (n, 2) N m, logged torques: the torque applied over the control period starting at t (with noise).
    pose : (n, 3) true x (m), y (m), phi (rad, unwrapped) of the axle midpoint.
    wheel_angle : (n, 2) rad, true wheel angles theta [right, left], 0 at t = 0.
    true, nominal : the plant's parameters (at t = 0, before any change) and the controller's.
    settings : everything needed to reproduce the run (JSON-serialisable); with a plant change, its ``"change"``
        entry holds kind, requested time t, actual switch time t_switch (s) and control period switch_period, the
        base parameters ``before`` and ``after`` (as ``truth()["parameters"]``), the physical sets
        ``physical_before`` and ``physical_after``, and the change's detail (payload, or wheel, factor, terms,
        parameters).
    reference : (n, 3) reference pose x_r (m), y_r (m), phi_r (rad) at t.
    eta_ref : (n, 2) rad/s, the reference's wheel speeds [right, left] at t: (v_r +/- b w_r) / r with the NOMINAL
        r, b -- the wheel-speed set-points a planner would send (uncorrelated with the disturbance), logged as
        eta_ref_r, eta_ref_l (the instruments of ``identify --method iv``, :mod:`wmrid.estimators.regression.iv`).
    disturbance : (n, 2) N m, caster torque tau_d applied over the control period starting at t (unlogged in a
        real log; kept for tests and diagnostics).
    eta_true : (n, 2) rad/s, true wheel velocities at t (the clean counterpart of ``eta``).
    change : the plant change of the run, or None.
    caster_load : (n, K) N, each caster's normal force at t (multibody only, else None; mean: ``mean_normal_load``).
    """

    t: np.ndarray
    eta: np.ndarray
    tau: np.ndarray
    pose: np.ndarray
    wheel_angle: np.ndarray
    true: PhysicalParameters
    nominal: PhysicalParameters
    settings: dict
    reference: np.ndarray = field(repr=False, default=None)  # type: ignore[assignment]
    disturbance: np.ndarray = field(repr=False, default=None)  # type: ignore[assignment]
    eta_true: np.ndarray = field(repr=False, default=None)  # type: ignore[assignment]
    change: PlantChange | None = field(repr=False, default=None)
    eta_ref: np.ndarray = field(repr=False, default=None)  # type: ignore[assignment]
    caster_load: np.ndarray | None = field(repr=False, default=None)

    def plant_at(self, t: float) -> PhysicalParameters:
        """The plant's parameters over the control period starting at t (s): ``true`` before the switch time,
        the change's ``after`` from it on."""
        if self.change is None:
            return self.true
        t_switch = self.settings["change"]["t_switch"]
        return self.change.after if t >= t_switch - 1e-9 * self.settings["control_period"] else self.true

    def to_wheel_log(self, source: str = "simulation") -> WheelLog:
        """The log as an identification sees it: t, eta, tau, the pose and, as the wheel-speed reference, the
        reference's wheel speeds :attr:`eta_ref` (not the reference pose)."""
        return WheelLog(
            t=self.t, eta=self.eta, tau=self.tau, source=source, pose=self.pose,
            reference=self.eta_ref,
        )  # fmt: skip

    def to_frame(self) -> pandas.DataFrame:
        """Columns t, eta_r, eta_l, tau_r, tau_l, x, y, phi, theta_r, theta_l, eta_ref_r, eta_ref_l (SI units;
        r = right; the last two: the reference's wheel speeds, :attr:`eta_ref`)."""
        import pandas as pd  # pandas (~0.2 s): only a run written as a table

        return pd.DataFrame(
            {
                "t": self.t,
                "eta_r": self.eta[:, 0],
                "eta_l": self.eta[:, 1],
                "tau_r": self.tau[:, 0],
                "tau_l": self.tau[:, 1],
                "x": self.pose[:, 0],
                "y": self.pose[:, 1],
                "phi": self.pose[:, 2],
                "theta_r": self.wheel_angle[:, 0],
                "theta_l": self.wheel_angle[:, 1],
                "eta_ref_r": self.eta_ref[:, 0],
                "eta_ref_l": self.eta_ref[:, 1],
            }
        )

    def truth(self) -> dict:
        """The true base parameters (m11, m12, m22, Vc, Fv1, Fv2, Fd1, Fd2, M11, M12, M22), inputs, settings."""
        return {
            "parameters": model.named_base(model.base_parameters(self.true)),
            "physical": self.true.to_dict(),
            "nominal_physical": self.nominal.to_dict(),
            "settings": self.settings,
        }


def timing(rate: float) -> tuple[float, int]:
    """(control period T in s, control periods per log period N) for a log rate in Hz.

    T = 1 ms (the paper's sampling time) for rate <= 1 kHz, else 1/rate.  Raises UsageError unless
    N = (1/rate)/T is a whole number.
    """
    rate = positive_number("rate", rate)
    if rate > 1.0 / CONTROL_PERIOD:
        return 1.0 / rate, 1
    ratio = (1.0 / rate) / CONTROL_PERIOD
    every = round(ratio)
    if every < 1 or abs(ratio - every) > 1e-9 * ratio:
        raise UsageError(
            f"rate {rate:g} Hz: the log period 1/rate must be a whole number of {CONTROL_PERIOD * 1e3:g} ms "
            f"control periods (e.g. 1000, 500, 250, 200, 100 Hz), or the rate must exceed 1000 Hz"
        )
    return CONTROL_PERIOD, int(every)


def _plant_vector(p: PhysicalParameters) -> np.ndarray:
    """The kernel's plant vector [m11, m12, m22, Vc, Fv1, Fv2, Fd1, Fd2, r, b] of parameters p."""
    theta = model.base_parameters(p)
    m = model.inverse_inertia(theta)
    return np.array([m[0, 0], m[0, 1], m[1, 1], *theta[3:8], p.r, p.b])


def _encoder_velocity(theta: np.ndarray, eta: np.ndarray, cpr: int, dt: float) -> np.ndarray:
    """Velocity (n, 2) rad/s an encoder driver reports: difference of quantised angles over one log period.

    theta (n, 2) rad, eta (n, 2) rad/s true; the count is floor(theta / (2 pi / cpr)).  Before t = 0
    the wheel is taken to turn at its initial speed, so theta(-dt) = theta(0) - dt eta(0).
    """
    step = 2.0 * math.pi / cpr
    counts = np.floor(theta / step)
    before = np.floor((theta[0] - dt * eta[0]) / step)
    diff = np.diff(counts, axis=0, prepend=before[None, :])
    return diff * (step / dt)


#: Noise-free sensors: the default of :func:`simulate`.
NO_NOISE = NoiseSettings()


def simulate(
    true: PhysicalParameters,
    nominal: PhysicalParameters,
    *,
    trajectory: str | None = None,
    duration: float | None = None,
    rate: float = 1000.0,
    noise: NoiseSettings = NO_NOISE,
    seed: int | None = None,
    substeps: int = 4,
    change: PlantChange | None = None,
    reference: Reference | None = None,
) -> SimulatedLog:
    """Simulate the closed loop and return its log.

    true : plant parameters (at t = 0); nominal : what the controller believes.
    trajectory : one of :data:`TRAJECTORIES` (None: ``sinusoid``); or ``reference`` (also what None means with a
    ``reference``): track ``reference``, samples of v and omega (:mod:`wmrid.sim.reference`), from its first sample
    at the origin facing +x. duration : s (> 0; None: :data:`DEFAULT_DURATION`, or the reference's length, which a
    duration may not exceed); the log has n = floor(duration * rate) + 1 samples at t = 0, 1/rate, ... rate : log
    rate in Hz (see :func:`timing`). noise : see :class:`NoiseSettings`. seed : non-negative int for
    ``numpy.random.PCG64`` (None: ``noise.seed``); same seed, same output bit for bit. substeps : RK4 steps per
    control period (>= 1).
    change : a :class:`PlantChange` whose ``before`` is ``true``, switching the plant to ``change.after`` at the
    first control period starting at or after ``change.t``, which must come before the last sample; None (default):
    no change, and the output is exactly that of a simulator without this option.
    """
    if not isinstance(true, PhysicalParameters):
        raise UsageError("true and nominal must be PhysicalParameters")
    if isinstance(substeps, bool) or not isinstance(substeps, (int, np.integer)) or substeps < 1:
        raise UsageError(f"substeps must be a whole number >= 1, got {substeps!r}")
    run = plan_run(
        nominal, trajectory=trajectory, duration=duration, rate=rate, noise=noise, seed=seed, reference=reference
    )
    period, every, n, n_ctrl = run.period, run.every, run.n, run.n_ctrl
    switch = -1
    if change is not None:
        if not isinstance(change, PlantChange):
            raise UsageError(f"change must be a PlantChange, got {type(change).__name__}")
        if change.before != true:
            raise UsageError("change.before must be the plant's parameters at t = 0 (the argument true)")
        switch = change.switch_period(period)
        if switch < 1 or switch >= n_ctrl - 1:
            raise UsageError(
                f"change time {change.t:g} s: the plant would switch at {switch * period:g} s (the first control "
                f"period starting at or after it), which must come after 0 and before the last sample at "
                f"{(n_ctrl - 1) * period:g} s"
            )
    plant = _plant_vector(true)
    traj, ctrl, gains, caster_z = run.traj, run.ctrl, run.gains, run.caster_z

    args = (KIND[run.trajectory], traj, plant, ctrl, gains, period, int(substeps), n, every, caster_z,
            noise.caster_std, noise.caster_time)  # fmt: skip
    if change is None:
        pose, angle, eta_true, tau_applied, refpose, dist = closed_loop_kernel(*args)
    else:
        pose, angle, eta_true, tau_applied, refpose, dist = closed_loop_kernel(
            *args, _plant_vector(change.after), switch
        )

    check_finite(eta_true, tau_applied, period * every)
    return run.log(true, pose, angle, eta_true, tau_applied, refpose, dist, {"substeps": int(substeps)}, change)


@dataclass(frozen=True, eq=False)
class RunPlan:
    """What every closed-loop simulator of wmrid shares: the checked run settings, the random streams and the
    controller's vectors (see :func:`plan_run`), and the assembly of the log (:meth:`log`).

    period : control period T, s; every : control periods per log period; n : log samples; n_ctrl : control
    periods; eta_z, tau_z (n, 2) and caster_z (n_ctrl, 2): standard normals, drawn in that order from
    PCG64(seed); traj, ctrl (10,), gains (4,): the kernel's reference, NOMINAL controller and gain vectors;
    trajectory_parameters: what the settings record of the trajectory (a reference's file, sha256, samples).
    """

    nominal: PhysicalParameters
    trajectory: str
    duration: float
    rate: float
    noise: NoiseSettings
    seed: int
    period: float
    every: int
    n: int
    n_ctrl: int
    eta_z: np.ndarray
    tau_z: np.ndarray
    caster_z: np.ndarray
    traj: np.ndarray
    ctrl: np.ndarray
    gains: np.ndarray
    trajectory_parameters: dict = field(default_factory=dict)

    def log(
        self, true: PhysicalParameters, pose: np.ndarray, angle: np.ndarray, eta_true: np.ndarray,
        tau_applied: np.ndarray, refpose: np.ndarray, dist: np.ndarray, extra: dict, change: PlantChange | None,
    ) -> SimulatedLog:  # fmt: skip
        """The SimulatedLog of a run: encoder quantisation and noise on the logged speeds and torques, the
        settings (``extra`` merged in), read-only arrays."""
        noise = self.noise
        dt = self.every * self.period
        cpr = noise.encoder_cpr
        eta_meas = _encoder_velocity(angle, eta_true, cpr, dt) if cpr > 0 else eta_true.copy()
        eta_log = eta_meas + noise.eta_std * self.eta_z
        tau_log = tau_applied + noise.tau_std * self.tau_z
        t = np.arange(self.n) * dt
        settings = {
            "trajectory": self.trajectory,
            "trajectory_parameters": dict(self.trajectory_parameters),
            "duration": self.duration,
            "rate": self.rate,
            "control_period": self.period,
            "substeps": None,
            "n_samples": self.n,
            "seed": self.seed,
            "generator": "numpy PCG64",
            "noise": noise.to_dict(),
            "gains": dict(GAINS),
            **extra,
        }
        if change is not None:
            settings["change"] = change.to_dict(self.period)
        eta_ref = reference_wheel_speeds(KIND[self.trajectory], self.traj, t, self.nominal.r, self.nominal.b)
        for a in (t, eta_log, tau_log, pose, angle, refpose, dist, eta_true, eta_ref):
            a.setflags(write=False)
        return SimulatedLog(
            t=t, eta=eta_log, tau=tau_log, pose=pose, wheel_angle=angle, true=true, nominal=self.nominal,
            settings=settings, reference=refpose, disturbance=dist, eta_true=eta_true, change=change, eta_ref=eta_ref,
        )  # fmt: skip


#: Bytes a simulated run holds per logged sample (the log's 12 columns, the noise draws, the controller's state and
#: the writer's copies; measured for `simulate --duration 600`: 820 B written as CSV, 600 B as Parquet) and per
#: control step (the caster draws).
BYTES_PER_SAMPLE = 900


BYTES_PER_CONTROL_STEP = 32


def check_run_memory(
    n: int, n_ctrl: int, duration: float, rate: float, per_control_step: int = BYTES_PER_CONTROL_STEP
) -> None:
    """UsageError before anything is allocated when a run of n samples (n_ctrl control steps, ``per_control_step``
    bytes each) would need more than the memory budget (:mod:`wmrid.runtime.limits`): ``simulate --duration 1e9`` used
    to die of "Unable to allocate 14.6 TiB"."""
    need = n * BYTES_PER_SAMPLE + n_ctrl * per_control_step
    budget = memory_budget()
    if need > budget:
        longest = budget / (BYTES_PER_SAMPLE + per_control_step * n_ctrl / max(n, 1)) / rate
        raise UsageError(
            f"{option('duration')} {duration:g} s at {rate:g} Hz is {n:,} samples, about {describe(need)} of memory, "
            "beyond the "
            f"budget of {describe(budget)} ({ENV}); simulate at most {longest:,.0f} s at this rate, in several runs"
        )


def _run_trajectory(trajectory: str | None, duration: float | None, reference: Reference | None) -> tuple[str, float]:
    """(trajectory name, duration s) of a run, checked: a built-in name or a reference, not both; a duration that
    the reference covers."""
    if reference is None:
        name = "sinusoid" if trajectory is None else trajectory
        if name == REFERENCE:
            raise UsageError(f"trajectory {REFERENCE!r} needs {option('reference')} (the file or samples to track)")
        if name not in TRAJECTORIES:
            raise UsageError(f"unknown trajectory {name!r}; choose one of {', '.join(TRAJECTORIES)}")
        return name, plan_duration(duration)
    if not isinstance(reference, Reference):
        raise UsageError(f"reference must be a wmrid.sim.reference.Reference, got {type(reference).__name__}")
    if trajectory not in (None, REFERENCE):
        raise UsageError(
            f"{option('reference')} and {option('trajectory', trajectory)}: the run tracks one reference; give one "
            "of them"
        )
    return REFERENCE, plan_duration(duration, reference)


def plan_duration(duration: float | None, reference: Reference | None = None) -> float:
    """The duration (s) of a run: ``duration`` checked (> 0, and with a ``reference`` at most its length), or when
    None :data:`DEFAULT_DURATION` (the whole reference with one)."""
    if reference is None:
        return positive_number("duration", DEFAULT_DURATION if duration is None else duration)
    longest = reference.duration
    if duration is None:
        return longest
    duration = positive_number("duration", duration)
    if duration > longest + 1e-9 * max(1.0, longest):
        where = f"the reference {reference.source}" if reference.source else "the reference"
        raise UsageError(
            f"{option('duration')} {duration:g} s is longer than {where} ({longest:g} s); give at most "
            f"{longest:g} s, or leave the duration out to run the whole reference"
        )
    return duration


def plan_run(
    nominal: PhysicalParameters, *, trajectory: str | None, duration: float | None, rate: float,
    noise: NoiseSettings, seed: int | None = None, reference: Reference | None = None,
) -> RunPlan:  # fmt: skip
    """Check a run's settings (UsageError naming the bad one) and draw its random streams; see :class:`RunPlan`.

    trajectory : a built-in name (None: ``sinusoid``), or None / ``reference`` with a ``reference`` to track, whose
    table on the control grid becomes the kernel's ``traj``.  duration : s; None: :data:`DEFAULT_DURATION`, or the
    reference's length (which a duration may not exceed)."""
    trajectory, duration = _run_trajectory(trajectory, duration, reference)
    if not isinstance(nominal, PhysicalParameters):
        raise UsageError("true and nominal must be PhysicalParameters")
    if not isinstance(noise, NoiseSettings):
        raise UsageError(f"noise must be a NoiseSettings, got {type(noise).__name__}")
    period, every = timing(rate)
    rate = float(rate)
    seed = noise.seed if seed is None else seed
    check_seed(seed)
    n = math.floor(duration * rate + 1e-9) + 1
    if n < 2:
        raise UsageError(f"duration {duration:g} s at {rate:g} Hz gives fewer than 2 samples")
    n_ctrl = (n - 1) * every + 1
    per_step = BYTES_PER_CONTROL_STEP + (TABLE_BYTES_PER_CONTROL_STEP if reference is not None else 0)
    check_run_memory(n, n_ctrl, duration, rate, per_step)
    rng = np.random.Generator(np.random.PCG64(int(seed)))
    eta_z = rng.standard_normal((n, 2))
    tau_z = rng.standard_normal((n, 2))
    caster_z = rng.standard_normal((n_ctrl, 2))
    if reference is None:
        described = dict(TRAJECTORY_PARAMETERS[trajectory])
        traj = np.array(list(described.values()), dtype=np.float64)
    else:
        described = reference.describe()
        traj = pack_table(reference_table(reference, period, n_ctrl), period)
    big_nom = model.inertia_matrix(nominal)
    ctrl = np.array(
        [big_nom[0, 0], big_nom[0, 1], big_nom[1, 1], model.coriolis_coefficient(nominal),
         nominal.F_v1, nominal.F_v2, nominal.F_d1, nominal.F_d2, nominal.r, nominal.b]
    )  # fmt: skip
    gains = np.array([GAINS["k1"], GAINS["k2"], GAINS["k3"], GAINS["K"]])
    return RunPlan(
        nominal=nominal, trajectory=trajectory, duration=duration, rate=rate, noise=noise, seed=int(seed),
        period=period, every=every, n=n, n_ctrl=n_ctrl, eta_z=eta_z, tau_z=tau_z, caster_z=caster_z, traj=traj,
        ctrl=ctrl, gains=gains, trajectory_parameters=described,
    )  # fmt: skip
