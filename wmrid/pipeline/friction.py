"""The friction model a log is identified with (``--friction auto``): the wheels' alone, their casters' drag too,
and the drag's load terms, each taken when the log shows it (:func:`choose_friction`)."""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import replace

from wmrid.core.errors import NotIdentifiableError
from wmrid.core.wheel_log import LogStream
from wmrid.estimators.diagnostics import AUTO_NO_REVERSAL, AUTO_P, caster_drag_test
from wmrid.estimators.findings import FrictionChoice, LoadTermsChoice
from wmrid.estimators.observer.observe import observe
from wmrid.estimators.observer.survey import Survey
from wmrid.estimators.options import ObserverOptions
from wmrid.estimators.result import IdentificationResult
from wmrid.model.robot import Robot


def choose_friction(
    stream: LogStream,
    sv: Survey,
    robot: Robot | None,
    options: ObserverOptions,
    *,
    geometry: tuple[float, ...] = (),
    load_terms: bool = True,
    progress: Callable[[int, int], None] | None = None,
) -> tuple[IdentificationResult, FrictionChoice]:
    """(the observer's run with the friction model ``options.friction`` names, the record of how it was chosen for
    ``diagnostics.friction``).  ``auto``: the wheel model and the caster model (one more pass over the log), the
    caster model taken when a Wald test puts its drag off zero at p < AUTO_P (never on a log whose wheels keep one
    sign, and not when the drag would push the robot); with the casters' positions and ``load_terms``, then also
    ``wheel+caster+load`` (:func:`_with_load`).  Each pass: :func:`wmrid.estimators.observer.observe.observe`."""

    def run(model: str) -> IdentificationResult:
        return observe(stream, sv, robot, replace(options, friction=model), geometry, progress)

    friction = options.friction
    if friction != "auto":
        return run(friction), FrictionChoice(model=friction, chosen_by="--friction")
    wheel = run("wheel")
    if wheel.form.kind == "paper":
        return wheel, FrictionChoice(model="wheel", chosen_by="auto", reason=AUTO_NO_REVERSAL)
    try:
        caster = run("wheel+caster")
    except NotIdentifiableError as err:
        return wheel, FrictionChoice(model="wheel", chosen_by="auto", reason=f"caster model failed: {err}")
    choice = caster_drag_test(caster)
    significant = choice["p_value"] < AUTO_P
    chosen = caster if significant and not choice["negative"] else wheel
    reason = (
        f"the caster drag ({choice['text']}) differs from zero (p = {choice['p_value']:.2g} < {AUTO_P:g})"
        if significant
        else f"this log shows no caster drag ({choice['text']}: indistinguishable from zero, p = "
        f"{choice['p_value']:.2g}, where {AUTO_P:g} is needed)"
    )
    if significant and choice["negative"]:
        reason += (
            f", but {', '.join(choice['negative'])} would push the robot, which no caster does: not a caster's drag "
            "(a sign, a unit, or an effect neither model has), so the wheel model is kept"
        )
    # the test's figures as they are (a drag not determined has no "negative")
    record = FrictionChoice.from_dict({"model": chosen.form.friction, "chosen_by": "auto", "reason": reason, **choice})
    if chosen is caster and caster.form.geometry and load_terms:
        return _with_load(chosen, record, lambda: run("wheel+caster+load"))
    return chosen, record


def _with_load(
    caster: IdentificationResult, record: FrictionChoice, run_load: Callable[[], IdentificationResult]
) -> tuple[IdentificationResult, FrictionChoice]:
    """``--friction auto`` after the caster model was chosen: the ``wheel+caster+load`` model too, taken when a Wald
    test puts its load terms off zero at p < AUTO_P (:func:`wmrid.estimators.diagnostics.caster_drag_test` on them)
    and the log departs from it no more than from the caster model (its model-error scale S,
    :func:`wmrid.estimators.model_error.widen`, not larger); the record says why.

    The second condition guards against load terms that fit something else and move the fit away from the model
    instead of towards it.  (The case that motivated it -- the paper robot's MuJoCo plan log at 0.02 rad/s: D1dv
    -0.91 N s^2/m for the engine's -0.43, S 189 where the caster model had 133 -- was a delay the timing check had
    invented from the casters' drag, :func:`wmrid.estimators.observer.observe.delay_profile_form`; profiled with the
    drag, the same log takes the load model with S 1.0 and D1dv -0.48.)"""
    try:
        loaded = run_load()
    except NotIdentifiableError as err:
        return caster, replace(record, load=LoadTermsChoice(taken=False, reason=f"load model failed: {err}"))
    test = caster_drag_test(loaded, loaded.form.base_names[8 + loaded.form.n_casters :])
    scale = [_model_error_scale(r) for r in (caster, loaded)]
    shown = test["p_value"] < AUTO_P
    taken = shown and scale[1] <= scale[0]
    reason = (
        f"the drag's load terms ({test['text']}) differ from zero (p = {test['p_value']:.2g} < {AUTO_P:g})"
        if shown
        else f"this log shows no load terms of the drag ({test['text']}: indistinguishable from zero, p = "
        f"{test['p_value']:.2g}, where {AUTO_P:g} is needed)"
    )
    if shown and not taken:
        reason += (
            f", but the log departs further from that model (model-error scale {scale[1]:.3g} against the caster "
            f"model's {scale[0]:.3g}), so the caster model is kept"
        )
    load = LoadTermsChoice(
        taken=taken, reason=reason, scale=scale[1], caster_scale=scale[0], statistic=test["statistic"],
        dof=test["dof"], p_value=test["p_value"],
    )  # fmt: skip
    if not taken:
        return caster, replace(record, load=load)
    return loaded, replace(record, model=loaded.form.friction, load=load)


def _model_error_scale(result: IdentificationResult) -> float:
    """The model-error scale S of an observer's run (:func:`wmrid.estimators.model_error.widen`)."""
    uncertainty = result.diagnostics.uncertainty
    model_error = None if uncertainty is None else uncertainty.model_error
    assert model_error is not None, "an observer's run records its widening"
    assert model_error.scale is not None, "an observer's run records its model-error scale"
    return float(model_error.scale)
