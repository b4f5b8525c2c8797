"""Presenting results: rich tables for people, JSON for pipes.  No computation happens here."""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

from wmrid.estimators.findings import StructuralMismatch, Uncertainty
from wmrid.estimators.methods import Comparison
from wmrid.estimators.records import Verdict
from wmrid.estimators.result import IdentificationResult
from wmrid.estimators.verdict import LEGEND
from wmrid.io.inspect import McapInventory, TableInventory
from wmrid.model.payload import PAYLOAD_UNITS, payload_statement
from wmrid.reporting.terminal import STYLES, print_table, styled, warning as warning_line
from wmrid.reporting.warning_groups import grouped_warnings
from wmrid.runtime.atomic import to_json_text


def to_json(obj: Any) -> str:
    """Strict JSON (NaN/inf become null), without a trailing newline."""
    return to_json_text(obj).rstrip("\n")


def _fmt(x: float | None, digits: int = 6) -> str:
    if x is None or not math.isfinite(x):
        return "-"
    return f"{x:.{digits}g}"


def _cell(text: str, meaning: str | None) -> Any:
    return text if meaning is None else styled(text, meaning)


def print_verdict(verdict: Verdict | None, console: Any, prefix: str = "") -> None:
    """The verdict (:func:`wmrid.estimators.verdict.verdict`) before any number: its summary, then one line per
    parameter group; a summary that says not to use the numbers in the impossible style."""
    if verdict is None:
        return
    console.print(f"{prefix}verdict: {verdict.summary}", style=STYLES["impossible"] if verdict.doubt else "bold")
    for line in verdict.first:  # a method note (the closed-loop check reported IDIM): which estimate the numbers are
        console.print(f"{prefix}  {line}", style="bold")
    for line in verdict.lines or [g.text for g in verdict.groups]:
        console.print(f"{prefix}  {line}")
    for line in verdict.check:
        console.print(f"{prefix}  check: {line}")
    if verdict.units:
        console.print(f"{prefix}  {verdict.units}")


#: What the rows of the base parameters are, in the glossary's words (docs/reference/glossary.md).
ROWS_MEAN = (
    "rows: the inverse of the inertia matrix M (m11 m12 m22), M itself at the wheels (M11 M12 M22), the Coriolis "
    "coefficient (Vc), the viscous (Fv1 Fv2) and Coulomb (Fd1 Fd2) friction of the right (1) and left (2) wheel"
)


