"""``wmrid fleet-report``: the fleet review as a page (:func:`to_html`), Markdown (:func:`to_markdown`) or plain data
(:func:`to_json_dict`), with the presentation of ``wmrid report``: the ranked table first, then each flagged robot's
findings and figure, then the other robots, the statements of what a flag means, and the reproducibility block.
"""

from __future__ import annotations

import html
import math
from dataclasses import dataclass, field
from typing import Any

from wmrid.fleets.figures import build_evidence_figure, build_robot_figure
from wmrid.fleets.review import FleetReview, RobotReview
from wmrid.reporting.figures import check_format, render
from wmrid.reporting.markdown import text
from wmrid.reporting.report_html import _CSS, _html_provenance, _html_table
from wmrid.reporting.report_markdown import _md_table, md_provenance, svg_data_uri
from wmrid.reporting.report_table import ReportTable

#: Robots drawn at most (flagged robots always; the others in rank order up to this count).
MAX_ROBOT_FIGURES = 60


@dataclass
class FleetReport:
    """A fleet review with its table's summary, the figures to draw and the provenance (:func:`fleet_report`).

    Attributes
    ----------
    review
        The review of the table.
    table
        The table reviewed (its path, or "rows").
    summary
        The table's summary, a sentence each.
    provenance
        How the review was made: wmrid's version, the time (UTC), the command, the options, the table's size and
        SHA-256.
    figure_objects
        The figures to draw: name -> :class:`wmrid.reporting.svg.Figure`, rendered once when an output needs them.
    figure_notes
        Name -> a sentence about the figure.
    """

    review: FleetReview
    table: str
    summary: list[str]
    provenance: dict[str, Any] = field(default_factory=dict)
    figure_objects: dict[str, Any] = field(default_factory=dict, repr=False)
    figure_notes: dict[str, str] = field(default_factory=dict)
    _rendered: dict[str, bytes] = field(default_factory=dict, repr=False)

    def rendered(self, name: str, fmt: str = "svg") -> bytes:
        """The figure ``name`` as ``fmt`` bytes ("svg", the only format), rendered once."""
        check_format(fmt)
        if name not in self._rendered:
            self._rendered[name] = render(self.figure_objects[name], fmt)
        return self._rendered[name]


def _date(review: RobotReview, index: int | None) -> str:
    return "" if index is None else review.label_of(index)


def ranked_table(review: FleetReview) -> ReportTable:
    """Robots ranked by the evidence against them: rank, robot, model, logs (failed), evidence, flags, change onset,
    first flagged."""
    rows = []
    for i, rv in enumerate(review.robots, 1):
        change = rv.history.changes[0] if rv.history.changes else None
        evidence = f"{rv.evidence:.3g}" if math.isfinite(rv.evidence) else "—"
        rows.append([
            i, rv.robot_id, rv.model, f"{len(rv.rows)}" + (f" ({rv.failed} failed)" if rv.failed else ""), evidence,
            "; ".join(rv.flags) or "—", _date(rv, change.onset if change else None) or "—",
            _date(rv, change.alarm if change else None) or "—",
        ])  # fmt: skip
    header = ["rank", "robot", "robot file", "logs", "evidence", "flags", "change from", "first flagged"]
    return ReportTable(header, rows)


