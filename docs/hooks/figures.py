"""mkdocs hook: figures on the site rendered from the benchmarks' result files, so that a quoted figure and the run
that measured it cannot disagree.

A page writes ``{{ FILE:PATH|OPS }}`` where it quotes a figure:

* ``FILE`` is a results file of ``bench/results/`` without ``.json`` (``bench_report``, ``bench_live-x20``);
* ``PATH`` is a dotted path into it (``figures.wall_s_median``, ``command``, ``date_utc``; a key may hold spaces:
  ``figures.in_one_process.ROS 1 bag.loop_s``); a number indexes a list,
  ``*`` takes every item of a list or every value of a mapping, ``A+B`` the keys A and B of a mapping,
  ``[key=value,...]`` the items of a list whose keys hold those values (``a/b=v``: the key b of the item's mapping a;
  numbers compare as numbers, ``true``/``false`` as JSON's; one item, or a list of several, of which an aggregate
  below makes one number);
* ``OPS`` (optional) are ``;``-separated steps applied in order: ``min``, ``max``, ``median``, ``sum``, ``len``
  (of a list, or of a mapping's keys), ``xK`` (multiply by K: ``x1000`` for s -> ms, ``x100`` for a fraction -> %),
  ``abs``, ``date`` (the ``YYYY-MM-DD`` of a timestamp), ``known`` (drop the nulls: a bench writes NaN and inf as
  null, and an aggregate refuses them unless told), and last a Python format spec (``.3g``, ``,.0f``, ``.2f``).
  Without a format spec a value is printed as ``str`` gives it.

The command column of a table is itself ``{{ FILE:command }}``, so the command shown is the one that wrote the figures.
A placeholder that does not resolve fails the build (``mkdocs build --strict`` in CI), and
``tests/contract/test_docs.py`` renders every page's placeholders.
"""

from __future__ import annotations

import json
import re
import statistics
from functools import cache
from pathlib import Path
from typing import Any

ROOT = Path(__file__).resolve().parents[2]
RESULTS = ROOT / "bench" / "results"

#: ``{{ FILE:PATH }}`` or ``{{ FILE:PATH|OPS }}``.
PLACEHOLDER = re.compile(r"\{\{\s*([\w.-]+):([^|}]+?)(?:\|([^}]*))?\s*\}\}")

_AGGREGATES = {"min": min, "max": max, "median": statistics.median, "len": len, "sum": sum}


class FigureError(ValueError):
    """A placeholder that names no file, no value, or a step that does not apply."""


def results(name: str) -> dict[str, Any]:
    """The results file ``bench/results/<name>.json`` (read again when it changed: ``mkdocs serve`` after a run)."""
    path = RESULTS / f"{name}.json"
    if not path.is_file():
        raise FigureError(f"no results file bench/results/{name}.json")
    return _read(path, path.stat().st_mtime_ns)


@cache
def _read(path: Path, mtime_ns: int) -> dict[str, Any]:
    return json.loads(path.read_text(encoding="utf-8"))


def value(document: Any, path: str) -> Any:
    """The value at the dotted ``path`` of ``document`` (see the module docstring)."""

    def walk(node: Any, parts: list[str]) -> Any:
        if not parts:
            return node
        head, rest = parts[0], parts[1:]
        if head == "*":
            if not isinstance(node, (dict, list)):
                raise TypeError(f"* of a {type(node).__name__}")
            items = node.values() if isinstance(node, dict) else node
            return [walk(item, rest) for item in items]
        if head.startswith("[") and head.endswith("]"):  # the items of a list whose keys hold these values
            wanted = dict(cond.split("=", 1) for cond in head[1:-1].split(","))
            chosen = [x for x in node if all(_holds(x, k, v) for k, v in wanted.items())]
            if not chosen:
                raise KeyError(f"no item with {head}")
            return walk(chosen[0], rest) if len(chosen) == 1 else [walk(x, rest) for x in chosen]
        if "+" in head:  # several keys of a mapping
            return [walk(node[key], rest) for key in head.split("+")]
        if isinstance(node, list):
            return walk(node[int(head)], rest)
        return walk(node[head], rest)

    try:
        return walk(document, _parts(path))
    except (KeyError, IndexError, ValueError, TypeError) as exc:
        raise FigureError(f"no value at {path!r} ({type(exc).__name__}: {exc})") from None


def _parts(path: str) -> list[str]:
    """``path`` split at its dots, those inside a ``[...]`` filter kept (``[case/caster=0.015].error``)."""
    parts, depth, start = [], 0, 0
    for i, ch in enumerate(path):
        depth += (ch == "[") - (ch == "]")
        if ch == "." and depth == 0:
            parts.append(path[start:i])
            start = i + 1
    return [*parts, path[start:]]


