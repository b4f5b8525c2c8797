"""The package's layers: a module never imports one from a higher layer, nor from a sibling layer of the same rank.

Layers, lowest first (docs/development.md): ``core`` (errors, choices, extras, the log types) -> ``runtime`` (signals,
atomic outputs, the memory budget, careful reading of side files) -> ``model``
(dynamics, robot, payload, predictor) -> ``io`` (readers, writers) | ``estimators`` | ``sim`` (siblings: the
estimators never import a reader, the readers never an estimator) -> ``pipeline`` (the identification's route over
the estimators) -> ``monitoring`` | ``design`` (``wmrid plan``:
experiment design on the model, the simulator's built-in trajectories as its baselines) -> ``reporting`` |
``exports`` (siblings: ``wmrid export``'s writers) -> ``api`` (the front door) -> ``fleets`` (a fleet's table, its
run on Dask over the api, its review) -> ``cli``. Every import counts,
including those inside functions and under ``TYPE_CHECKING``.
"""

from __future__ import annotations

import ast
import functools
import io
import re
import tokenize
from pathlib import Path

import pytest

import wmrid

PACKAGE = Path(wmrid.__file__).parent
RANK = {
    "core": 0,
    "runtime": 1,
    "model": 2,
    "io": 3,
    "estimators": 3,
    "sim": 3,
    "pipeline": 4,
    "monitoring": 5,
    "design": 5,
    "reporting": 6,
    "exports": 6,
    "api": 7,
    "fleets": 8,
    "cli": 9,
}


def _layer(module: str) -> str | None:
    """The layer of a dotted module name inside wmrid (None for the package itself and ``__main__``)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[1] in RANK else None


@functools.cache
def _source(path: Path) -> str:
    return path.read_text(encoding="utf-8")


@functools.cache
def _tree(path: Path) -> ast.Module:
    """The module's syntax tree, parsed once for all the tests (read-only: no test changes it)."""
    return ast.parse(_source(path))


def _modules() -> list[tuple[str, Path]]:
    out = []
    for path in sorted(PACKAGE.rglob("*.py")):
        rel = path.relative_to(PACKAGE.parent).with_suffix("")
        name = ".".join(p for p in rel.parts if p != "__init__")
        out.append((name, path))
    return out


def _imports(name: str, path: Path) -> list[tuple[int, str]]:
    """(line, imported wmrid module) for every import in the file: import statements, names taken from the package
    (its lazy exports resolved to the modules that define them), ``wmrid.NAME`` attribute uses, and
    ``importlib.import_module("wmrid....")`` calls."""
    tree = _tree(path)
    package = name if path.name == "__init__.py" else name.rpartition(".")[0]
    exports = wmrid._EXPORTS
    found = []
    for node in ast.walk(tree):
        if isinstance(node, ast.Import):
            found += [(node.lineno, a.name) for a in node.names]
        elif isinstance(node, ast.ImportFrom):
            if node.level:  # relative: resolve against the package
                base = package.split(".")[: len(package.split(".")) - node.level + 1]
                target = ".".join([*base, node.module] if node.module else base)
            else:
                target = node.module or ""
            found.append((node.lineno, target))
            if target == "wmrid":
                found += [(node.lineno, exports.get(a.name, f"wmrid.{a.name}")) for a in node.names]
        elif isinstance(node, ast.Attribute) and isinstance(node.value, ast.Name) and node.value.id == "wmrid":
            found.append((node.lineno, exports.get(node.attr, f"wmrid.{node.attr}")))
        elif (
            isinstance(node, ast.Call)
            and getattr(node.func, "attr", getattr(node.func, "id", None)) == "import_module"
            and node.args
            and isinstance(node.args[0], ast.Constant)
            and isinstance(node.args[0].value, str)
        ):
            found.append((node.lineno, node.args[0].value))
    return [(line, t) for line, t in found if t == "wmrid" or t.startswith("wmrid.")]


def test_every_module_belongs_to_a_layer():
    loose = [n for n, p in _modules() if _layer(n) is None and n not in ("wmrid", "wmrid.__main__")]
    assert loose == [], f"modules outside the layers {sorted(RANK)}: {loose}"


@pytest.mark.parametrize(("name", "path"), _modules(), ids=lambda v: v if isinstance(v, str) else "")
def test_no_upward_or_sideways_import(name, path):
    mine = _layer(name)
    if mine is None:
        return  # the package's front (lazy exports) and __main__ may import anything
    bad = []
    for line, target in _imports(name, path):
        theirs = _layer(target)
        if theirs is None or theirs == mine:
            continue
        if RANK[theirs] > RANK[mine] or RANK[theirs] == RANK[mine]:
            bad.append(f"{path.relative_to(PACKAGE.parent)}:{line} imports {target} ({theirs} over {mine})")
    assert bad == [], "\n".join(bad)


