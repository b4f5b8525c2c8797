"""The documentation site (docs/, mkdocs.yml) says what the code does: the generated command-line reference matches
the Typer app, the API reference covers every public name, the published result schema holds for every bundled
sample's identify JSON, and the README stays a front page (its example runs, its test command is CI's, its links
lead into the site).  The examples of the site run in ``tests/contract/test_docs_examples.py``."""

from __future__ import annotations

import html
import importlib.util
import json
import re

import pytest
from locations import ROOT_DIR

ROOT = ROOT_DIR
DOCS = ROOT / "docs"
REAL_LOGS = ROOT.parent / "shared" / "real_logs"
SCHEMA = DOCS / "reference" / "result.schema.json"


def _hook(name: str):
    """A mkdocs hook of docs/hooks/ as a module (the build loads it by path, not as a package)."""
    spec = importlib.util.spec_from_file_location(f"wmrid_docs_{name}", DOCS / "hooks" / f"{name}.py")
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


HOOK = _hook("reference")


# ---- the command-line reference


def _normal(text: str) -> str:
    return " ".join(text.split())


def _sections(markdown: str) -> dict[str, str]:
    """``wmrid CMD`` -> its section of the generated reference."""
    parts = re.split(r"^## `(wmrid[^`]*)`$", markdown, flags=re.M)
    return dict(zip(parts[1::2], parts[2::2], strict=True))


def test_the_cli_reference_lists_every_command_and_option_of_the_app():
    """The reference is generated from the app at build time; this walks the app itself and finds each command,
    each option (with its value, default and help) in the generated page, and nothing the app does not have."""
    from typer import _click as click

    from wmrid.cli.app import command

    root = HOOK.cli_app()
    running = command()  # the command line as `wmrid` runs it
    assert list(root.commands) == list(running.commands)
    for name, cmd in running.commands.items():
        assert [p.name for p in root.commands[name].params] == [p.name for p in cmd.params]
    markdown = HOOK.cli_markdown(root)
    sections = _sections(markdown)
    listed = root.list_commands(click.Context(root, info_name="wmrid"))  # wmrid --help's order: identify first
    commands = ["wmrid", *(f"wmrid {n}" for n in listed if not getattr(root.commands[n], "hidden", False))]
    assert list(sections) == commands
    assert commands[1] == "wmrid identify"
    assert {"wmrid identify", "wmrid report", "wmrid live", "wmrid export", "wmrid fleet"} <= set(sections)
    root_ctx = click.Context(root, info_name="wmrid")
    for name in commands:
        cmd = root if name == "wmrid" else root.commands[name.split()[1]]
        ctx = root_ctx if cmd is root else click.Context(cmd, info_name=cmd.name, parent=root_ctx)
        section = sections[name]
        rows = {m.group(1): m.group(0) for m in re.finditer(r"^\| `([^`]+)` \|.*$", section, flags=re.M)}
        documented = 0
        for param in cmd.get_params(ctx):
            if getattr(param, "hidden", False) or "--help" in param.opts:
                continue
            record = HOOK.option_record(param, ctx)
            row = rows.get(record["flags"])
            assert row is not None, f"{name}: {record['flags']} is not in the reference"
            if param.param_type_name == "option":
                assert all(opt in record["flags"].split(", ") for opt in param.opts)
            plain = _normal(html.unescape(re.sub(r"\\(.)", r"\1", row)))
            assert _normal(record["help"]) in plain, f"{name} {record['flags']}: help differs"
            if record["default"]:
                assert f"| {_normal(record['default'])} |" in plain, f"{name} {record['flags']}: default differs"
            documented += 1
        assert documented == len(rows), f"{name}: the reference has options the app does not"
        if cmd.help:
            assert _normal(cmd.help) in _normal(html.unescape(re.sub(r"\\(.)", r"\1", section)))


def test_the_cli_reference_page_is_the_generated_one():
    page = (DOCS / "reference" / "cli.md").read_text(encoding="utf-8")
    assert HOOK.CLI_MARKER in page


# ---- the Python API reference


def test_the_api_reference_documents_every_public_name_from_its_docstring():
    import wmrid

    names = HOOK.public_names()
    assert set(names) == set(wmrid.__all__) - {"__version__"}
    markdown = HOOK.api_markdown()
    directives = re.findall(r"^::: (\S+)$", markdown, flags=re.M)
    assert sorted(directives) == sorted(f"{module}.{name}" for name, module in names.items())
    assert "Other" not in re.findall(r"^## (.*)$", markdown, flags=re.M), "a public name has no group on the page"
    for name in names:
        assert (getattr(wmrid, name).__doc__ or "").strip(), f"wmrid.{name} has no docstring for the reference"
    assert HOOK.API_MARKER in (DOCS / "reference" / "api.md").read_text(encoding="utf-8")


# ---- the result schema


@pytest.fixture(scope="module")
def validator():
    jsonschema = pytest.importorskip("jsonschema")
    schema = json.loads(SCHEMA.read_text(encoding="utf-8"))
    jsonschema.Draft202012Validator.check_schema(schema)
    return jsonschema.Draft202012Validator(schema)


