"""The bench scripts use wmrid as its users do (issue 31), and their figures files say where they come from (issue 33).

Every Python file under bench/ imports from wmrid only its front door: ``import wmrid`` (then ``wmrid.NAME``) or
``from wmrid import NAME`` with NAME one of ``wmrid.__all__``; no ``wmrid.<module>`` import, no
``importlib.import_module("wmrid....")``, no ``wmrid.<module>`` attribute (an internal module reached through the
package).  The CLI they run as a subprocess is the other public way in.  Every bench/results/*.json is what
bench/_common.py's ``write_results`` writes: the script that made it (which exists), the exact command, the date, the
machine, wmrid's version, the git commit, and the figures.
"""

from __future__ import annotations

import ast
import json
import re
from pathlib import Path

import pytest
from locations import ROOT_DIR

import wmrid

BENCH = ROOT_DIR / "bench"
#: bench/_common.py and the scripts of each kind's folder (bench/out/ holds generated files, never a script).
SCRIPTS = sorted([*BENCH.glob("*.py"), *(p for p in BENCH.glob("*/*.py") if p.parent.name not in ("out", "results"))])
RESULTS = sorted((BENCH / "results").glob("*.json"))
PUBLIC = set(wmrid.__all__)


def private_uses(path: Path) -> list[str]:
    """``line: what`` for every use of wmrid other than its front door in the file at ``path``."""
    tree = ast.parse(path.read_text(encoding="utf-8"), filename=str(path))
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [f"{node.lineno}: import {a.name}" for a in node.names if a.name.startswith("wmrid.")]
        elif isinstance(node, ast.ImportFrom) and not node.level and node.module:
            if node.module.startswith("wmrid."):
                found.append(f"{node.lineno}: from {node.module} import ...")
            elif node.module == "wmrid":
                found += [f"{node.lineno}: from wmrid import {a.name}" for a in node.names if a.name not in PUBLIC]
        elif isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id == "wmrid":
            if node.attr not in PUBLIC and node.attr != "__version__":
                found.append(f"{node.lineno}: wmrid.{node.attr}")
        elif (
            isinstance(node, ast.Call)
            and getattr(node.func, "attr", getattr(node.func, "id", None)) in ("import_module", "__import__")
            and node.args
            and isinstance(node.args[0], ast.Constant)
            and isinstance(node.args[0].value, str)
            and node.args[0].value.startswith("wmrid.")
        ):
            found.append(f"{node.lineno}: import_module({node.args[0].value!r})")
    return found


def test_there_are_bench_scripts_in_folders_by_kind():
    kinds = {p.relative_to(BENCH).parts[0] for p in SCRIPTS if len(p.relative_to(BENCH).parts) > 1}
    assert kinds == {"speed", "accuracy", "studies", "fuzz"}
    assert not [p.name for p in SCRIPTS if p.parent == BENCH and p.name != "_common.py"], "a script outside a kind"


@pytest.mark.parametrize("path", SCRIPTS, ids=[str(p.relative_to(BENCH)) for p in SCRIPTS])
def test_a_bench_script_imports_only_the_public_api(path: Path):
    uses = private_uses(path)
    assert not uses, f"{path.relative_to(ROOT_DIR)} reaches past wmrid's front door:\n" + "\n".join(uses)


def test_the_check_finds_what_it_should(tmp_path: Path):
    """The check itself: each way into an internal module is found, the front door is not."""
    script = tmp_path / "bench_x.py"
    script.write_text(
        "import wmrid\nimport wmrid.io.logs\nfrom wmrid.sim import simulate\nfrom wmrid import identify, Steps\n"
        "from wmrid import read_log as rl\nimport importlib\nimportlib.import_module('wmrid.pipeline.identify')\n"
        "wmrid.identify(None)\nwmrid.pipeline\nprint(wmrid.__version__)\n"
    )
    assert [u.split(":")[0] for u in private_uses(script)] == ["2", "3", "4", "7", "9"]


def test_the_readme_lists_every_script():
    readme = (BENCH / "README.md").read_text(encoding="utf-8")
    for path in SCRIPTS:
        if path.name != "_common.py":
            assert f"`{path.relative_to(BENCH)}`" in readme, f"bench/README.md does not list {path.name}"


@pytest.mark.parametrize("path", RESULTS, ids=[p.name for p in RESULTS])
def test_a_results_file_says_where_its_figures_come_from(path: Path):
    data = json.loads(path.read_text(encoding="utf-8"))
    assert set(data) >= {"script", "command", "date_utc", "machine", "wmrid_version", "git", "figures"}
    assert path.stem == data["script"] or path.stem.startswith(data["script"] + "-")
    command = data["command"].split()
    assert command[0] == "python3"
    assert (ROOT_DIR / command[1]).is_file(), f"{path.name}: {command[1]} is no script of the checkout"
    assert Path(command[1]).stem == data["script"]
    assert re.fullmatch(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\+00:00", data["date_utc"])
    assert {"platform", "cpu_count", "cpu_model"} <= set(data["machine"])
    assert data["git"] is None or re.fullmatch(r"[0-9a-f]{40}", data["git"]["commit"])
    assert isinstance(data["figures"], dict)
    assert data["figures"]
