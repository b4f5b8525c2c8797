"""The last word on a result: every statement that quotes a parameter, made once from its final numbers.

A result passes through several stages (the observer's run, a method's estimate, the closed-loop check, the
timing and hold terms); each may change a std.  What the user reads must not depend on which stage wrote it, so
:func:`settle` rebuilds, from the reported parameters and their final covariance:

* the per-parameter warnings (poorly determined, not positive definite, negative friction), so that every std a
  warning quotes is the table's;
* ``diagnostics.flagged``, which has one meaning everywhere: *do not trust this value's std*.  A parameter is
  flagged when the log does not determine it (infinite std), when the model does not fit the log so that no std
  covers the error (the prediction-error check), when its value is one no robot has, and when its unit is in
  doubt (:mod:`wmrid.estimators.plausibility`).  A std widened to cover a model error is trusted (marked "†",
  ``diagnostics.inflated``), and so is a large std (``diagnostics.poorly_determined``): both say how
  uncertain the value is;
* the units check (``diagnostics.units``);
* the verdict (``result.verdict``): one plain sentence per parameter group (inertia, Coriolis, friction,
  casters) saying whether this log determines it, and the main reason when it does not.

Idempotent: settling a settled result changes nothing.
"""

from __future__ import annotations

import math
from dataclasses import replace
from typing import Any

import numpy as np

from wmrid.estimators.diagnostics import (
    NOT_SEPARABLE,
    POORLY_DETERMINED,
    derived_poorly_determined,
    flagged_names,
    impossible_parameters,
    physics_warnings,
    poorly_text,
)
from wmrid.estimators.findings import UnitsCheck
from wmrid.estimators.plausibility import units_check
from wmrid.estimators.records import GroupVerdict, Verdict

#: The start of the warning that names ``wmrid plan`` when a parameter is poorly determined (issue 29).
PLAN_HINT = "to determine "

#: Warnings :func:`settle` owns: dropped from the stages' warnings and made again from the final numbers.
OWNED = (
    " is poorly determined by this log", " is poorly determined by these logs",
    "is not positive definite, which no robot has", "friction cannot push; check signs",
    "drag cannot push; check signs", "unit check: ", "the estimated inertia matrix M is not positive definite",
    PLAN_HINT,
)  # fmt: skip

#: Above this relative std a parameter cannot be told from zero: "not determined by this log".
NOT_DETERMINED = 1.0

#: The parameter groups of the verdict, in the order said.  The inertia is judged on its diagonal (the coupling
#: M12 is often near zero, where a relative std says little) and the coupling is named when it is worse.
GROUPS = (
    ("inertia", ("M11", "M22"), ("M12",)),
    ("Coriolis coefficient", ("Vc",), ()),
    ("friction", ("Fv1", "Fv2", "Fd1", "Fd2"), ()),
)

#: The one legend of each mark, the same in the table, compare, the report and the docs.
LEGEND = {
    "†": "† std widened to cover an error the log shows beyond its noise (model, timing, feedback); it includes it",
    "!": "! flagged: do not trust this std (see the warnings)",
    "✗": "✗ impossible for a physical robot",
}


def _relative(value: float, std: float) -> float:
    if not math.isfinite(std):
        return math.inf
    if value == 0:
        return math.inf if std > 0 else 0.0
    return std / abs(value)


def _references(result: Any) -> list[tuple[str, dict[str, float]]]:
    """(label, values) of the robot file for the units check: its nominal and CAD base parameters, also when the
    result does not show them (efforts not in N m: ``diagnostics.robot_values``)."""
    out = []
    kept = result.diagnostics.robot_values or {}
    for label, ref in (
        ("nominal", result.nominal or kept.get("nominal")),
        ("CAD", result.reference or kept.get("CAD")),
    ):
        if ref:
            out.append((label, {k: v for k, v in ref.items() if v is not None}))
    return out


def _correlations(result: Any) -> tuple[tuple[str, ...], np.ndarray]:
    names = result.form.base_names
    cov = np.asarray(result.theta0_cov, dtype=float)
    if cov.shape != (len(names), len(names)):
        return names, np.zeros((len(names), len(names)))
    std = np.sqrt(np.clip(np.diag(cov), 0.0, None))
    ok = np.isfinite(std) & (std > 0)
    safe = np.where(ok, std, 1.0)
    with np.errstate(invalid="ignore"):
        corr = cov / np.outer(safe, safe)
    corr[~ok, :] = 0.0
    corr[:, ~ok] = 0.0
    return names, np.nan_to_num(corr)


