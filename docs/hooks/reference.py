"""mkdocs hook: the reference pages generated from the code, so that they cannot drift from it.

* ``<!-- wmrid:cli-reference -->`` becomes every command and option of the ``wmrid`` Typer app (walked through the
  click command Typer builds), grouped in the panels ``--help`` shows;
* ``<!-- wmrid:api-reference -->`` becomes a mkdocstrings block for every public name in ``wmrid.__all__``;
* ``<!-- wmrid:result-schema -->`` becomes the published JSON Schema of the identify result, verbatim.

``tests/contract/test_docs.py`` checks the generated reference against the app and the API page against
``wmrid.__all__``.
"""

from __future__ import annotations

import html
import re
import sys
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
SCHEMA = ROOT / "docs" / "reference" / "result.schema.json"

CLI_MARKER = "<!-- wmrid:cli-reference -->"
API_MARKER = "<!-- wmrid:api-reference -->"
SCHEMA_MARKER = "<!-- wmrid:result-schema -->"


def _wmrid_on_path() -> None:
    """Document the checkout this hook belongs to, whatever is installed."""
    if str(ROOT) not in sys.path:
        sys.path.insert(0, str(ROOT))


# ---------------------------------------------------------------------------------------------------------------
# The command line


def cli_app() -> Any:
    """The click command Typer builds from ``wmrid``'s app, every command joined, help texts as written."""
    _wmrid_on_path()
    import importlib
    import pkgutil

    import typer

    import wmrid.cli
    from wmrid.cli import app as app_module

    for module in pkgutil.iter_modules(wmrid.cli.__path__):  # each *_commands module joins its commands to ``app``
        if module.name.endswith("_commands"):
            importlib.import_module(f"wmrid.cli.{module.name}")
    return typer.main.get_command(app_module.app)


def _md(text: str) -> str:
    """Plain help text as Markdown that shows it as written (no emphasis, no HTML, no table breaks)."""
    text = html.escape(" ".join(text.split()), quote=False)
    return re.sub(r"([\\`*_\[\]|#])", r"\\\1", text)


_EXTRA = re.compile(r"\s+\[((?:default: |required|env var: )[^\[\]]*)\]$")


def option_record(param: Any, ctx: Any) -> dict[str, str]:
    """One option or argument as the reference shows it: names, value, default, help (``[required]`` apart)."""
    names, help_text = param.get_help_record(ctx) or ("", "")
    extra = ""
    match = _EXTRA.search(help_text)
    if match:
        extra, help_text = match.group(1), help_text[: match.start()]
    default = required = ""
    for part in extra.split("; ") if extra else ():
        if part.startswith("default: "):
            default = part[len("default: ") :]
        elif part == "required":
            required = "required"
    flags = ", ".join([*param.opts, *getattr(param, "secondary_opts", [])]) if param.param_type_name == "option" else ""
    flags = flags or (param.metavar or param.name.upper()).rstrip(".")
    value = names
    for name in sorted([*param.opts, *getattr(param, "secondary_opts", [])], key=len, reverse=True):
        value = value.replace(name, "")
    value = value.strip(" ,/")
    if param.param_type_name == "argument":  # its name is the option column; the usage line says {LOG}...
        value = "repeatable" if param.nargs != 1 else ""
    value = re.sub(r"<list\[([^\]]*)\]>", r"<\1>...", value)  # a repeatable option, as --help shows it
    return {"flags": flags, "value": value, "default": default, "required": required, "help": help_text.strip()}


def _panel(param: Any) -> str:
    default = "Arguments" if param.param_type_name == "argument" else "Options"
    return getattr(param, "rich_help_panel", None) or default


def command_records(root: Any) -> list[tuple[str, Any, Any]]:
    """(``wmrid NAME``, the command, its context) for the root and every command, in ``wmrid --help``'s order."""
    from typer import _click as click

    root_ctx = click.Context(root, info_name="wmrid")
    out = [("wmrid", root, root_ctx)]
    for name in root.list_commands(root_ctx):  # wmrid --help's order (wmrid.cli.help.COMMAND_ORDER)
        cmd = root.commands[name]
        if not getattr(cmd, "hidden", False):
            out.append((f"wmrid {name}", cmd, click.Context(cmd, info_name=name, parent=root_ctx)))
    return out


