"""Presenting results: rich tables for people, JSON for pipes.  No computation happens here."""

from __future__ import annotations

import math
from typing import Any

from wmrid.core.atomic import to_json_text
from wmrid.estimators.model_error import std_mark
from wmrid.estimators.result import IdentificationResult


def to_json(obj: Any) -> str:
    """Strict JSON (NaN/inf become null), without a trailing newline."""
    return to_json_text(obj).rstrip("\n")


def _fmt(x: float | None, digits: int = 6) -> str:
    if x is None or not math.isfinite(x):
        return "-"
    return f"{x:.{digits}g}"


def print_identification(result: IdentificationResult, console: Any) -> None:
    """A rich table of the base parameters with their standard errors, nominal and CAD values."""
    from rich import box
    from rich.table import Table

    method = getattr(result, "method", "observer")
    title = f"wmrid identify: {result.source}" + (f" (method {method})" if method != "observer" else "")
    table = Table(title=title, title_justify="left", box=box.SIMPLE_HEAD)
    table.add_column("param", no_wrap=True)
    table.add_column("estimate", justify="right", no_wrap=True)
    table.add_column("std", justify="right", no_wrap=True)
    table.add_column("unit", no_wrap=True)
    if result.nominal is not None:
        table.add_column("nominal", justify="right", no_wrap=True)
    if result.reference is not None:
        table.add_column("CAD", justify="right", no_wrap=True)
        table.add_column("Δ/std", justify="right", no_wrap=True)
    inflated = set(result.diagnostics.get("inflated", []))
    marks = {name: std_mark(name, result.diagnostics) for name in result.parameters}
    for name, (value, std) in result.parameters.items():
        row = [name, _fmt(value), _fmt(std, 2) + marks[name], result.units[name]]
        if result.nominal is not None:
            row.append(_fmt(result.nominal.get(name)))
        if result.reference is not None:
            ref = result.reference.get(name, math.nan)
            row.append(_fmt(ref))
            z = (value - ref) / std if std and math.isfinite(std) and std > 0 else math.nan
            row.append(f"{z:+.1f}" if math.isfinite(z) else "")
        table.add_row(*row)
    console.print(table)
    if result.payload is not None:
        from wmrid.model.payload import PAYLOAD_UNITS

        pt = Table(title="payload (against the unloaded robot)", title_justify="left", box=box.SIMPLE_HEAD)
        for col in ("quantity", "estimate", "std", "unit"):
            pt.add_column(col, no_wrap=True, justify="right" if col in ("estimate", "std") else "left")
        for name, (value, std) in result.payload.items():
            pt.add_row(name, _fmt(value), _fmt(std, 2), PAYLOAD_UNITS[name])
        console.print(pt)
    info = result.log_info
    console.print(
        f"{info['samples']} samples, {info['duration_s']:.3f} s at {info['rate_hz']:.6g} Hz; "
        f"regressor: {result.form.kind} form ({result.form.n_columns} columns), {result.form.friction} friction; "
        f"k = {result.settings.k:g} 1/s, alpha = {result.settings.alpha:g}; start: {result.start_source}"
    )
    diag = result.diagnostics
    friction = diag.get("friction")
    if friction and friction.get("chosen_by") == "auto":
        console.print(f"friction model: {friction['model']} (auto: {friction.get('reason', '')})", markup=False)
    console.print(
        f"lambda_min(Gamma) = {diag['lambda_min_gamma']:.3g}; structural mismatch p = "
        f"{diag['structural_mismatch']['p_value']:.2g} ({diag['structural_mismatch']['dof']} directions)"
    )
    unc = diag["uncertainty"]
    console.print(
        f"std: {unc['method']}" + (f", {unc['segments']} segments" if unc.get("segments") else "") + f" "
        f"({unc['dof']} dof); "
        f"estimate ± {unc['interval_factor']['95%']:.2f} std covers the truth with 95 % probability, "
        f"± {unc['interval_factor']['99.7%']:.2f} std with 99.7 %, if disturbances do not feed back into the "
        "efforts (in closed loop see diagnostics.feedback: the closed-loop check)"
    )
    model_error = unc.get("model_error")
    if inflated and model_error:
        scale = f" (S = {model_error['scale']:.3g})" if model_error.get("applied") else ""
        console.print(f"† std widened{scale}: {model_error['meaning']}", markup=False)
    if any("!" in mark for mark in marks.values()):
        console.print(
            "! flagged (poorly determined, or the log departs from the model): the std may not cover the error; "
            "see the warnings", markup=False,
        )  # fmt: skip
    if info.get("effort_unit", "N m") != "N m":
        console.print(
            f"[bold]units: the effort is in {info['effort_unit']}, not N m, so every parameter is in "
            f"{info['effort_unit']}-based units (see the unit column)[/bold]"
        )
    if method != "observer":
        console.print(
            f"method {method}: {result.diagnostics['method']['seconds']:.3g} s; the excitation figures above and the "
            "history are the observer's, run on the same log"
        )
    validation = getattr(result, "validation", None)
    if validation is not None:
        fit = validation["fit_percent"]
        console.print(
            f"validation on {validation['log']}: fit {_fmt(fit['eta_r'], 3)} % (right), "
            f"{_fmt(fit['eta_l'], 3)} % (left) "
            f"({validation['predictor']})",
            markup=False,
        )
    for note in info["notes"]:
        console.print(f"note: {note}")
    for warning in result.warnings:
        console.print(f"[yellow]warning:[/yellow] {warning}")