def _poorly_warnings(result: Any, method: str | None) -> tuple[list[str], list[str], list[list[Any]]]:
    """(warnings, names, not-separable pairs) for the reported parameters whose std exceeds POORLY_DETERMINED of
    their value, the std being the reported one: the base parameters with the partners they cannot be told from,
    then M11, M12, M22 (:func:`wmrid.estimators.diagnostics.derived_poorly_determined`)."""
    names, corr = _correlations(result)
    combined = result.diagnostics.combined
    logs = 1 + len((None if combined is None else combined.results) or ())
    texts, poorly, pairs = [], [], []
    for i, name in enumerate(names):
        value, std = result.parameters[name]
        if not math.isfinite(std) or std <= POORLY_DETERMINED * abs(value):
            continue
        poorly.append(name)
        partners = [j for j in np.argsort(-np.abs(corr[i])) if j != i and abs(corr[i, j]) > NOT_SEPARABLE]
        pairs += [[name, names[j], float(corr[i, j])] for j in partners]
        why = "; it is not separable from " + ", ".join(
            f"{names[j]} (correlation {corr[i, j]:+.3f})" for j in partners
        ) if partners else ""  # fmt: skip
        texts.append(poorly_text(name, (value, std), result.units[name], method, logs) + why)
    derived = derived_poorly_determined(result.parameters, names)
    texts += [poorly_text(name, result.parameters[name], result.units[name], method, logs) for name in derived]
    return texts, poorly + derived, pairs


def settle(result: Any, radius: float | None = None) -> Any:
    """``result`` with its parameter statements made from its final numbers (module docstring).  ``radius`` m:
    the robot's wheel radius for the units check (default: the one a previous settle recorded)."""
    previous = result.diagnostics.units
    r = radius if radius is not None else (None if previous is None else previous.wheel_radius)
    effort_free = result.log_info.effort_unit != "N m"
    notes = result.log_info.notes
    checked = units_check(result.parameters, result.log_info.scales, _references(result), r, notes, effort_free)
    units = UnitsCheck.from_dict({**checked, "wheel_radius": r})
    method = result.method if result.method != "observer" else None
    poorly_texts, poorly, pairs = _poorly_warnings(result, method)
    diagnostics = replace(result.diagnostics, units=units, poorly_determined=tuple(poorly), not_separable=tuple(pairs))
    diagnostics = replace(diagnostics, flagged=flagged_names(result.parameters, diagnostics))
    impossible = impossible_parameters(result.parameters)
    diagnostics = replace(diagnostics, impossible=tuple(n for n in result.parameters if n in impossible))
    kept = [w for w in result.warnings if not any(key in w for key in OWNED)]
    unit_texts = [f"unit check: {f['text']}" for f in checked["findings"]]
    hint = [plan_hint(poorly)] if poorly else []
    warnings = (*unit_texts, *kept, *poorly_texts, *hint, *physics_warnings(result.parameters))
    out = replace(result, diagnostics=diagnostics, warnings=warnings)
    return replace(out, verdict=verdict(out))


def plan_hint(poorly: list[str]) -> str:
    """The warning that says how to get the poorly determined parameters: a drive designed for them."""
    return (
        f"{PLAN_HINT}{_join(poorly)}, drive the robot as wmrid plan designs it: save this result (--format json -o "
        "run.json), then wmrid plan --robot ROBOT --given run.json -o next.csv adds what this log holds and targets "
        "the rest; identify that drive's log with --given run.json to combine the two"
    )


def _reason(names: tuple[str, ...], result: Any) -> str:
    """The main reason the parameters ``names`` are not (well) determined."""
    diag = result.diagnostics
    pairs = [p for p in diag.not_separable or () if p[0] in names]
    if pairs:
        a, b, c = pairs[0]
        return f"{a} cannot be told from {b} on this log (correlation {c:+.3f}); drive so that they act differently"
    if set(diag.timing_widened()) & set(names):
        return "the efforts' timing against the speeds is uncertain and moves them"
    feedback = () if diag.feedback is None else diag.feedback.widened or ()
    if set(feedback) & set(names):
        return "a disturbance fed back by the controller moves them (the closed-loop term)"
    scale = (None if diag.model_error is None else diag.model_error.scale) or 1.0
    if scale > 2.0:
        return f"the log departs from the model (std scaled by {scale:.3g} to cover it)"
    return "too little excitation: accelerate, brake, turn and reverse more, for longer"