def _problems(validator, document: dict) -> list[str]:
    return [f"{'/'.join(map(str, e.path))}: {e.message[:200]}" for e in validator.iter_errors(document)]


def test_the_schema_is_of_the_version_wmrid_writes():
    from wmrid.estimators.result import SCHEMA_VERSION

    schema = json.loads(SCHEMA.read_text(encoding="utf-8"))
    assert schema["properties"]["schema_version"]["const"] == SCHEMA_VERSION


SAMPLES = sorted(p.name for p in (ROOT / "sample_logs").glob("*.*") if p.suffix in (".csv", ".mcap", ".parquet"))


@pytest.mark.parametrize("sample", SAMPLES)
def test_every_bundled_samples_identify_json_follows_the_published_schema(validator, sample):
    """``wmrid identify SAMPLE --format json`` for each bundled sample (without a robot: the other test has one)."""
    from tests.cliutil import wmrid

    proc = wmrid("identify", str(ROOT / "sample_logs" / sample), "--format", "json")
    assert proc.returncode == 0, proc.stderr
    assert _problems(validator, json.loads(proc.stdout)) == []


def test_the_schema_holds_for_other_methods_a_payload_a_validation_and_no_history(validator):
    import wmrid
    from wmrid.reporting.render import to_json

    log = wmrid.read_log(ROOT / "sample_logs" / "paper_sinusoid.csv")
    results = [
        wmrid.validate(
            wmrid.identify(log, "paper", method="idim"), str(ROOT / "sample_logs" / "paper_sinusoid.parquet")
        ),
        wmrid.identify(log, "paper", observer=wmrid.ObserverOptions(payload=True)),
    ]
    for result in results:
        for history in (True, False):
            document = json.loads(to_json(result.to_dict(history=history)))
            assert _problems(validator, document) == []
    broken = json.loads(to_json(results[1].to_dict()))
    del broken["parameters"]["m11"]["std"]
    assert _problems(validator, broken), "the schema must refuse a parameter without its std"


# ---- the README: a front page that points into the site


def test_the_readme_is_a_front_page():
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert len(readme.splitlines()) <= 250
    ci = (ROOT / ".ci" / "run").read_text(encoding="utf-8")
    test_command = next(line for line in ci.splitlines() if line.startswith("python3 -m venv"))
    assert test_command in readme.splitlines(), "the README's test command must be the one CI runs"
    for target in re.findall(r"\]\((docs/[^)#]+)", readme):
        assert (ROOT / target).exists(), f"the README links to {target}, which does not exist"


def test_the_docs_link_only_to_pages_that_exist():
    """mkdocs --strict checks links between pages; this checks the links from files outside docs/ into it."""
    for path in [ROOT / "README.md", ROOT / "examples" / "README.md", ROOT / "CHANGELOG.md"]:
        if path.exists():
            for target in re.findall(r"\]\(((?:\.\./)?docs/[^)#]+)", path.read_text(encoding="utf-8")):
                assert (path.parent / target).resolve().exists(), f"{path.name} links to {target}"


def test_the_readme_python_example_runs(tmp_path, monkeypatch):
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    code = re.search(r"```python\n(.*?)```", readme.split("## Python", 1)[1], re.S).group(1)
    from tests.contract.test_docs_examples import workdir

    monkeypatch.chdir(workdir(tmp_path))
    scope: dict = {}
    exec(compile(code, "README.md", "exec"), scope)
    assert scope["value"] == pytest.approx(0.7872544, rel=1e-6)
    assert (tmp_path / "report.html").read_text(encoding="utf-8").startswith("<!DOCTYPE html>")


# ---- figures rendered from the benchmarks' result files (docs/hooks/figures.py)


FIGURES = _hook("figures")


@pytest.mark.parametrize("page", sorted(DOCS.rglob("*.md")), ids=lambda p: str(p.relative_to(DOCS)))
def test_every_figure_a_page_quotes_from_a_results_file_is_in_that_file(page):
    """Issue 33: the site's figures are rendered from ``bench/results/*.json`` at build time; a placeholder whose file
    or value is missing (a renamed figure, a results file not committed) fails here and in ``mkdocs build --strict``."""
    text = page.read_text(encoding="utf-8")
    rendered = FIGURES.render_page(text, str(page.relative_to(DOCS)))  # raises, naming the page, what does not resolve
    assert not re.search(r"\{\{\s*[\w-]+:", rendered), "a placeholder the hook's pattern does not read"


def _table_rows(markdown: str, heading: str) -> list[str]:
    section = markdown.split(f"\n## {heading}\n", 1)[1].split("\n## ", 1)[0]
    return [line for line in section.splitlines() if line.startswith("| ") and not line.startswith("| ---")][1:]


