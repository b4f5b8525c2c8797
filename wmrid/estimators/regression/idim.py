"""The classical inverse dynamic identification model (IDIM): least squares on filtered signals.

The rival the paper sets its observer against (Sec. 1): the inverse model, Eq. (9) without disturbance,

    tau_1 = M11 a_1 + M12 a_2 + V_c (eta_1 eta_2 - eta_2^2) + F_v1 eta_1 + F_d1 sgn(eta_1)
    tau_2 = M12 a_1 + M22 a_2 + V_c (eta_1 eta_2 - eta_1^2) + F_v2 eta_2 + F_d2 sgn(eta_2)

(a = eta_dot, rad/s^2) is linear in phi = [M11 M12 M22 Vc Fv1 Fv2 Fd1 Fd2] (:data:`PHI_NAMES`), so phi is
an ordinary least-squares fit once the accelerations are known.  They are not measured; IDIM gets them
by differentiating low-pass filtered velocities, which is where its choices live:

* Time base.  The filter needs a uniform grid: that with the log's first and last time and number of
  samples.  A log whose time stamps stay within :data:`UNEVEN_TOLERANCE` steps of it is used as is (the
  rounding of epoch time stamps is 2e-4 of a 1 ms step); otherwise every signal is linearly
  interpolated onto it (linear interpolation attenuates a component
  at f by less than (pi f / rate)^2 / 3: 1e-5 at 1 Hz from 1 kHz).  A step longer than
  :data:`MAX_STEP_RATIO` mean steps is a hole interpolation cannot bridge: refused.
* Parallel filtering (Gautier 1997).  One zero-phase Butterworth low-pass (:mod:`wmrid.estimators.regression.lowpass`,
  as ``scipy.signal.butter`` + ``sosfiltfilt``; order ``order``, so the magnitude is 1 / (1 + (f / f_c)^(2 order))
  and the phase 0)
  is applied to the torques AND to every regressor column that is a function of the velocities:
  eta_i, the Coriolis columns eta_1 eta_2 - eta_j^2 and sgn(eta_i), each computed from the unfiltered
  samples first.  The acceleration columns are the 5-point central derivative of the filtered velocity,
  i.e. the filtered acceleration.  The filter is linear, so the filtered signals satisfy the same linear
  equation in phi: on a noise-free log the regression is exact whatever the cutoff (up to the
  derivative's (2 pi f / rate)^4 / 30 error and the edges), instead of carrying the (f / f_c)^(2 order)
  distortion of products and signs of filtered velocities.  The filter only has to suppress noise.
* Default cutoff (:func:`default_cutoff`): f_c = 2 f_s, twice the velocities' bandwidth, clipped to
  [f_lo, f_hi].  f_s (:func:`velocity_bandwidth`) is the highest frequency at which the Welch spectrum of
  a wheel speed stands :data:`BANDWIDTH_SNR` times above its noise floor (the median spectrum above
  rate / 4).  f_hi = min(10 Hz, rate / 20): a wheeled base of tens of kg on geared motors has its
  mechanical and speed-loop dynamics at a few Hz (the paper's simulated speed loop: 8 Hz), and rate / 20
  keeps at least 20 samples per cutoff period, where the 5-point derivative's gain error is at most
  3e-4.  f_lo: the edges dropped (below) take at most :data:`MAX_EDGE_FRACTION` of the log at each end.
  Why not simply f_hi: the noise on the velocities reaches the acceleration column amplified as
  f_c^(3/2) and biases the inertia (errors in variables), and with parallel filtering a cutoff above the
  signal's band buys nothing but that noise.  Measured (rate 1 kHz, noise 0.01 rad/s on eta): on the
  open-loop test log (torques below 0.5 Hz, 20 s) a 10 Hz cutoff biased m12 by -12.6 % and m11, m22
  by 4.5-4.9 %, 2 Hz by less than 0.07 %; on the noisy closed-loop simulation
  (``bench/_common.noisy_paper_sim``, 40 s, seed 1) the inertia errors were within 0.5 % for cutoffs of
  2-15 Hz, 0.5-1.1 % at 25 Hz and 3.7-5.9 % at 50 Hz (the rule picks about 5 Hz there).  On a noise-free
  log the floor is rounding noise and the rule gives f_hi.  Noise that is quiet above rate / 4 (speeds derived
  from encoder positions by a smoothing derivative) hides from that floor, so the default is then lowered by
  sqrt(2) while the estimate moves with the cutoff (:func:`fit_with_cutoff`): on 2048-count positions of the paper
  sinusoid 10 Hz biased the inertia by 0.5-1.2 %, the 5-7 Hz it lowers to by at most 0.05 %.
* Edges.  The zero-phase filter pads by odd reflection over as many samples as are later dropped; the samples
  within :func:`edge_seconds` of either end (the slowest filter pole decayed to :data:`EDGE_TOLERANCE`:
  0.38 s for order 4 at 10 Hz; with the long padding the
  remaining transient measured ~1e-6 of the torque on a noise-free log) are dropped.
* Decimation (``decimate=True``): the filtered columns carry nothing above f_c, so keeping every k-th
  sample with k = floor(rate / (4 f_c)) (the new Nyquist frequency at least 2 f_c, where the filter
  passes 1 / (1 + 4^order) of the noise power) loses almost no information while thinning the strongly
  correlated residuals (the parallel decimation of Gautier's IDIM).

Caster drag (``form`` with ``caster``, :class:`wmrid.model.dynamics.RegressorForm`, the observer's ``wheel+caster``
model): the casters' rolling drag adds to wheel i's torque sum_j theta0[p_j] col_j (1 if i = 1 else s_j)
over the caster columns col_j of :func:`wmrid.model.dynamics.caster_columns` ((column, p_j, s_j) from
``form.caster_map``; several columns may share one parameter, as the geometric model's two per caster share
D_k).  That is linear too: phi gains the caster parameters (Cv, Cw or D_1..D_K, the same in phi and theta0),
and the caster columns, computed from the unfiltered speeds like sgn(eta_i), go through the same parallel
filter, so the filtered regression stays exact.  Their excitation scale is the most a column can be per unit
parameter (:func:`caster_scales`).  Without ``form`` (or with a form without caster) everything is as above.

Least squares: both wheel equations stacked (2 rows per sample), solved by QR.  ``weighted=True``: two
steps, the rows of wheel j weighted by 1 / s_j with s_j the rms residual of its equation in the
ordinary fit.  Standard errors: the residuals are coloured (filtered; the caster disturbance; closed
loop), so sigma^2 (X^T X)^-1 would understate them many times; wmrid reports the delete-a-segment
jackknife over contiguous segments of the log as :mod:`wmrid.estimators.uncertainty` does (same segment
count rule), dof = G - 1, averaged over GRID_SHIFTS grids of G segments, each moved 1 / GRID_SHIFTS of a segment
further along the log (circularly, :func:`shifted_groups`).  Every grid's jackknife estimates the same variance; one
grid's also carries where its boundaries happen to fall (the same estimate on a 40 s heavy-robot log got an Fv1 std
of 5.7 % on IDIM's 17 segments and 9.3 % on RLS's 18), and the mean over grids carries less of it.  The dof stays
G - 1 (the mean is at least as steady as one grid; by how much more is not claimed).  Each leave-one-out solution
comes from the per-segment QR factors R_g of [X_g y_g] (X_g^T X_g = R_g^T R_g), without refitting, those of a
segment from its sub-segments' (:func:`sub_segments`).  theta0 = [m11 m12 m22 Vc Fv1 Fv2 Fd1 Fd2]
(then the caster parameters) with m = M^-1; its covariance by the delta method (:func:`theta0_jacobian`).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from wmrid.core.errors import NotIdentifiableError
from wmrid.estimators.estimate import BaseEstimate, SegmentEstimates
from wmrid.estimators.regression.idim_checks import CUTOFF_RATIO, cutoff_check, slow_speed_check
from wmrid.estimators.regression.idim_rows import (
    LOW_CUTOFF_HZ,
    PHI_NAMES,
    IdimRegression,
    cutoff_bounds,
    effort_delay,
    idim_regression,
    phi_to_theta0,
    qr_r,
    segment_factors,
    solve_r,
)
from wmrid.estimators.uncertainty import segment_count
from wmrid.model import dynamics as model
from wmrid.model.dynamics import RegressorForm

#: A direction of the physically scaled information whose eigenvalue is below this fraction of the largest
#: is not excited (the singular value ratio is its square root).
UNEXCITED = 1e-12


def segment_index(t: np.ndarray) -> tuple[np.ndarray, int]:
    """Jackknife segment (N,) of each sample in [0, G) and G, by :func:`wmrid.estimators.uncertainty.segment_count`."""
    duration = float(t[-1] - t[0])
    g = segment_count(duration, len(t))
    pos = (t - t[0]) / max(duration, 1e-300)
    return np.minimum((pos * g).astype(np.int64), g - 1), g


def not_identifiable_message(info_scaled: np.ndarray, names: tuple[str, ...] = PHI_NAMES) -> str | None:
    """None when the scaled information (p, p) is well posed; else a one-line reason naming phi's parameters
    (``names``, p of them)."""
    p = info_scaled.shape[0]
    evals, evecs = np.linalg.eigh(info_scaled)
    top = max(float(evals[-1]), 0.0)
    null = evals <= UNEXCITED * top if top > 0 else np.ones(p, dtype=bool)
    if not np.any(null):
        return None
    loose = [names[j] for j in range(p) if np.any(np.abs(evecs[j, null]) > 0.1)]
    why = "the wheel speeds and torques barely vary, or a wheel never turns"
    if any(name not in PHI_NAMES for name in loose):
        why += "; caster drag is told from the wheels' Coulomb friction only where the wheels stop, reverse or turn"
        why += " opposite ways"
    return (
        f"the log does not excite the dynamics: the regression leaves {', '.join(loose)} undetermined ({why}); "
        "record a log that accelerates, brakes and turns"
    )


def jackknife_from_factors(factors: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Delete-a-segment jackknife from per-segment triangular factors R_g (p + 1, p + 1) of [X_g y_g].

    Returns (leave-one-out solutions (G, p), covariance (p, p) = (G - 1) / G sum (phi_g - mean)(...)^T).
    """
    g = len(factors)
    loo = np.empty((g, factors[0].shape[1] - 1))
    with np.errstate(all="ignore"):
        for i in range(g):
            loo[i] = solve_r(np.vstack(factors[:i] + factors[i + 1 :]))
    centred = loo - loo.mean(axis=0)
    cov = (g - 1) / g * (centred.T @ centred)
    return loo, 0.5 * (cov + cov.T)


