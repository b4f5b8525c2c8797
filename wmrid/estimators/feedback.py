"""The closed-loop check: is the observer's estimate biased by the feedback of the loop that recorded the log?

In closed loop the controller answers a disturbance (a caster's drag, the floor), so the efforts in the observer's
regressor carry it and least squares is no longer consistent (:mod:`wmrid.estimators.regression.iv` explains why).  The
bias is the same all along the log, so the jackknife cannot see it.  What can is a second estimate that the feedback
does not bias, or biases far less, computed on the same log: the Durbin-Wu-Hausman idea (Janot, Vandanjon & Gautier,
IEEE TCST 2014, propose it for robots).  The two agree up to noise when there is no feedback bias and differ beyond it
when there is.  A feedback bias needs a disturbance to feed back, and a disturbance shows in the observer's
prediction error (:func:`disturbance`); the check runs only then.

The second estimate: IDIM-IV (:func:`wmrid.estimators.regression.iv.identify_iv`) when the log carries the wheel-speed
reference (eta_ref_r, eta_ref_l), else IDIM (:func:`wmrid.estimators.regression.idim.identify_idim`), whose regressor
(the speeds) the feedback
reaches only through the tracking error the controller lets through.  Both are fitted on the observer's jackknife
segments, so the difference delta = theta0_observer - theta0_other has a delete-a-segment jackknife of its own
(the classical Hausman variance V_IV - V_LS needs the least-squares estimate to be efficient, which the observer
on coloured residuals is not).  When some |delta_j| exceeds the gate (FAMILY_ALPHA) in its jackknife std, wmrid
says so and reports the second estimate, with its own standard errors and checks
(:func:`wmrid.estimators.substitution.with_estimate`).
The second estimate's own errors that its checks measured (IDIM's
movement with its filter, the errors in variables of noisy speeds) join that std first (:func:`systematic_variance`):
a difference they explain is not feedback, and an estimate is never reported for a difference within its own
stated uncertainty.

Measured (``bench/accuracy/bench_coverage.py --robot amr --caster 0.02 --eta-noise 0.02 --tau-noise 0.01``, 20
seeds): see docs/explanation/checks.md, "The closed-loop check".
"""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import numpy as np

from wmrid.core.errors import NotIdentifiableError, UsageError, WmridError
from wmrid.core.wheel_log import LogStream
from wmrid.estimators.diagnostics import impossible_parameters
from wmrid.estimators.estimate import BaseEstimate
from wmrid.estimators.findings import FeedbackCheck
from wmrid.estimators.substitution import with_estimate
from wmrid.estimators.widening import with_covariance

#: The check reports the other estimate when some |delta_j| exceeds the gate, in jackknife std of delta_j: the
#: Student-t quantile (G - 1 dof) that keeps the chance of any of the m judged parameters passing it by noise alone
#: at FAMILY_ALPHA (Bonferroni): 3.8 std for 8 parameters on 40 s logs (19 dof), 4.6 on 20 s logs (9 dof).
FAMILY_ALPHA = 0.01
#: A disturbance is in evidence when the observer's prediction error exceeds the speeds' noise this many times
#: (:func:`wmrid.estimators.model_error.prediction_misfit`): sqrt(2), an unmodelled part at least as large as the noise.
DISTURBANCE_RATIO = 2.0**0.5
#: ... and this fraction of the speeds' rms: ten times the replay's discretisation error on noise-free 1 kHz logs
#: (measured at most 1.3e-5 on the multibody prototype), where the two methods differ by their own small biases
#: (IDIM's derivative and hold), not by feedback.  The light AMR's disturbance shows at 5e-3.
DISTURBANCE_SHARE = 1e-4
#: Logs longer than this (samples) are not checked: the second fit holds the whole log in memory.
MAX_SAMPLES = 2_000_000