def print_identification(result: IdentificationResult, console: Any, verbose: bool = False) -> None:
    """A table of the base parameters with their standard errors, nominal and CAD values; a flagged value in the
    flagged style, a physically impossible one in the impossible style and marked ✗ (the flags the estimator
    recorded: :attr:`IdentificationResult.table`).  Then what the numbers rest on in plain words; ``verbose``: the
    estimator's own figures too (its regressor and gains, lambda_min(Gamma), the structural mismatch test, how the
    std was computed), which the JSON always holds."""
    method = getattr(result, "method", "observer")
    print_verdict(result.verdict, console)
    title = f"wmrid identify: {result.source}" + (f" (method {method})" if method != "observer" else "")
    header = ["param", "estimate", "std", "unit"]
    if result.nominal is not None:
        header.append("nominal")
    if result.reference is not None:
        header += ["CAD", "Δ/std"]
    table = result.table
    marks = {name: parameter.mark for name, parameter in table.items()}
    impossible = [name for name, parameter in table.items() if parameter.impossible]
    rows = []
    for name, parameter in table.items():
        value, std = parameter.value, parameter.std
        meaning = "impossible" if parameter.impossible else ("flagged" if not parameter.trusted else None)
        row = [_cell(name, meaning), _cell(_fmt(value) + ("✗" if parameter.impossible else ""), meaning),
               _cell(_fmt(std, 2) + parameter.mark, meaning), parameter.unit]  # fmt: skip
        if result.nominal is not None:
            row.append(_fmt(result.nominal.get(name)))
        if result.reference is not None:
            ref = result.reference.get(name)
            known = ref is not None and math.isfinite(ref)
            row.append(_fmt(ref) if known else "—")
            z = (value - ref) / std if known and std and math.isfinite(std) and std > 0 else math.nan
            row.append(f"{z:+.1f}" if math.isfinite(z) else "—")
        rows.append(row)
    print_table(console, header, rows, title=title, numeric=tuple(i for i in range(1, len(header)) if i != 3))
    if result.payload is not None:
        rows = [[name, _fmt(value), _fmt(std, 2), PAYLOAD_UNITS[name]] for name, (value, std) in result.payload.items()]
        print_table(console, ["quantity", "estimate", "std", "unit"], rows,
                    title="payload (against the unloaded robot)", numeric=(1, 2))  # fmt: skip
        console.print(payload_statement(result.payload))
    if impossible:
        console.print(
            LEGEND["✗"] + " (" + ", ".join(sorted(impossible)) + "): see the warnings",
            style=STYLES["impossible"],
        )
    info = result.log_info
    console.print(ROWS_MEAN)
    console.print(
        f"{info.samples} samples, {info.duration_s:.3f} s at {info.rate_hz:.6g} Hz; {result.form.friction} friction; "
        f"start: {result.start_source}"
    )
    diag = result.diagnostics
    if verbose:
        method_text = "" if result.method_settings is None else result.method_settings.before_observer()
        console.print(
            f"regressor: {result.form.kind} form ({result.form.n_columns} columns); "
            f"{method_text}k = {result.observer_settings.k:g} 1/s, alpha = {result.observer_settings.alpha:g}"
        )
    if diag.robot_assumed:
        console.print("robot file: assumed " + "; ".join(diag.robot_assumed))
    friction = diag.friction
    if friction is not None and friction.chosen_by == "auto":
        console.print(f"friction model: {friction.model} (auto: {friction.reason or ''})")
    if verbose:
        mismatch = diag.structural_mismatch or StructuralMismatch()
        console.print(
            f"lambda_min(Gamma) = {diag.lambda_min_gamma:.3g}; structural mismatch p = "
            f"{mismatch.p_value:.2g} ({mismatch.dof} directions)"
        )
    unc = diag.uncertainty or Uncertainty()
    factor = unc.interval_factor or {}
    how = (
        f"{unc.method}" + (f", {unc.segments} segments" if unc.segments else "") + f" ({unc.dof} dof)"
        if verbose
        else "how the estimate varies along the log" + (f" ({unc.segments} parts)" if unc.segments else "")
    )
    console.print(
        f"std: {how}; estimate ± {factor['95%']:.2f} std covers the truth with 95 % probability, "
        f"± {factor['99.7%']:.2f} std with 99.7 %, if disturbances do not feed back into the efforts (in closed loop "
        "see the closed-loop check, diagnostics.feedback in the JSON)"
    )
    model_error = unc.model_error
    if any("†" in mark for mark in marks.values()):
        scale = f" (S = {model_error.scale:.3g})" if model_error is not None and model_error.applied else ""
        console.print(LEGEND["†"] + (f"; here{scale}: {model_error.meaning}" if model_error is not None else ""))
    if any("!" in mark for mark in marks.values()):
        console.print(LEGEND["!"])
    if info.effort_unit != "N m":
        console.print(
            f"units: the effort is in {info.effort_unit}, not N m, so every parameter is in "
            f"{info.effort_unit}-based units (see the unit column)", style="bold",
        )  # fmt: skip
    if method != "observer":
        console.print(
            f"method {method}: {result.diagnostics.method_seconds:.3g} s; the excitation figures above and the "
            "history are the observer's, run on the same log"
        )
    validation = result.validation
    if validation is not None and validation.not_simulated:
        console.print(f"validation on {validation.log}: {validation.not_simulated}")
    elif validation is not None:
        fit = validation.fit_percent
        console.print(
            f"validation on {validation.log}: fit {_fmt(fit['eta_r'], 3)} % (right), "
            f"{_fmt(fit['eta_l'], 3)} % (left) "
            f"({validation.predictor})",
        )
    for note in info.notes:
        console.print(f"note: {note}")
    for warning in grouped_warnings(result.warnings):
        console.print(warning_line(warning))