#: theta0 (..., p) = [m11 m12 m22 Vc ...] from phi (..., p) = [M11 M12 M22 Vc ...] (m = M^-1; every entry after the
#: third, the caster parameters too, is the same in both): the model's one conversion.
#: d theta0 / d phi (p, p) at phi: the 2x2 inverse's derivative dm = -m dM m, identity elsewhere.
theta0_jacobian = model.invert_inertia_jacobian


def theta0_covariance(phi: np.ndarray, cov_phi: np.ndarray) -> np.ndarray:
    """Covariance (p, p) of theta0 from that of phi by the delta method."""
    jac = theta0_jacobian(phi)
    cov = jac @ cov_phi @ jac.T
    return 0.5 * (cov + cov.T)


def inertia_warnings(phi: np.ndarray) -> list[str]:
    """Plain-English warnings about an estimated inertia matrix M = [[M11 M12] [M12 M22]] that is not physical."""
    big = np.array([[phi[0], phi[1]], [phi[1], phi[2]]])
    if np.all(np.linalg.eigvalsh(big) > 0):
        return []
    return ["the estimated inertia matrix M is not positive definite: the log barely excites the accelerations"]


#: The reported jackknife covariance is the mean of GRID_SHIFTS jackknives over the same G equal segments, the grid
#: moved along the log by 1 / GRID_SHIFTS of a segment each time (:func:`shifted_groups`).  Each is the delete-a-segment
#: jackknife with the same expectation; what one grid's spread owes to where its boundaries happen to fall averages
#: out.  On 20 heavy-robot MuJoCo logs (the study of bench/studies/study_caster_heavy.py, payload 60@-0.2,0) one
#: grid's Fv1 std varied by 23 % over seeds (median unchanged by averaging; 16 % with 8 grids), and the same estimate
#: got 5.7 % from IDIM's grid and 9.3 % from RLS's, one segment more.  8 grids: 16 and 32 changed no |z| by more than
#: 0.05.
GRID_SHIFTS = 8
#: How the std were computed (``diagnostics["uncertainty"]``), for IDIM, IV and RLS without forgetting.
JACKKNIFE_TEXT = (
    "delete-a-segment jackknife over contiguous segments of the log, averaged over the segment grid moved by "
    f"1/{GRID_SHIFTS} of a segment at a time"
)