#: A parameter whose value the log bounds (|value| + 3 std) below this share of the term's largest effort is
#: negligible: determined to be small, whatever its relative std.
NEGLIGIBLE = 0.02


def _negligible(name: str, value: float, std: float, result: Any) -> float | None:
    """The 3-std bound on |``name``| when it is negligible (module constant NEGLIGIBLE), else None.  The term's
    scale: the largest effort for a Coulomb friction or a caster's drag, over the largest speed for a viscous
    friction, over its square for Vc (the log's ``scales``); inertia entries are never negligible."""
    scales = result.log_info.scales or {}
    effort, speed = max(scales.get("effort_max") or [0.0]), max(scales.get("speed_max") or [0.0])
    if not (math.isfinite(value) and math.isfinite(std)) or effort <= 0 or speed <= 0:
        return None
    if name in ("Fd1", "Fd2", "Cv", "Cw") or (name.startswith("D") and name[1:].isdigit()):
        scale = effort
    elif name in ("Fv1", "Fv2"):
        scale = effort / speed
    elif name == "Vc":
        scale = effort / speed**2
    else:
        return None
    bound = abs(value) + 3.0 * std
    return bound if bound < NEGLIGIBLE * scale else None


#: Words of the signal warnings that put the efforts' signs in doubt
# (wmrid.estimators.observer.survey.Survey.signal_warnings).
SIGN_WARNINGS = ("mostly opposes its speed", "never changes sign while its speed does")


def _signs(result: Any) -> str:
    """A clause naming the efforts' signs when the signal warnings put them in doubt, else ""."""
    if any(key in w for w in result.warnings for key in SIGN_WARNINGS):
        return "; the efforts' signs are suspect (see the warnings)"
    return ""


def _group_sentence(group: str, names: tuple[str, ...], extra: tuple[str, ...], result: Any) -> GroupVerdict | None:
    params = result.parameters
    present = tuple(n for n in names if n in params)
    if not present:
        return None
    flagged = set(result.diagnostics.flagged or ())
    units = result.diagnostics.units or UnitsCheck()
    misfit = result.diagnostics.prediction_misfit
    rel = {n: _relative(*params[n]) for n in present + tuple(n for n in extra if n in params)}
    # a value the log bounds to a negligible share of the effort is determined: it is small, not unknown
    negligible = {
        n: bound
        for n in present
        if rel[n] > POORLY_DETERMINED and (bound := _negligible(n, *params[n], result)) is not None
    }
    judged = tuple(n for n in present if n not in negligible) or present
    if set(negligible) == set(present):  # all negligible: judged on the bound itself
        rel.update({n: 0.0 for n in present})
    worst = max(judged, key=lambda n: rel[n])
    label = f"{group} ({', '.join(present + tuple(n for n in extra if n in params))})"
    impossible = impossible_parameters(params) & set(present)
    status: str
    reason: str | None = None
    if units.doubt:
        status, reason = "in doubt", "the log's units or columns are in doubt (see the unit check)"
    elif not math.isfinite(rel[worst]):
        status, reason = "not determined", "the log does not excite it: the start value sets it"
    elif impossible:
        status, reason = "in doubt", f"{', '.join(sorted(impossible))}: a value no robot has{_signs(result)}"
    elif misfit.applied and set(present) <= flagged:
        quality = (
            "determined"
            if rel[worst] <= POORLY_DETERMINED
            else "poorly determined"
            if rel[worst] <= NOT_DETERMINED
            else "not determined"
        )
        status = "in doubt"
        reason = (
            f"{quality} by its std, but the model does not fit this log (slip, backlash or an effect it leaves "
            f"out), so no std covers the error{_signs(result)}"
        )
    elif rel[worst] <= POORLY_DETERMINED:
        status = "determined"
    elif rel[worst] <= NOT_DETERMINED:
        status, reason = "poorly determined", _reason(present, result)
    else:
        status, reason = "not determined", _reason(present, result) + " (its std exceeds its value)"
    pct = f"{100 * rel[worst]:.2g} %" if math.isfinite(rel[worst]) else "unbounded"
    text = f"{label}: {status}"
    small = ", ".join(f"|{n}| < {b:.2g} {result.units[n]}" for n, b in negligible.items())
    said_negligible = None
    if status in ("determined", "poorly determined") and len(negligible) == len(present):
        text += f" as negligible ({small}, at 3 std: under {100 * NEGLIGIBLE:g} % of the largest effort)"
        said_negligible = negligible
    elif status in ("determined", "poorly determined"):
        text += f" (std up to {pct} of the value" + (f", {worst})" if len(judged) > 1 else ")")
        if negligible:
            text += f"; negligible: {small}"
            said_negligible = negligible
    coupling = [n for n in extra if n in rel and rel[n] > POORLY_DETERMINED and status == "determined"]
    if coupling:
        text += (
            f"; {coupling[0]} only to {100 * rel[coupling[0]]:.2g} %"
            if math.isfinite(rel[coupling[0]])
            else (f"; {coupling[0]} not determined")
        )
    if reason:
        text += f": {reason}"
    return GroupVerdict(
        group=group, parameters=present, worst=worst, relative_std=rel[worst] if math.isfinite(rel[worst]) else None,
        status=status, reason=reason, text=text, negligible=said_negligible,
    )  # fmt: skip