def cli_markdown(root: Any | None = None) -> str:
    """The whole command-line reference as Markdown."""
    root = cli_app() if root is None else root
    lines: list[str] = []
    for title, cmd, ctx in command_records(root):
        lines += [f"## `{title}`", ""]
        usage = " ".join(cmd.get_usage(ctx).split()).removeprefix("Usage: ")
        lines += ["```text", usage, "```", ""]
        for paragraph in re.split(r"\n\s*\n", cmd.help or ""):
            if paragraph.strip():
                lines += [_md(paragraph), ""]
        panels: dict[str, list[dict[str, str]]] = {}
        for param in cmd.get_params(ctx):
            if getattr(param, "hidden", False):
                continue
            record = option_record(param, ctx)
            if record["flags"] in ("--help",):
                continue
            panels.setdefault(_panel(param), []).append(record)
        for panel, records in panels.items():
            lines += [f"**{_md(panel)}**", "", "| option | value | default | meaning |", "| --- | --- | --- | --- |"]
            for r in records:
                default = _md(r["default"]) if r["default"] else r["required"]
                value = _md(r["value"]) if r["value"] else ""
                lines.append(f"| `{r['flags']}` | {value} | {default} | {_md(r['help'])} |")
            lines.append("")
        if cmd.epilog:
            examples = [line for line in cmd.epilog.splitlines() if line.strip() and not line.endswith(":")]
            lines += ["Examples from `--help`:", "", "```text", *examples, "```", ""]
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------------------------
# The Python API

#: How the API page groups the public names (every name of ``wmrid.__all__`` falls in one group).
API_GROUPS = (
    (
        "Reading logs and robots",
        ("read_log", "open_log", "LogOptions", "inspect", "load_robot", "Robot", "WheelLog", "LogStream"),
    ),
    (
        "Identifying",
        (
            "identify",
            "ObserverOptions",
            "MethodOptions",
            "validate",
            "compare",
            "IdentificationResult",
            "BaseEstimate",
            "ObserverRun",
            "Parameter",
            "Verdict",
            "GroupVerdict",
            "LogInfo",
            "Validation",
            "PayloadEstimate",
            "Diagnostics",
            "Comparison",
            "ValidationLog",
        ),
    ),
    ("Reports", ("report", "Identification", "write_report", "Report")),
    (
        "Simulating",
        (
            "simulate",
            "NoiseSettings",
            "Payload",
            "Change",
            "PlantChange",
            "MultibodySettings",
            "load_reference",
            "write_simulation",
            "SimulationRun",
        ),
    ),
    ("Watching for changes", ("monitor", "MonitorResult", "MonitorSettings")),
    ("Fleets", ("fleet", "FleetRun", "fleet_report", "write_fleet_report", "FleetReport")),
    ("Planning a drive", ("plan", "predict_plan", "write_plan", "read_plan", "Plan")),
    ("Exporting", ("export", "ExportResult", "ExportCheck", "PhysicalEstimate")),
    ("Live identification", ("live", "LiveRun", "LiveUpdate", "LiveChange", "PayloadMass", "LiveResult")),
    ("Errors", ("WmridError",)),
)


def public_names() -> dict[str, str]:
    """Every public name of ``wmrid`` (``wmrid.__all__`` but ``__version__``) -> the module defining it."""
    _wmrid_on_path()
    import wmrid

    return {name: wmrid._EXPORTS[name] for name in wmrid.__all__ if name != "__version__"}


def api_markdown() -> str:
    names = public_names()
    placed = [n for _, group in API_GROUPS for n in group]
    missing = sorted(set(names) - set(placed))
    groups = [*API_GROUPS, *([("Other", tuple(missing))] if missing else [])]
    lines: list[str] = []
    for title, group in groups:
        lines += [f"## {title}", ""]
        for name in group:
            if name in names:
                lines += [f"::: {names[name]}.{name}", ""]
    return "\n".join(lines)


# ---------------------------------------------------------------------------------------------------------------
# mkdocs


def on_page_markdown(markdown: str, page: Any, config: Any, files: Any) -> str:
    if CLI_MARKER in markdown:
        markdown = markdown.replace(CLI_MARKER, cli_markdown())
    if API_MARKER in markdown:
        markdown = markdown.replace(API_MARKER, api_markdown())
    if SCHEMA_MARKER in markdown:
        markdown = markdown.replace(SCHEMA_MARKER, "```json\n" + SCHEMA.read_text(encoding="utf-8").strip() + "\n```")
    return markdown


#: A Sphinx cross-reference role in a docstring as Markdown renders it: :class:`~wmrid.x.Name` becomes
#: ``:class:<code>~wmrid.x.Name</code>``.
_ROLE = re.compile(r":(?:class|func|meth|mod|data|attr|exc|obj):<code>(~?)([^<]*)</code>")


def on_page_content(html_text: str, page: Any, config: Any, files: Any) -> str:
    """The docstrings use Sphinx roles (:class:`Name`): shown as the name in code, the role dropped (and with ``~``,
    the module path, as Sphinx does)."""

    def name(match: re.Match[str]) -> str:
        target = match.group(2)
        return f"<code>{target.rsplit('.', 1)[-1] if match.group(1) else target}</code>"

    return _ROLE.sub(name, html_text)