@pytest.mark.parametrize("heading", ["Accuracy", "Speed"])
def test_the_validation_tables_are_rendered_from_the_run_each_row_names(heading):
    """Each row of the validation page's accuracy and speed tables shows the command that wrote its results file
    (``{{ FILE:command }}``) and takes every figure from that one file, so that a figure cannot come from another run
    than the command beside it (the files of short check runs are named by their own command)."""
    rows = _table_rows((DOCS / "validation" / "index.md").read_text(encoding="utf-8"), heading)
    assert rows
    for row in rows:
        files = {m.group(1) for m in FIGURES.PLACEHOLDER.finditer(row)}
        assert len(files) == 1, row
        (name,) = files
        assert f"{{{{ {name}:command }}}}" in row, row
        command = FIGURES.render(name, "command")
        assert command.startswith("python3 bench/"), command
        assert "python3 bench/" not in FIGURES.PLACEHOLDER.sub("", row), f"a command typed by hand: {row}"


def test_the_figure_placeholders_mini_language(tmp_path, monkeypatch):
    """Paths into a results file (keys with spaces, list indices, ``*``, ``A+B``, ``[key=value]``), the steps (min, max,
    median, len, xK, date, a format spec), and one plain sentence for what does not resolve."""
    (tmp_path / "demo.json").write_text(json.dumps({
        "command": "python3 bench/speed/demo.py --fast",
        "date_utc": "2026-12-06T09:00:00+00:00",
        "figures": {"wall s": [2.0, 1.0, 3.0], "rows": [{"level": "low", "m": "a", "e": {"M": 1.0, "V": 5.0}},
                                                       {"level": "bench", "m": "a", "e": {"M": 2.0, "V": 7.0}},
                                                       {"level": "bench", "m": "b", "e": {"M": 4.0, "V": 9.0}}],
                    "ratio": 0.1234, "none": None, "nulls": [1.0, None, 3.0],
                    "cases": [{"case": {"caster": 0.0}, "clean": False, "e": 1.5, "tag": None},
                              {"case": {"caster": 0.015}, "clean": False, "e": 2.5},
                              {"case": {"caster": 0.0}, "clean": True, "e": 9.0}]},
    }))  # fmt: skip
    monkeypatch.setattr(FIGURES, "RESULTS", tmp_path)
    FIGURES._read.cache_clear()
    try:
        page = (
            "{{ demo:command }} on {{ demo:date_utc|date }}: {{ demo:figures.wall s|median;.3g }} s of "
            "{{ demo:figures.wall s|len }}, max {{ demo:figures.wall s.2 }}, {{ demo:figures.ratio|x100;.1f }} %, "
            "{{ demo:figures.rows.[level=bench].e.M+V|min }}..{{ demo:figures.rows.[level=bench].e.*|max;.0f }}, "
            "{{ demo:figures.rows.[level=bench,m=b].e.M|.2f }}, {{demo:figures.rows.0.m}}, "
            "{{ demo:figures.cases.[case/caster=0,clean=false].e }}, {{ demo:figures.cases.[case/caster=0.015].e }}, "
            "{{ demo:figures.cases.*.e|sum }}, {{ demo:figures.nulls|known;max }}, {{ demo:figures.nulls|len }}, "
            "{{ demo:figures.cases.[tag=null].e }}"
        )
        assert FIGURES.render_page(page) == (
            "python3 bench/speed/demo.py --fast on 2026-12-06: 2 s of 3, max 3.0, 12.3 %, 2.0..9, 4.00, a, 1.5, 2.5, "
            "13.0, 3.0, 3, 1.5"
        )
        for bad, said in [
            ("{{ nothing:command }}", "no results file bench/results/nothing.json"),
            ("{{ demo:figures.missing }}", "no value at 'figures.missing'"),
            ("{{ demo:figures.wall s }}", "is a list: take min, max, median, sum or len of it"),
            ("{{ demo:figures.nulls|max }}", "a value is null (not measured, or not finite); 'known' drops them"),
            ("{{ demo:figures.wall s|.2f;max }}", "the format '.2f' must be the last step"),
            ("{{ demo:figures.wall s|date }}", "date of 'figures.wall s', which is not a timestamp"),
            ("{{ demo:command.*|len }}", "no value at 'command.*'"),
            ("{{ demo:figures.ratio|abs;xq }}", "format 'xq' does not apply"),
            ("{{ demo figures.ratio }}", "not a placeholder this hook reads"),
            ("{{ demo:figures.none }}", "is null"),
            ("{{ demo:figures.rows.[level=high].m }}", "no value at"),
            ("{{ demo:command|.2f }}", "format '.2f' does not apply"),
        ]:
            with pytest.raises(FIGURES.FigureError, match=re.escape(said)):
                FIGURES.render_page(f"text {bad}", "page.md")
    finally:
        FIGURES._read.cache_clear()


def test_the_readmes_accuracy_figure_is_the_paper_tables_run():
    """The README cannot render placeholders (it is read on the forge as written): its one accuracy figure is checked
    against the results file of the run it comes from instead."""
    worst = FIGURES.value(FIGURES.results("paper_tables"), "figures.largest_error_percent.default")
    readme = (ROOT / "README.md").read_text(encoding="utf-8")
    assert f"every base parameter comes out within {worst:#.2g} % of the truth" in _normal(readme)
