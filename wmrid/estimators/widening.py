"""Terms the std carries beyond the jackknife, each added to a result's covariance as delta delta^T.

The jackknife sees how an estimate varies along a log; an error the same all along it, it cannot see.  Three such
errors are measured by identifying the log another admissible way and taking the change delta of theta0:

* the timing term: the efforts' estimated delay moved by its resolution (:func:`with_timing_term`), or, when the
  timing check left them as stamped, moved to the delay the log cannot rule out
  (:func:`wmrid.pipeline.timing.carry_unresolved_delay`, :func:`with_unresolved_timing`);
* the hold term: a slow log read under foh instead of zoh when its controller's rate is unknown
  (:func:`with_hold_term`);
* the closed-loop term: the observer against IDIM/IV (:func:`wmrid.estimators.feedback.widened`).

:func:`with_covariance` is the one place any of them widens a result: the parameters' std, ``theta0_cov``, the
payload's std, the inflated and flagged lists and the widening mark's legend.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import TYPE_CHECKING

import numpy as np

from wmrid.estimators.diagnostics import flagged_names
from wmrid.estimators.estimate import BaseEstimate
from wmrid.estimators.findings import DelayApplied, HoldTerm, ModelError, TimingCheck, TimingTerm, Uncertainty
from wmrid.estimators.model_error import INFLATION_MARK
from wmrid.estimators.result import reported_names
from wmrid.model.base_params import derived_with_std
from wmrid.model.payload import payload_with_std
from wmrid.model.robot import Robot

if TYPE_CHECKING:
    from wmrid.estimators.result import IdentificationResult


def with_covariance(
    result: IdentificationResult, cov: np.ndarray, note: str, robot: Robot | None = None, mark: float | None = None
) -> tuple[IdentificationResult, list[str]]:
    """(``result`` reporting its estimate with the covariance ``cov`` (n0, n0), the parameters it widened): their std
    recomputed (:func:`wmrid.model.base_params.derived_with_std`), ``theta0_cov`` and the payload's std (with ``robot``)
    too, the parameters grown beyond INFLATION_MARK times the old std added to ``diagnostics.inflated`` (a widened
    std is trusted: ``["flagged"]`` is made again, :func:`wmrid.estimators.diagnostics.flagged_names`), and ``note``
    (what widened them) to the meaning of the widening mark (``diagnostics.uncertainty.model_error.meaning``)
    when any grew.  The one place a term (timing, hold,
    closed loop) widens a result.  ``mark``: the growth that marks a parameter (default INFLATION_MARK)."""
    mark = INFLATION_MARK if mark is None else mark
    est = result.estimate
    assert est is not None
    parameters = derived_with_std(np.asarray(est.theta0, dtype=float), cov, result.form.base_names)
    parameters = {name: parameters[name] for name in reported_names(result.form)}
    grown = [
        name for name, (_, std) in parameters.items()
        if math.isfinite(std) and std > mark * result.parameters[name][1]
    ]  # fmt: skip
    diagnostics = result.diagnostics
    if grown:
        unc = diagnostics.uncertainty or Uncertainty()
        model_error = unc.model_error or ModelError()
        before = model_error.meaning if diagnostics.inflated else None
        model_error = replace(model_error, meaning=f"{before}; {note}" if before else note)
        diagnostics = replace(diagnostics, uncertainty=replace(unc, model_error=model_error))
    inflated = set(diagnostics.inflated or ()) | set(grown)
    diagnostics = replace(diagnostics, inflated=tuple(n for n in parameters if n in inflated))
    diagnostics = replace(diagnostics, flagged=flagged_names(parameters, diagnostics))
    payload = result.payload
    if payload is not None and robot is not None:
        payload = payload_with_std(np.asarray(est.theta0, dtype=float), cov, robot.reference)
    out = replace(
        result, parameters=parameters, diagnostics=diagnostics, estimate=replace(est, cov=cov), theta0_cov=cov,
        payload=payload,
    )  # fmt: skip
    return out, grown


def with_hold_term(
    result: IdentificationResult, zoh: BaseEstimate, foh: IdentificationResult, robot: Robot | None = None
) -> IdentificationResult:
    """``result`` with delta delta^T added to its covariance, delta the observer's estimate under --torque-hold foh
    (``foh``) minus that under zoh (``zoh``, the observer's estimate behind ``result``): on a log slower than the hold
    check's 400 Hz whose controller rate is unknown, the hold is uncertain between those two.  Measured on the light
    AMR (bench/accuracy/bench_timing.py, 1 kHz controller): at 100 Hz zoh and foh bias friction by about the same
    amount in opposite directions, so the bracket covers the truth.  Parameters widened beyond INFLATION_MARK are
    marked.  When the closed-loop check reported another method, the observer's zoh-to-foh change stands for that
    method's (an approximation: every method reads the efforts under the same hold)."""
    est = result.estimate
    if est is None or foh.estimate is None or len(foh.estimate.theta0) != len(zoh.theta0):
        return result
    delta = np.asarray(foh.estimate.theta0, dtype=float) - np.asarray(zoh.theta0, dtype=float)
    if len(delta) != len(est.theta0) or not np.all(np.isfinite(delta)):
        return result
    note = "the hold of the efforts is unknown on this slow log: the change from zoh to foh was added to the covariance"
    result, grown = with_covariance(result, np.asarray(est.cov, dtype=float) + np.outer(delta, delta), note, robot)
    timing = replace(
        result.diagnostics.timing or TimingCheck(), hold_term=HoldTerm(delta=delta.tolist(), widened=tuple(grown))
    )
    diagnostics = replace(result.diagnostics, timing=timing)
    warnings = list(result.warnings)
    if grown:
        warnings.append(
            f"the log ({1.0 / result.log_info.rate_hz * 1e3:.3g} ms steps) does not say how fast the controller "
            f"that held its efforts was; the estimates under a hold over each step and a much faster controller "
            f"differ, and the std of {', '.join(grown)} carries that difference: give --control-rate HZ if known"
        )
    return replace(result, diagnostics=diagnostics, warnings=tuple(warnings))


#: The unresolved-delay term marks (and warns about) a parameter only when it grows its std by this factor: the
#: check resolves an on-time sinusoid's delay to 0.1 ms, and what that leaves grows the friction's std by 5-20 %
#: on every such log; a flag on every log would say nothing.
UNRESOLVED_MARK = 1.5


def with_unresolved_timing(
    result: IdentificationResult, delta: np.ndarray, delay: float, how: str, warning: str, robot: Robot | None = None
) -> IdentificationResult:
    """``result`` (its efforts used as stamped) with delta delta^T added to its covariance, delta (n0,) the change of
    theta0 when the efforts are read ``delay`` s earlier (:func:`wmrid.estimators.timing_check.unresolved_delay`;
    ``how`` it was
    found: "identified again" or "the profile's slope"); recorded as ``diagnostics.timing.timing_term``;
    parameters grown beyond UNRESOLVED_MARK are marked and ``warning`` is said."""
    est = result.estimate
    assert est is not None
    delta = np.asarray(delta, dtype=float)
    if len(delta) != len(est.theta0) or not np.all(np.isfinite(delta)):
        return result
    note = (
        f"the efforts' delay could not be told from zero; reading them {delay * 1e3:+.2g} ms earlier (what the log "
        "cannot rule out) moves the estimate, and that change was added to the covariance"
    )
    cov = np.asarray(est.cov, dtype=float) + np.outer(delta, delta)
    widened, grown = with_covariance(result, cov, note, robot, mark=UNRESOLVED_MARK)
    term = TimingTerm(delay_s=delay, delta=delta.tolist(), found_by=how, widened=tuple(grown))
    diagnostics = replace(
        widened.diagnostics, timing=replace(widened.diagnostics.timing or TimingCheck(), timing_term=term)
    )
    warnings = (warning, *widened.warnings) if grown and warning else tuple(widened.warnings)
    return replace(widened, diagnostics=diagnostics, warnings=warnings)


def with_timing_term(
    base: IdentificationResult, moved: IdentificationResult, record: DelayApplied, warnings: list[str], step: float,
    robot: Robot | None = None,
) -> IdentificationResult:  # fmt: skip
    """``base`` (identified with the estimated delay applied) with delta delta^T added to its covariance, delta the
    change of theta0 when the delay moves by ``step`` s (``moved``): the estimate's uncertainty about the timing,
    which its jackknife cannot see.  The parameters it widens by more than INFLATION_MARK are marked inflated."""
    est = base.estimate
    assert est is not None
    assert moved.estimate is not None
    theta0 = np.asarray(est.theta0, dtype=float)
    delta = np.asarray(moved.estimate.theta0, dtype=float) - theta0
    if len(delta) != len(theta0) or not np.all(np.isfinite(delta)):
        delta = np.zeros_like(theta0)
    note = (
        f"the efforts' delay was estimated and applied; moving it by {step * 1e3:.2g} ms (its resolution) moved "
        "the estimate, and that change was added to the covariance"
    )
    widened, grown = with_covariance(base, np.asarray(est.cov, dtype=float) + np.outer(delta, delta), note, robot)
    term = TimingTerm(step_s=step, delta=delta.tolist(), widened=tuple(grown))
    diagnostics = replace(widened.diagnostics, delay=replace(record, timing_term=term))
    return replace(widened, diagnostics=diagnostics, warnings=tuple(warnings) + tuple(base.warnings))