def sub_segments(t: np.ndarray, seg: np.ndarray, g: int, grid: tuple[float, float, int] | None = None) -> np.ndarray:
    """Sub-segment (N,) in [0, G K) of each regression time t (N,) s (K = GRID_SHIFTS): segment s of the jackknife's
    G (seg (N,), :func:`jackknife_segments` on ``grid``) cut into K equal parts s K, ..., s K + K - 1."""
    t = np.asarray(t, dtype=np.float64)
    t0, duration = (float(t[0]), float(t[-1] - t[0])) if grid is None else (float(grid[0]), float(grid[1]))
    within = (t - t0) / max(duration, 1e-300) * g - seg
    return seg * GRID_SHIFTS + np.clip((within * GRID_SHIFTS).astype(np.int64), 0, GRID_SHIFTS - 1)


def shifted_groups(g: int) -> list[np.ndarray]:
    """The GRID_SHIFTS grids of the jackknife over G segments, each (G, K) the sub-segments (:func:`sub_segments`)
    making up its segments: grid j is the jackknife's own (j = 0) moved j / K of a segment later, its last segment
    wrapping round to the log's start (circular blocks), so every grid has G segments of equal length."""
    n = g * GRID_SHIFTS
    base = np.arange(n).reshape(g, GRID_SHIFTS)
    return [(base + j) % n for j in range(GRID_SHIFTS)]