def test_the_checker_sees_an_upward_import(tmp_path):
    """The check itself: upward imports in every form are found (so the test cannot pass vacuously)."""
    f = tmp_path / "m.py"
    f.write_text(
        "import importlib\nimport wmrid\nfrom wmrid import identify\n\n\ndef f():\n    from wmrid.cli.app import main\n"
        "    import wmrid.io.logs\n    wmrid.report(1)\n    importlib.import_module('wmrid.sim.simulate')\n"
    )
    layers = {_layer(t) for _, t in _imports("wmrid.core.m", f)}
    assert {"api", "cli", "io", "sim"} <= layers


def _graph() -> dict[str, set[str]]:
    """module -> the wmrid modules it imports (every import, inside functions too; ``from wmrid.pkg import name``
    counted as the submodule ``name`` where there is one)."""
    names = {n for n, _ in _modules()}
    graph: dict[str, set[str]] = {}
    for name, path in _modules():
        targets = set()
        tree = _tree(path)
        for node in ast.walk(tree):
            if isinstance(node, ast.ImportFrom) and node.module and not node.level:
                subs = {f"{node.module}.{a.name}" for a in node.names} & names
                targets |= subs or ({node.module} & names)
        targets |= {
            t for _, t in _imports(name, path) if t in names and not any(s.startswith(t + ".") for s in targets)
        }
        graph[name] = targets - {name}
    return graph


def _loops(graph: dict[str, set[str]]) -> list[tuple[str, ...]]:
    """The import loops inside one folder: strongly connected groups (Tarjan) of two or more modules of the same
    package."""
    index: dict[str, int] = {}
    low: dict[str, int] = {}
    stack: list[str] = []
    on: set[str] = set()
    found: list[tuple[str, ...]] = []

    def visit(v: str) -> None:
        index[v] = low[v] = len(index)
        stack.append(v)
        on.add(v)
        for w in sorted(graph.get(v, ())):
            if w.rpartition(".")[0] != v.rpartition(".")[0]:
                continue  # another folder: the layer test's business
            if w not in index:
                visit(w)
                low[v] = min(low[v], low[w])
            elif w in on:
                low[v] = min(low[v], index[w])
        if low[v] == index[v]:
            group = []
            while True:
                w = stack.pop()
                on.discard(w)
                group.append(w)
                if w == v:
                    break
            if len(group) > 1:
                found.append(tuple(sorted(group)))

    for v in sorted(graph):
        if v not in index:
            visit(v)
    return sorted(found)


#: Import loops inside a folder that stand, each with why (issue 31).  A new loop fails the test; so does a listed
#: loop that is gone (take it off the list).
KNOWN_LOOPS = {
    ("wmrid.cli.app", "wmrid.cli.export_commands", "wmrid.cli.fleet_commands", "wmrid.cli.identify_commands",
     "wmrid.cli.live_commands", "wmrid.cli.plan_commands", "wmrid.cli.sim_commands"):
        "start-up time: the command modules register on the app, which imports them only when it builds the command",
}  # fmt: skip


def test_no_import_loop_inside_a_folder_but_the_known_ones() -> None:
    loops = set(_loops(_graph()))
    assert loops - set(KNOWN_LOOPS) == set(), f"new import loops: {sorted(loops - set(KNOWN_LOOPS))}"
    assert set(KNOWN_LOOPS) - loops == set(), f"gone (take them off KNOWN_LOOPS): {sorted(set(KNOWN_LOOPS) - loops)}"


def test_the_loop_finder_sees_a_loop() -> None:
    graph = {"wmrid.x.a": {"wmrid.x.b"}, "wmrid.x.b": {"wmrid.x.c"}, "wmrid.x.c": {"wmrid.x.a"}, "wmrid.y.d": set()}
    assert _loops(graph) == [("wmrid.x.a", "wmrid.x.b", "wmrid.x.c")]
    graph["wmrid.x.c"] = {"wmrid.y.d"}
    assert _loops(graph) == []


#: The longest a module may be (issue 31): past it, a module holds more than one concern; split it by what it holds.
MAX_MODULE_LINES = 500


def test_no_module_is_longer_than_the_limit() -> None:
    long = {
        str(path.relative_to(PACKAGE.parent)): n
        for _, path in _modules()
        if (n := len(_source(path).splitlines())) > MAX_MODULE_LINES
    }
    assert long == {}, f"modules over {MAX_MODULE_LINES} lines: {long}"


