"""The validation predictor: the model's wheel speeds simulated from the measured torques.

Given the logged torques tau (n, 2) N m and base parameters theta0 (see :mod:`wmrid.model.dynamics`), integrate
the direct model (Eq. 20, no disturbance)::

    eta_dot = m (tau - V(eta) - F_v eta - F_d sgn(eta)),   m = M^-1

from the log's first measured speed, open loop: the simulated speed never sees the measured one again.
Comparing it with the measured speed (:func:`fit_percent`, MATLAB ``compare``'s NRMSE fit) is the usual
validation of an identified model, and minimising the difference is the output-error method
(:mod:`wmrid.estimators.output_error`).

Torque between samples (``torque_hold``): ``"zoh"`` holds tau[k] over [t_k, t_k+1) (a digital
controller's command; the simulator's convention), ``"foh"`` interpolates linearly from tau[k] to
tau[k+1] (a measured, continuous effort).  Same meaning as the observer's option.

Integration: classical RK4 with a fixed step, each sample interval split into
ceil((t_k+1 - t_k) / max_step) equal substeps (default max_step = 1 ms: one substep at 1 kHz, ten at
100 Hz; uneven logs are fine).  Sample times are substep boundaries, so the torque is smooth within
every step and RK4 keeps its fourth order.  The wheel dynamics are slow against 1 ms (rates m F_v and
m V_c eta of 0.01-1 1/s for the paper's robot; the local error goes as (rate h)^5): on the paper
robot over 5 s the speeds at h = 1 ms differ from those at h = 0.01 ms by 2e-13 rad/s, and by 5e-11
rad/s at h = 10 ms.  A robot with much faster wheel dynamics (rate h > 0.1) wants a smaller max_step.

Coulomb friction at zero speed (the one discontinuity): the friction is set-valued at eta_j = 0, as
in the standard (stiction-free) Coulomb model: a wheel at rest stays at rest while the friction torque
needed to hold it, |f_j| <= F_dj, and otherwise starts to turn in the direction of the net torque.
Concretely:

* within a step each wheel has a fixed mode, s_j = +1 or -1 (turning; friction F_dj s_j) or 0 (at
  rest; eta_j' = 0 and f_j whatever holds it), so RK4 integrates a smooth vector field;
* a turning wheel whose speed would cross zero within a step: the crossing instant is located (regula
  falsi on the RK4 step length, to ~1e-12 of the step), the step is cut there, the speed set to exactly
  0, and the rest of the step continues in the mode chosen below;
* at zero speed the mode is the (unique, for positive definite M and F_d >= 0) consistent one of
  {rest, +1, -1} per wheel: rest if the holding friction f = F - M eta' (F = tau - V - F_v eta) is within
  [-F_d, F_d], else the direction of the resulting acceleration.  Breakaway is checked at step starts,
  so it can be late by at most one substep (where the excess torque is still ~0).

So a wheel that brakes through zero with |net torque| < F_d stops and stays stopped, and one pushed
harder reverses: neither smoothing of sgn nor chattering around zero.  For a log whose wheels never
reach zero (the paper's sinusoid) this is exactly Eq. (20).  With non-physical parameters (F_d < 0, or
m not positive definite) a consistent mode may not exist; the wheel then leaves zero with sgn(0) = 0.

Caster drag (``form``, the identified :class:`wmrid.model.dynamics.RegressorForm`): with the geometric model (the
casters' positions known) theta0 has form.n_base entries, the drag forces D_k last, and the drag's wheel
torques (:func:`wmrid.model.torques.friction_torque`) join V and F_v eta in the integrated field.  The drag is smooth
in eta (its direction regularised by :data:`wmrid.model.dynamics.DRAG_SPEED`, 0 at eta = 0), so it adds no event: at
zero speed it is part of the known torque F the Coulomb friction must hold (F = tau - V - F_v eta - drag).
Without caster drag the kernel does exactly the arithmetic it did before (bit for bit).  The two-term model
(Cv sgn(eta_1 + eta_2), Cw sgn(eta_1 - eta_2), no positions) has switches of its own at eta_1 = +-eta_2 that
would need the same exact event treatment: it is refused (:class:`UsageError`) rather than smoothed silently.

Pure functions on numpy arrays; the loop is a numba kernel: 0.43 s (zoh) / 0.54 s (foh) for 3.6 M
samples, one hour at 1 kHz, after compilation (one core; 2 substeps per sample: 0.76 s).
"""