def _format_name(info: McapInventory) -> str:
    """'MCAP, profile ros2', 'ROS 1 bag', 'ROS 2 bag'."""
    if info.format == "mcap":
        return f"MCAP, profile {info.profile or '-'}"
    return {"ros1 bag": "ROS 1 bag", "ros2 bag": "ROS 2 bag"}.get(info.format, info.format)


def print_inspection(info: McapInventory | TableInventory, console: Any) -> None:
    """Tables of what a log holds (:func:`wmrid.io.inspect.inspect_log`); topic, joint and column names fold onto
    more lines at the terminal's edge, never cut."""
    if isinstance(info, TableInventory):
        rows = [[str(col.name), str(col.type)] for col in info.columns]
        print_table(console, ["column", "type"], rows, title=f"wmrid inspect: {info.source} ({info.format})")
        if info.rows is not None:
            console.print(f"{info.rows} rows")
        missing = info.canonical_missing
        console.print(
            "canonical columns: all of t, eta_r, eta_l, tau_r, tau_l found"
            if not missing
            else f"canonical columns missing: {', '.join(missing)} (map them with --columns)"
        )
        if info.comments:
            console.print("comment lines (they often say what the columns are):")
            for line in info.comments:
                console.print(f"  {line}")
        for note in info.notes:
            console.print(f"note: {note}")
        return
    if info.start_s is not None:
        span = f"{info.duration_s:.3f} s"
    else:  # a recording read through rosbags gives other topics' counts without their times
        counted = sum(entry.messages or 0 for entry in info.topics)
        span = f"{counted} messages, times not read" if counted else "no messages"
    t0 = info.start_s or 0.0
    rows = []
    for entry in info.topics:
        rate = f"{entry.rate_hz:.4g}" if entry.rate_hz else "-"
        start = "-" if entry.start_s is None else f"{entry.start_s - t0:.3f}"
        end = "-" if entry.end_s is None else f"{entry.end_s - t0:.3f}"
        rows.append([entry.topic, entry.type, entry.encoding, str(entry.messages), rate, start, end])
    print_table(
        console, ["topic", "type", "encoding", "messages", "rate Hz", "start s", "end s"], rows,
        title=f"wmrid inspect: {info.source} ({_format_name(info)}, {info.size_bytes} bytes, {span})",
        numeric=(3, 4, 5, 6), fold=(1,),
    )  # fmt: skip
    joints = [e for e in info.topics if e.joints is not None]
    if joints:
        rows = [[e.topic, ", ".join(e.joints or ()), *((e.fields or {})[f] for f in ("position", "velocity", "effort")),
                 e.header_stamps] for e in joints]  # fmt: skip
        print_table(console, ["topic", "joints", "position", "velocity", "effort", "header stamps"], rows,
                    title="JointState topics", fold=(1, 5))  # fmt: skip
    else:
        console.print(
            "no sensor_msgs/msg/JointState topic: give the wheel signals by field path (below) with --columns "
            "eta_r=TOPIC:PATH,eta_l=...,tau_r=...,tau_l=... (or a JSON topic with --topic and --columns)"
        )
    by_path = [e for e in info.topics if e.field_paths]
    if by_path:
        rows = [[e.topic, ", ".join(p.split(":", 1)[1] for p in e.field_paths or ())] for e in by_path]
        print_table(
            console,
            ["topic", "field paths"],
            rows,
            fold=(1,),
            title="Numeric fields (for --columns eta_r=TOPIC:PATH,...; @NAME picks by name, [i] by position)",
        )
    for note in info.notes:
        console.print(f"note: {note}")