def _resolved(node: ast.Import | ast.ImportFrom, package: str, names: set[str]) -> list[str]:
    """The wmrid modules an import statement loads (``from a import b``: the submodule ``a.b`` when there is one)."""
    if isinstance(node, ast.Import):
        return [a.name for a in node.names if a.name in names]
    base = node.module or ""
    if node.level:
        parts = package.split(".")[: len(package.split(".")) - node.level + 1]
        base = ".".join([*parts, *([base] if base else [])])
    subs = [f"{base}.{a.name}" for a in node.names if f"{base}.{a.name}" in names]
    return [m for m in (subs or [base]) if m in names]


def _import_time_and_local_imports() -> tuple[dict[str, set[str]], dict[str, list[tuple[int, str]]]]:
    """(module -> the wmrid modules its body imports when it is imported, ``TYPE_CHECKING`` blocks left out;
    module -> (line, module) of each import inside one of its functions)."""
    names = {n for n, _ in _modules()}
    at_import: dict[str, set[str]] = {}
    local: dict[str, list[tuple[int, str]]] = {}

    def body_imports(body: list[ast.stmt], package: str, found: set[str]) -> None:
        for node in body:
            if isinstance(node, (ast.Import, ast.ImportFrom)):
                found.update(_resolved(node, package, names))
            elif isinstance(node, ast.If) and "TYPE_CHECKING" not in ast.unparse(node.test):
                body_imports(node.body, package, found)
                body_imports(node.orelse, package, found)
            elif isinstance(node, ast.Try):
                for block in (node.body, *(h.body for h in node.handlers), node.orelse, node.finalbody):
                    body_imports(block, package, found)

    for name, path in _modules():
        tree = _tree(path)
        package = name if path.name == "__init__.py" else name.rpartition(".")[0]
        found: set[str] = set()
        body_imports(tree.body, package, found)
        at_import[name] = found
        local[name] = [
            (node.lineno, target)
            for function in ast.walk(tree)
            if isinstance(function, (ast.FunctionDef, ast.AsyncFunctionDef))
            for node in ast.walk(function)
            if isinstance(node, (ast.Import, ast.ImportFrom))
            for target in _resolved(node, package, names)
        ]
    return at_import, local


#: The fleet's front doors: wmrid.fleet and wmrid.fleet_report, as lazy about what they load as ``wmrid.api``.
FRONT_DOORS = ("wmrid.fleets.run", "wmrid.fleets.report")


def _front(module: str) -> bool:
    """Whether ``module`` is a front one: the command line, the api, the package's front or a fleet's front door."""
    return module in ("wmrid", *FRONT_DOORS) or module.startswith(("wmrid.cli", "wmrid.api"))


def test_a_function_imports_a_module_only_to_put_off_loading_it() -> None:
    """Imports inside functions are for start-up time only (issue 31), each for one of three reasons:

    * in ``wmrid.cli``: ``wmrid --help`` and each command load only what that command runs;
    * in ``wmrid.api``, the fleet's front doors (``wmrid.fleets.run``, ``wmrid.fleets.report``) and the package's
      front: ``import wmrid`` and each function load only what they use;
    * elsewhere: the module imported is one its importer does not load otherwise (numba's kernels, scipy, the
      figure builders, an optional package behind it), checked here: a function-local import of a module the importer
      loads anyway at import time puts nothing off and belongs at the top.
    """
    at_import, local = _import_time_and_local_imports()

    def loaded(module: str, seen: set[str]) -> set[str]:
        for target in at_import.get(module, ()):
            parts = target.split(".")
            for i in range(2, len(parts) + 1):  # a package's __init__ runs before its module
                step = ".".join(parts[:i])
                if step in at_import and step not in seen:
                    seen.add(step)
                    loaded(step, seen)
        return seen

    needless = []
    for module, imports in local.items():
        if _front(module):
            continue
        already = loaded(module, set())
        needless += [f"{module}:{line} imports {target}" for line, target in imports if target in already | {module}]
    assert needless == [], "function-local imports of modules loaded anyway:\n" + "\n".join(needless)


#: How a front module says, once, why it imports inside functions: in its docstring, or in a comment under its imports.
REASON_MARK = "Imports inside functions:"
#: A comment that is only a tool's pragma says nothing about why.
_PRAGMA = re.compile(r"#\s*(noqa|type:|fmt:|pragma|pyright:)")


def _function_imports(tree: ast.Module) -> list[ast.Import | ast.ImportFrom]:
    """The import statements inside functions (nested ones once), in line order."""
    found = {
        node.lineno: node
        for function in ast.walk(tree)
        if isinstance(function, (ast.FunctionDef, ast.AsyncFunctionDef))
        for node in ast.walk(function)
        if isinstance(node, (ast.Import, ast.ImportFrom))
    }
    return [found[line] for line in sorted(found)]