from __future__ import annotations

import math

import numpy as np

from wmrid.core.choices import TorqueHold, values
from wmrid.core.errors import UsageError
from wmrid.model.dynamics import RegressorForm
from wmrid.model.kernels import plain
from wmrid.model.predict_kernel import simulate_kernel

#: Default longest RK4 substep, s (one substep per sample at 1 kHz; see the module docstring).
MAX_STEP = 1e-3
#: The kernel's caster argument when the model has no caster drag.
NO_CASTERS = np.zeros(0)

PREDICTOR = (
    "wheel speeds simulated open loop from the measured torques ({hold}) by the identified model "
    "(Eq. 20, RK4, Coulomb friction holding a wheel at rest), starting at the log's first measured speed"
)


# --------------------------------------------------------------------------------------------------
# Compiled kernel.  th (8,) = theta0 = [m11, m12, m22, Vc, Fv1, Fv2, Fd1, Fd2]; a mode s_j is +1 / -1
# (wheel turning that way, friction Fd_j s_j) or 0 (wheel at rest, eta_j' = 0).


# --------------------------------------------------------------------------------------------------


def _check_hold(torque_hold: str) -> bool:
    if torque_hold not in values(TorqueHold):
        raise UsageError(f"torque_hold must be zoh or foh, got {torque_hold!r}")
    return torque_hold == "foh"


#: Refusal of the two-term caster model (no positions): its sgn(eta_1 +- eta_2) switches are not handled.
TWO_TERM_REFUSAL = (
    "--validate/oe model the caster drag only with the casters' positions ([[caster]] in the robot file); "
    "the two-term model (Cv, Cw) switches at eta_1 = -eta_2 and eta_1 = eta_2, which the predictor does not "
    "handle as events"
)


def unsimulated(form: RegressorForm | None) -> str | None:
    """Why the validation predictor cannot simulate a model of ``form`` (the two-term caster drag: see
    :func:`caster_array`), said in one sentence, or None when it can."""
    if form is not None and form.caster and not form.geometry:
        return (
            "no fit: the identified caster drag (Cv, Cw) cannot be simulated without the casters' positions; give "
            "a robot file with [[caster]] tables to validate it"
        )
    if form is not None and form.load:
        return LOAD_REFUSAL
    return None


#: Why the predictor does not simulate the ``wheel+caster+load`` model.
LOAD_REFUSAL = (
    "no fit: the predictor does not simulate a caster drag that follows the load (friction wheel+caster+load); "
    "identify with --friction wheel+caster to validate"
)


def caster_array(theta0: np.ndarray, form: RegressorForm | None) -> np.ndarray:
    """The kernel's caster argument for base parameters theta0 of model ``form``.

    [r, b, x_1, y_1, D_1, ..., x_K, y_K, D_K] for the geometric caster model (form.geometry and
    theta0[8:] = D_1..D_K); :data:`NO_CASTERS` (empty) without caster drag (form None or form.caster
    False).  The two-term model (caster drag without positions) raises :class:`UsageError`: its Coulomb-like
    switches at eta_1 = +-eta_2 would need exact event handling the predictor does not do, and smoothing them
    would be a silent approximation.
    """
    if form is None or not form.caster:
        return NO_CASTERS
    if not form.geometry:
        raise UsageError(TWO_TERM_REFUSAL)
    if form.load:
        raise UsageError(LOAD_REFUSAL)
    geo = form.geometry
    cas = [geo[0], geo[1]]
    for k in range(form.n_casters):
        cas += [geo[2 + 2 * k], geo[3 + 2 * k], float(theta0[8 + k])]
    return np.array(cas, dtype=float)


