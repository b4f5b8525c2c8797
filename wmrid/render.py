"""Presenting results: rich tables for people, JSON for pipes.  No computation happens here."""

from __future__ import annotations

import math
from typing import Any

from wmrid.atomic import to_json_text
from wmrid.identify import IdentificationResult


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

    table = Table(title=f"wmrid identify: {result.source}", title_justify="left", box=box.SIMPLE_HEAD)
    table.add_column("param", no_wrap=True)
    table.add_column("estimate", justify="right", no_wrap=True)
    table.add_column("std", justify="right", no_wrap=True)
    table.add_column("unit", no_wrap=True)
    if result.nominal is not None:
        table.add_column("nominal", justify="right", no_wrap=True)
    if result.reference is not None:
        table.add_column("CAD", justify="right", no_wrap=True)
        table.add_column("Δ/std", justify="right", no_wrap=True)
    for name, (value, std) in result.parameters.items():
        row = [name, _fmt(value), _fmt(std, 2), result.units[name]]
        if result.nominal is not None:
            row.append(_fmt(result.nominal[name]))
        if result.reference is not None:
            ref = result.reference[name]
            row.append(_fmt(ref))
            z = (value - ref) / std if std and math.isfinite(std) and std > 0 else math.nan
            row.append(f"{z:+.1f}" if math.isfinite(z) else "")
        table.add_row(*row)
    console.print(table)
    info = result.log_info
    console.print(
        f"{info['samples']} samples, {info['duration_s']:.3f} s at {info['rate_hz']:.6g} Hz; "
        f"regressor: {result.form.kind} form ({result.form.n_columns} columns); "
        f"k = {result.settings.k:g} 1/s, alpha = {result.settings.alpha:g}; start: {result.start_source}"
    )
    diag = result.diagnostics
    console.print(
        f"lambda_min(Gamma) = {diag['lambda_min_gamma']:.3g}; structural mismatch p = "
        f"{diag['structural_mismatch']['p_value']:.2g} ({diag['structural_mismatch']['dof']} directions)"
    )
    unc = diag["uncertainty"]
    console.print(
        f"std: jackknife over {unc['segments']} segments of the log ({unc['dof']} dof); "
        f"estimate ± {unc['interval_factor']['95%']:.2f} std covers the truth with 95 % probability, "
        f"± {unc['interval_factor']['99.7%']:.2f} std with 99.7 %"
    )
    for note in info["notes"]:
        console.print(f"note: {note}")
    for warning in result.warnings:
        console.print(f"[yellow]warning:[/yellow] {warning}")