def _comments(text: str) -> dict[int, str]:
    """line -> its comment's text (without ``#``), pragmas left out."""
    out = {}
    for tok in tokenize.generate_tokens(io.StringIO(text).readline):
        if tok.type == tokenize.COMMENT and not _PRAGMA.match(tok.string) and tok.string.lstrip("#").strip():
            out[tok.start[0]] = tok.string.lstrip("#").strip()
    return out


def _unexplained_imports(name: str, path: Path) -> list[str]:
    """``module:line  statement`` of each function-local import without a comment on its lines or on a line of its
    own just before (another import's trailing comment there does not count)."""
    text = _source(path)
    lines, comments = text.splitlines(), _comments(text)

    def explained(node: ast.Import | ast.ImportFrom) -> bool:
        before = node.lineno - 1
        if before in comments and lines[before - 1].lstrip().startswith("#"):
            return True
        return any(line in comments for line in range(node.lineno, (node.end_lineno or node.lineno) + 1))

    return [
        f"{name}:{node.lineno}  {ast.unparse(node)}" for node in _function_imports(_tree(path)) if not explained(node)
    ]


def _states_its_reason(path: Path) -> bool:
    """Whether the module says once why it imports inside functions (:data:`REASON_MARK` and a reason after it, in
    its docstring or a comment of its own line at the top level)."""
    text = _source(path)
    said = re.compile(re.escape(REASON_MARK) + r"\s*\S")
    docstring = ast.get_docstring(_tree(path)) or ""
    top_comments = [c for line, c in _comments(text).items() if text.splitlines()[line - 1].startswith("#")]
    return bool(said.search(docstring)) or any(said.match(c) for c in top_comments)


def test_every_function_local_import_says_why() -> None:
    """Issue 31: outside the front modules (:func:`_front`), an import inside a function puts a load off for
    start-up time, and says so where it stands: a comment on its line (or the line before) naming what it puts off
    and why (``# scipy.stats (~0.6 s): only a fleet review``, ``# optional extra [physics]``).  An import with no
    such reason belongs at the top of its module."""
    missing = [entry for name, path in _modules() if not _front(name) for entry in _unexplained_imports(name, path)]
    assert missing == [], (
        "function-local imports without a comment saying what they put off and why (on the line or the one "
        "before; or move them to the top):\n" + "\n".join(missing)
    )


def test_each_front_module_says_once_why_it_imports_inside_functions() -> None:
    """Issue 31: a front module's imports inside functions are all for start-up time; the module says so once
    ("Imports inside functions: <reason>" in its docstring or a comment under its imports), not on every line."""
    missing = [
        name
        for name, path in _modules()
        if _front(name) and _function_imports(_tree(path)) and not _states_its_reason(path)
    ]
    assert missing == [], (
        f"front modules that import inside functions without saying why once ({REASON_MARK!r}): {missing}"
    )


def test_the_reason_checks_see_what_is_missing(tmp_path) -> None:
    """The checks themselves: an import without a comment is named by module and line; a comment on its line (a
    multi-line import's lines too) or on a line of its own before it counts, a pragma alone or the previous import's
    comment does not; a front module's reason is found in its docstring or a top-level comment."""
    f = tmp_path / "m.py"
    f.write_text(
        "import os\n\n\ndef f():\n    import json\n    import csv  # csv: only f\n    # ssl: only f\n    import ssl\n"
        "    from typing import (\n        Any,  # typing: only f\n    )\n    import zlib  # noqa: F401\n\n"
        "    def g():\n        import uuid  # uuid: only g\n        import hmac\n"
    )
    assert _unexplained_imports("wmrid.x.m", f) == [
        "wmrid.x.m:5  import json",
        "wmrid.x.m:12  import zlib",
        "wmrid.x.m:16  import hmac",
    ]
    assert not _states_its_reason(f)
    f = tmp_path / "m2.py"  # a new file: the checks read each path once
    f.write_text('"""Doc.\n\nImports inside functions: start-up time."""\n\n\ndef f():\n    import json\n')
    assert _states_its_reason(f)
    f = tmp_path / "m3.py"  # a new file: the checks read each path once
    f.write_text("import os\n\n# Imports inside functions: start-up time\n\n\ndef f():\n    import json\n")
    assert _states_its_reason(f)
    f = tmp_path / "m4.py"  # a new file: the checks read each path once
    f.write_text(
        '"""Doc.  Imports inside functions:"""\n\n\ndef f():\n    # Imports inside functions: here\n    import json\n'
    )
    assert not _states_its_reason(f)