def averaged_covariance(jackknife: Callable[[np.ndarray], np.ndarray], g: int) -> np.ndarray:
    """The mean over :func:`shifted_groups` of ``jackknife(groups)`` (p, p), the delete-a-segment jackknife covariance
    over the G segments whose sub-segments are the rows of groups (G, K)."""
    cov = np.mean([jackknife(groups) for groups in shifted_groups(g)], axis=0)
    return 0.5 * (cov + cov.T)


def jackknife_segments(t: np.ndarray, grid: tuple[float, float, int] | None = None) -> tuple[np.ndarray, int]:
    """Segment (N,) of each regression time t (N,) s and G: :func:`segment_index`, or on ``grid`` (t0 s, duration s,
    G), another fit's segments (:attr:`wmrid.estimators.estimate.SegmentEstimates.grid`), so the two can be compared."""
    if grid is None:
        return segment_index(t)
    t0, duration, g = grid
    pos = (np.asarray(t) - t0) / max(duration, 1e-300)
    return np.clip((pos * g).astype(np.int64), 0, g - 1), int(g)


@dataclass(frozen=True, eq=False)
class RegressionFit:
    """A least-squares fit of an IDIM regression (:func:`fit_regression`).

    phi (p,), cov (p, p) its jackknife covariance (None when not asked for), loo (G, p) the leave-one-segment-out
    solutions; factors: the per-segment triangular factors of the (weighted) rows, seg (N,) each row's segment in
    [0, G); diagnostics and warnings as JSON-ready dict and plain-English list.
    """

    phi: np.ndarray
    cov: np.ndarray | None
    loo: np.ndarray
    factors: list[np.ndarray]
    seg: np.ndarray
    diagnostics: dict[str, Any]
    warnings: list[str]


