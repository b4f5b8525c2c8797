"""A report as one self-contained HTML page (:func:`to_html`): the summary box first, the tables, the figures inline as
SVG, the provenance."""

from __future__ import annotations

import html
import re
from typing import Any

from wmrid.reporting.report import Report, rendered, residual_lines
from wmrid.reporting.report_table import ReportTable

_CSS = """
*{box-sizing:border-box}
body{font-family:system-ui,sans-serif;max-width:1240px;margin:1.5em auto;color:#222;padding:0 1em;line-height:1.4}
header .path{font-family:ui-monospace,monospace;font-size:0.9em;overflow-wrap:anywhere;color:#444}
.scroll{overflow-x:auto;max-width:100%;margin:0.5em 0 1.5em}
table{border-collapse:collapse}
table{font-size:0.95em}
th,td{padding:0.25em 0.55em;border-bottom:1px solid #ddd;text-align:right;white-space:nowrap}
th{white-space:normal;vertical-align:bottom}
th:first-child,td:first-child{text-align:left}th{background:#f4f4f4}
td.wrap{white-space:normal;overflow-wrap:anywhere;text-align:left}
td.interval{white-space:normal;min-width:6em}
@media (max-width:900px){body{padding:0 0.5em}table{font-size:0.85em}th,td{padding:0.2em 0.4em}}
figure{margin:1.5em 0}figcaption{font-weight:600}figcaption .note{font-weight:400;color:#444}
figure svg{width:100%;height:auto}li{margin:0.2em 0}.small{color:#555;font-size:0.9em}
code{font-family:ui-monospace,monospace;overflow-wrap:anywhere}
.summary{border:1px solid #ccc;border-left:6px solid #2e7d32;border-radius:4px;padding:0.6em 1.1em;margin:1em 0;
background:#f8faf8}
.summary.fair{border-left-color:#e69500;background:#fffaf0}.summary.bad{border-left-color:#b00020;background:#fff5f5}
.summary .headline{font-size:1.15em;font-weight:700;margin:0.3em 0}.summary.bad .headline{color:#b00020}
.summary .next{font-weight:700;margin:0.8em 0 0.2em}
.numbers{display:grid;grid-template-columns:repeat(auto-fill,minmax(19em,1fr));gap:0.2em 1.2em;margin:0.6em 0}
.numbers div{display:flex;gap:0.6em}.numbers dt{font-weight:600;min-width:3.2em}.numbers dd{margin:0;white-space:nowrap}
.nb{white-space:nowrap}
"""


#: A command-line option in running text (``--format``, ``-o``): kept on one line, the browser breaks after a hyphen.
_OPTION = re.compile(r"(?<![\w-])(--?[A-Za-z][\w-]*)")


def _prose(text: str) -> str:
    """``text`` escaped for HTML, its command-line options unbreakable (``<span class='nb'>``)."""
    return _OPTION.sub(r"<span class='nb'>\1</span>", html.escape(text))


def _html_table(table: ReportTable) -> str:
    """A table in a box that scrolls sideways when the page is narrower (cells never break a number)."""
    head = "".join(f"<th>{html.escape(str(h))}</th>" for h in table.header)
    body = "".join("<tr>" + "".join(_html_cell(c) for c in row) + "</tr>" for row in table.rows)
    return f"<div class='scroll'><table><thead><tr>{head}</tr></thead><tbody>{body}</tbody></table></div>"


def _html_cell(value: Any) -> str:
    """A table cell; an interval 'lo … hi' may break at its spaces (never inside a number)."""
    text = str(value)
    kind = " class='interval'" if " … " in text else ""
    return f"<td{kind}>{html.escape(text)}</td>"