def verdict(result: Any) -> Verdict:
    """One sentence per parameter group (see the module docstring and :class:`Verdict`): the summary, a
    :class:`GroupVerdict` per group, the lines to print, and when there is something to add: ``first`` (a method
    switched), ``check`` (unit findings that are warnings, not doubts), ``units`` (what units were assumed, when no
    robot file could check them)."""
    said = [_group_sentence(g, names, extra, result) for g, names, extra in GROUPS]
    casters = tuple(result.form.base_names[8:])
    if casters:
        said.append(_group_sentence("casters", casters, (), result))
    groups = [g for g in said if g is not None]
    units = result.diagnostics.units or UnitsCheck()
    if units.doubt:
        first = (units.findings or ())[0].text
        summary = f"Do not use these numbers: {first}."
    else:
        good = [g.group for g in groups if g.status == "determined"]
        weak = [g.group for g in groups if g.status == "poorly determined"]
        bad = [g.group for g in groups if g.status in ("not determined", "in doubt")]
        parts = []
        subject = "these logs determine" if result.diagnostics.combined else "this log determines"
        if good:
            parts.append(f"{subject} the {_join(good)}")
        if weak:
            parts.append(f"{'' if good else subject + ' '}the {_join(weak)} only poorly")
        if bad:
            parts.append(f"not the {_join(bad)}")
        text = "; ".join(parts) if parts else "nothing to judge"
        summary = text[0].upper() + text[1:] + "."
        if not good and not weak:
            summary = f"{subject[0].upper() + subject[1:]} none of the parameters ({_join(bad)})."
    first: tuple[str, ...] = ()
    reported = None if result.diagnostics.feedback is None else result.diagnostics.feedback.reported
    if reported and reported != "observer" and result.method == reported:
        other = "IDIM-IV" if reported == "iv" else "IDIM"
        first = (
            f"method: {other}, not the observer: the closed-loop check found the observer's estimate biased by "
            "feedback (see the first warning); --method observer keeps the observer's",
        )
    findings = [f.text for f in units.findings or () if not f.doubt]
    check = tuple(findings) if findings and not units.doubt else ()
    assumed_units = None
    scales = result.log_info.scales or {}
    speed, effort = max(scales.get("speed_max") or [0.0]), max(scales.get("effort_max") or [0.0])
    unit = result.log_info.effort_unit
    assumed = f"speeds read as rad/s (up to {speed:.3g}), efforts as {unit} (up to {effort:.3g})"
    if scales and not _references(result):
        assumed_units = f"units not checked against a robot file (give --robot): {assumed}"
    elif scales and unit != "N m":
        assumed_units = (
            f"units checked against the robot file only through ratios of its parameters (the efforts are in {unit}, "
            f"its values in N m): {assumed}"
        )
    return Verdict(summary, tuple(groups), lines(groups), first, check, assumed_units)


def lines(groups: list[GroupVerdict]) -> tuple[str, ...]:
    """The groups' sentences to print: one per group, or one for all when every group has the same status and
    reason (a unit in doubt, a model that does not fit the log)."""
    if (
        len(groups) > 1
        and groups[0].reason
        and all((g.status, g.reason) == (groups[0].status, groups[0].reason) for g in groups)
    ):
        return (f"{_join([g.group for g in groups])}: {groups[0].status}: {groups[0].reason}",)
    return tuple(g.text for g in groups)


def _join(words: list[str]) -> str:
    return words[0] if len(words) == 1 else ", ".join(words[:-1]) + " and " + words[-1]