def fit_regression(
    reg: IdimRegression, *, weighted: bool = False, grid: tuple[float, float, int] | None = None,
    covariance: bool = True,
) -> RegressionFit:  # fmt: skip
    """Least squares of phi on a regression (:class:`RegressionFit`), p = len(reg.phi_names) (8, plus the caster
    parameters of ``reg.form``).

    weighted : two-step weighted LS, wheel j's rows scaled by 1 / s_j (s_j its OLS rms residual, N m).
    grid : the jackknife's segments (:func:`jackknife_segments`).  covariance : False leaves the jackknife
    covariance out (``cov`` None: GRID_SHIFTS jackknifes, a fifth of the fit's time, for a caller that needs only
    the estimate, its factors or the cutoff).
    Raises NotIdentifiableError when the regressor is rank deficient.
    """
    seg, g = jackknife_segments(reg.t, grid)
    sub = sub_segments(reg.t, seg, g, grid)
    scale = reg.scales()
    p = len(scale)

    rows = reg.rows()

    def grouped(fine: list[np.ndarray], groups: np.ndarray) -> list[np.ndarray]:
        return [qr_r(np.vstack([fine[i] for i in idx])) for idx in groups]

    def factors(weights: np.ndarray) -> list[np.ndarray]:
        # per sub-segment; the jackknife's own segments' factors are those of their sub-segments stacked
        return segment_factors(rows, reg.tau, weights, sub, g * GRID_SHIFTS)

    def residual_rms(phi: np.ndarray) -> np.ndarray:
        return np.sqrt(np.mean((rows @ phi - reg.tau) ** 2, axis=0))

    ones = np.ones(2)
    fine = factors(ones)
    r_all = qr_r(np.vstack(fine))
    rs = r_all[:p, :p] / scale[None, :]
    reason = not_identifiable_message(rs.T @ rs, reg.phi_names)
    if reason is not None:
        raise NotIdentifiableError(reason)
    sv = np.linalg.svd(rs, compute_uv=False)
    phi = solve_r(r_all)
    rms = residual_rms(phi)
    weights = ones
    if weighted:
        if np.any(rms <= 0):
            raise NotIdentifiableError("weighted IDIM: a wheel equation fits exactly, so its weight is undefined")
        weights = 1.0 / rms
        fine = factors(weights)
        phi = solve_r(np.vstack(fine))
        rms = residual_rms(phi)
    fac = grouped(fine, shifted_groups(g)[0])
    loo, _ = jackknife_from_factors(fac)
    cov = None
    if covariance:
        cov = averaged_covariance(lambda groups: jackknife_from_factors(grouped(fine, groups))[1], g)
    diagnostics: dict[str, Any] = {
        **reg.info(),
        "rows": 2 * len(reg.t),
        "weighted": bool(weighted),
        "weights": [float(w) for w in weights],
        "residual_rms": [float(v) for v in rms],
        "condition": float(sv[0] / sv[-1]),
        "segments": int(g),
        "grid_shifts": GRID_SHIFTS,
        "uncertainty": JACKKNIFE_TEXT,
    }
    warnings = inertia_warnings(phi)
    if reg.cutoff_hz < LOW_CUTOFF_HZ:
        warnings.append(
            f"the filter cutoff is only {reg.cutoff_hz:.3g} Hz (log rate {reg.rate_hz:.3g} Hz): faster dynamics "
            "are filtered out and little of the log's excitation is used"
        )
    return RegressionFit(phi, cov, loo, fac, seg, diagnostics, warnings)


#: The default cutoff is lowered at most this many times (by CUTOFF_RATIO each: 10 Hz -> 2.5 Hz).
MAX_LOWERINGS = 4
#: ... each time the cutoff check's difference exceeds this many of its std in some parameter.  Lower than the
#: check's own gate (CUTOFF_GATE, which adds the difference to the covariance): a needless step costs only the band
#: between f_c / CUTOFF_RATIO and f_c (the parallel-filtered regression stays exact), a missed one the noise's bias
#: (on 512-count encoder positions the check read 3.7 std at 10 Hz where m11 was 3.2 % off, 0.05 % at 5 Hz).
#: Noise alone passes it in about 6 % of logs (8 parameters, Student t with 19 dof).
LOWERING_GATE = 3.0


