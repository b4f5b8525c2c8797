"""Golden identify results (:mod:`tests.golden`): the JSON of each case, history included (by its hash), equals the
one written when the case was last meant to change.  A failure names the fields that moved; when the change is
meant, rewrite the file with ``python -m tests.golden --write NAME`` and say so in the commit."""

from __future__ import annotations

import json

import pytest

from tests.golden import CASES, REAL, Case, capture_in_process_of_one_thread, path_of


def _moved(old: object, new: object, where: str = "") -> list[str]:
    if isinstance(old, dict) and isinstance(new, dict):
        out = []
        for key in sorted(set(old) | set(new)):
            if key not in old or key not in new:
                out.append(f"{where}.{key} {'added' if key not in old else 'removed'}")
            else:
                out += _moved(old[key], new[key], f"{where}.{key}")
        return out
    return [] if old == new else [f"{where}: {old!r:.80} -> {new!r:.80}"]


def _param(case: Case):
    marks = [pytest.mark.slow] if case.slow else []
    if case.needs_real:
        marks.append(pytest.mark.skipif(not REAL.exists(), reason="../shared/real_logs is not beside the checkout"))
    return pytest.param(case, id=case.name, marks=marks)


@pytest.mark.parametrize("case", [_param(c) for c in CASES])
def test_identify_json_equals_its_golden_file(case: Case, tmp_path_factory) -> None:
    golden = json.loads(path_of(case).read_text())
    record = capture_in_process_of_one_thread(case, tmp_path_factory.getbasetemp() / "golden_logs")
    if record["sha256"] != golden["sha256"]:
        moved = _moved(golden["result"], record["result"]) or ["the history arrays (only the hash covers them)"]
        pytest.fail(f"{case.name}: {len(moved)} fields moved:\n" + "\n".join(moved[:40]))
