"""Every Python and shell example of the documentation site runs (docs/**/*.md).

Every fenced ``bash``/``sh`` and ``python`` block of a page runs, in order, in a fresh folder holding ``sample_logs/``,
``examples/`` and ``bench/`` (and ``real_logs/``, the logs of ``../shared/real_logs``, where they exist); the blocks of
one page share that folder (shell) and one namespace (Python), so a page reads as one session.  A block that cannot
run here is preceded by ``<!-- test: skip REASON -->`` (the reason is required); a page with a block preceded by
``<!-- test: slow -->`` is left out of the default run; ``<!-- test: needs real_logs -->`` skips a page when
``../shared/real_logs`` is absent.  Output shown on a page is in ``text`` blocks, which are not run."""

from __future__ import annotations

import os
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import pytest
from locations import ROOT_DIR

ROOT = ROOT_DIR
DOCS = ROOT / "docs"
REAL_LOGS = ROOT.parent / "shared" / "real_logs"


@dataclass
class Block:
    page: str
    line: int
    language: str
    code: str
    skip: str | None
    slow: bool
    needs_real_logs: bool


_FENCE = re.compile(r"^```([A-Za-z]*)[^\n]*\n(.*?)^```\s*$", re.S | re.M)
_MARK = re.compile(r"<!--\s*test:\s*(skip|slow|needs real_logs)\s*(.*?)\s*-->\s*$")
RUN = {"bash": "shell", "sh": "shell", "shell": "shell", "python": "python", "py": "python"}


def doc_blocks(path: Path) -> list[Block]:
    text = path.read_text(encoding="utf-8")
    blocks = []
    for match in _FENCE.finditer(text):
        language = RUN.get(match.group(1).lower())
        if language is None:
            continue
        before = text[: match.start()].rstrip("\n").splitlines()
        marks = []
        while before and _MARK.search(before[-1]):
            marks.append(_MARK.search(before[-1]).groups())
            before.pop()
        skip = next((why or "" for kind, why in marks if kind == "skip"), None)
        blocks.append(Block(
            page=str(path.relative_to(ROOT)), line=text[: match.start()].count("\n") + 1, language=language,
            code=match.group(2), skip=skip, slow=any(kind == "slow" for kind, _ in marks),
            needs_real_logs=any(kind == "needs real_logs" for kind, _ in marks),
        ))  # fmt: skip
    return blocks


PAGES = sorted(p for p in DOCS.rglob("*.md") if doc_blocks(p))


def _page_param(path: Path):
    blocks = doc_blocks(path)
    marks = [pytest.mark.slow] if any(b.slow for b in blocks) else []
    return pytest.param(path, id=str(path.relative_to(DOCS)), marks=marks)


def test_every_skipped_example_says_why():
    for path in sorted(DOCS.rglob("*.md")):
        for block in doc_blocks(path):
            if block.skip is not None:
                assert len(block.skip) > 10, f"{block.page}:{block.line}: a skipped example needs its reason"


def workdir(tmp_path: Path) -> Path:
    for name in ("sample_logs", "examples", "bench"):
        (tmp_path / name).symlink_to(ROOT / name)
    if REAL_LOGS.exists():
        (tmp_path / "real_logs").symlink_to(REAL_LOGS)
    return tmp_path


@pytest.mark.parametrize("page", [_page_param(p) for p in PAGES])
def test_the_examples_of_a_docs_page_run(page, tmp_path, monkeypatch):
    blocks = [b for b in doc_blocks(page) if b.skip is None]
    if any(b.needs_real_logs for b in doc_blocks(page)) and not REAL_LOGS.exists():
        pytest.skip("../shared/real_logs is not beside the checkout")
    work = workdir(tmp_path)
    env = {
        **os.environ,
        "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ.get('PATH', '')}",
        "PYTHONPATH": str(ROOT),
        "COLUMNS": "100",
        "NO_COLOR": "1",
        "WMRID_BENCH_RESULTS": str(tmp_path / "bench-results"),  # a bench script's figures, not the committed ones
    }
    scope: dict = {"__name__": "__docs__"}
    monkeypatch.chdir(work)
    for block in blocks:
        where = f"{block.page}:{block.line}"
        if block.language == "shell":
            proc = subprocess.run(
                ["bash", "-e", "-o", "pipefail", "-c", block.code], cwd=work, env=env, capture_output=True,
                text=True, timeout=900, stdin=subprocess.DEVNULL,
            )  # fmt: skip
            output = f"{proc.stdout[-2000:]}\n{proc.stderr[-3000:]}"
            assert proc.returncode == 0, f"{where} failed ({proc.returncode}):\n{output}"
        else:
            exec(compile(block.code, where, "exec"), scope)