def difference_test(
    a: BaseEstimate, b: BaseEstimate, names: tuple[str, ...], gate: float | None = None,
    systematic: np.ndarray | None = None,
) -> dict[str, Any]:  # fmt: skip
    """theta0 of ``a`` minus that of ``b``, judged by the delete-a-segment jackknife of the difference.

    Both need :attr:`BaseEstimate.segments` on the same grid.  Parameters either method leaves undetermined
    (infinite std) are not judged (their delta is reported as 0).  gate: in jackknife std (default: FAMILY_ALPHA's
    Bonferroni Student-t quantile for the judged count).  systematic (n0,): a variance added to the jackknife's,
    per parameter, for an error of ``b`` that is the same all along the log (:func:`systematic_variance`).
    Returns {"applied": some ratio > gate, "delta", "sd" (the jackknife's, with ``systematic``), "ratio" (per
    name), "largest_ratio", "largest", "gate", "dof"}.
    """
    from scipy.special import stdtrit  # scipy.special (~0.15 s): only when the check runs

    sa, sb = a.segments, b.segments
    if sa is None or sb is None or sa.grid != sb.grid:
        raise UsageError("difference_test needs both estimates' leave-one-segment-out fits on the same grid")
    delta = np.asarray(a.theta0, dtype=float) - np.asarray(b.theta0, dtype=float)
    loo = sa.loo - sb.loo
    g = loo.shape[0]
    centred = loo - loo.mean(axis=0)
    sd = np.sqrt((g - 1) / g * np.sum(centred**2, axis=0) + (0.0 if systematic is None else systematic))
    judged = np.isfinite(a.std) & np.isfinite(b.std) & np.isfinite(delta) & (sd > 0) & np.all(np.isfinite(loo), axis=0)
    with np.errstate(divide="ignore", invalid="ignore"):
        ratio = np.where(judged, np.abs(delta) / sd, 0.0)
    delta = np.where(judged, delta, 0.0)
    if gate is None:
        gate = float(stdtrit(g - 1, 1.0 - FAMILY_ALPHA / (2.0 * max(int(judged.sum()), 1))))
    j = int(np.argmax(ratio))
    return {
        "applied": bool(ratio[j] > gate),
        "delta": {n: float(v) for n, v in zip(names, delta, strict=True)},
        "sd": {n: float(v) for n, v in zip(names, sd, strict=True)},
        "ratio": {n: float(v) for n, v in zip(names, ratio, strict=True)},
        "largest_ratio": float(ratio[j]),
        "largest": names[j],
        "gate": gate,
        "dof": g - 1,
    }


def systematic_variance(other: BaseEstimate) -> tuple[np.ndarray, list[str]]:
    """(n0,) variance, per parameter, of the errors of ``other`` that its jackknife cannot see and its own checks
    measured (``diagnostics["checks"]``: IDIM's estimate at a lower filter cutoff and without the slow rows,
    :mod:`wmrid.estimators.regression.idim_checks`), delta_j^2 summed over the applied checks; and their names.

    Noise in the speeds biases IDIM's inertia towards zero (errors in variables) by the same amount all along the
    log, so it shows in the difference from the observer exactly as a feedback bias would.  Its mark is that the
    estimate moves with the filter's band (the cutoff check); a difference that this movement can explain is not
    evidence of feedback.  These are the terms the reported estimate's covariance takes in
    (:func:`wmrid.estimators.substitution.with_estimate`), so a difference called feedback is beyond the other
    estimate's own stated uncertainty too.
    """
    out = np.zeros(len(other.theta0))
    used = []
    for name, record in (other.diagnostics.get("checks") or {}).items():
        record = record or {}
        delta = record.get("delta")
        if record.get("applied") and delta is not None and len(delta) == len(out):
            out += np.nan_to_num(np.asarray(delta, dtype=float)) ** 2
            used.append(name)
    return out, used


