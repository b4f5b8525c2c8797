"""Another method's estimate reported on the observer's run of the same log (:func:`with_estimate`): every method
but the observer starts from the observer's run, and the closed-loop check may report IDIM or IDIM-IV instead."""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np

from wmrid.estimators.estimate import BaseEstimate
from wmrid.estimators.findings import MethodFigures, Uncertainty
from wmrid.estimators.model_error import record_widening
from wmrid.estimators.observer.observe import CLOSED_LOOP_CAVEAT
from wmrid.estimators.result import IdentificationResult, MethodSettings, finite_or_none, reported_names
from wmrid.estimators.uncertainty import interval_factor
from wmrid.model.base_params import derived_with_std
from wmrid.model.dynamics import RegressorForm
from wmrid.model.payload import payload_with_std
from wmrid.model.robot import Robot

#: Diagnostics that describe the observer's run on the log (kept, and listed as such, under another method).
OBSERVER_DIAGNOSTICS = (
    "lambda_min_gamma", "lambda_max_gamma", "condition_number_scaled", "weakest_directions", "undetermined",
    "not_separable", "at_box_boundary", "start_sensitivity", "structural_mismatch", "prediction_error_rms",
)  # fmt: skip


def with_estimate(result: IdentificationResult, est: BaseEstimate, robot: Robot | None = None) -> IdentificationResult:
    """``result`` (the observer's run on a log) reporting another method's estimate ``est`` of the same log.

    The parameters, their standard errors, the payload and the warnings about the estimate become the
    method's; what describes the log (notes, excitation, the observer's history and intermediate
    parameters, kept as the observer's) stays.  ``diagnostics.method`` holds the method's own
    figures and ``diagnostics.observer_parameters`` the observer's estimate for comparison.
    """
    diag = result.diagnostics
    model_error = None if diag.uncertainty is None else diag.uncertainty.model_error
    inflation = {"scale": 1.0, "applied": False} if model_error is None else model_error.to_dict()
    inflation.pop("meaning", None)
    # The model-error scale and the low-speed difference are evidence about the log and the model, so they carry
    # over to another method: the log departs from the same model (and in the same slow parts) whichever method
    # reads it.  The discretisation term is the observer's own replay and does not.
    # A method that refits itself without the slow parts (IDIM, wmrid.estimators.regression.idim_checks) uses its own
    # difference
    # instead of the observer's, and its other alternative fit (another filter cutoff) the same way.
    slow = inflation.get("slow_speed") or {}
    own = est.diagnostics.get("checks") or {}
    if own.get("slow_speed"):
        slow = {**own["slow_speed"], "method": est.method}
    if inflation.get("discretisation"):
        inflation["discretisation"] = {**inflation["discretisation"], "applied": False, "observer_only": True}
    if slow:
        inflation["slow_speed"] = {**slow, "fragile": []}
    if own.get("cutoff"):
        inflation["filter"] = {**own["cutoff"], "method": est.method}
    cov = np.array(est.cov, dtype=float) * inflation["scale"] ** 2  # the same log departs from the same model
    timing = (None if diag.delay is None else diag.delay.timing_term) or (
        None if diag.timing is None else diag.timing.timing_term
    )
    terms = [slow, inflation.get("filter") or {}]
    if timing is not None and timing.widened:  # the efforts' timing is as uncertain whichever method reads them
        terms.append({"applied": True, "delta": timing.delta})
    for term in terms:
        if term.get("applied") and term.get("delta") is not None and len(term["delta"]) == len(est.theta0):
            delta = np.asarray(term["delta"], dtype=float)
            cov = cov + np.outer(delta, delta)
    form = result.form if len(est.theta0) == result.form.n_base else RegressorForm("general")
    parameters = derived_with_std(np.asarray(est.theta0, dtype=float), cov, form.base_names)
    parameters = {name: parameters[name] for name in reported_names(form)}
    observer_parameters = {name: {"value": v, "std": finite_or_none(e)} for name, (v, e) in
                           result.parameters.items()}  # fmt: skip
    method = MethodFigures.from_dict({"name": est.method, "seconds": est.seconds, "dof": est.dof, **est.diagnostics})
    from_observer = tuple(k for k in OBSERVER_DIAGNOSTICS if getattr(diag, k) is not None)
    dof = est.dof
    uncertainty = Uncertainty(
        method=est.diagnostics.get("uncertainty", f"standard errors of method {est.method}"),
        segments=est.diagnostics.get("segments"),
        dof=dof,
        interval_factor={
            "95%": interval_factor(0.95, dof) if dof else 1.959964,
            "99.7%": interval_factor(0.9973, dof) if dof else 2.999977,
        },
        meaning="value +/- interval_factor * std covers the truth with that probability when the disturbances "
        "do not feed back into the efforts",
        caveat=CLOSED_LOOP_CAVEAT,
    )
    diagnostics = replace(diag, observer_parameters=observer_parameters, method=method, from_observer=from_observer,
                          uncertainty=uncertainty)  # fmt: skip
    # the per-parameter warnings (poorly determined, impossible values) are made by settle, from these numbers
    base_names = form.base_names
    undetermined = [name for name in base_names if not math.isfinite(parameters[name][1])]
    diagnostics = record_widening(diagnostics, inflation, parameters, undetermined)
    warnings = [*result.warnings, *est.warnings]
    payload_est = None
    if result.payload is not None and robot is not None:
        payload_est = payload_with_std(np.asarray(est.theta0, dtype=float), cov, robot.reference)
    from wmrid.estimators.verdict import settle  # the verdict's checks (~15 ms): only when another estimate is reported

    used = est.diagnostics  # the method's own figures: the cutoff it used, its weighting, its forgetting factor
    hold = result.observer_settings  # every method reads the efforts under the observer's hold
    method_settings = MethodSettings(
        method=est.method, torque_hold=hold.torque_hold, control_rate=hold.control_rate,
        cutoff_hz=used.get("cutoff_hz"), weighted=used.get("weighted"), forgetting=used.get("forgetting"),
    )  # fmt: skip
    return settle(replace(
        result, parameters=parameters, theta0_cov=cov, diagnostics=diagnostics, warnings=tuple(warnings),
        payload=payload_est, method=est.method, estimate=replace(est, cov=cov), method_settings=method_settings,
    ))  # fmt: skip