def build_fleet_report(
    review: FleetReview, rows: list[dict[str, Any]], table: str, *, figures: bool = True
) -> FleetReport:
    """The report of a review of the table's ``rows``; ``figures``: build the figures (HTML and Markdown)."""
    robots = len(review.robots)
    flagged = [rv for rv in review.robots if rv.flagged]
    failed = sum(1 for r in rows if r.get("error") is not None)
    times = sorted(r["start_time"] for r in rows if r.get("start_time") is not None)
    span = f", {times[0]:%Y-%m-%d} to {times[-1]:%Y-%m-%d}" if times else ""
    summary = [
        f"{len(rows)} logs of {robots} robots{span}; {failed} logs failed to identify (not used).",
        f"{len(flagged)} robot{'s' if len(flagged) != 1 else ''} flagged"
        + (": " + ", ".join(rv.robot_id for rv in flagged) if flagged else "")
        + ".",
    ]
    rep = FleetReport(review, table, summary)
    if figures:
        fig = build_evidence_figure(review)
        if fig is not None:
            rep.figure_objects["evidence"] = fig
            rep.figure_notes["evidence"] = "the largest statistic of each robot over its threshold; red: flagged"
        others = [rv for rv in review.robots if not rv.flagged][: max(0, MAX_ROBOT_FIGURES - len(flagged))]
        for rv in flagged + others:
            fig = build_robot_figure(rv)
            if fig is not None:
                rep.figure_objects[f"robot {rv.robot_id}"] = fig
                rep.figure_notes[f"robot {rv.robot_id}"] = (
                    "each log's estimate with ±2σ; dashed: mean before any change; dotted: the change's onset; red "
                    "line: first flagged; ×: odd logs; a band that fills its panel is far wider than the logs' spread "
                    "(an error common to all of them), and the axis then follows the values; Fw1, Fw2: each wheel's "
                    "friction at its typical speed"
                )
        left = len(review.robots) - len(flagged) - len(others)
        if left > 0:
            rep.summary.append(f"figures of {left} unflagged robots left out (the first {MAX_ROBOT_FIGURES} shown)")
    return rep


def _svg(rep: FleetReport, name: str) -> str:
    text = rep.rendered(name, "svg").decode("utf-8")
    return text[text.index("<svg") :] if "<svg" in text else text  # the XML declaration: not inside HTML


def _robot_html(rep: FleetReport, rv: RobotReview) -> list[str]:
    parts = [f"<h3 id='robot-{html.escape(rv.robot_id)}'>{html.escape(rv.robot_id)}</h3>"]
    if rv.findings:
        parts += ["<ul>", *[f"<li>{html.escape(f)}</li>" for f in rv.findings], "</ul>"]
    if rv.sensitivity_text:
        parts.append(f"<p class='small'>{html.escape(rv.sensitivity_text)}</p>")
    if rv.payload:
        rows = [[n, f"{v:.4g}", "—" if e is None else f"{e:.2g}"] for n, (v, e) in rv.payload.items()]
        parts.append(_html_table(ReportTable(["payload", "estimate", "std"], rows)))
    name = f"robot {rv.robot_id}"
    if name in rep.figure_objects:
        note = html.escape(rep.figure_notes.get(name, ""))
        parts.append(f"<figure><figcaption>{html.escape(name)} <span class='note'>— {note}</span></figcaption>"
                     f"{_svg(rep, name)}</figure>")  # fmt: skip
    return parts


def to_html(rep: FleetReport) -> str:
    """One self-contained HTML page: inline SVG figures, inline style, nothing fetched."""
    review = rep.review
    parts = [
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>",
        "<meta name='viewport' content='width=device-width, initial-scale=1'>",
        f"<title>wmrid fleet report: {html.escape(rep.table)}</title><style>{_CSS}</style></head><body>",
        f"<header><h1>wmrid fleet report</h1><p class='path'>{html.escape(rep.table)}</p>",
        *[f"<p class='small'>{html.escape(s)}</p>" for s in rep.summary],
        "</header>",
        "<h2>Robots ranked by the evidence against them</h2>",
        _html_table(ranked_table(review)),
    ]
    if "evidence" in rep.figure_objects:
        parts.append(f"<figure><figcaption>evidence <span class='note'>— {html.escape(rep.figure_notes['evidence'])}"
                     f"</span></figcaption>{_svg(rep, 'evidence')}</figure>")  # fmt: skip
    flagged = [rv for rv in review.robots if rv.flagged]
    parts.append("<h2>Flagged robots</h2>")
    if not flagged:
        parts.append("<p>No robot flagged.</p>")
    for rv in flagged:
        parts += _robot_html(rep, rv)
    parts.append("<h2>Other robots</h2>")
    for rv in review.robots:
        if not rv.flagged:
            parts += _robot_html(rep, rv)
    parts += ["<h2>What a flag means</h2><ul>", *[f"<li>{html.escape(s)}</li>" for s in review.statements], "</ul>"]
    parts += _html_provenance(rep.provenance)
    parts.append("</body></html>")
    return "\n".join(parts)


