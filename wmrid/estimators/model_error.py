"""What the standard errors cover when the model does not hold: the three widenings of
docs/explanation/uncertainty.md ("Errors the jackknife cannot see").

The jackknife (:mod:`wmrid.estimators.uncertainty`) measures how the estimate varies along a log; an error that is the
same all along it is invisible to it.  Three such errors are measured here, each from what the compiled
replay already produced, and added to the covariance of theta0 only where the evidence says they matter:

* model error: the structural-mismatch test's misfit scales every variance (:func:`model_error_scale`);
* discretisation: a half-rate replay bounds the error of the step, Richardson-style (:func:`discretisation_error`);
* friction at low speed: the estimate without the slow or reversing parts of the log (:func:`slow_speed_term`).

A fourth check widens nothing but flags every parameter: wheel speeds that the model predicts far worse than
their own noise (:func:`prediction_misfit`) -- slipping wheels, above all, which bias the estimate by tens of
per cent without making it vary along the log.

:func:`widen` applies the three and runs the fourth; :func:`record_widening` states them in a result's
diagnostics.  Pure
functions on arrays; no I/O.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np

from wmrid.estimators.diagnostics import MISMATCH_RELEVANT, flagged_names
from wmrid.estimators.findings import Diagnostics, ModelError
from wmrid.estimators.observer.kernel import project_history_box
from wmrid.estimators.uncertainty import FILTER_MEMORY, segments_of, slow_speed_difference
from wmrid.model import dynamics as model
from wmrid.model.base_params import BaseFit, fit_base_parameters
from wmrid.model.dynamics import RegressorForm

#: Model-error inflation (uncertainty.md): when the structural-mismatch test rejects at INFLATE_P, every
#: variance is multiplied by S^2 = 1 + T^2 (:func:`model_error_scale`).  A scale at least INFLATION_MARK marks
#: the parameters as inflated.
INFLATION_MARK = 1.05
#: The structural-mismatch test level at which the std are widened (the warning keeps MISMATCH_P).
INFLATE_P = 0.05
MODEL_ERROR_NOTE = (
    "the log departs from the model (Eqs. 9-25) beyond its noise, so every std was scaled by S = sqrt(1 + T2), T2 "
    "the structural-mismatch statistic: the std then covers a model error that moves the estimate along the "
    "model's surface as far as it visibly moves it off the surface"
)
DISCRETISATION_NOTE = (
    "replaying every other sample moved the estimate by more than its noise, so that difference (a Richardson "
    "bound on the error of turning samples into continuous-time filters) was added to the covariance"
)
SLOW_SPEED_NOTE = (
    "leaving out the parts of the log where a wheel is slow or reverses moved the estimate by more than its noise "
    "(friction near zero speed is not F_v eta + F_d sgn(eta): stiction, a smooth Coulomb law), so that "
    "difference was added to the covariance"
)
FILTER_NOTE = (
    "refitting with the filter's cutoff lowered by a factor sqrt(2) moved the estimate by more than its noise (the "
    "model or the noise makes the estimate depend on the band the filter keeps), so that difference was added to "
    "the covariance"
)
FRAGILE_NOTE = (
    "{} rest mostly on the parts of the log where a wheel is slow or reverses, where friction and caster drag are "
    "least like the model, so they report the std they have without those parts"
)


def widen(
    fit: BaseFit,
    theta: np.ndarray,
    out: Any,
    gamma: np.ndarray,
    theta_u: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    weight_cov: np.ndarray,
    form: RegressorForm,
    block_mid: np.ndarray,
    duration: float,
    k: float,
) -> tuple[np.ndarray, dict[str, Any]]:
    """The covariance (n0, n0) of theta0 with the three widenings, and their record (JSON-ready).

    fit : the minimum-distance fit of theta (2, p, projected on the box); out : the replay's output
    (:class:`wmrid.estimators.observer.replay.ReplayOutput`); gamma, theta_u : its final Gamma and unconstrained
    estimate; lo, hi :
    the box; weight_cov : the fit's weights; block_mid (J,) s : the blocks' mid-times from the log's start;
    duration : s; k : the observer's gain, 1/s.  The record holds the scale's test figures, "relative_misfit",
    "discretisation" and "slow_speed" (:func:`discretisation_error`, :func:`slow_speed_term`; fragile parameters
    by name), and "prediction_misfit" (:func:`prediction_misfit`: it widens nothing, it flags).
    """
    fitted = model.intermediate_parameters(fit.theta0, form)
    relative_misfit = float(np.max(np.abs(fitted - theta)) / max(np.max(np.abs(theta)), 1e-300))
    record = model_error_scale(fit, relative_misfit)
    record["relative_misfit"] = relative_misfit
    scale2 = record["scale"] ** 2
    cov0 = fit.cov * scale2
    record["discretisation"] = discretisation_error(out.theta_half, gamma, lo, hi, weight_cov, form, fit.theta0, cov0)
    if record["discretisation"]["applied"]:
        delta = np.asarray(record["discretisation"]["delta"])
        cov0 = cov0 + np.outer(delta, delta)
    slow = slow_speed_term(out, gamma, theta_u, fit.gain, block_mid, duration, k, cov0, scale2)
    if slow["applied"]:
        delta = np.asarray(slow["delta"])
        cov0 = cov0 + np.outer(delta, delta)
    grow = np.zeros(len(fit.theta0))
    for j in slow["fragile"]:
        grow[j] = max(slow["var_without"][j] - cov0[j, j], 0.0)
    cov0 = cov0 + np.diag(grow)
    record["slow_speed"] = {**slow, "fragile": [form.base_names[j] for j in slow["fragile"]]}
    # per sample, as the noise is measured (the time-weighted blk_ee would let one gap's catch-up weigh like the
    # whole gap): the decimated history holds e at up to max_history evenly spaced samples (the first is 0)
    e = np.asarray(out.hist_e)[1:]
    pe_rms = np.sqrt(np.mean(e**2, axis=0)) if len(e) else np.full(2, np.nan)
    record["prediction_misfit"] = prediction_misfit(pe_rms, out.noise_sigma, out.eta_rms)
    return cov0, record


#: The model predicts the speeds worse than their noise by more than this factor: on noisy logs where the model
#: holds (wmrid's simulator with a coloured disturbance in closed loop, multibody logs on a normal floor, 100 Hz
#: to 1 kHz) the ratio was 1.03-1.11; with slipping wheels (floor friction 0.15) 11-35.
MISFIT_RATIO = 2.0
#: ... and by more than this fraction of the speeds' rms, so that a noise-free log (whose noise floor is the
#: signal's own curvature, ~1e-7) is judged by its size: 2e-5 of rms on noise-free multibody logs where the model
#: holds, 2e-3 with caster drag left out, 0.025-0.09 with slip.
MISFIT_FLOOR = 5e-3
PREDICTION_MISFIT_NOTE = (
    "the model predicts the {side} wheel's speed to {pe} rad/s rms, {ratio} its noise of {sigma} rad/s and {share} % "
    "of its rms: wheels that slip, backlash, or an effect the model leaves out; such an error biases the estimate "
    "without making it vary along the log, so every parameter is flagged: its std does not cover it"
)


def prediction_misfit(pe_rms: np.ndarray, sigma: np.ndarray | None, eta_rms: np.ndarray | None) -> dict[str, Any]:
    """Whether the observer's prediction error is far above the speed sensors' noise (docs/explanation/uncertainty.md).

    pe_rms (2,) rad/s: rms of e = eta - eta_hat over the log's samples; sigma (2,) rad/s: the speeds' white-noise
    level (:class:`wmrid.estimators.noise_floor.NoiseFloor`; NaN where unknown); eta_rms (2,) rad/s.  Where the model
    holds, e is that noise and the ratio pe_rms / sigma is about 1.  Applied when, for a wheel whose noise is
    known, the ratio exceeds MISFIT_RATIO and pe_rms exceeds MISFIT_FLOOR of the speed's rms.
    Returns {"applied": bool, "wheel": the worst wheel (0 right, 1 left; the worst applied one), "ratio" and
    "share" (pe_rms / eta_rms) of that wheel, or None when no wheel's noise is known, and "prediction_error_rms",
    "noise_rms", "speed_rms": (2,) rad/s}.
    """
    none = {"applied": False, "wheel": None, "ratio": None, "share": None, "prediction_error_rms": None,
            "noise_rms": None, "speed_rms": None}  # fmt: skip
    if sigma is None or eta_rms is None:
        return none
    pe = np.asarray(pe_rms, dtype=float)
    sigma = np.asarray(sigma, dtype=float)
    eta_rms = np.asarray(eta_rms, dtype=float)
    known = np.isfinite(sigma) & (sigma > 0) & np.isfinite(pe)
    if not known.any():
        return none
    ratio = np.where(known, pe / np.where(known, sigma, 1.0), -np.inf)
    share = pe / np.maximum(eta_rms, 1e-300)
    hit = known & (ratio > MISFIT_RATIO) & (share > MISFIT_FLOOR)
    wheel = int(np.argmax(np.where(hit, ratio, -np.inf))) if hit.any() else int(np.argmax(ratio))
    return {
        "applied": bool(hit.any()), "wheel": wheel, "ratio": float(ratio[wheel]), "share": float(share[wheel]),
        "prediction_error_rms": pe.tolist(), "noise_rms": sigma.tolist(), "speed_rms": eta_rms.tolist(),
    }  # fmt: skip


#: The discretisation term is added when the half-rate estimate differs from the full-rate one by more than
#: this many standard errors in some base parameter (noise alone: |delta_j| / std_j ~ N(0, 1), so 4 is passed
#: by chance about once in 2,000 logs, for 8 parameters).
DISCRETISATION_GATE = 4.0


def discretisation_error(
    theta_half: np.ndarray | None,
    gamma: np.ndarray,
    lo: np.ndarray,
    hi: np.ndarray,
    weight_cov: np.ndarray,
    form: RegressorForm,
    theta0: np.ndarray,
    cov0: np.ndarray,
    scale2: float = 1.0,
) -> dict[str, Any]:
    """A Richardson estimate of the replay's discretisation error, and whether it matters.

    The estimator turns a sampled log into continuous-time filters; its error shrinks with the step h.
    Replaying every other sample (step 2h) moves the estimate by delta = theta0(h) - theta0(2h) = e(h) - e(2h);
    for an error of order q >= 1, |e(h)| = |delta| / (2^q - 1) <= |delta|, so delta bounds it.  On a noisy
    log delta is mostly noise (of about one std); it is added, as the rank-one covariance delta delta^T,
    only when some |delta_j| exceeds DISCRETISATION_GATE of its std: a noise-free log, or one logged so
    slowly that the step itself biases the estimate.
    Returns {"applied": bool, "delta": list (8,) or None, "largest_ratio": max_j |delta_j| / std_j}.
    """
    if theta_half is None or not np.all(np.isfinite(theta_half)):
        return {"applied": False, "delta": None, "largest_ratio": None}
    projected = np.empty_like(theta_half)
    project_history_box(theta_half[None], gamma[None], lo, hi, projected[None])
    half = fit_base_parameters(projected, weight_cov, form)
    delta = theta0 - half.theta0
    std = np.sqrt(np.clip(np.diag(cov0), 0.0, None))
    with np.errstate(divide="ignore", invalid="ignore"):  # a zero or non-finite std: an entry the log leaves unset
        ratio = np.where((std > 0) & np.isfinite(std), np.abs(delta) / std, 0.0)
    largest = float(np.max(ratio))
    return {"applied": bool(largest > DISCRETISATION_GATE), "delta": delta.tolist(), "largest_ratio": largest}


#: The low-speed difference is added when some |delta0_j| exceeds this many of its std: Student's t with 19 dof
#: passes 3 by chance with p = 0.007 per parameter, about 5 % of well-specified logs for 8 parameters -- the
#: level of the structural test's widening (INFLATE_P); on multibody logs the reversals' bias sat at 3.2-3.7.
SLOW_SPEED_GATE = 3.0
#: The slow parts' mean square prediction error over the other parts' at which the slow parts visibly depart from the
#: model (:func:`slow_residual`): 50 % more error power than where the wheels are fast.  Measured: REGBOT (a real robot,
#: currents as efforts) 2.1 and 2.8; the paper robot's MuJoCo plan logs 1.01-1.02 with the casters' load model, 1.10
#: with the wheels' friction alone (the casters' drag undescribed), 0.99-1.02 with frictionless casters.
SLOW_RESIDUAL_RATIO = 1.5
#: A base parameter whose std without the slow parts of the log exceeds this many times its std is
#: determined mostly by those parts, where friction is least like the model: it reports that larger std.
FRAGILE_RATIO = 2.0


def slow_speed_term(
    out: Any,
    gamma: np.ndarray,
    theta_u: np.ndarray,
    gain: np.ndarray,
    block_mid: np.ndarray,
    duration: float,
    k: float,
    cov0: np.ndarray,
    scale2: float = 1.0,
) -> dict[str, Any]:
    """Whether friction near zero speed departs from the model enough to matter (docs/explanation/uncertainty.md).

    The base parameters from the log without its slow-wheel parts
    (:func:`wmrid.estimators.uncertainty.slow_speed_difference`)
    differ from the full estimate by delta0 = G delta (G the minimum-distance gain) with a jackknife std
    per parameter.  When some |delta0_j| exceeds SLOW_SPEED_GATE of that std, delta0 delta0^T is added to the
    covariance.  A
    parameter whose std without the slow parts exceeds FRAGILE_RATIO times its std is "fragile": the log
    pins it mostly where the wheels are slow or reverse (Coulomb friction against caster drag, say, on a log
    that never turns on the spot), and it reports the std it has without those parts.  Only the parameters that are
    not fragile count towards the gate: a fragile one's estimate without the slow parts is near-singular, and the
    jackknife understates its spread (the paper robot's MuJoCo plan log, 71 % of it slow: F_d1 without the slow parts
    moved by 3.6 N m, 75 times its value, at 5.3 jackknife std; every parameter fragile, every one then reported
    12-11000 % uncertain where the full estimate was within 8 % of the engine's truth).
    Returns {"applied", "delta" (n0,) or None, "largest_ratio", "left_out_fraction", "fragile" (indices),
    "var_without" (n0,)}.
    """
    none = {"applied": False, "delta": None, "largest_ratio": None, "left_out_fraction": 0.0, "fragile": []}
    if out.blk_slow is None or duration <= 0:
        return none
    segment, n_seg = segments_of(np.asarray(block_mid) / duration, duration)
    block_seconds = duration / max(len(out.block_end), 1)
    spill = math.ceil(FILTER_MEMORY / (k * block_seconds))
    diff = slow_speed_difference(gamma, theta_u, out.blk_a, out.blk_c, out.blk_slow, segment, n_seg, spill)
    if diff is None:
        return none
    delta0 = gain @ diff["delta"]
    sd = np.sqrt(np.clip(np.diag(gain @ diff["cov"] @ gain.T), 0.0, None))
    std0 = np.sqrt(np.clip(np.diag(cov0), 0.0, None))
    var_without = np.clip(np.diag(gain @ diff["cov_without"] @ gain.T), 0.0, None) * scale2
    pinned_by_slow = np.array([var_without[j] > FRAGILE_RATIO**2 * max(cov0[j, j], 0.0) for j in range(len(delta0))])
    with np.errstate(divide="ignore", invalid="ignore"):  # undetermined (inf) or unset entries do not count
        ratio = np.where((sd > 0) & np.isfinite(sd) & np.isfinite(std0), np.abs(delta0) / sd, 0.0)
    # The evidence comes from the parameters the log still determines without its slow parts: the difference of one
    # it does not is mostly the information lost (its estimate without them is near-singular, and the jackknife of a
    # near-singular solve understates its spread).
    largest = float(np.max(np.where(pinned_by_slow, 0.0, ratio)))
    residual = slow_residual(out, diff["left_out"], segment, n_seg, duration)
    applied = bool(largest > SLOW_SPEED_GATE or residual["departs"])
    # Only where the slow parts visibly depart from the model: on a reversing log the reversals carry much of
    # the excitation whether or not the model holds there, so a larger std without them is no evidence alone.
    fragile = [j for j in range(len(delta0)) if pinned_by_slow[j]] if applied else []
    return {
        "applied": applied, "delta": delta0.tolist(), "largest_ratio": largest,
        "left_out_fraction": diff["fraction"], "fragile": fragile, "var_without": var_without.tolist(),
        "residual_ratio": residual["ratio"], "residual_z": residual["z"],
    }  # fmt: skip


def slow_residual(
    out: Any, left_out: np.ndarray, segment: np.ndarray, n_segments: int, duration: float
) -> dict[str, Any]:
    """Whether the model fits the slow parts of the log visibly worse than the rest, from the observer's prediction
    error: per wheel, the mean square of e = eta - eta_hat over the blocks ``left_out`` (slow, and the filter's memory
    after them) over that of the other blocks (``out.blk_ee``, Sum h e^2 per block; ``out.block_t`` their ends, s),
    and the delete-a-segment jackknife std of its logarithm (``segment`` (J,) of ``n_segments``).

    Unlike the difference of the estimates (:func:`slow_speed_term`), this needs no estimate without the slow parts,
    so it holds where those parts carry most of the excitation (a reversing drive, a plan): where the model holds
    there, the error is the speeds' noise everywhere and the ratio is 1.  The slow parts depart when a wheel's ratio
    is at least SLOW_RESIDUAL_RATIO and its logarithm beyond one jackknife std.
    Returns {"departs": bool, "ratio": [2] or None, "z": [2] or None}."""
    none = {"departs": False, "ratio": None, "z": None}
    ends = np.asarray(out.block_t, dtype=float)
    if len(ends) != len(left_out) or len(ends) == 0:
        return none
    span = np.diff(np.concatenate(([ends[-1] - duration], ends)))

    def ratio(keep: np.ndarray) -> np.ndarray | None:
        slow, fast = keep & left_out, keep & ~left_out
        t_slow, t_fast = span[slow].sum(), span[fast].sum()
        if not (t_slow > 0 and t_fast > 0):
            return None
        e_slow, e_fast = out.blk_ee[slow].sum(axis=0) / t_slow, out.blk_ee[fast].sum(axis=0) / t_fast
        if not (np.all(e_slow > 0) and np.all(e_fast > 0)):
            return None
        return e_slow / e_fast

    full = ratio(np.ones(len(ends), dtype=bool))
    reps = [ratio(segment != g) for g in range(n_segments)]
    if full is None or n_segments < 2 or any(r is None for r in reps):
        return none
    logs = np.log(np.array(reps))
    jack = np.sqrt((n_segments - 1) / n_segments * np.sum((logs - logs.mean(axis=0)) ** 2, axis=0))
    with np.errstate(divide="ignore", invalid="ignore"):
        z = np.where(jack > 0, np.log(full) / jack, 0.0)
    departs = bool(np.any((full >= SLOW_RESIDUAL_RATIO) & (z > 1.0)))
    return {"departs": departs, "ratio": full.tolist(), "z": z.tolist()}


def model_error_scale(fit: Any, relative_misfit: float = math.inf) -> dict[str, Any]:
    """The model-error scale factor of a minimum-distance fit (docs/explanation/uncertainty.md).

    theta (2p numbers) must lie on the n0-dimensional surface theta = f(theta0) (Eqs. 23-24).  A model error
    moves it by a bias b; the fit sees only the part of b off the surface, the misfit rho, whose size in units
    of the estimate's own spread is Hotelling's T^2 (d directions).  The part along the surface is invisible
    and moves theta0: by at most |b_along| std_j for parameter j, in the same units.  Taking the invisible part
    no larger than the visible one, each bias is at most sqrt(T^2 - E0) std_j, E0 = d B / (B - d - 1) the part
    of T^2 that noise alone gives (Hotelling's mean); the variances are multiplied by S^2 = 1 + max(T^2 - E0, 0),
    which covers that bias and the noise together.  ``relative_misfit``: the largest misfit over max |theta|;
    below MISMATCH_RELEVANT (1e-5, the discretisation of a noise-free log, which the Richardson term covers)
    nothing is scaled.  Applied when the
    structural-mismatch test rejects at INFLATE_P (F = (B - d + 1) T^2 / (B d) ~ F(d, B - d + 1) with B the
    jackknife's degrees of freedom): a lenient level, because a model error of the size of the noise already
    biases the estimate by a few std (on multibody logs with sensor noise p was 0.005-0.03 while the
    inertia entries sat 3-6 std off); where the model holds, S = 1 in 95 % of logs.
    Returns {"scale": S, "applied": bool, "T2": T^2, "F": F, "p_value": p}.
    """
    big_b = getattr(fit, "report_dof", None)
    stat = float("nan")
    if fit.dof > 0:
        if big_b is not None and big_b - fit.dof + 1 > 0:
            stat = (big_b - fit.dof + 1) * fit.chi2 / (big_b * fit.dof)
        else:
            stat = fit.chi2 / fit.dof
    expected = fit.dof * big_b / (big_b - fit.dof - 1) if big_b is not None and big_b - fit.dof - 1 > 0 else fit.dof
    applied = bool(
        fit.dof > 0 and math.isfinite(fit.p_value) and fit.p_value < INFLATE_P and relative_misfit > MISMATCH_RELEVANT
    )
    scale = math.sqrt(1.0 + max(fit.chi2 - expected, 0.0)) if applied else 1.0
    return {
        "scale": scale, "applied": applied, "T2": float(fit.chi2), "T2_expected": float(expected), "F": stat,
        "p_value": float(fit.p_value),
    }  # fmt: skip


def record_widening(
    diagnostics: Diagnostics, inflation: dict[str, Any], parameters: dict[str, Any], undetermined: list[str]
) -> Diagnostics:
    """``diagnostics`` (with its uncertainty) with the model-error scale (``uncertainty.model_error``), the
    parameters whose std it widened (``inflated``) and those whose std is not to be trusted (``flagged``,
    :func:`wmrid.estimators.diagnostics.flagged_names`)."""
    scale = inflation["scale"]
    skip = set(undetermined)
    disc = inflation.get("discretisation") or {}
    slow = inflation.get("slow_speed") or {}
    cutoff = inflation.get("filter") or {}
    widened = (
        scale >= INFLATION_MARK or bool(disc.get("applied")) or bool(slow.get("applied")) or bool(cutoff.get("applied"))
    )
    fragile = set(slow.get("fragile") or [])
    inflated = [n for n in parameters if n not in skip and (widened or n in fragile)]
    if fragile & {"m11", "m12", "m22"}:
        inflated += [n for n in ("M11", "M12", "M22") if n not in inflated]
    meaning = []
    if inflation["applied"]:
        meaning.append(MODEL_ERROR_NOTE)
    if disc.get("applied"):
        meaning.append(DISCRETISATION_NOTE)
    if slow.get("applied"):
        meaning.append(SLOW_SPEED_NOTE)
    if cutoff.get("applied"):
        meaning.append(FILTER_NOTE)
    if fragile:
        meaning.append(FRAGILE_NOTE.format(", ".join(sorted(fragile))))
    model_error = ModelError.from_dict({
        **inflation,
        "meaning": "; ".join(meaning)
        or "the model holds within the log's noise, and the step is fine enough: no widening",
    })  # fmt: skip
    assert diagnostics.uncertainty is not None, "the uncertainty is recorded before its widening"
    out = replace(diagnostics, uncertainty=replace(diagnostics.uncertainty, model_error=model_error))
    out = replace(out, inflated=tuple(inflated))
    return replace(out, flagged=flagged_names(parameters, out))


def misfit_text(misfit: dict[str, Any]) -> str:
    """The statement of an applied :func:`prediction_misfit` (its worst wheel's figures)."""
    wheel = misfit["wheel"]
    ratio = misfit["ratio"]
    return PREDICTION_MISFIT_NOTE.format(
        side=("right", "left")[wheel],
        pe=f"{misfit['prediction_error_rms'][wheel]:.2g}",
        ratio=f"{ratio:.3g} times" if ratio < 1000 else "over 1000 times",
        sigma=f"{misfit['noise_rms'][wheel]:.2g}",
        share=f"{100 * misfit['share']:.2g}",
    )