def _holds(item: Any, key: str, wanted: str) -> bool:
    """Whether ``item``'s ``key`` (``a/b``: the key b of its mapping a) holds ``wanted``: equal as text, or as numbers
    (``caster=0`` matches 0.0), ``True``/``False`` as JSON's true/false."""
    for part in key.split("/"):
        if not isinstance(item, dict) or part not in item:
            return False
        item = item[part]
    if item is None:
        return wanted in ("null", "None")
    if isinstance(item, bool):
        return str(item).lower() == wanted.lower()
    if str(item) == wanted:
        return True
    try:
        return float(item) == float(wanted)
    except (TypeError, ValueError):
        return False


def _flat(v: Any) -> list[Any]:
    return [y for x in v for y in _flat(x)] if isinstance(v, list) else [v]


def render(name: str, path: str, ops: str | None = None) -> str:
    """The text of ``{{ name:path|ops }}``; :class:`FigureError` for anything that does not apply."""
    v = value(results(name), path)
    spec = None
    for op in [o.strip() for o in (ops or "").split(";") if o.strip()]:
        if spec is not None:
            raise FigureError(f"the format {spec!r} must be the last step, not before {op!r}")
        try:
            v = _step(v, op, path)
        except FigureError:
            raise
        except (TypeError, ValueError, ArithmeticError) as exc:
            raise FigureError(f"{op!r} does not apply to {path!r}: {exc}") from None
        if not _is_step(op):
            spec = op
    if isinstance(v, list):
        raise FigureError(f"{path!r} is a list: take min, max, median, sum or len of it")
    if v is None:
        raise FigureError(f"{path!r} is null (not measured in that run, or not finite)")
    try:
        return format(v, spec) if spec else str(v)
    except (ValueError, TypeError) as exc:
        raise FigureError(f"format {spec!r} does not apply to {v!r}: {exc}") from None


#: ``xK``: multiply by K.
_SCALE = r"x[-+]?[0-9.]+(?:e[-+]?[0-9]+)?"


def _is_step(op: str) -> bool:
    """Whether ``op`` is a step of :func:`_step` (else a format spec)."""
    return op in _AGGREGATES or op in ("known", "abs", "date") or re.fullmatch(_SCALE, op) is not None


def _step(v: Any, op: str, path: str) -> Any:
    """``v`` after the step ``op`` (a format spec is returned unchanged: :func:`render` applies it last)."""
    if op == "known":  # drop the nulls, explicitly: a figure never silently leaves a case out
        if not isinstance(v, list):
            raise FigureError(f"known of {path!r}, which is not a list")
        return [x for x in _flat(v) if x is not None]
    if op == "len":
        if not isinstance(v, (list, dict)):
            raise FigureError(f"len of {path!r}, which is neither a list nor a mapping")
        return len(v)
    if op in _AGGREGATES:
        if not isinstance(v, list):
            raise FigureError(f"{op} of {path!r}, which is not a list")
        flat = _flat(v)
        if not flat:
            raise FigureError(f"{op} of {path!r}: the list is empty")
        if any(x is None for x in flat):
            raise FigureError(f"{op} of {path!r}: a value is null (not measured, or not finite); 'known' drops them")
        return _AGGREGATES[op](flat)
    if re.fullmatch(_SCALE, op):
        return [x * float(op[1:]) for x in _flat(v)] if isinstance(v, list) else v * float(op[1:])
    if op == "abs":
        return [abs(x) for x in _flat(v)] if isinstance(v, list) else abs(v)
    if op == "date":
        if not isinstance(v, str) or not re.match(r"\d{4}-\d\d-\d\d", v):
            raise FigureError(f"date of {path!r}, which is not a timestamp")
        return v[:10]
    return v  # a format spec


def render_page(markdown: str, where: str = "page") -> str:
    """``markdown`` with every placeholder replaced by its figure; raises :class:`FigureError` naming the first that
    does not resolve."""

    def one(m: re.Match[str]) -> str:
        try:
            return render(m.group(1), m.group(2), m.group(3))
        except FigureError as exc:
            raise FigureError(f"{where}: {m.group(0)}: {exc}") from None

    out = PLACEHOLDER.sub(one, markdown)
    left = re.search(r"\{\{.{0,80}", out)
    if left:
        raise FigureError(f"{where}: {left.group(0)!r}: not a placeholder this hook reads ({{{{ FILE:PATH|OPS }}}})")
    return out


def on_page_markdown(markdown: str, page: Any, config: Any, files: Any) -> str:
    from mkdocs.exceptions import PluginError

    try:
        return render_page(markdown, page.file.src_path)
    except FigureError as exc:
        raise PluginError(str(exc)) from None
