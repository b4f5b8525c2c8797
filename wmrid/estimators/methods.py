"""The identification methods behind one interface: ``observer`` (the paper's), ``idim``, ``rls``, ``oe``.

Every method takes a log in memory (t (n,) s, eta (n, 2) rad/s, tau (n, 2) N m) and returns a
:class:`wmrid.estimators.estimate.BaseEstimate`.  The observer runs first in every case: it streams the log, checks
its excitation and gives the start of ``oe`` (which removes the output-error method's initial-guess
problem); :func:`run` then reports the chosen method's estimate through
:func:`wmrid.estimators.substitution.with_estimate`.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass, replace
from typing import Any

import numpy as np

from wmrid.core.choices import Method, values
from wmrid.core.errors import UsageError, WmridError, option
from wmrid.estimators.estimate import BaseEstimate
from wmrid.estimators.options import MethodOptions
from wmrid.estimators.result import IdentificationResult, payload_dict
from wmrid.estimators.substitution import with_estimate
from wmrid.model.robot import Robot

METHODS = values(Method, without=("auto",))
DESCRIPTIONS = {
    "observer": "the paper's observer-based adaptive estimator (Eqs. 26-37), no accelerations",
    "idim": "inverse dynamic model, least squares on zero-phase low-pass filtered and differentiated speeds",
    "iv": "instrumental variables (IDIM-IV): IDIM with the logged wheel-speed reference as instruments, "
    "consistent under feedback",
    "rls": "recursive least squares with forgetting on the IDIM regression",
    "oe": "output error: simulate the model on the log's torques and minimise the speed error, from the observer",
}


def check_method(name: str) -> str:
    if name not in METHODS:
        raise UsageError(f"{option('method')} must be one of {', '.join(METHODS)}, got {name!r}")
    return name


def estimate(name: str, log: Any, observer: IdentificationResult, options: MethodOptions) -> BaseEstimate:
    """Method ``name``'s estimate on ``log`` (in memory); ``observer`` is the observer's result on the same log.

    Errors of the methods are re-raised with the log's name in front, like every other wmrid error.
    """
    check_method(name)
    if observer.method != "observer":
        raise UsageError(
            f"the observer's run reports method {observer.method!r}: give identify(..., feedback=False)'s result"
        )
    if name == "observer":
        assert observer.estimate is not None
        return observer.estimate
    t = np.asarray(log.t, dtype=np.float64)
    eta = np.asarray(log.eta, dtype=np.float64)
    tau = np.asarray(log.tau, dtype=np.float64)
    applied = (observer.diagnostics.get("delay") or {}).get("applied_s") or 0.0
    if applied:  # the efforts' delay the observer's run applied (identify(..., delay=)): the same log for every method
        # IDIM's rows (~10 ms): only a log the observer's run shifted
        from wmrid.estimators.regression.idim_rows import shifted

        tau = shifted(t, tau, -applied)
    source = getattr(log, "source", observer.source)
    try:
        if name == "idim":
            # each method's estimator is loaded only when asked for
            from wmrid.estimators.regression.idim import identify_idim

            # the observer's form: IDIM models the casters' drag too when the observer does (wheel+caster)
            # and the effort held as the observer assumed (--torque-hold, --control-rate)
            hold = {"torque_hold": observer.settings.torque_hold, "control_rate": observer.settings.control_rate}
            return identify_idim(
                t, eta, tau, cutoff_hz=options.cutoff_hz, weighted=options.weighted, form=observer.form, **hold
            )
        if name == "iv":
            # each method's estimator is loaded only when asked for
            from wmrid.estimators.regression.iv import identify_iv

            reference = getattr(log, "reference", None)
            if reference is None:
                raise UsageError(
                    f"{option('method', 'iv')} needs the wheel-speed reference (set-points) the controller tracked: "
                    "columns "
                    f"eta_ref_r, eta_ref_l, or name yours with {option('columns')} eta_ref_r=...,eta_ref_l=..."
                )
            hold = {"torque_hold": observer.settings.torque_hold, "control_rate": observer.settings.control_rate}
            return identify_iv(
                t, eta, tau, reference, cutoff_hz=options.cutoff_hz, weighted=options.weighted, form=observer.form,
                **hold,
            )  # fmt: skip
        if name == "rls":
            # each method's estimator is loaded only when asked for (RLS: numba kernels)
            from wmrid.estimators.regression.rls import identify_rls

            hold = {"torque_hold": observer.settings.torque_hold, "control_rate": observer.settings.control_rate}
            return identify_rls(
                t, eta, tau, forgetting=options.forgetting, cutoff_hz=options.cutoff_hz, form=observer.form, **hold
            )
        # output error: scipy.optimize (~0.3 s), only for --method oe
        from wmrid.estimators.output_error import identify_oe

        assert observer.estimate is not None
        est = identify_oe(
            t,
            eta,
            tau,
            np.asarray(observer.estimate.theta0),
            torque_hold=observer.settings.torque_hold,
            form=observer.form,
        )
        diagnostics = {
            **est.diagnostics,
            "uncertainty": "cluster-robust sandwich over contiguous segments of the log",
            "segments": est.diagnostics.get("clusters"),
        }
        return replace(est, diagnostics=diagnostics)
    except WmridError as err:
        if str(err).startswith(source):
            raise
        raise type(err)(f"{source}: {name}: {err}") from err


def run(
    name: str, log: Any, observer: IdentificationResult, options: MethodOptions, robot: Robot | None = None
) -> IdentificationResult:
    """The observer's result on ``log`` reporting method ``name``'s estimate (itself for ``observer``)."""
    if name == "observer":
        return observer
    return with_estimate(observer, estimate(name, log, observer, options), robot)


@dataclass(frozen=True)
class Comparison:
    """Every method's estimate on one log (:func:`compare`); ``to_dict`` is the ``wmrid compare`` JSON.

    methods : name -> {"description", "parameters": {n: {"value", "std", "unit"[, "error_percent"]}}, "flagged",
        "marks", "seconds", "warnings", "verdict"[, "validation": {"fit_percent": {"eta_r", "eta_l"}}]}, in the order
        run.
    validation : {"log", "samples", "predictor"} of the second log each model was validated on, or None.
    truth : the true base parameters the errors are against, or None.
    """

    source: str
    methods: dict[str, dict[str, Any]]
    validation: dict[str, Any] | None = None
    truth: dict[str, float] | None = None

    def to_dict(self) -> dict[str, Any]:
        out: dict[str, Any] = {"source": self.source, "methods": self.methods}
        if self.validation is not None:
            out["validation"] = self.validation
        if self.truth is not None:
            out["truth"] = self.truth
        return out


def compare(
    log: Any,
    observer: IdentificationResult,
    options: MethodOptions,
    names: tuple[str, ...] = METHODS,
    *,
    other: Any = None,
    truth: dict[str, float] | None = None,
    stage: Callable[[str], None] | None = None,
    robot: Robot | None = None,
) -> Comparison:
    """Every method in ``names`` on ``log`` (in memory; ``observer`` is the observer's result on it), JSON-ready.

    {"methods": {name: {"description", "parameters": {n: {"value", "std", "unit", "flags"[, "error_percent"]}},
    "flagged", "marks" ({n: "", "†", "!" or "†!"}: :attr:`wmrid.estimators.parameter.Parameter.mark`),
    "seconds", "warnings"[, "validation": {"fit_percent": {"eta_r", "eta_l"}}]}}, ...}.  The std, flags and
    warnings are those ``identify --method NAME`` reports (model-error widenings included); the parameters are
    the form's (caster drag too under ``--friction wheel+caster``).  ``other`` : a second
    log to validate each model on (:func:`wmrid.model.predict.validation_fit`); ``truth`` : true base parameters.
    ``stage`` : called with each method's name as it starts (a progress display).  ``robot``: the robot the
    observer's run estimated a payload against (its row's ``"payload"``, when the observer's result has one).
    """
    from wmrid.model.predict import unsimulated, validation_fit  # the predictor's numba kernel: only compare's fits

    methods: dict[str, dict[str, Any]] = {}
    predictor = None
    for i, name in enumerate(names, 1):
        if stage is not None:
            stage(f"{name} ({i} of {len(names)})")
        est = estimate(name, log, observer, options)
        # the same honest std, flags and warnings as ``identify --method NAME``
        # (wmrid.estimators.substitution.with_estimate)
        result = observer if name == "observer" else with_estimate(observer, est, robot)
        params = {}
        table = result.table
        for key, parameter in table.items():
            entry = parameter.to_dict()
            if truth is not None and key in truth and truth[key]:
                entry["error_percent"] = 100.0 * (parameter.value - truth[key]) / abs(truth[key])
            params[key] = entry
        row: dict[str, Any] = {
            "description": DESCRIPTIONS[name],
            "parameters": params,
            "flagged": list(result.diagnostics.get("flagged", [])),
            "marks": {key: parameter.mark for key, parameter in table.items()},
            "seconds": est.seconds,
            "warnings": list(result.warnings),
            "verdict": result.verdict,
        }
        if result.payload is not None:
            row["payload"] = payload_dict(result.payload)
        if other is not None:
            form = observer.form if len(est.theta0) == observer.form.n_base else None
            why = unsimulated(form)
            if why:
                row["validation"] = {"fit_percent": {"eta_r": None, "eta_l": None}, "not_simulated": why}
            else:
                fit = validation_fit(
                    other.t, other.eta, other.tau, np.asarray(est.theta0), observer.settings.torque_hold, form=form
                )
                fit_percent = {w: fit[w] if np.isfinite(fit[w]) else None for w in ("eta_r", "eta_l")}
                row["validation"] = {"fit_percent": fit_percent}
                predictor = fit["predictor"]
        methods[name] = row
    return Comparison(
        source=observer.source,
        methods=methods,
        validation=None if other is None else {"log": other.source, "samples": len(other.t), "predictor": predictor},
        truth=None if truth is None else {key: value for key, value in truth.items() if key in observer.parameters},
    )