def predictor_text(torque_hold: str, form: RegressorForm | None = None) -> str:
    """One sentence naming the predictor (:data:`PREDICTOR`, plus the casters' drag when the model has it)."""
    text = PREDICTOR.format(hold=torque_hold)
    if form is not None and form.caster:
        text = text.replace("holding a wheel at rest)", "holding a wheel at rest, the casters' rolling drag)")
    return text


def _check_inputs(
    t: np.ndarray, tau: np.ndarray, theta0: np.ndarray, max_step: float, form: RegressorForm | None = None
) -> tuple[np.ndarray, ...]:
    """Checked (t, tau, theta0[:8], cas): the wheel part of theta0 and the kernel's caster argument."""
    t = plain(t)
    tau = plain(tau)
    theta0 = plain(theta0)
    if t.ndim != 1 or t.size < 1:
        raise UsageError(f"t must be a non-empty 1-D array, got shape {t.shape}")
    if tau.shape != (t.size, 2):
        raise UsageError(f"tau must have shape ({t.size}, 2), got {tau.shape}")
    n_base = 8 if form is None else form.n_base
    if theta0.shape != (n_base,):
        raise UsageError(f"theta0 must have shape ({n_base},), got {theta0.shape}")
    if not (np.all(np.isfinite(t)) and np.all(np.isfinite(tau)) and np.all(np.isfinite(theta0))):
        raise UsageError("t, tau and theta0 must be finite")
    if t.size > 1 and not np.all(np.diff(t) > 0):
        raise UsageError("t must be strictly increasing")
    if not (math.isfinite(max_step) and max_step > 0):
        raise UsageError(f"max_step must be a finite number > 0 (s), got {max_step}")
    cas = caster_array(theta0, form)
    return t, tau, np.ascontiguousarray(theta0[:8]), cas


def simulate_segments(
    t: np.ndarray,
    tau: np.ndarray,
    theta0: np.ndarray,
    eta: np.ndarray,
    starts: np.ndarray,
    *,
    torque_hold: str = "zoh",
    max_step: float = MAX_STEP,
    form: RegressorForm | None = None,
) -> np.ndarray:
    """Simulated speeds (n, 2) rad/s, restarted from the measured speed eta[s] at each index s of ``starts``.

    t (n,) s strictly increasing, tau (n, 2) N m, theta0 (form.n_base,) (8 without a form), eta (n, 2) rad/s
    measured speeds (only the rows in ``starts`` are read), starts (G,) increasing sample indices with
    starts[0] = 0.  Each segment [starts[g], starts[g+1]) is an independent open-loop simulation (the
    output-error method's multiple shooting); see :func:`simulate_speeds` for the integration and ``form``.
    """
    t, tau, theta0, cas = _check_inputs(t, tau, theta0, max_step, form)
    foh = _check_hold(torque_hold)
    starts = np.ascontiguousarray(starts, dtype=np.int64)
    if starts.ndim != 1 or starts.size < 1 or starts[0] != 0 or np.any(np.diff(starts) <= 0) or starts[-1] >= t.size:
        raise UsageError("starts must be increasing sample indices beginning at 0")
    eta = np.asarray(eta, dtype=float)
    if eta.shape != (t.size, 2):
        raise UsageError(f"eta must have shape ({t.size}, 2), got {eta.shape}")
    eta_start = np.ascontiguousarray(eta[starts])
    if not np.all(np.isfinite(eta_start)):
        raise UsageError("the measured speeds at the segment starts must be finite")
    return simulate_kernel(t, tau, theta0, starts, eta_start, foh, float(max_step), cas)


