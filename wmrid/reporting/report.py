"""``wmrid report``: what was identified, how sure it is, how it compares with nominal/CAD and truth.

:func:`build_report` turns an identification (run on a log, or a saved ``identify --format json``
result) into a :class:`Report`: the paper's tables (Table 2: intermediate parameters; Table 3: base
parameters), a comparison with the robot's nominal and CAD values in units of the standard error,
error columns when a truth file is given, the diagnostics in plain words, residual statistics, and
figures (:mod:`wmrid.reporting.figures`).  :func:`to_html` (one self-contained file: inline SVG, no external
resources), :func:`to_markdown` (SVG figures as data URIs) and :func:`to_json_dict` render it.

Residuals: (1) the estimator's prior prediction error e (rad/s) of each wheel, RMS over the decimated
history; (2) when the log itself is at hand, the torque residual of the identified model,
tau - M eta_dot - V(eta) - F_v eta - F_d sgn(eta), with eta_dot from a zero-phase Savitzky-Golay cubic
over ACCEL_WINDOW_S = 0.1 s (:func:`wmrid.io.signals.speed_from_position` applied to the speed), never a raw
difference of noise: 0.1 s keeps speed noise out of the accelerations (white speed noise of 0.01 rad/s
at 1 kHz becomes about 0.03 rad/s^2) and still follows motion at a few hertz.  Its
RMS and the fit percentage 100 (1 - ||tau - tau_model|| / ||tau - mean(tau)||) per wheel are reported
(100 = the model explains every torque variation).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from wmrid.core.errors import WmridError
from wmrid.estimators.findings import StructuralMismatch, Uncertainty
from wmrid.estimators.records import GroupVerdict
from wmrid.estimators.result import IdentificationResult
from wmrid.estimators.verdict import LEGEND, PLAN_HINT
from wmrid.io.signals import speed_from_position
from wmrid.model import dynamics as model, torques
from wmrid.model.dynamics import RegressorForm
from wmrid.model.payload import PAYLOAD_UNITS, payload_statement
from wmrid.reporting import figures as fg
from wmrid.reporting.figures import check_format, render
from wmrid.reporting.report_table import ReportTable
from wmrid.reporting.warning_groups import grouped_warnings

#: A difference from the CAD value beyond this many standard errors is flagged.
SIGNIFICANT = 3.0
#: Window of the Savitzky-Golay differentiator for the accelerations of the torque residual, s.
ACCEL_WINDOW_S = 0.1


@dataclass
class Report:
    """Tables (lists of rows with a header), statements, residual statistics and rendered figures."""

    title: str
    summary: list[str]
    intermediate: ReportTable
    base: ReportTable
    payload: ReportTable | None
    diagnostics: list[str]
    notes: list[str]
    residuals: dict[str, Any]
    figures: dict[str, bytes] = field(default_factory=dict)  # name -> SVG bytes, rendered when first needed
    #: What the log determines (the result's verdict): its summary first, then one line per parameter group.
    verdict: list[str] = field(default_factory=list)
    figure_notes: dict[str, str] = field(default_factory=dict)  # name -> one sentence under its title
    result: dict[str, Any] = field(default_factory=dict)
    #: The verdict's parameter groups (their status colours the summary box).
    groups: tuple[GroupVerdict, ...] = ()
    #: How the report was made: wmrid's version, time, command, options, inputs with their SHA-256
    #: (:func:`wmrid.api.reporting.report`).
    provenance: dict[str, Any] = field(default_factory=dict)
    #: name -> :class:`wmrid.reporting.svg.Figure`, rendered once when an output needs it (:func:`rendered`).
    figure_objects: dict[str, Any] = field(default_factory=dict, repr=False, compare=False)
    #: The summary box at the top: the key numbers (label, value text) and what to do next (:func:`summary_box`).
    key_numbers: list[tuple[str, str]] = field(default_factory=list)
    next_steps: list[str] = field(default_factory=list)
    #: The identification (a saved result read back) and its log when the report was made from a log.
    identification: Any = field(default=None, repr=False, compare=False)
    log: Any = field(default=None, repr=False, compare=False)


def rendered(report: Report, fmt: str = "svg") -> dict[str, bytes]:
    """The report's figures as ``fmt`` bytes ("svg", the only format; else UsageError) by name, in order, each
    rendered once (kept in ``report.figures``)."""
    check_format(fmt)
    cache = report.figures
    for name, fig in report.figure_objects.items():
        if name not in cache:
            cache[name] = render(fig, fmt)
    return cache


def torque_residual(log: Any, theta0: np.ndarray, form: RegressorForm | None = None) -> dict[str, Any]:
    """RMS (N m) and fit % per wheel of tau - tau_model(eta, eta_dot) on the whole log (see the module docstring)."""
    eta_dot, how = speed_from_position(np.asarray(log.t) - log.t[0], np.asarray(log.eta), window_s=ACCEL_WINDOW_S)
    predicted = torques.wheel_torque(np.asarray(log.eta), eta_dot, theta0, form)
    res = np.asarray(log.tau) - predicted
    spread = np.asarray(log.tau) - np.asarray(log.tau).mean(axis=0)
    rms = np.sqrt(np.mean(res**2, axis=0))
    fit = 100.0 * (1.0 - np.linalg.norm(res, axis=0) / np.maximum(np.linalg.norm(spread, axis=0), 1e-300))
    return {
        "rms_n_m": {"tau_r": float(rms[0]), "tau_l": float(rms[1])},
        "fit_percent": {"tau_r": float(fit[0]), "tau_l": float(fit[1])},
        "eta_dot": how.replace("wheel speeds derived from wheel positions", "accelerations from wheel speeds"),
        "residual": res,
    }


def _interval(value: float, half: float) -> str:
    """'lo … hi' with the digits that tell the two ends apart (two significant digits of the half-width)."""
    digits = 6
    if half > 0 and value != 0:
        digits = max(digits, min(16, math.ceil(math.log10(abs(value) / half)) + 2))
    return f"{value - half:.{digits}g} … {value + half:.{digits}g}"


def _num(x: Any) -> float:
    """A reference value as a float, NaN where there is none (None: unknown)."""
    return math.nan if x is None else float(x)


def _pct(value: float, truth: float) -> float:
    return 100.0 * abs(value - truth) / abs(truth) if truth else math.nan


def _fmt(x: Any, digits: int = 6) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "—"
    if isinstance(x, str):
        return x
    return f"{x:.{digits}g}"


def build_report(
    result: IdentificationResult,
    *,
    document: dict[str, Any] | None = None,
    log: Any = None,
    truth: dict[str, float] | None = None,
    figures: bool = True,
    validation_log: Any = None,
) -> Report:
    """A report of ``result`` (run on ``log`` when it is given; ``document``: the saved identify JSON it was read from,
    kept in the report as it was; None: ``result.to_dict()``).  ``validation_log``: the ``--validate`` log in memory,
    for its measured and predicted speeds.  ``figures``: build the figures (rendered only when an output needs them:
    :func:`rendered`).  Everything is read from the typed result; nothing is decided again."""
    rl = result
    form = rl.form
    names = form.theta_names()
    observer = rl.observer_settings  # the observer's run every method starts from
    nominal, reference = rl.nominal, rl.reference
    effort_unit = rl.log_info.effort_unit
    diag = rl.diagnostics

    # Table 2: intermediate parameters
    theta = rl.theta_dict()  # values, std (None: not finite) and start by name, as the JSON's "theta"
    theta_vals, theta_std, start = theta["values"], theta["std"], theta["start"]
    ref_theta = true_theta_row = None
    # A caster-drag parameter the reference or truth does not give is NaN: its intermediate parameters show "—".
    if reference is not None:
        ref_base = np.array([_num(reference.get(n)) for n in form.base_names])
        ref_theta = model.intermediate_parameters(ref_base, form).ravel()
    if truth is not None:
        true_theta_row = model.intermediate_parameters(
            np.array([truth.get(n, math.nan) for n in form.base_names]), form
        ).ravel()
    header = ["parameter", "start (nominal)"]
    header += ["CAD"] if ref_theta is not None else []
    header += ["true", "estimate", "std", "error %"] if true_theta_row is not None else ["estimate", "std"]
    rows = []
    for j, name in enumerate(names):
        row = [name, _fmt(start[name])]
        if ref_theta is not None:
            row.append(_fmt(ref_theta[j]))
        if true_theta_row is not None:
            row += [_fmt(true_theta_row[j]), _fmt(theta_vals[name]), _fmt(theta_std[name], 2),
                    _fmt(_pct(theta_vals[name], true_theta_row[j]), 3)]  # fmt: skip
        else:
            row += [_fmt(theta_vals[name]), _fmt(theta_std[name], 2)]
        rows.append(row)
    intermediate = ReportTable(header, rows)

    # Table 3: base parameters, with the comparison against nominal and CAD
    factor = ((diag.uncertainty or Uncertainty()).interval_factor or {})["95%"]
    header = ["parameter", "unit", "estimate", "std", "95 % interval"]
    header += (["nominal"] if nominal else []) + (["CAD", "(est − CAD)/std"] if reference else [])
    header += ["true", "error %", "(est − true)/std"] if truth else []
    rows = []
    flagged = []
    table = rl.table  # value, std, unit and the flags the estimator recorded
    inflated = any("inflated" in parameter.flags for parameter in table.values())
    warned = any(not parameter.trusted for parameter in table.values())
    for name, parameter in table.items():
        value, known_std = parameter.value, math.isfinite(parameter.std)
        std = parameter.std if known_std else None
        interval = _interval(value, factor * parameter.std) if known_std else "—"
        mark = f" {parameter.mark}" if parameter.mark else ""
        row = [name, parameter.unit, _fmt(value), _fmt(std, 2) + mark, interval]
        if nominal:
            row.append(_fmt(nominal.get(name)))
        if reference:
            ref = _num(reference.get(name))  # no CAD value of a caster's drag, nor of a URDF's friction
            z = (value - ref) / std if known_std and std else math.nan
            mark = " ⚑" if math.isfinite(z) and abs(z) > SIGNIFICANT else ""
            if mark:
                flagged.append(f"{name} differs from its CAD value by {z:+.1f} std")
            row += [_fmt(ref), f"{z:+.1f}{mark}" if math.isfinite(z) else "—"]
        if truth:
            t = truth.get(name)
            zt = (value - t) / std if (t is not None and known_std and std) else math.nan
            row += [
                _fmt(t),
                _fmt(_pct(value, t), 3) if t is not None else "—",
                f"{zt:+.1f}" if math.isfinite(zt) else "—",
            ]
        rows.append(row)
    base = ReportTable(header, rows)

    payload = None
    if rl.payload is not None:
        said = payload_statement(rl.payload)
        payload = ReportTable(
            header=["quantity", "estimate", "std", "unit"],
            rows=[[k, _fmt(v), _fmt(e, 2), PAYLOAD_UNITS[k]] for k, (v, e) in rl.payload.items()],
            statement=said[0].upper() + said[1:] + ".",
        )

    statements = _statements(rl, inflated=inflated, warned=warned, flagged=flagged)

    residuals = {}
    if rl.history is not None:
        e = np.asarray(rl.history.e)
        residuals = {
            "rms_e_rad_s": {
                "eta_r": float(np.sqrt(np.mean(e[:, 0] ** 2))),
                "eta_l": float(np.sqrt(np.mean(e[:, 1] ** 2))),
            },
            "samples": len(e),
        }
    if diag.prediction_error_rms is not None:
        residuals["prediction_error_rms"] = diag.prediction_error_rms.to_dict()
    if log is not None and effort_unit == "N m":
        theta0 = np.array([rl.parameters[n][0] for n in form.base_names])
        residuals["torque"] = torque_residual(log, theta0, form)

    verdict = rl.verdict
    # the verdict heads the summary box; a method note (verdict.first) follows it, as in the terminal
    said_verdict = [] if verdict is None else [verdict.summary, *(f[0].upper() + f[1:] + "." for f in verdict.first)]
    groups = [] if verdict is None else list(verdict.lines or [g.text for g in verdict.groups])
    said_verdict += [line[0].upper() + line[1:] + "." for line in groups]
    said_verdict += [f"Check: {line}." for line in verdict.check] if verdict is not None else []
    said_verdict += [verdict.units[0].upper() + verdict.units[1:] + "."] if verdict and verdict.units else []
    info = rl.log_info
    samples = "?" if info.samples is None else info.samples
    duration = math.nan if info.duration_s is None else info.duration_s
    rate = math.nan if info.rate_hz is None else info.rate_hz
    method_text = "" if rl.method_settings is None else rl.method_settings.before_observer()
    report = Report(
        title=f"wmrid report: {rl.source}",
        verdict=said_verdict,
        summary=[
            f"{samples} samples, {duration:.3f} s at {rate:.5g} Hz; regressor: {form.kind} form; "
            f"{method_text}k = {observer.k:g} 1/s; start: {rl.start_source}",
        ],
        intermediate=intermediate, base=base, payload=payload, diagnostics=statements,
        notes=list(info.notes), residuals=residuals, result=rl.to_dict() if document is None else document,
        groups=() if verdict is None else verdict.groups, identification=rl, log=log,
    )  # fmt: skip
    report.key_numbers, report.next_steps = summary_box(rl)
    if figures:
        _add_figures(report, rl, log, truth, validation_log)
    return report


def _statements(rl: IdentificationResult, *, inflated: bool, warned: bool, flagged: list[str]) -> list[str]:
    """The diagnostics in plain words: the std's meaning, the friction model, the structural check, the excitation,
    the CAD differences (``flagged``), then the warnings; the validation, the method and a non-N m effort first."""
    diag = rl.diagnostics
    unc = diag.uncertainty or Uncertainty()
    model_error = unc.model_error
    friction = diag.friction
    mismatch = diag.structural_mismatch or StructuralMismatch()
    statements = [
        "Standard errors: how much each estimate varies along the log"
        + f" ({unc.method or 'jackknife'}"
        + (f", {unc.segments} segments" if unc.segments else "")
        + f", {unc.dof} degrees of "
        f"freedom); estimate ± {(unc.interval_factor or {})['95%']:.2f} std covers the truth with 95 % probability "
        "when disturbances do not feed back into the efforts. " + (f"Caveat: {unc.caveat}." if unc.caveat else ""),
        *(
            [
                LEGEND["†"]
                + "; here"
                + (f" (S = {model_error.scale:.3g})" if model_error.applied else "")
                + f": {model_error.meaning}."
            ]
            if inflated and model_error is not None
            else []
        ),
        *([LEGEND["!"] + "."] if warned else []),
        *(
            [
                f"Friction model: {friction.model} ({friction.chosen_by}"
                + (f": {friction.reason}" if friction.reason else "")
                + ")."
            ]
            if friction is not None
            else []
        ),
        "Model check: "
        + (
            "the intermediate parameters do not fit one set of base parameters as the model says they must"
            if mismatch.p_value is not None and mismatch.p_value < 1e-3
            else "the intermediate parameters fit one set of base parameters, as the model says they must"
        )
        + f" (structural consistency, Eqs. 23-24: p = {mismatch.p_value:.2g} on {mismatch.dof} directions).",
        "Excitation: "
        + (
            f"not determined by this log: {', '.join(diag.undetermined)}"
            if diag.undetermined
            else "the data, not the start value, set every parameter"
        )
        + f" (λ_min(Γ) = {diag.lambda_min_gamma:.3g}, α = {rl.observer_settings.alpha:g}).",
        *flagged,
        *(["Robot file: assumed " + "; ".join(diag.robot_assumed) + "."] if diag.robot_assumed else []),
        *grouped_warnings(rl.warnings),
    ]
    effort_unit = rl.log_info.effort_unit
    if effort_unit != "N m":
        statements.insert(
            0, f"Units: the effort is in {effort_unit}, not N m, so every parameter is in {effort_unit}-based units."
        )
    if rl.method != "observer":
        statements.insert(
            0,
            f"Method: {rl.method} ({diag.method_seconds:.3g} s). Table 3 holds its "
            "estimate; Table 2, the excitation figures and the history are the observer's, run on the same log.",
        )
    v = rl.validation
    if v is not None and v.not_simulated:
        statements.insert(0, f"Validation on {v.log}: {v.not_simulated}.")
    elif v is not None:
        statements.insert(
            0,
            f"Validation on {v.log}: fit {_fmt(v.fit_percent['eta_r'], 3)} % (right wheel), "
            f"{_fmt(v.fit_percent['eta_l'], 3)} % (left wheel): {v.definition}; "
            f"the prediction: {v.predictor}.",
        )
    return statements


#: The parameters the summary box shows: the inertia matrix, the Coriolis coefficient and the wheels' friction (the
#: physical quantities; m11, m12, m22, its inverse, stay in the table).
KEY_PARAMETERS = ("M11", "M22", "M12", "Vc", "Fv1", "Fv2", "Fd1", "Fd2")


def summary_box(result: IdentificationResult) -> tuple[list[tuple[str, str]], list[str]]:
    """The key numbers (name, "value ± std unit") and the next steps, in words, of an identification."""
    table = result.table
    flagged = {name for name, parameter in table.items() if not parameter.trusted}
    numbers = []
    for name in [n for n in KEY_PARAMETERS if n in table] + [n for n in table if n not in (*KEY_PARAMETERS, "m11",
                                                                                          "m12", "m22")]:  # fmt: skip
        parameter = table[name]
        std = parameter.std
        spread = f" ± {_fmt(std, 2)}" if math.isfinite(std) else " (std unknown)"
        numbers.append((name + (" ⚑" if name in flagged else ""), f"{_fmt(parameter.value)}{spread} {parameter.unit}"))
    verdict = result.verdict
    groups = () if verdict is None else verdict.groups
    steps = []
    if verdict is not None and verdict.doubt:
        steps.append("Check the log's units and columns first (see the verdict and the diagnostics): these numbers "
                     "are not usable as they are.")  # fmt: skip
    plan = [w for w in result.warnings if w.startswith(PLAN_HINT)]
    if plan:
        steps.append(plan[0][0].upper() + plan[0][1:] + ".")
    elif any(g.status in ("poorly determined", "not determined") for g in groups):
        steps.append("Record a longer log that drives the robot harder (faster turns, both directions): the "
                     "parameters marked poorly or not determined need more excitation.")  # fmt: skip
    if flagged:
        steps.append(f"Do not trust the std of {', '.join(sorted(flagged))} (⚑): the warnings under Diagnostics say "
                     "why.")  # fmt: skip
    if not steps or all(g.status == "determined" for g in groups):
        steps.append("Use the numbers: save the result (wmrid identify LOG --robot ROBOT -o run.json) and turn it into "
                     "a robot model or a feedforward with wmrid export run.json --robot ROBOT -o robot.urdf (or .xml, "
                     ".yaml, .py); check later logs against it with wmrid monitor LOG --model run.json.")  # fmt: skip
    return numbers, steps


def _speed_fit(log: Any, theta0: np.ndarray, form: Any, torque_hold: str) -> tuple[np.ndarray, dict[str, Any]]:
    """The model's simulated wheel speeds on ``log`` (from its first speed, driven by its efforts) and their fit
    (:func:`wmrid.model.predict.validation_fit`'s)."""
    # the predictor's numba kernel: only a report with the log
    from wmrid.model.predict import fit_percent, predictor_text, simulate_speeds

    t, eta = np.asarray(log.t, dtype=float), np.asarray(log.eta, dtype=float)
    eta_hat = simulate_speeds(t, np.asarray(log.tau, dtype=float), theta0, eta[0], torque_hold=torque_hold, form=form)
    return eta_hat, {"fit": fit_percent(eta, eta_hat), "predictor": predictor_text(torque_hold, form)}


def _add_figures(report: Report, rl: Any, log: Any, truth: dict[str, float] | None, validation_log: Any) -> None:
    """The report's figures, each under a short title with a sentence saying what it shows (``figure_notes``)."""
    # the figure builders (~10 ms): only a report with figures
    from wmrid.reporting import convergence_figures as cf, fit_figures as ff

    def both(name: str, fig: Any, note: str) -> None:
        if fig is None:
            return
        report.figure_objects[name] = fig  # rendered when an output needs it (:func:`rendered`)
        report.figure_notes[name] = note

    theta0 = np.array([rl.parameters[n][0] for n in rl.form.base_names])
    hold = rl.settings.torque_hold
    if rl.history is not None:
        both("Base parameters over time", cf.build_base_convergence_figure(rl, truth),
             "Each base parameter recovered (Eq. 21, in closed form) from the observer's intermediate estimates as "
             "the log is replayed; the band is the final estimate ± 2σ.")  # fmt: skip
    for which, wheel_log in (("identification", log), ("validation", validation_log)):
        if wheel_log is None or not np.all(np.isfinite(theta0)):
            continue
        title = "Measured and predicted wheel speeds" + (" (validation log)" if which == "validation" else "")
        try:
            eta_hat, fit = _speed_fit(wheel_log, theta0, rl.form, hold)
        except WmridError as err:  # a model the simulator cannot run (a two-term caster drag): said, not drawn
            report.diagnostics.append(f"{title}: not drawn: {err}")
            continue
        figure = ff.build_speed_fit_figure(np.asarray(wheel_log.t), np.asarray(wheel_log.eta), eta_hat, fit["fit"])
        note = (
            f"On the {which} log ({getattr(wheel_log, 'source', '')}): fit {_fmt(fit['fit'][0], 3)} % right, "
            f"{_fmt(fit['fit'][1], 3)} % left (100 (1 − ‖η − η̂‖ / ‖η − mean η‖)); {fit['predictor']}."
        )
        both(title, figure, note)
    estimate = rl.estimate
    if estimate is not None and estimate.cov.size:
        cov = np.where(np.isfinite(estimate.cov), estimate.cov, math.nan)  # unknown: NaN, as in the JSON (null)
        names = list(rl.form.base_names[: len(estimate.theta0)])
        both("Parameter correlations", ff.build_correlation_figure(names, cov),
             "Correlations of the base parameters' estimates (from their covariance): near ±1, the log moves the "
             "two together and tells them apart poorly.")  # fmt: skip
    if log is not None:
        both("Wheel efforts and speeds (paper Fig. 6)", fg.build_log_overview(log), "The log as read.")
        if getattr(log, "pose", None) is not None:
            both("Path (paper Fig. 5)", fg.build_path_figure(log.pose), "The robot's path in the plane.")
    if rl.history is not None:
        both("Intermediate parameters over time", cf.build_estimates_figure(rl, truth),
             f"The observer's estimates θ̂ of Eqs. 23-24 (row i: wheel i, 1 = right, 2 = left; {rl.form.kind} form, "
             f"k = {rl.observer_settings.k:g} 1/s).")  # fmt: skip
        if truth is not None:
            both("Estimation errors over time (paper Fig. 7)", cf.build_estimates_figure(rl, truth, error_mode=True),
                 "θ̂ − θ of the intermediate parameters against the truth.")  # fmt: skip
        both("Prediction errors", ff.build_residuals_figure(rl),
             "The estimator's prediction errors of the wheel speeds, over time and their distribution.")  # fmt: skip
        both("Excitation: λ_min(Γ) over time", ff.build_excitation_figure(rl),
             "The smallest eigenvalue of the information matrix Γ: the data outweigh the start value once it is "
             "well above α.")  # fmt: skip


# --------------------------------------------------------------------------------------------------
# Rendering


def residual_lines(report: Report) -> list[str]:
    """The residual statistics in words."""
    out = []
    rms = report.residuals.get("rms_e_rad_s")
    if rms:
        out.append("RMS prediction error of the estimator: " + ", ".join(f"{k} {v:.3g} rad/s" for k, v in rms.items()))
    tq = report.residuals.get("torque")
    if tq:
        out.append(
            "torque residual of the identified model: RMS "
            + ", ".join(f"{k} {v:.3g} N m" for k, v in tq["rms_n_m"].items())
            + "; fit "
            + ", ".join(f"{k} {v:.1f} %" for k, v in tq["fit_percent"].items())
            + f" ({tq['eta_dot']})"
        )
    return out


def to_json_dict(report: Report) -> dict[str, Any]:
    """The report's content as plain data (figures left out)."""
    residuals = {k: v for k, v in report.residuals.items() if k != "torque"}
    if "torque" in report.residuals:
        residuals["torque"] = {k: v for k, v in report.residuals["torque"].items() if k != "residual"}
    return {
        "title": report.title, "base": report.base.to_dict(), "intermediate": report.intermediate.to_dict(),
        "payload": None if report.payload is None else report.payload.to_dict(),
        "key_numbers": [list(pair) for pair in report.key_numbers], "next_steps": report.next_steps,
        "diagnostics": report.diagnostics, "residuals": residuals, "notes": report.notes,
        "result": report.result, "provenance": report.provenance,
    }  # fmt: skip