def _format_name(info: dict) -> str:
    """'MCAP, profile ros2', 'ROS 1 bag', 'ROS 2 bag'."""
    if info["format"] == "mcap":
        return f"MCAP, profile {info['profile'] or '-'}"
    return {"ros1 bag": "ROS 1 bag", "ros2 bag": "ROS 2 bag"}.get(info["format"], info["format"])


def print_inspection(info: dict, console: Any) -> None:
    """Tables of what a log holds (:func:`wmrid.io.inspect.inspect_log`)."""
    from rich import box
    from rich.table import Table

    if "topics" not in info:  # a CSV or Parquet log (an MCAP or a bag lists topics)
        table = Table(
            title=f"wmrid inspect: {info['source']} ({info['format']})", title_justify="left", box=box.SIMPLE_HEAD
        )
        table.add_column("column", no_wrap=True)
        table.add_column("type", no_wrap=True)
        for col in info["columns"]:
            table.add_row(col["name"], col["type"])
        console.print(table)
        if info.get("rows") is not None:
            console.print(f"{info['rows']} rows")
        missing = info["canonical_missing"]
        console.print(
            "canonical columns: all of t, eta_r, eta_l, tau_r, tau_l found"
            if not missing
            else f"canonical columns missing: {', '.join(missing)} (map them with --columns)"
        )
        if info.get("comments"):
            console.print("comment lines (they often say what the columns are):")
            for line in info["comments"]:
                console.print(f"  {line}", markup=False, highlight=False)
        for note in info.get("notes", []):
            console.print(f"note: {note}")
        return
    span = f"{info['duration_s']:.3f} s" if info.get("start_s") is not None else "no messages"
    console.print(f"wmrid inspect: {info['source']} ({_format_name(info)}, {info['size_bytes']} bytes, {span})")
    table = Table(box=box.SIMPLE_HEAD)
    for name in ("topic", "type", "encoding", "messages", "rate Hz", "start s", "end s"):
        table.add_column(name, no_wrap=name != "type", justify="right" if name in ("messages", "rate Hz") else "left")
    t0 = info.get("start_s") or 0.0
    for entry in info["topics"]:
        rate = f"{entry['rate_hz']:.4g}" if entry["rate_hz"] else "-"
        start = "-" if entry["start_s"] is None else f"{entry['start_s'] - t0:.3f}"
        end = "-" if entry["end_s"] is None else f"{entry['end_s'] - t0:.3f}"
        table.add_row(entry["topic"], entry["type"], entry["encoding"], str(entry["messages"]), rate, start, end)
    console.print(table)
    joints = [e for e in info["topics"] if "joints" in e]
    if joints:
        jt = Table(title="JointState topics", title_justify="left", box=box.SIMPLE_HEAD)
        for name in ("topic", "joints", "position", "velocity", "effort", "header stamps"):
            jt.add_column(name)
        for e in joints:
            f = e["fields"]
            jt.add_row(
                e["topic"], ", ".join(e["joints"]), f["position"], f["velocity"], f["effort"], e["header_stamps"]
            )
        console.print(jt)
    else:
        console.print(
            "no sensor_msgs/msg/JointState topic: give the wheel signals by field path (below) with --columns "
            "eta_r=TOPIC:PATH,eta_l=...,tau_r=...,tau_l=... (or a JSON topic with --topic and --columns)",
            markup=False, highlight=False,
        )  # fmt: skip
    by_path = [e for e in info["topics"] if e.get("field_paths")]
    if by_path:
        from rich.markup import escape

        title = escape("Numeric fields (for --columns eta_r=TOPIC:PATH,...; @NAME picks by name, [i] by position)")
        ft = Table(title=title, title_justify="left", box=box.SIMPLE_HEAD)
        ft.add_column("topic", no_wrap=True)
        ft.add_column("field paths")
        for e in by_path:
            ft.add_row(escape(e["topic"]), escape(", ".join(p.split(":", 1)[1] for p in e["field_paths"])))
        console.print(ft)
    for note in info["notes"]:
        console.print(f"note: {note}", markup=False, highlight=False)