def simulate_speeds(
    t: np.ndarray,
    tau: np.ndarray,
    theta0: np.ndarray,
    eta0: np.ndarray,
    *,
    torque_hold: str = "zoh",
    max_step: float = MAX_STEP,
    form: RegressorForm | None = None,
) -> np.ndarray:
    """The model's wheel speeds eta_hat (n, 2) rad/s, simulated open loop from the measured torques.

    t (n,) s strictly increasing (uneven steps allowed), tau (n, 2) N m, theta0 (8,) base parameters,
    eta0 (2,) rad/s the speed at t[0] (the log's first measured speed), torque_hold "zoh" (tau[k] held
    over [t_k, t_k+1)) or "foh" (linear between samples), max_step: longest RK4 substep (s).
    eta_hat[0] = eta0.  Integration and the treatment of zero speed: see the module docstring.

    form: the identified model's :class:`wmrid.model.dynamics.RegressorForm` (None: the eight wheel parameters).  With
    the geometric caster model theta0 has form.n_base entries, the last ones the drag forces D_k, and the drag
    (smooth in eta) is part of the simulated dynamics; a form without caster drag changes nothing; the
    two-term caster model (no positions) is refused with :class:`UsageError`.
    """
    t, tau, theta0, cas = _check_inputs(t, tau, theta0, max_step, form)
    foh = _check_hold(torque_hold)
    eta0 = np.asarray(eta0, dtype=float)
    if eta0.shape != (2,) or not np.all(np.isfinite(eta0)):
        raise UsageError(f"eta0 must be 2 finite speeds (rad/s), got {eta0!r}")
    starts = np.zeros(1, dtype=np.int64)
    return simulate_kernel(t, tau, theta0, starts, eta0.reshape(1, 2).copy(), foh, float(max_step), cas)


def fit_percent(y: np.ndarray, y_hat: np.ndarray) -> np.ndarray:
    """NRMSE fit (k,) in %, per column: 100 (1 - ||y - y_hat|| / ||y - mean(y)||), as MATLAB's ``compare``.

    y, y_hat (n, k) (or (n,), giving shape ()).  100 is a perfect fit, 0 no better than the mean, and it
    can be negative.  A constant column of y gives NaN (the fit is undefined).
    """
    y = np.asarray(y, dtype=float)
    y_hat = np.asarray(y_hat, dtype=float)
    if y.shape != y_hat.shape:
        raise UsageError(f"y and y_hat must have the same shape, got {y.shape} and {y_hat.shape}")
    num = np.linalg.norm(y - y_hat, axis=0)
    den = np.linalg.norm(y - y.mean(axis=0), axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(den > 0, 100.0 * (1.0 - num / np.where(den > 0, den, 1.0)), np.nan)


def validation_fit(
    t: np.ndarray,
    eta: np.ndarray,
    tau: np.ndarray,
    theta0: np.ndarray,
    torque_hold: str = "zoh",
    form: RegressorForm | None = None,
) -> dict[str, object]:
    """Fit (%) of the simulated wheel speeds to the measured ones, per wheel, with the predictor's definition.

    t (n,) s, eta (n, 2) rad/s measured, tau (n, 2) N m, theta0 (8,) or (form.n_base,) with ``form`` (the
    identified model's; caster drag as :func:`simulate_speeds`).  Returns {"eta_r": fit %, "eta_l": fit %,
    "predictor": one sentence}; the simulation starts at eta[0] (:func:`simulate_speeds`).
    """
    eta = np.asarray(eta, dtype=float)
    if eta.ndim != 2 or eta.shape[1] != 2 or eta.shape[0] < 1:
        raise UsageError(f"eta must have shape (n, 2), got {eta.shape}")
    eta_hat = simulate_speeds(t, tau, theta0, eta[0], torque_hold=torque_hold, form=form)
    fit = fit_percent(eta, eta_hat)
    return {"eta_r": float(fit[0]), "eta_l": float(fit[1]), "predictor": predictor_text(torque_hold, form)}