def to_markdown(rep: FleetReport) -> str:
    """Markdown: the ranked table, findings, SVG figures as data URIs (one file); the table's path, robot ids and
    every other string from the table escaped (:mod:`wmrid.reporting.markdown`)."""
    review = rep.review
    parts = [f"# wmrid fleet report: {text(rep.table, False)}", "", *[text(s) for s in rep.summary], "",
             "## Robots ranked by the evidence against them", "", _md_table(ranked_table(review))]  # fmt: skip
    for title, group in (("Flagged robots", [rv for rv in review.robots if rv.flagged]),
                         ("Other robots", [rv for rv in review.robots if not rv.flagged])):  # fmt: skip
        parts += ["", f"## {title}"]
        if not group:
            parts += ["", "No robot flagged." if title == "Flagged robots" else "None: every robot is flagged."]
        for rv in group:
            parts += ["", f"### {text(rv.robot_id)}", "", *[f"- {text(f)}" for f in rv.findings]]
            if rv.sensitivity_text:
                parts += ["", f"*{text(rv.sensitivity_text, False)}*"]
            name = f"robot {rv.robot_id}"
            if name in rep.figure_objects:
                parts += ["", f"![{text(name, False)}]({svg_data_uri(rep.rendered(name, 'svg'))})"]
    parts += ["", "## What a flag means", "", *[f"- {text(s)}" for s in review.statements]]
    parts += md_provenance(rep.provenance)
    return "\n".join(parts) + "\n"


def _iso(when: Any) -> str | None:
    return None if when is None else when.isoformat()


def robot_dict(rv: RobotReview) -> dict[str, Any]:
    """One robot of the review as plain data."""
    changes = []
    for c in rv.history.changes:
        changes.append({
            "parameters": c.parameters, "kind": c.kind, "onset_log": rv.rows[c.onset]["log"],
            "onset_time": _iso(rv.time_of(c.onset)), "alarm_log": rv.rows[c.alarm]["log"],
            "alarm_time": _iso(rv.time_of(c.alarm)),
            "evidence": c.evidence, "confirmed": c.confirmed, "before": c.before, "after": c.after,
            "relative_change": {p: c.relative(p) for p in c.parameters}, "rate_per_day": c.rate_per_day,
        })  # fmt: skip
    return {
        "robot_id": rv.robot_id, "robot_file": rv.model, "logs": len(rv.rows), "failed": rv.failed,
        "evidence": rv.evidence if math.isfinite(rv.evidence) else None, "flagged": rv.flagged, "flags": rv.flags,
        "findings": rv.findings, "changes": changes, "odd_logs": [rv.rows[i]["log"] for i in rv.history.odd_logs],
        "outlier_t": rv.outlier,
        "payload": None if rv.payload is None else {k: {"value": v, "std": e} for k, (v, e) in rv.payload.items()},
        "threshold": rv.history.threshold if math.isfinite(rv.history.threshold) else None, "note": rv.history.note,
        "typical_speed": {name: omega for name, (omega, _, _) in rv.wheel_friction.items()},
        "sensitivity": _finite(rv.sensitivity),
    }  # fmt: skip


def _finite(value: Any) -> Any:
    """Infinities and NaN as None, inside dicts (JSON has no infinity)."""
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def to_json_dict(rep: FleetReport) -> dict[str, Any]:
    """The report's content as plain data (figures left out)."""
    review = rep.review
    return {
        "table": rep.table, "summary": rep.summary, "settings": review.settings, "statements": review.statements,
        "outlier_thresholds": {m: {"robots": n, "threshold": h} for m, (n, h) in review.outlier_thresholds.items()},
        "ranked": ranked_table(review).to_dict(), "robots": [robot_dict(rv) for rv in review.robots],
        "provenance": rep.provenance,
    }  # fmt: skip