def _lower_cutoff(
    t: np.ndarray, eta: np.ndarray, tau: np.ndarray, reg: IdimRegression, cut: dict[str, Any],
    lowered: list[dict[str, Any]], default: bool, decimate: bool, order: int, form: RegressorForm | None,
    delay: float,
) -> IdimRegression | None:  # fmt: skip
    """The regression at the next lower cutoff when the default cutoff's estimate moves with the filter (errors in
    variables), else None; appends to ``lowered`` what was seen.

    Noise in the speeds reaches the acceleration columns through the filter, amplified with the band it keeps
    (errors in variables, which bias the inertia towards zero).  Where the model holds and
    the speeds are noise-free, the parallel-filtered regression is exact at every cutoff, so an estimate that moves
    when the cutoff is divided by CUTOFF_RATIO (:func:`wmrid.estimators.regression.idim_checks.cutoff_check`, beyond
    LOWERING_GATE std of the difference) measures the noise's bias.  That bias shrinks as the band does (as f_c^3
    for white noise on the speeds, faster for quantised positions differentiated); a model error's need not, so the
    cutoff is lowered only while the difference keeps shrinking (its largest entry in the first step's std), at
    most MAX_LOWERINGS times and never below the default's lower bound
    (:func:`wmrid.estimators.regression.idim_rows.cutoff_bounds`).  Only the default cutoff is lowered (``default``).
    """

    if not default or len(lowered) >= MAX_LOWERINGS or cut.get("delta") is None:
        return None
    ratio = float(cut["largest_ratio"])
    if ratio <= LOWERING_GATE:
        return None
    delta, sd = np.abs(np.asarray(cut["delta"], dtype=float)), np.asarray(cut["sd"], dtype=float)
    sd0 = np.asarray(lowered[0]["sd"], dtype=float) if lowered else sd
    with np.errstate(divide="ignore", invalid="ignore"):
        size = float(np.max(np.where(sd0 > 0, delta / sd0, 0.0)))  # in the first step's std: comparable
    if lowered and size >= lowered[-1]["size"]:
        return None
    low = reg.cutoff_hz / CUTOFF_RATIO
    f_lo = cutoff_bounds(reg.rate_hz, float(t[-1] - t[0]), order)[0]
    if low < f_lo:
        return None
    try:
        lower = idim_regression(t, eta, tau, low, decimate, order=order, form=form, effort_delay=delay)
    except NotIdentifiableError:
        return None
    head = lowered[0]["rule"] if lowered else reg.cutoff_rule
    lowered.append({
        "from_hz": float(reg.cutoff_hz), "to_hz": float(low), "largest_ratio": ratio, "rule": head, "size": size,
        "sd": sd.tolist(),
    })  # fmt: skip
    rule = (
        f"{head}; lowered to {low:.3g} Hz ({len(lowered)} x 1/{CUTOFF_RATIO:.3g}): the estimate moved with the cutoff "
        f"beyond {LOWERING_GATE:g} std of the difference (errors in variables: noise in the speeds)"
    )
    return replace(lower, cutoff_rule=rule)


def fit_with_cutoff(
    t: np.ndarray, eta: np.ndarray, tau: np.ndarray, cutoff_hz: float | None, *, weighted: bool = False,
    decimate: bool = True, order: int = 4, form: RegressorForm | None = None, delay: float = 0.0,
    grid: tuple[float, float, int] | None = None, covariance: bool = True,
) -> tuple[IdimRegression, RegressionFit, dict[str, Any], list[dict[str, Any]]]:  # fmt: skip
    """IDIM's regression, its fit and its cutoff check (:func:`wmrid.estimators.regression.idim_checks.cutoff_check`) at
    ``cutoff_hz``, or at the default cutoff lowered while the estimate moves with it (:func:`_lower_cutoff`).

    Returns (regression, fit, cutoff check, the lowerings made: [{"from_hz", "to_hz", "largest_ratio", "rule"}]).
    Arguments as :func:`identify_idim`'s (``delay``: its effort delay, s); covariance : as :func:`fit_regression`'s
    (the cutoff check and the lowering do not use it).
    """

    reg = idim_regression(t, eta, tau, cutoff_hz, decimate, order=order, form=form, effort_delay=delay)
    lowered: list[dict[str, Any]] = []
    while True:
        fit = fit_regression(reg, weighted=weighted, grid=grid, covariance=covariance)
        weights = np.asarray(fit.diagnostics["weights"])
        t0, span = (float(reg.t[0]), float(reg.t[-1] - reg.t[0])) if grid is None else (grid[0], grid[1])
        cut = cutoff_check(t, eta, tau, reg, fit.factors, weights, fit.seg, len(fit.factors), decimate, delay,
                           (t0, span))  # fmt: skip
        lower = _lower_cutoff(t, eta, tau, reg, cut, lowered, cutoff_hz is None, decimate, order, form, delay)
        if lower is None:
            return reg, fit, cut, lowered
        reg = lower


