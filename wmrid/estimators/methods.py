"""The identification methods behind one interface: ``observer`` (the paper's), ``idim``, ``rls``, ``oe``.

Every method takes a log in memory (t (n,) s, eta (n, 2) rad/s, tau (n, 2) N m) and returns a
:class:`wmrid.estimators.estimate.BaseEstimate`.  The observer runs first in every case: it streams the log, checks
its excitation and gives the start of ``oe`` (which removes the output-error method's initial-guess
problem); :func:`run` then reports the chosen method's estimate through
:func:`wmrid.estimators.substitution.with_estimate`.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from dataclasses import dataclass, field, replace
from typing import Any

import numpy as np

from wmrid.core.choices import Method, values
from wmrid.core.errors import UsageError, WmridError, option
from wmrid.estimators.estimate import BaseEstimate
from wmrid.estimators.options import MethodOptions
from wmrid.estimators.parameter import Parameter
from wmrid.estimators.records import Verdict
from wmrid.estimators.result import IdentificationResult
from wmrid.estimators.substitution import with_estimate
from wmrid.model.payload import PayloadEstimate
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
    applied = (None if observer.diagnostics.delay is None else observer.diagnostics.delay.applied_s) or 0.0
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
class MethodRow:
    """One method's estimate in a comparison: what ``identify --method NAME`` reports, in short.

    description : the method in one line.  parameters : name -> :class:`~wmrid.estimators.parameter.Parameter`
    (value, std, unit, flags).  error_percent : name ->
    100 (value - truth) / |truth| where a truth was given.  seconds : the method's run time, s.  warnings, verdict,
    payload : its result's (payload: with ``--payload``, else None).  fit_percent : {"eta_r", "eta_l"} % of its
    model on the validation log (None: no validation log; a value None: not simulated or not finite).
    not_simulated : why its model could not be simulated there (None: it was).
    """

    description: str
    parameters: dict[str, Parameter]
    seconds: float | None
    warnings: tuple[str, ...]
    verdict: Verdict | None
    error_percent: dict[str, float] = field(default_factory=dict)
    payload: PayloadEstimate | None = None
    fit_percent: dict[str, float | None] | None = None
    not_simulated: str | None = None

    def to_dict(self) -> dict[str, Any]:
        """The row of ``wmrid compare``'s JSON: {"description", "parameters": {n: {"value", "std", "unit", "flags"[,
        "error_percent"]}}, "flagged", "marks", "seconds", "warnings", "verdict"[, "payload"][, "validation":
        {"fit_percent"[, "not_simulated"]}]}."""
        params = {}
        for name, parameter in self.parameters.items():
            entry = parameter.to_dict()
            if name in self.error_percent:
                entry["error_percent"] = self.error_percent[name]
            params[name] = entry
        row: dict[str, Any] = {
            "description": self.description, "parameters": params, "flagged": list(self.flagged),
            "marks": {name: parameter.mark for name, parameter in self.parameters.items()}, "seconds": self.seconds,
            "warnings": list(self.warnings), "verdict": None if self.verdict is None else self.verdict.to_dict(),
        }  # fmt: skip
        if self.payload is not None:
            row["payload"] = self.payload.to_dict()
        if self.fit_percent is not None:
            row["validation"] = {"fit_percent": dict(self.fit_percent)}
            if self.not_simulated is not None:
                row["validation"]["not_simulated"] = self.not_simulated
        return row

    @property
    def flagged(self) -> tuple[str, ...]:
        """The parameters whose std is not to be trusted (their "flagged" flag), in the parameters' order."""
        return tuple(name for name, parameter in self.parameters.items() if not parameter.trusted)


@dataclass(frozen=True)
class ValidationLog:
    """The second log every method's model was validated on in a comparison (``wmrid compare --validate``).

    Each row's fit % is its :attr:`MethodRow.fit_percent`.

    Attributes
    ----------
    log
        That log.
    samples
        Its samples.
    predictor
        How the wheel speeds were simulated open loop from its efforts (None: no method's model could be
        simulated).
    """

    log: str
    samples: int
    predictor: str | None

    def to_dict(self) -> dict[str, Any]:
        """The comparison JSON's ``validation``: {"log", "samples", "predictor"}."""
        return {"log": self.log, "samples": self.samples, "predictor": self.predictor}

    @classmethod
    def from_dict(cls, data: Mapping[str, Any]) -> ValidationLog:
        predictor = data.get("predictor")
        return cls(log=str(data["log"]), samples=int(data["samples"]),
                   predictor=None if predictor is None else str(predictor))  # fmt: skip


@dataclass(frozen=True)
class Comparison:
    """Every method's estimate on one log (:func:`wmrid.compare`); ``to_dict`` is the ``wmrid compare`` JSON.

    Attributes
    ----------
    source
        The log.
    methods
        Name -> :class:`MethodRow`, in the order run.
    validation
        The second log each model was validated on (:class:`ValidationLog`), or None.
    truth
        The true base parameters the errors are against, or None.
    """

    source: str
    methods: dict[str, MethodRow]
    validation: ValidationLog | None = None
    truth: dict[str, float] | None = None

    def to_dict(self) -> dict[str, Any]:
        methods = {name: row.to_dict() for name, row in self.methods.items()}
        out: dict[str, Any] = {"source": self.source, "methods": methods}
        if self.validation is not None:
            out["validation"] = self.validation.to_dict()
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

    methods: dict[str, MethodRow] = {}
    predictor = None
    for i, name in enumerate(names, 1):
        if stage is not None:
            stage(f"{name} ({i} of {len(names)})")
        est = estimate(name, log, observer, options)
        # the same honest std, flags and warnings as ``identify --method NAME``
        # (wmrid.estimators.substitution.with_estimate)
        result = observer if name == "observer" else with_estimate(observer, est, robot)
        table = result.table
        errors = {
            key: 100.0 * (parameter.value - truth[key]) / abs(truth[key])
            for key, parameter in table.items()
            if truth is not None and key in truth and truth[key]
        }
        fit_percent: dict[str, float | None] | None = None
        why = None
        if other is not None:
            form = observer.form if len(est.theta0) == observer.form.n_base else None
            why = unsimulated(form)
            if why:
                fit_percent = {"eta_r": None, "eta_l": None}
            else:
                fit = validation_fit(
                    other.t, other.eta, other.tau, np.asarray(est.theta0), observer.settings.torque_hold, form=form
                )
                fit_percent = {w: float(fit[w]) if np.isfinite(fit[w]) else None for w in ("eta_r", "eta_l")}
                predictor = fit["predictor"]
        methods[name] = MethodRow(
            description=DESCRIPTIONS[name], parameters=dict(table), seconds=est.seconds,
            warnings=tuple(result.warnings), verdict=result.verdict, error_percent=errors, payload=result.payload,
            fit_percent=fit_percent, not_simulated=why or None,
        )  # fmt: skip
    return Comparison(
        source=observer.source,
        methods=methods,
        validation=None if other is None else ValidationLog(other.source, len(other.t), predictor),
        truth=None if truth is None else {key: value for key, value in truth.items() if key in observer.parameters},
    )