def other_estimate(log: Any, result: Any, grid: tuple[float, float, int] | None = None) -> BaseEstimate:
    """IDIM-IV on ``log``'s reference when it has one, else IDIM, with the observer's settings (form, hold) and the
    jackknife segments ``grid`` (:func:`wmrid.estimators.regression.idim.jackknife_segments`; None: the method's
    own)."""
    t = np.asarray(log.t, dtype=np.float64)
    eta = np.asarray(log.eta, dtype=np.float64)
    tau = np.asarray(log.tau, dtype=np.float64)
    common = {
        "form": result.form, "torque_hold": result.settings.torque_hold,
        "control_rate": result.settings.control_rate, "grid": grid,
    }  # fmt: skip
    reference = getattr(log, "reference", None)
    if reference is not None:
        # IDIM-IV (~20 ms): only when the check runs, on a log with the reference
        from wmrid.estimators.regression.iv import identify_iv

        try:
            return identify_iv(t, eta, tau, reference, **common)
        except NotIdentifiableError:  # a reference that does not describe the motion: IDIM, as without one
            pass
    from wmrid.estimators.regression.idim import identify_idim  # IDIM (~20 ms): only when the check runs

    return identify_idim(t, eta, tau, **common)


def check(result: Any, log: Any, robot: Any = None, switch: bool = True) -> Any:
    """``result`` (the observer's) with ``diagnostics.feedback``: reporting the other estimate (on its own
    segments), with a warning, when the difference test (:func:`difference_test`) finds the observer's estimate
    biased; else the observer's with the closed-loop term delta delta^T added to its covariance (:func:`widened`).
    ``switch`` False (the user named the observer): the observer's estimate is kept even past the gate, widened by
    the difference as below it, with a warning that says the bias was found and how to get the other estimate.
    Only when the prediction error shows a disturbance (:func:`disturbance`): without one nothing feeds back, and
    on noise-free logs the two methods differ by their own tiny biases, which the difference test would see.

    log : the same log as the observer read (a :class:`wmrid.core.wheel_log.LogStream` or arrays t, eta, tau, optionally
    reference).  Logs over MAX_SAMPLES samples, and logs where the other method cannot fit, are not checked (the
    record says why).
    """
    est = result.estimate
    if est is None or est.segments is None or result.method != "observer":
        return result
    evidence = disturbance(result)
    if not evidence["disturbance"]:
        why = "no disturbance shows in the prediction error, so none feeds back"
        return _with_record(result, FeedbackCheck.from_dict({"checked": False, **evidence, "why": why}))
    samples = result.log_info.samples or 0
    if samples > MAX_SAMPLES:
        why = f"the log has {samples} samples, more than the check holds in memory"
        return _with_record(result, FeedbackCheck(checked=False, why=why))
    if isinstance(log, LogStream):
        log = log.read()
    try:
        with np.errstate(all="ignore"):
            matched = other_estimate(log, result, est.segments.grid)
            systematic, terms = systematic_variance(matched)
            test = difference_test(est, matched, result.form.base_names, systematic=systematic)
            other = other_estimate(log, result) if test["applied"] else matched
    except (WmridError, np.linalg.LinAlgError) as err:
        return _with_record(result, FeedbackCheck(checked=False, why=f"{type(err).__name__}: {err}"))
    label = {"iv": "instrumental-variable (IDIM-IV, the logged reference as instruments)", "idim": "IDIM"}
    # other_systematic: its own checks whose difference joined the difference's variance
    record = FeedbackCheck.from_dict(
        {"checked": True, "against": other.method, **evidence, **test, "reported": result.method,
         "other_systematic": terms}
    )  # fmt: skip
    impossible: set[str] = set()
    if test["applied"] and switch:  # never report an estimate no robot has (the evidence says it is the worse one)
        candidate = with_estimate(result, other, robot)
        impossible = impossible_parameters(candidate.parameters)
    if not test["applied"] or not switch or impossible:
        out = widened(result, np.array(list(test["delta"].values())), matched.std, record, robot)
        if not test["applied"]:
            return out
        big = [n for n, r in test["ratio"].items() if r > test["gate"]]
        other_name = "IDIM-IV" if matched.method == "iv" else "IDIM"
        why = (
            f"the {other_name} estimate has values no robot has ({', '.join(sorted(impossible))}), so the observer's "
            "is kept"
            if impossible
            else f"the observer's estimate is kept as --method observer asks (the default, --method auto, reports the "
            f"{other_name} estimate)"
        )
        text = (
            f"closed-loop bias: the observer's {', '.join(big)} differ from the {label[matched.method]} estimate by up "
            f"to {test['largest_ratio']:.1f} std of their difference (noise explains up to {test['gate']:.1f}), the "
            f"mark of a controller answering a disturbance through the efforts; {why}, its std widened by that "
            "difference"
        )
        if impossible:
            kept = out.diagnostics.feedback or record
            out = _with_record(out, replace(kept, not_reported=f"{other_name}: {', '.join(sorted(impossible))}"))
        return replace(out, warnings=(text, *out.warnings))
    out = candidate
    record = replace(record, reported=other.method)
    big = [n for n, r in test["ratio"].items() if r > test["gate"]]
    text = (
        f"closed-loop bias: the observer's {', '.join(big)} differ from the {label[other.method]} estimate by up to "
        f"{test['largest_ratio']:.1f} std of their difference (noise explains up to {test['gate']:.1f}), the mark of "
        "a controller answering a disturbance (a caster, the floor) through the efforts; reporting the "
        f"{other.method.upper() if other.method == 'iv' else 'IDIM'} estimate instead of the observer's "
        "(--method observer keeps the observer's)"
    )
    if other.method == "idim":
        text += (
            ", which the controller's answer biases less; logging the wheel-speed reference (columns eta_ref_r, "
            "eta_ref_l) gives the IV estimate, which it does not bias"
        )
    return replace(_with_record(out, record), warnings=(text, *out.warnings))