def identify_idim(
    t: np.ndarray,
    eta: np.ndarray,
    tau: np.ndarray,
    *,
    cutoff_hz: float | None = None,
    weighted: bool = False,
    order: int = 4,
    decimate: bool = True,
    form: RegressorForm | None = None,
    torque_hold: str = "zoh",
    control_rate: float | None = None,
    grid: tuple[float, float, int] | None = None,
) -> BaseEstimate:
    """IDIM least-squares estimate of the base parameters from a log.

    t : (n,) s strictly increasing; eta : (n, 2) rad/s [right, left]; tau : (n, 2) N m.
    cutoff_hz : Butterworth cutoff (default :func:`default_cutoff`); order : its order; decimate :
    parallel decimation; weighted : two-step weighted LS.  form : the observer's regressor form; with caster
    drag (``form.caster``) theta0 and phi gain its caster parameters (``form.base_names[8:]``), otherwise (or
    None) it is ignored.  torque_hold, control_rate : how the effort was held between samples, as for the
    observer (:func:`effort_delay`).  grid : (t0 s, duration s, G) the jackknife's segments, e.g. the observer's
    (default: G equal segments of the regression's span).  See the module docstring for each choice.
    Returns a :class:`BaseEstimate` (method "idim"): theta0 in the m = M^-1 parameterisation (``form.n_base``
    entries with caster drag, else 8), the jackknife covariance through the delta method, dof = G - 1;
    diagnostics hold the preprocessing choices, the residual rms per wheel (N m), ``checks``: the estimate at
    a lower cutoff and without the slow rows (:mod:`wmrid.estimators.regression.idim_checks`; not yet in the
    covariance), phi = [M11 M12 M22 Vc Fv1 Fv2 Fd1 Fd2, caster...] and its standard errors.
    Raises NotIdentifiableError when the log does not excite the dynamics.
    """

    start = time.perf_counter()
    delay = effort_delay(t, torque_hold, control_rate)
    reg, fit, cut, lowered = fit_with_cutoff(
        t, eta, tau, cutoff_hz, weighted=weighted, decimate=decimate, order=order, form=form, delay=delay, grid=grid
    )
    weights = np.asarray(fit.diagnostics["weights"])
    phi, cov_phi, diagnostics, warnings, loo = fit.phi, fit.cov, fit.diagnostics, fit.warnings, fit.loo
    diagnostics["effort_delay_s"] = delay
    fac, seg, g = fit.factors, fit.seg, len(fit.factors)
    t0, span = (float(reg.t[0]), float(reg.t[-1] - reg.t[0])) if grid is None else (grid[0], grid[1])
    if lowered:
        diagnostics["cutoff_lowered"] = lowered
    diagnostics["checks"] = {
        "cutoff": cut,
        "slow_speed": slow_speed_check(reg, np.asarray(eta, dtype=np.float64), fac, weights, seg, g),
    }
    theta0 = phi_to_theta0(phi)
    cov0 = theta0_covariance(phi, cov_phi)
    std_phi = np.sqrt(np.clip(np.diag(cov_phi), 0.0, None))
    diagnostics["phi"] = {name: float(v) for name, v in zip(reg.phi_names, phi, strict=True)}
    diagnostics["phi_std"] = {name: float(v) for name, v in zip(reg.phi_names, std_phi, strict=True)}
    return BaseEstimate(
        method="idim", theta0=theta0, cov=cov0, dof=diagnostics["segments"] - 1,
        seconds=time.perf_counter() - start, diagnostics=diagnostics, warnings=tuple(warnings),
        segments=SegmentEstimates(t0, span, phi_to_theta0(loo)),
    )  # fmt: skip
