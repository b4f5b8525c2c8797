"""The identification result every method returns (:class:`IdentificationResult`) and its JSON form.

``to_dict`` gives the document ``identify --format json`` prints, with a ``schema_version``; :func:`from_dict` reads
one back (``report``, ``monitor`` and ``compare`` read saved results through it), so that
``from_dict(r.to_dict()).to_dict() == r.to_dict()``.  The JSON keeps the history decimated to at most
``JSON_HISTORY_POINTS`` samples and the intermediate parameters' standard errors, not their covariance: a result
read back carries those, and the base parameters' full covariance under ``estimate``.  The pieces of the JSON (null
for NaN and inf, the estimate, the decimated history) are :mod:`wmrid.estimators.result_json`'s.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any, Protocol

import numpy as np

from wmrid.core.errors import LogFormatError
from wmrid.estimators.estimate import BaseEstimate
from wmrid.estimators.findings import Diagnostics
from wmrid.estimators.observer.settings import ObserverSettings
from wmrid.estimators.parameter import Parameter, parameter_table
from wmrid.estimators.records import LogInfo, Validation, Verdict
from wmrid.estimators.result_json import (
    JSON_HISTORY_POINTS as JSON_HISTORY_POINTS,
    box,
    estimate_dict,
    finite_or_none as finite_or_none,
    floats,
    history_dict,
)
from wmrid.model.dynamics import THETA0_UNITS, RegressorForm
from wmrid.model.payload import PayloadEstimate

#: Reported parameter names, in report order.
REPORTED = ("m11", "m12", "m22", "M11", "M12", "M22", "Vc", "Fv1", "Fv2", "Fd1", "Fd2")


def reported_names(form: RegressorForm) -> tuple[str, ...]:
    """The reported names for ``form``: REPORTED, then its caster-drag parameters."""
    return REPORTED + form.base_names[8:]


#: Version of the JSON document :meth:`IdentificationResult.to_dict` writes.  1: the first with a version (the
#: documents before it are read as version 1 too: it only added ``schema_version`` and ``estimate``).  A document
#: of a newer version is refused by :func:`from_dict` with a message, not misread.  2: a result of another method
#: than the observer has that method's ``settings`` (:class:`MethodSettings`) and the observer's run's under
#: ``observer_settings`` (version 1 put the observer's in ``settings`` whatever the method; both are read).
SCHEMA_VERSION = 2


class LogLike(Protocol):
    """A wheel log in memory (:class:`wmrid.core.wheel_log.WheelLog`, whose fields are read-only, or the like): read,
    never set."""

    @property
    def t(self) -> np.ndarray: ...
    @property
    def eta(self) -> np.ndarray: ...
    @property
    def tau(self) -> np.ndarray: ...
    @property
    def source(self) -> str: ...
    @property
    def notes(self) -> tuple[str, ...]: ...


@dataclass(frozen=True)
class History:
    """Decimated per-sample record: t (m,) s, theta (m, 2, p) projected estimate, e (m, 2) rad/s prior
    prediction error, lambda_min (m,) smallest eigenvalue of Gamma."""

    t: np.ndarray
    theta: np.ndarray
    e: np.ndarray
    lambda_min: np.ndarray


@dataclass(frozen=True)
class ObserverRun:
    """The paper's observer run on the log (Eqs. 26-36): what it was given and what it found in its own terms.

    Attributes
    ----------
    settings
        Gain, start and box (:class:`ObserverSettings`).
    start_source
        Where the start came from.
    theta
        (2, p) intermediate parameters, projected onto the box.
    theta_unconstrained
        (2, p) intermediate parameters, not projected onto the box.
    theta_cov
        (2p, 2p) their covariance.
    history
        The decimated per-sample record, or None (a result read back from a document without one).
    """

    settings: ObserverSettings
    start_source: str
    theta: np.ndarray
    theta_unconstrained: np.ndarray
    theta_cov: np.ndarray
    history: History | None


@dataclass(frozen=True)
class MethodSettings:
    """What a classical method's estimate was made with (a result of IDIM, IV, RLS or OE; the observer's run that
    every method starts from keeps its own, :attr:`IdentificationResult.observer_settings`).

    method : "idim", "iv", "rls" or "oe".  torque_hold, control_rate : how the efforts were held (the observer's).
    cutoff_hz : Hz, the zero-phase filter's cutoff used (IDIM, IV, RLS).  weighted : IDIM's/IV's two-step weighting.
    forgetting : RLS's forgetting factor.  None: the method has no such setting.
    """

    method: str
    torque_hold: str
    control_rate: float | None = None
    cutoff_hz: float | None = None
    weighted: bool | None = None
    forgetting: float | None = None

    def to_dict(self) -> dict[str, Any]:
        """The settings as JSON: the method and the hold always, the others where the method has them."""
        always = ("method", "torque_hold", "control_rate")
        return {k: v for k, v in dataclasses.asdict(self).items() if k in always or v is not None}

    def said(self) -> str:
        """The settings in words, e.g. "idim: cutoff 10 Hz, unweighted" (a report's and the table's line)."""
        said = [f"cutoff {self.cutoff_hz:.3g} Hz"] if self.cutoff_hz is not None else []
        if self.weighted is not None:
            said.append("weighted" if self.weighted else "unweighted")
        if self.forgetting is not None:
            said.append(f"forgetting factor {self.forgetting:g}")
        return f"{self.method}: {', '.join(said) or 'its defaults'}"

    def before_observer(self) -> str:
        """The settings said before the observer's run the method started from (the table's and the report's
        summary line)."""
        return f"{self.said()}; the observer's run it started from: "

    @classmethod
    def from_dict(cls, data: dict[str, Any]) -> MethodSettings:
        return cls(
            method=str(data["method"]), torque_hold=str(data.get("torque_hold", "zoh")),
            control_rate=data.get("control_rate"), cutoff_hz=data.get("cutoff_hz"), weighted=data.get("weighted"),
            forgetting=data.get("forgetting"),
        )  # fmt: skip


@dataclass(frozen=True)
class IdentificationResult:
    """Everything an identification found, whichever the method, immutable.

    ``to_dict`` gives the JSON form; :meth:`from_dict` reads it back.

    Attributes
    ----------
    source
        The log.
    form
        The regressor (friction model included).
    parameters
        Name -> (value, std), REPORTED names, SI units (the effort's units for a PWM log).
    theta0_cov
        (n0, n0) covariance of the base parameters.
    diagnostics
        What the log and the method showed (:class:`~wmrid.estimators.findings.Diagnostics`).
    warnings
        Said to the user.
    log_info
        What the log was (:class:`~wmrid.estimators.records.LogInfo`).
    observer
        The observer's run on the log (every method runs it first: its excitation figures and history describe the
        log), or None.
    nominal
        The robot's nominal base parameters, or None.
    reference
        The robot's CAD base parameters, or None.
    units
        Parameter name -> its unit (default: the SI units, ``THETA0_UNITS``).
    payload
        The payload's mass, position and inertia (:class:`~wmrid.model.payload.PayloadEstimate`, ``--payload``), or
        None.
    method
        The method whose estimate is reported.
    estimate
        The method's :class:`~wmrid.estimators.estimate.BaseEstimate`: the reported theta0 and its covariance
        (undetermined: NaN/inf).
    validation
        The fit on another log (:class:`~wmrid.estimators.records.Validation`), or None.
    verdict
        What the log determines, per parameter group (:class:`~wmrid.estimators.records.Verdict`).
    method_settings
        What another method's estimate was made with (None for the observer's): :attr:`settings`.
    """

    source: str
    form: RegressorForm
    parameters: dict[str, tuple[float, float]]  # name -> (value, std), REPORTED names, SI units
    theta0_cov: np.ndarray  # (n0, n0)
    diagnostics: Diagnostics
    warnings: tuple[str, ...]
    log_info: LogInfo
    observer: ObserverRun | None = None
    nominal: dict[str, float] | None = None
    reference: dict[str, float] | None = None
    units: dict[str, str] = field(default_factory=THETA0_UNITS.copy)
    payload: PayloadEstimate | None = None
    method: str = "observer"
    estimate: BaseEstimate | None = None  # the reported theta0 and its covariance (undetermined: NaN/inf)
    validation: Validation | None = None
    verdict: Verdict | None = None
    method_settings: MethodSettings | None = None

    @property
    def table(self) -> dict[str, Parameter]:
        """The reported parameters as :class:`Parameter` (value, std, unit and the flags the estimator recorded),
        what every view of the result prints."""
        return parameter_table(self.parameters, self.units, self.diagnostics)

    @property
    def settings(self) -> ObserverSettings | MethodSettings:
        """The settings of the method reported: the observer's (:attr:`observer_settings`), or another method's."""
        return self.method_settings if self.method_settings is not None else self._run().settings

    # The observer run's figures, read through the result (the reports and figures use them).
    @property
    def observer_settings(self) -> ObserverSettings:
        return self._run().settings

    @property
    def start_source(self) -> str:
        return self._run().start_source

    @property
    def theta(self) -> np.ndarray:
        return self._run().theta

    @property
    def theta_unconstrained(self) -> np.ndarray:
        return self._run().theta_unconstrained

    @property
    def theta_cov(self) -> np.ndarray:
        return self._run().theta_cov

    @property
    def history(self) -> History | None:
        return None if self.observer is None else self.observer.history

    def _run(self) -> ObserverRun:
        if self.observer is None:
            raise AttributeError(f"{self.source}: this result holds no observer run")
        return self.observer

    @classmethod
    def from_dict(cls, data: Any, source: str = "result") -> IdentificationResult:
        """Read back the result that :meth:`to_dict` wrote as a document (:func:`from_dict`).

        Parameters
        ----------
        data
            The document (``identify --format json``).
        source
            Where it came from, named in error messages.

        Returns
        -------
        IdentificationResult
            The result the document describes.

        Raises
        ------
        LogFormatError
            ``data`` is not a complete result, or is one of a newer schema (the message names ``source``).
        """
        return from_dict(data, source)

    def theta_dict(self) -> dict[str, Any]:
        names = self.form.theta_names()
        std = np.sqrt(np.clip(np.diag(self.theta_cov), 0, None))
        return {
            "form": self.form.to_dict(),
            "values": {n: float(v) for n, v in zip(names, self.theta.ravel(), strict=True)},
            "std": {n: finite_or_none(s) for n, s in zip(names, std, strict=True)},
            "unconstrained": {n: float(v) for n, v in zip(names, self.theta_unconstrained.ravel(), strict=True)},
            "start": {n: float(v) for n, v in zip(names, self.observer_settings.theta_init.ravel(), strict=True)},
            "box_min": {
                n: finite_or_none(v) for n, v in zip(names, self.observer_settings.theta_min.ravel(), strict=True)
            },
            "box_max": {
                n: finite_or_none(v) for n, v in zip(names, self.observer_settings.theta_max.ravel(), strict=True)
            },
        }

    def to_dict(self, history: bool = True) -> dict[str, Any]:
        """The result as JSON-ready data: the document ``identify --format json`` prints.

        Parameters
        ----------
        history
            Include the estimates over time (most of its size).

        Returns
        -------
        dict
            The document, with its ``schema_version``.
        """
        params = {name: parameter.to_dict() for name, parameter in self.table.items()}
        out: dict[str, Any] = {
            "schema_version": SCHEMA_VERSION,
            "source": self.source,
            "method": self.method,
            "effort_unit": self.log_info.effort_unit,
        }
        if self.verdict is not None:
            out["verdict"] = self.verdict.to_dict()
        out["parameters"] = params
        if self.observer is not None:
            out["theta"] = self.theta_dict()
            observer = {
                "k": self.observer_settings.k,
                "alpha": self.observer_settings.alpha,
                "torque_hold": self.observer_settings.torque_hold,
                "control_rate": self.observer_settings.control_rate,
                "start": self.start_source,
            }
            if self.method_settings is None:
                out["settings"] = observer
            else:  # another method's: its own settings, the observer's run under its own name
                out["settings"] = self.method_settings.to_dict()
                out["observer_settings"] = observer
        out.update(diagnostics=self.diagnostics.to_dict(), warnings=list(self.warnings), log=self.log_info.to_dict())
        if self.estimate is not None:
            out["estimate"] = estimate_dict(self.estimate, self.form.base_names)
        if history and self.history is not None:
            out["history"] = history_dict(self)
        if self.validation is not None:
            out["validation"] = self.validation.to_dict()
        if self.payload is not None:
            out["payload"] = self.payload.to_dict()
        if self.nominal is not None:
            out["nominal"] = self.nominal
        if self.reference is not None:
            out["reference"] = self.reference
        return out


def from_dict(data: Any, source: str = "result") -> IdentificationResult:
    """Read back the result that :meth:`IdentificationResult.to_dict` wrote (``identify --format json``).

    Exact for everything the document holds: ``from_dict(d).to_dict() == d`` for a document ``to_dict`` wrote.
    A document saved before results carried a verdict gets one, made from its numbers (its warnings and flags
    made again, :func:`wmrid.estimators.verdict.settle`).  What it does not hold comes back as follows: the
    intermediate parameters' covariance as its diagonal (their std), the history as the decimated one the document
    keeps (None when it has none), the base parameters' covariance from ``estimate`` (documents before schema 1:
    the diagonal of the reported std).
    Raises :class:`LogFormatError` naming ``source`` when ``data`` is not a complete result, or one of a newer
    schema.
    """
    if not isinstance(data, dict) or not isinstance(data.get("parameters"), dict) or "theta" not in data:
        raise LogFormatError(
            f"{source}: not an identify result (no 'parameters'/'theta'); give a log or the output of "
            f"`wmrid identify --format json`"
        )
    version = data.get("schema_version", 1)
    if isinstance(version, bool) or not isinstance(version, int) or version < 1:
        raise LogFormatError(f"{source}: its schema_version {version!r} is not a version number (1, 2, ...)")
    if version > SCHEMA_VERSION:
        raise LogFormatError(
            f"{source}: an identify result of schema version {version!r}, newer than this wmrid reads "
            f"({SCHEMA_VERSION}); upgrade wmrid"
        )
    try:
        return _from_dict(data, source)
    except LogFormatError:
        raise
    except (KeyError, TypeError, ValueError, IndexError, AttributeError, OverflowError) as err:
        what = f"no {err.args[0]!r}" if isinstance(err, KeyError) and err.args else " ".join(str(err).split())
        raise LogFormatError(
            f"{source}: not a complete identify result ({what}); give a log, or the unedited output of "
            f"`wmrid identify LOG --format json`"
        ) from err


def _from_dict(data: dict[str, Any], source: str) -> IdentificationResult:
    theta_d = data["theta"]
    form = RegressorForm.from_dict(theta_d["form"])
    names = form.theta_names()
    p = form.n_columns
    settings_d = data.get("observer_settings", data["settings"])
    method_settings = MethodSettings.from_dict(data["settings"]) if "observer_settings" in data else None
    settings = ObserverSettings(
        form=form,
        theta_init=box(theta_d["start"], names, p, math.nan),
        theta_min=box(theta_d.get("box_min", dict.fromkeys(names)), names, p, -math.inf),
        theta_max=box(theta_d.get("box_max", dict.fromkeys(names)), names, p, math.inf),
        k=float(settings_d["k"]),
        alpha=float(settings_d["alpha"]),
        torque_hold=settings_d.get("torque_hold", "zoh"),
        control_rate=settings_d.get("control_rate"),
    )
    theta = box(theta_d["values"], names, p, math.nan)
    unconstrained = box(theta_d.get("unconstrained", theta_d["values"]), names, p, math.nan)
    theta_std = box(theta_d.get("std", dict.fromkeys(names)), names, p, math.inf).ravel()
    params_d = data["parameters"]
    parameters = {
        name: (math.nan if e["value"] is None else float(e["value"]), math.inf if e["std"] is None else float(e["std"]))
        for name, e in params_d.items()
    }
    units = dict(THETA0_UNITS)
    units.update({name: str(e["unit"]) for name, e in params_d.items()})
    estimate = None
    est_d = data.get("estimate")
    base = form.base_names
    if est_d is not None:
        cov = np.array([floats(row) for row in est_d["covariance"]], dtype=float).reshape(len(est_d["theta0"]), -1)
        cov[~np.isfinite(cov)] = math.nan
        undetermined = np.isnan(np.diag(cov))
        cov[np.diag_indices_from(cov)] = np.where(undetermined, math.inf, np.diag(cov))
        weight_cov = None
        if est_d.get("weight_covariance") is not None:
            weight_cov = np.array([floats(row) for row in est_d["weight_covariance"]], dtype=float).reshape(cov.shape)
            unset = np.isnan(np.diag(weight_cov))  # undetermined: NaN row and column, +inf on the diagonal
            weight_cov[np.diag_indices_from(weight_cov)] = np.where(unset, math.inf, np.diag(weight_cov))
        estimate = BaseEstimate(method=est_d["method"], theta0=floats(est_d["theta0"]), cov=cov, dof=est_d.get("dof"),
                                weight_cov=weight_cov)  # fmt: skip
        theta0_cov = cov
    else:
        std = np.array([parameters.get(n, (math.nan, math.inf))[1] for n in base])
        theta0_cov = np.diag(std**2)
    hist_d = data.get("history")
    history = None
    if hist_d is not None:
        t = floats(hist_d["t"])
        history = History(
            t=t,
            theta=np.column_stack([floats(hist_d["theta"][n]) for n in names]).reshape(len(t), 2, p),
            e=np.column_stack([floats(hist_d["e_r"]), floats(hist_d["e_l"])]),
            lambda_min=floats(hist_d["lambda_min"]),
        )
    payload_d = data.get("payload")
    validation_d = data.get("validation")
    verdict_d = data.get("verdict")
    result = IdentificationResult(
        source=data.get("source") or source,
        form=form,
        parameters=parameters,
        theta0_cov=theta0_cov,
        diagnostics=Diagnostics.from_dict(data.get("diagnostics", {})),
        warnings=tuple(data.get("warnings", ())),
        log_info=LogInfo.from_dict(data["log"]),
        observer=ObserverRun(
            settings=settings,
            start_source=settings_d.get("start", ""),
            theta=theta,
            theta_unconstrained=unconstrained,
            theta_cov=np.diag(theta_std**2),
            history=history,
        ),
        nominal=data.get("nominal"),
        reference=data.get("reference"),
        units=units,
        payload=None if payload_d is None else PayloadEstimate.from_dict(payload_d),
        method=data.get("method", "observer"),
        estimate=estimate,
        validation=None if validation_d is None else Validation.from_dict(validation_d),
        verdict=None if verdict_d is None else Verdict.from_dict(verdict_d),
        method_settings=method_settings,
    )
    if result.verdict is None:  # saved before the verdict: said from its numbers (wmrid.estimators.verdict)
        # the verdict's checks (~15 ms): only a result saved before verdicts
        from wmrid.estimators.verdict import settle

        result = settle(result)
    return result