def print_report(report: Any, console: Any) -> None:
    """The report's tables and statements on a terminal (figures need -o report.html or .md); a table wider than
    the terminal is printed in slices of columns (:func:`print_table`)."""
    console.print(report.title, style="bold")
    for line in report.summary:
        console.print(line)
    for title, table in (("Base parameters (paper Table 3)", report.base),
                         ("Intermediate parameters (paper Table 2)", report.intermediate),
                         ("Payload", report.payload)):  # fmt: skip
        if not table:
            continue
        console.print()
        if table.statement:
            console.print(table.statement)
        rows = [[str(c) for c in row] for row in table.rows]
        print_table(console, [str(h) for h in table.header], rows, title=title, numeric=table.numeric)
    for statement in report.diagnostics:
        console.print(f"- {statement}")


def print_comparison(comparison: Comparison, console: Any) -> None:
    """A table of ``wmrid compare``'s result: one column per method (estimate ± std, error % with truth), in
    slices of methods where the terminal is narrow."""
    methods = comparison.methods
    truth = comparison.truth
    verdicts = [(name, m.verdict.summary) for name, m in methods.items() if m.verdict is not None]
    doubt = {m.verdict.summary for m in methods.values() if m.verdict is not None and m.verdict.doubt}
    for names, summary in said_once(verdicts):
        console.print(
            f"verdict ({', '.join(names)}): {summary}", style=STYLES["impossible"] if summary in doubt else "bold"
        )
    header = ["param", *(["true"] if truth else []), *methods]
    rows = []
    first = next(iter(methods.values()))
    for key, parameter in first.parameters.items():
        row: list[Any] = [f"{key}\n{parameter.unit}"]
        if truth:
            row.append(_fmt(truth.get(key)))
        for m in methods.values():
            e = m.parameters.get(key)
            if e is None:  # a parameter this method does not report
                row.append("—")
                continue
            cell = f"{_fmt(e.value)}{'✗' if e.impossible else ''}\n± {_fmt(e.std, 2)}{e.mark}"
            if key in m.error_percent:
                cell += f"\n{m.error_percent[key]:+.2g} %"
            row.append(_cell(cell, "impossible" if e.impossible else "flagged" if "!" in e.mark else None))
        rows.append(row)
    rows.append(["run time (s)", *([""] if truth else []), *(_fmt(m.seconds, 3) for m in methods.values())])
    if comparison.validation is not None:
        for wheel in ("eta_r", "eta_l"):
            rows.append([f"fit {wheel} (%)", *([""] if truth else []),
                         *(_fmt((m.fit_percent or {}).get(wheel), 3) for m in methods.values())])  # fmt: skip
    print_table(console, header, rows, title=f"wmrid compare: {comparison.source}",
                numeric=tuple(range(1, len(header))))  # fmt: skip
    if comparison.validation is not None:
        v = comparison.validation
        console.print(f"fit on {v.log}: {v.predictor or 'not simulated (see the warnings)'}")
    marks = "".join(p.mark for m in methods.values() for p in m.parameters.values())
    if "†" in marks:
        console.print(LEGEND["†"])
    if "!" in marks:
        console.print(LEGEND["!"])
    if any(p.impossible for m in methods.values() for p in m.parameters.values()):
        console.print(LEGEND["✗"], style=STYLES["impossible"])
    for names, warning in said_once([(name, w) for name, m in methods.items() for w in grouped_warnings(m.warnings)]):
        console.print(warning_line(warning, f"warning ({', '.join(names)})"))


def said_once(items: Sequence[tuple[str, str]]) -> list[tuple[list[str], str]]:
    """``(who, text)`` pairs said once per text, in the order first said: (every who that said it, text)."""
    said: dict[str, list[str]] = {}
    for who, text in items:
        names = said.setdefault(text, [])
        if who not in names:
            names.append(who)
    return [(names, text) for text, names in said.items()]
