"""A report as Markdown (:func:`to_markdown`), its figures inline as SVG data URIs."""

from __future__ import annotations

import base64
from typing import Any

from wmrid.reporting import markdown as md
from wmrid.reporting.markdown import code, text
from wmrid.reporting.report import Report, rendered, residual_lines
from wmrid.reporting.report_table import ReportTable


def _md_table(table: ReportTable) -> str:
    """A table as Markdown, every cell escaped (:mod:`wmrid.reporting.markdown`)."""
    return md.table(table.header, table.rows)


def to_markdown(report: Report) -> str:
    """Markdown with the tables, statements and SVG figures as data URIs (one file); every string that came from an
    input (names, a saved result's source, notes, warnings) escaped (:mod:`wmrid.reporting.markdown`)."""
    verdict = []
    if report.verdict:
        verdict = [f"**Verdict:** {text(report.verdict[0], False)}", "", *(f"- {text(v)}" for v in report.verdict[1:])]
        verdict.append("")
    if report.key_numbers:
        verdict += [" · ".join(f"**{text(k, False)}** {text(v, False)}" for k, v in report.key_numbers), ""]
    if report.next_steps:
        verdict += ["**What to do next**", "", *(f"- {text(step)}" for step in report.next_steps), ""]
    parts = [
        f"# {text(report.title)}",
        "",
        *verdict,
        *[text(s) for s in report.summary],
        "",
        "## Base parameters (paper Table 3)",
        "",
        _md_table(report.base),
    ]
    parts += ["", "## Intermediate parameters (paper Table 2)", "", _md_table(report.intermediate)]
    if report.payload:
        parts += ["", "## Payload", "", text(report.payload.statement or ""), "", _md_table(report.payload)]
    parts += ["", "## Diagnostics", "", *[f"- {text(s)}" for s in report.diagnostics]]
    if report.residuals:
        parts += ["", "## Residuals", "", *[f"- {text(s)}" for s in residual_lines(report)]]
    for name, svg in rendered(report, "svg").items():
        note = report.figure_notes.get(name)
        parts += ["", f"### {text(name)}", "", *([text(note), ""] if note else []),
                  f"![{text(name, False)}]({svg_data_uri(svg)})"]  # fmt: skip
    if report.notes:
        parts += ["", "## Notes on the log", "", *[f"- {text(n)}" for n in report.notes]]
    parts += md_provenance(report.provenance)
    return "\n".join(parts) + "\n"


def svg_data_uri(svg: bytes) -> str:
    """``svg`` (an SVG document) as a ``data:image/svg+xml;base64,...`` URI, for an image in Markdown."""
    return f"data:image/svg+xml;base64,{base64.b64encode(svg).decode()}"


def md_provenance(prov: dict[str, Any]) -> list[str]:
    """The reproducibility block in Markdown: version, time, command, options, inputs with their SHA-256 (each
    escaped: the command line and the paths are the user's)."""
    if not prov:
        return []
    parts = ["", "## Reproducibility", "",
             f"- wmrid {text(prov.get('wmrid', '?'), False)}, made {text(prov.get('made_utc', '?'), False)} (UTC)",
             f"- command: {code(prov.get('command', '?'))}"]  # fmt: skip
    parts += [f"- option {text(k, False)}: {code(repr(v))}" for k, v in prov.get("options", {}).items()]
    parts += [
        f"- input {code(i.get('path', '?'))}: {i.get('bytes', 0):,} bytes, SHA-256 {code(i.get('sha256', '?'))}"
        for i in prov.get("inputs", [])
    ]
    return parts