def _html_summary(report: Report) -> list[str]:
    """The summary box at the top of the page: the verdict (red when it says not to use the numbers, amber when some
    group is not determined), the groups, the key numbers, what to do next."""
    lines = report.verdict
    if not lines and not report.key_numbers:
        return []
    tone = (
        "bad" if lines and lines[0].startswith("Do not use")
        else "fair" if any(g.status != "determined" for g in report.groups) else "good"
    )  # fmt: skip
    out = [f"<section class='summary {tone}'>"]
    if lines:
        out.append(f"<p class='headline'>{_prose(lines[0])}</p>")
        out += ["<ul>", *[f"<li>{_prose(line)}</li>" for line in lines[1:]], "</ul>"] if lines[1:] else []
    if report.key_numbers:
        out.append("<dl class='numbers'>" + "".join(
            f"<div><dt>{html.escape(k)}</dt><dd>{html.escape(v)}</dd></div>" for k, v in report.key_numbers
        ) + "</dl>")  # fmt: skip
    if report.next_steps:
        out += ["<p class='next'>What to do next</p><ul>"]
        out += [f"<li>{_prose(step)}</li>" for step in report.next_steps] + ["</ul>"]
    out.append("</section>")
    return ["".join(out)]


def to_html(report: Report) -> str:
    """One self-contained HTML page: inline SVG figures (text kept as text), inline style, nothing fetched."""
    source = str(report.result.get("source", "?"))
    parts = [
        "<!DOCTYPE html><html lang='en'><head><meta charset='utf-8'>",
        "<meta name='viewport' content='width=device-width, initial-scale=1'>",
        f"<title>{html.escape(report.title)}</title><style>{_CSS}</style></head><body>",
        f"<header><h1>wmrid report</h1><p class='path'>{html.escape(source)}</p>",
        *_html_summary(report),
        *[f"<p class='small'>{html.escape(s)}</p>" for s in report.summary],
        "</header>",
        "<h2>Base parameters (paper Table 3)</h2>",
        _html_table(report.base),
    ]
    if report.payload:
        parts += [
            "<h2>Payload</h2>",
            f"<p>{_prose(report.payload.statement or '')}</p>",
            _html_table(report.payload),
        ]
    parts += ["<h2>Diagnostics</h2><ul>", *[f"<li>{_prose(s)}</li>" for s in report.diagnostics], "</ul>"]
    if report.residuals:
        parts.append(
            "<h2>Residuals</h2><ul>" + "".join(f"<li>{html.escape(s)}</li>" for s in residual_lines(report)) + "</ul>"
        )
    if report.figure_objects or report.figures:
        parts.append("<h2>Figures</h2>")
    for name, svg in rendered(report, "svg").items():
        text = svg.decode("utf-8")
        text = text[text.index("<svg") :] if "<svg" in text else text  # the XML declaration: not inside HTML
        note = report.figure_notes.get(name, "")
        caption = html.escape(name) + (f" <span class='note'>— {html.escape(note)}</span>" if note else "")
        parts.append(f"<figure><figcaption>{caption}</figcaption>{text}</figure>")
    parts += ["<h2>Intermediate parameters (paper Table 2)</h2>", _html_table(report.intermediate)]
    if report.notes:
        parts += ["<h2>Notes on the log</h2><ul>", *[f"<li>{_prose(n)}</li>" for n in report.notes], "</ul>"]
    parts += _html_provenance(report.provenance)
    parts.append("</body></html>")
    return "\n".join(parts)


def _html_provenance(prov: dict[str, Any]) -> list[str]:
    """The reproducibility block: version, time, command, options, inputs with their SHA-256."""
    if not prov:
        return []
    rows = [("wmrid", prov.get("wmrid", "?")), ("made (UTC)", prov.get("made_utc", "?")),
            ("command", prov.get("command", "?"))]  # fmt: skip
    rows += [(f"option {k}", repr(v) if not isinstance(v, str) else v) for k, v in prov.get("options", {}).items()]
    out = ["<h2 id='reproducibility'>Reproducibility</h2>", "<div class='scroll'><table class='provenance'><tbody>"]
    out += [f"<tr><th>{html.escape(k)}</th><td class='wrap'><code>{html.escape(str(v))}</code></td></tr>"
            for k, v in rows]  # fmt: skip
    out.append("</tbody></table></div>")
    if prov.get("inputs"):
        out.append("<div class='scroll'><table class='inputs'><thead><tr><th>input</th><th>bytes</th><th>SHA-256</th>"
                   "</tr></thead><tbody>")  # fmt: skip
        out += [f"<tr><td class='wrap'><code>{html.escape(i['path'])}</code></td><td>{i['bytes']:,}</td>"
                f"<td class='wrap'><code>{i['sha256']}</code></td></tr>" for i in prov["inputs"]]  # fmt: skip
        out.append("</tbody></table></div>")
    return out
