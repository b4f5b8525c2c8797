"""What an identification found beside the numbers: the diagnostics tree of a result (:class:`Diagnostics`), typed.

Each part is a frozen :class:`~wmrid.core.json_record.JsonRecord`: ``to_dict`` writes the object a result's JSON
holds under ``diagnostics`` (the keys in the order given here; None: the key is absent, except the fields that are
always written), ``from_dict`` reads one back, keys it does not know kept in ``other``.  Units are SI (seconds,
rad/s, the base parameters' units); the meaning of each figure is said by the check that makes it:

* :class:`Uncertainty` (+ :class:`ModelError`, :class:`WideningTerm`, :class:`PredictionMisfit`): what the std is
  and the model-error widening
  (:mod:`wmrid.estimators.uncertainty`, :mod:`wmrid.estimators.model_error`);
* :class:`StructuralMismatch`: the misfit of the intermediate parameters to the model's form (Eqs. 23-24);
* :class:`FrictionChoice` (+ :class:`LoadTermsChoice`): the friction model and why (:mod:`wmrid.pipeline.friction`);
* :class:`TimingCheck`, :class:`DelayApplied` (+ :class:`EstimatedDelay`, :class:`TimingTerm`, :class:`HoldTerm`):
  the efforts' timing (:mod:`wmrid.estimators.timing_check`, :mod:`wmrid.estimators.widening`);
* :class:`FeedbackCheck`: the closed-loop check (:mod:`wmrid.estimators.feedback`);
* :class:`UnitsCheck` (+ :class:`UnitFinding`, :class:`RobotComparison`): the units check
  (:mod:`wmrid.estimators.plausibility`);
* :class:`MethodFigures`: another method's own figures (its filter, weighting, forgetting, ... in ``other``);
* :class:`Combination` (+ :class:`CombinedResult`): earlier results combined with this log's.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

from wmrid.core.json_record import JsonRecord, each, kept, names, nested, other_keys, spliced


@dataclass(frozen=True, kw_only=True)
class WeakDirection(JsonRecord):
    """A weakly excited direction of the column-scaled information: its eigenvalue over the largest, the regressor
    columns it involves."""

    relative_eigenvalue: float | None = None
    columns: tuple[str, ...] | None = names()
    other: dict[str, Any] = other_keys()


@dataclass(frozen=True, kw_only=True)
class StructuralMismatch(JsonRecord):
    """Hotelling T2 (``statistic``) of the misfit of theta to the model's form on ``dof`` directions, its p-value,
    the largest misfit relative to max |theta|."""

    statistic: float | None = None
    dof: int | None = None
    p_value: float | None = None
    relative_misfit: float | None = None
    meaning: str | None = None
    other: dict[str, Any] = other_keys()


@dataclass(frozen=True, kw_only=True)
class WideningTerm(JsonRecord):
    """A term the std may carry (:mod:`wmrid.estimators.model_error`, :mod:`wmrid.estimators.regression.idim_checks`):
    ``applied`` when its change of theta0 (``delta`` (n0,)) passes its gate in ``sd`` (n0,) (``largest_ratio``), or
    ``why`` it could not be measured.  The discretisation's (``observer_only``: not another method's), the slow parts'
    (``left_out_fraction`` of the log; ``fragile``: the parameters only the slow parts determine, their variance
    ``var_without`` without them; the residuals' ``residual_ratio`` and ``residual_z`` per wheel), the filter
    cutoff's (``cutoff_hz``: [used, lowered] Hz); ``method``: whose it is when not the observer's."""

    applied: bool | None = None
    delta: list[float] | None = None
    sd: list[float] | None = None
    largest_ratio: float | None = None
    why: str | None = None
    left_out_fraction: float | None = None
    cutoff_hz: list[float] | None = None
    method: str | None = None
    observer_only: bool | None = None
    fragile: tuple[str, ...] | None = names()
    var_without: list[float] | None = None
    residual_ratio: list[float] | None = None
    residual_z: list[float] | None = None
    other: dict[str, Any] = other_keys()


@dataclass(frozen=True, kw_only=True)
class PredictionMisfit(JsonRecord):
    """The prediction-misfit test (:func:`wmrid.estimators.model_error.prediction_misfit`): ``applied`` when the
    worst ``wheel``'s (0 right, 1 left) prediction error is ``ratio`` times the speeds' noise and ``share`` of their
    rms; per wheel, rad/s: ``prediction_error_rms``, ``noise_rms``, ``speed_rms`` (None: not measured)."""

    applied: bool | None = None
    wheel: int | None = kept()
    ratio: float | None = kept()
    share: float | None = kept()
    prediction_error_rms: list[float] | None = kept()
    noise_rms: list[float] | None = kept()
    speed_rms: list[float] | None = kept()
    other: dict[str, Any] = other_keys()


@dataclass(frozen=True, kw_only=True)
class ModelError(JsonRecord):
    """The model-error widening: every std scaled by ``scale`` (``applied``) from the misfit's T2 (F, p_value);
    the other terms (:class:`WideningTerm`): the discretisation, the slow parts, the filter cutoff; the prediction
    misfit (:class:`PredictionMisfit`); ``meaning``: what widened the std."""

    scale: float | None = None
    applied: bool | None = None
    T2: float | None = None
    T2_expected: float | None = None
    F: float | None = None
    p_value: float | None = None
    relative_misfit: float | None = None
    discretisation: WideningTerm | None = nested(WideningTerm)
    slow_speed: WideningTerm | None = nested(WideningTerm)
    prediction_misfit: PredictionMisfit | None = nested(PredictionMisfit)
    filter: WideningTerm | None = nested(WideningTerm)
    meaning: str | None = None
    other: dict[str, Any] = other_keys()


@dataclass(frozen=True, kw_only=True)
class Uncertainty(JsonRecord):
    """What the std is: ``method`` (the jackknife over ``segments`` of the log, ``dof`` degrees of freedom), the
    Student-t ``interval_factor`` per coverage ("95%", "99.7%"), the jackknife's ``blocks`` of ``block_seconds`` s,
    the model-error widening, and, for a combination of logs, what was combined (``combined``)."""

    method: str | None = None
    segments: int | None = kept()
    dof: int | None = kept()
    interval_factor: dict[str, float] | None = None
    meaning: str | None = None
    caveat: str | None = None
    blocks: int | None = None
    block_seconds: float | None = None
    model_error: ModelError | None = nested(ModelError)
    combined: str | None = None
    other: dict[str, Any] = other_keys()


@dataclass(frozen=True, kw_only=True)
class PredictionErrorRms(JsonRecord):
    """The observer's prior prediction error, rms per wheel, in ``unit`` (rad/s)."""

    eta_r: float | None = None
    eta_l: float | None = None
    unit: str | None = None
    other: dict[str, Any] = other_keys()


@dataclass(frozen=True, kw_only=True)
class LoadTermsChoice(JsonRecord):
    """Whether friction auto took the casters' load terms (``taken``, ``reason``): the Wald test of the terms
    (statistic, dof, p_value) and the model-error scales with and without them."""

    taken: bool | None = None
    reason: str | None = None
    scale: float | None = None
    caster_scale: float | None = None
    statistic: float | None = None
    dof: int | None = None
    p_value: float | None = None
    text: str | None = None
    negative: tuple[str, ...] | None = names()
    other: dict[str, Any] = other_keys()


@dataclass(frozen=True, kw_only=True)
class FrictionChoice(JsonRecord):
    """The friction model (``model``), who chose it (``chosen_by``: "--friction" or "auto") and why; for auto, the
    Wald test of the casters' drag against zero (statistic, dof, p_value, ``text``: the drag values, ``negative``:
    those that push) and the load terms' choice."""

    model: str | None = None
    chosen_by: str | None = None
    reason: str | None = None
    statistic: float | None = None
    dof: int | None = None
    p_value: float | None = None
    text: str | None = None
    negative: tuple[str, ...] | None = names()
    load: LoadTermsChoice | None = nested(LoadTermsChoice)
    other: dict[str, Any] = other_keys()


@dataclass(frozen=True, kw_only=True)
class EstimatedDelay(JsonRecord):
    """A delay of the efforts behind the speeds, estimated (:class:`wmrid.estimators.delay.DelayEstimate`'s
    figures): ``delay_s`` s (> 0: stamped late) and its jackknife ``std_s`` s (None: not determined), whether it is
    ``significant``, over ``segments``, at the edge of the search, by which ``estimator``."""

    delay_s: float | None = kept()
    std_s: float | None = kept()
    significant: bool | None = None
    segments: int | None = None
    at_edge_of_search: bool | None = None
    estimator: str | None = None
    meaning: str | None = None
    other: dict[str, Any] = other_keys()


@dataclass(frozen=True, kw_only=True)
class HoldTerm(JsonRecord):
    """The hold term of a slow log: theta0's change (n0,) from zoh to foh, and the parameters it widened."""

    delta: list[float] | None = None
    widened: tuple[str, ...] | None = names()
    other: dict[str, Any] = other_keys()


@dataclass(frozen=True, kw_only=True)
class TimingTerm(JsonRecord):
    """The timing term: theta0's change (n0,) with the delay moved by ``step_s`` s, and the parameters it widened
    (``delay_s``, ``found_by``: an unresolved delay's, and how the change was found)."""

    step_s: float | None = None
    delay_s: float | None = None
    delta: list[float] | None = None
    found_by: str | None = None
    widened: tuple[str, ...] | None = names()
    other: dict[str, Any] = other_keys()


@dataclass(frozen=True, kw_only=True)
class TimingCheck(JsonRecord):
    """The timing check of the efforts against the speeds on a window of the log (``checked``; else ``why`` not).

    estimate : the delay it found.  apply : significant and not at the edge of the search (the efforts are timed).
    slow : the log is slower than the check's rate.  faster_controller : the controller runs faster than the log.
    samples_profiled, of, windows : what of the log was profiled.  profiled_with, wheel_model : the friction model of
    the profile, and the wheel model's estimate when that was another.  theta0_slope_per_s : (8,) the profile's
    slope of theta0 in the delay.  note : what the casters' drag explains.  timing_term, hold_term : the terms the
    std carries for the timing.
    """

    checked: bool | None = None
    estimate: EstimatedDelay | None = spliced(EstimatedDelay)
    apply: bool | None = None
    slow: bool | None = None
    faster_controller: bool | None = None
    why: str | None = None
    samples_profiled: int | None = None
    of: int | None = None
    windows: int | None = None
    profiled_with: str | None = None
    wheel_model: EstimatedDelay | None = nested(EstimatedDelay)
    note: str | None = None
    theta0_slope_per_s: list[float] | None = None
    timing_term: TimingTerm | None = nested(TimingTerm)
    hold_term: HoldTerm | None = nested(HoldTerm)
    other: dict[str, Any] = other_keys()


@dataclass(frozen=True, kw_only=True)
class DelayApplied(JsonRecord):
    """The delay the efforts were read earlier by (``applied_s`` s), chosen by "--delay" or "auto" (then estimated
    on the whole log: ``estimate``, the profile's friction model, the wheel model's estimate), and the timing term
    the std carries."""

    chosen_by: str | None = None
    estimate: EstimatedDelay | None = spliced(EstimatedDelay)
    profiled_with: str | None = None
    wheel_model: EstimatedDelay | None = nested(EstimatedDelay)
    applied_s: float | None = None
    timing_term: TimingTerm | None = nested(TimingTerm)
    other: dict[str, Any] = other_keys()


@dataclass(frozen=True, kw_only=True)
class FeedbackCheck(JsonRecord):
    """The closed-loop check (``checked``; else ``why`` not): whether the prediction error shows a disturbance the
    loop could feed back; the observer against IDIM or IDIM-IV (``against``): per parameter the difference
    (``delta``), its jackknife sd and their ``ratio``; ``applied`` when the largest ratio passes ``gate``; the
    method ``reported``; the parameters whose std it ``widened``."""

    checked: bool | None = None
    against: str | None = None
    disturbance: bool | None = None
    prediction_error_ratio: Any = None
    prediction_error_share: Any = None
    why: str | None = None
    applied: bool | None = None
    delta: dict[str, float] | None = None
    sd: dict[str, float] | None = None
    ratio: dict[str, float] | None = None
    largest_ratio: float | None = None
    largest: str | None = None
    gate: float | None = None
    dof: int | None = None
    reported: str | None = None
    other_systematic: Any = None
    not_reported: str | None = None
    widened: tuple[str, ...] | None = names()
    other: dict[str, Any] = other_keys()


@dataclass(frozen=True, kw_only=True)
class UnitFinding(JsonRecord):
    """A unit the log's numbers point to: the ``quantity`` ("time", "speed", "effort", "columns", "robot"), the
    ``unit`` it seems to be in and the option that says so (``fix``), the statement, and whether it puts every std
    in ``doubt``."""

    quantity: str | None = None
    unit: str | None = kept()
    fix: str | None = kept()
    text: str | None = None
    doubt: bool | None = None
    other: dict[str, Any] = other_keys()


@dataclass(frozen=True, kw_only=True)
class RobotComparison(JsonRecord):
    """The estimate against the robot file's values: the ``reference``, the rms factor between them, the parameters
    ``compared``."""

    reference: str | None = None
    rms_factor: float | None = None
    compared: tuple[str, ...] | None = names()
    other: dict[str, Any] = other_keys()


@dataclass(frozen=True, kw_only=True)
class UnitsCheck(JsonRecord):
    """The units check: its ``findings``, the comparison with the robot file (None: none), whether the numbers are
    in ``doubt``, the wheel radius m it used."""

    findings: tuple[UnitFinding, ...] | None = each(UnitFinding)
    robot: RobotComparison | None = nested(RobotComparison, keep=True)
    doubt: bool | None = None
    wheel_radius: float | None = kept()
    other: dict[str, Any] = other_keys()


@dataclass(frozen=True, kw_only=True)
class MethodFigures(JsonRecord):
    """Another method's run: its ``name``, its run time s, its degrees of freedom; its own figures (filter cutoff,
    weighting, forgetting factor, optimiser status, ...) in ``other``, as the method wrote them."""

    name: str | None = None
    seconds: float | None = None
    dof: int | None = kept()
    other: dict[str, Any] = other_keys()

    @property
    def figures(self) -> dict[str, Any]:
        """The method's own figures."""
        return self.other


@dataclass(frozen=True, kw_only=True)
class CombinedResult(JsonRecord):
    """An earlier result combined with this log's: its file, its log, method, dof and the parameters taken."""

    source: str | None = None
    log: str | None = None
    method: str | None = None
    dof: int | None = kept()
    parameters: tuple[str, ...] | None = names()
    other: dict[str, Any] = other_keys()


@dataclass(frozen=True, kw_only=True)
class Combination(JsonRecord):
    """Earlier results combined with this log's (``--given``): them, this log's own estimate (name -> {"value",
    "std"}) and dof, and what the combination means."""

    results: tuple[CombinedResult, ...] | None = each(CombinedResult)
    this_log: dict[str, dict[str, float | None]] | None = None
    this_log_dof: int | None = kept()
    meaning: str | None = None
    other: dict[str, Any] = other_keys()


@dataclass(frozen=True, kw_only=True)
class Diagnostics(JsonRecord):
    """What the log and the method showed, beside the numbers (a result's ``diagnostics``).

    Attributes
    ----------
    lambda_min_gamma
        Gamma's smallest eigenvalue.
    lambda_max_gamma
        Gamma's largest eigenvalue.
    condition_number_scaled
        The condition number of the column-scaled information.
    weakest_directions
        Its two weakest directions (:class:`WeakDirection`).
    undetermined
        The base parameters the log does not determine.
    at_box_boundary
        The intermediate parameters held on the box.
    start_sensitivity
        Name -> how much the start value sets it, in its unit.
    structural_mismatch
        The misfit of theta to the model's form (:class:`StructuralMismatch`).
    uncertainty
        What the std is (:class:`Uncertainty`).
    inflated
        The parameters whose std a term widened.
    flagged
        Those whose std is not to be trusted.
    prediction_error_rms
        The observer's prior prediction error, rms per wheel (:class:`PredictionErrorRms`).
    friction
        The friction model, who chose it and why (:class:`FrictionChoice`).
    timing
        The timing check of the efforts against the speeds (:class:`TimingCheck`).
    delay
        The delay the efforts were read earlier by (:class:`DelayApplied`).
    feedback
        The closed-loop check (:class:`FeedbackCheck`).
    units
        The units check (:class:`UnitsCheck`).
    poorly_determined
        The verdict's statement: the parameters poorly determined.
    not_separable
        The verdict's statement: the pairs of parameters that are not separable, with their correlation
        ([name, other, correlation]).
    impossible
        The verdict's statement: the parameters whose values are impossible for a physical robot.
    observer_parameters
        The observer's estimate (name -> {"value", "std"}) when another method is reported.
    method
        Another method's run (:class:`MethodFigures`).
    from_observer
        When another method is reported: the diagnostics that are the observer's.
    combined
        Earlier results combined with this log's (:class:`Combination`, ``--given``).
    robot_assumed
        What the robot file left out.
    robot_values
        The robot's values in the log's effort units (ratios only).
    other
        The keys the record does not know, in their order.
    """

    lambda_min_gamma: float | None = None
    lambda_max_gamma: float | None = None
    condition_number_scaled: float | None = None
    weakest_directions: tuple[WeakDirection, ...] | None = each(WeakDirection)
    undetermined: tuple[str, ...] | None = names()
    at_box_boundary: tuple[str, ...] | None = names()
    start_sensitivity: dict[str, float] | None = None
    structural_mismatch: StructuralMismatch | None = nested(StructuralMismatch)
    uncertainty: Uncertainty | None = nested(Uncertainty)
    inflated: tuple[str, ...] | None = names()
    flagged: tuple[str, ...] | None = names()
    prediction_error_rms: PredictionErrorRms | None = nested(PredictionErrorRms)
    friction: FrictionChoice | None = nested(FrictionChoice)
    timing: TimingCheck | None = nested(TimingCheck)
    delay: DelayApplied | None = nested(DelayApplied)
    feedback: FeedbackCheck | None = nested(FeedbackCheck)
    units: UnitsCheck | None = nested(UnitsCheck)
    poorly_determined: tuple[str, ...] | None = names()
    not_separable: tuple[Any, ...] | None = names()
    impossible: tuple[str, ...] | None = names()
    observer_parameters: dict[str, dict[str, float | None]] | None = None
    method: MethodFigures | None = nested(MethodFigures)
    from_observer: tuple[str, ...] | None = names()
    combined: Combination | None = nested(Combination)
    robot_assumed: tuple[str, ...] | None = names()
    robot_values: dict[str, Any] | None = None
    other: dict[str, Any] = other_keys()

    @property
    def model_error(self) -> ModelError | None:
        """The model-error widening (``uncertainty.model_error``), None when not recorded."""
        return None if self.uncertainty is None else self.uncertainty.model_error

    @property
    def prediction_misfit(self) -> PredictionMisfit:
        """The prediction-misfit test (``uncertainty.model_error.prediction_misfit``; not recorded: one with no
        figures, not applied)."""
        model_error = self.model_error
        return (None if model_error is None else model_error.prediction_misfit) or PredictionMisfit()

    @property
    def method_seconds(self) -> float:
        """The reported method's own run time s (another method's; NaN when not recorded)."""
        seconds = None if self.method is None else self.method.seconds
        return math.nan if seconds is None else float(seconds)

    def timing_widened(self) -> tuple[str, ...]:
        """The parameters whose std a timing term widened (the timing check's unresolved delay, the applied delay's
        resolution)."""
        out: tuple[str, ...] = ()
        for record in (self.timing, self.delay):
            term = None if record is None else record.timing_term
            out += () if term is None else tuple(term.widened or ())
        return out
