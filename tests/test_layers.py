"""The package's layers: a module never imports one from a higher layer, nor from a sibling layer of the same rank.

Layers, lowest first (docs/development.md): ``core`` (errors, limits, atomic outputs, the log types) -> ``model``
(dynamics, robot, payload, predictor) -> ``io`` (readers, writers) | ``estimators`` | ``sim`` (siblings: the
estimators never import a reader, the readers never an estimator) -> ``monitoring`` | ``design`` (``wmrid plan``:
experiment design on the model, the simulator's built-in trajectories as its baselines) -> ``reporting`` |
``exports`` (siblings: ``wmrid export``'s writers) -> ``api`` (the front door) -> ``cli``. Every import counts,
including those inside functions and under ``TYPE_CHECKING``.
"""

from __future__ import annotations

import ast
from pathlib import Path

import pytest

import wmrid

PACKAGE = Path(wmrid.__file__).parent
RANK = {
    "core": 0,
    "model": 1,
    "io": 2,
    "estimators": 2,
    "sim": 2,
    "monitoring": 3,
    "design": 3,
    "reporting": 4,
    "exports": 4,
    "api": 5,
    "cli": 6,
}


def _layer(module: str) -> str | None:
    """The layer of a dotted module name inside wmrid (None for the package itself and ``__main__``)."""
    parts = module.split(".")
    return parts[1] if len(parts) > 1 and parts[1] in RANK else None


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
    tree = ast.parse(path.read_text(encoding="utf-8"))
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
