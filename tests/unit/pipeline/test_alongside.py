"""Two passes at once (wmrid.pipeline.alongside): the main one on a second thread, its outcome raised or returned on
the caller's; one thread when the process asks for one (wmrid fleet's workers)."""

from __future__ import annotations

import threading

import pytest

from wmrid.core.errors import NotIdentifiableError
from wmrid.estimators.observer import replay
from wmrid.pipeline.alongside import Once, alongside


def test_once_computes_once_and_keeps_its_error():
    calls = []

    def fails() -> int:
        calls.append(1)
        raise NotIdentifiableError("no")

    once = Once(fails)
    once.run()
    for _ in range(2):
        with pytest.raises(NotIdentifiableError, match="no"):
            once()
    assert calls == [1]
    value = Once(lambda: 7)
    assert [value(), value()] == [7, 7]


def test_alongside_runs_the_main_pass_on_a_second_thread_and_the_other_meanwhile():
    seen = {}

    def main() -> str:
        seen["main"] = threading.current_thread() is not threading.main_thread()
        return "timing"

    def meanwhile() -> None:
        seen["meanwhile"] = threading.current_thread() is threading.main_thread()

    assert alongside(main, meanwhile) == "timing"
    assert seen == {"main": True, "meanwhile": True}


def test_alongside_raises_the_main_error_once_the_other_has_run():
    ran = []

    def main() -> None:
        raise NotIdentifiableError("main")

    with pytest.raises(NotIdentifiableError, match="main"):
        alongside(main, lambda: ran.append(1))
    assert ran == [1]


def test_one_thread_runs_the_main_pass_alone_on_the_callers_thread():
    ran = []
    replay.one_thread()
    try:
        assert alongside(lambda: threading.current_thread() is threading.main_thread(), lambda: ran.append(1))
    finally:
        replay.one_thread(False)
    assert ran == []
    assert alongside(lambda: 3, None) == 3