def print_report(report: Any, console: Any) -> None:
    """The report's tables and statements on a terminal (figures need -o report.html or .md)."""
    from rich import box
    from rich.table import Table

    console.print(report.title)
    for line in report.summary:
        console.print(line)
    for title, table in (("Base parameters (paper Table 3)", report.base),
                         ("Intermediate parameters (paper Table 2)", report.intermediate),
                         ("Payload", report.payload)):  # fmt: skip
        if not table:
            continue
        t = Table(title=title, title_justify="left", box=box.SIMPLE_HEAD)
        for h in table["header"]:
            t.add_column(str(h), no_wrap=True)
        for row in table["rows"]:
            t.add_row(*[str(c) for c in row])
        console.print(t)
    for statement in report.diagnostics:
        console.print(f"- {statement}", markup=False)


def print_comparison(data: dict, console: Any) -> None:
    """A rich table of ``wmrid compare``'s result: one column per method (estimate ± std, error % with truth)."""
    from rich import box
    from rich.markup import escape
    from rich.table import Table

    methods = data["methods"]
    truth = data.get("truth")
    table = Table(title=f"wmrid compare: {data['source']}", title_justify="left", box=box.SIMPLE_HEAD, show_lines=True)
    table.add_column("param", no_wrap=True)
    if truth:
        table.add_column("true", justify="right", no_wrap=True)
    for name in methods:
        table.add_column(name, justify="right", no_wrap=True)
    first = next(iter(methods.values()))
    for key, entry in first["parameters"].items():
        row = [f"{key}\n{entry['unit']}"]
        if truth:
            row.append(_fmt(truth.get(key)))
        for m in methods.values():
            e = m["parameters"].get(key)
            if e is None:  # a parameter this method does not report
                row.append("—")
                continue
            cell = f"{_fmt(e['value'])}\n± {_fmt(e['std'], 2)}{m.get('marks', {}).get(key, '')}"
            if "error_percent" in e:
                cell += f"\n{e['error_percent']:+.2g} %"
            row.append(cell)
        table.add_row(*row)
    table.add_row(*(["run time (s)"] + ([""] if truth else []) + [f"{m['seconds']:.3g}" for m in methods.values()]))
    if "validation" in data:
        for wheel in ("eta_r", "eta_l"):
            table.add_row(
                *([f"fit {wheel} (%)"] + ([""] if truth else [])
                  + [_fmt(m["validation"]["fit_percent"][wheel], 3) for m in methods.values()])
            )  # fmt: skip
    console.print(table)
    if "validation" in data:
        v = data["validation"]
        console.print(f"fit on {v['log']}: {v['predictor']}", markup=False)
    marks = "".join(mark for m in methods.values() for mark in m.get("marks", {}).values())
    if "†" in marks:
        console.print("† std widened for model error (see the JSON's diagnostics)", markup=False)
    if "!" in marks:
        console.print("! flagged: the std may not cover this parameter's error (see the warnings)", markup=False)
    for name, m in methods.items():
        for warning in m["warnings"]:
            console.print(f"[yellow]warning ({name}):[/yellow] {escape(warning)}")