def _with_record(result: Any, record: FeedbackCheck) -> Any:
    """``result`` with ``record`` as its ``diagnostics.feedback``."""
    return replace(result, diagnostics=replace(result.diagnostics, feedback=record))


def widened(result: Any, delta: np.ndarray, other_std: np.ndarray, record: FeedbackCheck, robot: Any = None) -> Any:
    """The observer's ``result`` with the closed-loop term, ``record`` as ``diagnostics.feedback``.

    The observer's estimate is the other method's plus delta (n0,), so its error is the other's error plus delta,
    and its covariance becomes
    C + delta delta^T, C the observer's own with its rows and columns scaled up to the other method's std
    (other_std (n0,)): in closed loop the observer's jackknife understates its spread as well.  Below the gate
    delta holds the part of the feedback bias too small to prove on this log.  Measured on the light AMR's 40 s
    logs (docs/explanation/checks.md): m11 beyond 3 std in 18 % of seeds without the term, 3 % with it.
    The parameters it widens by more than INFLATION_MARK are marked inflated.
    """
    est = result.estimate
    delta = np.where(np.isfinite(delta), delta, 0.0)
    cov = np.asarray(est.cov, dtype=float)
    own = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = np.where((own > 0) & np.isfinite(other_std), np.maximum(1.0, other_std / own), 1.0)
    other = {"iv": "IDIM-IV", "idim": "IDIM"}.get(record.against or "", "the other method")
    note = (
        f"the prediction error shows a disturbance the loop may feed back: the std was raised to at least {other}'s "
        "and the difference from it added (the closed-loop term)"
    )
    out, grown = with_covariance(result, cov * np.outer(scale, scale) + np.outer(delta, delta), note, robot)
    return _with_record(out, replace(record, widened=tuple(grown)))


def disturbance(result: Any) -> dict[str, Any]:
    """Whether the observer's prediction error shows a disturbance that the loop could feed back: {"disturbance":
    its worst wheel's error above DISTURBANCE_RATIO times the speeds' noise and DISTURBANCE_SHARE of their rms,
    "prediction_error_ratio", "prediction_error_share"} (:func:`wmrid.estimators.model_error.prediction_misfit`'s
    figures;
    without a measured noise floor, no evidence)."""
    misfit = result.diagnostics.prediction_misfit
    ratio, share = misfit.ratio, misfit.share
    found = ratio is not None and share is not None and ratio > DISTURBANCE_RATIO and share > DISTURBANCE_SHARE
    return {"disturbance": bool(found), "prediction_error_ratio": ratio, "prediction_error_share": share}
